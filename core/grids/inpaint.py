"""Filling empty cells of a grid.

:func:`inpaint_harmonic` gives every NaN cell the value that minimises the sum of
squared differences between 4-neighbours (a membrane, or Pingel's "springs").
That is the solution of the discrete Laplace equation on the unknown cells with
the known cells as boundary values. Pingel's Python code reaches the same minimum
by ``lsqr`` on the spring system.

Each hole (4-connected group of NaN cells) is an independent system: its cells see
only each other and known cells. Small holes (at most :data:`DIRECT_MAX_CELLS`
cells) are solved together by one sparse LU factorisation; each larger hole by
conjugate gradients with a multigrid preconditioner on the box around it
(``_inpaint_kernels.py``), to a residual of :data:`RELATIVE_TOLERANCE` times the
range of its boundary values: the same fill as the direct solve to about 1e-11 of
that range (docs/BENCHMARKS.md), at a tenth of its time and memory on the mostly
empty grids of sparse clouds. A hole where the iteration does not converge (none
seen) falls back to the direct solve.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse.linalg import spsolve

from ..errors import InputError

#: holes of at most this many cells are solved by the sparse LU (all at once); larger ones iteratively
DIRECT_MAX_CELLS = 4096
#: more large holes than this: one iterative solve over the whole grid instead of one per hole's box
MAX_SEPARATE_HOLES = 32
#: the iteration stops when no cell's residual exceeds this times half the range of the boundary values
RELATIVE_TOLERANCE = 1e-14
#: over-correction of the multigrid's piecewise-constant coarse levels
COARSE_SCALE = 1.8
MAX_ITERATIONS = 400


def inpaint_harmonic(grid: np.ndarray) -> np.ndarray:
    """Copy of ``grid`` with every NaN replaced by harmonic (membrane) interpolation."""
    grid = np.asarray(grid, dtype=np.float64)
    out = grid.copy()
    missing = np.isnan(out)
    n_missing = int(np.count_nonzero(missing))
    if n_missing == 0:
        return out
    if n_missing == out.size:
        raise InputError("cannot fill a grid that holds no value at all")
    if n_missing <= DIRECT_MAX_CELLS:
        out[missing] = _direct(out, missing)
        return out
    labels, count = ndimage.label(missing)  # 4-connected holes
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    sizes[0] = 0
    big = np.flatnonzero(sizes > DIRECT_MAX_CELLS)
    small = missing.copy()
    if big.size:
        small &= ~np.isin(labels, big) if big.size > 1 else labels != big[0]
    if small.any():
        out[small] = _direct(out, small)
    if big.size > MAX_SEPARATE_HOLES:
        _iterative(out, missing & ~small)
    else:
        boxes = ndimage.find_objects(labels)
        for lab in big:
            rs, cs = boxes[lab - 1]
            box = (slice(max(rs.start - 1, 0), min(rs.stop + 1, out.shape[0])),
                   slice(max(cs.start - 1, 0), min(cs.stop + 1, out.shape[1])))
            sub = out[box]  # a view: filled in place
            _iterative(sub, labels[box] == lab)
    return out


def _iterative(grid: np.ndarray, mask: np.ndarray) -> None:
    """Fill the cells of ``mask`` in ``grid`` (in place). Every 4-neighbour of a ``mask`` cell is
    either in ``mask`` or known (other NaN cells of ``grid`` must not touch ``mask``)."""
    from ._inpaint_kernels import _boundary_range, _coarsen, _fine_level, _pcg_kernel
    grid_c = np.ascontiguousarray(grid)
    mask = np.ascontiguousarray(mask)
    lo, hi = _boundary_range(grid_c, mask)
    shift = 0.5 * (lo + hi)          # values solved relative to the middle of the boundary range
    half = max(0.5 * (hi - lo), 1e-300)
    shapes = [grid.shape]
    while shapes[-1] != (1, 1):
        a, c = shapes[-1]
        shapes.append(((a + 1) // 2, (c + 1) // 2))
    sizes = [(a + 2) * (c + 2) for a, c in shapes]
    offs = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    nys = np.array([s[0] for s in shapes], dtype=np.int64)
    nxs = np.array([s[1] for s in shapes], dtype=np.int64)
    total = int(sum(sizes))
    dg, dinv, we, ws = (np.zeros(total) for _ in range(4))
    b = np.zeros(sizes[0])
    _fine_level(grid_c, mask, shift, dg, dinv, we, ws, b)
    for lev in range(len(shapes) - 1):
        _coarsen(dg, dinv, we, ws, offs[lev], nys[lev], nxs[lev], offs[lev + 1], nys[lev + 1], nxs[lev + 1])
    x = np.zeros(sizes[0])
    tol = RELATIVE_TOLERANCE * half
    iterations, rmax = _pcg_kernel(offs, nys, nxs, dg, dinv, we, ws, b, x, tol, MAX_ITERATIONS, COARSE_SCALE)
    if iterations < 0 or not rmax <= 10.0 * tol:  # not converged (never seen): the direct solve
        grid[mask] = _direct(grid_c, mask)
        return
    inner = x.reshape(grid.shape[0] + 2, grid.shape[1] + 2)[1:-1, 1:-1]
    grid[mask] = inner[mask] + shift


def _direct(grid: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """Values of the ``missing`` cells by one sparse LU solve (neighbours outside ``missing`` known)."""
    nrows, ncols = grid.shape
    n_missing = int(np.count_nonzero(missing))
    index = np.full(grid.shape, -1, dtype=np.int64)
    index[missing] = np.arange(n_missing)
    rows, cols = np.nonzero(missing)
    diag = np.zeros(n_missing)
    rhs = np.zeros(n_missing)
    off_i, off_j = [], []
    known = np.where(missing, 0.0, grid)
    unknown_ids = index[rows, cols]
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        nr, nc = rows + dr, cols + dc
        inside = (nr >= 0) & (nr < nrows) & (nc >= 0) & (nc < ncols)
        me = unknown_ids[inside]
        nr, nc = nr[inside], nc[inside]
        diag[me] += 1.0
        other = index[nr, nc]
        is_unknown = other >= 0
        off_i.append(me[is_unknown])
        off_j.append(other[is_unknown])
        np.add.at(rhs, me[~is_unknown], known[nr[~is_unknown], nc[~is_unknown]])
    off_i = np.concatenate(off_i)
    off_j = np.concatenate(off_j)
    a = sparse.csc_matrix(
        (np.concatenate([diag, -np.ones(off_i.size)]),
         (np.concatenate([np.arange(n_missing), off_i]), np.concatenate([np.arange(n_missing), off_j]))),
        shape=(n_missing, n_missing))
    # A group of holes with no known neighbour anywhere would make the system singular;
    # it cannot happen when at least one cell is known and the grid is connected.
    return np.atleast_1d(spsolve(a, rhs))
