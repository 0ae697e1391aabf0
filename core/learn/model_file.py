"""The Random Forest model file: a NumPy ``.npz`` archive of plain arrays (read with
``allow_pickle=False``, so loading cannot run code) and a JSON header with a SHA-256 over both.
A file whose format, version or checksum does not match is refused."""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
from typing import Dict

import numpy as np

from ..errors import InputError, InvalidParameterError
from ..io import atomic_path
from .rf import SCALERS, Model, Scaler


FORMAT = "groundsieve-rf"
FORMAT_VERSION = 1
MODEL_EXTENSION = ".npz"


# -- the model file -------------------------------------------------------------------------------

_ARRAYS = ("classes", "roots", "left", "right", "feature", "threshold", "missing_left", "value")


def _digest(arrays: Dict[str, np.ndarray], header: dict) -> str:
    """SHA-256 over every array and the header (less its own checksum)."""
    h = hashlib.sha256()
    h.update(json.dumps({k: v for k, v in header.items() if k != "sha256"}, sort_keys=True).encode("utf-8"))
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_model(model: Model, path: str, *, atomic: bool = True) -> None:
    """Write ``model`` to ``path`` (.npz), atomically unless the caller already writes to a
    temporary path of its own (``atomic=False``)."""
    path = os.fspath(path)
    if not path.lower().endswith(MODEL_EXTENSION):
        raise InvalidParameterError(f"{path}: a model file must end in {MODEL_EXTENSION}")
    arrays = {name: getattr(model, name) for name in _ARRAYS}
    if model.scaler.kind != "none":
        arrays["scaler_center"] = model.scaler.center
        arrays["scaler_scale"] = model.scaler.scale
    header = dict(model.meta, format=FORMAT, format_version=FORMAT_VERSION, features=list(model.features),
                  scaler=model.scaler.kind)
    header["sha256"] = _digest(arrays, header)
    arrays["header"] = np.frombuffer(json.dumps(header, sort_keys=True).encode("utf-8"), dtype=np.uint8)
    with (atomic_path(path) if atomic else contextlib.nullcontext(path)) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, **arrays)


