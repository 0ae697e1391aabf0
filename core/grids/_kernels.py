"""numba kernels of the grid machinery. Private: call them through the public functions of
``morphology`` and ``rasterize``, which validate and cast first."""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True)
def _cell_of(x, y, x0, top, cell, nrows, ncols):
    """(row, col) of the grid cell holding (x, y), clamped to the grid (see core/grids/spec.py)."""
    c = min(max(int(math.floor((x - x0) / cell)), 0), ncols - 1)
    r = min(max(int(math.floor((top - y) / cell)), 0), nrows - 1)
    return r, c


@njit(cache=True, nogil=True)
def _cell_min_kernel(x, y, z, x0, top, cell, nrows, ncols, out):
    """out[row, col] = min z of the points in the cell (NaN where empty)."""
    out[:, :] = np.nan
    for k in range(x.shape[0]):
        r, c = _cell_of(x[k], y[k], x0, top, cell, nrows, ncols)
        v = out[r, c]
        if not (z[k] >= v):  # also true when v is NaN
            out[r, c] = z[k]


@njit(cache=True, nogil=True)
def _cell_mean_kernel(x, y, z, x0, top, cell, nrows, ncols, total, count):
    for k in range(x.shape[0]):
        r, c = _cell_of(x[k], y[k], x0, top, cell, nrows, ncols)
        total[r, c] += z[k]
        count[r, c] += 1


@njit(cache=True, nogil=True)
def _running_extremes(src, s, r, take_max, buf):
    """buf[w, x] = extreme of src[s, x-w .. x+w] (cells outside the row ignored), w = 0..r."""
    ncols = src.shape[1]
    for x in range(ncols):
        buf[0, x] = src[s, x]
    for w in range(1, r + 1):
        lo = min(w, ncols)
        hi = max(ncols - w, lo)
        if take_max:
            for x in range(0, lo):  # left edge: no cell at x - w
                v = buf[w - 1, x]
                if x + w < ncols:
                    v = max(v, src[s, x + w])
                buf[w, x] = v
            for x in range(lo, hi):
                buf[w, x] = max(max(buf[w - 1, x], src[s, x - w]), src[s, x + w])
            for x in range(hi, ncols):  # right edge: no cell at x + w
                v = buf[w - 1, x]
                if x - w >= 0:
                    v = max(v, src[s, x - w])
                buf[w, x] = v
        else:
            for x in range(0, lo):
                v = buf[w - 1, x]
                if x + w < ncols:
                    v = min(v, src[s, x + w])
                buf[w, x] = v
            for x in range(lo, hi):
                buf[w, x] = min(min(buf[w - 1, x], src[s, x - w]), src[s, x + w])
            for x in range(hi, ncols):
                v = buf[w - 1, x]
                if x - w >= 0:
                    v = min(v, src[s, x - w])
                buf[w, x] = v


@njit(cache=True, nogil=True)
def _disk_extreme_rows(src, r, half, take_max, row_lo, row_hi, out):
    """Rows ``row_lo:row_hi`` of the erosion/dilation (see ``_disk_extreme_kernel``)."""
    nrows, ncols = src.shape
    fill = -np.inf if take_max else np.inf
    for i in range(row_lo, row_hi):
        for x in range(ncols):
            out[i, x] = fill
    buf = np.empty((r + 1, ncols), dtype=src.dtype)
    for s in range(max(row_lo - r, 0), min(row_hi + r, nrows)):
        _running_extremes(src, s, r, take_max, buf)
        for dy in range(-r, r + 1):
            i = s - dy
            if i < row_lo or i >= row_hi:
                continue
            w = half[dy + r]
            if take_max:
                for x in range(ncols):
                    out[i, x] = max(out[i, x], buf[w, x])
            else:
                for x in range(ncols):
                    out[i, x] = min(out[i, x], buf[w, x])


@njit(cache=True, nogil=True, parallel=True)
def _disk_extreme_kernel(src, radius, take_max, out):
    """Grey erosion (min) or dilation (max) of ``src`` by the disk x²+y² <= radius².

    The disk is the union of horizontal chords of half width ``w(dy)``. For every
    source row the running extremes over widths 0..radius are built once
    (``2 * radius`` comparisons a cell), and each chord of each output row is then
    one lookup: O(radius) a cell instead of O(radius²). Cells outside the grid
    are ignored (not padded), as in scikit-image. Blocks of output rows run in
    parallel; each block reads the ``radius`` source rows around it.
    """
    nrows = src.shape[0]
    r = radius
    half = np.empty(2 * r + 1, dtype=np.int64)
    for dy in range(-r, r + 1):
        half[dy + r] = int(math.floor(math.sqrt(r * r - dy * dy) + 1e-9))
    block = max(64, 4 * r)
    nblocks = (nrows + block - 1) // block
    for b in prange(nblocks):
        _disk_extreme_rows(src, r, half, take_max, b * block, min((b + 1) * block, nrows), out)


