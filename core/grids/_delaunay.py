"""Numba kernel of the 2-D Delaunay triangulation (see :mod:`.triangulate` for the public
function). Sweep-hull insertion: the points are sorted by distance from the circumcentre of a
small seed triangle and added one by one outside the current convex hull; each new point is
joined to the hull edges it sees, then Lawson flips restore the empty-circumcircle property.
The hull is a doubly-linked list of vertices, counter-clockwise, with a hash on the
pseudo-angle around the seed centre to find a visible edge in near-constant time. The mesh is
stored as half-edges: half-edge ``k`` runs from ``tri[k]`` to ``tri[next(k)]`` inside triangle
``k // 3`` and ``twin[k]`` is the opposite half-edge (-1 on the hull).

Conventions are this module's own: triangles are counter-clockwise, the hull runs
counter-clockwise (interior on the left of ``v -> hull_next[v]``), and ``hull_tri[v]`` is the
half-edge of the hull edge leaving ``v``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _orient(ax, ay, bx, by, cx, cy):
    """Twice the signed area of a, b, c: > 0 when counter-clockwise."""
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(cache=True, nogil=True, inline="always")
def _in_circle(ax, ay, bx, by, cx, cy, px, py):
    """> 0 when p is strictly inside the circumcircle of the counter-clockwise a, b, c."""
    dx = ax - px
    dy = ay - py
    ex = bx - px
    ey = by - py
    fx = cx - px
    fy = cy - py
    ap = dx * dx + dy * dy
    bp = ex * ex + ey * ey
    cp = fx * fx + fy * fy
    return dx * (ey * cp - bp * fy) - dy * (ex * cp - bp * fx) + ap * (ex * fy - ey * fx)


@njit(cache=True, nogil=True, inline="always")
def _circumcentre_offset(ax, ay, bx, by, cx, cy):
    """The circumcentre of a, b, c minus a (infinite when they are on a line)."""
    dx = bx - ax
    dy = by - ay
    ex = cx - ax
    ey = cy - ay
    bl = dx * dx + dy * dy
    cl = ex * ex + ey * ey
    d = dx * ey - dy * ex
    if d == 0.0:
        return np.inf, np.inf
    d = 0.5 / d
    return (ey * bl - dy * cl) * d, (dx * cl - ex * bl) * d


@njit(cache=True, nogil=True, inline="always")
def _circumradius2(ax, ay, bx, by, cx, cy):
    x, y = _circumcentre_offset(ax, ay, bx, by, cx, cy)
    return x * x + y * y


@njit(cache=True, nogil=True, inline="always")
def _pseudo_angle(dx, dy):
    """Monotone in the angle of (dx, dy), counter-clockwise from the west, in [0, 1)."""
    s = abs(dx) + abs(dy)
    if s == 0.0:
        return 0.0
    p = dx / s
    if dy > 0.0:
        return (3.0 - p) / 4.0
    return (1.0 + p) / 4.0


@njit(cache=True, nogil=True, inline="always")
def _hash_key(x, y, cx, cy, size):
    k = int(math.floor(_pseudo_angle(x - cx, y - cy) * size))
    return k % size


@njit(cache=True, nogil=True, inline="always")
def _link(twin, a, b):
    twin[a] = b
    if b != -1:
        twin[b] = a


@njit(cache=True, nogil=True)
def _legalize(a, px, py, tri, twin, hull_tri, stack):
    """Lawson flips from half-edge ``a`` (whose opposite vertex is the point just added),
    spreading to the edges opposite that point after each flip. ``stack`` holds the edges still
    to check; it doubles when full (never an edge dropped), and the stack in use is returned."""
    top = 0
    while True:
        b = twin[a]
        if b == -1:
            if top == 0:
                return stack
            top -= 1
            a = stack[top]
            continue
        a0 = a - a % 3
        al = a0 + (a + 1) % 3
        ar = a0 + (a + 2) % 3
        b0 = b - b % 3
        bl = b0 + (b + 2) % 3
        p0 = tri[ar]   # the new point
        pu = tri[a]
        pv = tri[al]
        p1 = tri[bl]   # the vertex across edge a
        if _in_circle(px[pu], py[pu], px[pv], py[pv], px[p0], py[p0], px[p1], py[p1]) > 0.0:
            # Flip u-v into p0-p1: triangle a becomes (p1, v, p0), triangle b (p0, u, p1).
            tri[a] = p1
            tri[b] = p0
            hbl = twin[bl]
            har = twin[ar]
            if hbl == -1:
                hull_tri[p1] = a
            if har == -1:
                hull_tri[p0] = b
            _link(twin, a, hbl)
            _link(twin, b, har)
            _link(twin, ar, bl)
            br = b0 + (b + 1) % 3
            if top == stack.shape[0]:
                bigger = np.empty(2 * stack.shape[0], dtype=np.int64)
                bigger[:top] = stack
                stack = bigger
            stack[top] = br
            top += 1
        else:
            if top == 0:
                return stack
            top -= 1
            a = stack[top]


@njit(cache=True, nogil=True)
def _add_triangle(tri, twin, t, i0, i1, i2, a, b, c):
    k = 3 * t
    tri[k] = i0
    tri[k + 1] = i1
    tri[k + 2] = i2
    _link(twin, k, a)
    _link(twin, k + 1, b)
    _link(twin, k + 2, c)
    return k


@njit(cache=True, nogil=True)
def _sort_by_distance(dist):
    """Indices ordering ``dist`` ascending (ties by index): a counting sort into n buckets
    of equal width, then an insertion sort inside each. Squared distances from a point inside
    the data are close to uniform (area grows with r²), so buckets hold one or two points and
    this is O(n) where a comparison sort took a sixth of the triangulation's time at 5 M.
    A crowded bucket is merge-sorted instead, so a skewed input costs O(n log n), not O(n²)."""
    n = dist.shape[0]
    dmax = dist.max()
    order = np.empty(n, dtype=np.int64)
    if not dmax > 0.0:
        for i in range(n):
            order[i] = i
        return order
    scale = n / dmax
    start = np.zeros(n + 1, dtype=np.int64)
    bucket = np.empty(n, dtype=np.int64)
    for i in range(n):
        b = min(int(dist[i] * scale), n - 1)
        bucket[i] = b
        start[b + 1] += 1
    for b in range(n):
        start[b + 1] += start[b]
    for i in range(n):  # ascending i: stable, so ties stay by index
        b = bucket[i]
        order[start[b]] = i
        start[b] += 1
    lo = 0
    for b in range(n):
        hi = start[b]  # start[b] is now the end of bucket b
        if hi - lo > 32:  # a crowded bucket (e.g. one far outlier squeezes the rest): merge sort
            idx = order[lo:hi].copy()
            sub = np.argsort(dist[idx], kind="mergesort")
            for k in range(hi - lo):
                order[lo + k] = idx[sub[k]]
            lo = hi
            continue
        for k in range(lo + 1, hi):
            v = order[k]
            dv = dist[v]
            j = k - 1
            while j >= lo and dist[order[j]] > dv:
                order[j + 1] = order[j]
                j -= 1
            order[j + 1] = v
        lo = hi
    return order


@njit(cache=True, nogil=True)
def delaunay_kernel(px, py, stack_size=1024):
    """(m, 3) counter-clockwise triangles of the Delaunay triangulation of distinct points
    ``px, py`` (best relative to the data's corner); (0, 3) when they are all on a line.
    ``stack_size``: first room of the flip stack, which grows as needed (tests set it tiny)."""
    n = px.shape[0]
    empty = np.empty((0, 3), dtype=np.int64)
    if n < 3:
        return empty
    minx = px.min()
    maxx = px.max()
    miny = py.min()
    maxy = py.max()
    mx = 0.5 * (minx + maxx)
    my = 0.5 * (miny + maxy)
    # Seed: the point nearest the box centre, its nearest neighbour, and the point making the
    # smallest circumcircle with them.
    i0 = 0
    best = np.inf
    for i in range(n):
        d = (px[i] - mx) ** 2 + (py[i] - my) ** 2
        if d < best:
            best = d
            i0 = i
    i1 = -1
    best = np.inf
    for i in range(n):
        if i == i0:
            continue
        d = (px[i] - px[i0]) ** 2 + (py[i] - py[i0]) ** 2
        if d < best and d > 0.0:
            best = d
            i1 = i
    if i1 == -1:
        return empty
    i2 = -1
    best = np.inf
    for i in range(n):
        if i == i0 or i == i1:
            continue
        r = _circumradius2(px[i0], py[i0], px[i1], py[i1], px[i], py[i])
        if r < best:
            best = r
            i2 = i
    if i2 == -1 or best == np.inf:
        return empty  # all points on a line
    if _orient(px[i0], py[i0], px[i1], py[i1], px[i2], py[i2]) < 0.0:
        i1, i2 = i2, i1
    # Circumcentre of the seed triangle.
    ux, uy = _circumcentre_offset(px[i0], py[i0], px[i1], py[i1], px[i2], py[i2])
    cx = px[i0] + ux
    cy = py[i0] + uy

    dist = np.empty(n, dtype=np.float64)
    for i in range(n):
        dist[i] = (px[i] - cx) ** 2 + (py[i] - cy) ** 2
    order = _sort_by_distance(dist)
    # Work on the points renumbered in insertion order: each new point, and the triangles
    # made just before, are then next to each other in memory.
    rank = np.empty(n, dtype=np.int64)
    sx = np.empty(n, dtype=np.float64)
    sy = np.empty(n, dtype=np.float64)
    for k in range(n):
        rank[order[k]] = k
        sx[k] = px[order[k]]
        sy[k] = py[order[k]]
    px = sx
    py = sy
    i0 = rank[i0]
    i1 = rank[i1]
    i2 = rank[i2]

    hash_size = max(1, int(math.ceil(math.sqrt(n))))
    hull_next = np.empty(n, dtype=np.int32)
    hull_prev = np.empty(n, dtype=np.int32)
    hull_tri = np.empty(n, dtype=np.int32)
    hull_hash = np.full(hash_size, -1, dtype=np.int64)
    max_t = max(2 * n - 5, 1)
    tri = np.empty(3 * max_t, dtype=np.int32)
    twin = np.full(3 * max_t, -1, dtype=np.int32)
    stack = np.empty(max(1, stack_size), dtype=np.int64)

    hull_next[i0] = i1
    hull_next[i1] = i2
    hull_next[i2] = i0
    hull_prev[i0] = i2
    hull_prev[i1] = i0
    hull_prev[i2] = i1
    hull_hash[_hash_key(px[i0], py[i0], cx, cy, hash_size)] = i0
    hull_hash[_hash_key(px[i1], py[i1], cx, cy, hash_size)] = i1
    hull_hash[_hash_key(px[i2], py[i2], cx, cy, hash_size)] = i2
    _add_triangle(tri, twin, 0, i0, i1, i2, -1, -1, -1)
    hull_tri[i0] = 0
    hull_tri[i1] = 1
    hull_tri[i2] = 2
    nt = 1

    xp = np.nan
    yp = np.nan
    for i in range(n):
        x = px[i]
        y = py[i]
        if x == xp and y == yp:
            continue  # duplicate of the previous point
        xp = x
        yp = y
        if i == i0 or i == i1 or i == i2:
            continue
        # A hull vertex near the point's angle, then the first edge it sees.
        key = _hash_key(x, y, cx, cy, hash_size)
        start = -1
        for j in range(hash_size):
            start = hull_hash[(key + j) % hash_size]
            if start != -1 and start != hull_next[start]:
                break
        start = hull_prev[start]
        e = start
        while _orient(px[e], py[e], px[hull_next[e]], py[hull_next[e]], x, y) >= 0.0:
            e = hull_next[e]
            if e == start:
                e = -1
                break
        if e == -1:
            continue  # inside the hull: only a near-duplicate can be
        # Triangle on the visible edge e -> n.
        nxt = hull_next[e]
        t = _add_triangle(tri, twin, nt, e, i, nxt, -1, -1, hull_tri[e])
        nt += 1
        hull_tri[e] = t
        hull_tri[i] = t + 1
        stack = _legalize(t + 2, px, py, tri, twin, hull_tri, stack)
        # Walk forward over the other visible edges.
        n_ = nxt
        while True:
            q = hull_next[n_]
            if _orient(px[n_], py[n_], px[q], py[q], x, y) >= 0.0:
                break
            t = _add_triangle(tri, twin, nt, n_, i, q, hull_tri[i], -1, hull_tri[n_])
            nt += 1
            hull_tri[i] = t + 1
            stack = _legalize(t + 2, px, py, tri, twin, hull_tri, stack)
            hull_next[n_] = n_  # out of the hull
            n_ = q
        # Walk backward if the first visible edge may not have been the first one.
        if e == start:
            while True:
                q = hull_prev[e]
                if _orient(px[q], py[q], px[e], py[e], x, y) >= 0.0:
                    break
                t = _add_triangle(tri, twin, nt, q, i, e, -1, hull_tri[e], hull_tri[q])
                nt += 1
                hull_tri[q] = t
                stack = _legalize(t + 2, px, py, tri, twin, hull_tri, stack)
                hull_next[e] = e
                e = q
        hull_prev[i] = e
        hull_next[e] = i
        hull_prev[n_] = i
        hull_next[i] = n_
        hull_hash[_hash_key(x, y, cx, cy, hash_size)] = i
        hull_hash[_hash_key(px[e], py[e], cx, cy, hash_size)] = e

    out = np.empty((nt, 3), dtype=np.int64)
    for t in range(nt):
        out[t, 0] = order[tri[3 * t]]
        out[t, 1] = order[tri[3 * t + 1]]
        out[t, 2] = order[tri[3 * t + 2]]
    return out
