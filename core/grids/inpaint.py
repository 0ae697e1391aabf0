"""Filling empty cells of a grid.

:func:`inpaint_harmonic` gives every NaN cell the value that minimises the sum of
squared differences between 4-neighbours (a membrane, or Pingel's "springs").
That is the solution of the discrete Laplace equation on the unknown cells with
the known cells as boundary values; it is solved directly with a sparse LU
factorisation, one system for all holes. Pingel's Python code reaches the same
minimum by ``lsqr`` on the spring system; the direct solve is exact and faster.
"""
from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from ..errors import InputError


def inpaint_harmonic(grid: np.ndarray) -> np.ndarray:
    """Copy of ``grid`` with every NaN replaced by harmonic (membrane) interpolation."""
    grid = np.asarray(grid, dtype=np.float64)
    out = grid.copy()
    missing = np.isnan(out)
    n_missing = int(missing.sum())
    if n_missing == 0:
        return out
    if n_missing == out.size:
        raise InputError("cannot fill a grid that holds no value at all")
    nrows, ncols = out.shape
    index = np.full(out.shape, -1, dtype=np.int64)
    index[missing] = np.arange(n_missing)
    rows, cols = np.nonzero(missing)
    diag = np.zeros(n_missing)
    rhs = np.zeros(n_missing)
    off_i, off_j = [], []
    known = np.where(missing, 0.0, out)
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
    out[missing] = spsolve(a, rhs)
    return out
