"""PTD (core.filters.ptd, progressive TIN densification) on generated scenes with known truth; its TIN
kernels against scipy's Delaunay and brute-force oracles; validation, progress, cancellation;
and its accuracy on the ISPRS reference samples of the shared data."""
from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest

from groundsieve.core.filters import _ptd_kernels as K
from groundsieve.core.filters import _ptd_tin as T
from groundsieve.core.errors import Cancelled, InvalidParameterError
from groundsieve.core.progress import Steps
from groundsieve.core.filters.ptd import PTD, PTDResult, triangulate
from groundsieve.tests.core import scenes
from groundsieve.tests.core.scenes import X0, Y0, add_trees

plane_scene = partial(scenes.plane_scene, size=80.0)  # here 80 m wide by default
BOX = (30.0, 50.0, 25.0, 45.0)  # 20 x 20 m, smaller than the 30 m default seed cell


# --- known answers on generated scenes ------------------------------------------------------------

@pytest.mark.parametrize("tilt", [(0.0, 0.0), (0.1, 0.05), (-0.3, 0.2)], ids=["flat", "tilted", "steep"])
def test_plane_is_all_ground(tilt):
    xyz, _ = plane_scene(tilt=tilt)
    res = PTD().run(xyz)
    assert res.ground.dtype == bool and res.ground.shape == (xyz.shape[0],)
    assert res.ground.all()
    assert res.rounds >= 1 and res.added[-1] == 0


def test_noisy_plane_is_ground():
    """5 cm of noise on 0.7 m spacing: the angle test alone rejects many points next to a
    vertex; the final offset (0.2 m) takes all but the noise's tail."""
    xyz, _ = plane_scene(seed=1, density=2.0, noise=0.05)
    assert PTD().run(xyz).ground.mean() > 0.998
    assert PTD(offset_m=0.0).run(xyz).ground.mean() < 0.99


def test_dense_plane_is_all_ground_with_thinning():
    """Over 2 points/m² only the lowest point of each 1 m square is densified; the others
    are judged against the final TIN."""
    xyz, _ = plane_scene(seed=2, size=40.0, density=12.0, tilt=(0.05, -0.02), noise=0.02)
    res = PTD().run(xyz)
    assert res.ground.all()
    assert res.tin_vertex.sum() < 0.2 * len(xyz)  # about one vertex per m²


def test_a_thinned_point_can_be_a_seed():
    """A low outlier rejected as a seed leaves the seed to the next lowest point of its cell, here a
    point of the outlier's 1 m square, thinned (not a candidate): the rounds, which work on the
    candidates and seeds only, still have it as a vertex."""
    xyz, _ = plane_scene(seed=3, size=40.0, density=6.0)
    outlier, seed = len(xyz), len(xyz) + 1
    xyz = np.vstack([xyz, [[X0 + 15.3, Y0 + 15.3, 80.0], [X0 + 15.6, Y0 + 15.6, 99.5]]])
    res = PTD().run(xyz)
    assert res.low_outlier[outlier] and not res.ground[outlier]
    assert res.seed[seed] and res.tin_vertex[seed] and res.ground[seed]
    assert res.ground.mean() > 0.999


@pytest.mark.parametrize("tilt", [(0.0, 0.0), (0.1, 0.05)], ids=["flat", "tilted"])
def test_box_on_plane_is_object_and_plane_is_ground(tilt):
    xyz, truth = plane_scene(tilt=tilt, box=BOX)
    np.testing.assert_array_equal(PTD()(xyz), truth)


def test_box_larger_than_the_seed_cell_needs_a_larger_cell():
    """A 45 m building holds a whole 30 m seed cell (seed cells from the scene's corner, the
    paper's grid): its roof gets a seed. With the seed cell at the building's size (as Axelsson
    asks) it is found."""
    box = (15.0, 60.0, 15.0, 60.0)
    xyz, truth = plane_scene(seed=3, size=100.0, density=1.0, box=box)
    assert (PTD(seed_origin="cloud")(xyz) & ~truth).any()
    np.testing.assert_array_equal(PTD(seed_cell_m=60.0, seed_origin="cloud")(xyz), truth)


