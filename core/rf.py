"""Random Forest classification of points (matrone2024, Method 3).

Training uses scikit-learn. The trained forest is then stored as plain arrays, never as a
pickle: a model file is a NumPy ``.npz`` archive (read with ``allow_pickle=False``, so loading
cannot run code) holding each tree's node arrays, the scaler's statistics and a JSON header
(format version, feature names, class codes, training versions, a SHA-256 of every array). A
model whose checksum, format or features do not match is refused. Prediction runs on those
arrays with a numba kernel (core/_rf_kernels.py), so applying a model needs no scikit-learn
object and gives the same answer on every installation.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from typing import Dict, List, Optional, Sequence

import numpy as np

from .errors import InputError, InvalidParameterError
from .io import atomic_path
from .smrf import check_choice

FORMAT = "groundsieve-rf"
FORMAT_VERSION = 1
MODEL_EXTENSION = ".npz"

#: Point attributes read from the LAS file (name -> how to get it from a laspy LasData).
ATTRIBUTE_FEATURES = ("red", "green", "blue", "intensity", "return_number", "number_of_returns",
                      "scan_angle", "gps_time")

CRITERIA = ("gini", "entropy")
SCALERS = ("none", "standard", "robust")


@dataclass(frozen=True)
class ForestParams:
    """Training parameters (the paper: gini or entropy; 100, 150 or 200 trees; no, standard or
    robust scaler; no depth limit)."""
    n_trees: int = 100
    criterion: str = "gini"
    scaler: str = "none"
    max_depth: Optional[int] = None
    #: samples drawn per tree (bootstrap); caps the training time and the tree size on large
    #: clouds (None = all, as scikit-learn's default)
    max_samples: Optional[int] = 100_000
    min_samples_leaf: int = 1
    seed: int = 0

    def __post_init__(self):
        if isinstance(self.n_trees, bool) or not isinstance(self.n_trees, (int, np.integer)) or self.n_trees < 1:
            raise InvalidParameterError(f"n_trees must be a whole number >= 1 (got {self.n_trees!r})")
        check_choice(self, "criterion", CRITERIA)
        check_choice(self, "scaler", SCALERS)
        if self.max_depth is not None and (not isinstance(self.max_depth, (int, np.integer)) or self.max_depth < 1):
            raise InvalidParameterError(f"max_depth must be None or a whole number >= 1 (got {self.max_depth!r})")
        if self.max_samples is not None and (not isinstance(self.max_samples, (int, np.integer))
                                             or self.max_samples < 1):
            raise InvalidParameterError(f"max_samples must be None or >= 1 (got {self.max_samples!r})")
        if not isinstance(self.min_samples_leaf, (int, np.integer)) or self.min_samples_leaf < 1:
            raise InvalidParameterError(f"min_samples_leaf must be >= 1 (got {self.min_samples_leaf!r})")


@dataclass
class Scaler:
    kind: str = "none"
    center: Optional[np.ndarray] = None
    scale: Optional[np.ndarray] = None

    @classmethod
    def fit(cls, kind: str, X: np.ndarray) -> "Scaler":
        if kind == "none":
            return cls("none")
        if kind == "standard":
            center, scale = np.nanmean(X, axis=0), np.nanstd(X, axis=0)
        else:  # robust: median and interquartile range
            center = np.nanmedian(X, axis=0)
            q75, q25 = np.nanpercentile(X, [75, 25], axis=0)
            scale = q75 - q25
        scale = np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)
        return cls(kind, center.astype(np.float64), scale.astype(np.float64))

    def transform(self, X: np.ndarray) -> np.ndarray:
        if self.kind == "none":
            return X
        return ((X - self.center) / self.scale).astype(np.float32)


@dataclass
class Model:
    """A trained forest as arrays, with what is needed to apply it safely."""
    features: List[str]
    classes: np.ndarray                 #: ASPRS class codes, in probability-column order
    roots: np.ndarray
    left: np.ndarray
    right: np.ndarray
    feature: np.ndarray
    threshold: np.ndarray
    missing_left: np.ndarray            #: 1 where a missing value (NaN) goes to the left child
    value: np.ndarray                   #: (nodes, classes) leaf class probabilities
    scaler: Scaler = field(default_factory=Scaler)
    meta: dict = field(default_factory=dict)

    @property
    def n_trees(self) -> int:
        return int(self.roots.shape[0])

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        from ._rf_kernels import _forest_proba_kernel
        X = np.ascontiguousarray(self.scaler.transform(np.asarray(X, dtype=np.float32)), dtype=np.float32)
        if X.ndim != 2 or X.shape[1] != len(self.features):
            raise InputError(f"the model expects {len(self.features)} features, got an array of shape {X.shape}")
        out = np.empty((X.shape[0], self.classes.size), dtype=np.float64)
        _forest_proba_kernel(X, self.roots, self.left, self.right, self.feature, self.threshold,
                             self.missing_left, self.value, out)
        return out

    def predict(self, X: np.ndarray) -> np.ndarray:
        return self.classes[np.argmax(self.predict_proba(X), axis=1)]


def from_sklearn(forest, features: Sequence[str], classes: np.ndarray, scaler: Scaler, meta: dict) -> Model:
    """Flatten a fitted ``RandomForestClassifier`` into a :class:`Model`."""
    roots, lefts, rights, feats, thrs, missing, values = [], [], [], [], [], [], []
    offset = 0
    for est in forest.estimators_:
        tree = est.tree_
        n = tree.node_count
        left = tree.children_left.astype(np.int64)
        right = tree.children_right.astype(np.int64)
        inner = left != -1
        left = np.where(inner, left + offset, -1)
        right = np.where(inner, right + offset, -1)
        val = tree.value[:, 0, :].astype(np.float64)
        sums = val.sum(axis=1, keepdims=True)
        val = np.divide(val, sums, out=np.zeros_like(val), where=sums > 0)
        roots.append(offset)
        lefts.append(left)
        rights.append(right)
        feats.append(np.where(inner, tree.feature, 0).astype(np.int64))
        thrs.append(tree.threshold.astype(np.float64))
        missing.append(np.asarray(tree.missing_go_to_left, dtype=np.uint8))
        values.append(val)
        offset += n
    if offset >= 2 ** 31 or len(features) >= 2 ** 15:
        raise InvalidParameterError("the forest is too large to store (over 2^31 nodes or 2^15 features)")
    # Compact node arrays (int32 children, int16 features): a tree's walk touches less memory.
    return Model(list(features), np.asarray(classes, dtype=np.uint8), np.asarray(roots, dtype=np.int64),
                 np.concatenate(lefts).astype(np.int32), np.concatenate(rights).astype(np.int32),
                 np.concatenate(feats).astype(np.int16),
                 np.concatenate(thrs), np.concatenate(missing), np.concatenate(values), scaler, meta)


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


def save_model(model: Model, path: str) -> None:
    """Write ``model`` to ``path`` (.npz) atomically."""
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
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, **arrays)


def load_model(path: str) -> Model:
    """Read a model file, refusing anything that is not an intact GroundSieve model."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such model file")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except Exception as err:  # zip errors, pickled objects refused, ...
        raise InputError(f"{path}: not a GroundSieve model file ({err})") from err
    try:
        header = json.loads(bytes(arrays.pop("header")).decode("utf-8"))
    except Exception as err:
        raise InputError(f"{path}: not a GroundSieve model file (no readable header)") from err
    if header.get("format") != FORMAT:
        raise InputError(f"{path}: not a GroundSieve model file")
    if header.get("format_version") != FORMAT_VERSION:
        raise InputError(f"{path}: model format version {header.get('format_version')} is not supported by "
                         f"this GroundSieve (it reads version {FORMAT_VERSION}); train the model again")
    missing = [name for name in _ARRAYS if name not in arrays]
    if missing or _digest(arrays, header) != header.get("sha256"):
        raise InputError(f"{path}: the model file has been changed or damaged (checksum mismatch); "
                         "it is refused")
    n_nodes = arrays["left"].shape[0]
    for name in ("right", "feature", "threshold", "missing_left"):
        if arrays[name].shape != (n_nodes,):
            raise InputError(f"{path}: inconsistent model arrays")
    features = header["features"]
    if (arrays["feature"].min(initial=0) < 0 or arrays["feature"].max(initial=0) >= len(features)
            or arrays["left"].max(initial=-1) >= n_nodes or arrays["right"].max(initial=-1) >= n_nodes):
        raise InputError(f"{path}: inconsistent model arrays")
    scaler = Scaler(header.get("scaler", "none"), arrays.get("scaler_center"), arrays.get("scaler_scale"))
    meta = {k: v for k, v in header.items() if k not in ("format", "format_version", "features", "scaler", "sha256")}
    return Model(features, arrays["classes"], arrays["roots"], arrays["left"], arrays["right"],
                 arrays["feature"], arrays["threshold"], arrays["missing_left"], arrays["value"], scaler, meta)


