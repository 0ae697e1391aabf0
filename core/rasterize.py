"""Points to grids: per-cell statistics and the TIN-interpolated DTM."""
from __future__ import annotations

import numpy as np

from .errors import InputError
from .grid import GridSpec


def _xyz(x, y, z):
    return (np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(y, dtype=np.float64),
            np.ascontiguousarray(z, dtype=np.float64))


def cell_min(x, y, z, grid: GridSpec) -> np.ndarray:
    """Lowest z per cell of ``grid``; NaN where a cell holds no point."""
    from ._kernels import _cell_min_kernel
    x, y, z = _xyz(x, y, z)
    out = np.empty(grid.shape, dtype=np.float64)
    _cell_min_kernel(x, y, z, grid.x0, grid.top, grid.cell, grid.nrows, grid.ncols, out)
    return out


def cell_mean(x, y, z, grid: GridSpec) -> tuple:
    """Mean z per cell (NaN where empty) and the point count per cell."""
    from ._kernels import _cell_mean_kernel
    x, y, z = _xyz(x, y, z)
    total = np.zeros(grid.shape, dtype=np.float64)
    count = np.zeros(grid.shape, dtype=np.int64)
    _cell_mean_kernel(x, y, z, grid.x0, grid.top, grid.cell, grid.nrows, grid.ncols, total, count)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return mean, count


def tin_dtm(x, y, z, grid: GridSpec, *, fill_outside: bool = False) -> np.ndarray:
    """DTM of ``grid`` by linear interpolation on the Delaunay triangulation of the
    points (normally the ground points). Cells whose centre is outside the convex
    hull are NaN, or with ``fill_outside`` take the value of the nearest filled cell.

    Points with the same x, y are reduced to the lowest one before triangulating.
    """
    from scipy.ndimage import distance_transform_edt
    from scipy.spatial import Delaunay, QhullError

    from ._kernels import _rasterize_tin_kernel
    x, y, z = _xyz(x, y, z)
    if x.size == 0:
        raise InputError("no ground points to make a DTM from")
    out = np.full(grid.shape, np.nan, dtype=np.float64)
    # Unique planimetric positions (lowest z first), relative coordinates for qhull's precision.
    order = np.lexsort((z, y, x))
    xs, ys, zs = x[order], y[order], z[order]
    keep = np.ones(xs.size, dtype=bool)
    keep[1:] = (xs[1:] != xs[:-1]) | (ys[1:] != ys[:-1])
    xs, ys, zs = xs[keep], ys[keep], zs[keep]
    ox, oy = float(xs.min()), float(ys.min())
    triangles = None
    if xs.size >= 3:
        try:
            triangles = Delaunay(np.column_stack([xs - ox, ys - oy])).simplices.astype(np.int64)
        except QhullError:
            triangles = None  # collinear points: no triangle
    if triangles is not None and triangles.size:
        _rasterize_tin_kernel(xs - ox, ys - oy, zs, np.ascontiguousarray(triangles),
                              grid.x0 - ox, grid.top - oy, grid.cell, out)
    else:
        # Fewer than three distinct positions, or all on a line: the cells holding them.
        out[grid.row_of(ys), grid.col_of(xs)] = zs
    if fill_outside:
        missing = np.isnan(out)
        if missing.all():
            out[grid.row_of(ys), grid.col_of(xs)] = zs
            missing = np.isnan(out)
        if missing.any():
            idx = distance_transform_edt(missing, return_distances=False, return_indices=True)
            out = out[tuple(idx)]
    return out
