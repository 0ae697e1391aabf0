"""The harmonic fill's iterative path (multigrid-preconditioned conjugate gradients on large holes)
gives the direct sparse solve's fill."""
from __future__ import annotations

import numpy as np
import pytest

from groundsieve.core.grids import inpaint
from groundsieve.core.grids.inpaint import inpaint_harmonic


def direct(grid):
    out = np.array(grid, dtype=np.float64)
    missing = np.isnan(out)
    out[missing] = inpaint._direct(out, missing)
    return out


def sparse_cloud_grid(shape=(180, 230), known_share=0.15, seed=0):
    """Like the 1 m minimum surface of a sparse rural ISPRS sample: a few known cells in one large hole."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    grid = 250.0 + 0.2 * rows - 0.1 * cols + 5.0 * np.sin(cols / 17.0) + rng.normal(0, 0.5, shape)
    grid[rng.random(shape) > known_share] = np.nan
    return grid


@pytest.mark.parametrize("case", ["sparse", "lake", "two cells", "strip", "one row", "one column"])
def test_large_holes_match_the_direct_solve(case):
    rng = np.random.default_rng(3)
    if case == "sparse":
        grid = sparse_cloud_grid()
    elif case == "lake":
        grid = rng.normal(120.0, 10.0, (150, 170))
        grid[20:140, 15:160] = np.nan
    elif case == "two cells":
        grid = np.full((97, 131), np.nan)
        grid[0, 0], grid[96, 60] = 5.0, 80.0
    elif case == "strip":  # a long thin hole
        grid = rng.normal(30.0, 1.0, (40, 2000))
        grid[18:21, 5:1995] = np.nan
    elif case == "one row":
        grid = rng.normal(0.0, 3.0, (1, 9000))
        grid[0, 100:8900] = np.nan
    else:
        grid = rng.normal(0.0, 3.0, (9000, 1))
        grid[100:8900, 0] = np.nan
    assert np.count_nonzero(np.isnan(grid)) > inpaint.DIRECT_MAX_CELLS
    out = inpaint_harmonic(grid)
    ref = direct(grid)
    known = ~np.isnan(grid)
    np.testing.assert_array_equal(out[known], grid[known])
    span = np.nanmax(grid) - np.nanmin(grid)
    assert np.abs(out - ref).max() <= 1e-11 * max(span, 1.0)


def test_many_large_holes_in_one_solve_and_small_ones_direct(monkeypatch):
    rng = np.random.default_rng(5)
    grid = rng.normal(10.0, 2.0, (120, 160))
    for r in range(0, 120, 30):
        for c in range(0, 160, 40):
            grid[r + 2:r + 20, c + 3:c + 30] = np.nan      # 12 large holes
            grid[r + 24, c + 35] = np.nan                  # and small ones
    ref = direct(grid)
    separate = inpaint_harmonic(grid)
    monkeypatch.setattr(inpaint, "DIRECT_MAX_CELLS", 100)
    monkeypatch.setattr(inpaint, "MAX_SEPARATE_HOLES", 4)   # 12 > 4: one solve over the whole grid
    together = inpaint_harmonic(grid)
    np.testing.assert_allclose(together, ref, rtol=0, atol=1e-10)
    np.testing.assert_allclose(separate, ref, rtol=0, atol=1e-10)


def test_no_convergence_falls_back_to_the_direct_solve(monkeypatch):
    grid = sparse_cloud_grid((90, 100), seed=1)
    monkeypatch.setattr(inpaint, "MAX_ITERATIONS", 1)
    calls = []
    real = inpaint._direct
    monkeypatch.setattr(inpaint, "_direct", lambda g, m: calls.append(int(m.sum())) or real(g, m))
    out = inpaint_harmonic(grid)
    assert calls and max(calls) > inpaint.DIRECT_MAX_CELLS
    np.testing.assert_array_equal(out, direct(grid))


def test_constant_boundary_fills_the_constant():
    grid = np.full((80, 90), 7.25)
    grid[5:75, 5:85] = np.nan
    np.testing.assert_array_equal(inpaint_harmonic(grid), np.full((80, 90), 7.25))
