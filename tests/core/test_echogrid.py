"""The return-number grid filter (core.filters.echogrid, Matrone et al. 2024 Method 2): numpy oracles of
the faithful and the evidence rules on random clouds with random return numbers, known answers
on small built scenes (plane, building, tree, a stepped kernel of single returns), clouds without
return information, the result counts, validation, and the driver passing the return arrays of
the selected points only."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from groundsieve.core.filters.echogrid import MODES, EchoGrid, EchoGridResult
from groundsieve.core.errors import InvalidParameterError
from groundsieve.core.io import PointCloud
from groundsieve.core.progress import Steps
from groundsieve.core.engine.workflow import FilterOptions, classify_cloud

X0, Y0 = 512000.0, 5403000.0  # UTM-sized coordinates, as real data


# --- numpy oracles ----------------------------------------------------------------------------

def _kernels(xyz, kernel):
    """Column, row and flat index of the kernel of every point, kernels on multiples of the kernel
    size (the first holding min x / min y)."""
    x, y = xyz[:, 0], xyz[:, 1]
    x0, y0 = np.floor(x.min() / kernel) * kernel, np.floor(y.min() / kernel) * kernel
    col = np.floor((x - x0) / kernel).astype(np.int64)
    row = np.floor((y - y0) / kernel).astype(np.int64)
    nx, ny = int(col.max()) + 1, int(row.max()) + 1
    return col, row, row * nx + col, nx, ny


def oracle_faithful(xyz, rn, nr, kernel, dz):
    """The paper's rule: ground if z <= lowest z of the kernel + dz, or every point of the kernel
    has return number 1 (only when the cloud holds return information at all)."""
    z = xyz[:, 2]
    _, _, k, nx, ny = _kernels(xyz, kernel)
    zmin = np.full(nx * ny, np.inf)
    np.minimum.at(zmin, k, z)
    has_returns = bool((rn > 1).any() or (nr > 1).any())
    not_first = np.bincount(k, weights=(rn != 1).astype(float), minlength=nx * ny)
    counts = np.bincount(k, minlength=nx * ny)
    bypass = (counts > 0) & (not_first == 0) & has_returns
    ground = (z <= zmin[k] + dz) | bypass[k]
    return ground, int((counts > 0).sum()), int(bypass.sum())


def oracle_evidence(xyz, rn, nr, kernel, dz, neighbourhood=5.0, slope=0.15):
    """The evidence rule as documented in core/filters/echogrid.py."""
    z = xyz[:, 2]
    col, row, k, nx, ny = _kernels(xyz, kernel)
    zmin = np.full((ny, nx), np.inf)
    zmax = np.full((ny, nx), -np.inf)
    np.minimum.at(zmin, (row, col), z)
    np.maximum.at(zmax, (row, col), z)
    multi = np.zeros((ny, nx), dtype=bool)
    np.logical_or.at(multi, (row, col), nr > 1)
    occupied = np.isfinite(zmin)
    nbh = np.full((ny, nx), np.inf)
    rad = int(np.ceil(neighbourhood / kernel))
    for r in range(ny):
        for c in range(nx):
            for rr in range(max(r - rad, 0), min(r + rad + 1, ny)):
                for cc in range(max(c - rad, 0), min(c + rad + 1, nx)):
                    d = kernel * np.hypot(rr - r, cc - c)
                    nbh[r, c] = min(nbh[r, c], zmin[rr, cc] + slope * d)
    with np.errstate(invalid="ignore"):
        raised = occupied & (zmin - nbh > dz)
    reference = np.where(raised, nbh, zmin)
    has_returns = bool((rn > 1).any() or (nr > 1).any())
    bypass = occupied & ~multi & ((zmax - zmin) <= dz) & ~raised & has_returns
    ground = bypass[row, col] | (z <= reference[row, col] + dz)
    if has_returns:
        ground &= rn >= nr
    return ground, int(occupied.sum()), int(bypass.sum())


ORACLES = {"faithful": oracle_faithful, "evidence": oracle_evidence}


def random_cloud(seed, n=600, size=40.0, lattice=None):
    """Points with random heights (ground noise, low and high objects) and random echoes
    (1 to 4 returns a pulse, mostly single); ``lattice`` puts x, y on a grid of that spacing
    (many points exactly on kernel edges)."""
    rng = np.random.default_rng(seed)
    if lattice:
        steps = int(size / lattice)
        x = rng.integers(0, steps + 1, n) * lattice
        y = rng.integers(0, steps + 1, n) * lattice
    else:
        x = rng.uniform(0.0, size, n)
        y = rng.uniform(0.0, size, n)
    ground = 100.0 + 0.05 * x - 0.03 * y
    kind = rng.choice(3, n, p=[0.6, 0.2, 0.2])
    z = ground + rng.normal(0.0, 0.05, n) + np.where(kind == 1, rng.uniform(0.3, 2.5, n), 0.0) \
        + np.where(kind == 2, rng.uniform(2.0, 20.0, n), 0.0)
    nr = rng.choice([1, 2, 3, 4], n, p=[0.7, 0.15, 0.1, 0.05]).astype(np.uint8)
    rn = np.minimum(rng.integers(1, 5, n), nr).astype(np.uint8)
    rn[rng.random(n) < 0.5] = 1  # many first returns: kernels of only first returns exist
    return np.column_stack([x + X0, y + Y0, z]), rn, nr


ORACLE_CASES = [  # seed, kernel_m, dz_m, lattice
    (0, 5.0, 2.0, None), (1, 3.0, 1.0, None), (2, 2.0, 0.5, None), (3, 7.5, 0.0, None),
    (4, 2.0, 1.0, 0.5), (5, 5.0, 2.0, 1.0), (6, 1.0, 0.3, None),
]


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("seed, kernel_m, dz_m, lattice", ORACLE_CASES)
def test_matches_numpy_oracle_point_for_point(mode, seed, kernel_m, dz_m, lattice):
    xyz, rn, nr = random_cloud(seed, lattice=lattice)
    want, kernels, bypassed = ORACLES[mode](xyz, rn, nr, kernel_m, dz_m)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # see test_evidence_mode_no_runtime_warning
        res = EchoGrid(kernel_m=kernel_m, dz_m=dz_m, mode=mode).run(xyz, return_number=rn, number_of_returns=nr)
    assert isinstance(res, EchoGridResult)
    assert res.ground.dtype == bool and res.ground.shape == (len(xyz),)
    np.testing.assert_array_equal(res.ground, want)
    assert (res.kernels, res.bypassed, res.used_returns) == (kernels, bypassed, True)
    # The random clouds do exercise both branches of the rule.
    assert 0 < want.sum() < len(want)


@pytest.mark.parametrize("mode", MODES)
def test_oracle_without_return_information(mode):
    xyz, _, _ = random_cloud(11)
    ones = np.ones(len(xyz), np.uint8)
    want, kernels, bypassed = ORACLES[mode](xyz, ones, ones, 4.0, 1.0)
    assert bypassed == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        res = EchoGrid(kernel_m=4.0, dz_m=1.0, mode=mode).run(xyz, return_number=ones, number_of_returns=ones)
    np.testing.assert_array_equal(res.ground, want)
    assert (res.kernels, res.bypassed, res.used_returns) == (kernels, 0, False)


@pytest.mark.parametrize("mode", MODES)
def test_point_order_does_not_matter(mode):
    xyz, rn, nr = random_cloud(12)
    perm = np.random.default_rng(13).permutation(len(xyz))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        a = EchoGrid(mode=mode)(xyz, return_number=rn, number_of_returns=nr)
        b = EchoGrid(mode=mode)(xyz[perm], return_number=rn[perm], number_of_returns=nr[perm])
    np.testing.assert_array_equal(a[perm], b)


# --- built scenes ---------------------------------------------------------------------------

def plane(size=40.0, density=4.0, seed=0, tilt=(0.0, 0.0)):
    """Single returns on z = 100 + tilt·(x, y), with points at (0, 0) and (size, size) so the
    kernels are tiled from exactly (X0, Y0)."""
    rng = np.random.default_rng(seed)
    n = int(size * size * density)
    x = np.concatenate([[0.0, size], rng.uniform(0.0, size, n)])
    y = np.concatenate([[0.0, size], rng.uniform(0.0, size, n)])
    z = 100.0 + tilt[0] * x + tilt[1] * y
    return x, y, z


def assemble(*parts):
    """Stack parts (x, y, z, rn, nr) into xyz (shifted to X0, Y0) and the return arrays."""
    x, y, z, rn, nr = (np.concatenate([np.asarray(p[i], dtype=float) for p in parts]) for i in range(5))
    return np.column_stack([x + X0, y + Y0, z]), rn.astype(np.uint8), nr.astype(np.uint8)


def singles(x, y, z):
    n = len(x)
    return x, y, z, np.ones(n), np.ones(n)


def tree_pulses(cx, cy, n=60, seed=1, ground=100.0, height=12.0):
    """Pulses through a crown at (cx, cy) within 2 m: a first return in the crown and a last
    return on the ground (1 of 2, 2 of 2). Returns the part and a mask of the crown returns."""
    rng = np.random.default_rng(seed)
    px = cx + rng.uniform(-2.0, 2.0, n)
    py = cy + rng.uniform(-2.0, 2.0, n)
    x = np.concatenate([px, px])
    y = np.concatenate([py, py])
    z = np.concatenate([ground + height + rng.uniform(-1.0, 1.0, n), np.full(n, ground)])
    rn = np.concatenate([np.ones(n), np.full(n, 2.0)])
    nr = np.full(2 * n, 2.0)
    return (x, y, z, rn, nr), np.arange(2 * n) < n


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("tilt", [(0.0, 0.0), (0.04, -0.02)], ids=["flat", "tilted"])
@pytest.mark.parametrize("returns", ["single", "none", "tree"])
def test_plane_is_all_ground(mode, tilt, returns):
    parts = [singles(*plane(tilt=tilt))]
    if returns == "tree":  # some multiple returns elsewhere: the cloud has return information
        part, _ = tree_pulses(30.0, 30.0)
        ground_z = 100.0 + tilt[0] * part[0] + tilt[1] * part[1]
        part = (part[0], part[1], np.where(part[3] == 2, ground_z, part[2]), part[3], part[4])
        parts.append(part)
        tree_crown = np.concatenate([np.zeros(len(parts[0][0]), bool), part[3] == 1])
    else:
        tree_crown = np.zeros(len(parts[0][0]), bool)
    xyz, rn, nr = assemble(*parts)
    kwargs = {} if returns == "none" else {"return_number": rn, "number_of_returns": nr}
    res = EchoGrid(mode=mode).run(xyz, **kwargs)
    assert res.ground[~tree_crown].all()
    assert not res.ground[tree_crown].any()


# A 10 x 10 m building on the kernel edges (5 m kernels from (0, 0)): four kernels lie entirely on
# its roof, each with ground kernels around it.
BOX = (10.0, 20.0, 10.0, 20.0)


def building_scene(box=BOX, height=10.0, tree=True):
    x, y, z = plane()
    on_roof = (x > box[0]) & (x < box[1]) & (y > box[2]) & (y < box[3])
    z = z + height * on_roof
    parts = [singles(x, y, z)]
    if tree:  # far from the building; makes the cloud one with return information
        part, crown = tree_pulses(32.0, 32.0)
        parts.append(part)
        crown = np.concatenate([np.zeros(len(x), bool), crown])
    else:
        crown = np.zeros(len(x), bool)
    roof = np.concatenate([on_roof, np.zeros(len(crown) - len(x), bool)])
    xyz, rn, nr = assemble(*parts)
    return xyz, rn, nr, roof, crown


def test_building_roof_kernel_is_ground_in_faithful_mode():
    """The paper's bypass: a kernel entirely on a roof holds only single returns, so it is
    taken as ground whole, roof included."""
    xyz, rn, nr, roof, crown = building_scene()
    res = EchoGrid().run(xyz, return_number=rn, number_of_returns=nr)
    assert roof.sum() > 300
    assert res.ground[roof].all()
    assert res.ground[~roof & ~crown].all()
    assert not res.ground[crown].any()
    assert res.used_returns


def test_building_roof_kernel_is_not_ground_in_evidence_mode():
    xyz, rn, nr, roof, crown = building_scene()
    res = EchoGrid(mode="evidence").run(xyz, return_number=rn, number_of_returns=nr)
    assert not res.ground[roof].any()
    assert res.ground[~roof & ~crown].all()
    assert not res.ground[crown].any()


def test_evidence_mode_and_the_centre_of_a_wide_roof():
    """A roof three kernels wide (15 x 15 m on the kernel edges) has a central kernel whose 3 x 3
    neighbours are all roof: with the default 5 m neighbourhood it is taken as ground (the rim
    kernels are found); a 20 m neighbourhood reaches the ground around it."""
    box = (10.0, 25.0, 10.0, 25.0)
    xyz, rn, nr, roof, crown = building_scene(box=box)
    x, y = xyz[:, 0] - X0, xyz[:, 1] - Y0
    centre = (x > 15.0) & (x < 20.0) & (y > 15.0) & (y < 20.0)
    assert centre.sum() > 50
    narrow = EchoGrid(mode="evidence").run(xyz, return_number=rn, number_of_returns=nr)
    assert narrow.ground[centre].all()
    assert not narrow.ground[roof & ~centre].any()
    wide = EchoGrid(mode="evidence", neighbourhood_m=20.0).run(xyz, return_number=rn, number_of_returns=nr)
    assert not wide.ground[roof].any()


@pytest.mark.parametrize("mode", MODES)
def test_tree_kernel_gets_the_height_test(mode):
    """A kernel with multiple returns (a crown over ground) is never bypassed: crown returns are
    non-ground, the last returns on the ground are ground."""
    x, y, z = plane(seed=3)
    part, crown = tree_pulses(12.5, 12.5, n=80, seed=4, height=6.0)
    xyz, rn, nr = assemble(singles(x, y, z), part)
    crown = np.concatenate([np.zeros(len(x), bool), crown])
    res = EchoGrid(mode=mode).run(xyz, return_number=rn, number_of_returns=nr)
    assert not res.ground[crown].any()
    assert res.ground[~crown].all()
    # The kernel [10, 15) x [10, 15) holds the crown: not bypassed.
    assert res.bypassed < res.kernels


def test_evidence_mode_never_keeps_a_non_last_return():
    """First of two returns only 10 cm above the ground (low vegetation): the height test alone
    (faithful mode) calls it ground; the evidence mode does not, the pulse went on below it.
    A middle return (2 of 3) is not ground either; last returns are."""
    x, y, z = plane(seed=5)
    rng = np.random.default_rng(6)
    m = 50
    px, py = rng.uniform(1.0, 39.0, m), rng.uniform(1.0, 39.0, m)
    first = (px, py, np.full(m, 100.1), np.ones(m), np.full(m, 2.0))
    last = (px + 0.05, py, np.full(m, 100.0), np.full(m, 2.0), np.full(m, 2.0))
    middle = (px - 0.05, py, np.full(m, 100.05), np.full(m, 2.0), np.full(m, 3.0))
    xyz, rn, nr = assemble(singles(x, y, z), first, last, middle)
    non_last = rn < nr
    assert non_last.sum() == 2 * m
    faithful = EchoGrid().run(xyz, return_number=rn, number_of_returns=nr).ground
    evidence = EchoGrid(mode="evidence").run(xyz, return_number=rn, number_of_returns=nr).ground
    assert faithful.all()
    assert not evidence[non_last].any()
    assert evidence[~non_last].all()


def stepped_kernel_scene():
    """A plane of single returns with a 3 m step inside one kernel, [20, 25) x [20, 25): its east
    half (x > 22.5) is 3 m up, and nothing else in that kernel. A tree elsewhere gives the cloud
    return information."""
    x, y, z = plane(seed=7)
    high = (x > 22.5) & (x < 25.0) & (y > 20.0) & (y < 25.0)
    z = z + 3.0 * high
    part, crown = tree_pulses(7.5, 32.5, seed=8)
    xyz, rn, nr = assemble(singles(x, y, z), part)
    n_extra = len(xyz) - len(x)
    return xyz, rn, nr, np.concatenate([high, np.zeros(n_extra, bool)]), \
        np.concatenate([np.zeros(len(x), bool), crown])


def test_single_return_kernel_with_a_step_is_bypassed_only_in_faithful_mode():
    xyz, rn, nr, high, crown = stepped_kernel_scene()
    assert high.sum() > 30
    faithful = EchoGrid().run(xyz, return_number=rn, number_of_returns=nr)
    assert faithful.ground[high].all()  # bypassed whole: the 3 m step is ground
    assert faithful.ground[~crown].all()
    evidence = EchoGrid(mode="evidence").run(xyz, return_number=rn, number_of_returns=nr)
    assert not evidence.ground[high].any()  # z range 3 m > dz: height test
    assert evidence.ground[~high & ~crown].all()


def test_bypass_counts_of_the_stepped_scene():
    """Bypassed kernels, by construction: faithful mode bypasses every kernel without a return
    number > 1 (all but the tree's); evidence mode also drops the stepped kernel (z range 3 m)."""
    xyz, rn, nr, high, crown = stepped_kernel_scene()
    _, _, k, _, _ = _kernels(xyz, 5.0)
    occupied = np.unique(k)
    tree_kernels = np.unique(k[nr > 1])
    faithful = EchoGrid().run(xyz, return_number=rn, number_of_returns=nr)
    evidence = EchoGrid(mode="evidence").run(xyz, return_number=rn, number_of_returns=nr)
    # 8 x 8 kernels over the 40 m square, plus the one holding only the corner point (40, 40)
    assert faithful.kernels == evidence.kernels == occupied.size == 65
    assert faithful.bypassed == occupied.size - tree_kernels.size
    assert evidence.bypassed == faithful.bypassed - 1


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("how", ["all_one_of_one", "none"])
def test_no_return_information_means_height_test_everywhere(mode, how):
    """Every point 1 of 1 (or no return arrays at all): the faithful bypass would make the
    whole cloud ground; the filter warns through ``log`` and tests heights everywhere."""
    x, y, z = plane(seed=7)
    high = (x > 22.5) & (x < 25.0) & (y > 20.0) & (y < 25.0)
    z = z + 3.0 * high
    xyz = np.column_stack([x + X0, y + Y0, z])
    ones = np.ones(len(xyz), np.uint8)
    kwargs = {"return_number": ones, "number_of_returns": ones} if how == "all_one_of_one" else {}
    messages = []
    res = EchoGrid(mode=mode).run(xyz, log=messages.append, **kwargs)
    assert not res.used_returns
    assert res.bypassed == 0
    assert res.kernels == 65  # 8 x 8 kernels, plus the corner point (40, 40) alone in its own
    np.testing.assert_array_equal(res.ground, ~high)
    assert len(messages) == 1
    assert "no return information" in messages[0]


@pytest.mark.parametrize("mode", MODES)
def test_no_message_when_the_cloud_has_returns(mode):
    xyz, rn, nr, _, _ = building_scene(height=1.0)  # (a roof within dz of the ground around: nothing raised)
    messages = []
    res = EchoGrid(mode=mode).run(xyz, return_number=rn, number_of_returns=nr, log=messages.append)
    assert res.used_returns
    assert messages == []


def test_faithful_mode_says_how_many_bypassed_kernels_stand_above_their_surroundings():
    """The paper's bypass makes a flat roof's kernels ground whole (a UAV surveyor's farm: 99.4 % of its roof
    points, the DTM 4.9 m up, and nothing said but small spikes): faithful mode now counts the bypassed kernels
    standing more than dz above what the slope reaches from their neighbours, and says so; evidence mode, which
    keeps them out, says nothing."""
    xyz, rn, nr, roof, _crown = building_scene()
    messages = []
    EchoGrid().run(xyz, return_number=rn, number_of_returns=nr, log=messages.append)
    assert len(messages) == 1 and "4 of the" in messages[0] and "flat roofs" in messages[0], messages
    assert f"({int(roof.sum()):,} points)" in messages[0]
    messages = []
    EchoGrid(mode="evidence").run(xyz, return_number=rn, number_of_returns=nr, log=messages.append)
    assert messages == []


def test_first_returns_only_keep_the_literal_bypass_only_when_asked():
    """A cloud of first returns only (rn 1, some nr > 1): the paper's bypass, read literally, takes
    every kernel as ground (every kernel holds only return number 1). It is now treated as a cloud
    without echoes (height test, a warning; test_first_returns_only_are_not_all_ground_and_are_warned);
    echoes="yes" still gives the literal rule."""
    xyz, _, _ = assemble(singles(*plane(seed=9)))
    xyz[:50, 2] += 8.0
    rn = np.ones(len(xyz), np.uint8)
    nr = np.ones(len(xyz), np.uint8)
    nr[:50] = 3
    res = EchoGrid(echoes="yes").run(xyz, return_number=rn, number_of_returns=nr)
    assert res.used_returns and res.ground.all() and res.bypassed == res.kernels
    res = EchoGrid().run(xyz, return_number=rn, number_of_returns=nr)
    assert not res.used_returns and not res.ground.all() and res.ground[50:].all()
    np.testing.assert_array_equal(res.ground, EchoGrid(echoes="no").run(xyz, return_number=rn, number_of_returns=nr).ground)


def test_log_is_optional():
    xyz, _, _ = assemble(singles(*plane(seed=10)))
    assert EchoGrid().run(xyz).ground.all()
    assert EchoGrid()(xyz).all()


def test_call_matches_run_and_progress_completes():
    xyz, rn, nr, _, _ = building_scene()
    seen = []
    res = EchoGrid().run(xyz, Steps(progress=seen.append), return_number=rn, number_of_returns=nr)
    np.testing.assert_array_equal(EchoGrid()(xyz, return_number=rn, number_of_returns=nr), res.ground)
    assert seen and seen[-1] == pytest.approx(1.0)
    assert all(b >= a for a, b in zip(seen, seen[1:]))


def test_result_counts_on_a_tiny_cloud():
    """Three occupied kernels of 2 m (and one empty): one with only return number 1 (bypassed
    in faithful mode), one with a second return, one of a single point."""
    xyz = np.array([[0.0, 0.0, 100.0], [1.0, 1.0, 105.0],          # kernel (0, 0): 1 of 1 twice
                    [2.5, 0.5, 100.0], [2.6, 0.6, 109.0],          # kernel (0, 1): 2 of 2, 1 of 2
                    [4.5, 4.5, 101.0]]) + [X0, Y0, 0.0]            # kernel (2, 2)
    rn = np.array([1, 1, 2, 1, 1], np.uint8)
    nr = np.array([1, 1, 2, 2, 1], np.uint8)
    res = EchoGrid(kernel_m=2.0, dz_m=1.0).run(xyz, return_number=rn, number_of_returns=nr)
    assert (res.kernels, res.bypassed, res.used_returns) == (3, 2, True)
    np.testing.assert_array_equal(res.ground, [True, True, True, False, True])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ev = EchoGrid(kernel_m=2.0, dz_m=1.0, mode="evidence").run(xyz, return_number=rn, number_of_returns=nr)
    # Kernel (0, 0) spans 5 m > dz: no bypass, the height test drops its upper point. Kernel
    # (2, 2), a lone single return with only empty kernels around it, is bypassed.
    assert (ev.kernels, ev.bypassed) == (3, 1)
    np.testing.assert_array_equal(ev.ground, [True, False, True, False, True])


def test_one_point():
    res = EchoGrid().run(np.array([[X0, Y0, 50.0]]), return_number=[1], number_of_returns=[1])
    assert res.ground.tolist() == [True] and res.kernels == 1 and not res.used_returns


def test_evidence_mode_no_runtime_warning():
    xyz = np.array([[0.0, 0.0, 100.0], [0.5, 0.5, 100.1],
                    [30.0, 30.0, 100.0], [30.5, 30.2, 105.0]]) + [X0, Y0, 0.0]
    rn = np.array([1, 1, 1, 2], np.uint8)
    nr = np.array([1, 1, 2, 2], np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = EchoGrid(mode="evidence").run(xyz, return_number=rn, number_of_returns=nr)
    # The far pair: a first return (never ground in evidence mode) and a last return 5 m above the
    # kernel's lowest point (more than dz).
    np.testing.assert_array_equal(res.ground, [True, True, False, False])


# --- parameters and inputs ----------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, name", [
    ({"kernel_m": 0}, "kernel_m"),
    ({"kernel_m": 0.0}, "kernel_m"),
    ({"kernel_m": -5.0}, "kernel_m"),
    ({"kernel_m": math.nan}, "kernel_m"),
    ({"kernel_m": math.inf}, "kernel_m"),
    ({"kernel_m": None}, "kernel_m"),
    ({"kernel_m": "5"}, "kernel_m"),
    ({"dz_m": -0.1}, "dz_m"),
    ({"dz_m": math.nan}, "dz_m"),
    ({"dz_m": None}, "dz_m"),
    ({"dz_m": True}, "dz_m"),
    ({"mode": "paper"}, "mode"),
    ({"mode": None}, "mode"),
    ({"mode": "Faithful"}, "mode"),
])
def test_invalid_parameters_name_the_parameter(kwargs, name):
    with pytest.raises(InvalidParameterError) as info:
        EchoGrid(**kwargs)
    assert name in str(info.value)