# -- spatial blocks ----------------------------------------------------------------------------

def spatial_split(x: np.ndarray, y: np.ndarray, block_m: float, fractions=(0.6, 0.2, 0.2),
                  seed: int = 0) -> np.ndarray:
    """0 (train), 1 (validation) or 2 (test) per point, by square blocks of ``block_m`` assigned
    at random in the given proportions, so that neighbouring points stay in the same set."""
    if not (math.isfinite(block_m) and block_m > 0):
        raise InvalidParameterError(f"block size must be > 0 m (got {block_m})")
    fractions = np.asarray(fractions, dtype=np.float64)
    if fractions.shape != (3,) or (fractions < 0).any() or not math.isclose(fractions.sum(), 1.0):
        raise InvalidParameterError(f"split fractions must be three numbers >= 0 summing to 1 (got {fractions})")
    # Block edges on multiples of block_m, as the grids of core/grid.py: the same blocks in every tile.
    col = np.floor(x / block_m).astype(np.int64)
    row = np.floor(y / block_m).astype(np.int64)
    col -= col.min()
    row -= row.min()
    block = row * (col.max() + 1) + col
    ids, inverse = np.unique(block, return_inverse=True)
    rng = np.random.default_rng(seed)
    order = rng.permutation(ids.size)
    cuts = np.round(np.cumsum(fractions)[:2] * ids.size).astype(np.int64)
    assignment = np.empty(ids.size, dtype=np.int8)
    assignment[order[:cuts[0]]] = 0
    assignment[order[cuts[0]:cuts[1]]] = 1
    assignment[order[cuts[1]:]] = 2
    return assignment[inverse]