@pytest.mark.parametrize("origin", ["grid", "cloud"])
def test_seed_cells_sit_on_multiples_of_the_cell_or_on_the_cloud_corner(origin):
    """On a plane rising to the north-east the seeds are the lowest (south-west) point of each
    seed cell: cells on multiples of 30 m ("grid", shared by a tile and the whole survey) or
    from the cloud's lowest corner ("cloud", the paper's). The scene's corner is not on a
    multiple of 30 m, so the two give different seeds."""
    xyz, _ = plane_scene(tilt=(0.1, 0.05))
    res = PTD(seed_origin=origin).run(xyz)
    x, y, z = xyz.T
    ox, oy = (0.0, 0.0) if origin == "grid" else (x.min(), y.min())
    key = np.floor((x - ox) / 30.0) * 1e6 + np.floor((y - oy) / 30.0)
    order = np.lexsort((z, key))
    first = order[np.r_[True, key[order][1:] != key[order][:-1]]]  # the lowest point per cell
    assert set(np.flatnonzero(res.seed)) == set(first)
    other = PTD(seed_origin="cloud" if origin == "grid" else "grid").run(xyz)
    assert set(np.flatnonzero(other.seed)) != set(first)


def test_low_building_is_found():
    """A 2 m high flat roof: more than the 1.4 m iteration distance above the TIN."""
    xyz, truth = plane_scene(seed=4, box=BOX, box_height=2.0)
    np.testing.assert_array_equal(PTD()(xyz), truth)


def test_smooth_hill_is_kept_at_sparse_spacing():
    """A bare Gaussian hill 12 m high, 2.4 m point spacing (ISPRS rural density): PTD follows
    the convex top (the issue's known weakness of CSF)."""
    rng = np.random.default_rng(5)
    n = int(200 * 200 / 2.4 ** 2)
    x, y = rng.uniform(0, 200, n), rng.uniform(0, 200, n)
    z = 300.0 + 12.0 * np.exp(-((x - 100) ** 2 + (y - 100) ** 2) / (2 * 35.0 ** 2))
    ground = PTD()(np.column_stack([x + X0, y + Y0, z]))
    assert ground.mean() > 0.995, f"{(~ground).sum()} of {n} hill points lost"


def test_trees_are_never_ground():
    xyz, truth = plane_scene(seed=6, tilt=(0.05, -0.03), box=BOX)
    xyz, truth = add_trees(xyz, truth, n=60, seed=7, size=80.0, tilt=(0.05, -0.03))
    ground = PTD()(xyz)
    assert not (ground & ~truth).any(), "an object point was called ground"
    assert ground[truth].all()


def test_single_low_outliers_are_not_ground():
    xyz, _ = plane_scene(seed=8)
    low = np.array([10, 500, 2000, 4000, 7000, 9000])
    xyz[low, 2] -= np.array([20.0, 30.0, 45.0, 25.0, 60.0, 5.0])
    res = PTD().run(xyz)
    assert not res.ground[low].any()
    rest = np.ones(len(xyz), dtype=bool)
    rest[low] = False
    assert res.ground[rest].all()
    assert not (res.low_outlier & res.ground).any()


@pytest.mark.parametrize("size", [25, 60, 100])
def test_group_of_low_outliers_is_not_ground(size):
    """Multipath echoes: points along a line 12 m long, 25 m below the ground. They hold each other
    up, but most of the ground around them is far above. A group of 60 or more fills its seed cell's
    32 tries: the low-outlier retry made it a seed at a lower share, 15 of 60 points ground and the
    TIN 25 m down (a code reviewer); a cell among cells that found their seed is not retried."""
    xyz, _ = plane_scene(seed=9)
    rng = np.random.default_rng(10)
    t = rng.uniform(0, 12, size)
    group = np.column_stack([X0 + 20 + t, Y0 + 30 + 0.3 * rng.standard_normal(size), 75.0 + rng.uniform(0, 1, size)])
    xyz = np.vstack([xyz, group])
    res = PTD().run(xyz)
    n = len(xyz) - size
    assert not res.ground[n:].any()
    assert res.ground[:n].mean() > 0.999
    assert res.low_outlier[n:].any() and not res.low_outlier[:n].any()


def test_without_low_outlier_check_a_low_seed_spoils_its_cell():
    xyz, _ = plane_scene(seed=11)
    i = int(np.argmin((xyz[:, 0] - X0 - 45) ** 2 + (xyz[:, 1] - Y0 - 45) ** 2))
    xyz[i, 2] -= 40.0
    checked = PTD().run(xyz)
    unchecked = PTD(low_outlier_check=False).run(xyz)
    assert not checked.ground[i] and checked.low_outlier[i]
    assert unchecked.seed[i] and unchecked.ground[i]
    assert unchecked.ground.sum() < checked.ground.sum()


