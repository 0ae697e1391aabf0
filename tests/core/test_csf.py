"""CSF (core.filters.csf) on generated scenes with known truth, its validation, progress and
cancellation, and the behaviour of its kernels against the reference implementation."""
from __future__ import annotations

import math

import numpy as np
import pytest

from groundsieve.core.filters.csf import CSF, CSFResult
from groundsieve.core.errors import Cancelled, InvalidParameterError
from groundsieve.core.progress import Steps
from groundsieve.tests.core.scenes import BOX, X0, Y0, add_trees, plane_scene


def hill_scene(height=10.0, radius=40.0, size=200.0, spacing=2.4, seed=0):
    """A bare, smooth, convex hill (z = 100 + height * cos²(pi r / 2 radius) within ``radius``)
    on a flat plain, sampled uniformly at random with a mean spacing of ``spacing`` metres
    (2.4 m: the ISPRS rural samples). Every point is ground; returns xyz and 'on the hill'."""
    rng = np.random.default_rng(seed)
    n = int(size * size / spacing ** 2)
    x = rng.uniform(0.0, size, n)
    y = rng.uniform(0.0, size, n)
    r = np.hypot(x - size / 2, y - size / 2)
    z = 100.0 + np.where(r < radius, height * np.cos(np.pi * r / (2 * radius)) ** 2, 0.0)
    return np.column_stack([x + X0, y + Y0, z]), r < radius


@pytest.mark.parametrize("tilt", [(0.0, 0.0), (0.1, 0.05), (-0.08, 0.06)], ids=["flat", "tilted", "tilted2"])
def test_plane_is_all_ground(tilt):
    xyz, _ = plane_scene(tilt=tilt)
    ground = CSF()(xyz)
    assert ground.dtype == bool and ground.shape == (xyz.shape[0],)
    assert ground.all()


@pytest.mark.parametrize("rigidness", [1, 2, 3])
@pytest.mark.parametrize("tilt", [(0.0, 0.0), (0.05, 0.02)], ids=["flat", "tilted"])
def test_box_on_plane_is_object_and_plane_is_ground(tilt, rigidness):
    xyz, truth = plane_scene(tilt=tilt, box=BOX)
    ground = CSF(rigidness=rigidness)(xyz)
    np.testing.assert_array_equal(ground, truth)


def test_box_at_the_papers_isprs_settings():
    xyz, truth = plane_scene(seed=1, tilt=(0.03, -0.02), box=BOX)
    ground = CSF(cloth_resolution_m=0.5, rigidness=2)(xyz)
    np.testing.assert_array_equal(ground, truth)


def test_trees_are_never_ground():
    """Scattered 'tree' points several metres above a plane are never ground."""
    xyz, truth = plane_scene(seed=3, tilt=(0.05, -0.03), box=BOX)
    xyz, truth = add_trees(xyz, truth, n=40, seed=4, tilt=(0.05, -0.03))
    ground = CSF()(xyz)
    assert not (ground & ~truth).any(), "an object point was called ground"
    assert ground[truth].mean() > 0.99


# --- the convex hill at sparse spacing ---------------------------------------------------------
#
# Issue 4: at ISPRS rural spacing (about 2.4 m) the authors' CSF leaves the cloth hanging below
# convex hilltops and loses 28-56 % of the ground points of a bare smooth hill at every rigidness.
# On this 10 m high, 80 m wide hill, measured here (the library: cloth-simulation-filter 1.1.7):
#
#   points of the hill called object, %   library 1.1.7   ours, "cell"   ours, default ("nearest")
#   0.5 m, rigidness 1, smoothing on / off    58 / 64          58 / 64          8 / 29
#   0.5 m, rigidness 2, smoothing on / off    59 / 65          59 / 65         34 / 42
#   0.5 m, rigidness 3, smoothing on / off    60 / 66          59 / 65         34 / 44
#   1 m (default), any rigidness              61-70            61-70           54-66
#
# The cloth is stiff by design (it must bridge buildings): it hangs over any (inverted) basin more
# curved than gravity / stiffness allows, and a convex hill is such a basin. What rescues the
# hill is the slope post-processing, which pins the hanging cloth onto the surface while
# neighbouring particle heights differ by less than 0.3 m. With the library's particle heights
# (the points rounding to a particle, empty particles filled from the east) the heights of the
# sparse cloud are steps of a whole point spacing and the smoothing stops at the first one. With
# the paper's nearest-point heights they are steps too (where the nearest point changes: slope x
# about 2.4 m, up to 0.9 m on the flanks, which are 39 % steep at mid-height), but the softest cloth
# (rigidness 1) sags by itself past the steep mid-flank, and from there the smoothing goes up to
# the top: 8 % lost instead of 58 %. The stiffer cloths hang from lower on the flanks, where the
# steps stop the smoothing; at 1 m the cloth is stiffer still (the same per-particle stiffness over
# twice the distance). So the weakness is beaten only with the paper's ISPRS resolution and
# steep-slope settings; elsewhere ours loses less than the library but still a third or more.