def test_valid_edge_parameters_and_defaults():
    EchoGrid(dz_m=0.0)
    EchoGrid(kernel_m=0.01, mode="evidence")
    g = EchoGrid()
    assert (g.kernel_m, g.dz_m, g.mode) == (5.0, 2.0, "faithful")
    assert g.point_fields == ("return_number", "number_of_returns") and g.wants_log


@pytest.mark.parametrize("which", ["return_number", "number_of_returns"])
def test_return_arrays_of_the_wrong_length(which):
    xyz, rn, nr, _, _ = building_scene()
    arrays = {"return_number": rn, "number_of_returns": nr}
    arrays[which] = arrays[which][:-1]
    with pytest.raises(InvalidParameterError, match="one value per point"):
        EchoGrid().run(xyz, **arrays)


def test_too_many_kernels_are_refused():
    xyz = np.array([[0.0, 0.0, 0.0], [50_000.0, 50_000.0, 0.0]]) + [X0, Y0, 0.0]
    with pytest.raises(InvalidParameterError, match="kernel_m"):
        EchoGrid(kernel_m=1.0).run(xyz)


# --- through the driver ----------------------------------------------------------------------

class Spy:
    """Wraps a filter and records what the driver hands it."""

    def __init__(self, inner):
        self.inner = inner
        self.point_fields = inner.point_fields
        self.wants_log = inner.wants_log
        self.seen = {}

    def run(self, xyz, steps=None, **fields):
        self.seen = {"xyz": np.array(xyz), **fields}
        return self.inner.run(xyz, steps, **fields)