def closed_canopy(seed, size=120.0, density=12.0, shrubs=0.0):
    """Crowns 5 m apart over rolling ground (no gap wider than a crown), 1.2 % of the pulses under
    them reach the ground (``shrubs`` of the others hit understory 0.3-3 m up); 20 isolated low
    outliers and two multipath clusters of 10, 10-30 m below the ground. Truth: ground, outliers."""
    from scipy.spatial import cKDTree
    rng = np.random.default_rng(seed)

    def terrain(u, v):
        return 100 + 0.1 * u + 3 * np.sin(2 * np.pi * (u + v) / 90)
    g = np.arange(2.5, size, 5.0)
    tu, tv = [a.ravel() + rng.uniform(-1.4, 1.4, a.size) for a in np.meshgrid(g, g)]
    radius, height = rng.uniform(3.3, 4.6, tu.size), rng.uniform(18, 32, tu.size)
    n = int(size * size * density)
    u, v = rng.uniform(0, size, n), rng.uniform(0, size, n)
    d, k = cKDTree(np.column_stack([tu, tv])).query(np.column_stack([u, v]))
    covered = d < radius[k]
    crown = terrain(tu, tv)[k] + height[k] * (1 - 0.55 * (d / radius[k]) ** 2)
    ground = ~covered | (rng.random(n) < 0.012)
    shrub = ~ground & (rng.random(n) < shrubs)
    z = np.where(ground, terrain(u, v) + rng.normal(0, 0.03, n),
                 np.where(shrub, terrain(u, v) + rng.uniform(0.3, 3.0, n), crown - rng.uniform(0, 0.3, n)))
    ou = np.r_[rng.uniform(5, size - 5, 20), np.repeat(rng.uniform(20, size - 20, 2), 10) + rng.normal(0, 1, 20)]
    ov = np.r_[rng.uniform(5, size - 5, 20), np.repeat(rng.uniform(20, size - 20, 2), 10) + rng.normal(0, 1, 20)]
    oz = terrain(ou, ov) - rng.uniform(10, 30, 40)
    xyz = np.column_stack([np.r_[u, ou] + X0, np.r_[v, ov] + Y0, np.r_[z, oz]])
    return xyz, np.r_[ground, np.zeros(40, bool)], np.r_[np.zeros(n, bool), np.ones(40, bool)]


@pytest.mark.parametrize("seed", [1, 2])
def test_the_ground_under_a_closed_canopy_is_not_taken_for_low_outliers(seed):
    """Under crowns that close over the ground, the lowest points of most fine cells are crowns: the
    ground seen through them had too little support, every seed candidate was rejected, and the one
    seed left (the lowest point of all, an outlier 10-30 m down) kept the TIN below the ground: all
    the ground was lost (a forester's generated forest: 73 %). A cell without a supported point is
    now tried again with half the share."""
    xyz, ground, outlier = closed_canopy(seed)
    before = PTD(low_outlier_retry=False).run(xyz)
    assert before.ground[ground].mean() < 0.05  # the failure: the whole ground lost
    res = PTD().run(xyz)
    assert res.ground[ground].mean() > 0.9
    assert not res.ground[outlier].any() and not res.ground[~ground & ~outlier].any()


def test_result_fields():
    xyz, truth = plane_scene(box=BOX)
    res = PTD(seed_origin="cloud").run(xyz)
    assert isinstance(res, PTDResult)
    np.testing.assert_array_equal(res.ground, PTD(seed_origin="cloud")(xyz))
    for mask in (res.seed, res.tin_vertex, res.low_outlier):
        assert mask.dtype == bool and mask.shape == res.ground.shape
    assert not (res.seed & ~res.tin_vertex).any()
    assert not (res.tin_vertex & ~res.ground).any()
    # one seed in each 30 m cell of the 80 m square (3 x 3 from its corner), none on the box
    assert res.seed.sum() == 9 and not (res.seed & ~truth).any()
    # every vertex but the seeds was added in a round; the rounds may add ground besides
    assert res.tin_vertex.sum() - res.seed.sum() <= sum(res.added) <= res.ground.sum() - res.seed.sum()
    assert res.rounds == len(res.added) and res.added[-1] == 0