# -- training ----------------------------------------------------------------------------------

def train_forest(X: np.ndarray, y: np.ndarray, features: Sequence[str], params: ForestParams = ForestParams(),
                 *, n_jobs: int = -1, meta: Optional[dict] = None) -> Model:
    """Fit a forest on ``X`` (n, features) and labels ``y`` (ASPRS codes)."""
    import sklearn
    from sklearn.ensemble import RandomForestClassifier
    X = np.asarray(X, dtype=np.float32)
    y = np.asarray(y)
    if X.shape[0] != y.shape[0] or X.shape[0] == 0:
        raise InputError(f"training needs labelled points (got {X.shape[0]} samples, {y.shape[0]} labels)")
    classes = np.unique(y)
    if classes.size < 2:
        raise InputError(f"training needs at least two classes (got only {classes.tolist()})")
    scaler = Scaler.fit(params.scaler, X)
    Xs = scaler.transform(X)  # NaN (e.g. a feature undefined for too few neighbours) stays NaN:
    # scikit-learn's trees learn where missing values go, and the predictor follows them.
    max_samples = params.max_samples if params.max_samples and params.max_samples < X.shape[0] else None
    forest = RandomForestClassifier(n_estimators=params.n_trees, criterion=params.criterion,
                                    max_depth=params.max_depth, min_samples_leaf=params.min_samples_leaf,
                                    max_samples=max_samples, n_jobs=n_jobs, random_state=params.seed)
    t0 = time.perf_counter()
    forest.fit(Xs, y)
    info = dict(meta or {}, params=asdict(params), trained_on=int(X.shape[0]),
                training_seconds=round(time.perf_counter() - t0, 3), sklearn_version=sklearn.__version__,
                impurity_importance=[float(v) for v in forest.feature_importances_])
    return from_sklearn(forest, features, forest.classes_, scaler, info)


# -- features of a cloud -----------------------------------------------------------------------

#: f4-f7 of the paper: verticality 0.6 m, planarity 0.6 m, eigenentropy 0.4 m, surface variation 0.6 m.
GEOMETRIC = ("verticality_r0p6", "planarity_r0p6", "eigenentropy_r0p4", "surface_variation_r0p6")
#: ``radiometry`` stands for red, green, blue, or intensity when the cloud has no colour.
RADIOMETRY = "radiometry"
#: The paper's feature configurations (its Table 7).
PRESETS = {
    "C1": (RADIOMETRY,),
    "C2": (RADIOMETRY, "return_number"),
    "C3": (RADIOMETRY, "return_number", "scan_angle", "gps_time"),
    "C4": (RADIOMETRY, "return_number", "scan_angle", "gps_time") + GEOMETRIC,
    "C5": (RADIOMETRY, "return_number") + GEOMETRIC,
    # Ours: C5 plus the height above the lowest point within 2.5 m and the local density, which
    # carry the ground/non-ground contrast on sparse ALS where 0.4-0.6 m spheres hold few points.
    "C5H": (RADIOMETRY, "return_number") + GEOMETRIC + ("height_above_min_r2p5", "density_r1"),
}
DEFAULT_PRESET = "C5H"


