"""numba kernels of progressive TIN densification (core.ptd). Private: call them through
:class:`~groundsieve.core.ptd.PTD`, which validates and lays out the arrays first.

The TIN is an incremental Delaunay triangulation with an adjacency structure:

* vertices are indices into the coordinate arrays ``vx, vy, vz``: the points (sorted
  spatially) followed by a few virtual vertices around the data;
* triangle ``t`` has vertices ``tv[t, 0..2]`` counter-clockwise and neighbours ``tn[t, i]``,
  the triangle across the edge opposite ``tv[t, i]`` (-1 on the outer boundary);
* every triangle keeps the candidate points lying in it (in plan) in a linked list, ``head[t]``
  then ``nxt[point]``; when a triangle is split or flipped, the points of the triangles it
  replaces are shared out among the new ones by orientation tests, so no point is ever looked
  for again;
* a triangle made or changed since the last test is "dirty": it is put on a list (once:
  ``tstamp[t]`` holds the mark of the list it is on) and only the points of dirty triangles
  are tested in the next round.

``state`` = [number of triangles, length of the dirty list being filled, its mark].

A new vertex splits its triangle in three (or, on an edge, the two triangles of the edge in
four) and the Delaunay property is restored by Lawson flips. Predicates are evaluated in
floating point on coordinates relative to the data's corner with small tolerances: a point
within 1e-6 m of an edge is inserted on the edge, one within 1e-6 m of a vertex is not
inserted (a duplicate position), and an edge is flipped only when the opposite vertex is
clearly inside the circumcircle (cocircular points are left alone).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: point states
CANDIDATE = 0
GROUND_VERTEX = 1     #: ground, vertex of the TIN
GROUND_OTHER = 2      #: ground, not inserted (in a triangle too small to densify, a duplicate, near the TIN)
EXCLUDED = 3          #: never ground (a cell's lowest point rejected as a low outlier)
THINNED = 4           #: not the lowest of its thinning square: judged against the final TIN only

_ON_EDGE_M = 1e-6     #: a point this close to an edge (m) is inserted on the edge
_INCIRCLE_REL = 1e-12  #: flip only when the in-circle determinant exceeds this share of its magnitude


# --- predicates ------------------------------------------------------------------------------

@njit(cache=True, nogil=True, inline="always")
def _orient(ax, ay, bx, by, cx, cy):
    """Twice the signed area of (a, b, c): > 0 when counter-clockwise."""
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(cache=True, nogil=True)
def _incircle(ax, ay, bx, by, cx, cy, dx, dy):
    """True when d is clearly inside the circle through the counter-clockwise a, b, c."""
    adx = ax - dx
    ady = ay - dy
    bdx = bx - dx
    bdy = by - dy
    cdx = cx - dx
    cdy = cy - dy
    ad = adx * adx + ady * ady
    bd = bdx * bdx + bdy * bdy
    cd = cdx * cdx + cdy * cdy
    det = (adx * (bdy * cd - bd * cdy) - ady * (bdx * cd - bd * cdx) + ad * (bdx * cdy - bdy * cdx))
    mag = (abs(adx) * (abs(bdy) * cd + bd * abs(cdy)) + abs(ady) * (abs(bdx) * cd + bd * abs(cdx))
           + ad * (abs(bdx) * abs(cdy) + abs(bdy) * abs(cdx)))
    return det > _INCIRCLE_REL * mag


# --- point location -------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _walk(tv, tn, vx, vy, t, px, py):
    """The triangle holding (px, py), found by walking from triangle ``t``: at each step, cross
    the first edge (in an order that rotates from step to step, so the walk cannot cycle) that
    has the point strictly on its outer side. -1 if the walk leaves the triangulation."""
    step = 0
    while True:
        moved = False
        for k in range(3):
            e = (k + step) % 3
            a = tv[t, (e + 1) % 3]
            b = tv[t, (e + 2) % 3]
            ax = vx[a]
            ay = vy[a]
            bx = vx[b]
            by = vy[b]
            o = _orient(ax, ay, bx, by, px, py)
            if o < 0.0:
                # a point on the edge's line (within rounding) is not outside
                tol = 4e-16 * (abs(bx - ax) * abs(py - ay) + abs(by - ay) * abs(px - ax))
                if o < -tol:
                    t = tn[t, e]
                    if t < 0:
                        return -1
                    moved = True
                    break
        if not moved:
            return t
        step += 1
        if step > 100_000_000:
            return -1


@njit(cache=True, nogil=True)
def _locate_brute(tv, ntri, vx, vy, px, py):
    """The first triangle holding (px, py), by testing every triangle (tests and fall-back)."""
    for t in range(ntri):
        a = tv[t, 0]
        b = tv[t, 1]
        c = tv[t, 2]
        if (_orient(vx[a], vy[a], vx[b], vy[b], px, py) >= 0.0
                and _orient(vx[b], vy[b], vx[c], vy[c], px, py) >= 0.0
                and _orient(vx[c], vy[c], vx[a], vy[a], px, py) >= 0.0):
            return t
    return -1


@njit(cache=True, nogil=True)
def _locate(tv, tn, ntri, vx, vy, t, px, py):
    r = _walk(tv, tn, vx, vy, t, px, py)
    if r < 0:
        r = _locate_brute(tv, ntri, vx, vy, px, py)
    return r


# --- TIN updates ---------------------------------------------------------------------------------

@njit(cache=True, nogil=True, inline="always")
def _replace_neighbor(tn, u, old, new):
    if u >= 0:
        for k in range(3):
            if tn[u, k] == old:
                tn[u, k] = new
                return


@njit(cache=True, nogil=True, inline="always")
def _mark(tstamp, dirty, state, t):
    """Put triangle t on the dirty list being filled (once)."""
    if tstamp[t] != state[2]:
        tstamp[t] = state[2]
        dirty[state[1]] = t
        state[1] += 1


@njit(cache=True, nogil=True, inline="always")
def _push(head, nxt, t, x):
    nxt[x] = head[t]
    head[t] = x


@njit(cache=True, nogil=True)
def _share_by_line(lst, ax, ay, bx, by, left, right, vx, vy, head, nxt, status):
    """Move the points of the list starting at ``lst`` to triangle ``left`` when they lie on the
    left of a -> b (or on it), else to ``right``. (Points that are no longer candidates move
    along; the next test drops them.)"""
    x = lst
    while x >= 0:
        following = int(nxt[x])
        if _orient(ax, ay, bx, by, vx[x], vy[x]) >= 0.0:
            _push(head, nxt, left, x)
        else:
            _push(head, nxt, right, x)
        x = following


@njit(cache=True, nogil=True)
def _legalize(tv, tn, tstamp, dirty, state, vx, vy, head, nxt, status, stack, nstack):
    """Lawson flips from the triangles on ``stack`` (each with the new vertex at index 0)."""
    while nstack > 0:
        nstack -= 1
        t = stack[nstack]
        u = tn[t, 0]
        if u < 0:
            continue
        p = tv[t, 0]
        q = tv[t, 1]
        r = tv[t, 2]
        j = 0
        while tn[u, j] != t:
            j += 1
        s = tv[u, j]
        if not _incircle(vx[p], vy[p], vx[q], vy[q], vx[r], vy[r], vx[s], vy[s]):
            continue
        a_nb = tn[t, 1]             # across (r, p)
        b_nb = tn[t, 2]             # across (p, q)
        c_nb = tn[u, (j + 1) % 3]   # across (q, s)
        d_nb = tn[u, (j + 2) % 3]   # across (s, r)
        # t becomes (p, q, s), u becomes (p, s, r)
        tv[t, 2] = s
        tn[t, 0] = c_nb
        tn[t, 1] = u
        tn[t, 2] = b_nb
        tv[u, 0] = p
        tv[u, 1] = s
        tv[u, 2] = r
        tn[u, 0] = d_nb
        tn[u, 1] = a_nb
        tn[u, 2] = t
        _replace_neighbor(tn, c_nb, u, t)
        _replace_neighbor(tn, a_nb, t, u)
        # their points: left of p -> s is u, right is t
        lt = head[t]
        lu = head[u]
        head[t] = -1
        head[u] = -1
        _share_by_line(lt, vx[p], vy[p], vx[s], vy[s], u, t, vx, vy, head, nxt, status)
        _share_by_line(lu, vx[p], vy[p], vx[s], vy[s], u, t, vx, vy, head, nxt, status)
        _mark(tstamp, dirty, state, t)
        _mark(tstamp, dirty, state, u)
        if nstack + 2 > stack.shape[0]:
            continue  # cannot happen in practice (the stack is large); stay safe
        stack[nstack] = t
        stack[nstack + 1] = u
        nstack += 2


@njit(cache=True, nogil=True)
def _insert(tv, tn, tstamp, dirty, state, vx, vy, head, nxt, status, v, t, stack):
    """Insert vertex ``v`` (no longer a candidate) into the TIN; ``t`` is a triangle holding it.
    Returns False (nothing changed) when ``v`` is at the position of a vertex of ``t``."""
    px = vx[v]
    py = vy[v]
    a = tv[t, 0]
    b = tv[t, 1]
    c = tv[t, 2]
    edge = -1
    for e in range(3):
        i = tv[t, (e + 1) % 3]
        k = tv[t, (e + 2) % 3]
        ex = vx[k] - vx[i]
        ey = vy[k] - vy[i]
        length = math.sqrt(ex * ex + ey * ey)
        d = abs(_orient(vx[i], vy[i], vx[k], vy[k], px, py)) / length if length > 0.0 else 0.0
        if d <= _ON_EDGE_M:
            if edge >= 0:
                return False  # on two edges: on their common vertex
            edge = e
    for w in (a, b, c):
        dx = vx[w] - px
        dy = vy[w] - py
        if dx * dx + dy * dy <= _ON_EDGE_M * _ON_EDGE_M:
            return False
    ntri = state[0]
    if edge < 0 or tn[t, edge] < 0:
        # split t in three: t0 = (v, a, b) in t, t1 = (v, b, c), t2 = (v, c, a)
        na = tn[t, 0]
        nb = tn[t, 1]
        nc = tn[t, 2]
        t0 = t
        t1 = ntri
        t2 = ntri + 1
        state[0] = ntri + 2
        tv[t0, 0] = v
        tv[t0, 1] = a
        tv[t0, 2] = b
        tn[t0, 0] = nc
        tn[t0, 1] = t1
        tn[t0, 2] = t2
        tv[t1, 0] = v
        tv[t1, 1] = b
        tv[t1, 2] = c
        tn[t1, 0] = na
        tn[t1, 1] = t2
        tn[t1, 2] = t0
        tv[t2, 0] = v
        tv[t2, 1] = c
        tv[t2, 2] = a
        tn[t2, 0] = nb
        tn[t2, 1] = t0
        tn[t2, 2] = t1
        _replace_neighbor(tn, na, t, t1)
        _replace_neighbor(tn, nb, t, t2)
        tstamp[t1] = -1
        tstamp[t2] = -1
        lst = head[t]
        head[t0] = -1
        head[t1] = -1
        head[t2] = -1
        x = lst
        while x >= 0:
            following = int(nxt[x])
            if x != v:
                xx = vx[x]
                yy = vy[x]
                sa = _orient(px, py, vx[a], vy[a], xx, yy)
                sb = _orient(px, py, vx[b], vy[b], xx, yy)
                if sa >= 0.0 and sb <= 0.0:
                    _push(head, nxt, t0, x)
                elif sb >= 0.0 and _orient(px, py, vx[c], vy[c], xx, yy) <= 0.0:
                    _push(head, nxt, t1, x)
                else:
                    _push(head, nxt, t2, x)
            x = following
        _mark(tstamp, dirty, state, t0)
        _mark(tstamp, dirty, state, t1)
        _mark(tstamp, dirty, state, t2)
        stack[0] = t0
        stack[1] = t1
        stack[2] = t2
        _legalize(tv, tn, tstamp, dirty, state, vx, vy, head, nxt, status, stack, 3)
        return True
    # on the edge opposite tv[t, edge]: split t and its neighbour u in two each
    u = tn[t, edge]
    aa = tv[t, edge]
    q = tv[t, (edge + 1) % 3]
    r = tv[t, (edge + 2) % 3]
    j = 0
    while tn[u, j] != t:
        j += 1
    s = tv[u, j]
    a_nb = tn[t, (edge + 1) % 3]   # across (r, aa)
    b_nb = tn[t, (edge + 2) % 3]   # across (aa, q)
    c_nb = tn[u, (j + 1) % 3]      # across (q, s)
    d_nb = tn[u, (j + 2) % 3]      # across (s, r)
    t1 = t
    t2 = ntri
    u1 = u
    u2 = ntri + 1
    state[0] = ntri + 2
    tv[t1, 0] = v
    tv[t1, 1] = aa
    tv[t1, 2] = q
    tn[t1, 0] = b_nb
    tn[t1, 1] = u2
    tn[t1, 2] = t2
    tv[t2, 0] = v
    tv[t2, 1] = r
    tv[t2, 2] = aa
    tn[t2, 0] = a_nb
    tn[t2, 1] = t1
    tn[t2, 2] = u1
    tv[u1, 0] = v
    tv[u1, 1] = s
    tv[u1, 2] = r
    tn[u1, 0] = d_nb
    tn[u1, 1] = t2
    tn[u1, 2] = u2
    tv[u2, 0] = v
    tv[u2, 1] = q
    tv[u2, 2] = s
    tn[u2, 0] = c_nb
    tn[u2, 1] = u1
    tn[u2, 2] = t1
    _replace_neighbor(tn, a_nb, t, t2)
    _replace_neighbor(tn, c_nb, u, u2)
    tstamp[t2] = -1
    tstamp[u2] = -1
    lt = head[t]
    lu = head[u]
    head[t1] = -1
    head[t2] = -1
    head[u1] = -1
    head[u2] = -1
    # t's points: left of v -> aa is t1 = (v, aa, q); u's: left of v -> s is u1 = (v, s, r)
    _share_by_line(lt, px, py, vx[aa], vy[aa], t1, t2, vx, vy, head, nxt, status)
    _share_by_line(lu, px, py, vx[s], vy[s], u1, u2, vx, vy, head, nxt, status)
    _mark(tstamp, dirty, state, t1)
    _mark(tstamp, dirty, state, t2)
    _mark(tstamp, dirty, state, u1)
    _mark(tstamp, dirty, state, u2)
    stack[0] = t1
    stack[1] = t2
    stack[2] = u1
    stack[3] = u2
    _legalize(tv, tn, tstamp, dirty, state, vx, vy, head, nxt, status, stack, 4)
    return True


@njit(cache=True, nogil=True)
def init_box_kernel(tv, tn, tstamp, head, state, c0, c1, c2, c3):
    """Two triangles over the four counter-clockwise corner vertices c0..c3."""
    tv[0, 0] = c0
    tv[0, 1] = c1
    tv[0, 2] = c2
    tv[1, 0] = c0
    tv[1, 1] = c2
    tv[1, 2] = c3
    tn[0, 0] = -1   # across (c1, c2)
    tn[0, 1] = 1    # across (c2, c0)
    tn[0, 2] = -1   # across (c0, c1)
    tn[1, 0] = -1   # across (c2, c3)
    tn[1, 1] = -1   # across (c3, c0)
    tn[1, 2] = 0    # across (c0, c2)
    tstamp[0] = -1
    tstamp[1] = -1
    head[0] = -1
    head[1] = -1
    state[0] = 2


@njit(cache=True, nogil=True)
def insert_vertices_kernel(tv, tn, tstamp, dirty, state, vx, vy, head, nxt, status, vertices, inserted):
    """Insert ``vertices`` in order (the initial TIN, before any point is in a list);
    inserted[k] tells whether the k-th was (False for a duplicate position)."""
    stack = np.empty(4096, dtype=np.int32)
    hint = 0
    for k in range(vertices.shape[0]):
        v = vertices[k]
        t = _locate(tv, tn, state[0], vx, vy, hint, vx[v], vy[v])
        if t < 0:
            inserted[k] = False
            continue
        inserted[k] = _insert(tv, tn, tstamp, dirty, state, vx, vy, head, nxt, status, v, t, stack)
        hint = state[0] - 1 if inserted[k] else t


@njit(cache=True, nogil=True)
def fill_buckets_kernel(tv, tn, ntri, vx, vy, n, status, head, nxt):
    """Put every candidate in the list of the triangle holding it (points in spatial order, each
    search starting from the previous point's triangle)."""
    for t in range(ntri):
        head[t] = -1
    hint = 0
    for i in range(n):
        if status[i] != CANDIDATE:
            continue
        t = _locate(tv, tn, ntri, vx, vy, hint, vx[i], vy[i])
        _push(head, nxt, t, i)
        hint = t


@njit(cache=True, nogil=True)
def locate_kernel(tv, tn, ntri, vx, vy, px, py, out):
    """Triangle holding each (px, py), walking from triangle 0 (tests)."""
    for k in range(px.shape[0]):
        out[k] = _locate(tv, tn, ntri, vx, vy, 0, px[k], py[k])


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
                 radius, dz, tan_angle, share, max_tries, status, seed_of_cell):
    """The seed of each seed cell: its lowest point that has support (see _has_support; the
    lowest point of each fine cell is in ``zmin_fine``; radius < 0: no test). A lowest point
    without support is a low outlier: it is EXCLUDED and the next lowest is tried, at most
    ``max_tries`` times a cell (then the cell has no seed). ``seed_of_cell`` gets the sorted
    index of each cell's seed or -1."""
    ncell = scols * srows
    zmin = np.empty(ncell)
    found = np.empty(ncell, dtype=np.int64)
    tries = np.zeros(ncell, dtype=np.int64)
    done = np.zeros(ncell, dtype=np.bool_)
    seed_of_cell[:] = -1
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
def _axelsson_test(vx, vy, vz, a, b, c, px, py, pz, tan2_angle, max_dist, max_slope2, below_free):
    """Axelsson's test of point p against the facet (a, b, c). Above the facet, p passes when
    its distance to the facet's plane is at most ``max_dist`` and every angle between the
    plane and the lines from p to the three vertices is at most the iteration angle (tan²
    given; the angle at the vertex nearest p's projection is the largest). Below the facet
    (with ``below_free``) only the distance counts: the TIN, built up from the lowest points,
    is too high there. A facet steeper than the terrain angle (slope² > ``max_slope2``, e.g.
    one stood up along a wall) is no terrain and accepts nothing. Returns the signed distance
    (positive above) when p passes, NaN otherwise."""
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
        return np.nan
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nz < 0.0:
        norm = -norm
    nx /= norm
    ny /= norm
    nz /= norm
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