@njit(cache=True, nogil=True)
def _keys_weights(t, w):
    """Cubic convolution weights (Keys 1981, a = -0.5) for offsets -1, 0, 1, 2."""
    a = -0.5
    for k in range(4):
        d = abs(t - (k - 1))
        if d <= 1.0:
            w[k] = (a + 2.0) * d ** 3 - (a + 3.0) * d ** 2 + 1.0
        elif d < 2.0:
            w[k] = a * d ** 3 - 5.0 * a * d ** 2 + 8.0 * a * d - 4.0 * a
        else:
            w[k] = 0.0


@njit(cache=True, nogil=True)
def _cubic_one(grid, fc, fr, wx, wy):
    """Cubic convolution value of ``grid`` at fractional (column, row) ``(fc, fr)``,
    where integer positions are cell centres; indices beyond the edge are clamped."""
    nrows, ncols = grid.shape
    c0 = int(math.floor(fc))
    r0 = int(math.floor(fr))
    _keys_weights(fc - c0, wx)
    _keys_weights(fr - r0, wy)
    acc = 0.0
    for a in range(4):
        rr = min(max(r0 + a - 1, 0), nrows - 1)
        row_acc = 0.0
        for b in range(4):
            cc = min(max(c0 + b - 1, 0), ncols - 1)
            row_acc += wx[b] * grid[rr, cc]
        acc += wy[a] * row_acc
    return acc


@njit(cache=True, nogil=True)
def _cubic_at_points_kernel(grid, x, y, x0, top, cell, out):
    """Bicubic (cubic convolution) value of ``grid`` at each (x, y)."""
    wx = np.empty(4)
    wy = np.empty(4)
    for k in range(x.shape[0]):
        out[k] = _cubic_one(grid, (x[k] - x0) / cell - 0.5, (top - y[k]) / cell - 0.5, wx, wy)


@njit(cache=True, nogil=True, inline="always")
def _fill_triangle(px, py, pz, i0, i1, i2, x0, top, cell, row_lo, row_hi, out):
    """Give each cell centre of rows ``row_lo..row_hi`` inside triangle (i0, i1, i2) the height
    of the triangle's plane there."""
    nrows, ncols = out.shape
    xa, ya, za = px[i0], py[i0], pz[i0]
    xb, yb, zb = px[i1], py[i1], pz[i1]
    xc, yc, zc = px[i2], py[i2], pz[i2]
    det = (yb - yc) * (xa - xc) + (xc - xb) * (ya - yc)
    if det == 0.0:
        return
    xmin = min(xa, min(xb, xc))
    xmax = max(xa, max(xb, xc))
    c_lo = max(int(math.ceil((xmin - x0) / cell - 0.5)), 0)
    c_hi = min(int(math.floor((xmax - x0) / cell - 0.5)), ncols - 1)
    eps = -1e-9
    for r in range(row_lo, row_hi + 1):
        yy = top - (r + 0.5) * cell
        for c in range(c_lo, c_hi + 1):
            xx = x0 + (c + 0.5) * cell
            l1 = ((yb - yc) * (xx - xc) + (xc - xb) * (yy - yc)) / det
            l2 = ((yc - ya) * (xx - xc) + (xa - xc) * (yy - yc)) / det
            l3 = 1.0 - l1 - l2
            if l1 >= eps and l2 >= eps and l3 >= eps:
                out[r, c] = l1 * za + l2 * zb + l3 * zc


@njit(cache=True, nogil=True)
def _rasterize_tin_kernel(px, py, pz, simplices, x0, top, cell, out):
    """Linear interpolation on a triangulation: each cell centre inside a triangle
    gets the plane of that triangle. Cells covered by no triangle keep their value."""
    nrows = out.shape[0]
    for t in range(simplices.shape[0]):
        i0 = simplices[t, 0]
        i1 = simplices[t, 1]
        i2 = simplices[t, 2]
        ymin = min(py[i0], min(py[i1], py[i2]))
        ymax = max(py[i0], max(py[i1], py[i2]))
        r_lo = max(int(math.ceil((top - ymax) / cell - 0.5)), 0)
        r_hi = min(int(math.floor((top - ymin) / cell - 0.5)), nrows - 1)
        _fill_triangle(px, py, pz, i0, i1, i2, x0, top, cell, r_lo, r_hi, out)