def load_model(path: str) -> Model:
    """Read a model file, refusing anything that is not an intact GroundSieve model.

    The file is untrusted input: its SHA-256 only shows that it was not damaged by accident (anyone
    can edit the arrays and compute the sum again). Every array's kind, shape and range and every
    tree's structure are therefore checked here (see :func:`_check_forest`) before a kernel sees
    them; a file that fails any check is refused with an :class:`InputError` naming it."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such model file")
    with open(path, "rb") as f:
        magic = f.read(6)
    if magic[:4] != b"PK\x03\x04":  # an .npz is a zip archive; numpy would call anything else pickled data
        raise InputError(f"{path}: not a GroundSieve model file (not an .npz archive: "
                         + ("an empty file" if not magic else "it does not start as a zip file does") + ")")
    try:
        with np.load(path, allow_pickle=False) as data:
            if not hasattr(data, "files"):
                raise ValueError("a single array, not an archive")
            arrays = {name: data[name] for name in data.files}
    except Exception as err:  # zip errors, pickled objects refused, ...
        raise InputError(f"{path}: not a GroundSieve model file ({err})") from err
    raw = arrays.pop("header", None)
    try:
        if not (isinstance(raw, np.ndarray) and raw.dtype == np.uint8 and raw.ndim == 1):
            raise ValueError("no header")
        header = json.loads(raw.tobytes().decode("utf-8"))
    except Exception as err:
        raise InputError(f"{path}: not a GroundSieve model file (no readable header)") from err
    if not isinstance(header, dict):
        raise InputError(f"{path}: not a GroundSieve model file (its header is a JSON "
                         f"{type(header).__name__}, not an object)")
    if header.get("format") != FORMAT:
        raise InputError(f"{path}: not a GroundSieve model file")
    version = header.get("format_version")
    if isinstance(version, bool) or version != FORMAT_VERSION:
        raise InputError(f"{path}: model format version {version!r} is not supported by "
                         f"this GroundSieve (it reads version {FORMAT_VERSION}); train the model again")
    missing = [name for name in _ARRAYS if name not in arrays]
    if missing:
        raise InputError(f"{path}: not a complete GroundSieve model file (no {', '.join(missing)} "
                         "array); it is refused")
    if _digest(arrays, header) != header.get("sha256"):
        raise InputError(f"{path}: the model file has been changed or damaged (checksum mismatch); "
                         "it is refused")
    try:
        features, scaler, forest = _check_forest(arrays, header)
    except _Unusable as err:
        raise InputError(f"{path}: this model file cannot be used: {err}. It was edited or written by "
                         "another program; train the model again or use an intact copy") from None
    meta = {k: v for k, v in header.items() if k not in ("format", "format_version", "features", "scaler", "sha256")}
    return Model(features, forest["classes"], forest["roots"], forest["left"], forest["right"],
                 forest["feature"], forest["threshold"], forest["missing_left"], forest["value"], scaler, meta)


# -- checks of an untrusted file -----------------------------------------------------------------

class _Unusable(Exception):
    """One problem of a model file, in a user's words (load_model adds the file's name)."""


def _array(arrays, name: str, kinds: str, ndim: int) -> np.ndarray:
    a = arrays.get(name)
    if (not isinstance(a, np.ndarray) or a.dtype.fields is not None or a.dtype.kind not in kinds
            or a.ndim != ndim):
        what = {"f": "numbers", "iu": "whole numbers", "iub": "0 or 1"}[kinds]
        got = "missing" if a is None else f"{a.ndim}-D array of {a.dtype}"
        raise _Unusable(f"'{name}' must be a {ndim}-D array of {what} (got {got})")
    return a


def _in_range(a: np.ndarray, name: str, lo: int, hi: int) -> np.ndarray:
    """``a`` as int64 when every value is in [lo, hi), else a clear refusal."""
    if a.size and (a.min() < lo or a.max() >= hi):
        bad = a[(a < lo) | (a >= hi)][0]
        raise _Unusable(f"'{name}' holds {bad}, outside {lo}..{hi - 1}")
    return a.astype(np.int64)


def _check_header(header: dict):
    features = header.get("features")
    if (not isinstance(features, list) or not features
            or not all(isinstance(f, str) and f for f in features)):
        raise _Unusable("the feature names must be a non-empty list of names")
    if len(set(features)) != len(features):
        raise _Unusable(f"a feature name appears twice in {features}")
    if len(features) >= 2 ** 15:
        raise _Unusable(f"{len(features)} features (at most {2 ** 15 - 1})")
    preset = header.get("preset_features")
    if preset is not None and (not isinstance(preset, list) or not preset
                               or not all(isinstance(f, str) and f for f in preset)):
        raise _Unusable("the preset feature names must be a non-empty list of names")
    kind = header.get("scaler")
    if not isinstance(kind, str) or kind not in SCALERS:
        raise _Unusable(f"unknown scaler {kind!r} (known: {', '.join(SCALERS)})")
    return list(features), kind


def _check_scaler(arrays, kind: str, n_features: int) -> Scaler:
    if kind == "none":
        return Scaler("none")
    if "scaler_center" not in arrays or "scaler_scale" not in arrays:
        raise _Unusable(f"the {kind} scaler's centre and scale arrays are missing")
    center = _array(arrays, "scaler_center", "f", 1)
    scale = _array(arrays, "scaler_scale", "f", 1)
    for name, a in (("scaler_center", center), ("scaler_scale", scale)):
        if a.shape != (n_features,):
            raise _Unusable(f"'{name}' holds {a.size} values for {n_features} features")
        if not np.isfinite(a).all():
            raise _Unusable(f"'{name}' holds a value that is not a finite number")
    if not (scale > 0).all():
        raise _Unusable("'scaler_scale' holds a scale <= 0")
    return Scaler(kind, center.astype(np.float64), scale.astype(np.float64))


def _check_forest(arrays, header: dict):
    """Every array and every tree of the forest, as ``rf.from_sklearn`` writes them:

    - ``classes``: at least two distinct ASPRS codes (0-255); training refuses a single class;
    - ``roots``: at least one tree, each root a node index, all distinct, none the child of a node;
    - ``left``/``right``: -1 in both for a leaf, else two node indices; every node is the child of
      at most one node and is reached from exactly one root, so each tree is a tree (no cycle, no
      node shared between trees, no stray node) and a walk from a root ends at a leaf within
      as many steps as the forest has nodes;
    - ``feature``: a feature index (0 .. features-1) at every inner node;
    - ``threshold``: not NaN at inner nodes (+-infinity is kept: scikit-learn splits missing from
      present values with +infinity);
    - ``missing_left``: 0 or 1;
    - ``value``: (nodes, classes) probabilities, finite and within 0..1, each leaf's summing to 1;
    - the scaler: a known kind, with finite centre and scale > 0 per feature unless it is "none".

    Returns the feature names, the scaler and the arrays in the kinds the predictor uses."""
    features, kind = _check_header(header)
    scaler = _check_scaler(arrays, kind, len(features))

    classes = _array(arrays, "classes", "iu", 1)
    classes = _in_range(classes, "classes", 0, 256)
    if classes.size < 2:
        raise _Unusable(f"the model knows {classes.size} class(es); a model separates at least two")
    if np.unique(classes).size != classes.size:
        raise _Unusable(f"a class appears twice in {classes.tolist()}")

    left = _array(arrays, "left", "iu", 1)
    n = left.shape[0]
    if n == 0:
        raise _Unusable("the forest has no node")
    if n >= 2 ** 31:
        raise _Unusable(f"{n} nodes (at most 2^31 - 1)")
    for name, kinds in (("right", "iu"), ("feature", "iu"), ("threshold", "f"), ("missing_left", "iub")):
        a = _array(arrays, name, kinds, 1)
        if a.shape[0] != n:
            raise _Unusable(f"'{name}' holds {a.shape[0]} nodes, 'left' {n}")
    value = _array(arrays, "value", "f", 2)
    if value.shape != (n, classes.size):
        raise _Unusable(f"'value' has shape {value.shape}, expected ({n}, {classes.size}): one "
                        "probability per node and class")

    roots = _in_range(_array(arrays, "roots", "iu", 1), "roots", 0, n)
    if roots.size == 0:
        raise _Unusable("the forest has no tree")
    left = _in_range(left, "left", -1, n)
    right = _in_range(arrays["right"], "right", -1, n)
    leaf = left == -1
    if not np.array_equal(leaf, right == -1):
        node = int(np.flatnonzero(leaf != (right == -1))[0])
        raise _Unusable(f"node {node} has one child (a node has two children or none)")
    missing_left = _in_range(arrays["missing_left"], "missing_left", 0, 2).astype(np.uint8)
    inner = ~leaf
    feature = arrays["feature"]
    if inner.any():
        _in_range(feature[inner], "feature", 0, len(features))
    feature = np.where(inner, feature, 0).astype(np.int16)
    threshold = arrays["threshold"].astype(np.float64)
    if np.isnan(threshold[inner]).any():
        raise _Unusable("a split threshold is not a number (NaN)")
    _check_structure(roots, left, right, inner)

    value = value.astype(np.float64)
    if not np.isfinite(value).all() or (value < 0).any() or (value > 1).any():
        raise _Unusable("'value' holds a probability that is not a number between 0 and 1")
    sums = value[leaf].sum(axis=1)
    if sums.size and not np.allclose(sums, 1.0, rtol=0, atol=1e-6):
        raise _Unusable("a leaf's class probabilities do not sum to 1")
    forest = dict(classes=classes.astype(np.uint8), roots=roots, left=left.astype(np.int32),
                  right=right.astype(np.int32), feature=feature, threshold=threshold,
                  missing_left=missing_left, value=value)
    return features, scaler, forest


def _check_structure(roots: np.ndarray, left: np.ndarray, right: np.ndarray, inner: np.ndarray) -> None:
    """Each node is the child of at most one node, roots of none, and every node is reached from a
    root: then every tree is a tree (no cycle, no shared node) and holds each node once.

    Why that suffices: follow a node's parents upwards; with one parent each, the path is unique,
    so a node reached from two roots, or twice from one, would have two parents or be a root with a
    parent. Reachability is found by pointer doubling on the parent array (log2(nodes) numpy steps,
    whatever the depth), so a crafted chain of a million nodes costs no more than a bushy tree."""
    n = left.shape[0]
    children = np.concatenate([left[inner], right[inner]])
    indegree = np.bincount(children, minlength=n)
    if indegree.max(initial=0) > 1:
        raise _Unusable(f"node {int(np.argmax(indegree > 1))} is the child of two nodes (trees must not "
                        "share or repeat nodes)")
    if np.unique(roots).size != roots.size:
        raise _Unusable("two trees start at the same node")
    if indegree[roots].any():
        raise _Unusable(f"the root node {int(roots[indegree[roots] > 0][0])} is also a child of a node")
    parent = np.arange(n, dtype=np.int64)  # a root (or a stray node) points to itself
    inner_nodes = np.flatnonzero(inner)
    parent[left[inner]] = inner_nodes
    parent[right[inner]] = inner_nodes
    top = parent
    for _ in range(max(1, int(n).bit_length())):  # after k steps, top = 2^k-th ancestor (or the top)
        top = top[top]
    is_root = np.zeros(n, dtype=bool)
    is_root[roots] = True
    if not is_root[top].all():
        node = int(np.flatnonzero(~is_root[top])[0])
        raise _Unusable(f"node {node} is not reached from any tree's root (a cycle or a stray node)")
