"""numba kernels of ``core.learn.features``. Private: call them through
:func:`groundsieve.core.learn.features.compute_features`, which validates, sorts and casts first.

Neighbour search. The points are binned in vertical columns of square cells (``cell`` = the
radius divided by ``split``), identified by the key ``ix * ny + iy``; they are sorted by (key, z),
so that each occupied column is one run of the sorted arrays, ordered by height. ``ukeys`` holds
the sorted keys of the occupied columns and ``starts`` where each run begins; a key is found
through ``lookup``, a dense key -> column table, when the grid is small enough (at most 4 cells
per point or 1 M cells), else by binary search in ``ukeys`` (a sorted-array hash). For a point, the columns within ``split`` cells are looked up
once per column of the point (all points of a column share them), those whose footprint lies
wholly beyond the radius are skipped, and in the others only the points with
``|dz| <= radius`` are visited: a window found by advancing one pointer per neighbour column,
since the points of a column are handled in increasing z. This is the 27-voxel scan with the
vertical extent of the voxels cut to the exact window.

Work is shared between threads by ``ntasks`` interleaved tasks (task ``t`` takes columns
``c0 + t``, ``c0 + t + ntasks``, ...), which balances dense and sparse parts of a scene.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: Rows of the sphere features, in the order the kernel knows them.
LINEARITY, PLANARITY, SPHERICITY, OMNIVARIANCE, ANISOTROPY, EIGENENTROPY, SURFACE_VARIATION, \
    VERTICALITY, EIGENVALUE_SUM, DENSITY = range(10)
N_SPHERE = 10

#: Fewest points (the point itself included) a sphere must hold for the eigen features.
MIN_POINTS = 3


@njit(cache=True, nogil=True)
def _lower_bound(a, lo, hi, value):
    while lo < hi:
        mid = (lo + hi) >> 1
        if a[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True)
def _neighbour_columns(ukeys, lookup, c, nx, ny, cell, split, cols, box):
    """The occupied columns within ``split`` cells of column ``c``: their indices in ``cols``
    and their footprints (xmin, xmax, ymin, ymax) in ``box``; returns how many. ``lookup``
    maps a key to its column (-1: empty) when the grid is small enough to be dense, else it
    is empty and keys are found by binary search in ``ukeys``."""
    key = ukeys[c]
    cx = key // ny
    cy = key - cx * ny
    m = 0
    nk = ukeys.shape[0]
    dense = lookup.shape[0] > 0
    for dx in range(-split, split + 1):
        xx = cx + dx
        if xx < 0 or xx >= nx:
            continue
        for dy in range(-split, split + 1):
            yy = cy + dy
            if yy < 0 or yy >= ny:
                continue
            k = xx * ny + yy
            if dense:
                j = lookup[k]
            else:
                j = _lower_bound(ukeys, 0, nk, k)
                if j >= nk or ukeys[j] != k:
                    j = -1
            if j >= 0:
                cols[m] = j
                box[m, 0] = xx * cell
                box[m, 1] = (xx + 1) * cell
                box[m, 2] = yy * cell
                box[m, 3] = (yy + 1) * cell
                m += 1
    return m


@njit(cache=True, nogil=True)
def _box_d2(box, t, px, py):
    """Squared horizontal distance from (px, py) to footprint ``t`` (0 inside)."""
    dx = 0.0
    if px < box[t, 0]:
        dx = box[t, 0] - px
    elif px > box[t, 1]:
        dx = px - box[t, 1]
    dy = 0.0
    if py < box[t, 2]:
        dy = box[t, 2] - py
    elif py > box[t, 3]:
        dy = py - box[t, 3]
    return dx * dx + dy * dy


@njit(cache=True, nogil=True)
def _jacobi3(a, v, w):
    """Eigenvalues ``w`` and eigenvectors (columns of ``v``) of the symmetric 3x3 ``a``
    (destroyed), by cyclic Jacobi rotations; unsorted."""
    for i in range(3):
        for j in range(3):
            v[i, j] = 1.0 if i == j else 0.0
    for _sweep in range(50):
        off = abs(a[0, 1]) + abs(a[0, 2]) + abs(a[1, 2])
        diag = abs(a[0, 0]) + abs(a[1, 1]) + abs(a[2, 2])
        if off <= 1e-12 * diag or off == 0.0:
            break
        for p in range(2):
            for q in range(p + 1, 3):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                a[p, p] -= t * apq
                a[q, q] += t * apq
                a[p, q] = 0.0
                a[q, p] = 0.0
                r = 3 - p - q
                arp = a[r, p]
                arq = a[r, q]
                a[r, p] = c * arp - s * arq
                a[p, r] = a[r, p]
                a[r, q] = s * arp + c * arq
                a[q, r] = a[r, q]
                for k in range(3):
                    vkp = v[k, p]
                    vkq = v[k, q]
                    v[k, p] = c * vkp - s * vkq
                    v[k, q] = s * vkp + c * vkq
    w[0] = a[0, 0]
    w[1] = a[1, 1]
    w[2] = a[2, 2]


@njit(cache=True, nogil=True)
def _sphere_values(k, sx, sy, sz, sxx, syy, szz, sxy, sxz, syz, r, a, v, w, vals):
    """The N_SPHERE features of one sphere from its point count and sums of offsets (relative
    to the centre point) and their products."""
    vals[DENSITY] = k / (4.0 / 3.0 * math.pi * r * r * r)
    for f in range(N_SPHERE):
        if f != DENSITY:
            vals[f] = np.nan
    if k < MIN_POINTS:
        return
    inv = 1.0 / k
    mx = sx * inv
    my = sy * inv
    mz = sz * inv
    cxx = sxx * inv - mx * mx
    cyy = syy * inv - my * my
    czz = szz * inv - mz * mz
    trace = cxx + cyy + czz
    if trace <= (1e-6 * r) ** 2:
        # (Nearly) coincident points: no shape, and no normal.
        vals[EIGENVALUE_SUM] = max(trace, 0.0)
        return
    scale = 1.0 / trace
    a[0, 0] = cxx * scale
    a[1, 1] = cyy * scale
    a[2, 2] = czz * scale
    a[0, 1] = a[1, 0] = (sxy * inv - mx * my) * scale
    a[0, 2] = a[2, 0] = (sxz * inv - mx * mz) * scale
    a[1, 2] = a[2, 1] = (syz * inv - my * mz) * scale
    _jacobi3(a, v, w)
    # indices of the largest (i1), middle (i2) and smallest (i3) eigenvalue
    i1, i2, i3 = 0, 1, 2
    if w[i1] < w[i2]:
        i1, i2 = i2, i1
    if w[i2] < w[i3]:
        i2, i3 = i3, i2
    if w[i1] < w[i2]:
        i1, i2 = i2, i1
    l1 = max(w[i1], 0.0)
    l2 = max(w[i2], 0.0)
    l3 = max(w[i3], 0.0)
    if k == 3:
        l3 = 0.0  # three points are coplanar: drop the rounding noise (it shows in the cube root)
    total = l1 + l2 + l3
    e1 = l1 / total
    e2 = l2 / total
    e3 = l3 / total
    vals[LINEARITY] = (e1 - e2) / e1
    vals[PLANARITY] = (e2 - e3) / e1
    vals[SPHERICITY] = e3 / e1
    vals[ANISOTROPY] = (e1 - e3) / e1
    vals[OMNIVARIANCE] = (e1 * e2 * e3) ** (1.0 / 3.0)
    entropy = 0.0
    if e1 > 0.0:
        entropy -= e1 * math.log(e1)
    if e2 > 0.0:
        entropy -= e2 * math.log(e2)
    if e3 > 0.0:
        entropy -= e3 * math.log(e3)
    vals[EIGENENTROPY] = entropy
    vals[SURFACE_VARIATION] = e3
    nz = v[2, i3] / math.sqrt(v[0, i3] ** 2 + v[1, i3] ** 2 + v[2, i3] ** 2)
    vals[VERTICALITY] = 1.0 - abs(nz)
    vals[EIGENVALUE_SUM] = trace


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _accumulate(xs, ys, zs, j0, j1, px, py, pz, r2):
    """Count and sums of the offsets (and their products) from (px, py, pz) of the points
    ``j0:j1`` within ``sqrt(r2)``. Branch-free so that it vectorises (reassociation allowed;
    no NaN/inf assumptions)."""
    k = 0.0
    sx = sy = sz = sxx = syy = szz = sxy = sxz = syz = 0.0
    for j in range(j0, j1):
        dx = xs[j] - px
        dy = ys[j] - py
        dz = zs[j] - pz
        inside = 1.0 if dx * dx + dy * dy + dz * dz <= r2 else 0.0
        wx = inside * dx
        wy = inside * dy
        wz = inside * dz
        k += inside
        sx += wx
        sy += wy
        sz += wz
        sxx += wx * dx
        syy += wy * dy
        szz += wz * dz
        sxy += wx * dy
        sxz += wx * dz
        syz += wy * dz
    return k, sx, sy, sz, sxx, syy, szz, sxy, sxz, syz


@njit(cache=True, nogil=True)
def _sphere_column(c, xs, ys, zs, order, starts, ukeys, lookup, nx, ny, cell, split, r, rows, out,
                   cols, box, lo, hi, a, v, w, vals):
    m = _neighbour_columns(ukeys, lookup, c, nx, ny, cell, split, cols, box)
    for t in range(m):
        lo[t] = starts[cols[t]]
        hi[t] = starts[cols[t]]
    r2 = r * r
    for i in range(starts[c], starts[c + 1]):
        px = xs[i]
        py = ys[i]
        pz = zs[i]
        zlo = pz - r
        zhi = pz + r
        k = 0.0
        sx = sy = sz = sxx = syy = szz = sxy = sxz = syz = 0.0
        for t in range(m):
            if _box_d2(box, t, px, py) > r2:
                continue
            end = starts[cols[t] + 1]
            # z only grows along the column of the point: the window [lo, hi) only moves up
            j0 = lo[t]
            while j0 < end and zs[j0] < zlo:
                j0 += 1
            lo[t] = j0
            j1 = max(hi[t], j0)
            while j1 < end and zs[j1] <= zhi:
                j1 += 1
            hi[t] = j1
            if j1 > j0:
                s = _accumulate(xs, ys, zs, j0, j1, px, py, pz, r2)
                k += s[0]
                sx += s[1]
                sy += s[2]
                sz += s[3]
                sxx += s[4]
                syy += s[5]
                szz += s[6]
                sxy += s[7]
                sxz += s[8]
                syz += s[9]
        _sphere_values(int(k + 0.5), sx, sy, sz, sxx, syy, szz, sxy, sxz, syz, r, a, v, w, vals)
        dest = order[i]
        for f in range(N_SPHERE):
            row = rows[f]
            if row >= 0:
                out[row, dest] = vals[f]


@njit(cache=True, nogil=True, parallel=True)
def _sphere_features_kernel(xs, ys, zs, order, starts, ukeys, lookup, nx, ny, cell, split, r, rows,
                            c0, c1, ntasks, out):
    """Sphere features of the points of columns ``c0:c1``: ``out[rows[f], p]`` gets feature
    ``f`` of point ``p`` (original order) for every ``rows[f] >= 0``."""
    width = 2 * split + 1
    for task in prange(ntasks):
        cols = np.empty(width * width, dtype=np.int64)
        box = np.empty((width * width, 4), dtype=np.float64)
        lo = np.empty(width * width, dtype=np.int64)
        hi = np.empty(width * width, dtype=np.int64)
        a = np.empty((3, 3), dtype=np.float64)
        v = np.empty((3, 3), dtype=np.float64)
        w = np.empty(3, dtype=np.float64)
        vals = np.empty(N_SPHERE, dtype=np.float64)
        for c in range(c0 + task, c1, ntasks):
            _sphere_column(c, xs, ys, zs, order, starts, ukeys, lookup, nx, ny, cell, split, r, rows, out,
                           cols, box, lo, hi, a, v, w, vals)


@njit(cache=True, nogil=True)
def _column_min_column(c, xs, ys, zs, order, starts, ukeys, lookup, nx, ny, cell, split, r, out, cols, box):
    m = _neighbour_columns(ukeys, lookup, c, nx, ny, cell, split, cols, box)
    r2 = r * r
    for i in range(starts[c], starts[c + 1]):
        px = xs[i]
        py = ys[i]
        best = zs[i]  # the point itself is in its column
        for t in range(m):
            col = cols[t]
            j = starts[col]
            end = starts[col + 1]
            if j >= end or zs[j] >= best:
                continue
            d2 = _box_d2(box, t, px, py)
            if d2 > r2:
                continue
            # Points of a column come by increasing z: the first inside the disk is its lowest.
            while j < end and zs[j] < best:
                dx = xs[j] - px
                dy = ys[j] - py
                if dx * dx + dy * dy <= r2:
                    best = zs[j]
                    break
                j += 1
        out[order[i]] = zs[i] - best


@njit(cache=True, nogil=True, parallel=True)
def _column_min_kernel(xs, ys, zs, order, starts, ukeys, lookup, nx, ny, cell, split, r, c0, c1, ntasks, out):
    """``out[p]`` = z of point ``p`` minus the lowest z within horizontal distance ``r``."""
    width = 2 * split + 1
    for task in prange(ntasks):
        cols = np.empty(width * width, dtype=np.int64)
        box = np.empty((width * width, 4), dtype=np.float64)
        for c in range(c0 + task, c1, ntasks):
            _column_min_column(c, xs, ys, zs, order, starts, ukeys, lookup, nx, ny, cell, split, r, out, cols,
                               box)