def test_sparse_convex_hill_steep_slope_settings_keep_the_hill():
    xyz, on_hill = hill_scene()
    ground = CSF(cloth_resolution_m=0.5, rigidness=1, slope_smooth=True)(xyz)
    lost = 1.0 - ground[on_hill].mean()
    assert lost < 0.12, f"{100 * lost:.1f} % of the hill's ground points lost"
    assert ground[~on_hill].mean() > 0.99


def test_sparse_convex_hill_2016_scheme_is_softer():
    """The 2016 constraint scheme (pinned particles pull only their W, SW, S and SE neighbours)
    sags further over the hill: 1 % lost at the steep-slope settings (library scheme 5 %), and
    less than the library scheme at the stiffer settings too (0.5 m, rigidness 2: 14 % vs 34 %)."""
    xyz, on_hill = hill_scene()
    lost = {}
    for scheme in ("library", "2016"):
        for rigidness in (1, 2):
            ground = CSF(cloth_resolution_m=0.5, rigidness=rigidness, constraint_scheme=scheme)(xyz)
            lost[scheme, rigidness] = 1.0 - ground[on_hill].mean()
    assert lost["2016", 1] < 0.03, lost
    assert lost["2016", 2] < lost["library", 2] - 0.1, lost


def test_sparse_convex_hill_reference_heights_lose_the_hilltop():
    """The reference library's behaviour, reproduced by intersection_height='cell'."""
    xyz, on_hill = hill_scene()
    ground = CSF(cloth_resolution_m=0.5, rigidness=1, slope_smooth=True, intersection_height="cell")(xyz)
    lost = 1.0 - ground[on_hill].mean()
    assert lost > 0.5, f"only {100 * lost:.1f} % lost: the reference-compatible mode changed"


def test_sparse_convex_hill_flat_settings_hang_below_the_top():
    """Rigidness 3 without smoothing (the paper's flat-scene settings) still loses the hilltop:
    the cloth's stiffness, not a bug; 44 % here (library: 66 %; 28-56 % in the issue)."""
    xyz, on_hill = hill_scene()
    res = CSF(cloth_resolution_m=0.5, rigidness=3, slope_smooth=False).run(xyz)
    lost = 1.0 - res.ground[on_hill].mean()
    assert 0.2 < lost < 0.6
    top = np.abs(xyz[:, 0] - X0 - 100.0) + np.abs(xyz[:, 1] - Y0 - 100.0) < 5.0
    assert not res.ground[top].any(), "the cloth reached the hilltop"


# --- low outliers ------------------------------------------------------------------------------

def test_low_outliers_are_not_ground_and_do_not_pin_the_cloth():
    xyz, _ = plane_scene(seed=5)
    low = np.array([10, 500, 2000, 4000, 6000])
    xyz[low, 2] -= np.array([20.0, 30.0, 45.0, 25.0, 60.0])
    res = CSF().run(xyz)
    assert res.low_outliers[low].all() and res.low_outliers.sum() == len(low)
    assert not res.ground[low].any()
    rest = np.ones(len(xyz), dtype=bool)
    rest[low] = False
    assert res.ground[rest].all()


def test_without_the_outlier_step_a_low_outlier_pins_a_tent():
    """The reference's behaviour (low_outlier_m=0): the outlier pins the cloth far below the
    ground and the ground points around it are lost."""
    xyz, _ = plane_scene(seed=5)
    xyz[500, 2] -= 30.0
    res = CSF(low_outlier_m=0.0).run(xyz)
    assert not res.low_outliers.any()
    near = np.hypot(xyz[:, 0] - xyz[500, 0], xyz[:, 1] - xyz[500, 1]) < 2.0
    assert not res.ground[near].all()


