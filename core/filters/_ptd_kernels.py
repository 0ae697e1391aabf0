"""numba kernels of the densification rules of progressive TIN densification (core.filters.ptd):
the spatial sort, the seeds and their low-outlier test, Axelsson's angle and distance test of the
candidates against the TIN, the virtual vertices' heights, thinning and the last pass. Private:
call them through :class:`~groundsieve.core.filters.ptd.PTD`, which validates and lays out the
arrays first. The triangulation they grow is in ``_ptd_tin``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._ptd_tin import (_ON_EDGE_M, CANDIDATE, EXCLUDED, GROUND_OTHER, GROUND_VERTEX, THINNED, _incident, _insert,
                       _locate, _mark, _star, _walk)


# --- spatial sort and the low-outlier test ---------------------------------------------------------

@njit(cache=True, nogil=True, inline="always")
def _cell_key(c, r, nbx, block):
    return ((r // block) * nbx + (c // block)) * block * block + (r % block) * block + (c % block)


@njit(cache=True, nogil=True)
def spatial_sort_kernel(x, y, x0, y0, cell, ncols, nrows, block, perm, cell_start):
    """Counting sort of the points by cell of a fine grid, the cells ordered block by block
    (``block`` x ``block`` cells, row-major inside and between blocks) so that points close
    in space are close in memory. ``perm`` gets the point of each sorted position,
    ``cell_start[key]`` the first sorted position of cell ``key`` (``key`` in block order)."""
    n = x.shape[0]
    nbx = (ncols + block - 1) // block
    keys = np.empty(n, dtype=np.int64)
    cell_start[:] = 0
    for i in range(n):
        c = min(max(int((x[i] - x0) / cell), 0), ncols - 1)
        r = min(max(int((y[i] - y0) / cell), 0), nrows - 1)
        k = _cell_key(c, r, nbx, block)
        keys[i] = k
        cell_start[k + 1] += 1
    for k in range(1, cell_start.shape[0]):
        cell_start[k] += cell_start[k - 1]
    fill = cell_start[:-1].copy()
    for i in range(n):
        k = keys[i]
        perm[fill[k]] = i
        fill[k] += 1


@njit(cache=True, nogil=True)
def gather_kernel(xyz, perm, x0, y0, out):
    """``out[j]`` = the point ``perm[j]`` of ``xyz`` relative to (x0, y0) (numpy's fancy indexing
    of one column at a time reads the points three times)."""
    for j in range(perm.shape[0]):
        i = perm[j]
        out[j, 0] = xyz[i, 0] - x0
        out[j, 1] = xyz[i, 1] - y0
        out[j, 2] = xyz[i, 2]


@njit(cache=True, nogil=True)
def cell_min_kernel(vz, cell_start, out):
    """Lowest z of each fine cell (inf where empty); points are sorted by cell."""
    for k in range(out.shape[0]):
        m = np.inf
        for j in range(cell_start[k], cell_start[k + 1]):
            if vz[j] < m:
                m = vz[j]
        out[k] = m


@njit(cache=True, nogil=True)
def _has_support(i, vx, vy, vz, zmin, cell, ncols, nrows, block, radius, dz, tan_angle, share):
    """Whether point ``i`` is ground enough to be a seed: among the non-empty fine cells whose
    centre is within ``radius`` of it, at least ``share`` have their lowest point no higher
    than ``dz + tan_angle * h`` above it (h the horizontal distance to the cell centre). An
    isolated low outlier, or a group of them (multipath echoes along a wall), lies far below
    most cells around it; real ground, even in a forest or a pit, does not (the lowest points of
    most cells around it are ground too). Coordinates are relative to the fine grid's origin."""
    nbx = (ncols + block - 1) // block
    px = vx[i]
    py = vy[i]
    pz = vz[i]
    c0 = int(px / cell)
    r0 = int(py / cell)
    reach = int(math.ceil(radius / cell))
    total = 0
    ok = 0
    for r in range(max(r0 - reach, 0), min(r0 + reach, nrows - 1) + 1):
        for c in range(max(c0 - reach, 0), min(c0 + reach, ncols - 1) + 1):
            m = zmin[_cell_key(c, r, nbx, block)]
            if m == np.inf:
                continue
            hx = (c + 0.5) * cell - px
            hy = (r + 0.5) * cell - py
            h = math.sqrt(hx * hx + hy * hy)
            if h > radius:
                continue
            total += 1
            if m - pz <= dz + tan_angle * h:
                ok += 1
    return total == 0 or ok >= share * total