@njit(cache=True, nogil=True)
def _cell_lookup_kernel(x, y, grid, x0, top, cell, out):
    """out[k] = grid value of the cell holding point k."""
    nrows, ncols = grid.shape
    for k in range(x.shape[0]):
        r, c = _cell_of(x[k], y[k], x0, top, cell, nrows, ncols)
        out[k] = grid[r, c]


@njit(cache=True, nogil=True)
def _thin_dense_kernel(x, y, z, col0, row0, sub, nrows_sub, ncols_sub, best):
    """For each sub-cell (row-major in ``best``, -1 = empty), the index of the point nearest
    its centre, the lowest on a tie, then the first. Sub-cells by their index on the lattice of
    multiples of ``sub`` (column ``floor(x / sub) - col0``, row ``row0 + floor(-y / sub)``), so that
    a point falls in the same sub-cell whatever grid it is thinned on (a survey's DTM and a tile's
    block agree). False when a point falls off the grid (``best`` then incomplete)."""
    for i in range(x.shape[0]):
        gx = math.floor(x[i] / sub)
        gy = math.floor(-y[i] / sub)
        col = gx - col0
        row = row0 + gy
        if row < 0 or col < 0 or row >= nrows_sub or col >= ncols_sub:
            return False
        key = int(row) * ncols_sub + int(col)
        j = best[key]
        if j == -1:
            best[key] = i
            continue
        cx = (gx + 0.5) * sub
        cy = -(gy + 0.5) * sub
        di = (x[i] - cx) ** 2 + (cy - y[i]) ** 2
        dj = (x[j] - cx) ** 2 + (cy - y[j]) ** 2
        if di < dj or (di == dj and (z[i] < z[j] or (z[i] == z[j] and i < j))):
            best[key] = i
    return True


@njit(cache=True, nogil=True)
def _compact_kernel(best):
    n = 0
    for k in range(best.shape[0]):
        if best[k] != -1:
            n += 1
    out = np.empty(n, dtype=np.int64)
    n = 0
    for k in range(best.shape[0]):
        if best[k] != -1:
            out[n] = best[k]
            n += 1
    return out


@njit(cache=True, nogil=True)
def _triangle_rows(px, py, simplices, top, cell, nrows):
    """First and last grid row whose cell centres a triangle's box spans (first > last: none)."""
    m = simplices.shape[0]
    r_lo = np.empty(m, dtype=np.int64)
    r_hi = np.empty(m, dtype=np.int64)
    for t in range(m):
        ya = py[simplices[t, 0]]
        yb = py[simplices[t, 1]]
        yc = py[simplices[t, 2]]
        ymin = min(ya, min(yb, yc))
        ymax = max(ya, max(yb, yc))
        r_lo[t] = max(int(math.ceil((top - ymax) / cell - 0.5)), 0)
        r_hi[t] = min(int(math.floor((top - ymin) / cell - 0.5)), nrows - 1)
    return r_lo, r_hi


@njit(cache=True, nogil=True, parallel=True)
def _rasterize_tin_bands_kernel(px, py, pz, simplices, x0, top, cell, out, band):
    """:func:`_rasterize_tin_kernel` in parallel over bands of ``band`` rows: each band takes
    the triangles reaching it in the serial order, so every cell gets the same value as the
    serial kernel (the last triangle holding its centre)."""
    nrows = out.shape[0]
    m = simplices.shape[0]
    r_lo, r_hi = _triangle_rows(px, py, simplices, top, cell, nrows)
    nb = (nrows + band - 1) // band
    start = np.zeros(nb + 1, dtype=np.int64)
    for t in range(m):
        if r_lo[t] <= r_hi[t]:
            for b in range(r_lo[t] // band, r_hi[t] // band + 1):
                start[b + 1] += 1
    for b in range(nb):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    members = np.empty(start[nb], dtype=np.int64)
    for t in range(m):
        if r_lo[t] <= r_hi[t]:
            for b in range(r_lo[t] // band, r_hi[t] // band + 1):
                members[fill[b]] = t
                fill[b] += 1
    for b in prange(nb):
        row0 = b * band
        row1 = min(row0 + band, nrows) - 1
        for k in range(start[b], start[b + 1]):
            t = members[k]
            _fill_triangle(px, py, pz, simplices[t, 0], simplices[t, 1], simplices[t, 2], x0, top, cell,
                           max(r_lo[t], row0), min(r_hi[t], row1), out)