def test_a_pit_is_not_an_outlier():
    """A 3 m deep, 10 m wide pit is terrain, not a low outlier (the test needs 5 m)."""
    xyz, _ = plane_scene(seed=6)
    pit = np.hypot(xyz[:, 0] - X0 - 30.0, xyz[:, 1] - Y0 - 30.0) < 5.0
    xyz[pit, 2] -= 3.0
    res = CSF(rigidness=1).run(xyz)
    assert not res.low_outliers.any()


# --- the result ----------------------------------------------------------------------------------

def test_result_fields():
    xyz, truth = plane_scene(box=BOX)
    res = CSF().run(xyz)
    assert isinstance(res, CSFResult)
    np.testing.assert_array_equal(res.ground, CSF()(xyz))
    assert res.cloth.shape == res.grid.shape == res.pinned.shape
    assert res.grid.cell == 1.0
    # Cell centres on the particles: two particles beyond the points on the west and south.
    xs, ys = res.grid.centers()
    assert xs[0] == pytest.approx(xyz[:, 0].min() - 2.0)
    assert ys[-1] == pytest.approx(xyz[:, 1].min() - 2.0)
    assert xs[-1] >= xyz[:, 0].max() and ys[0] >= xyz[:, 1].max()
    # The cloth lies on the plane and bridges the box; it is pinned off the box.
    np.testing.assert_allclose(res.cloth, 100.0, atol=0.1)
    assert res.pinned.mean() > 0.8
    assert 1 <= res.iterations < 500


def test_cloth_follows_a_tilted_plane():
    xyz, _ = plane_scene(seed=2, tilt=(0.1, 0.05))
    res = CSF().run(xyz)
    xs, ys = res.grid.centers()
    expected = 100.0 + 0.1 * (xs[None, :] - X0) + 0.05 * (ys[:, None] - Y0)
    inside = ((xs[None, :] > X0 + 2) & (xs[None, :] < X0 + 58) & (ys[:, None] > Y0 + 2) & (ys[:, None] < Y0 + 58))
    assert np.abs(res.cloth - expected)[inside].max() < 0.2


def test_point_order_does_not_matter():
    xyz, _ = plane_scene(seed=8, tilt=(0.05, 0.02), box=BOX)
    xyz[::37, 2] += 3.0
    perm = np.random.default_rng(9).permutation(len(xyz))
    for mode in ("nearest", "cell"):
        a = CSF(intersection_height=mode)(xyz)
        b = CSF(intersection_height=mode)(xyz[perm])
        np.testing.assert_array_equal(a[perm], b)


def test_tiny_time_step_stops_after_one_iteration_as_the_reference():
    """The reference stops as soon as no particle moved more than 5 mm in an iteration: with
    time_step 0.35 the gravity step (0.2 * 0.35**4 = 3 mm) is below that from the start."""
    xyz, _ = plane_scene(size=20.0)
    xyz[:, 2] += np.random.default_rng(0).uniform(0, 2, len(xyz))
    assert CSF(time_step=0.35).run(xyz).iterations == 1
    assert CSF().run(xyz).iterations > 1


# --- kernels against the reference's semantics --------------------------------------------------

@pytest.mark.parametrize("shape", [(9, 13), (12, 12)], ids=["9x13", "12x12"])
def test_each_rotating_sweep_is_the_reference_sweep_on_the_turned_cloth(shape):
    """sweep_order='rotating' cycles through 8 sweeps; sweep g over the cloth must be, bit for
    bit, the reference sweep over the cloth transformed by g (mirrored and/or turned), so that
    turning the cloud only changes which of the 8 comes first."""
    from groundsieve.core.filters import _csf_cloth as cloth
    from groundsieve.core.filters.csf import sweeps
    H, W = shape
    rng = np.random.default_rng(8)
    hv = -(100.0 + rng.uniform(0, 3, (H, W)))
    start = float(hv.max()) + 0.3
    acc = -0.2 * 0.65 ** 4
    index = np.arange(W * H).reshape(H, W)

    def simulate(hv2d, neighbours=None, flags=()):
        h, w = hv2d.shape
        pos = np.full(h * w, start)
        old = pos.copy()
        movable = np.ones(h * w, dtype=bool)
        quiet = np.zeros(h * w, dtype=bool)
        extra = () if neighbours is None else (neighbours, *flags)
        for _ in range(40):
            cloth._time_step_kernel(pos, old, movable, quiet, hv2d.ravel().copy(), w, h, acc, 0.51, 0.42, *extra)
        return pos, movable

    orders = sweeps()
    assert len(orders) == 8
    seen = set()
    for g, (neighbours, flags) in enumerate(orders):
        mirror, turns = divmod(g, 4)
        transform = lambda a: np.rot90(a[:, ::-1] if mirror else a, turns)  # noqa: E731
        ours_pos, ours_mov = simulate(hv, neighbours, flags)
        ref_pos, ref_mov = simulate(np.ascontiguousarray(transform(hv)))
        back = transform(index).ravel()  # G index of each particle of the turned cloth
        expect_pos = np.empty(W * H)
        expect_pos[back] = ref_pos
        expect_mov = np.empty(W * H, dtype=bool)
        expect_mov[back] = ref_mov
        np.testing.assert_array_equal(ours_pos, expect_pos)
        np.testing.assert_array_equal(ours_mov, expect_mov)
        assert 0 < ours_mov.sum() < W * H  # some particles pinned, some not: a real test
        seen.add(ours_pos.tobytes())
    assert len(seen) == 8  # eight different results: the order matters, hence the cycle


