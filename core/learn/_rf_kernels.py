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


#: forests whose trees are at most this deep are walked as complete binary trees (see _complete_block)
MAX_COMPLETE_DEPTH = 12


@njit(cache=True, nogil=True)
def _max_depth(roots, left, right, limit):
    """Depth (inner nodes on the longest root-to-leaf path) of the deepest tree, or -1 when a tree
    is deeper than ``limit`` or a walk visits more nodes than the forest has (a cycle). Indices have
    been checked by :func:`_indices_ok`."""
    n_nodes = left.shape[0]
    stack_node = np.empty(2 * limit + 4, dtype=np.int64)
    stack_level = np.empty(2 * limit + 4, dtype=np.int64)
    deepest = 0
    for t in range(roots.shape[0]):
        top = 0
        stack_node[0] = roots[t]
        stack_level[0] = 0
        visited = 0
        while top >= 0:
            node = stack_node[top]
            level = stack_level[top]
            top -= 1
            visited += 1
            if visited > n_nodes:
                return -1
            if left[node] == -1:
                deepest = max(deepest, level)
                continue
            if level >= limit:
                return -1
            stack_node[top + 1] = left[node]
            stack_level[top + 1] = level + 1
            stack_node[top + 2] = right[node]
            stack_level[top + 2] = level + 1
            top += 2
    return deepest


@njit(cache=True, nogil=True)
def _complete_trees(roots, left, right, feature, threshold, missing_left, value, depth,
                    feat, thr, nan_right, leaf):
    """Each tree laid out as a complete binary tree of ``depth`` levels: node k's children are
    2k+1 (left) and 2k+2 (right). A leaf shallower than ``depth`` becomes inner nodes that send
    every value left (threshold +inf, NaN left) down to its leftmost slot on the last level, which
    holds its class probabilities: every point reaches the leaf it reaches in the original tree.
    The forest has passed :func:`_max_depth` with this depth."""
    inner = (1 << depth) - 1
    stack_node = np.empty(2 * depth + 4, dtype=np.int64)
    stack_pos = np.empty(2 * depth + 4, dtype=np.int64)
    stack_level = np.empty(2 * depth + 4, dtype=np.int64)
    for t in range(roots.shape[0]):
        top = 0
        stack_node[0] = roots[t]
        stack_pos[0] = 0
        stack_level[0] = 0
        while top >= 0:
            node = stack_node[top]
            pos = stack_pos[top]
            level = stack_level[top]
            top -= 1
            if left[node] == -1:
                while level < depth:
                    pos = 2 * pos + 1
                    level += 1
                for c in range(value.shape[1]):
                    leaf[t, pos - inner, c] = value[node, c]
                continue
            feat[t, pos] = feature[node]
            thr[t, pos] = threshold[node]
            nan_right[t, pos] = 0 if missing_left[node] else 1
            stack_node[top + 1] = left[node]
            stack_pos[top + 1] = 2 * pos + 1
            stack_level[top + 1] = level + 1
            stack_node[top + 2] = right[node]
            stack_pos[top + 2] = 2 * pos + 2
            stack_level[top + 2] = level + 1
            top += 2


@njit(cache=True, nogil=True)
def _complete_block(X, lo, hi, depth, feat, thr, nan_right, leaf, out):
    """Rows ``lo:hi`` on complete trees (:func:`_complete_trees`): every point takes exactly
    ``depth`` steps, each ``k = 2k + 1 + (goes right)`` without a branch, level by level over the
    block's points (independent walks the processor overlaps). Same comparisons and the same sum
    over the trees in the same order as :func:`_forest_block`: the same probabilities, bit for bit."""
    n_classes = leaf.shape[2]
    inner = (1 << depth) - 1
    m = hi - lo
    node = np.empty(m, dtype=np.int64)
    for i in range(lo, hi):
        for c in range(n_classes):
            out[i, c] = 0.0
    has_nan = False
    for i in range(lo, hi):
        for f in range(X.shape[1]):
            if X[i, f] != X[i, f]:
                has_nan = True
    n_trees = feat.shape[0]
    for t in range(n_trees):
        ft = feat[t]
        tt = thr[t]
        nt = nan_right[t]
        for j in range(m):
            node[j] = 0
        if has_nan:
            for _level in range(depth):
                for j in range(m):
                    k = node[j]
                    v = X[lo + j, ft[k]]
                    right = (v > tt[k]) | ((v != v) & (nt[k] != 0))
                    node[j] = 2 * k + 1 + right
        else:  # no missing value in the block: the comparison alone (a third faster)
            for _level in range(depth):
                for j in range(m):
                    k = node[j]
                    node[j] = 2 * k + 1 + (X[lo + j, ft[k]] > tt[k])
        lt = leaf[t]
        for j in range(m):
            for c in range(n_classes):
                out[lo + j, c] += lt[node[j] - inner, c]
    for i in range(lo, hi):
        for c in range(n_classes):
            out[i, c] /= n_trees


@njit(cache=True, nogil=True, parallel=True)
def _forest_proba_kernel(X, roots, left, right, feature, threshold, missing_left, value, out):
    """Mean class probabilities of a forest stored as flat node arrays; returns False when the
    forest is malformed (``out`` is then meaningless).

    Tree t starts at node ``roots[t]``; a node is a leaf when ``left`` is -1; an inner node
    sends a sample left when ``X[i, feature] <= threshold`` (scikit-learn's rule), and a missing
    value (NaN) left when ``missing_left`` is set. ``value`` holds each leaf's class
    probabilities. Blocks of points run in parallel. Forests of trees at most
    :data:`MAX_COMPLETE_DEPTH` deep are walked as complete trees (:func:`_complete_block`), the
    others node by node (:func:`_forest_block`)."""
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
    depth = _max_depth(roots, left, right, MAX_COMPLETE_DEPTH)
    if depth >= 0:  # shallow trees (the hybrid filter's): branch-free walks on complete trees
        n_trees = roots.shape[0]
        feat = np.zeros((n_trees, max((1 << depth) - 1, 1)), dtype=np.int64)
        thr = np.full((n_trees, max((1 << depth) - 1, 1)), np.inf)
        nan_right = np.zeros((n_trees, max((1 << depth) - 1, 1)), dtype=np.uint8)
        leaf = np.zeros((n_trees, 1 << depth, value.shape[1]))
        _complete_trees(roots, left, right, feature, threshold, missing_left, value, depth, feat, thr, nan_right,
                        leaf)
        for b in prange(nblocks):
            _complete_block(X, b * block, min((b + 1) * block, n), depth, feat, thr, nan_right, leaf, out)
        return True
    bad = np.zeros(nblocks, dtype=np.uint8)
    for b in prange(nblocks):
        if _forest_block(X, b * block, min((b + 1) * block, n), roots, left, right, feature, threshold,
                         missing_left, value, out):
            bad[b] = 1
    return not bad.any()
