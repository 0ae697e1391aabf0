"""Random Forest classification of points (matrone2024, Method 3).

Training uses scikit-learn. The trained forest is then stored as plain arrays, never as a
pickle: a model file is a NumPy ``.npz`` archive (read with ``allow_pickle=False``, so loading
cannot run code) holding each tree's node arrays, the scaler's statistics and a JSON header
(format version, feature names, class codes, training versions, a SHA-256 of every array). The
file is read and written by ``model_file``; the file-to-file training and classification
are in ``core/engine/learning.py``. A model whose checksum, format or features do not match is refused. Prediction runs on those
arrays with a numba kernel (core/learn/_rf_kernels.py), so applying a model needs no scikit-learn
object and gives the same answer on every installation.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Dict, List, Optional, Sequence

import numpy as np

from ..errors import InputError, InvalidParameterError
from ..validate import check_choice


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

    def predict_proba(self, X: np.ndarray, *, steps=None) -> np.ndarray:
        """(n, classes) mean class probabilities of the rows of ``X``. The rows go through the
        forest in blocks of about a tenth of a second, with progress and a cancel check on
        ``steps`` (core/progress.py) between blocks; each row's result does not depend on the blocks."""
        from ..progress import Steps, run_in_row_blocks
        from ._rf_kernels import _forest_proba_kernel
        steps = steps or Steps()
        X = np.ascontiguousarray(self.scaler.transform(np.asarray(X, dtype=np.float32)), dtype=np.float32)
        if X.ndim != 2 or X.shape[1] != len(self.features):
            raise InputError(f"the model expects {len(self.features)} features, got an array of shape {X.shape}")
        self._check_arrays()
        out = np.empty((X.shape[0], self.classes.size), dtype=np.float64)

        def block(lo, hi):
            if not _forest_proba_kernel(X[lo:hi], self.roots, self.left, self.right, self.feature, self.threshold,
                                        self.missing_left, self.value, out[lo:hi]):
                raise InputError("the model's trees are malformed (a node index or feature index out of "
                                 "range, a cycle, or class columns that do not match); train the model again")
        run_in_row_blocks(block, X.shape[0], steps)
        return out

    def _check_arrays(self) -> None:
        """The kinds and dimensions the kernel is compiled for (``model_file.load_model`` checks
        the rest; the kernel checks every index again)."""
        arrays = {"roots": self.roots, "left": self.left, "right": self.right, "feature": self.feature,
                  "threshold": self.threshold, "missing_left": self.missing_left, "value": self.value,
                  "classes": self.classes}
        kinds = {"threshold": "f", "value": "f", "missing_left": "iub"}
        for name, a in arrays.items():
            ndim = 2 if name == "value" else 1
            if (not isinstance(a, np.ndarray) or a.ndim != ndim or a.dtype.fields is not None
                    or a.dtype.kind not in kinds.get(name, "iu")):
                raise InputError(f"the model's array '{name}' is not a {ndim}-D array of "
                                 f"{'numbers' if name in kinds else 'whole numbers'}")
        if self.value.shape[1] != self.classes.size:
            raise InputError(f"the model has {self.classes.size} classes but {self.value.shape[1]} "
                             "probability columns")

    def predict(self, X: np.ndarray, *, steps=None) -> np.ndarray:
        """The most probable class of each row (a tie to the first class); ``steps`` as in
        :meth:`predict_proba`."""
        return self.classes[np.argmax(self.predict_proba(X, steps=steps), axis=1)]


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
    # Block edges on multiples of block_m, as the grids of core/grids/spec.py: the same blocks in every tile.
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
                impurity_importance=[float(v) for v in forest.feature_importances_],
                feature_ranges=feature_ranges(X))
    return from_sklearn(forest, features, forest.classes_, scaler, info)


def feature_ranges(X: np.ndarray) -> list:
    """[1st, 99th] percentile of each feature column (NaN ignored; None when a column has none)."""
    out = []
    for j in range(X.shape[1]):
        column = X[:, j][np.isfinite(X[:, j])]
        out.append([float(v) for v in np.percentile(column, [1, 99])] if column.size else None)
    return out