def test_rotating_and_fixed_sweeps_on_the_box_scene():
    xyz, truth = plane_scene(tilt=(0.05, 0.02), box=BOX)
    res = CSF().run(xyz)
    assert res.iterations < 500
    np.testing.assert_array_equal(res.ground, truth)
    fixed = CSF(sweep_order="fixed").run(xyz)
    np.testing.assert_array_equal(fixed.ground, truth)


def test_rotating_sweep_runs_the_eight_orders_in_turn(monkeypatch):
    """CSF.run with the default sweep calls the kernel with sweeps()[0], [1], ..., [7], [0], ...
    from the first iteration after the free fall, and stops only after whole cycles."""
    from groundsieve.core.filters import _csf_cloth as cloth
    from groundsieve.core.filters.csf import sweeps
    seen = []
    real = cloth._time_step_kernel

    def recording(*args):
        seen.append(None if len(args) == 10 else (args[10].tobytes(), tuple(args[11:])))
        return real(*args)

    monkeypatch.setattr(cloth, "_time_step_kernel", recording)
    xyz, _ = plane_scene(tilt=(0.05, 0.02), box=BOX)
    res = CSF().run(xyz)
    orders = [(n.tobytes(), tuple(f)) for n, f in sweeps()]
    assert len(set(orders)) == 8
    assert len(seen) > 8 and len(seen) % 8 == 0 and res.iterations < 500
    assert seen == [orders[i % 8] for i in range(len(seen))]
    seen.clear()
    CSF(sweep_order="fixed").run(xyz)
    assert seen and all(s is None for s in seen)  # the reference's own order, its defaults


def test_free_fall_shortcut_is_exactly_the_simulation():
    from groundsieve.core.filters import _csf_cloth as cloth
    rng = np.random.default_rng(1)
    W, H = 30, 20
    hv = -(100.0 + rng.uniform(0, 8, W * H))
    acc = -0.2 * 0.65 ** 4
    start = float(hv.max()) + 40.0  # the cloth starts well above: a long free fall
    results = []
    for shortcut in (True, False):
        pos = np.full(W * H, start)
        old = pos.copy()
        movable = np.ones(W * H, dtype=bool)
        quiet = np.zeros(W * H, dtype=bool)
        done = 0
        if shortcut:
            done, stopped = cloth._free_fall_kernel(pos, old, hv, acc, 300, 0.005)
            assert done > 10 and not stopped and movable.all()
        while done < 300:
            md, _ = cloth._time_step_kernel(pos, old, movable, quiet, hv, W, H, acc, 0.3, 0.3)
            done += 1
            if md != 0 and md < 0.005:
                break
        results.append((pos.copy(), movable.copy(), done))
    np.testing.assert_array_equal(results[0][0], results[1][0])
    np.testing.assert_array_equal(results[0][1], results[1][1])
    assert results[0][2] == results[1][2]


