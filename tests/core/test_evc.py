"""The multiscale EVC filter (core.filters.evc, Fan et al. 2023): a numpy oracle of the whole faithful
pipeline (mean grids, difference, focal statistics with window growth, EVC, Table 2 classes,
points), the sign option and the ground offset, what a perfectly flat plane gives, noisy planes,
a shrub patch, sparse clouds, the natural-break threshold, and validation."""
from __future__ import annotations

import math

import numpy as np
import pytest

from groundsieve.core.errors import InvalidParameterError
from groundsieve.core.filters.evc import (EMPTY, EVC, GROUND, VEGETATION_AREA, VEGETATION_BOUNDARY,
                                          EVCResult, natural_break)
from groundsieve.core.io import PointCloud
from groundsieve.core.progress import Steps
from groundsieve.core.engine.workflow import classify_cloud

from groundsieve.tests.core.scenes import X0, Y0, plane_scene


# --- numpy oracle -------------------------------------------------------------------------------

def oracle_grid(x, y, cell):
    """Edges on multiples of ``cell``: x0 = floor(xmin / c) c, top = ceil(ymax / c) c; column and
    row of every point; the grid just holds every point."""
    x0 = math.floor(x.min() / cell) * cell
    top = math.ceil(y.max() / cell) * cell
    col = np.floor((x - x0) / cell).astype(np.int64)
    row = np.floor((top - y) / cell).astype(np.int64)
    return x0, top, row, col, (int(row.max()) + 1, int(col.max()) + 1)