def test_point_order_does_not_matter_on_a_clear_scene():
    xyz, truth = plane_scene(seed=12, tilt=(0.05, 0.02), box=BOX)
    perm = np.random.default_rng(13).permutation(len(xyz))
    np.testing.assert_array_equal(PTD()(xyz[perm]), truth[perm])


def test_min_edge_limits_the_tin_not_the_ground():
    xyz, truth = plane_scene(seed=14, box=BOX)
    coarse = PTD(min_edge_m=4.0).run(xyz)
    fine = PTD().run(xyz)
    np.testing.assert_array_equal(coarse.ground, truth)
    assert coarse.tin_vertex.sum() < 0.5 * fine.tin_vertex.sum()


def test_max_edge_stops_triangles_bridging_gaps():
    """Seeds 30 m apart: with a 10 m edge limit no triangle may accept a point."""
    xyz, _ = plane_scene(seed=15)
    res = PTD(max_edge_m=10.0).run(xyz)
    np.testing.assert_array_equal(res.ground, res.seed)


def test_mirror_points_climb_a_steep_embankment():
    """A 35° embankment 6 m high between two flat levels, each level holding seeds: without
    mirroring the densification gets stuck at the foot and the top; with it, it climbs."""
    rng = np.random.default_rng(16)
    n = 9000
    x, y = rng.uniform(0, 150, n), rng.uniform(0, 60, n)
    rise = np.clip((x - 70.0) * math.tan(math.radians(35.0)), 0.0, 6.0)
    xyz = np.column_stack([x + X0, y + Y0, 200.0 + rise])
    slope = (rise > 0.3) & (rise < 5.7)
    plain = PTD(max_angle_deg=10.0, offset_m=0.0).run(xyz)
    mirrored = PTD(max_angle_deg=10.0, offset_m=0.0, mirror=True).run(xyz)
    assert mirrored.ground[slope].mean() > plain.ground[slope].mean() + 0.2
    assert mirrored.ground.mean() > 0.98


# --- degenerate inputs ----------------------------------------------------------------------

def test_duplicate_positions():
    """Points at the position of another: same height = ground, 5 m higher = not."""
    xyz, _ = plane_scene(seed=18, size=30.0)
    dup_same = xyz[:50].copy()
    dup_high = xyz[50:100].copy()
    dup_high[:, 2] += 5.0
    ground = PTD()(np.vstack([xyz, dup_same, dup_high]))
    n = len(xyz)
    assert ground[:n + 50].all() and not ground[n + 50:].any()


# --- the TIN kernels against oracles ---------------------------------------------------------------

def _circumcircle_holds(tri, x, y, tol=1e-9):
    """Whether any of the points lies strictly inside the circumcircle of triangle ``tri``."""
    a, b, c = tri
    ax, ay, bx, by, cx, cy = x[a], y[a], x[b], y[b], x[c], y[c]
    d = 2 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    ux = ((ax ** 2 + ay ** 2) * (by - cy) + (bx ** 2 + by ** 2) * (cy - ay) + (cx ** 2 + cy ** 2) * (ay - by)) / d
    uy = ((ax ** 2 + ay ** 2) * (cx - bx) + (bx ** 2 + by ** 2) * (ax - cx) + (cx ** 2 + cy ** 2) * (bx - ax)) / d
    r2 = (ax - ux) ** 2 + (ay - uy) ** 2
    inside = (x - ux) ** 2 + (y - uy) ** 2 < r2 * (1 - tol)
    inside[[a, b, c]] = False
    return inside.any()


@pytest.mark.parametrize("seed", range(4))
def test_triangulation_matches_scipy_delaunay(seed):
    from scipy.spatial import Delaunay
    rng = np.random.default_rng(seed)
    n = 300
    x, y = rng.uniform(0, 100, n), rng.uniform(0, 100, n)
    ours = {tuple(sorted(t)) for t in triangulate(x, y)}
    theirs = {tuple(sorted(t)) for t in Delaunay(np.column_stack([x, y])).simplices}
    assert ours <= theirs
    # What ours lacks: only flat triangles on the hull, whose circumcircle reaches the far
    # corners of the enclosing box.
    for t in theirs - ours:
        a, b, c = (np.array([x[i], y[i]]) for i in t)
        area = abs(np.cross(b - a, c - a)) / 2
        radius = np.linalg.norm(b - a) * np.linalg.norm(c - b) * np.linalg.norm(a - c) / (4 * area)
        assert radius > 500.0
    assert len(theirs - ours) <= 10