def test_scanline_fill_follows_the_reference_order():
    from groundsieve.core.filters import _csf_terrain as terrain
    W, H = 6, 5
    has = np.zeros(W * H, dtype=bool)
    hv = np.full(W * H, -np.inf)
    for (c, r, v) in [(4, 2, 1.0), (1, 2, 2.0), (0, 4, 3.0), (5, 0, 4.0)]:
        has[r * W + c] = True
        hv[r * W + c] = v
    out = terrain._scanline_fill_kernel(hv, has, W, H)
    grid = out.reshape(H, W)
    assert grid[2, 0] == 2.0 and grid[2, 2] == 1.0 and grid[2, 5] == 1.0  # east first, then west
    assert grid[4, 1] == 3.0 and grid[4, 5] == 3.0    # west when nothing to the east
    assert grid[1, 4] == 1.0                            # then south along the column ...
    assert grid[3, 5] == 4.0                            # ... and north when nothing south
    assert grid[0, 0] == 4.0
    assert np.isfinite(out).all()


def test_nearest_heights_are_the_nearest_point():
    from scipy.spatial import cKDTree

    from groundsieve.core.filters import _csf_terrain as terrain
    rng = np.random.default_rng(3)
    x, y = rng.uniform(0, 30, 200), rng.uniform(0, 20, 200)
    z = rng.uniform(0, 5, 200)
    res, W, H = 0.5, 64, 44
    ox, oy = -1.0, -1.0
    hv = np.full(W * H, -np.inf)
    found = np.zeros(W * H, dtype=bool)
    terrain._nearest_heights_kernel(x, y, z, np.ones(200, dtype=bool), ox, oy, res, W, H, 100, hv, found)
    assert found.all()
    gx, gy = np.meshgrid(ox + np.arange(W) * res, oy + np.arange(H) * res)
    _, idx = cKDTree(np.column_stack([x, y])).query(np.column_stack([gx.ravel(), gy.ravel()]))
    np.testing.assert_array_equal(hv, -z[idx])


def test_matches_the_reference_library_when_installed():
    """intersection_height='cell' without the outlier step is the library 1.1.7 (bench only)."""
    lib = pytest.importorskip("CSF")
    xyz, _ = plane_scene(seed=11, density=1.0, tilt=(0.05, -0.02), box=BOX)
    xyz[::13, 2] += np.random.default_rng(2).uniform(0.5, 8.0, len(xyz[::13]))
    c = lib.CSF()
    c.params.cloth_resolution = 0.5
    c.params.rigidness = 2
    c.setPointCloud(np.ascontiguousarray(xyz))
    ground_idx, other_idx = lib.VecInt(), lib.VecInt()
    c.do_filtering(ground_idx, other_idx, False)
    theirs = np.zeros(len(xyz), dtype=bool)
    theirs[np.array(ground_idx, dtype=np.int64)] = True
    ours = CSF(cloth_resolution_m=0.5, rigidness=2, intersection_height="cell", low_outlier_m=0.0,
               sweep_order="fixed", cloth_origin="cloud")(xyz)
    assert (ours == theirs).mean() > 0.995


# --- the 2016 code's constraint scheme -------------------------------------------------------

def _one_2016_step(W, H, pinned_at, passes=1):
    """A flat cloth at height 1 with one pinned particle at height 0 (row-major ``pinned_at``),
    no gravity: one iteration of the 2016 kernel. Returns the heights, row-major (H, W)."""
    from groundsieve.core.filters import _csf_cloth as cloth
    pos = np.ones(W * H)
    movable = np.ones(W * H, dtype=bool)
    pos[pinned_at] = 0.0
    movable[pinned_at] = False
    hv = np.full(W * H, -np.inf)
    t = lambda a: np.ascontiguousarray(a.reshape(H, W).T).ravel()  # noqa: E731 (column-major)
    pos_c, mov_c = t(pos), t(movable)
    cloth._time_step_2016_kernel(pos_c, pos_c.copy(), mov_c, t(hv), W, H, 0.0, passes)
    return pos_c.reshape(W, H).T


def test_2016_scheme_a_pinned_particle_pulls_only_the_neighbours_that_list_it_second():
    """The 2016 code moves a pair only when its first particle (the west, south or south-west
    one; the south-east end of the anti-diagonal) is movable. On a flat 3 x 3 cloth without
    gravity, a particle pinned below it at the south-west corner therefore moves nothing (it is
    every pair's first particle), while at the north-east corner it pulls its three neighbours;
    the library's scheme pulls them in both cases."""
    from groundsieve.core.filters import _csf_cloth as cloth
    sw = _one_2016_step(3, 3, 0)
    assert (np.delete(sw.ravel(), 0) == 1.0).all()
    ne = _one_2016_step(3, 3, 8)
    assert ne[2, 1] < 1.0 and ne[1, 2] < 1.0 and ne[1, 1] < 1.0
    for pinned_at in (0, 8):
        pos = np.ones(9)
        pos[pinned_at] = 0.0
        movable = np.ones(9, dtype=bool)
        movable[pinned_at] = False
        cloth._time_step_kernel(pos, pos.copy(), movable, np.zeros(9, dtype=bool), np.full(9, -np.inf),
                            3, 3, 0.0, 0.3, 0.3)
        assert (np.delete(pos, pinned_at) < 1.0).all()