def oracle_mean(z, row, col, shape):
    total = np.zeros(shape)
    count = np.zeros(shape)
    np.add.at(total, (row, col), z)
    np.add.at(count, (row, col), 1)
    with np.errstate(invalid="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def oracle_focal(values, radius, max_radius, min_cells):
    """Mean and population std of the non-NaN values in the (2r+1)² window, r growing from
    ``radius`` while fewer than ``min_cells`` are valid, up to ``max_radius``; NaN for NaN cells
    and for cells left with fewer than two values."""
    nrows, ncols = values.shape
    mean = np.full(values.shape, np.nan)
    std = np.full(values.shape, np.nan)
    for r in range(nrows):
        for c in range(ncols):
            if np.isnan(values[r, c]):
                continue
            rad = radius
            while True:
                win = values[max(r - rad, 0):r + rad + 1, max(c - rad, 0):c + rad + 1]
                win = win[~np.isnan(win)]
                if win.size >= min_cells or rad >= max_radius:
                    break
                rad += 1
            if win.size >= 2:
                mean[r, c] = win.mean()
                std[r, c] = win.std()
    return mean, std


def oracle_evc(xyz, small=0.5, large=2.0, radius=1, threshold=1.5, difference="large_minus_small",
               min_cells=3, max_radius=5, offset=0.0):
    """The faithful pipeline in plain numpy; ``large`` must be a multiple of ``small`` (every small
    cell then lies in one large cell, which holds its points and so is never empty)."""
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    sx0, stop, srow, scol, sshape = oracle_grid(x, y, small)
    lx0, ltop, lrow, lcol, lshape = oracle_grid(x, y, large)
    small_mean = oracle_mean(z, srow, scol, sshape)
    large_mean = oracle_mean(z, lrow, lcol, lshape)
    xs = sx0 + (np.arange(sshape[1]) + 0.5) * small
    ys = stop - (np.arange(sshape[0]) + 0.5) * small
    cols = np.clip(np.floor((xs - lx0) / large).astype(np.int64), 0, lshape[1] - 1)
    rows = np.clip(np.floor((ltop - ys) / large).astype(np.int64), 0, lshape[0] - 1)
    large_at = large_mean[rows[:, None], cols[None, :]]
    assert not np.isnan(large_at[~np.isnan(small_mean)]).any(), "oracle: scales must be multiples"
    diff = large_at - small_mean if difference == "large_minus_small" else small_mean - large_at
    mean, std = oracle_focal(diff, radius, max_radius, min_cells)
    with np.errstate(divide="ignore", invalid="ignore"):
        evc = std / (mean + offset)
    classes = np.full(evc.shape, VEGETATION_BOUNDARY, np.uint8)
    if offset > 0:  # our variant: the sign of the shifted mean decides "vegetation area"
        classes[mean + offset <= 0] = VEGETATION_AREA
        classes[(mean + offset > 0) & (evc <= threshold)] = GROUND
    else:  # Table 2 of the paper
        classes[evc <= 0] = VEGETATION_AREA
        classes[(evc > 0) & (evc <= threshold)] = GROUND
    classes[np.isnan(small_mean)] = EMPTY
    ground = classes[srow, scol] == GROUND
    return dict(small_mean=small_mean, large_mean=large_mean, difference=diff, evc=evc, classes=classes,
                ground=ground, small_origin=(sx0, stop), large_origin=(lx0, ltop), mean=mean)


def oracle_cloud(seed, size=20.0, density=4.0):
    """A noisy, gently tilted plane with a shrub patch (0.5-1 m), a 7 m wide gap holding one
    lone point (its window reaches max_radius with a single value: no EVC) and a sparse strip
    (window growth)."""
    rng = np.random.default_rng(seed)
    n = int(size * size * density)
    x = rng.uniform(0.0, size, n)
    y = rng.uniform(0.0, size, n)
    gap = (x > 1.0) & (x < 8.0) & (y > 11.0) & (y < 18.0)
    sparse = (x > 12.0) & (x < 18.0) & (y < 6.0) & (rng.random(n) < 0.85)
    keep = ~gap & ~sparse
    x, y = np.concatenate([x[keep], [4.6]]), np.concatenate([y[keep], [14.6]])
    z = 100.0 + 0.02 * x - 0.01 * y + rng.normal(0.0, 0.03, x.size)
    shrub = (x > 9.0) & (x < 13.0) & (y > 9.0) & (y < 13.0)
    z[shrub] += rng.uniform(0.5, 1.0, shrub.sum())
    return np.column_stack([x + X0, y + Y0, z])


ORACLE_CASES = [
    dict(),
    dict(difference="small_minus_large"),
    dict(offset=0.1),
    dict(offset=0.05, difference="small_minus_large", threshold=0.8),
    dict(min_cells=6, max_radius=3),
    dict(radius=2, max_radius=4, min_cells=8),
    dict(small=0.25, large=1.0, threshold=2.5),
    dict(small=0.5, large=3.0, offset=0.1),
]


def _evc_kwargs(case):
    names = {"small": "small_scale_m", "large": "large_scale_m", "offset": "ground_offset_m"}
    return {names.get(k, k): v for k, v in case.items()}


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("case", ORACLE_CASES, ids=lambda c: ",".join(f"{k}={v}" for k, v in c.items()) or "paper")
def test_matches_numpy_oracle(case, seed):
    xyz = oracle_cloud(seed)
    want = oracle_evc(xyz, **case)
    kwargs = _evc_kwargs(case)
    kwargs.setdefault("small_scale_m", 0.5)
    res = EVC(**kwargs).run(xyz)
    assert isinstance(res, EVCResult)
    assert (res.small_grid.x0, res.small_grid.top) == want["small_origin"]
    assert (res.large_grid.x0, res.large_grid.top) == want["large_origin"]
    for name in ("small_mean", "large_mean", "difference", "evc"):
        got, exp = getattr(res, name), want[name]
        assert got.shape == exp.shape, name
        np.testing.assert_array_equal(np.isnan(got), np.isnan(exp), err_msg=name)
        ok = np.isfinite(exp)
        np.testing.assert_allclose(got[ok], exp[ok], rtol=1e-7, atol=1e-9, err_msg=name)
    np.testing.assert_array_equal(res.classes, want["classes"])
    np.testing.assert_array_equal(res.ground, want["ground"])
    assert res.threshold == kwargs.get("threshold", 1.5)
    # Every class occurs, the window growth and the lone point are exercised.
    assert set(np.unique(res.classes)) == {EMPTY, GROUND, VEGETATION_AREA, VEGETATION_BOUNDARY}
    assert np.isnan(res.evc[~np.isnan(res.small_mean)]).any()


def test_oracle_cloud_exercises_window_growth():
    """With min_cells 6 the 3 x 3 window is too small in the sparse strip: the answer differs
    from a fixed 3 x 3 window there."""
    xyz = oracle_cloud(0)
    grown = oracle_evc(xyz, min_cells=6, max_radius=3)["mean"]
    fixed = oracle_evc(xyz, min_cells=6, max_radius=1)["mean"]
    both = np.isfinite(grown) & np.isfinite(fixed)
    assert (np.abs(grown[both] - fixed[both]) > 1e-9).sum() > 20
    assert (np.isfinite(grown) & np.isnan(fixed)).sum() > 5


def test_difference_sign_flips_the_difference_grid():
    xyz = oracle_cloud(3)
    a = EVC(small_scale_m=0.5).run(xyz)
    b = EVC(small_scale_m=0.5, difference="small_minus_large").run(xyz)
    np.testing.assert_array_equal(np.isnan(a.difference), np.isnan(b.difference))
    np.testing.assert_allclose(b.difference, -a.difference, equal_nan=True, atol=0)
    # The std is the same, the mean flips: the EVC flips too.
    np.testing.assert_allclose(b.evc, -a.evc, equal_nan=True, rtol=1e-12)
    np.testing.assert_array_equal(a.small_mean, b.small_mean)


@pytest.mark.parametrize("offset", [0.05, 0.1, 0.3])
def test_ground_offset_changes_evc_as_std_over_mean_plus_offset(offset):
    xyz = oracle_cloud(4)
    base = EVC(small_scale_m=0.5).run(xyz)
    off = EVC(small_scale_m=0.5, ground_offset_m=offset).run(xyz)
    np.testing.assert_array_equal(base.difference, off.difference)
    # std / mean = base.evc; std / (mean + offset) = off.evc: recover mean and std from the oracle.
    want = oracle_evc(xyz, offset=offset)
    np.testing.assert_allclose(off.evc, want["evc"], rtol=1e-7, atol=1e-9, equal_nan=True)
    mean = want["mean"]
    std = base.evc * mean
    ok = np.isfinite(std) & (np.abs(mean + offset) > 1e-6)
    np.testing.assert_allclose(off.evc[ok], std[ok] / (mean[ok] + offset), rtol=1e-6)


def test_result_fields_and_call():
    xyz = oracle_cloud(5)
    res = EVC(small_scale_m=0.5).run(xyz)
    np.testing.assert_array_equal(EVC(small_scale_m=0.5)(xyz), res.ground)
    assert res.ground.dtype == bool and res.ground.shape == (len(xyz),)
    assert res.classes.dtype == np.uint8
    assert res.small_mean.shape == res.difference.shape == res.evc.shape == res.classes.shape \
        == res.small_grid.shape
    assert res.large_mean.shape == res.large_grid.shape
    assert (res.small_grid.cell, res.large_grid.cell) == (0.5, 2.0)
    d = EVC()
    assert (d.small_scale_m, d.large_scale_m, d.radius, d.threshold, d.difference, d.ground_offset_m) == \
        (0.2, 2.0, 1, 1.5, "large_minus_small", 0.0)


def test_non_multiple_scales_leave_no_occupied_small_cell_without_a_difference():
    """0.3 and 2.0 m: small cells straddle large-cell edges and reach past the large grid at the
    rim; the large cell at a small cell's centre may then be empty (nearest one taken) or
    outside (clipped). Every occupied small cell still gets a difference."""
    for seed in range(3):
        xyz = oracle_cloud(seed)
        res = EVC(small_scale_m=0.3, large_scale_m=2.0).run(xyz)
        occupied = ~np.isnan(res.small_mean)
        assert np.isfinite(res.difference[occupied]).all()
        assert np.isnan(res.difference[~occupied]).all()
        # Where the centre lies in an occupied large cell, difference = large - small there.
        xs, ys = res.small_grid.centers()
        lm = res.large_mean[res.large_grid.row_of(ys)[:, None], res.large_grid.col_of(xs)[None, :]]
        ok = occupied & np.isfinite(lm)
        np.testing.assert_allclose(res.difference[ok], (lm - res.small_mean)[ok], rtol=0, atol=1e-9)


def test_every_point_gets_its_small_cells_class():
    xyz = oracle_cloud(6)
    res = EVC(small_scale_m=0.5).run(xyz)
    cls = res.classes[res.small_grid.row_of(xyz[:, 1]), res.small_grid.col_of(xyz[:, 0])]
    assert (cls != EMPTY).all()
    np.testing.assert_array_equal(res.ground, cls == GROUND)


def test_blunders_take_their_cells_class_in_the_paper_and_not_with_a_point_tolerance():
    """In the paper every point takes its small cell's class: a point floating 1-8 m above open ground (an
    image-matching blunder) or sunk below it is ground wherever its cell stays ground, a spike or a pit in the
    DTM (a photogrammetry reviewer: 82 of 248 floating points). With a point tolerance a ground cell's point is
    ground only near its window's ground level: the blunders are not, the plane's points still are, and the
    cells' classes are the paper's."""
    rng = np.random.default_rng(3)
    xyz = plane(400.0, size=12.0, noise=0.03, seed=3)
    m = 60
    at = rng.choice(len(xyz), m, replace=False)
    blunders = xyz[at] + np.c_[rng.normal(0, 0.02, (m, 2)), np.r_[rng.uniform(1, 8, m // 2), -rng.uniform(0.5, 3, m // 2)]]
    cloud = np.vstack([xyz, blunders])
    paper = EVC(ground_offset_m=0.1).run(cloud)
    tolerant = EVC(ground_offset_m=0.1, point_tolerance_m=0.3).run(cloud)
    assert paper.ground[len(xyz):].sum() >= m // 2  # (most cells keep their class under one blunder)
    assert tolerant.ground[len(xyz):].sum() == 0
    assert tolerant.ground[:len(xyz)].mean() >= 0.99 * paper.ground[:len(xyz)].mean()
    np.testing.assert_array_equal(tolerant.classes, paper.classes)
    assert not (tolerant.ground & ~paper.ground).any()


# --- planes, shrubs, sparse clouds ----------------------------------------------------------------

def plane(density, size=30.0, noise=0.0, seed=0, tilt=(0.0, 0.0)):
    return plane_scene(seed=seed, size=size, density=density, tilt=tilt, noise=noise)[0]


def point_classes(res, xyz):
    return res.classes[res.small_grid.row_of(xyz[:, 1]), res.small_grid.col_of(xyz[:, 0])]


def test_perfectly_flat_plane_faithful_is_vegetation_boundary():
    """Documents the faithful formula on a noise-free flat plane: every difference is exactly 0,
    std and mean are 0, EVC = 0/0 = NaN, which Table 2's tests (<= 0, (0, t]) both miss: every
    occupied cell is 'vegetation boundary' and no point is ground."""
    xyz = plane(30.0)
    res = EVC().run(xyz)
    occupied = ~np.isnan(res.small_mean)
    assert (res.difference[occupied] == 0.0).all()
    assert np.isnan(res.evc).all()
    assert (res.classes[occupied] == VEGETATION_BOUNDARY).all()
    assert (res.classes[~occupied] == EMPTY).all()
    assert not res.ground.any()


def test_perfectly_flat_plane_with_offset_is_ground():
    """The offset variant on the same plane: EVC = 0 / (0 + offset) = 0 with a positive shifted
    mean, which the variant calls ground (a perfectly smooth surface)."""
    xyz = plane(30.0)
    res = EVC(ground_offset_m=0.1).run(xyz)
    occupied = ~np.isnan(res.small_mean)
    assert (res.evc[occupied] == 0.0).all()
    assert (res.classes[occupied] == GROUND).all()
    assert res.ground.all()


def test_perfectly_flat_plane_has_no_natural_break():
    with pytest.raises(InvalidParameterError, match="natural break"):
        EVC(auto_threshold=True).run(plane(30.0))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noisy_flat_plane_with_offset_is_ground(seed):
    xyz = plane(30.0, noise=0.03, seed=seed)
    res = EVC(ground_offset_m=0.1).run(xyz)
    assert res.ground.mean() >= 0.99


def test_noisy_flat_plane_without_offset_is_mostly_not_ground():
    """Documents the faithful formula on open ground: the mean difference is noise around 0, so
    EVC = std/mean is mostly large (boundary) or negative (area); only a minority is ground
    (about 9 % here; the module docstring speaks of 'about half' falling into vegetation area,
    and the rest of the loss goes to vegetation boundary)."""
    xyz = plane(30.0, noise=0.03, seed=0)
    res = EVC().run(xyz)
    cls = point_classes(res, xyz)
    assert res.ground.mean() < 0.3
    assert 0.3 < (cls == VEGETATION_AREA).mean() < 0.7
    assert (cls == VEGETATION_BOUNDARY).mean() > 0.2


def shrub_scene(patch, density=30.0, size=30.0, seed=0, margin=0.3):
    """Noisy plane with a dense shrub patch 0.5-1 m high; returns xyz, the shrub mask and its
    interior (``margin`` inside the patch edge)."""
    rng = np.random.default_rng(seed)
    n = int(size * size * density)
    x = rng.uniform(0.0, size, n)
    y = rng.uniform(0.0, size, n)
    z = 100.0 + rng.normal(0.0, 0.03, n)
    shrub = (x > patch[0]) & (x < patch[1]) & (y > patch[2]) & (y < patch[3])
    z[shrub] += rng.uniform(0.5, 1.0, shrub.sum())
    inner = (x > patch[0] + margin) & (x < patch[1] - margin) & (y > patch[2] + margin) & (y < patch[3] - margin)
    return np.column_stack([x + X0, y + Y0, z]), shrub, inner


# 4 x 4 m, centred on a corner of the 2 m large grid (the large cells are a quarter shrub); and
# 1 x 1 m, inside one large cell. Patch and margin of its interior.
SHRUBS = {"4m": ((13.0, 17.0, 13.0, 17.0), 0.3), "1m": ((14.5, 15.5, 14.5, 15.5), 0.1)}


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("patch", list(SHRUBS), ids=list(SHRUBS))
def test_shrub_patch_interior_is_not_ground_with_the_default_sign(patch, seed):
    """The shrub raises its small cells above the large-scale mean: large - small < 0 there,
    EVC < 0 ('vegetation area') or > t ('vegetation boundary')."""
    xyz, shrub, inner = shrub_scene(SHRUBS[patch][0], seed=seed, margin=SHRUBS[patch][1])
    res = EVC().run(xyz)
    cls = point_classes(res, xyz)
    assert inner.sum() > 15
    assert (~res.ground[inner]).mean() >= 0.95
    assert np.isin(cls[inner], (VEGETATION_AREA, VEGETATION_BOUNDARY)).mean() >= 0.95
    assert (cls[inner] == VEGETATION_AREA).mean() >= 0.7
    # With the ground offset the plane becomes ground and the shrub interior stays mostly out.
    off = EVC(ground_offset_m=0.1).run(xyz)
    assert (~off.ground[inner]).mean() >= 0.7
    assert off.ground[~shrub].mean() >= 0.95


@pytest.mark.parametrize("patch", list(SHRUBS), ids=list(SHRUBS))
def test_shrub_patch_with_the_flipped_sign_is_missed(patch):
    """The other sign calls most of the same shrub interior ground (Table 2 then reads the
    canopy as ground, as the module docstring says)."""
    xyz, _, inner = shrub_scene(SHRUBS[patch][0], seed=0, margin=SHRUBS[patch][1])
    default = EVC().run(xyz)
    flipped = EVC(difference="small_minus_large").run(xyz)
    assert (~flipped.ground[inner]).mean() < (~default.ground[inner]).mean() - 0.5


def test_wide_shrub_patch_interior_is_mostly_ground_with_the_offset():
    """Documents a limit: a patch much wider than the large scale (12 m against 2 m) lifts the
    large-scale mean too; its interior differences are only the shrub's roughness around 0, and
    with the offset most of the interior is called ground."""
    xyz, shrub, _ = shrub_scene((9.0, 21.0, 9.0, 21.0), margin=2.0)
    x, y = xyz[:, 0] - X0, xyz[:, 1] - Y0
    core = (x > 11.0) & (x < 19.0) & (y > 11.0) & (y < 19.0)
    res = EVC(ground_offset_m=0.1).run(xyz)
    assert res.ground[core].mean() > 0.5


@pytest.mark.parametrize("density", [1.0, 5.0, 20.0])
@pytest.mark.parametrize("offset", [0.0, 0.1])
def test_sparse_clouds_do_not_collapse(density, offset):
    """At 1-20 points/m² most 0.2 m cells are empty; windows grow over them. Every point still
    gets a class (its cell is not empty) and the run completes."""
    xyz = plane(density, noise=0.03, seed=int(density))
    res = EVC(ground_offset_m=offset).run(xyz)
    cls = point_classes(res, xyz)
    assert np.isin(cls, (GROUND, VEGETATION_AREA, VEGETATION_BOUNDARY)).all()
    np.testing.assert_array_equal(res.ground, cls == GROUND)
    assert res.ground.shape == (len(xyz),)
    occupied = ~np.isnan(res.small_mean)
    assert (res.classes[occupied] != EMPTY).all() and (res.classes[~occupied] == EMPTY).all()
    assert occupied.mean() < 0.7  # sparse indeed
    # Almost every occupied cell has an EVC (found enough neighbours within max_radius).
    assert np.isfinite(res.evc[occupied]).mean() > 0.9


@pytest.mark.parametrize("seed", [0, 1])
def test_sparse_noisy_plane_with_offset_is_mostly_ground(seed):
    xyz = plane(5.0, noise=0.03, seed=seed)
    res = EVC(ground_offset_m=0.1).run(xyz)
    assert res.ground.mean() >= 0.9


def test_one_point_per_far_apart_cluster_gets_no_evc():
    """Two lone points 10 m apart: each window reaches max_radius (1 m at 0.2 m cells) with one
    value only: no EVC, 'vegetation boundary', not ground."""
    xyz = np.array([[X0, Y0, 100.0], [X0 + 10.0, Y0 + 10.0, 100.5]])
    res = EVC().run(xyz)
    assert np.isnan(res.evc).all()
    assert (point_classes(res, xyz) == VEGETATION_BOUNDARY).all()
    assert not res.ground.any()


# --- natural breaks ---------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 2])
def test_natural_break_separates_two_clusters(seed):
    rng = np.random.default_rng(seed)
    low = rng.uniform(0.2, 0.6, 300)
    high = rng.uniform(3.0, 4.0, 200)
    values = np.concatenate([low, high, [-1.0, 0.0, np.nan, np.inf, -np.inf]])
    rng.shuffle(values)
    t = natural_break(values.reshape(-1, 5))
    assert low.max() <= t < high.min()
    assert t == pytest.approx(low.max())  # the largest value of the lower class


@pytest.mark.parametrize("values", [[], [0.5], [0.5, -1.0, 0.0, np.nan, np.inf], [-1.0, -2.0, 0.0],
                                    [np.nan, np.nan]], ids=["none", "one", "one_positive", "non_positive", "nan"])
def test_natural_break_refuses_fewer_than_two_positive_values(values):
    with pytest.raises(InvalidParameterError, match="too few positive EVC values"):
        natural_break(np.array(values, dtype=float))


def test_natural_break_with_two_values_is_refused_too():
    """Documents: with exactly two positive values the upper one is above the 95th percentile
    and is trimmed first, so two values are refused as well; three are enough."""
    with pytest.raises(InvalidParameterError):
        natural_break(np.array([0.5, 3.0]))
    assert natural_break(np.array([0.5, 0.6, 3.0])) == 0.5


def test_auto_threshold_uses_natural_break():
    xyz, _, _ = shrub_scene(SHRUBS["4m"][0], density=10.0)
    res = EVC(auto_threshold=True, ground_offset_m=0.1).run(xyz)
    assert res.threshold == natural_break(res.evc)
    assert res.threshold != 1.5
    fixed = EVC(threshold=res.threshold, ground_offset_m=0.1).run(xyz)
    np.testing.assert_array_equal(res.classes, fixed.classes)
    np.testing.assert_array_equal(res.ground, fixed.ground)
    np.testing.assert_array_equal(res.evc, fixed.evc)


def test_natural_breaks_keep_every_value_with_breaks_percentile_100():
    """The trim of the EVC values above the 95th percentile before natural breaks is ours (the paper
    says natural breaks only, and a reviewer's untrimmed break measured better on his scene): the
    paper's untrimmed break is breaks_percentile=100."""
    xyz, _, _ = shrub_scene(SHRUBS["4m"][0], density=10.0)
    trimmed = EVC(auto_threshold=True, ground_offset_m=0.1).run(xyz)
    whole = EVC(auto_threshold=True, ground_offset_m=0.1, breaks_percentile=100.0).run(xyz)
    assert whole.threshold == natural_break(whole.evc, upper_percentile=100.0)
    assert whole.threshold != trimmed.threshold
    for bad in (0.0, -5.0, 101.0, math.nan):
        with pytest.raises(InvalidParameterError, match="breaks_percentile"):
            EVC(breaks_percentile=bad)


# --- parameters and inputs ----------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, name", [
    ({"radius": 0}, "radius"),
    ({"radius": -1}, "radius"),
    ({"radius": 1.5}, "radius"),
    ({"radius": 2.0}, "radius"),
    ({"radius": None}, "radius"),
    ({"radius": True}, "radius"),
    ({"min_cells": 1}, "min_cells"),
    ({"min_cells": 2.5}, "min_cells"),
    ({"max_radius": 0}, "max_radius"),
    ({"radius": 3, "max_radius": 2}, "max_radius"),
    ({"max_radius": None}, "max_radius"),
    ({"small_scale_m": 0.0}, "small_scale_m"),
    ({"small_scale_m": -0.2}, "small_scale_m"),
    ({"small_scale_m": math.nan}, "small_scale_m"),
    ({"small_scale_m": None}, "small_scale_m"),
    ({"small_scale_m": 2.0}, "large_scale_m"),
    ({"small_scale_m": 3.0}, "large_scale_m"),
    ({"large_scale_m": 0.1}, "large_scale_m"),
    ({"large_scale_m": math.inf}, "large_scale_m"),
    ({"large_scale_m": None}, "large_scale_m"),
    ({"threshold": 0.0}, "threshold"),
    ({"threshold": -1.0}, "threshold"),
    ({"threshold": math.nan}, "threshold"),
    ({"threshold": None}, "threshold"),
    ({"ground_offset_m": -0.1}, "ground_offset_m"),
    ({"ground_offset_m": math.inf}, "ground_offset_m"),
    ({"ground_offset_m": None}, "ground_offset_m"),
    ({"point_tolerance_m": -0.3}, "point_tolerance_m"),
    ({"point_tolerance_m": math.nan}, "point_tolerance_m"),
    ({"difference": "large-small"}, "difference"),
    ({"difference": None}, "difference"),
])
def test_invalid_parameters_name_the_parameter(kwargs, name):
    with pytest.raises(InvalidParameterError) as info:
        EVC(**kwargs)
    assert name in str(info.value)


def test_small_scale_equal_to_large_names_both():
    with pytest.raises(InvalidParameterError) as info:
        EVC(small_scale_m=2.0, large_scale_m=2.0)
    assert "large_scale_m" in str(info.value) and "small_scale_m" in str(info.value)


def test_valid_edge_parameters():
    EVC(radius=1, max_radius=1, min_cells=2, threshold=1e-6, ground_offset_m=0.0)
    EVC(radius=np.int64(2), max_radius=np.int32(3))
    EVC(small_scale_m=0.1, large_scale_m=0.11)


@pytest.mark.parametrize("size", [1.9, 1.0, 0.0])
def test_large_scale_larger_than_the_cloud_is_refused(size):
    rng = np.random.default_rng(0)
    xyz = np.column_stack([X0 + rng.uniform(0, size, 200), Y0 + rng.uniform(0, size, 200), np.full(200, 100.0)])
    with pytest.raises(InvalidParameterError, match="larger than the cloud") as info:
        EVC().run(xyz)
    assert "large_scale_m" in str(info.value)


def test_large_scale_within_the_cloud_along_one_axis_is_accepted():
    """A 30 x 1 m strip spans 30 m: the 2 m large scale is fine."""
    rng = np.random.default_rng(1)
    n = 3000
    xyz = np.column_stack([X0 + rng.uniform(0, 30, n), Y0 + rng.uniform(0, 1, n), 100 + rng.normal(0, 0.03, n)])
    res = EVC(ground_offset_m=0.1).run(xyz)
    assert res.ground.mean() > 0.9


def test_progress_is_monotonic_and_complete():
    seen = []
    EVC(small_scale_m=0.5).run(oracle_cloud(7), Steps(progress=seen.append))
    assert seen and seen[-1] == pytest.approx(1.0)
    assert all(b >= a for a, b in zip(seen, seen[1:]))


def test_through_the_driver():
    """EVC asks for no point field: the driver gives it the selected x, y, z only."""
    xyz = plane(10.0, size=20.0, noise=0.03, seed=8)
    n = len(xyz)
    cls = np.ones(n, np.uint8)
    cls[:5] = 7
    xyz[:5, 2] -= 30.0  # noise far below: would wreck the means if it were filtered
    cloud = PointCloud(path="memory", x=xyz[:, 0].copy(), y=xyz[:, 1].copy(), z=xyz[:, 2].copy(),
                       classification=cls, return_number=np.ones(n, np.uint8),
                       number_of_returns=np.ones(n, np.uint8))
    done = classify_cloud(cloud, EVC(ground_offset_m=0.1))
    direct = EVC(ground_offset_m=0.1).run(xyz[5:])
    np.testing.assert_array_equal(done.ground[5:], direct.ground)
    assert not done.ground[:5].any() and (done.classification[:5] == 7).all()
    np.testing.assert_array_equal(done.detail.classes, direct.classes)


def test_the_threshold_natural_breaks_chose_is_said_and_a_tiled_run_warns(tmp_path):
    """A reviewer never saw the threshold natural breaks picked (the log said THRESHOLD 1.5), and a
    tiled run picked one per tile without a word: a run logs the value, a tiled run says what
    per-tile thresholds mean."""
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
    from groundsieve.core.io import new_las, write_las
    xyz, _, _ = shrub_scene(SHRUBS["4m"][0], density=10.0)
    path = str(tmp_path / "shrubs.laz")
    write_las(new_las(xyz[:, 0] + 500000.0, xyz[:, 1] + 5400000.0, xyz[:, 2]), path)
    from groundsieve.core.io import read_cloud
    chosen = EVC(auto_threshold=True, ground_offset_m=0.1).run(read_cloud(path).xyz).threshold  # (as written)
    lines = []
    run_ground_filter(path, str(tmp_path / "o.laz"), EVC(auto_threshold=True, ground_offset_m=0.1), log=lines.append)
    assert f"EVC: natural breaks chose the threshold {chosen:.4g}." in lines
    lines = []
    run_ground_filter(path, str(tmp_path / "t.laz"), EVC(auto_threshold=True, ground_offset_m=0.1), log=lines.append,
                      options=FilterOptions(tiling=TileOptions(tile_size_m=20.0, workers=1, parallel="threads")))
    assert any(line.startswith("EVC: natural breaks picks its threshold in each tile") for line in lines)
    lines = []
    run_ground_filter(path, str(tmp_path / "u.laz"), EVC(), log=lines.append,
                      options=FilterOptions(tiling=TileOptions(tile_size_m=20.0, workers=1, parallel="threads")))
    assert not any("natural breaks" in line for line in lines)