@njit(cache=True, nogil=True)
def _test_point(tv, tn, vx, vy, vz, t, px, py, pz, tan2_angle, max_dist, max_slope2, mirror):
    """Axelsson's test of point p in triangle t; when it fails and ``mirror`` is set, the test
    of p's mirror image through the nearest vertex of t (2 v - p, in 3-D) against the triangle
    holding that image: a point up a steep slope from a vertex passes when the slope goes on
    beyond the vertex, which a single facet across a break of slope cannot show (Axelsson's
    mirror points). Returns the signed distance of the point (or of its image) to the facet
    when it passes, NaN otherwise."""
    a = tv[t, 0]
    b = tv[t, 1]
    c = tv[t, 2]
    d = _axelsson_test(vx, vy, vz, a, b, c, px, py, pz, tan2_angle, max_dist, max_slope2, True)
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
                    d = _test_point(tv, tn, vx, vy, vz, t, vx[x], vy[x], vz[x], tan2_angle, max_dist,
                                    max_slope2, mirror)
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
            d = _test_point(tv, tn, vx, vy, vz, t, vx[i], vy[i], vz[i], tan2_angle, max_dist, max_slope2,
                            mirror)
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
        x = head[t]
        while x >= 0:
            if status[x] == CANDIDATE:
                d = _axelsson_test(vx, vy, vz, tv[t, 0], tv[t, 1], tv[t, 2], vx[x], vy[x], vz[x], np.inf,
                                   offset, max_slope2, True)
                if d == d:
                    status[x] = GROUND_OTHER
                    found += 1
            x = int(nxt[x])
        total += found
    return total