@njit(cache=True, nogil=True)
def seeds_kernel(vx, vy, vz, n, seed_cell, scols, srows, zmin_fine, cell, ncols, nrows, block,
                 radius, dz, tan_angle, share, max_tries, status, seed_of_cell, active):
    """The seed of each ``active`` seed cell: its lowest point that has support (see _has_support;
    the lowest point of each fine cell is in ``zmin_fine``; radius < 0: no test). A lowest point
    without support is a low outlier: it is EXCLUDED and the next lowest is tried, at most
    ``max_tries`` times a cell (then the cell has no seed). ``seed_of_cell`` gets the sorted
    index of each active cell's seed or -1 (the other cells' entries are left as they are)."""
    ncell = scols * srows
    zmin = np.empty(ncell)
    found = np.empty(ncell, dtype=np.int64)
    tries = np.zeros(ncell, dtype=np.int64)
    done = np.empty(ncell, dtype=np.bool_)
    for k in range(ncell):
        done[k] = not active[k]
        if active[k]:
            seed_of_cell[k] = -1
    pending = ncell
    while pending > 0:
        zmin[:] = np.inf
        found[:] = -1
        for i in range(n):
            if status[i] == EXCLUDED:
                continue
            c = min(max(int(vx[i] / seed_cell), 0), scols - 1)
            r = min(max(int(vy[i] / seed_cell), 0), srows - 1)
            k = r * scols + c
            if done[k]:
                continue
            if vz[i] < zmin[k]:
                zmin[k] = vz[i]
                found[k] = i
        pending = 0
        for k in range(ncell):
            if done[k]:
                continue
            i = found[k]
            if i < 0:
                done[k] = True
                continue
            if radius < 0.0 or _has_support(i, vx, vy, vz, zmin_fine, cell, ncols, nrows, block, radius, dz,
                                            tan_angle, share):
                seed_of_cell[k] = i
                done[k] = True
                continue
            status[i] = EXCLUDED
            tries[k] += 1
            if tries[k] >= max_tries:
                done[k] = True
            else:
                pending += 1


# --- densification ----------------------------------------------------------------------------------

@njit(cache=True, nogil=True, inline="always")
def _longest_edge2(vx, vy, a, b, c):
    e1 = (vx[a] - vx[b]) ** 2 + (vy[a] - vy[b]) ** 2
    e2 = (vx[b] - vx[c]) ** 2 + (vy[b] - vy[c]) ** 2
    e3 = (vx[c] - vx[a]) ** 2 + (vy[c] - vy[a]) ** 2
    return max(e1, max(e2, e3))


@njit(cache=True, nogil=True, inline="always")
def _facet_plane(vx, vy, vz, a, b, c, max_slope2):
    """Unit normal (pointing up) of the facet (a, b, c); NaNs when the facet is vertical or
    steeper than the terrain angle (slope² > ``max_slope2``, e.g. one stood up along a wall:
    no terrain, it accepts nothing). Computed once per facet for all the points tested in it."""
    ax = vx[a]
    ay = vy[a]
    az = vz[a]
    ux = vx[b] - ax
    uy = vy[b] - ay
    uz = vz[b] - az
    wx = vx[c] - ax
    wy = vy[c] - ay
    wz = vz[c] - az
    nx = uy * wz - uz * wy
    ny = uz * wx - ux * wz
    nz = ux * wy - uy * wx
    if nz == 0.0 or nx * nx + ny * ny > max_slope2 * nz * nz:
        return np.nan, np.nan, np.nan
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nz < 0.0:
        norm = -norm
    return nx / norm, ny / norm, nz / norm