def test_triangulation_of_a_grid_and_of_duplicates():
    """Cocircular points (a grid) and repeated positions: a valid Delaunay triangulation,
    each position once, no flat triangle."""
    gx, gy = np.meshgrid(np.arange(8.0), np.arange(6.0))
    x = np.concatenate([gx.ravel(), gx.ravel()[:10]])
    y = np.concatenate([gy.ravel(), gy.ravel()[:10]])
    tris = triangulate(x, y)
    assert len(tris) == 2 * 7 * 5
    assert (tris < 48).all()  # the repeated positions are not vertices
    for t in tris:
        (ax, ay), (bx, by), (cx, cy) = ((x[i], y[i]) for i in t)
        assert (bx - ax) * (cy - ay) - (by - ay) * (cx - ax) > 0  # counter-clockwise, not flat
        assert not _circumcircle_holds(t, x[:48], y[:48])


def _tin(x, y, vertices):
    """A TIN of the given vertices inside a far box, with every other point in the list of the
    triangle holding it; returns the arrays."""
    n = x.size
    m = 10.0 * max(np.ptp(x), np.ptp(y))
    vx = np.concatenate([x, [x.min() - m, x.max() + m, x.max() + m, x.min() - m]])
    vy = np.concatenate([y, [y.min() - m, y.min() - m, y.max() + m, y.max() + m]])
    cap = 2 * (n + 4) + 16
    tv, tn = np.empty((cap, 3), np.int32), np.empty((cap, 3), np.int32)
    tstamp, head, dirty = np.empty(cap, np.int32), np.empty(cap, np.int32), np.empty(cap, np.int32)
    state, status, nxt = np.zeros(3, np.int64), np.zeros(n, np.uint8), np.empty(n, np.int32)
    T.init_box_kernel(tv, tn, tstamp, head, state, n, n + 1, n + 2, n + 3)
    status[vertices] = T.GROUND_VERTEX
    T.insert_vertices_kernel(tv, tn, tstamp, dirty, state, vx, vy, head, nxt, status,
                             np.asarray(vertices, np.int32), np.zeros(len(vertices), bool))
    T.fill_buckets_kernel(tv, tn, int(state[0]), vx, vy, n, status, head, nxt)
    return dict(tv=tv, tn=tn, tstamp=tstamp, head=head, dirty=dirty, state=state, status=status, nxt=nxt,
                vx=vx, vy=vy)


def _contains(tin, t, px, py, tol=1e-9):
    vx, vy, tv = tin["vx"], tin["vy"], tin["tv"]
    a, b, c = tv[t]
    o = [(vx[q] - vx[p]) * (py - vy[p]) - (vy[q] - vy[p]) * (px - vx[p]) for p, q in ((a, b), (b, c), (c, a))]
    return min(o) >= -tol


def test_point_location_matches_brute_force():
    rng = np.random.default_rng(20)
    x, y = rng.uniform(0, 50, 400), rng.uniform(0, 50, 400)
    tin = _tin(x, y, np.arange(400))
    qx, qy = rng.uniform(-5, 55, 2000), rng.uniform(-5, 55, 2000)
    found = np.empty(2000, np.int64)
    T.locate_kernel(tin["tv"], tin["tn"], int(tin["state"][0]), tin["vx"], tin["vy"], qx, qy, found)
    for k in range(2000):
        brute = T._locate_brute(tin["tv"], int(tin["state"][0]), tin["vx"], tin["vy"], qx[k], qy[k])
        assert found[k] >= 0 and _contains(tin, found[k], qx[k], qy[k])
        assert brute >= 0 and _contains(tin, brute, qx[k], qy[k])


