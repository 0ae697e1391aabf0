"""numba kernels of the hybrid filter's features (private; see core/learn/hybrid.py)."""
import math

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True)
def _bilinear(grid, fx, fy):
    """Bilinear value of ``grid`` at fractional (col, row) ``fx, fy`` of cell centres, clamped."""
    nrows, ncols = grid.shape
    fx = min(max(fx, 0.0), ncols - 1.0)
    fy = min(max(fy, 0.0), nrows - 1.0)
    c0 = min(int(math.floor(fx)), max(ncols - 2, 0))
    r0 = min(int(math.floor(fy)), max(nrows - 2, 0))
    c1 = min(c0 + 1, ncols - 1)
    r1 = min(r0 + 1, nrows - 1)
    tx = fx - c0
    ty = fy - r0
    top = grid[r0, c0] * (1.0 - tx) + grid[r0, c1] * tx
    bottom = grid[r1, c0] * (1.0 - tx) + grid[r1, c1] * tx
    return top * (1.0 - ty) + bottom * ty


@njit(cache=True, nogil=True, parallel=True)
def _point_features_into(x, y, z, surfaces, surface_mode, zmin_raw, zmax_raw, x0, top, cell, column, out):
    """The values of :func:`_point_features_kernel` (its columns: one per surface, then the three
    column features), value j of point i written to ``out[i, column[j]]``, or not computed when
    ``column[j]`` is -1: a point's row is written at once, in the order the caller wants."""
    n = x.shape[0]
    k = surfaces.shape[0]
    nrows, ncols = zmin_raw.shape
    for i in prange(n):
        fx = (x[i] - x0) / cell - 0.5
        fy = (top - y[i]) / cell - 0.5
        for j in range(k):
            if column[j] >= 0:
                v = _bilinear(surfaces[j], fx, fy)
                out[i, column[j]] = z[i] - v if surface_mode[j] == 1 else v
        if column[k] >= 0 or column[k + 1] >= 0 or column[k + 2] >= 0:
            c = min(max(int(math.floor((x[i] - x0) / cell)), 0), ncols - 1)
            r = min(max(int(math.floor((top - y[i]) / cell)), 0), nrows - 1)
            lo = zmin_raw[r, c]
            hi = zmax_raw[r, c]
            if column[k] >= 0:
                out[i, column[k]] = z[i] - lo
            if column[k + 1] >= 0:
                out[i, column[k + 1]] = hi - lo
            if column[k + 2] >= 0:
                out[i, column[k + 2]] = (z[i] - lo) / (hi - lo) if hi > lo else 0.0


@njit(cache=True, nogil=True)
def _point_features_kernel(x, y, z, surfaces, surface_mode, zmin_raw, zmax_raw, x0, top, cell, out):
    """One row of ``out`` (n, n_surfaces + 3) per point.

    Column j < n_surfaces: the grid ``surfaces[j]`` interpolated bilinearly at the point (cell
    centres as nodes); ``surface_mode[j]`` 1 = height of the point above it (z - value), 0 = the
    value itself. Then three column features from the raw per-cell minimum and maximum of the
    point's own cell: z - min, max - min, and the rank (z - min) / (max - min) (0 when max = min).
    """
    column = np.arange(surfaces.shape[0] + 3)
    _point_features_into(x, y, z, surfaces, surface_mode, zmin_raw, zmax_raw, x0, top, cell, column, out)


@njit(cache=True, nogil=True)
def _block_occupancy(x, y, x0, y0, block, nx, ny, out):
    """``out[row, col]`` = True where a point falls in the ``block`` m block (col from ``x0``, row from ``y0``)."""
    for i in range(x.shape[0]):
        c = min(int((x[i] - x0) / block), nx - 1)
        r = min(int((y[i] - y0) / block), ny - 1)
        out[r, c] = True


@njit(cache=True, nogil=True, parallel=True)
def _block_label(x, y, x0, y0, block, nx, ny, labels, out):
    """``out[i]`` = ``labels`` of the block of point i."""
    for i in prange(x.shape[0]):
        c = min(int((x[i] - x0) / block), nx - 1)
        r = min(int((y[i] - y0) / block), ny - 1)
        out[i] = labels[r, c]
