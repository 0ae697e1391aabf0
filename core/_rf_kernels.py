"""numba kernels of the Random Forest predictor (private; see core/rf.py)."""
import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True, parallel=True)
def _forest_proba_kernel(X, roots, left, right, feature, threshold, missing_left, value, out):
    """Mean class probabilities of a forest stored as flat node arrays.

    Tree t starts at node ``roots[t]``; a node is a leaf when ``left`` is -1; an inner node
    sends a sample left when ``X[i, feature] <= threshold`` (scikit-learn's rule), and a missing
    value (NaN) left when ``missing_left`` is set. ``value`` holds each leaf's class probabilities."""
    n = X.shape[0]
    n_trees = roots.shape[0]
    n_classes = value.shape[1]
    for i in prange(n):
        for c in range(n_classes):
            out[i, c] = 0.0
        for t in range(n_trees):
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
        for c in range(n_classes):
            out[i, c] /= n_trees