def cloud_with_noise():
    """The stepped scene plus a class 7 noise point first (so a misaligned return array would
    shift every point), with return information."""
    xyz, rn, nr, high, crown = stepped_kernel_scene()
    xyz = np.vstack([[X0 + 22.0, Y0 + 22.0, 60.0], xyz])  # far below, in the stepped kernel
    rn = np.concatenate([[3], rn]).astype(np.uint8)
    nr = np.concatenate([[3], nr]).astype(np.uint8)
    cls = np.ones(len(xyz), np.uint8)
    cls[0] = 7
    cloud = PointCloud(path="memory", x=xyz[:, 0].copy(), y=xyz[:, 1].copy(), z=xyz[:, 2].copy(),
                       classification=cls, return_number=rn, number_of_returns=nr, has_return_info=True)
    return cloud, np.concatenate([[False], high]), np.concatenate([[False], crown])


@pytest.mark.parametrize("mode", MODES)
def test_driver_passes_the_return_arrays_of_the_selected_points(mode):
    cloud, high, crown = cloud_with_noise()
    spy = Spy(EchoGrid(mode=mode))
    messages = []
    done = classify_cloud(cloud, spy, FilterOptions(last_returns_only=False), log=messages.append)
    sel = np.arange(1, len(cloud))
    np.testing.assert_array_equal(done.filtered, np.arange(len(cloud)) > 0)
    np.testing.assert_array_equal(spy.seen["xyz"], cloud.xyz[sel])
    np.testing.assert_array_equal(spy.seen["return_number"], cloud.return_number[sel])
    np.testing.assert_array_equal(spy.seen["number_of_returns"], cloud.number_of_returns[sel])
    assert spy.seen["log"] is not None
    direct = EchoGrid(mode=mode).run(cloud.xyz[sel], return_number=cloud.return_number[sel],
                                     number_of_returns=cloud.number_of_returns[sel])
    np.testing.assert_array_equal(done.ground[sel], direct.ground)
    assert done.detail.bypassed == direct.bypassed
    assert not done.ground[0] and done.classification[0] == 7  # the noise point is left alone
    # The noise point 40 m below would have pulled the stepped kernel's lowest z down.
    if mode == "faithful":
        assert done.ground[high].all()
    else:
        assert not done.ground[high].any() and done.ground[~high & ~crown & (np.arange(len(cloud)) > 0)].all()
    assert any("Filtering" in m for m in messages)
    assert not any("no return information" in m for m in messages)