def _reference_2016_step(pos, old, movable, hv, W, H, acceleration, passes):
    """One iteration of the 2016 code written plainly from its description (row-major arrays):
    the Verlet step; ``passes`` passes over the constraint list in the order the 2016 Cloth
    constructor builds it, each Constraint::satisfyConstraint moving p1 by 0.3 of the gap when p1
    is movable and then p2 back by as much when p1 and p2 are; the collision."""
    pairs = []
    for dist in (1, 2):
        for x in range(W):
            for y in range(H):
                if x < W - dist:
                    pairs.append((y * W + x, y * W + x + dist))
                if y < H - dist:
                    pairs.append((y * W + x, (y + dist) * W + x))
                if x < W - dist and y < H - dist:
                    pairs.append((y * W + x, (y + dist) * W + x + dist))
                    pairs.append((y * W + x + dist, (y + dist) * W + x))
    for p in range(W * H):
        if movable[p]:
            pos[p], old[p] = pos[p] + (pos[p] - old[p]) * 0.99 + acceleration, pos[p]
    for _ in range(passes):
        for a, b in pairs:
            if movable[a]:
                d = (pos[b] - pos[a]) * 0.3
                pos[a] += d
                if movable[b]:
                    pos[b] -= d
    for p in range(W * H):
        if movable[p] and pos[p] < hv[p]:
            pos[p] = hv[p]
            movable[p] = False


@pytest.mark.parametrize("W, H, passes", [(7, 4, 1), (4, 9, 2), (6, 6, 3), (1, 5, 3), (5, 1, 2)])
def test_2016_kernel_is_the_plain_constraint_list(W, H, passes):
    """The column-major numba kernel against the plain constraint list, bit for bit, over 25
    iterations with particles pinned along the way."""
    from groundsieve.core.filters import _csf_cloth as cloth
    rng = np.random.default_rng(W * 100 + H)
    hv = rng.uniform(-0.4, 0.2, W * H)
    pos = rng.uniform(0.0, 0.3, W * H)
    old = pos + rng.uniform(0.0, 0.05, W * H)
    movable = rng.random(W * H) > 0.25
    pos[~movable] = hv[~movable] - 0.2  # pinned ones lie low and pull the others down onto theirs
    ref = [pos.copy(), old.copy(), movable.copy()]
    t = lambda a: a.reshape(H, W).T.copy().ravel()  # noqa: E731 (column-major, always a copy)
    ours = [t(pos), t(old), t(movable)]
    hv_c = t(hv)
    moving_after_first = 0
    for i in range(25):
        _reference_2016_step(*ref, hv, W, H, -0.036, passes)
        cloth._time_step_2016_kernel(ours[0], ours[1], ours[2], hv_c, W, H, -0.036, passes)
        if i == 0:
            moving_after_first = int(ref[2].sum())
    back = lambda a: np.ascontiguousarray(a.reshape(W, H).T).ravel()  # noqa: E731
    np.testing.assert_array_equal(back(ours[0]), ref[0])
    np.testing.assert_array_equal(back(ours[2]), ref[2])
    assert ref[2].sum() < movable.sum()  # particles were pinned on the way
    assert moving_after_first > 0      # and others still moved after the first iteration


def test_2016_scheme_one_pair_closes_three_tenths_of_the_gap():
    """Two particles, the west one movable at 1, the east one pinned at 0: one pass moves the
    west one to 0.7; rigidness 3 (three passes) to 1 - 0.7**3."""
    assert _one_2016_step(2, 1, 1)[0, 0] == pytest.approx(0.7)
    assert _one_2016_step(2, 1, 1, passes=3)[0, 0] == pytest.approx(0.7 ** 3)
    assert _one_2016_step(2, 1, 0)[0, 1] == 1.0  # pinned west particle: the east one stays


