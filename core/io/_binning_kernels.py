"""numba kernels of the tile binning. Private: call them through ``lasfiles.bin_file``."""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _reach(f, size, buffer, m):
    """The tile steps (lo, hi) along one axis whose buffers hold a point at ``f`` (its position
    inside its own tile, [0, size); ``size`` on the survey's far edge, which closes its tile): ``lasfiles._in_buffer`` for every step from -m to m, which
    holds on one run of steps around 0 (the test only loosens towards 0)."""
    lo = 0
    for d in range(1, m + 1):  # d tiles before: f + (d - 1) * size < buffer
        if f + (d - 1) * size < buffer:
            lo = -d
        else:
            break
    hi = 0
    for d in range(1, m + 1):  # d tiles after: (size - f) + (d - 1) * size <= buffer
        if (size - f) + (d - 1) * size <= buffer:
            hi = d
        else:
            break
    return lo, hi


@njit(cache=True, nogil=True)
def bin_chunk_kernel(X, Y, sx, ox, sy, oy, size, buffer, m, first, edge_x, edge_y, edge_xmax, edge_ymax):
    """Every (tile, point) pair of one chunk: the point in the tile or in its buffer.

    ``X``, ``Y``: the records' integer coordinates (scaled as laspy does, ``X * sx + ox``);
    ``first``: the chunk's first point in the file; ``edge_x``, ``edge_y``: the tile index the survey's
    far edge closes along each axis (``TileGrid.edge_keys``), a point there at most ``edge_xmax``,
    ``edge_ymax`` (on the edge) going to the tile below (``TileGrid.key_of``).

    Returns (kx0, ky0, nky, bucket_start, out_idx, own_count): the pairs grouped by tile (bucket
    ``b`` is tile (kx0 + b // nky, ky0 + b % nky) and holds the pairs
    ``bucket_start[b]:bucket_start[b + 1]``), each group in file order; ``out_idx`` the point's
    index in the file (``-1 - index`` for a buffer point), ``own_count`` the tile's own points per
    bucket."""
    n = X.shape[0]
    kx = np.empty(n, dtype=np.int64)
    ky = np.empty(n, dtype=np.int64)
    rx = np.empty((n, 2), dtype=np.int64)
    ry = np.empty((n, 2), dtype=np.int64)
    kxmin = np.iinfo(np.int64).max
    kxmax = np.iinfo(np.int64).min
    kymin = kxmin
    kymax = kxmax
    for i in range(n):
        x = X[i] * sx + ox
        y = Y[i] * sy + oy
        a = np.int64(math.floor(x / size))
        b = np.int64(math.floor(y / size))
        if a == edge_x and x <= edge_xmax:
            a -= 1
        if b == edge_y and y <= edge_ymax:
            b -= 1
        kx[i] = a
        ky[i] = b
        lo, hi = _reach(x - a * size, size, buffer, m)
        rx[i, 0] = lo
        rx[i, 1] = hi
        lo, hi = _reach(y - b * size, size, buffer, m)
        ry[i, 0] = lo
        ry[i, 1] = hi
        kxmin = min(kxmin, a)
        kxmax = max(kxmax, a)
        kymin = min(kymin, b)
        kymax = max(kymax, b)
    if n == 0:
        kxmin = kxmax = kymin = kymax = 0
    kx0 = kxmin - m
    ky0 = kymin - m
    nkx = kxmax - kxmin + 1 + 2 * m
    nky = kymax - kymin + 1 + 2 * m
    counts = np.zeros(nkx * nky + 1, dtype=np.int64)
    for i in range(n):
        for dx in range(rx[i, 0], rx[i, 1] + 1):
            for dy in range(ry[i, 0], ry[i, 1] + 1):
                counts[(kx[i] + dx - kx0) * nky + (ky[i] + dy - ky0) + 1] += 1
    for b in range(nkx * nky):
        counts[b + 1] += counts[b]
    total = counts[nkx * nky]
    fill = counts[:-1].copy()
    out_idx = np.empty(total, dtype=np.int64)
    own_count = np.zeros(nkx * nky, dtype=np.int64)
    for i in range(n):
        for dx in range(rx[i, 0], rx[i, 1] + 1):
            for dy in range(ry[i, 0], ry[i, 1] + 1):
                b = (kx[i] + dx - kx0) * nky + (ky[i] + dy - ky0)
                j = fill[b]
                fill[b] = j + 1
                if dx == 0 and dy == 0:
                    out_idx[j] = first + i
                    own_count[b] += 1
                else:
                    out_idx[j] = -1 - (first + i)
    return kx0, ky0, nky, counts, out_idx, own_count