def test_point_lists_follow_splits_and_flips():
    """Vertices inserted one by one with the lists active: every candidate stays in the list of
    a triangle holding it, exactly once, and the TIN is still Delaunay (checked by brute force)."""
    rng = np.random.default_rng(21)
    n = 1500
    x, y = np.round(rng.uniform(0, 40, n), 2), np.round(rng.uniform(0, 40, n), 2)  # cm, as real data
    tin = _tin(x, y, np.arange(50))
    stack = np.empty(4096, np.int32)
    for v in range(50, 700):
        tin["status"][v] = T.GROUND_VERTEX
        t = T._locate(tin["tv"], tin["tn"], tin["state"][0], tin["vx"], tin["vy"], 0, x[v], y[v])
        tin["state"][1] = 0
        tin["state"][2] += 1
        T._insert(tin["tv"], tin["tn"], tin["tstamp"], tin["dirty"], tin["state"], tin["vx"], tin["vy"],
                  tin["head"], tin["nxt"], tin["status"], v, t, stack)
    seen = np.zeros(n, int)
    ntri = int(tin["state"][0])
    for t in range(ntri):
        p = tin["head"][t]
        while p >= 0:
            if tin["status"][p] == T.CANDIDATE:
                seen[p] += 1
                assert _contains(tin, t, x[p], y[p])
            p = tin["nxt"][p]
    assert (seen[700:] == 1).all()
    real = tin["tv"][:ntri][(tin["tv"][:ntri] < n).all(axis=1)]
    for t in real[::7]:
        assert not _circumcircle_holds(t, x[:700], y[:700], tol=1e-7)


def test_axelsson_test_against_direct_geometry():
    """Distance to the plane and the largest angle to the vertices, computed directly."""
    rng = np.random.default_rng(22)
    for _ in range(200):
        tri = rng.uniform(0, 10, size=(3, 3))
        p = np.array([*tri[:, :2].mean(axis=0) + rng.uniform(-1, 1, 2), tri[:, 2].mean() + rng.uniform(-2, 2)])
        normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        if abs(normal[2]) < 1e-3:
            continue
        normal = normal / np.linalg.norm(normal) * np.sign(normal[2])
        d = float((p - tri[0]) @ normal)
        foot = p - d * normal
        angle = max(math.degrees(math.atan2(abs(d), np.linalg.norm(foot - v))) for v in tri)
        vx, vy, vz = (np.append(tri[:, k], 0.0) for k in range(3))
        for max_angle, max_dist in ((20.0, 1.0), (45.0, 3.0)):
            got = K._axelsson_test(vx, vy, vz, 0, 1, 2, p[0], p[1], p[2], math.tan(math.radians(max_angle)) ** 2,
                                   max_dist, np.inf, True)
            if d < 0:  # below: distance only
                expected = abs(d) <= max_dist
            else:
                expected = d <= max_dist and angle <= max_angle
            assert (got == got) == expected
            if expected:
                assert got == pytest.approx(d)


# --- parameters ---------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, name", [
    ({"seed_cell_m": 0}, "seed_cell_m"),
    ({"seed_cell_m": -5.0}, "seed_cell_m"),
    ({"seed_cell_m": math.nan}, "seed_cell_m"),
    ({"seed_cell_m": math.inf}, "seed_cell_m"),
    ({"seed_cell_m": "30"}, "seed_cell_m"),
    ({"max_angle_deg": 0.0}, "max_angle_deg"),
    ({"max_angle_deg": 90.0}, "max_angle_deg"),
    ({"max_angle_deg": math.nan}, "max_angle_deg"),
    ({"max_distance_m": 0.0}, "max_distance_m"),
    ({"max_distance_m": -1.0}, "max_distance_m"),
    ({"max_distance_m": None}, "max_distance_m"),
    ({"max_terrain_angle_deg": 0.0}, "max_terrain_angle_deg"),
    ({"max_terrain_angle_deg": 91.0}, "max_terrain_angle_deg"),
    ({"min_edge_m": -0.1}, "min_edge_m"),
    ({"min_edge_m": math.inf}, "min_edge_m"),
    ({"max_edge_m": -1.0}, "max_edge_m"),
    ({"max_edge_m": 2.0, "min_edge_m": 3.0}, "max_edge_m"),
    ({"offset_m": -0.1}, "offset_m"),
    ({"offset_m": math.nan}, "offset_m"),
    ({"mirror": 1}, "mirror"),
    ({"low_outlier_check": "yes"}, "low_outlier_check"),
    ({"seed_cell_m": 1e9}, "seed_cell_m must be at most 1000 m"),
    ({"low_outlier_support": 0.0}, "low_outlier_support"),
    ({"low_outlier_support": 1.5}, "low_outlier_support"),
    ({"low_outlier_support": math.nan}, "low_outlier_support"),
    ({"low_outlier_retry": 1}, "low_outlier_retry"),
])
def test_invalid_parameters_name_the_parameter(kwargs, name):
    with pytest.raises(InvalidParameterError) as info:
        PTD(**kwargs)
    assert name in str(info.value)


