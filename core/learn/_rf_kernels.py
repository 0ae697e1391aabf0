"""numba kernels of the Random Forest predictor (private; see core/learn/rf.py)."""
import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True)
def _forest_block(X, lo, hi, roots, left, right, feature, threshold, missing_left, value, out):
    """Rows ``lo:hi``: tree by tree over the whole block, so that one tree's nodes stay in the
    cache while the block's points walk down it."""
    n_classes = value.shape[1]
    for i in range(lo, hi):
        for c in range(n_classes):
            out[i, c] = 0.0
    for t in range(roots.shape[0]):
        for i in range(lo, hi):
            node = roots[t]
            while left[node] != -1:
                v = X[i, feature[node]]
                if np.isnan(v):
                    node = left[node] if missing_left[node] else right[node]
                elif v <= threshold[node]:
                    node = left[node]
                else:
                    node = right[node]
            for c in range(n_classes):
                out[i, c] += value[node, c]
    n_trees = roots.shape[0]
    for i in range(lo, hi):
        for c in range(n_classes):
            out[i, c] /= n_trees


@njit(cache=True, nogil=True, parallel=True)
def _forest_proba_kernel(X, roots, left, right, feature, threshold, missing_left, value, out):
    """Mean class probabilities of a forest stored as flat node arrays.

    Tree t starts at node ``roots[t]``; a node is a leaf when ``left`` is -1; an inner node
    sends a sample left when ``X[i, feature] <= threshold`` (scikit-learn's rule), and a missing
    value (NaN) left when ``missing_left`` is set. ``value`` holds each leaf's class
    probabilities. Blocks of points run in parallel."""
    n = X.shape[0]
    block = 2048
    nblocks = (n + block - 1) // block
    for b in prange(nblocks):
        _forest_block(X, b * block, min((b + 1) * block, n), roots, left, right, feature, threshold,
                      missing_left, value, out)
