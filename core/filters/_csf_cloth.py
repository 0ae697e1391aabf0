"""numba kernels of the cloth of the cloth simulation filter (core.filters.csf): the particles'
time steps under both constraint schemes, the slope smoothing and the final classification.
Private: call them through :class:`groundsieve.core.filters.csf.CSF`, which validates and casts
first. The heights the cloth cannot fall below come from ``_csf_terrain``.

The cloth lives in the reference implementation's *inverted* frame: a particle's height
``h`` is ``-z``, the cloth starts above every inverted point and falls (``h`` decreases).
Particles are stored row-major, ``p = row * W + col``, with column ``col`` at
``x = ox + col * res`` and row ``row`` at ``y = oy + row * res`` (row 0 south, as the
reference's ``j`` index; the public result flips it to the core's north-up convention).
"""
from __future__ import annotations

import numpy as np
from numba import njit


#: Neighbour offsets (d_col, d_row) of a particle's constraint list, in the order the
#: reference's Cloth constructor appends them (immediate ring first, then distance 2).
NEIGHBOURS = np.array([(-1, -1), (-1, 0), (-1, 1), (0, -1), (1, -1), (1, 0), (0, 1), (1, 1),
                       (-2, -2), (-2, 0), (-2, 2), (0, -2), (2, -2), (2, 0), (0, 2), (2, 2)],
                      dtype=np.int64)


# --------------------------------------------------------------------------------------------
# The cloth
# --------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _verlet_step(pos, old, movable, acceleration):
    """The reference's Particle::timeStep for every movable particle:
    ``pos += (pos - old) * 0.99 + acceleration``."""
    for p in range(pos.shape[0]):
        if movable[p]:
            t = pos[p]
            pos[p] = t + (t - old[p]) * 0.99 + acceleration
            old[p] = t


@njit(cache=True, nogil=True)
def _collide(pos, old, movable, hv):
    """``max_diff`` (the largest |pos - old| of the movable particles, for the early stop) and
    the reference's Cloth::terrCollision: a particle below its intersection height is put on it
    and pinned. Returns (max_diff, number of particles pinned)."""
    max_diff = 0.0
    pinned = 0
    for p in range(pos.shape[0]):
        if movable[p]:
            d = abs(old[p] - pos[p])
            if d > max_diff:
                max_diff = d
            if pos[p] < hv[p]:
                pos[p] = hv[p]
                movable[p] = False
                pinned += 1
    return max_diff, pinned


@njit(cache=True, nogil=True)
def _max_change(pos, before, movable):
    """The largest |pos - before| of the movable particles (0 when none is)."""
    m = 0.0
    for p in range(pos.shape[0]):
        if movable[p]:
            d = abs(pos[p] - before[p])
            if d > m:
                m = d
    return m


@njit(cache=True, nogil=True)
def _time_step_kernel(pos, old, movable, quiet, hv, W, H, acceleration, single_move, double_move,
                      neighbours=NEIGHBOURS, transpose=False, rev_outer=False, rev_inner=False):
    """One iteration of the reference (Cloth::timeStep then Cloth::terrCollision).

    1. Verlet step of every movable particle: ``pos += (pos - old) * 0.99 + acceleration``.
    2. Internal forces, particle by particle in index order, each over its 16 neighbours in
       the reference's list order (so each pair is met twice per iteration, once from each
       end, as in Particle::satisfyConstraintSelf): the height difference ``d`` closes by
       ``double_move * d`` at each end when both move, by ``single_move * d`` when one does.
    3. ``max_diff``: the largest |pos - old| of the movable particles.
    4. Collision: a particle below its intersection height is put on it and pinned.

    The defaults are the reference's order. ``neighbours`` (16 (d_col, d_row)) and the three
    flags give the order of the same sweep run on the cloth turned or mirrored (see
    ``core.filters.csf.sweeps()``): the particles column by column when ``transpose``, the outer loop
    (rows, or columns) backwards when ``rev_outer``, the inner one backwards when ``rev_inner``.

    ``quiet`` marks pinned particles whose 16 neighbours are pinned too: nothing can move
    them or be moved by them any more, so they are skipped (set here, once for good).

    Returns (max_diff, number of particles pinned in this iteration)."""
    _verlet_step(pos, old, movable, acceleration)
    offsets = np.empty(16, dtype=np.int64)
    for k in range(16):
        offsets[k] = neighbours[k, 1] * W + neighbours[k, 0]
    n_outer = W if transpose else H
    n_inner = H if transpose else W
    for io in range(n_outer):
        a = n_outer - 1 - io if rev_outer else io
        for ii in range(n_inner):
            b = n_inner - 1 - ii if rev_inner else ii
            if transpose:
                r = b
                c = a
            else:
                r = a
                c = b
            p = r * W + c
            if quiet[p]:
                continue
            mp = movable[p]
            if 2 <= r < H - 2 and 2 <= c < W - 2:
                # Fast path: all 16 neighbours exist.
                if mp:
                    hp = pos[p]
                    for k in range(16):
                        q = p + offsets[k]
                        d = pos[q] - hp
                        if movable[q]:
                            hp += d * double_move
                            pos[q] -= d * double_move
                        else:
                            hp += d * single_move
                    pos[p] = hp
                else:
                    hp = pos[p]
                    still = True
                    for k in range(16):
                        q = p + offsets[k]
                        if movable[q]:
                            pos[q] -= (pos[q] - hp) * single_move
                            still = False
                    quiet[p] = still
                continue
            still = not mp
            for k in range(16):
                cc = c + neighbours[k, 0]
                rr = r + neighbours[k, 1]
                if cc < 0 or cc >= W or rr < 0 or rr >= H:
                    continue
                q = rr * W + cc
                mq = movable[q]
                if mq:
                    still = False
                if mp:
                    d = pos[q] - pos[p]
                    if mq:
                        pos[p] += d * double_move
                        pos[q] -= d * double_move
                    else:
                        pos[p] += d * single_move
                elif mq:
                    pos[q] -= (pos[q] - pos[p]) * single_move
            quiet[p] = still
    return _collide(pos, old, movable, hv)


