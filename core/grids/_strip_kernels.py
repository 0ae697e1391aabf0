"""Numba kernels of the strip-parallel TIN (``rasterize._strips_tin``): which of a strip's triangles
are triangles of the whole cloud's Delaunay triangulation, and which cells the whole cloud's convex
hull holds. The certification works on coordinates relative to its bins' origin; the hull's tests
take differences of coordinates only, so absolute ones do."""
import math

import numpy as np
from numba import njit

from ._delaunay import _circumcentre_offset, _orient


@njit(cache=True, nogil=True)
def bin_points_kernel(x, y, size, nbx, nby):
    """Counting sort of the points (x, y >= 0) into square bins of ``size``, row-major ``nbx`` x ``nby``:
    the points of bin k are ``order[start[k]:start[k + 1]]``."""
    n = x.shape[0]
    start = np.zeros(nbx * nby + 1, dtype=np.int64)
    key = np.empty(n, dtype=np.int32)
    for i in range(n):
        bx = min(max(int(x[i] / size), 0), nbx - 1)
        by = min(max(int(y[i] / size), 0), nby - 1)
        key[i] = by * nbx + bx
        start[key[i] + 1] += 1
    for k in range(nbx * nby):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        order[fill[key[i]]] = i
        fill[key[i]] += 1
    return start, order


@njit(cache=True, nogil=True)
def certify_kernel(px, py, simplices, lo, hi, blo, bhi, own_lo, own_hi, ax, ay, start, order, size, nbx, nby):
    """For each triangle of a strip's triangulation (points ``px, py``, all the cloud's points with
    ``lo <= x < hi`` and ``blo <= y < bhi``): True when it may be rasterised into the strip's own columns
    ``[own_lo, own_hi]``, i.e. it reaches them and it is a triangle of the whole cloud's Delaunay
    triangulation too: no point of the cloud (``ax, ay``, binned by :func:`bin_points_kernel`) outside
    the strip lies inside its circumcircle (inside the strip none does, it is Delaunay there).
    Points on the circle (cocircular, the triangulation not unique there) do not count."""
    m = simplices.shape[0]
    ok = np.zeros(m, dtype=np.bool_)
    for t in range(m):
        i0, i1, i2 = simplices[t, 0], simplices[t, 1], simplices[t, 2]
        xa, ya = px[i0], py[i0]
        xb, yb = px[i1], py[i1]
        xc, yc = px[i2], py[i2]
        if max(xa, max(xb, xc)) < own_lo or min(xa, min(xb, xc)) > own_hi:
            continue  # does not reach the strip's own columns
        ux, uy = _circumcentre_offset(xa, ya, xb, yb, xc, yc)
        if not np.isfinite(ux):
            ok[t] = True  # flat: holds no cell centre
            continue
        r2 = ux * ux + uy * uy
        r = math.sqrt(r2)
        ox, oy = xa + ux, ya + uy
        if ox - r >= lo and ox + r < hi and oy - r >= blo and oy + r < bhi:
            ok[t] = True  # the circle holds no point outside the strip
            continue
        lim = r2 * (1.0 - 1e-10)
        empty = True
        c_lo = max(int(math.floor((ox - r) / size)), 0)
        c_hi = min(int(math.floor((ox + r) / size)), nbx - 1)
        r_lo = max(int(math.floor((oy - r) / size)), 0)
        r_hi = min(int(math.floor((oy + r) / size)), nby - 1)
        for row in range(r_lo, r_hi + 1):
            if not empty:
                break
            y0 = row * size
            rows_in = y0 >= blo and y0 + size < bhi and row < nby - 1
            dy = max(y0 - oy, max(0.0, oy - (y0 + size)))
            for col in range(c_lo, c_hi + 1):
                x0 = col * size
                if rows_in and x0 >= lo and x0 + size < hi and col < nbx - 1:
                    continue  # a bin inside the strip (the last bin also holds points beyond it)
                dx = max(x0 - ox, max(0.0, ox - (x0 + size)))
                if dx * dx + dy * dy >= r2 and col < nbx - 1 and row < nby - 1:
                    continue
                k = row * nbx + col
                for s in range(start[k], start[k + 1]):
                    j = order[s]
                    qx = ax[j]
                    qy = ay[j]
                    if lo <= qx < hi and blo <= qy < bhi:
                        continue
                    ex, ey = qx - ox, qy - oy
                    if ex * ex + ey * ey < lim:
                        empty = False
                        break
                if not empty:
                    break
        ok[t] = empty
    return ok