def _has_colour(cloud) -> bool:
    las = cloud.las
    if las is None or "red" not in las.point_format.dimension_names:
        return False
    return bool(np.any(las.red) or np.any(las.green) or np.any(las.blue))


def resolve_features(names: Sequence[str], cloud, log=None) -> List[str]:
    """Expand ``radiometry`` for this cloud (RGB when it has colour, else intensity)."""
    out: List[str] = []
    for name in names:
        if name == RADIOMETRY:
            if _has_colour(cloud):
                out += ["red", "green", "blue"]
            else:
                if log:
                    log(f"{cloud.path}: no colour (RGB) in the file; the radiometric feature is the intensity.")
                out.append("intensity")
        elif name not in out:
            out.append(name)
    return out


def _attribute(cloud, name: str) -> np.ndarray:
    las = cloud.las
    if name in ("return_number", "number_of_returns"):
        return getattr(cloud, name).astype(np.float32)
    if las is None:
        raise InputError(f"{cloud.path}: the feature '{name}' needs a LAS/LAZ file (this is ISPRS text)")
    dims = set(las.point_format.dimension_names)
    if name == "scan_angle":
        if "scan_angle" in dims:  # formats 6-10: 0.006 degree units
            return (np.asarray(las.scan_angle, dtype=np.float32) * np.float32(0.006))
        if "scan_angle_rank" in dims:
            return np.asarray(las.scan_angle_rank, dtype=np.float32)
    if name in dims:
        return np.asarray(las[name], dtype=np.float32)
    raise InputError(f"{cloud.path}: the feature '{name}' is not in this file (dimensions: "
                     f"{', '.join(sorted(dims))})")


def feature_matrix(cloud, names: Sequence[str], steps=None) -> np.ndarray:
    """(n, len(names)) float32 matrix of the named features of ``cloud``. Attributes are read from
    the file; geometric features (``<feature>_r<radius>``) are taken from the file's extra bytes when
    present (e.g. written by groundsieve:features) and computed otherwise."""
    from .features import FeatureSpec, compute_features, parse_feature_name
    from .progress import Steps
    steps = steps or Steps()
    columns: Dict[str, np.ndarray] = {}
    dims = set(cloud.las.point_format.dimension_names) if cloud.las is not None else set()
    to_compute = []
    for name in names:
        if name in ATTRIBUTE_FEATURES or name in ("scan_angle",):
            columns[name] = _attribute(cloud, name)
        elif name in dims:
            columns[name] = np.asarray(cloud.las[name], dtype=np.float32)
        else:
            parse_feature_name(name)  # a clear error for an unknown name
            to_compute.append(name)
    if to_compute:
        computed = compute_features(cloud.xyz, FeatureSpec.from_names(to_compute), steps=steps)
        columns.update(computed)
    steps.report(1.0)
    return np.column_stack([columns[name] for name in names]).astype(np.float32)


# -- file to file ------------------------------------------------------------------------------

#: The paper's grid: splitting criterion x number of trees x scaler.
PAPER_GRID = tuple((c, t, s) for c in CRITERIA for t in (100, 150, 200) for s in SCALERS)
EXCLUDED_BY_DEFAULT = (0, 7, 18)  # never classified, noise


@dataclass(frozen=True)
class TrainOptions:
    features: tuple = PRESETS[DEFAULT_PRESET]
    classes: Optional[tuple] = None      #: ASPRS codes to learn; None = all present but 0, 7, 18
    params: ForestParams = ForestParams()
    block_m: float = 25.0                #: spatial blocks of the train/validation/test split
    fractions: tuple = (0.6, 0.2, 0.2)
    grid: bool = False                   #: run the paper's grid, keep the best on validation
    permutation_points: int = 20_000     #: test points used for permutation importance
    permutation_repeats: int = 2


@dataclass
class TrainRun:
    model: Model
    evaluations: dict
    features: List[str]
    timings: dict
    grid: Optional[List[dict]] = None