@njit(cache=True, nogil=True)
def _time_step_2016_kernel(pos, old, movable, hv, W, H, acceleration, passes):
    """One iteration of the authors' 2016 code (CSFDLL, the repository's first version):

    1. the same Verlet step as :func:`_time_step_kernel`;
    2. ``passes`` (= rigidness) passes over the cloth's constraints, each pair once per pass
       with the factor 0.3, in the order the 2016 Cloth constructor made them: for each
       column ``x``, for each row ``y``, the pairs to (x+1, y), (x, y+1), (x+1, y+1) and
       (x+1, y)-(x, y+1); then, in a second sweep, the same four at distance two. The first
       particle of each pair is the one that must be movable: it closes 0.3 of the height
       difference towards the second, and only then is the second (when movable) moved the same
       amount the other way, so a pinned particle pulls only the neighbours that list it second
       (Constraint::satisfyConstraint of that code);
    3. ``max_diff`` and the collision, as :func:`_time_step_kernel`.

    The arrays are **column-major** here (``p = x * H + y``, the caller transposes them once
    per run), so that this order walks memory forwards.

    Returns (max_diff, number of particles pinned in this iteration)."""
    _verlet_step(pos, old, movable, acceleration)
    for _ in range(passes):
        for dist in range(1, 3):
            east = dist * H
            for x in range(W):
                right = x < W - dist
                for y in range(H):
                    p = x * H + y
                    up = y < H - dist
                    # The pair's first particle carries it: a pinned p moves nothing in its
                    # first three pairs, a pinned p + east nothing in the fourth. Written out
                    # with p's height kept in a local: a helper function per pair (even inlined)
                    # measured twice as slow.
                    if movable[p]:
                        hp = pos[p]
                        if right:
                            q = p + east
                            d = (pos[q] - hp) * 0.3
                            hp += d
                            if movable[q]:
                                pos[q] -= d
                        if up:
                            q = p + dist
                            d = (pos[q] - hp) * 0.3
                            hp += d
                            if movable[q]:
                                pos[q] -= d
                            if right:
                                q = p + east + dist
                                d = (pos[q] - hp) * 0.3
                                hp += d
                                if movable[q]:
                                    pos[q] -= d
                        pos[p] = hp
                    if right and up and movable[p + east]:
                        a = p + east
                        q = p + dist
                        d = (pos[q] - pos[a]) * 0.3
                        pos[a] += d
                        if movable[q]:
                            pos[q] -= d
    return _collide(pos, old, movable, hv)