@njit(cache=True, nogil=True, inline="always")
def _plane_test(vx, vy, vz, a, b, c, nx, ny, nz, px, py, pz, tan2_angle, max_dist, below_free):
    """Axelsson's test of point p against the facet (a, b, c) of unit normal (nx, ny, nz) (from
    _facet_plane; NaN: the facet accepts nothing). Above the facet, p passes when its distance
    to the facet's plane is at most ``max_dist`` and every angle between the plane and the lines
    from p to the three vertices is at most the iteration angle (tan² given; the angle at the
    vertex nearest p's projection is the largest). Below the facet (with ``below_free``) only
    the distance counts: the TIN, built up from the lowest points, is too high there. Returns
    the signed distance (positive above) when p passes, NaN otherwise."""
    if nz != nz:
        return np.nan
    ax = vx[a]
    ay = vy[a]
    az = vz[a]
    d = (px - ax) * nx + (py - ay) * ny + (pz - az) * nz
    if abs(d) > max_dist:
        return np.nan
    if d < 0.0 and below_free:
        return d
    qx = px - d * nx
    qy = py - d * ny
    qz = pz - d * nz
    h2 = (qx - ax) ** 2 + (qy - ay) ** 2 + (qz - az) ** 2
    e2 = (qx - vx[b]) ** 2 + (qy - vy[b]) ** 2 + (qz - vz[b]) ** 2
    if e2 < h2:
        h2 = e2
    e2 = (qx - vx[c]) ** 2 + (qy - vy[c]) ** 2 + (qz - vz[c]) ** 2
    if e2 < h2:
        h2 = e2
    if d * d > tan2_angle * h2:
        return np.nan
    return d


@njit(cache=True, nogil=True, inline="always")
def _axelsson_test(vx, vy, vz, a, b, c, px, py, pz, tan2_angle, max_dist, max_slope2, below_free):
    """Axelsson's test of point p against the facet (a, b, c) (_facet_plane, then _plane_test).
    Returns the signed distance (positive above) when p passes, NaN otherwise."""
    nx, ny, nz = _facet_plane(vx, vy, vz, a, b, c, max_slope2)
    return _plane_test(vx, vy, vz, a, b, c, nx, ny, nz, px, py, pz, tan2_angle, max_dist, below_free)


@njit(cache=True, nogil=True)
def _test_point(tv, tn, vx, vy, vz, t, nx, ny, nz, px, py, pz, tan2_angle, max_dist, max_slope2, mirror):
    """Axelsson's test of point p in triangle t (of unit normal (nx, ny, nz), from _facet_plane);
    when it fails and ``mirror`` is set, the test of p's mirror image through the nearest vertex
    of t (2 v - p, in 3-D) against the triangle holding that image: a point up a steep slope
    from a vertex passes when the slope goes on beyond the vertex, which a single facet across a
    break of slope cannot show (Axelsson's mirror points). Returns the signed distance of the point (or of its image) to the facet
    when it passes, NaN otherwise."""
    a = tv[t, 0]
    b = tv[t, 1]
    c = tv[t, 2]
    d = _plane_test(vx, vy, vz, a, b, c, nx, ny, nz, px, py, pz, tan2_angle, max_dist, True)
    if d == d or not mirror:
        return d
    v = a
    best = (vx[a] - px) ** 2 + (vy[a] - py) ** 2
    e = (vx[b] - px) ** 2 + (vy[b] - py) ** 2
    if e < best:
        best = e
        v = b
    e = (vx[c] - px) ** 2 + (vy[c] - py) ** 2
    if e < best:
        v = c
    mx = 2.0 * vx[v] - px
    my = 2.0 * vy[v] - py
    mz = 2.0 * vz[v] - pz
    t2 = _walk(tv, tn, vx, vy, t, mx, my)
    if t2 < 0 or t2 == t:
        return np.nan
    # the image is held to the full test even below its facet: otherwise a point could climb
    # any rise by mirroring it into a hollow
    return _axelsson_test(vx, vy, vz, tv[t2, 0], tv[t2, 1], tv[t2, 2], mx, my, mz, tan2_angle, max_dist,
                          max_slope2, False)


