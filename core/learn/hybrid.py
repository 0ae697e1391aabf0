"""The learned hybrid ground filter: features that know where the ground roughly is, and a
Random Forest trained on labelled clouds that turns them into a ground mask.

Per-point eigen features (matrone2024 Method 3) cannot tell a flat roof from the ground: they do
not know where the ground is. The features here do. On a grid of ``cell_size_m`` (1 m by
default, as SMRF), from the lowest point of each cell:

==========================  ==================================================================
feature                     value at the point
==========================  ==================================================================
``above_smrf``              z minus SMRF's provisional ground surface (Pingel et al. 2013,
                            its single-set defaults), bilinear at the point
``smrf_slope``              gradient magnitude (rise/run) of that surface
``smrf_curvature``          its Laplacian (1/m): negative on ridges, positive in hollows
``above_opening_r<R>``      z minus the minimum surface (low outliers removed as SMRF does,
                            empty cells inpainted) opened with a disk of radius R m: the height
                            above the ground as seen by a window of that size; several R give
                            the size of the object the point sits on
``above_cell_min``          z minus the lowest z of the point's own cell
``cell_range``              highest minus lowest z of the point's own cell
``column_rank``             (z - lowest) / (highest - lowest) in the cell (0 when flat)
``above_ptd_ground``        z minus the surface of PTD's ground points (core/filters/ptd.py with
                            the fixed settings :data:`PTD_SETTINGS`): the lowest PTD-ground point
                            of each cell, empty cells inpainted harmonically, bilinear at the point
``ptd_ground_slope``        gradient magnitude (rise/run) of that surface
==========================  ==================================================================

The PTD features cost a PTD run (the accurate model's filter takes about 2.4x the fast one's time
on 10 M points, docs/BENCHMARKS.md): they are computed only when a model asks for them (the
shipped :data:`PTD_MODEL`, not the default).

Every length is in metres, not in points, so the features mean the same on a 3 m-spacing
airborne survey and on a 3 cm UAV cloud. Names made by ``core/learn/features.py``
(``height_above_min_r2p5``, ``planarity_r0p6``, ...) are accepted too and computed there.

The classifier is the project's Random Forest (``core/learn/rf.py``), stored in the safe model
file of ``core/learn/model_file.py``; the shipped model (:data:`DEFAULT_MODEL`) is trained by
``bench/hybrid_train.py`` on the 8 shared ISPRS samples (its leave-one-sample-out figures are in
docs/BENCHMARKS.md). A model trained on other features is refused with the file's name.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..errors import InputError, InvalidParameterError
from ..progress import Steps
from ..validate import _require, check_number, validate_xyz

#: The shipped model (trained by bench/hybrid_train.py; see docs/BENCHMARKS.md).
DEFAULT_MODEL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "models", "hybrid_isprs.npz")

#: The second shipped model: the default features and the two PTD features (slower, more accurate on
#: the ISPRS samples; docs/BENCHMARKS.md "Learned hybrid filter").
PTD_MODEL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "models", "hybrid_isprs_ptd.npz")

#: The shipped models by name (what a user may give instead of a file).
SHIPPED_MODELS = {"fast": DEFAULT_MODEL, "accurate": PTD_MODEL}

#: ASPRS class of the ground, the class whose probability the filter thresholds.
GROUND_CLASS = 2

#: Model metadata key holding the grid cell (m) the features were computed with.
CELL_KEY = "hybrid_cell_size_m"

#: Features computed from grids here (the opening radii are part of their names).
PTD_FEATURES = ("above_ptd_ground", "ptd_ground_slope")
GRID_FEATURES = ("above_smrf", "smrf_slope", "smrf_curvature", "above_cell_min", "cell_range",
                 "column_rank") + PTD_FEATURES

#: PTD's settings for the PTD features, FIXED here and not the PTD filter's defaults: three of those
#: defaults (seed cell 30 m, offset 0.2 m, mirror off) were chosen on the ISPRS samples the shipped
#: models are trained and scored on, so features made with them would leak those samples into the
#: leave-one-sample-out figures. These values are fixed from outside the ISPRS data (lasR's ``ptd``:
#: 50 m seed cell ("res"), 30 degrees, 1 m, offset 0.05 m; mirror off as Axelsson's default).
#: Changing them changes the features: a model trained with them would have to be retrained.
PTD_SETTINGS = dict(seed_cell_m=50.0, max_angle_deg=30.0, max_distance_m=1.0, offset_m=0.05, mirror=False,
                    low_outlier_support=0.4, low_outlier_retry=False)
#: PTD settings added after models were trained: the value their features were computed with
#: (a model's stored settings lack the key), so that those models still load.
_PTD_SETTINGS_BEFORE = dict(low_outlier_support=0.4, low_outlier_retry=False)
_OPENING_RE = re.compile(r"^above_opening_r(?P<int>[0-9]+)(?:p(?P<frac>[0-9]+))?$")

#: The default feature set: heights above ground surfaces and their shape only, nothing that
#: depends on the point density (the column features added nothing on the ISPRS samples and would
#: not transfer to 100x denser UAV clouds; see docs/BENCHMARKS.md "Learned hybrid filter").
DEFAULT_FEATURES = ("above_smrf", "smrf_slope", "smrf_curvature", "above_opening_r2", "above_opening_r6",
                    "above_opening_r18")


def opening_radius(name: str) -> Optional[float]:
    """Radius (m) of an ``above_opening_r<R>`` name, else None."""
    match = _OPENING_RE.match(name)
    if not match:
        return None
    return float(match.group("int") + "." + (match.group("frac") or "0"))


def unknown_features(names: Sequence[str]) -> List[str]:
    """The names that neither this module nor core/learn/features.py computes."""
    from .features import parse_feature_name
    bad = []
    for name in names:
        if name in GRID_FEATURES or opening_radius(name) is not None:
            continue
        try:
            parse_feature_name(name)
        except InvalidParameterError:
            bad.append(name)
    return bad


def _slope(surface: np.ndarray, cell: float) -> Tuple[np.ndarray, np.ndarray]:
    """Gradient magnitude and Laplacian of a grid of cell ``cell``."""
    if min(surface.shape) < 2:
        zero = np.zeros_like(surface)
        return zero, zero
    gy, gx = np.gradient(surface, cell)
    gyy = np.gradient(gy, cell, axis=0)
    gxx = np.gradient(gx, cell, axis=1)
    return np.sqrt(gx * gx + gy * gy), gxx + gyy


#: Areas whose points are at least this far apart (m, and at least the features' reach) get their
#: features computed apart: one grid over several far-apart sites (training samples merged into one
#: file, a survey with a stray point) would be mostly empty cells inpainted across the gap.
ISLAND_GAP_M = 64.0


def islands(x: np.ndarray, y: np.ndarray, block_m: float) -> np.ndarray:
    """Label (int64 per point, 0..k-1) of the group of ``block_m`` blocks the point is in: blocks
    holding points, joined when they touch (8 neighbours). Points of two labels are at least
    ``block_m`` apart."""
    if len(x) == 0:
        return np.zeros(0, dtype=np.int64)
    x0, y0 = float(x.min()), float(y.min())
    nx = int((float(x.max()) - x0) // block_m) + 1
    ny = int((float(y.max()) - y0) // block_m) + 1
    if nx * ny <= 4_000_000:  # a coarse occupancy grid (the usual case: one pass, no sort)
        from scipy.ndimage import label as _label
        from ._hybrid_kernels import _block_label, _block_occupancy
        occupied = np.zeros((ny, nx), dtype=np.bool_)
        _block_occupancy(x, y, x0, y0, float(block_m), nx, ny, occupied)
        grid_label, count = _label(occupied, structure=np.ones((3, 3), dtype=bool))
        out = np.zeros(len(x), dtype=np.int64)
        if count > 1:
            _block_label(x, y, x0, y0, float(block_m), nx, ny, grid_label.astype(np.int64) - 1, out)
        return out
    bx = ((x - x0) // block_m).astype(np.int64)
    by = ((y - y0) // block_m).astype(np.int64)
    # Points spread over a huge extent: the occupied blocks only, joined by union-find.
    keys, inverse = np.unique(by * nx + bx, return_inverse=True)
    index = {int(k): j for j, k in enumerate(keys)}
    parent = list(range(len(keys)))

    def root(j):
        while parent[j] != j:
            parent[j] = parent[parent[j]]
            j = parent[j]
        return j
    for k, j in index.items():
        a, b = k % nx, k // nx
        for da in (-1, 0, 1):
            for db in (-1, 0, 1):
                if 0 <= a + da < nx:
                    other = index.get((b + db) * nx + a + da)
                    if other is not None:
                        ra, rb = root(j), root(other)
                        if ra != rb:
                            parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([root(j) for j in range(len(keys))])
    _u, lab = np.unique(roots, return_inverse=True)
    return lab[np.asarray(inverse).reshape(-1)].astype(np.int64)


def hybrid_features(xyz: np.ndarray, names: Sequence[str], *, cell_size_m: float = 1.0,
                    steps: Optional[Steps] = None) -> np.ndarray:
    """(n, len(names)) float32 matrix of the named features of the points ``xyz`` (n, 3).

    Groups of points farther apart than :data:`ISLAND_GAP_M` (or the features' reach) are
    computed apart, each on its own grid: the values are then those of each site alone."""
    steps = steps or Steps()
    if not (isinstance(cell_size_m, (int, float)) and math.isfinite(cell_size_m) and cell_size_m > 0):
        raise InvalidParameterError(f"cell_size_m must be > 0 (got {cell_size_m!r})")
    xyz = validate_xyz(xyz)
    reach = Hybrid.reach_of(list(names), cell_size_m) if not unknown_features(names) else 0.0
    label = islands(xyz[:, 0], xyz[:, 1], max(ISLAND_GAP_M, reach))
    steps.check()
    count = int(label.max()) + 1 if len(label) else 1
    if count == 1:
        return _hybrid_features(xyz, names, cell_size_m=cell_size_m, steps=steps)
    out = np.empty((len(xyz), len(names)), dtype=np.float32)
    done = 0
    for k in range(count):
        idx = np.flatnonzero(label == k)
        out[idx] = _hybrid_features(xyz[idx], names, cell_size_m=cell_size_m,
                                    steps=steps.sub(done / len(xyz), (done + len(idx)) / len(xyz)))
        done += len(idx)
    steps.report(1.0)
    return out


def _hybrid_features(xyz: np.ndarray, names: Sequence[str], *, cell_size_m: float = 1.0,
                     steps: Optional[Steps] = None) -> np.ndarray:
    from ..filters.smrf import SMRF
    from ..grids.morphology import opening
    from ..grids.rasterize import cell_min
    from ..grids.spec import GridSpec
    from ..progress import run_cancellable, run_in_row_blocks
    from ._hybrid_kernels import _point_features_into
    steps = steps or Steps()
    names = list(names)
    bad = unknown_features(names)
    if bad:
        raise InvalidParameterError(f"unknown feature(s) {', '.join(bad)}: the hybrid filter computes "
                                    f"{', '.join(GRID_FEATURES)}, above_opening_r<R> and the point "
                                    "features of groundsieve:features")
    if not (isinstance(cell_size_m, (int, float)) and math.isfinite(cell_size_m) and cell_size_m > 0):
        raise InvalidParameterError(f"cell_size_m must be > 0 (got {cell_size_m!r})")
    xyz = validate_xyz(xyz)
    x, y, z = (np.ascontiguousarray(xyz[:, i]) for i in range(3))
    cell = float(cell_size_m)
    radii = sorted({opening_radius(n) for n in names if opening_radius(n) is not None})
    uses_smrf = any(n in ("above_smrf", "smrf_slope", "smrf_curvature") for n in names)
    smrf = SMRF(cell_size_m=cell)
    minimum = None
    if uses_smrf or radii:
        # SMRF's steps 1-2 (its defaults: low outliers at slope 5 removed and refilled) once: the
        # surface of SMRF and the openings below both start from this cleaned minimum surface.
        minimum = smrf.minimum_surface(xyz, steps.sub(0.0, 0.1))
        grid, zmin_raw = minimum.grid, minimum.raw
    else:
        grid = GridSpec.covering(x, y, cell, what="hybrid feature grid")
        zmin_raw = cell_min(x, y, z, grid)
    surfaces: List[np.ndarray] = []
    modes: List[int] = []
    column: Dict[str, int] = {}

    def add(name, surface, above):
        column[name] = len(surfaces)
        surfaces.append(np.ascontiguousarray(surface, dtype=np.float64))
        modes.append(1 if above else 0)

    if uses_smrf:
        _grid, zpro, _objects = smrf.surface(xyz, steps.sub(0.1, 0.4), minimum)
        slope, curvature = _slope(zpro, cell)
        add("above_smrf", zpro, True)
        add("smrf_slope", slope, False)
        add("smrf_curvature", curvature, False)
    steps.report(0.4)
    uses_ptd = any(n in PTD_FEATURES for n in names)
    openings_end = 0.5 if uses_ptd else 0.7
    if radii:
        # The minimum surface as SMRF cleans it: empty cells inpainted, low outliers removed.
        for k, radius_m in enumerate(radii):
            # In a worker thread: a cancel is seen at once on a big grid (a sparse cloud's).
            share = steps.sub(0.4 + (openings_end - 0.4) * k / len(radii),
                              0.4 + (openings_end - 0.4) * (k + 1) / len(radii))
            opened = run_cancellable(opening, minimum.zmin, max(1, int(round(radius_m / cell))), steps=share)
            add(next(n for n in names if opening_radius(n) == radius_m), opened, True)
    if uses_ptd:
        ptd_surface = _ptd_ground_surface(x, y, z, grid, steps.sub(openings_end, 0.7))
        add("above_ptd_ground", ptd_surface, True)
        add("ptd_ground_slope", _slope(ptd_surface, cell)[0], False)
    if not surfaces:  # the kernel wants at least one grid
        add("", zmin_raw, False)
    # The cell's highest point only for the column features (else the kernel's columns for them are unused).
    wants_column = any(n in ("above_cell_min", "cell_range", "column_rank") for n in names)
    zmax_raw = -cell_min(x, y, -z, grid, steps.sub(0.7, 0.72)) if wants_column else zmin_raw
    k = len(surfaces)
    column.update(above_cell_min=k, cell_range=k + 1, column_rank=k + 2)
    # The kernel's value j of a point goes to the result's column of its name (-1: not asked).
    target = np.full(k + 3, -1, dtype=np.int64)
    for j, name in enumerate(names):
        if name in column:
            target[column[name]] = j
    result = np.empty((x.shape[0], len(names)), dtype=np.float32)
    stacked = np.stack(surfaces)
    modes_array = np.asarray(modes, dtype=np.int64)

    def block(lo, hi):
        _point_features_into(x[lo:hi], y[lo:hi], z[lo:hi], stacked, modes_array, zmin_raw, zmax_raw,
                             grid.x0, grid.top, grid.cell, target, result[lo:hi])
    run_in_row_blocks(block, x.shape[0], steps.sub(0.72, 0.8))
    for j, name in enumerate(names):  # a name given twice: the kernel wrote its last column only
        if name in column and target[column[name]] != j:
            result[:, j] = result[:, target[column[name]]]
    point_names = [n for n in names if n not in column]
    if point_names:
        from .features import FeatureSpec, compute_features
        computed = compute_features(xyz, FeatureSpec.from_names(point_names), steps=steps.sub(0.8, 1.0))
        for j, name in enumerate(names):
            if name in computed:
                result[:, j] = computed[name]
    steps.report(1.0)
    return result


def _ptd_ground_surface(x, y, z, grid, steps: Steps) -> np.ndarray:
    """The surface of PTD's ground points (:data:`PTD_SETTINGS`) on ``grid``: the lowest ground
    point of each cell, empty cells inpainted harmonically. With fewer than 3 ground points (a
    scrap of a cloud), the lowest point of every cell instead."""
    from ..filters.ptd import PTD
    from ..grids.inpaint import inpaint_harmonic
    from ..grids.rasterize import cell_min
    from ..progress import run_cancellable
    ground = PTD(**PTD_SETTINGS)(np.column_stack([x, y, z]), steps.sub(0.0, 0.9))
    if np.count_nonzero(ground) < 3:
        ground = np.ones(len(x), dtype=bool)
    lowest = cell_min(x[ground], y[ground], z[ground], grid, steps.sub(0.9, 0.95))
    # In a worker thread: a cancel is seen at once however many holes the grid has.
    return run_cancellable(inpaint_harmonic, lowest, steps=steps.sub(0.95, 1.0))


# -- the model ------------------------------------------------------------------------------------

_MODELS: Dict[Tuple[str, float, int], object] = {}


def load_hybrid_model(path: Optional[str] = None):
    """The model file at ``path`` (the shipped model when empty), checked for the hybrid filter:
    features it can compute and a ground class (2). Cached per path, modification time and size."""
    from .model_file import load_model
    path = os.fspath(path) if path else DEFAULT_MODEL
    if not os.path.isfile(path):
        if path in SHIPPED_MODELS.values():
            raise InputError(f"{path}: the shipped hybrid model is missing from this installation; "
                             "reinstall the plugin or give a model file")
        raise InputError(f"{path}: no such model file")
    stat = os.stat(path)
    key = (os.path.abspath(path), stat.st_mtime, stat.st_size)
    if key in _MODELS:
        return _MODELS[key]
    model = load_model(path)
    bad = unknown_features(model.features)
    if bad:
        raise InputError(f"{path}: this model was trained on features the hybrid filter does not compute "
                         f"({', '.join(bad)}); use it with groundsieve:rfclassify (in Python without QGIS: "
                         f"core.engine.learning.classify_file, docs/API.md), or train a model on the "
                         f"hybrid features")
    if GROUND_CLASS not in [int(c) for c in model.classes]:
        raise InputError(f"{path}: this model has no ground class (2) (its classes: "
                         f"{', '.join(str(int(c)) for c in model.classes)}); the hybrid filter needs one")
    settings = model.meta.get("hybrid_ptd_settings")
    if isinstance(settings, dict):
        settings = {**_PTD_SETTINGS_BEFORE, **settings}
    if settings is not None and any(f in PTD_FEATURES for f in model.features) and settings != PTD_SETTINGS:
        raise InputError(f"{path}: this model's PTD features were computed with PTD settings {settings}, "
                         f"this version computes them with {PTD_SETTINGS}; retrain the model")
    cell = model.meta.get(CELL_KEY, 1.0)
    if not (isinstance(cell, (int, float)) and math.isfinite(cell) and cell > 0):
        raise InputError(f"{path}: the model's feature cell size {cell!r} is not a number > 0")
    _MODELS.clear()  # keep one model in memory
    _MODELS[key] = model
    return model


@dataclass(frozen=True)
class HybridResult:
    ground: np.ndarray          #: bool per point
    probability: np.ndarray     #: float32 probability of ground per point


@dataclass(frozen=True)
class Hybrid:
    """The learned hybrid ground filter. ``model_path`` empty = the shipped model named by
    ``shipped_model``: "fast" (:data:`DEFAULT_MODEL`, SMRF's surfaces and openings) or "accurate"
    (:data:`PTD_MODEL`, the same and PTD's ground surface: about 2.4x the filtering time, better on the ISPRS
    samples). A point is ground when the model gives it a ground probability of at least
    ``ground_probability``."""
    model_path: str = ""
    ground_probability: float = 0.5
    shipped_model: str = "fast"
    _model: object = field(default=None, init=False, repr=False, compare=False)

    name = "hybrid"

    def __post_init__(self):
        check_number(self, "ground_probability")
        _require(0.0 < self.ground_probability < 1.0,
                 f"ground_probability must be between 0 and 1 (got {self.ground_probability})")
        if not isinstance(self.model_path, (str, os.PathLike)):
            raise InvalidParameterError(f"model_path must be a file path or empty (got {self.model_path!r})")
        _require(self.shipped_model in SHIPPED_MODELS,
                 f"shipped_model must be one of {', '.join(SHIPPED_MODELS)} (got {self.shipped_model!r})")
        object.__setattr__(self, "_model", load_hybrid_model(self.model_path or SHIPPED_MODELS[self.shipped_model]))

    @property
    def model(self):
        return self._model

    @property
    def features(self) -> List[str]:
        return list(self._model.features)

    @property
    def cell_size_m(self) -> float:
        return float(self._model.meta.get(CELL_KEY, 1.0))

    def describe(self) -> str:
        """The run's log line on what classifies (the engine logs it before the work)."""
        model = self.model_path or f"the shipped {self.shipped_model} model"
        return (f"{type(self).__name__}: {model} ({len(self.features)} features: {', '.join(self.features)}); "
                f"ground at a probability of {self.ground_probability:g} or more")

    @property
    def extra_bytes_per_point(self) -> Optional[int]:
        """Memory a point costs a whole run beyond a ground filter's (core/engine/tiles.whole_run_bytes):
        120 B with PTD's features (the accurate model; measured 40 B more than the fast model at 250
        points/m², 117 B at 1.2 points/m², docs/BENCHMARKS.md); None (not measured) for a model with
        point features."""
        if any(name not in GRID_FEATURES and name not in PTD_FEATURES and opening_radius(name) is None
               for name in self.features):
            return None
        return 120 if any(name in PTD_FEATURES for name in self.features) else 0

    @property
    def reach_m(self) -> float:
        """How far (m) points influence a point's class, for tiled runs (core/engine/tiles.py):
        the reach of SMRF's surface (its defaults) when a feature uses it, two radii of the largest
        opening (erosion then dilation) plus two cells for the bilinear value and the slope, and
        the largest radius of a point feature. As for SMRF, the harmonic inpainting of empty cells
        reaches further in principle; a tiled run agrees with the whole run on 99.9 % of the points
        or more (tests/core/test_hybrid.py)."""
        return self.reach_of(self.features, self.cell_size_m)

    @staticmethod
    def reach_of(features: Sequence[str], cell: float) -> float:
        """The reach (m) of the hybrid features ``features`` on a grid of ``cell`` m."""
        from ..filters.ptd import PTD
        from ..filters.smrf import SMRF
        from .features import parse_feature_name
        reach = 2.0 * cell
        for name in features:
            radius = opening_radius(name)
            if name in ("above_smrf", "smrf_slope", "smrf_curvature"):
                reach = max(reach, SMRF(cell_size_m=cell).reach_m)
            elif name in PTD_FEATURES:
                # PTD's reach (two seed cells) plus two cells for the bilinear value and the slope.
                reach = max(reach, PTD(**PTD_SETTINGS).reach_m + 2.0 * cell)
            elif radius is not None:
                reach = max(reach, 2.0 * radius + 2.0 * cell)
            elif name not in GRID_FEATURES:
                reach = max(reach, parse_feature_name(name)[1] + cell)
        return reach

    def __call__(self, xyz: np.ndarray, steps: Steps | None = None) -> np.ndarray:
        """Boolean ground mask of the points ``xyz`` (n, 3)."""
        return self.run(xyz, steps).ground

    def run(self, xyz: np.ndarray, steps: Steps | None = None) -> HybridResult:
        steps = steps or Steps()
        # The shares of the run (10 M points): the features 40 % with the fast model, 70 % with PTD's.
        split = 0.7 if any(name in PTD_FEATURES for name in self.features) else 0.4
        X = hybrid_features(xyz, self.features, cell_size_m=self.cell_size_m, steps=steps.sub(0.0, split))
        column = [int(c) for c in self._model.classes].index(GROUND_CLASS)
        proba = self._model.predict_proba(X, steps=steps.sub(split, 1.0))[:, column].astype(np.float32)
        steps.report(1.0)
        return HybridResult(proba >= self.ground_probability, proba)
