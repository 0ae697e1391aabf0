"""numba kernels of the Random Forest predictor (private; see core/learn/rf.py).

The arrays come from a model file, which is untrusted input. ``model_file.load_model`` checks
every array before a kernel sees it; the kernels are nevertheless safe on their own: every index
is checked before it is used (once per forest, in :func:`_indices_ok`, not per point) and every
walk down a tree stops after as many steps as the forest has nodes, so a malformed forest (a root
or child out of range, a cycle, a feature index out of range, a ``value`` array of the wrong
width, no tree) is reported, never a crash or a hang."""
import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True)
def _forest_block(X, lo, hi, roots, left, right, feature, threshold, missing_left, value, out):
    """Rows ``lo:hi``: tree by tree over the whole block, so that one tree's nodes stay in the
    cache while the block's points walk down it. Every root, child and feature index has been
    checked by :func:`_indices_ok`; a walk longer than the node count (a cycle) returns True (the
    block's rows of ``out`` are then meaningless)."""
    n_classes = value.shape[1]
    n_nodes = left.shape[0]
    for i in range(lo, hi):
        for c in range(n_classes):
            out[i, c] = 0.0
    for t in range(roots.shape[0]):
        root = roots[t]
        for i in range(lo, hi):
            node = root
            steps = 0
            while True:
                child = left[node]
                if child == -1:
                    break
                steps += 1
                if steps > n_nodes:  # longer than any tree: a cycle
                    return True
                v = X[i, feature[node]]
                if np.isnan(v):
                    if not missing_left[node]:
                        child = right[node]
                elif v > threshold[node]:
                    child = right[node]
                node = child
            for c in range(n_classes):
                out[i, c] += value[node, c]
    n_trees = roots.shape[0]
    for i in range(lo, hi):
        for c in range(n_classes):
            out[i, c] /= n_trees
    return False


@njit(cache=True, nogil=True)
def _indices_ok(roots, left, right, feature, n_features):
    """One pass over the nodes (not per point): roots and children are node indices (-1 in both
    children for a leaf), inner nodes' features are column indices of X."""
    n_nodes = left.shape[0]
    for t in range(roots.shape[0]):
        if roots[t] < 0 or roots[t] >= n_nodes:
            return False
    for k in range(n_nodes):
        a = left[k]
        b = right[k]
        if a == -1 and b == -1:
            continue
        if a < 0 or a >= n_nodes or b < 0 or b >= n_nodes or feature[k] < 0 or feature[k] >= n_features:
            return False
    return True


@njit(cache=True, nogil=True, parallel=True)
def _forest_proba_kernel(X, roots, left, right, feature, threshold, missing_left, value, out):
    """Mean class probabilities of a forest stored as flat node arrays; returns False when the
    forest is malformed (``out`` is then meaningless).

    Tree t starts at node ``roots[t]``; a node is a leaf when ``left`` is -1; an inner node
    sends a sample left when ``X[i, feature] <= threshold`` (scikit-learn's rule), and a missing
    value (NaN) left when ``missing_left`` is set. ``value`` holds each leaf's class
    probabilities. Blocks of points run in parallel."""
    n_nodes = left.shape[0]
    if (roots.shape[0] == 0 or right.shape[0] != n_nodes or feature.shape[0] != n_nodes
            or threshold.shape[0] != n_nodes or missing_left.shape[0] != n_nodes
            or value.shape[0] != n_nodes or value.shape[1] != out.shape[1] or out.shape[0] != X.shape[0]):
        return False
    if not _indices_ok(roots, left, right, feature, X.shape[1]):
        return False
    n = X.shape[0]
    block = 2048
    nblocks = (n + block - 1) // block
    bad = np.zeros(nblocks, dtype=np.uint8)
    for b in prange(nblocks):
        if _forest_block(X, b * block, min((b + 1) * block, n), roots, left, right, feature, threshold,
                         missing_left, value, out):
            bad[b] = 1
    return not bad.any()
