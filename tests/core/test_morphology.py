"""Disk morphology of core.grids.morphology against a plain-numpy oracle."""
from __future__ import annotations

import numpy as np
import pytest

from groundsieve.core.errors import InvalidParameterError
from groundsieve.core.grids.morphology import dilate, disk, erode, opening, progressive_filter

SHAPES = [(1, 1), (1, 9), (9, 1), (2, 3), (3, 2), (5, 7), (13, 4), (4, 13), (17, 19)]
RADII = range(0, 7)


def offsets(radius: int):
    """(dy, dx) with dx² + dy² <= r², built independently of core.grids.morphology.disk."""
    return [(dy, dx) for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)
            if dx * dx + dy * dy <= radius * radius]


def oracle(grid: np.ndarray, radius: int, reduce) -> np.ndarray:
    """Min or max over the disk, cells outside the grid ignored."""
    nrows, ncols = grid.shape
    out = np.empty(grid.shape, dtype=np.float64)
    offs = offsets(radius)
    for i in range(nrows):
        for j in range(ncols):
            vals = [grid[i + dy, j + dx] for dy, dx in offs
                    if 0 <= i + dy < nrows and 0 <= j + dx < ncols]
            out[i, j] = reduce(vals)
    return out


def random_grid(shape, seed, ties=False):
    rng = np.random.default_rng(seed)
    if ties:  # few distinct values: many ties
        return rng.integers(0, 4, size=shape).astype(np.float64)
    return rng.normal(100.0, 5.0, size=shape)


@pytest.mark.parametrize("radius", RADII)
def test_disk_footprint(radius):
    fp = disk(radius)
    assert fp.shape == (2 * radius + 1, 2 * radius + 1)
    expected = {(dy + radius, dx + radius) for dy, dx in offsets(radius)}
    assert set(zip(*np.nonzero(fp))) == expected
    assert fp[radius, radius]
    np.testing.assert_array_equal(fp, fp.T)
    np.testing.assert_array_equal(fp, fp[::-1, :])


def test_disk_known_sizes():
    assert [int(disk(r).sum()) for r in range(5)] == [1, 5, 13, 29, 49]


@pytest.mark.parametrize("shape", SHAPES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("radius", RADII)
@pytest.mark.parametrize("ties", [False, True], ids=["distinct", "ties"])
def test_erode_dilate_match_oracle(shape, radius, ties):
    grid = random_grid(shape, seed=hash((shape, radius, ties)) % 2**32, ties=ties)
    before = grid.copy()
    np.testing.assert_array_equal(erode(grid, radius), oracle(grid, radius, min))
    np.testing.assert_array_equal(dilate(grid, radius), oracle(grid, radius, max))
    np.testing.assert_array_equal(grid, before)  # input untouched


@pytest.mark.parametrize("shape", SHAPES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("radius", RADII)
def test_opening_matches_oracle_and_is_an_opening(shape, radius):
    grid = random_grid(shape, seed=1000 + radius + 31 * shape[0] + shape[1])
    opened = opening(grid, radius)
    np.testing.assert_array_equal(opened, oracle(oracle(grid, radius, min), radius, max))
    assert (opened <= grid).all(), "opening must be anti-extensive"
    np.testing.assert_array_equal(opening(opened, radius), opened)  # idempotent


def test_radius_zero_is_identity():
    grid = random_grid((6, 5), seed=3)
    for fn in (erode, dilate, opening):
        np.testing.assert_array_equal(fn(grid, 0), grid)


def test_radius_larger_than_grid():
    grid = random_grid((3, 4), seed=4)
    np.testing.assert_array_equal(erode(grid, 6), np.full(grid.shape, grid.min()))
    np.testing.assert_array_equal(dilate(grid, 6), np.full(grid.shape, grid.max()))


def test_non_contiguous_and_integer_input():
    grid = random_grid((7, 11), seed=5)
    view = grid.T  # Fortran-ordered view
    np.testing.assert_array_equal(erode(view, 2), oracle(np.ascontiguousarray(view), 2, min))
    ints = np.arange(20).reshape(4, 5)
    np.testing.assert_array_equal(dilate(ints, 1), oracle(ints.astype(float), 1, max))
    assert erode(ints, 1).dtype == np.float64


def test_opening_removes_narrow_peaks_keeps_wide_ones():
    grid = np.zeros((15, 15))
    grid[2, 2] = 5.0               # one cell: removed by any disk of radius >= 1
    grid[6:13, 6:13] = 3.0         # 7x7 block: holds a disk of radius 3, not 4
    np.testing.assert_array_equal(opening(grid, 1)[2, 2], 0.0)
    np.testing.assert_array_equal(opening(grid, 3)[6:13, 6:13].max(), 3.0)
    assert opening(grid, 3)[9, 9] == 3.0
    assert opening(grid, 4).max() == 0.0


@pytest.mark.parametrize("bad", [-1, 1.5, 2.0000001])
def test_invalid_radius(bad):
    with pytest.raises(InvalidParameterError, match="radius"):
        erode(np.zeros((3, 3)), bad)
    with pytest.raises(InvalidParameterError, match="radius"):
        dilate(np.zeros((3, 3)), bad)


def test_grid_must_be_2d():
    with pytest.raises(InvalidParameterError, match="2-D"):
        erode(np.zeros(5), 1)
    with pytest.raises(InvalidParameterError, match="2-D"):
        dilate(np.zeros((2, 2, 2)), 1)


# --- progressive filter -------------------------------------------------------------------

def tilted_plane(shape=(40, 40), gx=0.05, gy=0.02, cell=1.0):
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    return 100.0 + gx * cols * cell + gy * rows * cell


@pytest.mark.parametrize("gradient", [(0.0, 0.0), (0.05, 0.02), (-0.1, 0.08)])
def test_progressive_filter_plane_is_not_object(gradient):
    surface = tilted_plane(gx=gradient[0], gy=gradient[1])
    obj = progressive_filter(surface, range(1, 11), 1.0, 0.15)
    assert obj.dtype == bool and obj.shape == surface.shape
    assert not obj.any()


@pytest.mark.parametrize("cell", [1.0, 0.5, 2.0])
def test_progressive_filter_flags_exactly_a_box_on_a_plane(cell):
    surface = tilted_plane(cell=cell)
    box = np.zeros(surface.shape, dtype=bool)
    box[15:23, 12:20] = True           # 8 x 8 cells, 10 m high
    surface[box] += 10.0
    obj = progressive_filter(surface, range(1, 11), cell, 0.15)
    np.testing.assert_array_equal(obj, box)


def test_progressive_filter_box_wider_than_window_is_kept():
    """A flat top wider than the largest window is (correctly) not an object for this step."""
    surface = tilted_plane()
    surface[5:35, 5:35] += 10.0        # 30 x 30 cells, window radius 5 (11 cells)
    obj = progressive_filter(surface, range(1, 6), 1.0, 0.15)
    assert not obj[12:28, 12:28].any()


def test_progressive_filter_reports_steps():
    seen = []

    class Rec:
        def report(self, fraction):
            seen.append(fraction)

    progressive_filter(tilted_plane((10, 10)), [1, 2, 3, 4], 1.0, 0.15, steps=Rec())
    assert seen == [0.25, 0.5, 0.75, 1.0]
