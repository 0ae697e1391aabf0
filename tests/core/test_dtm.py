"""TIN DTM rasterization (core.grids.rasterize.tin_dtm) and the grid convention (core.grids.spec)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import Delaunay

from groundsieve.core.errors import InputError, InvalidParameterError
from groundsieve.core.grids.spec import GridSpec
from groundsieve.core.grids.rasterize import cell_mean, cell_min, tin_dtm

X0, Y0 = 512000.0, 5403000.0
A, B, C = 0.13, -0.07, 250.0


def plane(x, y):
    return A * (x - X0) + B * (y - Y0) + C


def random_points(n=300, seed=0, w=50.0, h=40.0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, w, n) + X0
    y = rng.uniform(0, h, n) + Y0
    return x, y, plane(x, y)


def centre_mesh(grid):
    xs, ys = grid.centers()
    return np.meshgrid(xs, ys)


def inside_hull(x, y, grid):
    X, Y = centre_mesh(grid)
    tri = Delaunay(np.column_stack([x - X0, y - Y0]))
    return tri.find_simplex(np.column_stack([X.ravel() - X0, Y.ravel() - Y0])).reshape(X.shape) >= 0


@pytest.mark.parametrize("cell", [1.0, 0.5, 2.5])
def test_plane_reproduced_inside_hull_nan_outside(cell):
    x, y, z = random_points()
    grid = GridSpec.covering(x, y, cell)
    dtm = tin_dtm(x, y, z, grid)
    assert dtm.shape == grid.shape
    X, Y = centre_mesh(grid)
    inside = inside_hull(x, y, grid)
    assert inside.sum() > 0.7 * inside.size
    np.testing.assert_allclose(dtm[inside], plane(X, Y)[inside], rtol=0, atol=1e-9)
    assert np.isnan(dtm[~inside]).all()


def test_row_zero_is_north():
    x, y, z = random_points(seed=1)
    grid = GridSpec.covering(x, y, 1.0)
    dtm = tin_dtm(x, y, z, grid)
    # B < 0: z falls northwards, so the mean of the first row is the lowest
    rows = np.nanmean(dtm, axis=1)
    assert rows[1] < rows[-2]
    assert np.all(np.diff(rows[1:-1]) > 0)


def test_fill_outside_hull():
    x, y, z = random_points(seed=2)
    grid = GridSpec.covering(x, y, 1.0)
    dtm = tin_dtm(x, y, z, grid)
    filled = tin_dtm(x, y, z, grid, fill_outside=True)
    assert np.isfinite(filled).all()
    inside = ~np.isnan(dtm)
    np.testing.assert_array_equal(filled[inside], dtm[inside])
    # Every filled cell takes the value of some interpolated cell (nearest neighbour).
    assert np.isin(filled[~inside], dtm[inside]).all()


def test_duplicated_xy_keeps_the_lowest():
    x, y, z = random_points(seed=3)
    xd = np.concatenate([x, x[:100], x[:50]])
    yd = np.concatenate([y, y[:100], y[:50]])
    zd = np.concatenate([z, z[:100] + 5.0, z[:50] + 0.5])  # higher duplicates: ignored
    rng = np.random.default_rng(4)
    perm = rng.permutation(xd.size)
    grid = GridSpec.covering(x, y, 1.0)
    dtm = tin_dtm(xd[perm], yd[perm], zd[perm], grid)
    X, Y = centre_mesh(grid)
    inside = inside_hull(x, y, grid)
    np.testing.assert_allclose(dtm[inside], plane(X, Y)[inside], atol=1e-9)


def test_exact_duplicates_ok():
    x, y, z = random_points(seed=5)
    grid = GridSpec.covering(x, y, 1.0)
    dtm = tin_dtm(np.tile(x, 3), np.tile(y, 3), np.tile(z, 3), grid)
    np.testing.assert_array_equal(dtm, tin_dtm(x, y, z, grid))


def test_points_on_a_lattice_hit_cell_centres():
    xs = X0 + 0.5 + np.arange(10.0)
    ys = Y0 + 0.5 + np.arange(8.0)
    X, Y = np.meshgrid(xs, ys)
    x, y = X.ravel(), Y.ravel()
    grid = GridSpec.covering(x, y, 1.0)
    dtm = tin_dtm(x, y, plane(x, y), grid)
    assert np.isfinite(dtm).all()  # every centre is a vertex or on an edge (eps)
    Xc, Yc = centre_mesh(grid)
    np.testing.assert_allclose(dtm, plane(Xc, Yc), atol=1e-9)


@pytest.mark.parametrize("pts", [
    [[X0 + 1.2, Y0 + 3.4, 5.0]],
    [[X0 + 1.2, Y0 + 3.4, 5.0], [X0 + 7.5, Y0 + 2.5, 6.0]],
    [[X0, Y0, 1.0], [X0 + 1, Y0 + 1, 2.0], [X0 + 2, Y0 + 2, 3.0]],
    [[X0, Y0, 1.0], [X0 + 1, Y0 + 1, 2.0], [X0 + 2, Y0 + 2, 3.0], [X0 + 3, Y0 + 3, 4.0]],
    [[X0 + t, Y0 + 5.0, t] for t in range(12)],
    [[X0 + 2.0, Y0 + t, t] for t in range(12)],
    [[X0 + 1.2, Y0 + 3.4, 5.0]] * 4,
], ids=["one", "two", "collinear3", "collinear4", "row", "column", "same-xy"])
@pytest.mark.parametrize("fill", [False, True], ids=["nofill", "fill"])
def test_few_or_collinear_points_do_not_crash(pts, fill):
    pts = np.asarray(pts, dtype=np.float64)
    grid = GridSpec.covering(pts[:, 0], pts[:, 1], 1.0)
    dtm = tin_dtm(pts[:, 0], pts[:, 1], pts[:, 2], grid, fill_outside=fill)
    assert dtm.shape == grid.shape
    # The cells holding the points carry (the lowest of) their values.
    cells = dtm[grid.row_of(pts[:, 1]), grid.col_of(pts[:, 0])]
    assert np.isfinite(cells).all()
    if fill:
        assert np.isfinite(dtm).all()
        assert dtm.min() >= pts[:, 2].min() and dtm.max() <= pts[:, 2].max()


def test_no_points_raises():
    grid = GridSpec(0.0, 10.0, 1.0, 10, 10)
    with pytest.raises(InputError, match="no ground points"):
        tin_dtm(np.array([]), np.array([]), np.array([]), grid)


# --- grid convention and per-cell statistics -----------------------------------------------

def test_grid_covering_convention():
    x = np.array([10.2, 14.9, 12.0])
    y = np.array([20.1, 23.0, 25.0])  # ymax exactly on an edge: it lies in row 0, (24, 25]
    g = GridSpec.covering(x, y, 1.0)
    assert g.x0 == 10.0 and g.top == 25.0
    assert g.geotransform == (10.0, 1.0, 0.0, 25.0, 0.0, -1.0)
    assert g.shape == (5, 5)
    np.testing.assert_array_equal(g.col_of(x), [0, 4, 2])
    # Rows are closed at their north edge: y = 23.0 lies in row 2, which covers (22, 23].
    np.testing.assert_array_equal(g.row_of(y), [4, 2, 0])
    xs, ys = g.centers()
    np.testing.assert_allclose(xs, 10.5 + np.arange(5))
    np.testing.assert_allclose(ys, 24.5 - np.arange(5))


@pytest.mark.parametrize("cell", [0.0, -1.0, float("nan"), float("inf")])
def test_grid_cell_must_be_positive(cell):
    with pytest.raises(InvalidParameterError, match="cell size"):
        GridSpec.covering(np.array([0.0, 1.0]), np.array([0.0, 1.0]), cell)


def test_grid_refuses_absurd_size():
    with pytest.raises(InvalidParameterError, match="larger cell size"):
        GridSpec.covering(np.array([0.0, 1e6]), np.array([0.0, 1e6]), 0.01)


def test_cell_min_and_mean():
    g = GridSpec(0.0, 2.0, 1.0, 2, 2)
    x = np.array([0.2, 0.7, 1.5, 1.5])
    y = np.array([1.5, 1.2, 0.5, 0.4])
    z = np.array([3.0, 1.0, 7.0, 9.0])
    mins = cell_min(x, y, z, g)
    np.testing.assert_array_equal(mins, [[1.0, np.nan], [np.nan, 7.0]])
    mean, count = cell_mean(x, y, z, g)
    np.testing.assert_array_equal(mean, [[2.0, np.nan], [np.nan, 8.0]])
    np.testing.assert_array_equal(count, [[2, 0], [0, 2]])


@pytest.mark.parametrize("ppc", [1, 4, 9])
def test_thinning_kernel_equals_the_sort(ppc):
    """The one-pass kernel of thin_for_grid keeps the same points in the same order as the
    sort it replaces, ties included (repeated positions with other heights, points on sub-cell
    edges and at equal distances from a centre)."""
    from groundsieve.core.grids.rasterize import _thin_sorted, thin_for_grid
    rng = np.random.default_rng(ppc)
    x = X0 + np.r_[rng.uniform(0, 60, 3000), np.repeat(rng.uniform(0, 60, 200), 3), np.arange(0, 60, 0.25)]
    y = Y0 + np.r_[rng.uniform(0, 40, 3000), np.repeat(rng.uniform(0, 40, 200), 3), np.full(240, 20.0)]
    z = np.r_[rng.normal(250, 1, 3000), rng.choice([250.0, 251.0], 600), np.full(240, 250.0)]
    grid = GridSpec.covering(x, y, 0.5)
    k = int(np.sqrt(ppc))
    kept = thin_for_grid(x, y, z, grid, ppc)
    np.testing.assert_array_equal(kept, _thin_sorted(x, y, z, grid, k))
    assert kept.size < x.size


@pytest.mark.parametrize("band", [1, 7, 64])
def test_parallel_rasterization_equals_serial(band):
    """Bands of rows in parallel give bit for bit the serial raster, shared edges included
    (cell centres on a regular point grid's edges)."""
    from groundsieve.core.grids.rasterize import rasterize_tin
    from groundsieve.core.grids.triangulate import delaunay
    rng = np.random.default_rng(band)
    x = np.r_[rng.uniform(0, 80, 2000), np.repeat(np.arange(0, 20.0, 1.0), 20)] + X0
    y = np.r_[rng.uniform(0, 60, 2000), np.tile(np.arange(0, 20.0, 1.0), 20)] + Y0
    xy = np.unique(np.column_stack([x, y]), axis=0)
    x, y = xy[:, 0], xy[:, 1]
    z = np.sin(x / 3) + np.cos(y / 4) + 250
    grid = GridSpec.covering(x, y, 0.5)
    tri = delaunay(x, y)
    serial = rasterize_tin(x, y, z, tri, grid, np.full(grid.shape, np.nan), parallel=False)
    banded = rasterize_tin(x, y, z, tri, grid, np.full(grid.shape, np.nan), parallel=True, band_rows=band)
    assert np.isfinite(serial).mean() > 0.9
    np.testing.assert_array_equal(banded, serial)


def _scene_ground(seed=3):
    from groundsieve.core.synthetic import SceneSpec, make_scene
    scene = make_scene(SceneSpec(size_m=120, density_per_m2=6, seed=seed))
    g = scene.ground
    return scene.x[g], scene.y[g], scene.z[g]


def _strips_against_one(monkeypatch, x, y, threads, buffer_m, buffer_cells=50):
    """The strips' DTM and the single triangulation's of ``z(x, y)``, and the strips' log line."""
    from groundsieve.core.grids import rasterize
    monkeypatch.setattr(rasterize, "STRIP_MIN_POINTS", 1000)  # a small scene takes the path too
    monkeypatch.setattr(rasterize, "STRIP_BUFFER_M", buffer_m)
    monkeypatch.setattr(rasterize, "STRIP_BUFFER_CELLS", buffer_cells)
    z = 0.01 * x + 0.02 * y + np.sin(x / 7.0) + np.cos(y / 5.0)
    grid = GridSpec.covering(x, y, 0.5)
    one = tin_dtm(x, y, z, grid, threads=1)
    logs = []
    strips = tin_dtm(x, y, z, grid, threads=threads, log=logs.append)
    return one, strips, [line for line in logs if "strips triangulated" in line][0]


def _assert_same_dtm(one, strips):
    assert np.isfinite(one).sum() > 1000
    assert np.array_equal(np.isnan(one), np.isnan(strips))
    assert np.nanmax(np.abs(one - strips)) < 1e-9


@pytest.mark.parametrize("threads", [2, 3])
def test_strips_in_threads_give_the_single_triangulation(monkeypatch, threads):
    """tin_dtm's parallel path (vertical strips, each with a buffer, in threads) on a generated
    scene (ground with holes under buildings): the single triangulation's DTM, border included
    (to 1e-9 m, NaN at the same cells)."""
    x, y, _ = _scene_ground()
    one, strips, log = _strips_against_one(monkeypatch, x, y, threads, 10.0, 0)
    assert f"{2 * threads} strips triangulated in {threads} threads" in log
    _assert_same_dtm(one, strips)


def _lake(rng, n=60_000):
    x, y = rng.uniform(0, 160, n), rng.uniform(0, 160, n)
    keep = (x - 80) ** 2 + (y - 80) ** 2 > 35 ** 2  # a 70 m wide hole across the strips' edges
    return x[keep], y[keep]


def _c_shape(rng, n=60_000):
    r, t = np.sqrt(rng.uniform(50 ** 2, 80 ** 2, n)), rng.uniform(np.pi / 4, 7 * np.pi / 4, n)
    return 80 + r * np.cos(t), 80 + r * np.sin(t)


def _l_shape(rng, n=60_000):
    return (np.concatenate([rng.uniform(0, 160, n // 2), rng.uniform(0, 30, n // 2)]),
            np.concatenate([rng.uniform(0, 30, n // 2), rng.uniform(0, 160, n // 2)]))


@pytest.mark.parametrize("shape", [_lake, _c_shape, _l_shape])
def test_strips_give_the_single_triangulation_across_holes_and_concave_borders(monkeypatch, shape):
    """A hole or a concavity wider than the strip buffer next to a strip's edge: triangles there
    are not the single triangulation's (their circumcircle holds points beyond the buffer), so the
    strips must not keep them. With a 10 m buffer the strips are triangulated again 4 times wider;
    with 1 m even that misses cells, taken from one triangulation of all points. Both: the single
    triangulation's DTM (before: up to 1.75 m off, and 24,593 cells NaN on the strips only)."""
    rng = np.random.default_rng(1)
    x, y = shape(rng)
    one, strips, log = _strips_against_one(monkeypatch, x, y, 2, 10.0, 0)
    assert "again with a wider buffer" in log
    _assert_same_dtm(one, strips)
    one, strips, log = _strips_against_one(monkeypatch, x, y, 2, 1.0, 0)
    assert "cells from one triangulation of all points" in log
    _assert_same_dtm(one, strips)


def test_convex_hull_spans_follow_the_hull():
    """Per row, the x-interval of the points' convex hull (a triangle here), exactly."""
    from groundsieve.core.grids.rasterize import convex_hull_spans
    rng = np.random.default_rng(5)
    u, v = rng.uniform(0, 1, 5000), rng.uniform(0, 1, 5000)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    x = np.concatenate([[0.0, 100.0, 0.0], 100 * u])  # inside the triangle (0,0) (100,0) (0,100)
    y = np.concatenate([[0.0, 0.0, 100.0], 100 * v])
    grid = GridSpec(-10.0, 110.0, 1.0, 120, 120)
    lo, hi = convex_hull_spans(x, y, grid, shrink=0.0)
    cy = 110.0 - (np.arange(120) + 0.5)
    inside = (cy >= 0) & (cy <= 100)
    np.testing.assert_allclose(lo[inside], 0.0, atol=1e-9)
    np.testing.assert_allclose(hi[inside], 100.0 - cy[inside], atol=1e-9)
    assert (lo[~inside] > hi[~inside]).all()


def test_strip_cuts_share_the_points_evenly():
    from groundsieve.core.grids.rasterize import strip_cuts
    cols = np.repeat(np.arange(10), [100, 0, 0, 0, 0, 0, 0, 0, 0, 100])
    assert strip_cuts(cols, 10, 2) == [0, 1, 10]
    assert strip_cuts(np.arange(100) % 50, 50, 4) == [0, 13, 25, 38, 50]
    assert strip_cuts(np.zeros(5, dtype=np.int64), 1, 3) == [0, 1]


def test_a_cell_too_small_for_dense_points_is_blamed_on_the_cell_not_on_stray_points():
    """A survey's normal extent with a DTM cell of a millimetre: no point is far from the others,
    so the message names the cell size that fits instead of advising to class stray points."""
    from groundsieve.core.errors import MemoryBudgetError
    from groundsieve.core.grids.spec import memory_budget
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0, 200, 5000), rng.uniform(0, 200, 5000)
    with memory_budget(1 << 30), pytest.raises(MemoryBudgetError) as err:
        GridSpec.covering(x, y, 0.01, what="DTM", bytes_per_cell=40)
    text = str(err.value)
    assert "The points themselves span this extent: use a larger cell size (" in text
    assert "noise" not in text
    fits = float(text.split("larger cell size (")[1].split(" m")[0])
    with memory_budget(1 << 30):
        GridSpec.covering(x, y, fits, what="DTM", bytes_per_cell=40)  # the cell named fits
    with memory_budget(1 << 30):
        with pytest.raises(MemoryBudgetError):
            GridSpec.covering(x, y, fits * 0.9, what="DTM", bytes_per_cell=40)


def test_a_dtm_cell_larger_than_the_cloud_is_warned():
    """A cell of 1000 (a typo, or feet for metres) on a 450 x 300 m sample wrote a 1 x 1 DTM without a
    word (a geomorphologist); a DTM of fewer than 3 cells across is now a warning."""
    from groundsieve.core.engine.workflow import DTMOptions, make_dtm
    from groundsieve.core.progress import WARNING_PREFIX
    x, y, z = random_points()
    ground = np.ones(x.size, dtype=bool)
    for cell, warned in ((1000.0, True), (1.0, False)):
        lines = []
        grid, _dtm = make_dtm(x, y, z, ground, DTMOptions(cell_size_m=cell), log=lines.append)
        said = [line for line in lines if line.startswith(WARNING_PREFIX + "DTM: a cell of")]
        assert bool(said) == warned, lines
    assert said == [] and grid.ncols == 50
    # a corridor (400 x 2 cells) is a DTM of its own, not a typo
    lines = []
    make_dtm(x * 8 - 7 * X0, (y - Y0) / 20 + Y0, z, ground, DTMOptions(cell_size_m=1.0), log=lines.append)
    assert not any(line.startswith(WARNING_PREFIX + "DTM: a cell of") for line in lines), lines


def test_a_whole_run_names_the_gaps_in_the_data_it_interpolates_across():
    """A photogrammetry cloud with a pond that gave no point: the whole run's DTM interpolated across it
    without a word, while a tiled run warns about gaps wider than its buffer (a UAV practitioner). The
    run now names the gap, its size and where it is; a cloud without gaps, or a run that leaves gaps empty
    (a maximum distance), says nothing."""
    from groundsieve.core.engine.workflow import DTMOptions, make_dtm
    rng = np.random.default_rng(1)
    n = 300_000
    x, y = rng.uniform(0, 300, n), rng.uniform(0, 300, n)
    z = 100 + 0.02 * x + rng.normal(0, 0.02, n)
    pond = (x - 150) ** 2 + (y - 120) ** 2 < 40 ** 2
    said = {}
    for name, keep, options in (("pond", ~pond, DTMOptions()), ("none", np.ones(n, bool), DTMOptions()),
                                ("limited", ~pond, DTMOptions(max_distance_m=5.0))):
        logs = []
        make_dtm(x[keep], y[keep], z[keep], np.ones(int(keep.sum()), bool), options, log=logs.append)
        said[name] = [line for line in logs if "gap(s)" in line]
    assert not said["none"] and not said["limited"]
    (line,) = said["pond"]
    area = float(line.split("the largest about ")[1].split(" m²")[0].replace(",", ""))
    assert 0.85 * np.pi * 40 ** 2 < area <= np.pi * 40 ** 2  # the blocks wholly inside the pond
    assert "around x 150, y 120" in line and "1 gap(s)" in line


def test_a_closed_grid_s_origin_is_the_decimal_its_cell_stands_for():
    """With 0.3 m cells a DTM's origin was 500003.69999999995 (1666679 x 0.3 in floating point), and two
    epochs' cell centres matched exactly in 236 of 590 columns (a geomorphologist): the origin is the
    decimal on the cell's lattice now, the points' cells unchanged."""
    x = np.array([500003.75, 500010.0, 500003.7])
    y = np.array([4000001.25, 4000004.9, 4000005.1])
    g = GridSpec.covering(x, y, 0.3, closed=True)
    assert repr(g.x0) == "500003.7" and repr(g.top) == "4000005.3"
    assert g.shape == (14, 21)  # (500010.0 on the eastern edge of column 20)
    np.testing.assert_array_equal(g.col_of(x), [0, 20, 0])
    np.testing.assert_array_equal(g.row_of(y), [13, 1, 0])
    assert GridSpec.covering(x, y, 0.25, closed=True).x0 == 500003.5
    third = 1.0 / 3.0  # (a cell of no short decimal keeps its product)
    assert GridSpec.covering(x, y, third, closed=True).x0 == math.floor(500003.7 / third) * third


def test_a_sparse_survey_raster_is_read_back_only_where_it_was_written(tmp_path):
    """A DTM extent far wider than the survey made the tiled run read back its whole work raster for the pits,
    the empty cells and the blanking beyond the points (an HPC reviewer: 400 M cells, 4.8 GB, for 5 M values).
    Only the box of the written cells is read now, and the answers are those of the whole raster's."""
    from groundsieve.core.raster.geotiff import BlockGeoTIFF
    big = GridSpec(x0=0.0, top=20000.0, cell=1.0, nrows=20000, ncols=20000)  # 400 M cells, never allocated
    writer = BlockGeoTIFF(str(tmp_path / "work.tif"), big)
    reads = []
    band_read = writer._band.ReadAsArray

    class Band:  # (the GDAL band's reads counted)
        def __getattr__(self, name):
            return getattr(writer._band_real, name)

        def ReadAsArray(self, *args):  # noqa: N802
            reads.append(args[2] * args[3])
            return band_read(*args)
    writer._band_real, writer._band = writer._band, Band()
    block = np.full((100, 120), 50.0)
    block[40, 60] = 40.0  # an isolated pit 10 m deep
    block[10:13, 10:13] = np.nan  # a hole with values all around
    writer.write_block(5000, 7000, block)
    (pits, depth, row, col), _spikes = writer.isolated_pits_and_spikes()
    assert (pits, row, col) == (1, 5040, 7060) and depth == pytest.approx(10.0)
    enclosed, _inside = writer.empty_cells()
    assert enclosed == 9
    writer.blank_outside(GridSpec(x0=7000.0, top=15000.0, cell=1.0, nrows=50, ncols=120))  # (the block's top half)
    assert writer._last[5049] >= 0 and writer._last[5050] < 0  # (its bottom half blanked)
    assert max(reads) <= 110 * 130  # (the written box, with a halo of 2: never the 400 M cells)
    writer._band = writer._band_real
    writer.close()