@pytest.mark.parametrize("rigidness", [1, 2, 3])
def test_2016_scheme_box_on_plane(rigidness):
    xyz, truth = plane_scene(tilt=(0.05, 0.02), box=BOX)
    res = CSF(rigidness=rigidness, constraint_scheme="2016").run(xyz)
    np.testing.assert_array_equal(res.ground, truth)
    assert res.iterations < 500  # the same early stop


def test_2016_scheme_plane_is_all_ground():
    xyz, _ = plane_scene(tilt=(-0.08, 0.06))
    assert CSF(cloth_resolution_m=0.5, constraint_scheme="2016")(xyz).all()


def test_2016_scheme_reproduces_the_published_isprs_figures():
    """Zhang et al. (2016) Table 3 with the paper's per-group parameters: the issue's target,
    every sample within 1.5 points of the published total error and the mean within 0.5 (the
    2016 scheme; the library scheme misses it, see docs/BENCHMARKS.md). The cloth starts at the
    cloud's corner, as in the paper's code (cloth_origin="cloud"): moved onto whole metres the
    same cloth gives samp23 6.20 % and samp41 7.38 %, the placement alone moving a sample by up
    to 2 points (docs/BENCHMARKS.md, "Seams of EVC, CSF and PTD")."""
    from groundsieve.core.io import read_cloud
    from groundsieve.core.metrics import ground_accuracy
    from groundsieve.tests.shared_data import shared_data_dir
    published = {"samp11": 12.01, "samp21": 3.42, "samp23": 4.79, "samp31": 1.61, "samp41": 5.14,
                 "samp51": 3.08, "samp52": 3.93, "samp54": 3.18}
    groups = {"samp11": (2, True), "samp21": (3, False), "samp23": (2, True), "samp31": (3, False),
              "samp41": (2, True), "samp51": (3, False), "samp52": (1, True), "samp54": (3, False)}
    root = shared_data_dir(*[f"isprs/{s}.txt" for s in published]) / "isprs"
    ours = {}
    for name, (rigidness, smooth) in groups.items():
        cloud = read_cloud(str(root / f"{name}.txt"))
        f = CSF(cloth_resolution_m=0.5, rigidness=rigidness, slope_smooth=smooth, constraint_scheme="2016",
                cloth_origin="cloud")
        ours[name] = 100 * ground_accuracy(cloud.reference_label == 0, f(cloud.xyz)).total
    report = ", ".join(f"{k} {v:.2f} (published {published[k]})" for k, v in ours.items())
    assert all(abs(ours[k] - published[k]) <= 1.5 for k in published), report
    assert abs(np.mean(list(ours.values())) - np.mean(list(published.values()))) <= 0.5, report


# --- degenerate inputs ----------------------------------------------------------------------

def test_too_fine_a_cloth_is_refused():
    xyz = np.array([[X0, Y0, 0.0], [X0 + 20000.0, Y0 + 20000.0, 0.0]])
    with pytest.raises(InvalidParameterError, match="cloth_resolution_m"):
        CSF(cloth_resolution_m=0.5)(xyz)


# --- parameters ---------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, name", [
    ({"cloth_resolution_m": 0}, "cloth_resolution_m"),
    ({"cloth_resolution_m": -1.0}, "cloth_resolution_m"),
    ({"cloth_resolution_m": math.nan}, "cloth_resolution_m"),
    ({"cloth_resolution_m": math.inf}, "cloth_resolution_m"),
    ({"cloth_resolution_m": "1"}, "cloth_resolution_m"),
    ({"rigidness": 0}, "rigidness"),
    ({"rigidness": 4}, "rigidness"),
    ({"rigidness": 2.5}, "rigidness"),
    ({"rigidness": None}, "rigidness"),
    ({"time_step": 0.0}, "time_step"),
    ({"time_step": -0.65}, "time_step"),
    ({"time_step": math.nan}, "time_step"),
    ({"class_threshold_m": 0.0}, "class_threshold_m"),
    ({"class_threshold_m": -0.5}, "class_threshold_m"),
    ({"class_threshold_m": math.inf}, "class_threshold_m"),
    ({"iterations": 0}, "iterations"),
    ({"iterations": 10.5}, "iterations"),
    ({"iterations": math.inf}, "iterations"),
    ({"slope_smooth": "yes"}, "slope_smooth"),
    ({"slope_smooth_height_m": 0.0}, "slope_smooth_height_m"),
    ({"low_outlier_m": -1.0}, "low_outlier_m"),
    ({"low_outlier_m": math.nan}, "low_outlier_m"),
    ({"intersection_height": "kdtree"}, "intersection_height"),
    ({"constraint_scheme": "2017"}, "constraint_scheme"),
    ({"sweep_order": "random"}, "sweep_order"),
])
def test_invalid_parameters_name_the_parameter(kwargs, name):
    with pytest.raises(InvalidParameterError) as info:
        CSF(**kwargs)
    assert name in str(info.value)