def test_valid_edge_parameters():
    PTD(max_angle_deg=0.5, max_terrain_angle_deg=90.0, min_edge_m=0.0, max_edge_m=0.0, offset_m=0.0)
    PTD(min_edge_m=1.0, max_edge_m=50.0, seed_cell_m=1, mirror=np.bool_(True))


def test_seed_cell_far_too_small_is_refused():
    xyz = np.array([[X0, Y0, 0.0], [X0 + 1e5, Y0 + 1e5, 0.0]])
    with pytest.raises(InvalidParameterError, match="seed_cell_m"):
        PTD(seed_cell_m=1.0)(xyz)


def test_defaults():
    p = PTD()
    assert (p.seed_cell_m, p.max_angle_deg, p.max_distance_m, p.max_terrain_angle_deg, p.min_edge_m,
            p.max_edge_m, p.offset_m, p.mirror, p.low_outlier_check, p.low_outlier_support, p.low_outlier_retry) == \
        (30.0, 30.0, 1.4, 75.0, 0.0, 0.0, 0.2, False, True, 0.4, True)
    assert PTD.name == "ptd"


# --- progress and cancellation ---------------------------------------------------------------

def test_progress_is_monotonic_and_complete():
    seen = []
    xyz, _ = plane_scene(box=BOX)
    res = PTD().run(xyz, Steps(progress=seen.append))
    assert all(0.0 <= f <= 1.0 for f in seen)
    assert all(b >= a for a, b in zip(seen, seen[1:])), seen
    assert seen[-1] == pytest.approx(1.0)
    assert len(seen) >= res.rounds  # one report per round at least


@pytest.mark.parametrize("after", [1, 3, 6])
def test_cancelled_midway(after):
    calls = {"n": 0}

    def is_cancelled():
        calls["n"] += 1
        return calls["n"] > after

    seen = []
    xyz, _ = plane_scene(box=BOX)
    with pytest.raises(Cancelled):
        PTD().run(xyz, Steps(progress=seen.append, is_cancelled=is_cancelled))
    assert len(seen) <= after  # stopped at the first check after the request
    assert not seen or seen[-1] < 1.0


def test_cancelled_during_the_rounds():
    """Cancellation is checked after every densification round."""
    xyz, _ = plane_scene(box=BOX)
    rounds = PTD().run(xyz).rounds
    assert rounds > 5
    calls = {"n": 0}

    def is_cancelled():
        calls["n"] += 1
        return calls["n"] > 8  # 4 reports before the rounds, then the rounds

    with pytest.raises(Cancelled):
        PTD().run(xyz, Steps(is_cancelled=is_cancelled))
    assert calls["n"] == 9


# --- real data: the ISPRS reference samples ---------------------------------------------------

ISPRS_SAMPLES = ("samp11", "samp21", "samp23", "samp31", "samp41", "samp51", "samp52", "samp54")
#: Axelsson's mean total error over the 15 samples (Sithole & Vosselman 2004, via the CSF paper's
#: Table 4; PUBLISHED_RESULTS.md) plus the issue's 1 point of slack.
AXELSSON_MEAN_TOTAL_PLUS_1 = 4.82 + 1.0


def test_isprs_default_parameters_mean_total_error():
    from groundsieve.core.io import read_cloud
    from groundsieve.core.metrics import ground_accuracy
    from groundsieve.tests.shared_data import shared_data_dir
    root = shared_data_dir(*[f"isprs/{s}.txt" for s in ISPRS_SAMPLES]) / "isprs"
    totals = {}
    for name in ISPRS_SAMPLES:
        cloud = read_cloud(str(root / f"{name}.txt"))
        totals[name] = 100 * ground_accuracy(cloud.reference_label == 0, PTD()(cloud.xyz)).total
    mean = float(np.mean(list(totals.values())))
    assert mean <= AXELSSON_MEAN_TOTAL_PLUS_1, \
        f"mean total error {mean:.2f} % > {AXELSSON_MEAN_TOTAL_PLUS_1} %; per sample: " + \
        ", ".join(f"{k} {v:.2f}" for k, v in totals.items())