def out_of_range_features(model, X: np.ndarray, share: float = 0.5) -> list:
    """[(feature, share outside, (low, high), median)] of the features whose values in ``X`` lie
    outside the range the model learnt them in ([1st, 99th] percentile) for at least ``share`` of the
    points, on either side (e.g. the GPS time of the rest of a flight, whose patch trained the model:
    a reviewer's 82 %, 81 % after it and 1 % before, had passed a test of 90 % on one side)."""
    ranges = model.meta.get("feature_ranges")
    found = []
    if not ranges:
        return found
    for j, (name, span) in enumerate(zip(model.features, ranges)):
        if span is None:
            continue
        column = X[:, j][np.isfinite(X[:, j])]
        if not column.size:
            continue
        low, high = span
        part = float(((column < low) | (column > high)).mean())
        if part >= share:
            found.append((name, part, (low, high), float(np.median(column))))
    return found


COLOURS = ("red", "green", "blue")


def colour_depth_factor(model, X: np.ndarray) -> float:
    """The factor that brings the colour columns of ``X`` to the depth the model learnt them in: 257
    for 8-bit colour (every value at most 255) given to a model trained on 16-bit colour (a learnt
    range beyond 255), 1/257 for the other way round, 1 otherwise (the same depth, or no colour, or a
    model that records no ranges). The LAS format stores 16-bit colour, but writers differ (a DJI
    Terra export against LAStools', CloudCompare's): a forest's thresholds read in the other depth
    classify every point alike."""
    ranges = model.meta.get("feature_ranges")
    columns = [j for j, name in enumerate(model.features) if name in COLOURS]
    if not ranges or not columns or any(ranges[j] is None for j in columns):
        return 1.0
    if all(ranges[j][1] <= ranges[j][0] for j in columns):  # (no colour learnt: RGB fields of 0, a code reviewer)
        return 1.0
    values = X[:, columns]
    values = values[np.isfinite(values)]
    if not values.size or values.max() <= 0:
        return 1.0
    learnt_16 = max(ranges[j][1] for j in columns) > 255
    given_16 = values.max() > 255
    if learnt_16 and not given_16:
        return 257.0
    if given_16 and not learnt_16:
        return 1.0 / 257.0
    return 1.0


def constant_features(model, X: np.ndarray) -> list:
    """[(feature, value, (low, high))] of the features that take one value on every point of ``X``
    although the model learnt them over a range (e.g. return_number on a cloud of single returns,
    for a model trained on multi-return LiDAR): they carry no information here."""
    ranges = model.meta.get("feature_ranges")
    found = []
    if not ranges:
        return found
    for j, (name, span) in enumerate(zip(model.features, ranges)):
        if span is None or span[0] >= span[1]:
            continue
        column = X[:, j][np.isfinite(X[:, j])]
        if column.size < 2:
            continue
        if column.min() == column.max():
            found.append((name, float(column[0]), tuple(span)))
    return found


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
    # The learned hybrid ground filter's features (core/learn/hybrid.py): heights above SMRF's surface
    # and multiscale openings; x, y, z only. Its models also run in groundsieve:hybrid.
    "HYBRID": ("above_smrf", "smrf_slope", "smrf_curvature", "above_opening_r2", "above_opening_r6",
               "above_opening_r18"),
}
#: rftrain's default (issue 12): the hybrid filter's features, which need x, y, z only and know where the
#: ground roughly is; the paper's C1-C5 and C5H stay available.
DEFAULT_PRESET = "HYBRID"


def _has_colour(cloud) -> bool:
    las = cloud.las
    if las is None or "red" not in las.point_format.dimension_names:
        return False
    return bool(np.any(las.red) or np.any(las.green) or np.any(las.blue))


def resolve_features(names: Sequence[str], cloud, log=None) -> List[str]:
    """Expand ``radiometry`` for this cloud (RGB when it has colour, else intensity); a feature of a radius
    by its name as the features are computed under (``planarity_r2p0`` is ``planarity_r2``: the first had
    crashed the training with a KeyError, a code reviewer)."""
    from .features import canonical_name
    out: List[str] = []
    for name in names:
        name = canonical_name(name)
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


#: seconds of a GPS week: the gps_time feature is the time within its week (see _attribute)
GPS_WEEK_S = 604800.0
#: adjusted standard GPS time (global encoding bit 0, LAS 1.4's rule for formats 6-10) is GPS time less 1e9 s
ADJUSTED_STANDARD_OFFSET_S = 1.0e9
#: the model metadata of the gps_time feature: the time within its GPS week, adjusted standard time put
#: back on the week first (from 2026-11-26: before, adjusted times were taken modulo a week as they are,
#: so their "week" turned over at 265,600 s, Wednesday 01:46:40 GPS, 11:46 in Sydney, mid-flight)
GPS_TIME_OF_WEEK = "seconds of the GPS week, adjusted standard time put back on the week"
#: ... of the models trained before it: the stored time modulo a week
GPS_TIME_MOD_WEEK = "seconds of the GPS week"
#: how a model's gps_time is computed, by its metadata (a model without it: the raw time in float32)
GPS_TIME_MODES = {GPS_TIME_OF_WEEK: "week", GPS_TIME_MOD_WEEK: "mod"}


