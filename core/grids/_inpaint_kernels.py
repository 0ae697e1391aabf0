"""numba kernels of the harmonic fill (private; call :func:`core.grids.inpaint.inpaint_harmonic`).

The system solved is the 5-point graph Laplacian of the unknown cells with the known cells as
fixed (Dirichlet) values: symmetric positive definite. It is solved by conjugate gradients
preconditioned with one multigrid V-cycle:

* every level is a grid of cells with, per cell, the weight of its edge to the east and to the
  south neighbour and its diagonal (0 = no unknown there); the finest level is the 5-point
  Laplacian itself (weights 1);
* a coarse cell is a 2 x 2 block of the finer level and the coarse operator is the Galerkin
  product with piecewise-constant interpolation (the weights of the fine edges between two blocks
  add up; edges inside a block drop out of the diagonal), so every level is again a weighted
  5-point Laplacian, symmetric positive definite, down to a single cell;
* smoothing: one forward Gauss-Seidel sweep before the coarse correction, one backward after
  (the V-cycle is then a symmetric operator, as conjugate gradients needs); the coarse correction
  is scaled by ``alpha`` (about 1.8: piecewise-constant interpolation under-corrects).

Each level is stored in flat arrays with a one-cell border of zeros (no bounds checks in the
sweeps), at offset ``offs[l]``, ``nys[l] x nxs[l]`` inner cells, row stride ``nxs[l] + 2``.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _boundary_range(grid, mask):
    """(lowest, highest) known 4-neighbour value of the cells of ``mask``."""
    ny, nx = grid.shape
    lo = np.inf
    hi = -np.inf
    for i in range(ny):
        for j in range(nx):
            if not mask[i, j]:
                continue
            for di, dj in ((0, 1), (0, -1), (1, 0), (-1, 0)):
                a = i + di
                b = j + dj
                if 0 <= a < ny and 0 <= b < nx and not mask[a, b]:
                    v = grid[a, b]
                    if v < lo:
                        lo = v
                    if v > hi:
                        hi = v
    return lo, hi


@njit(cache=True, nogil=True)
def _fine_level(grid, mask, shift, dg, dinv, we, ws, b):
    """The finest level: unknowns at ``mask``; ``b`` = sum of the known neighbours minus ``shift``."""
    ny, nx = grid.shape
    w = nx + 2
    for i in range(ny):
        for j in range(nx):
            if not mask[i, j]:
                continue
            k = (i + 1) * w + j + 1
            d = 0.0
            s = 0.0
            if j + 1 < nx:
                d += 1.0
                if mask[i, j + 1]:
                    we[k] = 1.0
                else:
                    s += grid[i, j + 1] - shift
            if j > 0:
                d += 1.0
                if not mask[i, j - 1]:
                    s += grid[i, j - 1] - shift
            if i + 1 < ny:
                d += 1.0
                if mask[i + 1, j]:
                    ws[k] = 1.0
                else:
                    s += grid[i + 1, j] - shift
            if i > 0:
                d += 1.0
                if not mask[i - 1, j]:
                    s += grid[i - 1, j] - shift
            dg[k] = d
            dinv[k] = 1.0 / d
            b[k] = s


@njit(cache=True, nogil=True)
def _coarsen(dg, dinv, we, ws, o, ny, nx, oc, cy, cx):
    """Level at ``oc`` (cy x cx, zeroed) from the level at ``o`` (ny x nx): Galerkin product with
    piecewise-constant interpolation over 2 x 2 blocks (all weights stay whole numbers: exact)."""
    w = nx + 2
    wc = cx + 2
    for i in range(ny):
        ci = i // 2
        for j in range(nx):
            k = o + (i + 1) * w + j + 1
            if dg[k] == 0.0:
                continue
            cj = j // 2
            kc = oc + (ci + 1) * wc + cj + 1
            dg[kc] += dg[k]
            e = we[k]
            if e != 0.0:
                if (j + 1) // 2 == cj:
                    dg[kc] -= 2.0 * e
                else:
                    we[kc] += e
            e = ws[k]
            if e != 0.0:
                if (i + 1) // 2 == ci:
                    dg[kc] -= 2.0 * e
                else:
                    ws[kc] += e
    for k in range(oc, oc + (cy + 2) * wc):
        if dg[k] != 0.0:
            dinv[k] = 1.0 / dg[k]


@njit(cache=True, nogil=True)
def _residual(dg, we, ws, o, ny, nx, u, f, out):
    """out = f - A u on the inner cells of one level (0 where there is no unknown)."""
    w = nx + 2
    for i in range(1, ny + 1):
        base = o + i * w
        for k in range(base + 1, base + nx + 1):
            out[k] = f[k] - (dg[k] * u[k] - we[k] * u[k + 1] - we[k - 1] * u[k - 1]
                             - ws[k] * u[k + w] - ws[k - w] * u[k - w])


@njit(cache=True, nogil=True)
def _gauss_seidel(dinv, we, ws, o, ny, nx, u, f, forward):
    """One Gauss-Seidel sweep (forward: row by row from the top left; else the reverse order)."""
    w = nx + 2
    for ii in range(1, ny + 1):
        if forward:
            base = o + ii * w
            for k in range(base + 1, base + nx + 1):
                u[k] = (f[k] + we[k] * u[k + 1] + we[k - 1] * u[k - 1] + ws[k] * u[k + w]
                        + ws[k - w] * u[k - w]) * dinv[k]
        else:
            base = o + (ny + 1 - ii) * w
            for k in range(base + nx, base, -1):
                u[k] = (f[k] + we[k] * u[k + 1] + we[k - 1] * u[k - 1] + ws[k] * u[k + w]
                        + ws[k - w] * u[k - w]) * dinv[k]


@njit(cache=True, nogil=True)
def _vcycle(offs, nys, nxs, dg, dinv, we, ws, u, f, r, rhs, out, alpha):
    """out = one symmetric V-cycle applied to ``rhs`` (the preconditioner)."""
    levels = offs.shape[0]
    n0 = (nys[0] + 2) * (nxs[0] + 2)
    for k in range(n0):
        f[k] = rhs[k]
    for lev in range(levels):
        o, ny, nx = offs[lev], nys[lev], nxs[lev]
        w = nx + 2
        for k in range(o, o + (ny + 2) * w):
            u[k] = 0.0
        if lev == levels - 1:  # a single cell (or a line of two): exact after a few sweeps
            for _s in range(4):
                _gauss_seidel(dinv, we, ws, o, ny, nx, u, f, True)
                _gauss_seidel(dinv, we, ws, o, ny, nx, u, f, False)
            break
        _gauss_seidel(dinv, we, ws, o, ny, nx, u, f, True)
        _residual(dg, we, ws, o, ny, nx, u, f, r)
        oc, cy, cx = offs[lev + 1], nys[lev + 1], nxs[lev + 1]
        wc = cx + 2
        for k in range(oc, oc + (cy + 2) * wc):
            f[k] = 0.0
        for i in range(ny):
            rowc = oc + (i // 2 + 1) * wc + 1
            base = o + (i + 1) * w + 1
            for j in range(nx):
                f[rowc + j // 2] += r[base + j]
    for lev in range(levels - 2, -1, -1):
        o, ny, nx = offs[lev], nys[lev], nxs[lev]
        w = nx + 2
        oc, cx = offs[lev + 1], nxs[lev + 1]
        wc = cx + 2
        for i in range(ny):
            rowc = oc + (i // 2 + 1) * wc + 1
            base = o + (i + 1) * w + 1
            for j in range(nx):
                if dinv[base + j] != 0.0:
                    u[base + j] += alpha * u[rowc + j // 2]
        _gauss_seidel(dinv, we, ws, o, ny, nx, u, f, False)
    for k in range(n0):
        out[k] = u[k]


@njit(cache=True, nogil=True)
def _pcg_kernel(offs, nys, nxs, dg, dinv, we, ws, b, x, tol, maxiter, alpha):
    """Conjugate gradients on the finest level from ``x`` (updated in place) until the largest
    residual is at most ``tol``. Returns (iterations, largest true residual at the end); iterations
    -1 = not converged in ``maxiter``."""
    n = (nys[0] + 2) * (nxs[0] + 2)
    total = dg.shape[0]
    u = np.zeros(total)
    f = np.zeros(total)
    r = np.zeros(total)
    res = np.zeros(n)
    z = np.zeros(n)
    p = np.zeros(n)
    q = np.zeros(n)
    zero = np.zeros(n)
    _residual(dg, we, ws, 0, nys[0], nxs[0], x, b, res)
    rmax = 0.0
    for k in range(n):
        rmax = max(rmax, abs(res[k]))
    if rmax <= tol:
        return 0, rmax
    _vcycle(offs, nys, nxs, dg, dinv, we, ws, u, f, r, res, z, alpha)
    rz = 0.0
    for k in range(n):
        p[k] = z[k]
        rz += res[k] * z[k]
    for it in range(1, maxiter + 1):
        _residual(dg, we, ws, 0, nys[0], nxs[0], p, zero, q)  # q = -A p
        pq = 0.0
        for k in range(n):
            pq -= p[k] * q[k]
        if not pq > 0.0:
            break
        a = rz / pq
        rmax = 0.0
        for k in range(n):
            x[k] += a * p[k]
            res[k] += a * q[k]
            rmax = max(rmax, abs(res[k]))
        if rmax <= tol:
            _residual(dg, we, ws, 0, nys[0], nxs[0], x, b, res)  # the true residual
            rmax = 0.0
            for k in range(n):
                rmax = max(rmax, abs(res[k]))
            return it, rmax
        _vcycle(offs, nys, nxs, dg, dinv, we, ws, u, f, r, res, z, alpha)
        rz_new = 0.0
        for k in range(n):
            rz_new += res[k] * z[k]
        beta = rz_new / rz
        rz = rz_new
        for k in range(n):
            p[k] = z[k] + beta * p[k]
    return -1, rmax
