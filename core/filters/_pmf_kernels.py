"""numba kernels of the progressive morphological filter (core.filters.pmf). Private: call them through
:mod:`groundsieve.core.filters.pmf`, which validates and casts first.

Square-window erosion and dilation are separable (a square is a row segment times a column
segment), and each 1-D pass uses the van Herk / Gil-Werman scheme: the line, padded with
``r`` neutral values (+inf for a minimum, -inf for a maximum) at both ends, is cut into blocks
of ``w = 2r + 1`` cells; a running extreme from the start of each block (``g``) and one from its
end (``h``) make every window of ``w`` cells the extreme of two values, ``h[i]`` and
``g[i + w - 1]``. About three comparisons a cell whatever the window, so the 33-cell window costs
what the 3-cell one does. Cells outside the grid are ignored (the neutral padding), as in
``core.grids.morphology``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: columns handled together by the column pass (one contiguous run of a row at a time)
_COLUMN_BLOCK = 64


@njit(cache=True, nogil=True)
def _better(a, b, take_max):
    if take_max:
        return a if a > b else b
    return a if a < b else b


@njit(cache=True, nogil=True)
def _line_extreme(line, r, take_max, g, h, out):
    """out[i] = extreme of line[i - r .. i + r] (clipped to the line); ``g`` and ``h`` are
    scratch buffers of at least ``line.size + 2r`` values."""
    n = line.shape[0]
    w = 2 * r + 1
    m = n + 2 * r
    pad = -np.inf if take_max else np.inf
    # g: running extreme from the start of each block of w (padded indices 0..m-1).
    for j in range(m):
        v = line[j - r] if r <= j < n + r else pad
        if j % w == 0:
            g[j] = v
        else:
            g[j] = _better(g[j - 1], v, take_max)
    # h: running extreme towards the start, restarting at the end of each block.
    for j in range(m - 1, -1, -1):
        v = line[j - r] if r <= j < n + r else pad
        if j % w == w - 1 or j == m - 1:
            h[j] = v
        else:
            h[j] = _better(h[j + 1], v, take_max)
    for i in range(n):
        out[i] = _better(h[i], g[i + w - 1], take_max)


@njit(cache=True, nogil=True, parallel=True)
def _rows_extreme_kernel(src, r, take_max, out):
    """Extreme over the row segment [c - r, c + r] of every cell (rows in parallel)."""
    nrows, ncols = src.shape
    if r == 0:
        out[:, :] = src
        return
    m = ncols + 2 * r
    nblocks = min(nrows, 64)
    for b in prange(nblocks):
        g = np.empty(m, dtype=src.dtype)
        h = np.empty(m, dtype=src.dtype)
        for i in range(b, nrows, nblocks):
            _line_extreme(src[i], r, take_max, g, h, out[i])


@njit(cache=True, nogil=True)
def _columns_block(src, r, take_max, c0, c1, g, h, out):
    """The column pass for columns c0..c1-1, walking whole row segments (contiguous)."""
    nrows = src.shape[0]
    w = 2 * r + 1
    m = nrows + 2 * r
    nc = c1 - c0
    pad = -np.inf if take_max else np.inf
    for j in range(m):
        inside = r <= j < nrows + r
        start = j % w == 0
        for k in range(nc):
            v = src[j - r, c0 + k] if inside else pad
            if start:
                g[j, k] = v
            else:
                g[j, k] = _better(g[j - 1, k], v, take_max)
    for j in range(m - 1, -1, -1):
        inside = r <= j < nrows + r
        end = j % w == w - 1 or j == m - 1
        for k in range(nc):
            v = src[j - r, c0 + k] if inside else pad
            if end:
                h[j, k] = v
            else:
                h[j, k] = _better(h[j + 1, k], v, take_max)
    for i in range(nrows):
        for k in range(nc):
            out[i, c0 + k] = _better(h[i, k], g[i + w - 1, k], take_max)


@njit(cache=True, nogil=True, parallel=True)
def _columns_extreme_kernel(src, r, take_max, out):
    """Extreme over the column segment [row - r, row + r] of every cell (column blocks in parallel)."""
    nrows, ncols = src.shape
    if r == 0:
        out[:, :] = src
        return
    m = nrows + 2 * r
    nblocks = (ncols + _COLUMN_BLOCK - 1) // _COLUMN_BLOCK
    for b in prange(nblocks):
        c0 = b * _COLUMN_BLOCK
        c1 = min(c0 + _COLUMN_BLOCK, ncols)
        g = np.empty((m, c1 - c0), dtype=src.dtype)
        h = np.empty((m, c1 - c0), dtype=src.dtype)
        _columns_block(src, r, take_max, c0, c1, g, h, out)


@njit(cache=True, nogil=True)
def _cell_of(x, y, x0, top, cell, nrows, ncols):
    c = int(math.floor((x - x0) / cell))
    r = int(math.floor((top - y) / cell))
    if c < 0:
        c = 0
    elif c >= ncols:
        c = ncols - 1
    if r < 0:
        r = 0
    elif r >= nrows:
        r = nrows - 1
    return r, c


@njit(cache=True, nogil=True)
def _xyz_cell_min_kernel(xyz, x0, top, cell, out):
    """out[row, col] = lowest z of the points of ``xyz`` (n, 3) in the cell; NaN where empty.
    Reads the (n, 3) array in place: no per-coordinate copies of the cloud."""
    nrows, ncols = out.shape
    out[:, :] = np.nan
    for k in range(xyz.shape[0]):
        r, c = _cell_of(xyz[k, 0], xyz[k, 1], x0, top, cell, nrows, ncols)
        v = out[r, c]
        z = xyz[k, 2]
        if not (z >= v):  # also true when v is NaN
            out[r, c] = z


@njit(cache=True, nogil=True, parallel=True)
def _below_limit_kernel(xyz, x0, top, cell, limit, out_ground):
    """out_ground[k] = z of point k <= limit of its cell."""
    nrows, ncols = limit.shape
    for k in prange(xyz.shape[0]):
        r, c = _cell_of(xyz[k, 0], xyz[k, 1], x0, top, cell, nrows, ncols)
        out_ground[k] = xyz[k, 2] <= limit[r, c]