# --- virtual vertices -----------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _star(tv, tn, t0, v, out):
    """Vertices adjacent to ``v`` (``t0`` a triangle having ``v``), written to ``out``; returns
    their count (at most out.shape[0])."""
    m = 0
    t = t0
    while True:
        i = 0
        while tv[t, i] != v:
            i += 1
        if m < out.shape[0]:
            out[m] = tv[t, (i + 1) % 3]
            m += 1
        nt = tn[t, (i + 1) % 3]
        if nt < 0:
            # v is on the outer boundary: add the last neighbour, then turn the other way
            if m < out.shape[0]:
                out[m] = tv[t, (i + 2) % 3]
                m += 1
            t = t0
            while True:
                i = 0
                while tv[t, i] != v:
                    i += 1
                nt = tn[t, (i + 2) % 3]
                if nt < 0:
                    return m
                t = nt
                i = 0
                while tv[t, i] != v:
                    i += 1
                if m < out.shape[0]:
                    out[m] = tv[t, (i + 1) % 3]
                    m += 1
        t = nt
        if t == t0:
            return m


@njit(cache=True, nogil=True, inline="always")
def _has_vertex(tv, t, v):
    return tv[t, 0] == v or tv[t, 1] == v or tv[t, 2] == v


@njit(cache=True, nogil=True)
def _incident(tv, tn, ntri, vx, vy, hint, v):
    """A triangle having vertex ``v`` (``hint`` if it still has it, else found by walking to v
    and, failing that, by a scan)."""
    if hint >= 0 and hint < ntri and _has_vertex(tv, hint, v):
        return hint
    t = _walk(tv, tn, vx, vy, hint, vx[v], vy[v])
    if t >= 0 and _has_vertex(tv, t, v):
        return t
    for t in range(ntri):
        if _has_vertex(tv, t, v):
            return t
    return -1


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
        for i in range(ch * size, min((ch + 1) * size, n)):
            if status[i] != THINNED:
                continue
            t = _locate(tv, tn, ntri, vx, vy, hint, vx[i], vy[i])
            hint = t
            a = tv[t, 0]
            b = tv[t, 1]
            c = tv[t, 2]
            if _longest_edge2(vx, vy, a, b, c) > max_edge2:
                continue
            d = _test_point(tv, tn, vx, vy, vz, t, vx[i], vy[i], vz[i], tan2_angle, max_dist, max_slope2, mirror)
            if d != d and offset > 0.0:
                d = _axelsson_test(vx, vy, vz, a, b, c, vx[i], vy[i], vz[i], np.inf, offset, max_slope2, True)
            if d == d:
                status[i] = GROUND_OTHER
                counts[ch] += 1
    return counts.sum()