@njit(cache=True, nogil=True)
def _free_fall_kernel(pos, old, hv, acceleration, iterations, stop_diff):
    """Iterations while no particle has touched yet. All particles are movable and at one
    height, so every internal force is exactly zero and the cloth moves as one particle:
    the same floating-point result as :func:`_time_step_kernel`, at the cost of one particle.
    Advances until the iteration in which the first particle would touch (left to
    :func:`_time_step_kernel`), or ``iterations``, or the reference's early stop (a step
    shorter than ``stop_diff``). Returns (iterations done, stopped early)."""
    top = -np.inf
    for p in range(hv.shape[0]):
        if hv[p] > top:
            top = hv[p]
    h = pos[0]
    o = old[0]
    done = 0
    stopped = False
    while done < iterations:
        t = h + (h - o) * 0.99 + acceleration
        if t < top:
            break
        o = h
        h = t
        done += 1
        d = abs(o - h)
        if d != 0.0 and d < stop_diff:
            stopped = True
            break
    for p in range(pos.shape[0]):
        pos[p] = h
        old[p] = o
    return done, stopped


@njit(cache=True, nogil=True)
def _neighbour4(p, k, W, H):
    """The k-th 4-neighbour (0 west, 1 east, 2 south, 3 north) of particle ``p`` on the
    row-major W x H cloth, or -1 beyond its edge."""
    r = p // W
    c = p - r * W
    if k == 0:
        c -= 1
    elif k == 1:
        c += 1
    elif k == 2:
        r -= 1
    else:
        r += 1
    if r < 0 or r >= H or c < 0 or c >= W:
        return -1
    return r * W + c


@njit(cache=True, nogil=True)
def _slope_smooth_kernel(pos, movable, hv, W, H, height_diff, min_size):
    """The reference's post-processing (Cloth::movableFilter): each 4-connected group of
    still-movable particles larger than ``min_size`` is pulled onto its intersection heights
    from its edges inwards: a movable particle 4-adjacent to a pinned one whose intersection
    height differs by less than ``height_diff`` is put on its own intersection height and
    pinned, and so on through the group while neighbouring intersection heights differ by
    less than ``height_diff``. The reference does this with an edge pass then a
    breadth-first pass; both reach the particles connected to a pinned particle by such
    steps, which is what this flood fill does. Returns the number of particles pinned."""
    n = W * H
    visited = np.zeros(n, dtype=np.bool_)
    member = np.zeros(n, dtype=np.bool_)
    comp = np.empty(n, dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    queued = np.zeros(n, dtype=np.bool_)
    total = 0
    for c0 in range(W):
        for r0 in range(H):
            p0 = r0 * W + c0
            if not movable[p0] or visited[p0]:
                continue
            size = 1
            comp[0] = p0
            visited[p0] = True
            head = 0
            while head < size:
                p = comp[head]
                head += 1
                for k in range(4):
                    q = _neighbour4(p, k, W, H)
                    if q < 0:
                        continue
                    if movable[q] and not visited[q]:
                        visited[q] = True
                        comp[size] = q
                        size += 1
            if size <= min_size:
                continue
            for i in range(size):
                member[comp[i]] = True
            qt = 0
            for i in range(size):
                p = comp[i]
                for k in range(4):
                    q = _neighbour4(p, k, W, H)
                    if q < 0:
                        continue
                    if not movable[q] and abs(hv[p] - hv[q]) < height_diff:
                        pos[p] = hv[p]
                        movable[p] = False
                        total += 1
                        queue[qt] = p
                        qt += 1
                        queued[p] = True
                        break
            head = 0
            while head < qt:
                p = queue[head]
                head += 1
                for k in range(4):
                    q = _neighbour4(p, k, W, H)
                    if q < 0:
                        continue
                    if member[q] and not queued[q] and abs(hv[p] - hv[q]) < height_diff:
                        if movable[q]:
                            pos[q] = hv[q]
                            movable[q] = False
                            total += 1
                        queued[q] = True
                        queue[qt] = q
                        qt += 1
            for i in range(size):
                member[comp[i]] = False
    return total


@njit(cache=True, nogil=True)
def _classify_kernel(x, y, z, use, ox, oy, res, W, H, pos, threshold, out):
    """The reference's c2cdist: the cloth's height at each point by bilinear interpolation
    between the four particles around it; ground when |z - cloth| < threshold (strictly).
    Points with ``use`` False (low outliers) are not ground."""
    for k in range(x.shape[0]):
        if not use[k]:
            out[k] = False
            continue
        dx = x[k] - ox
        dy = y[k] - oy
        c0 = min(max(int(dx / res), 0), W - 2)
        r0 = min(max(int(dy / res), 0), H - 2)
        tx = (dx - c0 * res) / res
        ty = (dy - r0 * res) / res
        p = r0 * W + c0
        f = (pos[p] * (1.0 - tx) * (1.0 - ty) + pos[p + W] * (1.0 - tx) * ty
             + pos[p + W + 1] * tx * ty + pos[p + 1] * tx * (1.0 - ty))
        out[k] = abs(f + z[k]) < threshold