def attribute_values(cloud, name: str, gps_time: str = "week") -> np.ndarray:
    """The float32 values of the attribute feature ``name`` (colour, intensity, returns, scan angle in
    degrees, GPS time as :func:`feature_matrix` reads it, or a dimension of the file) of ``cloud``, from
    its ``las`` (its records)."""
    if name in ATTRIBUTE_FEATURES:
        return _attribute(cloud, name, gps_time)
    dims = set(cloud.las.point_format.dimension_names) if cloud.las is not None else set()
    if name not in dims:
        raise InputError(f"{cloud.path}: the feature '{name}' is not in this file (dimensions: "
                         f"{', '.join(sorted(dims))})")
    return np.asarray(cloud.las[name], dtype=np.float32)


def _attribute(cloud, name: str, gps_time: str = "week") -> np.ndarray:
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
    if name == "gps_time" and name in dims and gps_time in ("week", "mod"):
        # adjusted standard GPS time is some 4e8-5e8 s (standard GPS time 1.4e9 s): in float32 (the forest's
        # type) its step is 32 s (128 s), so a flight's times became a few values; within the week
        # (< 604,800 s) the step is at most 0.06 s
        t = np.asarray(las[name], dtype=np.float64)
        if gps_time == "week" and _adjusted_standard(las):
            t = t + ADJUSTED_STANDARD_OFFSET_S
        return np.mod(t, GPS_WEEK_S).astype(np.float32)
    if name in dims:
        return np.asarray(las[name], dtype=np.float32)
    raise InputError(f"{cloud.path}: the feature '{name}' is not in this file (dimensions: "
                     f"{', '.join(sorted(dims))})")


def _adjusted_standard(las) -> bool:
    """Whether the file's GPS times are adjusted standard GPS time (global encoding bit 0)."""
    try:
        return bool(int(las.header.global_encoding.value) & 1)
    except AttributeError:
        return False


def feature_matrix(cloud, names: Sequence[str], steps=None, *, gps_time: str = "week") -> np.ndarray:
    """(n, len(names)) float32 matrix of the named features of ``cloud``. Attributes are read from
    the file; geometric features (``<feature>_r<radius>``) are taken from the file's extra bytes when
    present (e.g. written by groundsieve:features) and computed otherwise. ``gps_time``: "week", the
    GPS time as seconds within its GPS week (adjusted standard time put back on the week first);
    "mod", the stored time modulo a week, and "raw", the time as read: for models trained before
    (GPS_TIME_MODES)."""
    from ..progress import Steps
    from .features import FeatureSpec, compute_features, parse_feature_name
    from .hybrid import GRID_FEATURES, hybrid_features, opening_radius
    steps = steps or Steps()
    columns: Dict[str, np.ndarray] = {}
    dims = set(cloud.las.point_format.dimension_names) if cloud.las is not None else set()
    to_compute = []
    grid_names = [n for n in names if n in GRID_FEATURES or opening_radius(n) is not None]
    if grid_names:  # the hybrid filter's features (1 m grid, as its shipped model)
        grid_values = hybrid_features(cloud.xyz, grid_names, steps=steps.sub(0.0, 0.5))
        columns.update({n: grid_values[:, j] for j, n in enumerate(grid_names)})
    for name in names:
        if name in columns:
            continue
        if name in ATTRIBUTE_FEATURES or name in dims:  # (read from the file, as a tile reads them)
            columns[name] = attribute_values(cloud, name, gps_time)
        else:
            try:
                parse_feature_name(name)
            except InvalidParameterError as err:  # (a model's dimension missing from a file: "'amp' is not a feature name")
                raise InputError(f"{cloud.path}: the feature '{name}' is neither a dimension of this file ("
                                 f"{', '.join(sorted(dims)) or 'x, y, z only'}) nor computed: {err}") from None
            to_compute.append(name)
    if to_compute:
        computed = compute_features(cloud.xyz, FeatureSpec.from_names(to_compute), steps=steps)
        columns.update(computed)
    steps.report(1.0)
    return np.column_stack([columns[name] for name in names]).astype(np.float32)


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