def test_driver_forwards_the_filter_log():
    """A cloud read without return information (as from ISPRS text): the message reaches the
    caller's log through classify_cloud."""
    xyz, _, _, high, _ = stepped_kernel_scene()
    n = len(xyz)
    ones = np.ones(n, np.uint8)
    cloud = PointCloud(path="memory", x=xyz[:, 0].copy(), y=xyz[:, 1].copy(), z=xyz[:, 2].copy(),
                       classification=np.zeros(n, np.uint8), return_number=ones, number_of_returns=ones.copy())
    messages = []
    done = classify_cloud(cloud, EchoGrid(), log=messages.append)
    assert any("no return information" in m for m in messages)
    assert not done.detail.used_returns
    assert not done.ground[high].any()


def test_run_ground_filter_on_an_isprs_text_file(tmp_path):
    """File to file: ISPRS text has no returns; the warning goes to the log, the step is found."""
    import laspy

    from groundsieve.core.engine.workflow import run_ground_filter
    x, y, z = plane(size=20.0, density=2.0, seed=14)
    high = (x > 12.5) & (x < 15.0) & (y > 10.0) & (y < 15.0)
    z = z + 3.0 * high
    src = tmp_path / "cloud.txt"
    np.savetxt(src, np.column_stack([x + X0, y + Y0, z]), fmt="%.3f")
    messages = []
    run = run_ground_filter(str(src), str(tmp_path / "out.las"), EchoGrid(), log=messages.append)
    assert any("no return information" in m for m in messages)
    # the filter's warning names the file (the filter sees arrays; the run says which file)
    assert any(m.startswith(f"Warning: {src}: Echo grid: the cloud has no return information") for m in messages)
    np.testing.assert_array_equal(run.ground, ~high)
    written = laspy.read(str(tmp_path / "out.las"))
    np.testing.assert_array_equal(np.asarray(written.classification), np.where(high, 1, 2))


