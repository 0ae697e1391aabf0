"""numba kernels of the terrain under the cloth of the cloth simulation filter (core.filters.csf):
the low-outlier step and the intersection height value of each particle (the inverted height it
cannot fall below). Private: call them through :class:`groundsieve.core.filters.csf.CSF`. The
frame and particle layout are those of ``_csf_cloth``.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._csf_cloth import NEIGHBOURS


# --------------------------------------------------------------------------------------------
# Low outliers (an addition of GroundSieve, see core/csf.py)
# --------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _low_outliers_kernel(x, y, z, x0, y0, cell, ncols, nrows, threshold, out):
    """out[k] = point k lies more than ``threshold`` below the third lowest of the minima of
    the (up to 8) non-empty cells around its own cell. Cells with fewer than three non-empty
    neighbours flag nothing. The third lowest, not the lowest, so that a cluster of outliers
    spread over two neighbouring cells is still found."""
    n = x.shape[0]
    zmin = np.full((nrows, ncols), np.inf)
    for k in range(n):
        c = min(max(int((x[k] - x0) / cell), 0), ncols - 1)
        r = min(max(int((y[k] - y0) / cell), 0), nrows - 1)
        if z[k] < zmin[r, c]:
            zmin[r, c] = z[k]
    ref = np.full((nrows, ncols), -np.inf)
    buf = np.empty(8)
    for r in range(nrows):
        for c in range(ncols):
            if zmin[r, c] == np.inf:
                continue
            m = 0
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    if dr == 0 and dc == 0:
                        continue
                    rr = r + dr
                    cc = c + dc
                    if 0 <= rr < nrows and 0 <= cc < ncols and zmin[rr, cc] < np.inf:
                        # insertion into the sorted prefix buf[:m]
                        v = zmin[rr, cc]
                        i = m
                        while i > 0 and buf[i - 1] > v:
                            buf[i] = buf[i - 1]
                            i -= 1
                        buf[i] = v
                        m += 1
            if m >= 3:
                ref[r, c] = buf[2]
    count = 0
    for k in range(n):
        c = min(max(int((x[k] - x0) / cell), 0), ncols - 1)
        r = min(max(int((y[k] - y0) / cell), 0), nrows - 1)
        flag = z[k] < ref[r, c] - threshold
        out[k] = flag
        if flag:
            count += 1
    return count


# --------------------------------------------------------------------------------------------
# Intersection height values (IHV): the inverted height each particle cannot fall below
# --------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _cell_heights_kernel(x, y, z, use, ox, oy, res, W, H, hv, has):
    """The reference's Rasterization::RasterTerrian: each point goes to the particle at
    ``round((x - ox) / res), round((y - oy) / res)``; a particle takes the inverted height of
    the nearest of its points (the first one on a tie). ``has`` marks particles with a point."""
    best = np.full(W * H, np.inf)
    for k in range(x.shape[0]):
        if not use[k]:
            continue
        dx = x[k] - ox
        dy = y[k] - oy
        c = int(dx / res + 0.5)
        r = int(dy / res + 0.5)
        if c < 0 or r < 0 or c >= W or r >= H:
            continue
        p = r * W + c
        ex = dx - c * res
        ey = dy - r * res
        d = ex * ex + ey * ey
        if d < best[p]:
            best[p] = d
            hv[p] = -z[k]
            has[p] = True


@njit(cache=True, nogil=True)
def _bfs_height(p, hv, has, W, H, visited, queue, touched):
    """The reference's findHeightValByNeighbor: breadth-first over the constraint graph from
    particle ``p`` until a particle with a point is met; its height, or -inf if none."""
    qh = 0
    qt = 0
    nt = 0
    r0 = p // W
    c0 = p % W
    result = -np.inf
    for k in range(NEIGHBOURS.shape[0]):
        cc = c0 + NEIGHBOURS[k, 0]
        rr = r0 + NEIGHBOURS[k, 1]
        if 0 <= cc < W and 0 <= rr < H:
            q = rr * W + cc
            queue[qt] = q
            qt += 1
            if not visited[q]:
                visited[q] = True
                touched[nt] = q
                nt += 1
    if not visited[p]:
        visited[p] = True
        touched[nt] = p
        nt += 1
    while qh < qt:
        q = queue[qh]
        qh += 1
        if has[q]:
            result = hv[q]
            break
        r = q // W
        c = q % W
        for k in range(NEIGHBOURS.shape[0]):
            cc = c + NEIGHBOURS[k, 0]
            rr = r + NEIGHBOURS[k, 1]
            if 0 <= cc < W and 0 <= rr < H:
                s = rr * W + cc
                if not visited[s]:
                    visited[s] = True
                    touched[nt] = s
                    nt += 1
                    queue[qt] = s
                    qt += 1
    for i in range(nt):
        visited[touched[i]] = False
    return result


@njit(cache=True, nogil=True)
def _scanline_fill_kernel(hv, has, W, H):
    """The reference's findHeightValByScanline for every particle without a point: the first
    particle with a point to the east on its row, else to the west, else to the south on its
    column, else to the north; else breadth-first over the constraint graph. O(W * H): the
    nearest particle with a point in each direction is precomputed by one sweep per direction."""
    n = W * H
    east = np.full(n, -1, dtype=np.int64)
    west = np.full(n, -1, dtype=np.int64)
    south = np.full(n, -1, dtype=np.int64)
    north = np.full(n, -1, dtype=np.int64)
    for r in range(H):
        last = -1
        for c in range(W - 1, -1, -1):
            east[r * W + c] = last
            if has[r * W + c]:
                last = r * W + c
        last = -1
        for c in range(W):
            west[r * W + c] = last
            if has[r * W + c]:
                last = r * W + c
    for c in range(W):
        last = -1
        for r in range(H):
            south[r * W + c] = last
            if has[r * W + c]:
                last = r * W + c
        last = -1
        for r in range(H - 1, -1, -1):
            north[r * W + c] = last
            if has[r * W + c]:
                last = r * W + c
    out = hv.copy()
    visited = np.zeros(0, dtype=np.bool_)
    queue = np.zeros(0, dtype=np.int64)
    touched = np.zeros(0, dtype=np.int64)
    for p in range(n):
        if has[p]:
            continue
        if east[p] >= 0:
            out[p] = hv[east[p]]
        elif west[p] >= 0:
            out[p] = hv[west[p]]
        elif south[p] >= 0:
            out[p] = hv[south[p]]
        elif north[p] >= 0:
            out[p] = hv[north[p]]
        else:
            if visited.shape[0] == 0:
                visited = np.zeros(n, dtype=np.bool_)
                queue = np.empty(n + 16, dtype=np.int64)
                touched = np.empty(n, dtype=np.int64)
            out[p] = _bfs_height(p, hv, has, W, H, visited, queue, touched)
    return out


@njit(cache=True, nogil=True)
def _nearest_heights_kernel(x, y, z, use, ox, oy, res, W, H, max_ring, hv, found):
    """The paper's IHV: each particle takes the inverted height of the nearest point in the
    horizontal plane (the lowest point index on a tie). Points are bucketed by the particle
    they round to; a particle searches square rings of buckets outwards until the next ring
    cannot hold a nearer point, or up to ``max_ring`` rings (``found`` stays False beyond:
    the caller completes those far-from-any-point particles)."""
    n = x.shape[0]
    ncell = W * H
    start = np.zeros(ncell + 1, dtype=np.int64)
    for k in range(n):
        if not use[k]:
            continue
        c = int((x[k] - ox) / res + 0.5)
        r = int((y[k] - oy) / res + 0.5)
        start[r * W + c + 1] += 1
    for p in range(ncell):
        start[p + 1] += start[p]
    fill = start[:-1].copy()
    order = np.empty(start[ncell], dtype=np.int64)
    for k in range(n):
        if not use[k]:
            continue
        c = int((x[k] - ox) / res + 0.5)
        r = int((y[k] - oy) / res + 0.5)
        p = r * W + c
        order[fill[p]] = k
        fill[p] += 1
    for r0 in range(H):
        py = r0 * res
        for c0 in range(W):
            px = c0 * res
            best = np.inf
            best_k = -1
            ring = 0
            while ring <= max_ring:
                # Every point of ring ``ring`` is at least (ring - 0.5) * res away.
                if best_k >= 0:
                    lim = (ring - 0.5) * res
                    if lim > 0 and lim * lim > best:
                        break
                r_lo = r0 - ring
                r_hi = r0 + ring
                for rr in range(max(r_lo, 0), min(r_hi, H - 1) + 1):
                    edge_row = rr == r_lo or rr == r_hi
                    step = 1 if edge_row else 2 * ring
                    cc = c0 - ring
                    while cc <= c0 + ring:
                        if 0 <= cc < W:
                            q = rr * W + cc
                            for i in range(start[q], start[q + 1]):
                                k = order[i]
                                ex = x[k] - ox - px
                                ey = y[k] - oy - py
                                d = ex * ex + ey * ey
                                if d < best or (d == best and k < best_k):
                                    best = d
                                    best_k = k
                        if step == 0:
                            break
                        cc += step
                ring += 1
            p = r0 * W + c0
            if best_k >= 0:
                hv[p] = -z[best_k]
                found[p] = True
