"""The TIN of progressive TIN densification (core.filters.ptd), in numba. Private: call it through
:class:`~groundsieve.core.filters.ptd.PTD`, which validates and lays out the arrays first; the
densification rules that decide what is inserted are in ``_ptd_kernels``.

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
from numba import njit


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