def _labelled(cloud, classes, log):
    labels = cloud.classification
    if classes is None:
        present = np.unique(labels)
        classes = tuple(int(c) for c in present if c not in EXCLUDED_BY_DEFAULT)
        log(f"Learning the classes present in {cloud.path}: {', '.join(map(str, classes))}.")
    missing = [c for c in classes if not np.any(labels == c)]
    if missing:
        raise InputError(f"{cloud.path}: no point of class {', '.join(map(str, missing))} to learn from")
    if len(classes) < 2:
        raise InputError(f"{cloud.path}: at least two classes are needed to train (got {list(classes)})")
    return np.isin(labels, classes), tuple(classes)


def permutation_importance(model: Model, X: np.ndarray, y: np.ndarray, repeats: int = 3, seed: int = 0):
    """Mean drop in accuracy when each column of ``X`` is shuffled."""
    rng = np.random.default_rng(seed)
    base = float((model.predict(X) == y).mean())
    drops = np.zeros(X.shape[1])
    for j in range(X.shape[1]):
        for _ in range(repeats):
            shuffled = X.copy()
            shuffled[:, j] = rng.permutation(shuffled[:, j])
            drops[j] += base - float((model.predict(shuffled) == y).mean())
    return drops / repeats


def train_file(input_path: str, model_path: str, report_path: Optional[str] = None,
               options: TrainOptions = TrainOptions(), *, validation_path: Optional[str] = None,
               test_path: Optional[str] = None, progress=None, is_cancelled=None, log=None) -> TrainRun:
    """Train on the labelled cloud ``input_path`` (its classification is the label) and write the
    model and the report. Validation and test sets are spatial blocks of the input, or the
    separate files ``validation_path`` / ``test_path`` when given."""
    from .io import check_output_path, read_cloud
    from .metrics import class_report
    from .progress import Steps
    from .report import write_report
    steps = Steps(progress, is_cancelled)
    log = log or (lambda _msg: None)
    check_output_path(model_path, inputs=[input_path, validation_path, test_path], extensions=(MODEL_EXTENSION,),
                      what="model file")
    if report_path:
        check_output_path(report_path, inputs=[input_path, model_path], extensions=(".html", ".htm"),
                          what="report")
    timings = {}
    t0 = time.perf_counter()
    cloud = read_cloud(input_path)
    keep, classes = _labelled(cloud, options.classes, log)
    names = resolve_features(options.features, cloud, log)
    X = feature_matrix(cloud, names, steps.sub(0.0, 0.3))
    y = cloud.classification
    timings["features (training cloud)"] = time.perf_counter() - t0
    sets = {}
    if validation_path or test_path:
        sets["train"] = (X[keep], y[keep])
        for label, path in (("validation", validation_path), ("test", test_path)):
            if path:
                t1 = time.perf_counter()
                other = read_cloud(path)
                other_keep = np.isin(other.classification, classes)
                other_names = resolve_features(options.features, other, log)
                if other_names != names:
                    raise InputError(f"{path}: gives the features {other_names}, the training cloud {names}")
                Xo = feature_matrix(other, names)
                sets[label] = (Xo[other_keep], other.classification[other_keep])
                timings[f"features ({label} file)"] = time.perf_counter() - t1
    if not ("validation" in sets and "test" in sets):
        split = spatial_split(cloud.x, cloud.y, options.block_m, options.fractions, seed=options.params.seed)
        for label, code in (("train", 0), ("validation", 1), ("test", 2)):
            if label in sets and label != "train":
                continue
            mask = keep & (split == code)
            sets[label] = (X[mask], y[mask])
        if validation_path or test_path:
            log("Blocks of the input fill in the set not given as a file.")
    for label, (Xs, _ys) in sets.items():
        if len(Xs) == 0:
            raise InputError(f"{input_path}: the {label} set is empty; use smaller blocks "
                             f"(now {options.block_m:g} m) or give it as a file")
    log(", ".join(f"{label}: {len(v[0]):,} points" for label, v in sets.items()))
    steps.report(0.35)
    meta = dict(groundsieve_trained_from=os.path.basename(input_path), preset_features=list(options.features))
    candidates = [options.params]
    if options.grid:
        candidates = [ForestParams(n_trees=t, criterion=c, scaler=s, max_depth=options.params.max_depth,
                                   max_samples=options.params.max_samples, seed=options.params.seed)
                      for c, t, s in PAPER_GRID]
    best = None
    grid_rows = [] if options.grid else None
    t1 = time.perf_counter()
    for k, params in enumerate(candidates):
        steps.check()
        t_fit = time.perf_counter()
        model = train_forest(*sets["train"], names, params, meta=meta)
        Xv, yv = sets["validation"]
        report = class_report(yv, model.predict(Xv), classes)
        score = report.weighted(report.f1)
        if grid_rows is not None:
            grid_rows.append(dict(criterion=params.criterion, n_trees=params.n_trees, scaler=params.scaler,
                                  accuracy=report.accuracy, f1=score, seconds=time.perf_counter() - t_fit))
        if best is None or score > best[0]:
            best = (score, model)
        steps.report(0.35 + 0.5 * (k + 1) / len(candidates))
    model = best[1]
    timings["training" + (" (grid)" if options.grid else "")] = time.perf_counter() - t1
    t2 = time.perf_counter()
    evaluations = {}
    for label in ("validation", "test"):
        Xs, ys = sets[label]
        evaluations[f"{label} set"] = class_report(ys, model.predict(Xs), classes)
    timings["prediction (validation + test)"] = time.perf_counter() - t2
    Xt, yt = sets["test"]
    if len(Xt) > options.permutation_points:
        pick = np.random.default_rng(0).choice(len(Xt), options.permutation_points, replace=False)
        Xt, yt = Xt[pick], yt[pick]
    t3 = time.perf_counter()
    perm = permutation_importance(model, Xt, yt, options.permutation_repeats)
    timings["permutation importance"] = time.perf_counter() - t3
    model.meta.update(classes_learned=list(classes), test_accuracy=evaluations["test set"].accuracy)
    steps.check()
    save_model(model, model_path)
    if report_path:
        settings = dict(input=input_path, features=", ".join(names), classes=", ".join(map(str, classes)),
                        criterion=model.meta["params"]["criterion"], trees=model.meta["params"]["n_trees"],
                        scaler=model.meta["params"]["scaler"], max_depth=model.meta["params"]["max_depth"],
                        samples_per_tree=model.meta["params"]["max_samples"],
                        split=(f"spatial blocks of {options.block_m:g} m, fractions {options.fractions}"
                               if not (validation_path and test_path) else "separate files"))
        write_report(report_path, title="GroundSieve Random Forest training", evaluations=evaluations,
                     features=names, impurity=model.meta["impurity_importance"], permutation=perm,
                     timings=timings, settings=settings, grid=grid_rows)
    steps.report(1.0)
    return TrainRun(model, evaluations, names, timings, grid_rows)