@njit(cache=True, nogil=True, inline="always")
def _at_vertex(vx, vy, a, b, c, px, py):
    """Whether (px, py) is at the position of vertex a, b or c (within _ON_EDGE_M)."""
    e = _ON_EDGE_M * _ON_EDGE_M
    return ((vx[a] - px) ** 2 + (vy[a] - py) ** 2 <= e or (vx[b] - px) ** 2 + (vy[b] - py) ** 2 <= e
            or (vx[c] - px) ** 2 + (vy[c] - py) ** 2 <= e)


@njit(cache=True, nogil=True, parallel=True)
def test_kernel(tv, tn, vx, vy, vz, head, nxt, status, dirty, ndirty, best,
                tan2_angle, max_dist, max_slope2, min_edge2, max_edge2, mirror):
    """Phase 1 of a round: the candidates of every dirty triangle are tested against its facet
    and ``best[t]`` gets the passing point nearest the plane (-1: none). A point that passes
    in a triangle whose edges are all shorter than ``sqrt(min_edge2)``, or at the position of
    one of its vertices, is ground at once, without insertion; a triangle with an edge longer
    than ``sqrt(max_edge2)`` accepts nothing (inf: no limit). Triangles are handled in parallel
    (each changes only its own list). Returns the number of points labelled ground here."""
    total = 0
    for k in prange(ndirty):
        t = dirty[k]
        a = tv[t, 0]
        b = tv[t, 1]
        c = tv[t, 2]
        e2 = _longest_edge2(vx, vy, a, b, c)
        frozen = e2 < min_edge2
        nx, ny, nz = _facet_plane(vx, vy, vz, a, b, c, max_slope2)
        bi = -1
        bd = np.inf
        kept = -1
        found = 0
        x = head[t]
        while x >= 0:
            following = int(nxt[x])
            if status[x] == CANDIDATE:
                keep = True
                if e2 <= max_edge2:
                    d = _test_point(tv, tn, vx, vy, vz, t, nx, ny, nz, vx[x], vy[x], vz[x], tan2_angle,
                                    max_dist, max_slope2, mirror)
                    if d == d:
                        if frozen or _at_vertex(vx, vy, a, b, c, vx[x], vy[x]):
                            # not to be inserted: ground at once
                            status[x] = GROUND_OTHER
                            found += 1
                            keep = False
                        elif abs(d) < bd:
                            bd = abs(d)
                            bi = x
                if keep:
                    nxt[x] = kept
                    kept = x
            x = following
        head[t] = kept
        best[t] = bi
        total += found
    return total


@njit(cache=True, nogil=True)
def insert_kernel(tv, tn, tstamp, vx, vy, vz, head, nxt, status, dirty, ndirty, best, new_dirty, state,
                  tan2_angle, max_dist, max_slope2, min_edge2, max_edge2, mirror):
    """Phase 2 of a round: the best point of each dirty triangle is added to the ground:
    inserted into the TIN (its triangles go on the new dirty list, ``state[1:3]`` being that
    list's length and mark), or, in a triangle too small to densify or at the position of a
    vertex, only labelled ground. A point whose triangle was changed by an earlier insertion of
    the round is tested again against the TIN as it is now. Returns the number of points added."""
    stack = np.empty(4096, dtype=np.int32)
    added = 0
    for k in range(ndirty):
        t0 = dirty[k]
        i = best[t0]
        if i < 0 or status[i] != CANDIDATE:
            continue
        t = _locate(tv, tn, state[0], vx, vy, t0, vx[i], vy[i])
        a = tv[t, 0]
        b = tv[t, 1]
        c = tv[t, 2]
        e2 = _longest_edge2(vx, vy, a, b, c)
        if t != t0 or tstamp[t] == state[2]:
            # changed in this round: test again (when it fails now, its triangle is dirty and
            # it will be tested again next round)
            if e2 > max_edge2:
                continue
            nx, ny, nz = _facet_plane(vx, vy, vz, a, b, c, max_slope2)
            d = _test_point(tv, tn, vx, vy, vz, t, nx, ny, nz, vx[i], vy[i], vz[i], tan2_angle, max_dist,
                            max_slope2, mirror)
            if d != d:
                continue
        if e2 < min_edge2:
            status[i] = GROUND_OTHER
        else:
            status[i] = GROUND_VERTEX
            if not _insert(tv, tn, tstamp, new_dirty, state, vx, vy, head, nxt, status, i, t, stack):
                status[i] = GROUND_OTHER  # at the position of a vertex
        # the triangle's other points get another turn next round
        _mark(tstamp, new_dirty, state, t)
        added += 1
    return added