def test_defaults_are_the_reference_implementations():
    c = CSF()
    assert (c.cloth_resolution_m, c.rigidness, c.time_step, c.class_threshold_m, c.iterations, c.slope_smooth) == \
        (1.0, 3, 0.65, 0.5, 500, True)
    assert c.slope_smooth_height_m == 0.3
    assert c.gravity_step_m == pytest.approx(0.2 * 0.65 ** 4)
    assert CSF.name == "csf"


def test_valid_edge_parameters():
    CSF(rigidness=1, iterations=1, low_outlier_m=0.0, class_threshold_m=0.01, slope_smooth=False)
    CSF(rigidness=np.int64(2), cloth_resolution_m=np.float32(0.5), iterations=np.int32(10))


# --- progress and cancellation ---------------------------------------------------------------

def test_progress_is_monotonic_and_complete():
    seen = []
    xyz, _ = plane_scene(box=BOX)
    res = CSF().run(xyz, Steps(progress=seen.append))
    assert all(0.0 <= f <= 1.0 for f in seen)
    assert all(b >= a for a, b in zip(seen, seen[1:])), seen
    assert seen[-1] == pytest.approx(1.0)
    assert len(seen) >= res.iterations // 2  # about one report per iteration


@pytest.mark.parametrize("after", [3, 10, 40])
def test_cancellation_stops_within_one_iteration(after, monkeypatch):
    """Cancel once ``after`` iterations have run: no further iteration starts."""
    from groundsieve.core.filters import _csf_cloth as cloth
    calls = {"n": 0}
    real = cloth._time_step_kernel

    def counting(*args):
        calls["n"] += 1
        return real(*args)

    monkeypatch.setattr(cloth, "_time_step_kernel", counting)
    xyz, _ = plane_scene(seed=4, tilt=(0.2, 0.1), size=80.0)  # a long fall: many iterations
    assert CSF().run(xyz).iterations > 45
    calls["n"] = 0
    with pytest.raises(Cancelled):
        CSF().run(xyz, Steps(is_cancelled=lambda: calls["n"] >= after))
    assert calls["n"] == after


# --- the cloth's start height (tiles) ----------------------------------------------------------

def test_cloth_start_z_sets_the_height_the_cloth_falls_from():
    """None (the reference) falls from just above the lowest point; the same height given is the
    same run; a lower z (a survey's lowest point outside this tile) makes a longer fall."""
    xyz, _ = plane_scene(seed=4, density=1.0, tilt=(0.05, 0.0), box=BOX)
    ref = CSF().run(xyz)
    same = CSF(cloth_start_z=float(xyz[:, 2].min())).run(xyz)
    np.testing.assert_array_equal(same.ground, ref.ground)
    assert same.iterations == ref.iterations
    assert CSF(cloth_start_z=float(xyz[:, 2].min()) - 30.0).run(xyz).iterations > ref.iterations
    assert CSF(cloth_start_z="12.5").cloth_start_z == 12.5  # the command line gives text
    for bad in (float("nan"), "low", float("inf")):
        with pytest.raises(InvalidParameterError, match="cloth_start_z"):
            CSF(cloth_start_z=bad)


def test_cloth_origin_places_the_particles():
    """"grid" (default): particles on multiples of the cloth resolution, shared by a tile and its
    survey; "cloud": from the lowest corner, the reference's placement."""
    xyz, _ = plane_scene(seed=4, density=1.0, box=BOX)
    xyz[:, :2] += 0.37  # the corner off whole metres
    xmin = float(xyz[:, 0].min())
    grid, cloud = CSF().run(xyz).grid, CSF(cloth_origin="cloud").run(xyz).grid
    first_grid, first_cloud = grid.x0 + grid.cell / 2, cloud.x0 + cloud.cell / 2  # first particle
    assert abs(first_grid - round(first_grid)) < 1e-6 and first_grid <= xmin
    assert abs(first_cloud - (xmin - 2 * cloud.cell)) < 1e-6
    assert abs(first_grid - first_cloud) > 0.3