def classify_file(input_path: str, output_path: str, model_path: str, *, dtm_path: Optional[str] = None,
                  dtm=None, progress=None, is_cancelled=None, log=None):
    """Apply a saved model to ``input_path``; write the classified cloud (the model's ASPRS codes)
    and, optionally, a DTM from the points predicted as ground (class 2)."""
    from .io import CLASS_GROUND, read_cloud
    from .progress import Steps
    from .workflow import DTMOptions, check_outputs, make_dtm, write_outputs
    steps = Steps(progress, is_cancelled)
    log = log or (lambda _msg: None)
    dtm = dtm or DTMOptions()
    check_outputs(input_path, output_path, [dtm_path])
    model = load_model(model_path)
    cloud = read_cloud(input_path)
    names = resolve_features(model.meta.get("preset_features", model.features), cloud, log)
    if names != list(model.features):
        raise InputError(f"{input_path}: this cloud gives the features {names} but the model "
                         f"{model_path} was trained on {list(model.features)} (e.g. colour present in one "
                         "and not the other)")
    X = feature_matrix(cloud, names, steps.sub(0.0, 0.5))
    predicted = model.predict(X).astype(np.uint8)
    steps.report(0.7)
    log(", ".join(f"class {c}: {int((predicted == c).sum()):,}" for c in model.classes))
    rasters = []
    if dtm_path:
        ground = predicted == CLASS_GROUND
        if not ground.any():
            raise InputError(f"{input_path}: no point was predicted as ground (class 2): no DTM can be made")
        grid, values = make_dtm(cloud.x, cloud.y, cloud.z, ground, dtm)
        rasters.append((dtm_path, values, grid))
    write_outputs(cloud, predicted, output_path, rasters, steps)
    steps.report(1.0)
    return cloud, predicted