@njit(cache=True, nogil=True, parallel=True)
def offset_kernel(tv, ntri, vx, vy, vz, head, nxt, status, offset, max_slope2, max_edge2):
    """After densification: a candidate within ``offset`` (above or below) of the final TIN's
    facet is ground (GROUND_OTHER), unless the facet has an edge longer than
    ``sqrt(max_edge2)``. Returns how many."""
    total = 0
    for t in prange(ntri):
        found = 0
        if _longest_edge2(vx, vy, tv[t, 0], tv[t, 1], tv[t, 2]) > max_edge2:
            continue
        a = tv[t, 0]
        b = tv[t, 1]
        c = tv[t, 2]
        nx, ny, nz = _facet_plane(vx, vy, vz, a, b, c, max_slope2)
        x = head[t]
        while x >= 0:
            if status[x] == CANDIDATE:
                d = _plane_test(vx, vy, vz, a, b, c, nx, ny, nz, vx[x], vy[x], vz[x], np.inf, offset, True)
                if d == d:
                    status[x] = GROUND_OTHER
                    found += 1
            x = int(nxt[x])
        total += found
    return total


@njit(cache=True, nogil=True)
def _add_unique(arr, m, value):
    for q in range(m):
        if arr[q] == value:
            return m
    if m < arr.shape[0]:
        arr[m] = value
        m += 1
    return m


@njit(cache=True, nogil=True)
def update_virtual_kernel(tv, tn, tstamp, dirty, state, vx, vy, vz, n, nv, hints, zlo, zhi, tol):
    """Give each virtual vertex (indices n .. nv-1) the height that the plane fitted (least
    squares) to the real vertices among its neighbours and their neighbours in the TIN takes at
    its position, clipped to [zlo, zhi]: the TIN near the data's border then extrapolates the
    terrain instead of bending towards an arbitrary height. Where the height changes by more
    than ``tol``, the triangles around the vertex go on the dirty list so that their points are
    tested again. Returns the number of vertices moved."""
    ring1 = np.empty(256, dtype=np.int64)
    ring2 = np.empty(256, dtype=np.int64)
    real = np.empty(2048, dtype=np.int64)
    moved = 0
    ntri = state[0]
    for v in range(n, nv):
        t0 = _incident(tv, tn, ntri, vx, vy, hints[v - n], v)
        if t0 < 0:
            continue
        hints[v - n] = t0
        m1 = _star(tv, tn, t0, v, ring1)
        nreal = 0
        for k in range(m1):
            a = ring1[k]
            if a >= n:
                continue
            nreal = _add_unique(real, nreal, a)
            ta = _incident(tv, tn, ntri, vx, vy, t0, a)
            if ta < 0:
                continue
            m2 = _star(tv, tn, ta, a, ring2)
            for kk in range(m2):
                if ring2[kk] < n:
                    nreal = _add_unique(real, nreal, ring2[kk])
        if nreal == 0:
            continue
        # least squares z = c0 + c1 dx + c2 dy around v
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for q in range(nreal):
            j = real[q]
            sx += vx[j] - vx[v]
            sy += vy[j] - vy[v]
            sz += vz[j]
        mx = sx / nreal
        my = sy / nreal
        mz = sz / nreal
        sxx = 0.0
        sxy = 0.0
        syy = 0.0
        sxz = 0.0
        syz = 0.0
        for q in range(nreal):
            j = real[q]
            dx = vx[j] - vx[v] - mx
            dy = vy[j] - vy[v] - my
            dz = vz[j] - mz
            sxx += dx * dx
            sxy += dx * dy
            syy += dy * dy
            sxz += dx * dz
            syz += dy * dz
        det = sxx * syy - sxy * sxy
        z = mz
        if nreal >= 3 and det > 1e-9 * (sxx + syy) ** 2 and det > 0.0:
            gx = (syy * sxz - sxy * syz) / det
            gy = (sxx * syz - sxy * sxz) / det
            z = mz - gx * mx - gy * my
        z = min(max(z, zlo), zhi)
        if abs(z - vz[v]) <= tol:
            continue
        vz[v] = z
        moved += 1
        # the triangles around v are dirty: turn one way, then (on the boundary) the other
        t = t0
        while True:
            _mark(tstamp, dirty, state, t)
            i = 0
            while tv[t, i] != v:
                i += 1
            nt = tn[t, (i + 1) % 3]
            if nt < 0 or nt == t0:
                break
            t = nt
        if nt < 0:
            t = t0
            while True:
                i = 0
                while tv[t, i] != v:
                    i += 1
                nt = tn[t, (i + 2) % 3]
                if nt < 0:
                    break
                t = nt
                _mark(tstamp, dirty, state, t)
    return moved


