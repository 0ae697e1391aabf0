"""Harmonic inpainting of NaN cells (core.grids.inpaint)."""
from __future__ import annotations

import numpy as np
import pytest

from groundsieve.core.errors import GroundSieveError, InputError
from groundsieve.core.grids.inpaint import inpaint_harmonic


def ramp(shape=(30, 40), a=0.3, b=-0.7, c=2.0):
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    return c + a * rows + b * cols


def test_known_cells_unchanged_and_holes_filled():
    rng = np.random.default_rng(0)
    grid = rng.normal(50.0, 3.0, size=(25, 31))
    holes = rng.random(grid.shape) < 0.3
    grid[holes] = np.nan
    before = grid.copy()
    out = inpaint_harmonic(grid)
    np.testing.assert_array_equal(out[~holes], grid[~holes])
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(np.isnan(grid), np.isnan(before))  # input not modified
    np.testing.assert_array_equal(grid[~holes], before[~holes])
    # Maximum principle: filled values stay within the range of the known ones.
    known = grid[~holes]
    assert out[holes].min() >= known.min() - 1e-9 and out[holes].max() <= known.max() + 1e-9


def test_linear_ramp_with_interior_holes_is_restored_exactly():
    truth = ramp()
    grid = truth.copy()
    grid[5:15, 8:20] = np.nan      # a large hole
    grid[20, 30] = np.nan          # a single cell
    grid[22:25, 3:5] = np.nan      # a small block
    rng = np.random.default_rng(1)
    scattered = rng.random(grid.shape) < 0.2
    scattered[0, :] = scattered[-1, :] = scattered[:, 0] = scattered[:, -1] = False  # border known
    grid[scattered] = np.nan
    out = inpaint_harmonic(grid)
    np.testing.assert_allclose(out, truth, rtol=0, atol=1e-9)


def test_holes_touching_the_border_are_bounded():
    truth = ramp((12, 12))
    grid = truth.copy()
    grid[0:4, 0:4] = np.nan
    out = inpaint_harmonic(grid)
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out[4:, :], truth[4:, :])
    known = truth[~np.isnan(grid)]
    assert known.min() - 1e-9 <= out[0:4, 0:4].min() and out[0:4, 0:4].max() <= known.max() + 1e-9


def test_one_dimensional_grids():
    row = np.array([[1.0, np.nan, np.nan, np.nan, 5.0]])
    np.testing.assert_allclose(inpaint_harmonic(row), [[1.0, 2.0, 3.0, 4.0, 5.0]], atol=1e-12)
    col = row.T
    np.testing.assert_allclose(inpaint_harmonic(col), [[1.0], [2.0], [3.0], [4.0], [5.0]], atol=1e-12)
    end = np.array([[np.nan, 2.0, np.nan]])  # ends: no gradient across the free edge
    np.testing.assert_allclose(inpaint_harmonic(end), [[2.0, 2.0, 2.0]], atol=1e-12)


def test_single_known_cell_fills_a_constant():
    grid = np.full((7, 9), np.nan)
    grid[3, 4] = 12.5
    np.testing.assert_allclose(inpaint_harmonic(grid), np.full((7, 9), 12.5), atol=1e-9)


@pytest.mark.parametrize("shape", [(1, 1), (4, 6), (1, 8)])
def test_all_nan_raises_the_core_error(shape):
    with pytest.raises(InputError, match="no value"):
        inpaint_harmonic(np.full(shape, np.nan))
    with pytest.raises(GroundSieveError):
        inpaint_harmonic(np.full(shape, np.nan))


def test_no_nan_returns_a_copy():
    grid = ramp((5, 6))
    out = inpaint_harmonic(grid)
    np.testing.assert_array_equal(out, grid)
    assert out is not grid
    assert not np.shares_memory(out, grid)
    out[0, 0] = -1.0
    assert grid[0, 0] == ramp((5, 6))[0, 0]


def test_float32_and_int_input_give_float64():
    grid = ramp((6, 6)).astype(np.float32)
    grid[2, 3] = np.nan
    out = inpaint_harmonic(grid)
    assert out.dtype == np.float64
    np.testing.assert_allclose(out[2, 3], ramp((6, 6))[2, 3], atol=1e-5)
    assert inpaint_harmonic(np.arange(6).reshape(2, 3)).dtype == np.float64