@njit(cache=True, nogil=True)
def hull_candidates_kernel(x, y):
    """Indices of the points that may be vertices of the convex hull: all but those strictly inside
    the polygon of the extreme points in eight directions (Akl-Toussaint)."""
    n = x.shape[0]
    ext = np.zeros(8, dtype=np.int64)  # bottom, bottom-right, right, top-right, top, top-left, left, bottom-left
    for i in range(n):
        if y[i] < y[ext[0]]:
            ext[0] = i
        if x[i] - y[i] > x[ext[1]] - y[ext[1]]:
            ext[1] = i
        if x[i] > x[ext[2]]:
            ext[2] = i
        if x[i] + y[i] > x[ext[3]] + y[ext[3]]:
            ext[3] = i
        if y[i] > y[ext[4]]:
            ext[4] = i
        if y[i] - x[i] > y[ext[5]] - x[ext[5]]:
            ext[5] = i
        if x[i] < x[ext[6]]:
            ext[6] = i
        if -x[i] - y[i] > -x[ext[7]] - y[ext[7]]:
            ext[7] = i
    keep = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        inside = True
        edges = 0
        for e in range(8):
            a, b = ext[e], ext[(e + 1) % 8]
            if x[a] == x[b] and y[a] == y[b]:
                continue
            edges += 1
            if _orient(x[a], y[a], x[b], y[b], x[i], y[i]) <= 0.0:
                inside = False
                break
        keep[i] = not inside or edges < 3
    return np.flatnonzero(keep)


@njit(cache=True, nogil=True)
def monotone_hull_kernel(x, y):
    """Vertices of the convex hull of points sorted by x then y, counter-clockwise (Andrew)."""
    n = x.shape[0]
    hull = np.empty(2 * n + 1, dtype=np.int64)
    k = 0
    for i in range(n):
        while k >= 2 and _orient(x[hull[k - 2]], y[hull[k - 2]], x[hull[k - 1]], y[hull[k - 1]], x[i], y[i]) <= 0.0:
            k -= 1
        hull[k] = i
        k += 1
    lower = k + 1
    for i in range(n - 2, -1, -1):
        while k >= lower and _orient(x[hull[k - 2]], y[hull[k - 2]], x[hull[k - 1]], y[hull[k - 1]], x[i], y[i]) <= 0.0:
            k -= 1
        hull[k] = i
        k += 1
    return hull[:max(k - 1, 1)]


@njit(cache=True, nogil=True)
def hull_row_spans_kernel(hx, hy, centres_y, shrink):
    """For each row centre y, the x-interval of the convex polygon (``hx, hy``) on that line, shrunk
    by ``shrink`` at both ends; an empty interval (lo > hi) where the line misses it."""
    nr = centres_y.shape[0]
    lo = np.full(nr, np.inf)
    hi = np.full(nr, -np.inf)
    nv = hx.shape[0]
    for e in range(nv):
        xa, ya = hx[e], hy[e]
        xb, yb = hx[(e + 1) % nv], hy[(e + 1) % nv]
        ylo, yhi = min(ya, yb), max(ya, yb)
        for r in range(nr):
            yy = centres_y[r]
            if yy < ylo or yy > yhi:
                continue
            if ya == yb:
                xl, xr = min(xa, xb), max(xa, xb)
            else:
                xl = xr = xa + (yy - ya) * (xb - xa) / (yb - ya)
            lo[r] = min(lo[r], xl)
            hi[r] = max(hi[r], xr)
    return lo + shrink, hi - shrink