# --- thinning and the last pass ---------------------------------------------------------------------

@njit(cache=True, nogil=True)
def thin_kernel(vx, vy, vz, n, thin, ncols, nrows, status):
    """Keep as candidates only the lowest point of each square of side ``thin`` (a grid of
    ``ncols`` x ``nrows`` squares from the origin); the others become THINNED: they take no
    part in the densification and are judged against the final TIN instead."""
    lowest = np.full(ncols * nrows, -1, dtype=np.int64)
    for j in range(n):
        if status[j] != CANDIDATE:
            continue
        c = min(max(int(vx[j] / thin), 0), ncols - 1)
        r = min(max(int(vy[j] / thin), 0), nrows - 1)
        k = r * ncols + c
        b = lowest[k]
        if b < 0:
            lowest[k] = j
        elif vz[j] < vz[b]:
            status[b] = THINNED
            lowest[k] = j
        else:
            status[j] = THINNED


@njit(cache=True, nogil=True, parallel=True)
def last_pass_kernel(tv, tn, ntri, vx, vy, vz, n, status, tan2_angle, max_dist, max_slope2, max_edge2,
                     offset, mirror):
    """The thinned points, judged against the final TIN: ground when they pass Axelsson's test
    (as a candidate would have) or lie within ``offset`` of the facet. Returns how many."""
    nchunks = 256
    size = (n + nchunks - 1) // nchunks
    counts = np.zeros(nchunks, dtype=np.int64)
    for ch in prange(nchunks):
        hint = 0
        last = -1  # the triangle whose plane and edge test are at hand (consecutive points share one)
        long = False
        nx = ny = nz = np.nan
        for i in range(ch * size, min((ch + 1) * size, n)):
            if status[i] != THINNED:
                continue
            t = _locate(tv, tn, ntri, vx, vy, hint, vx[i], vy[i])
            hint = t
            a = tv[t, 0]
            b = tv[t, 1]
            c = tv[t, 2]
            if t != last:
                last = t
                long = _longest_edge2(vx, vy, a, b, c) > max_edge2
                nx, ny, nz = _facet_plane(vx, vy, vz, a, b, c, max_slope2)
            if long:
                continue
            d = _test_point(tv, tn, vx, vy, vz, t, nx, ny, nz, vx[i], vy[i], vz[i], tan2_angle, max_dist,
                            max_slope2, mirror)
            if d != d and offset > 0.0:
                d = _plane_test(vx, vy, vz, a, b, c, nx, ny, nz, vx[i], vy[i], vz[i], np.inf, offset, True)
            if d == d:
                status[i] = GROUND_OTHER
                counts[ch] += 1
    return counts.sum()