def test_kernel_larger_than_the_cloud_is_reported():
    xyz = np.array([[0.0, 0.0, 10.0], [1.0, 1.0, 10.5], [2.0, 0.5, 14.0]]) + [X0, Y0, 0.0]
    messages = []
    res = EchoGrid(kernel_m=50.0).run(xyz, return_number=[1, 1, 1], number_of_returns=[1, 1, 1],
                                      log=messages.append)
    assert any("larger than the cloud" in m for m in messages), messages
    assert res.kernels == 1
    np.testing.assert_array_equal(res.ground, [True, True, False])


def _slope_with_one_echo_patch(path):
    """An 80 x 20 m slope of 50 %, single returns everywhere but a 5 m patch of two-return pulses."""
    import laspy
    rng = np.random.default_rng(0)
    n = 16000
    x, y = rng.uniform(0, 80, n), rng.uniform(0, 20, n)
    z = 100 + 0.5 * x + rng.normal(0, 0.02, n)
    rn, nr = np.ones(n, np.uint8), np.ones(n, np.uint8)
    patch = (x < 5) & (y < 5)
    nr[patch] = 2
    rn[patch & (rng.random(n) < 0.5)] = 2
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales, header.offsets = [0.01] * 3, [X0, Y0, 0.0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = x + X0, y + Y0, z
    las.return_number, las.number_of_returns = rn, nr
    las.write(str(path))


def test_a_tiled_run_decides_once_whether_the_cloud_has_echoes(tmp_path):
    """Each tile decided from its own points whether the cloud had echoes: a tile of single returns
    in a cloud with echoes elsewhere turned the paper's bypass off and height-tested its kernels,
    so 15 % of a reviewer's slope changed class against the whole run. The survey's headers now
    decide it once (EchoGrid.for_survey), and the tiled run equals the whole one."""
    import laspy

    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import run_ground_filter
    from groundsieve.core.io.lasfiles import scan_header
    src = tmp_path / "slope.las"
    _slope_with_one_echo_patch(src)
    assert scan_header(str(src)).later_returns > 0
    assert EchoGrid().for_survey([scan_header(str(src))]).echoes == "yes"
    run_ground_filter(str(src), str(tmp_path / "whole.las"), EchoGrid())
    run_ground_filter(str(src), str(tmp_path / "tiled.las"), EchoGrid(),
                      options=FilterOptions(tiling=TileOptions(tile_size_m=20.0, workers=1, parallel="threads")))
    whole = np.asarray(laspy.read(str(tmp_path / "whole.las")).classification)
    tiled = np.asarray(laspy.read(str(tmp_path / "tiled.las")).classification)
    assert (whole == 2).mean() > 0.95  # the bypass: single-return kernels are ground on the slope
    np.testing.assert_array_equal(tiled, whole)


def test_first_returns_only_are_not_all_ground_and_are_warned():
    """A file of first returns only (every return number 1, number of returns up to 4; lidR's
    MixedConifer.laz is one) passed the 'has returns' check on number_of_returns, and the faithful
    bypass then took every kernel as ground (a forester: 100 % ground, DTM +10.8 m, no warning)."""
    from groundsieve.core.progress import WARNING_PREFIX
    xyz, _, _, high, _ = stepped_kernel_scene()
    n = len(xyz)
    rn = np.ones(n, np.uint8)
    nr = np.where(np.arange(n) % 3 == 0, 3, 1).astype(np.uint8)
    messages = []
    result = EchoGrid().run(xyz, return_number=rn, number_of_returns=nr, log=messages.append)
    assert not result.used_returns and not result.ground[high].any()
    assert len(messages) == 1 and messages[0].startswith(WARNING_PREFIX + "Echo grid: every point has return number 1")
    # a given answer wins over the cloud's (what a tiled run passes down)
    assert EchoGrid(echoes="yes").run(xyz, return_number=rn, number_of_returns=nr).used_returns


def test_a_survey_mixing_files_with_and_without_later_returns_decides_per_tile_and_says_so(tmp_path):
    """A folder with a first-returns-only file beside a normal one: 'yes' from the second file's header
    took every kernel of the first as ground (a reviewer: 100 % ground, no warning). The run keeps each
    tile's own decision and names the files without later returns."""
    import laspy

    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import run_ground_filter
    folder = tmp_path / "survey"
    folder.mkdir()
    _slope_with_one_echo_patch(folder / "a.las")
    first = laspy.read(str(folder / "a.las"))
    first.x = np.asarray(first.x) + 200.0  # beside the first file
    first.return_number = np.ones(len(first.points), np.uint8)  # first returns only
    first.number_of_returns = np.where(np.arange(len(first.points)) % 3 == 0, 3, 1).astype(np.uint8)
    first.update_header()
    first.write(str(folder / "b.las"))
    lines = []
    run_ground_filter(str(folder), str(tmp_path / "out.vpc"), EchoGrid(), log=lines.append,
                      options=FilterOptions(tiling=TileOptions(tile_size_m=40.0, workers=1, parallel="threads")))
    assert any("Echo grid: 1 file(s) have no later returns by their headers (b.las)" in line for line in lines), lines
    # the first-returns-only file alone, in tiles: its warning is said once by the run (a tile's is lost)
    lines = []
    run_ground_filter(str(folder / "b.las"), str(tmp_path / "b_tiled.las"), EchoGrid(), log=lines.append,
                      options=FilterOptions(tiling=TileOptions(tile_size_m=40.0, workers=1, parallel="threads")))
    assert sum(line.startswith("Warning: Echo grid: the headers count no return beyond the first") for line in lines) == 1
    b = np.asarray(laspy.read(str(tmp_path / "out" / "b.las")).classification)
    whole = EchoGrid().run(np.column_stack([first.x, first.y, first.z]), return_number=np.asarray(first.return_number),
                           number_of_returns=np.asarray(first.number_of_returns)).ground
    assert (b == 2).mean() < 1.0 and np.array_equal(b == 2, whole)
