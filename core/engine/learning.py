"""matrone2024 Method 3 from file to file: train a Random Forest on a labelled cloud (model file,
HTML/CSV report) and classify a cloud with a saved model (classified cloud, optional DTM)."""
from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from ..errors import InputError
from ..io import CLASS_GROUND, atomic_path
from ..progress import WARNING_PREFIX
from ..learn.hybrid import GROUND_CLASS, Hybrid, hybrid_features
from ..learn.model_file import MODEL_EXTENSION, load_model, save_model
from .workflow import NEEDED
from ..learn.rf import (CRITERIA, DEFAULT_PRESET, PRESETS, SCALERS, ForestParams, Model, feature_matrix,
                        permutation_importance, resolve_features, spatial_split, train_forest)


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
    #: train ground (2) against every other class learnt (as 1): a ground model, which with features of
    #: x, y, z runs in the hybrid filter too. None: when the features are the HYBRID preset's
    #: and no classes are named (the default)
    ground_vs_rest: Optional[bool] = None

    def ground_model(self) -> bool:
        if self.ground_vs_rest is not None:
            return bool(self.ground_vs_rest)
        return self.classes is None and tuple(self.features) == tuple(PRESETS["HYBRID"])


@dataclass
class TrainRun:
    model: Model
    evaluations: dict
    features: List[str]
    timings: dict
    grid: Optional[List[dict]] = None
    warnings: List[str] = None  #: what the log and the report warn about (possible label leakage)


def _without_withheld(cloud, log):
    """The cloud without its withheld points ("not to be included in processing"): they are
    neither learnt from, nor evaluated, nor in any point's neighbourhood."""
    withheld = cloud.withheld_mask
    if not withheld.any():
        return cloud
    log(f"{cloud.path}: {int(withheld.sum()):,} withheld points left out of training.")
    if withheld.all():
        raise InputError(f"{cloud.path}: every point is withheld: nothing to learn from")
    return cloud.subset(~withheld)


def _labelled(cloud, classes, log):
    labels = cloud.classification
    if classes is None:
        present = np.unique(labels)
        classes = tuple(int(c) for c in present if c not in EXCLUDED_BY_DEFAULT)
        if len(classes) < 2:
            from ..learn.report import ASPRS_NAMES
            never = ", ".join(f"{int(c)} = {ASPRS_NAMES[int(c)]}" for c in present if c in EXCLUDED_BY_DEFAULT)
            held = (f"only class {classes[0]}" + (f" besides classes never learnt ({never})" if never else "")
                    if classes else f"only classes never learnt ({never})")
            raise InputError(f"{cloud.path}: at least two classes are needed to train, and the file holds {held}; "
                             "classify a training area first (ground 2 and the others)")
        log(f"Learning the classes present in {cloud.path}: {', '.join(map(str, classes))}.")
    missing = [c for c in classes if not np.any(labels == c)]
    if missing:
        raise InputError(f"{cloud.path}: no point of class {', '.join(map(str, missing))} to learn from")
    if len(classes) < 2:
        raise InputError(f"{cloud.path}: at least two classes are needed to train (got {list(classes)})")
    return np.isin(labels, classes), tuple(classes)


#: Share of the training points one feature alone must get right to be named as a possible leak.
LEAK_ACCURACY = 0.995


def leaking_features(X: np.ndarray, y: np.ndarray, names, *, max_points: int = 50_000, seed: int = 0) -> list:
    """Features that alone predict the labels almost perfectly (at least ``LEAK_ACCURACY`` of at
    most ``max_points`` training points): ``[(name, accuracy), ...]``. Each feature is given a
    shallow one-feature tree (at most 4 leaves a class), which finds a label copied into an
    attribute (intensity equal to the class code) or any monotone code of it."""
    from sklearn.tree import DecisionTreeClassifier
    if len(y) == 0:
        return []
    if len(y) > max_points:
        pick = np.random.default_rng(seed).choice(len(y), max_points, replace=False)
        X, y = X[pick], y[pick]
    n_classes = len(np.unique(y))
    if n_classes < 2:
        return []
    found = []
    for j, name in enumerate(names):
        column = X[:, j:j + 1]
        tree = DecisionTreeClassifier(max_leaf_nodes=4 * n_classes, random_state=seed).fit(column, y)
        accuracy = float((tree.predict(column) == y).mean())
        if accuracy >= LEAK_ACCURACY:
            found.append((name, accuracy))
    return found


def train_file(input_path: str, model_path: str, report_path: Optional[str] = None,
               options: TrainOptions = TrainOptions(), *, validation_path: Optional[str] = None,
               test_path: Optional[str] = None, progress=None, is_cancelled=None, log=None) -> TrainRun:
    """Train on the labelled cloud ``input_path`` (its classification is the label) and write the
    model and the report. Validation and test sets are spatial blocks of the input, or the
    separate files ``validation_path`` / ``test_path`` when given."""
    from ..io import check_output_path, read_cloud
    from ..metrics import class_report
    from ..progress import Steps
    from .tiles import refuse_in_a_workers_import
    refuse_in_a_workers_import()
    steps = Steps(progress, is_cancelled)
    log = log or (lambda _msg: None)
    check_output_path(model_path, inputs=[input_path, validation_path, test_path], extensions=(MODEL_EXTENSION,),
                      what="model file")
    if report_path:
        check_output_path(report_path, inputs=[input_path, model_path], extensions=(".html", ".htm"),
                          what="report")
    timings = {}
    t0 = time.perf_counter()
    cloud = _without_withheld(read_cloud(input_path), log)
    from ..raster.crs import unit_warning
    # (a training converts nothing: "a preset's lengths are converted" had stood before C5's radii read as 0.6 ft,
    # all their features empty four lines on: a reviewer)
    warning = unit_warning(input_path, cloud.crs_wkt, "the features' radii and the blocks' size",
                           converted="nothing is converted: the paper's spheres of 0.4-0.6 m (C4, C5) are 0.4-0.6 "
                                     "{unit} here; name larger radii in a custom list (e.g. planarity_r2) if they "
                                     "hold too few points.")
    if warning and cloud.crs_wkt:
        log(WARNING_PREFIX + warning)
    keep, classes = _labelled(cloud, options.classes, log)
    target, learnt = (lambda labels: labels), classes  # noqa: E731
    if options.ground_model():
        if CLASS_GROUND not in classes:
            raise InputError(f"{input_path}: a ground model learns ground (class 2) against the other classes, "
                             f"and the file has no point of class 2 among those learnt ({', '.join(map(str, classes))})")
        others = [c for c in classes if c != CLASS_GROUND]
        if others != [1]:
            from ..learn.hybrid import unknown_features
            where = ("it runs in the learned hybrid filter too" if not unknown_features(
                resolve_features(options.features, cloud)) else "with features of x, y, z only (the HYBRID preset) it "
                "would run in the learned hybrid filter too; rfclassify runs these on files and surveys")
            # (a reviewer's C5 ground model was told it ran in both, and both refused it)
            log(f"Learning ground (2) against the other classes ({', '.join(map(str, others))}, learnt as 1): a "
                f"ground model ({where}); name the classes to learn them apart.")
        target = lambda labels: np.where(labels == CLASS_GROUND, CLASS_GROUND, 1).astype(labels.dtype)  # noqa: E731
        learnt = (1, CLASS_GROUND)
    names = resolve_features(options.features, cloud, log)
    where = [n for n in ("gps_time", "scan_angle") if n in names]
    if where:  # (said before the training: a reviewer learnt it only from the classified flight)
        log(f"{WARNING_PREFIX}the features {' and '.join(where)} stand for where the patch lies in the flight (when "
            "and from where in its strip it was measured), not for what a point is: on the rest of the flight they "
            "lie outside what the model learns, and mislead it (the paper's C3, with both, was its worst). Prefer "
            "a model without them unless the patch spans the flight.")
    X = feature_matrix(cloud, names, steps.sub(0.0, 0.3))
    y = target(cloud.classification)
    timings["features (training cloud)"] = time.perf_counter() - t0
    sets = {}
    if validation_path or test_path:
        sets["train"] = (X[keep], y[keep])
        for label, path in (("validation", validation_path), ("test", test_path)):
            if path:
                t1 = time.perf_counter()
                other = _without_withheld(read_cloud(path), log)
                other_keep = np.isin(other.classification, classes)
                other_names = resolve_features(options.features, other, log)
                if other_names != names:
                    raise InputError(f"{path}: gives the features {other_names}, the training cloud {names}")
                Xo = feature_matrix(other, names)
                sets[label] = (Xo[other_keep], target(other.classification[other_keep]))
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
    notes = []
    made = None
    if not (validation_path or test_path):  # the blocks' shares as made, against the fractions planned
        total = sum(len(v[0]) for v in sets.values())
        made = tuple(len(sets[label][0]) / total for label in ("train", "validation", "test"))
        short = [(label, got, planned) for label, got, planned in zip(("training", "validation", "test"), made,
                                                                      options.fractions) if got < 0.5 * planned]
        if short:  # (a reviewer's 60 m patch in 25 m blocks: 49/8/43 % for 60/20/20)
            notes.append(f"{WARNING_PREFIX}the spatial split made " + ", ".join(
                f"the {label} set {100 * got:.0f} % of the points (planned {100 * planned:.0f} %)"
                for label, got, planned in short) + f": the patch is few blocks of {options.block_m:g} m across; "
                "smaller blocks split it closer to the plan, or give the sets as files.")
            log(notes[-1])
    # The paper split its data "to have the presence of all the classes in each dataset"; random
    # blocks may miss a rare class (a power line in a few blocks): say so.
    present = {label: set(np.unique(ys).tolist()) for label, (_Xs, ys) in sets.items()}
    every = set().union(*present.values())
    for label, have in present.items():
        missing = sorted(every - have)
        if missing:
            effect = ("the model cannot learn " + ("it" if len(missing) == 1 else "them")) if label == "train" else \
                f"the {label} scores say nothing of " + ("it" if len(missing) == 1 else "them")
            notes.append(f"{WARNING_PREFIX}the {label} set holds no point of class {', '.join(map(str, missing))}: "
                         f"{effect}. Use smaller blocks (now {options.block_m:g} m), another seed, or give the "
                         "sets as files.")
            log(notes[-1])
    Xt = sets["train"][0]
    for note in _feature_notes(Xt, names, cloud.crs_wkt):
        notes.append(note)
        log(note)
    for name, accuracy in leaking_features(*sets["train"], names, seed=options.params.seed):
        notes.append(f"{WARNING_PREFIX}the feature '{name}' alone predicts {accuracy:.1%} of the training labels. "
                     "Check that it does not carry the label itself (e.g. a converted reference cloud whose "
                     "intensity is the class code): the scores below would then mean nothing.")
        log(notes[-1])
    steps.report(0.35)
    from ..raster.crs import horizontal_unit
    meta = dict(groundsieve_trained_from=os.path.basename(input_path), preset_features=list(options.features))
    if "gps_time" in names:
        from ..learn.rf import GPS_TIME_OF_WEEK
        meta["gps_time"] = GPS_TIME_OF_WEEK
    unit = horizontal_unit(cloud.crs_wkt)
    if unit:  # the unit its lengths (radii, heights) were read in
        meta["crs_unit"] = unit
    if radius_features(names):  # what they count within their spheres depends on it
        from .tiles import points_density  # (the labelled points', as those classified are measured)
        meta["points_per_unit2"] = round(points_density(cloud.x[keep], cloud.y[keep]), 3)
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
        report = class_report(yv, model.predict(Xv), learnt)
        score = report.weighted(report.f1)
        if grid_rows is not None:
            grid_rows.append(dict(criterion=params.criterion, n_trees=params.n_trees, scaler=params.scaler,
                                  accuracy=report.accuracy, f1=score, seconds=time.perf_counter() - t_fit))
            # (a grid's run said nothing for minutes: a reviewer's 7)
            log(f"Grid {k + 1}/{len(candidates)}: {params.criterion}, {params.n_trees} trees, scaler {params.scaler}: "
                f"validation weighted F1 {score:.4f} ({time.perf_counter() - t_fit:.0f} s).")
        if best is None or score > best[0]:
            best = (score, model)
        steps.report(0.35 + 0.5 * (k + 1) / len(candidates))
    model = best[1]
    if grid_rows is not None:
        chosen = model.meta["params"]
        log(f"Grid: kept {chosen['criterion']}, {chosen['n_trees']} trees, scaler {chosen['scaler']} (validation "
            f"weighted F1 {best[0]:.4f}).")
    timings["training" + (" (grid)" if options.grid else "")] = time.perf_counter() - t1
    t2 = time.perf_counter()
    evaluations = {}
    for label in ("validation", "test"):
        Xs, ys = sets[label]
        evaluations[f"{label} set"] = class_report(ys, model.predict(Xs), learnt)
    timings["prediction (validation + test)"] = time.perf_counter() - t2
    Xt, yt = sets["test"]
    if len(Xt) > options.permutation_points:
        pick = np.random.default_rng(0).choice(len(Xt), options.permutation_points, replace=False)
        Xt, yt = Xt[pick], yt[pick]
    t3 = time.perf_counter()
    perm = permutation_importance(model, Xt, yt, options.permutation_repeats)
    timings["permutation importance"] = time.perf_counter() - t3
    model.meta.update(classes_learned=list(learnt), test_accuracy=evaluations["test set"].accuracy)
    steps.check()
    settings = None
    if report_path:
        settings = dict(input=input_path, features=", ".join(names), classes=", ".join(map(str, learnt)) + (
                            " (ground (2) against " + ", ".join(str(c) for c in classes if c != GROUND_CLASS) + ")"
                            if learnt != classes else ""),
                        criterion=model.meta["params"]["criterion"], trees=model.meta["params"]["n_trees"],
                        scaler=model.meta["params"]["scaler"], max_depth=model.meta["params"]["max_depth"],
                        samples_per_tree=model.meta["params"]["max_samples"],
                        split=(f"spatial blocks of {options.block_m:g} m, planned "
                               + "/".join(f"{100 * f:.0f}" for f in options.fractions) + " %"
                               + (", made " + "/".join(f"{100 * f:.0f}" for f in made) + " % of the points"
                                  if made else "")
                               if not (validation_path and test_path) else "separate files"))
    _write_training_outputs(model, model_path, report_path, dict(
        title="GroundSieve Random Forest training", evaluations=evaluations, features=names,
        impurity=model.meta["impurity_importance"], permutation=perm, timings=timings, settings=settings,
        grid=grid_rows, notes=notes))
    steps.report(1.0)
    return TrainRun(model, evaluations, names, timings, grid_rows, notes)


def _radius_of(name: str) -> Optional[tuple]:
    """(feature, radius) of a feature computed within spheres of a fixed radius (the eigen features, density,
    height above the minimum: ``planarity_r0p6``), as core/learn/features.py names them; None for any other
    (an attribute, the hybrid's surfaces and openings)."""
    from ..errors import InvalidParameterError
    from ..learn.features import parse_feature_name
    try:
        return parse_feature_name(name)
    except InvalidParameterError:
        return None


def radius_features(names) -> List[str]:
    """The features of ``names`` computed within fixed radii, whose values change with the point density."""
    return [n for n in names if _radius_of(n) is not None]


def _density_matters(model) -> bool:
    """Whether the model keeps its training density and has features that depend on it."""
    return bool(model.meta.get("points_per_unit2")) and bool(radius_features(model.features))


#: a cloud this many times denser or sparser than the model's training cloud is warned about
DENSITY_RATIO = 3.0


def _say_density(model, model_path: str, where: str, here: float, crs_wkt, log) -> None:
    """Warn when the cloud's density ``here`` is DENSITY_RATIO times the model's training density or more,
    or as much below it, for a model of features within fixed radii (a reviewer's C5 model of 150 points/m²
    on a flight of 20: total error 5.1 -> 7.2 %, nothing said)."""
    trained = model.meta.get("points_per_unit2")
    if not _density_matters(model) or here <= 0 or max(here / trained, trained / here) < DENSITY_RATIO:
        return
    names = radius_features(model.features)
    from ..raster.crs import horizontal_unit
    unit = horizontal_unit(crs_wkt) or "metres"
    per = "points/m²" if unit == "metres" else f"points per square {unit}"
    log(f"{WARNING_PREFIX}{where}: {here:,.1f} {per} where it has points, the model {model_path} learnt from "
        f"{trained:,.1f}: its features within fixed radii ({', '.join(names)}) count other neighbourhoods, and its "
        "predictions may be worse. Train on a patch of this density, or a model on the HYBRID features, which "
        "depend on it less.")

#: a feature without a value on this share of the training points or more is said to be mostly missing
MISSING_SHARE = 0.5


def _feature_notes(X: np.ndarray, names, crs_wkt) -> List[str]:
    """Warnings on the training features that carry little: those without a value (NaN) on most points (a
    neighbourhood holding too few points: the paper's 0.4-0.6 m spheres on a sparse airborne cloud, or in a
    CRS in feet, where they are read as feet), and those of one value on every point (return_number on
    single returns). (All-NaN columns had been missed, and a numpy RuntimeWarning printed: a reviewer.)"""
    from ..learn.features import feature_name
    from ..raster.crs import horizontal_unit
    notes = []
    if X.shape[0] < 2:
        return notes
    finite = np.isfinite(X)
    unit = horizontal_unit(crs_wkt) or "metres"
    for j, name in enumerate(names):
        column = X[finite[:, j], j]
        missing = 1.0 - column.size / X.shape[0]
        if missing >= MISSING_SHARE:
            sphere = _radius_of(name)
            why = (f": its neighbourhood, {sphere[1]:g} {unit} around each point, holds too "
                   "few points there (a sparse cloud, or a radius meant in metres read in feet). Leave it out, or "
                   f"take a radius that holds a dozen points or more (a custom list, e.g. {feature_name(sphere[0], 2)} "
                   "for 2; Compute point features counts the spheres with too few)" if sphere else
                   ": leave it out, or train on a cloud that has it")
            notes.append(f"{WARNING_PREFIX}the feature '{name}' has no value on {missing:.1%} of the training "
                         f"points{why}.")
        elif column.size > 1 and column.min() == column.max():
            notes.append(f"{WARNING_PREFIX}the feature '{name}' is {float(column[0]):g} on every training point: it "
                         "carries no information (e.g. return_number on a cloud of single returns); leave it out, or "
                         "train on a cloud where it varies.")
    return notes


def _write_training_outputs(model, model_path: str, report_path: Optional[str], report: dict) -> None:
    """Write the model file, the HTML report and its CSV together: each to a temporary beside it,
    all renamed into place only once all three are complete, so that a failure in any (a full
    disk while writing the report) leaves none of them, not a model without its report."""
    import contextlib
    from ..learn.report import report_csv_path, write_report
    from ..errors import OutputError
    with contextlib.ExitStack() as stack:
        tmp_model = stack.enter_context(atomic_path(model_path))
        tmp_report = tmp_csv = None
        if report_path:
            tmp_report = stack.enter_context(atomic_path(report_path))
            tmp_csv = stack.enter_context(atomic_path(report_csv_path(report_path)))
        try:
            target = model_path
            save_model(model, tmp_model, atomic=False)
            if report_path:
                target = f"{report_path} (or its CSV {report_csv_path(report_path)})"
                write_report(tmp_report, csv_path=tmp_csv, atomic=False, **report)
        except OSError as err:
            raise OutputError(f"{target}: cannot be written ({err.strerror or err}); nothing was written: "
                              f"neither the model {model_path} nor its report") from err


@dataclass(frozen=True)
class ModelResult:
    """What :class:`ModelGround` gives a tile: ground (the predicted class is 2), the ground
    probability, and each point's predicted class (core/engine/workflow.classify_cloud writes it)."""
    ground: np.ndarray          #: bool per point
    probability: np.ndarray     #: float32 probability of ground per point (0 for a model without ground)
    point_classes: np.ndarray   #: uint8, the model's most probable class per point


def _ground_model(model) -> bool:
    """A model of ground (2) and the rest (1), which the filters' notes on the input's classes fit."""
    return {int(c) for c in model.classes} <= {1, GROUND_CLASS}


#: the least buffer (m) a model classifies tiles with: its DTM's surface near a tile's edge spans the ground
#: beyond it (lidR's catalogue buffers 30 m for the same reason), even for a model of point attributes alone
MODEL_MIN_REACH_M = 30.0


@dataclass(frozen=True)
class ModelGround(Hybrid):
    """A model of rfclassify in the buffered-tile engine, with rfclassify's rule: each point gets the
    model's predicted class (the most probable, a tie to the first class), ground being class 2 (not
    the hybrid filter's threshold on the ground probability), so that tiled and whole runs agree on
    ties too. Its features of x, y, z are computed on the tile and its buffer (as the hybrid filter's),
    but for those every file stores (``stored``); the others (colour, intensity, returns, scan angle,
    GPS time, a dimension of the files) are read from each tile's records as the whole run reads them
    from its file (:meth:`point_attributes`), the colour of the files of ``colour_factors`` ((file,
    factor), ...: judged file by file from all its points, :func:`survey_attributes`) multiplied by
    their factor. ``metres_per_unit``: the CRS's, for the least buffer (:data:`MODEL_MIN_REACH_M`)."""
    colour_factors: tuple = ()
    stored: tuple = ()
    metres_per_unit: float = 1.0
    #: a DTM is made: the buffer is then at least MODEL_MIN_REACH_M (without, the features' reach alone)
    dtm: bool = True

    name = "rfclassify"
    #: rfclassify gives every point a class of its model's: the log's advice on the input's other
    #: classes (workflow.replaced_note) names the hybrid filter, which can keep them
    keeps_classes = False
    #: nor has it the filters' 'Filter only last returns' (workflow.canopy_ground_note's advice: a reviewer read
    #: it in a tiled run)
    offers_last_returns = False

    @property
    def predicts_classes(self) -> bool:
        """A model of classes of its own (not ground and the rest): the filters' notes on the input's classes
        (workflow.replaced_note, demoted_note, structures_warning) are not said, as its whole run says none
        (a C2 model's 3, 5 and 6 were said to replace the input's 3, 5 and 6)."""
        return not _ground_model(self.model)

    def __post_init__(self):
        from ..errors import InvalidParameterError
        from ..validate import check_number
        if not isinstance(self.model_path, (str, os.PathLike)) or not os.fspath(self.model_path):
            raise InvalidParameterError(f"model_path must be a model file (got {self.model_path!r})")
        check_number(self, "metres_per_unit")
        if not self.metres_per_unit > 0:
            raise InvalidParameterError(f"metres_per_unit must be > 0 (got {self.metres_per_unit})")
        if any(not (isinstance(f, float) and f > 0) for _path, f in self.colour_factors):
            raise InvalidParameterError(f"colour_factors must be (file, factor > 0) pairs (got {self.colour_factors!r})")
        object.__setattr__(self, "_model", load_model(os.fspath(self.model_path)))

    @property
    def attribute_names(self) -> List[str]:
        """The model's features read from the points' records, not computed from x, y, z."""
        from ..learn.hybrid import unknown_features
        read = unknown_features(self.features)
        return read + [n for n in self.features if n in self.stored and n not in read]

    @property
    def point_fields(self) -> Tuple[str, ...]:
        return tuple(self.attribute_names)

    @property
    def point_attributes(self):
        """None for a model of x, y, z features; otherwise the function the tile engine gives each part's
        cloud (its ``las`` holding the part's records, read by its file's header) and its input file, and
        that returns {feature: float32 values}, computed as rfclassify's whole run computes them
        (learn/rf.py)."""
        return self._attributes_of if self.attribute_names else None

    def _attributes_of(self, cloud, path: str) -> dict:
        return read_attributes(self.model, self.attribute_names, cloud, dict(self.colour_factors).get(path, 1.0))

    @property
    def reach_m(self) -> float:
        """The reach of the model's features computed from x, y, z (the hybrid filter's rule), and at least
        :data:`MODEL_MIN_REACH_M` metres (in the CRS's unit) for the DTM."""
        names = [n for n in self.features if n not in self.attribute_names]
        reach = self.reach_of(names, self.cell_size_m) if names else 0.0  # (attributes alone: no neighbour)
        return max(reach, MODEL_MIN_REACH_M / self.metres_per_unit) if self.dtm else reach

    @property
    def min_tile_points(self) -> int:
        """A tile of fewer points keeps its classes (the engine's rule, for filters that need a grid): 1 for a
        model of attributes alone, which classifies each point by itself (a reviewer's 18 points on the
        survey's far edge, in tiles of their own with no buffer, kept their input class)."""
        from .tiles import MIN_TILE_POINTS
        return 1 if len(self.attribute_names) == len(self.features) else MIN_TILE_POINTS

    @property
    def extra_bytes_per_point(self) -> Optional[int]:
        """As rfclassify's whole run is priced (:class:`_WholeModelRun`): one file's run says one figure (a
        reviewer read 28 MB from rfclassify, then 45 MB from the engine, for the same file)."""
        return _WholeModelRun(self.model).extra_bytes_per_point

    @property
    def makes_grids(self) -> bool:
        return _WholeModelRun(self.model).makes_grids

    def describe(self) -> str:
        return (f"rfclassify in tiles: {self.model_path} ({len(self.features)} features: {', '.join(self.features)}); "
                "each point gets the model's most probable class")

    #: the tile engine says which points' classes are used (workflow.NEEDED: a tile's own points, without a
    #: DTM); the forest predicts those only (its prediction is most of a run: 8.6 s of 13 s in tiles of
    #: 100 m with 30 m buffers, docs/BENCHMARKS.md), the others are left not ground, of class 1
    optional_point_fields = (NEEDED,)

    def run(self, xyz, steps=None, **fields):
        from ..progress import Steps
        steps = steps or Steps()
        needed = fields.pop(NEEDED, None)
        names, read = self.features, set(self.attribute_names)
        X = np.empty((len(xyz), len(names)), dtype=np.float32)
        computed = [n for n in names if n not in read]
        if computed:
            values = hybrid_features(xyz, computed, cell_size_m=self.cell_size_m, steps=steps.sub(0.0, 0.6))
            for j, n in enumerate(computed):
                X[:, names.index(n)] = values[:, j]
        for n in read:
            X[:, names.index(n)] = fields[n]
        rows = np.arange(len(xyz)) if needed is None else np.flatnonzero(needed)
        classes = [int(c) for c in self.model.classes]
        proba = (self.model.predict_proba(X[rows], steps=steps.sub(0.6, 1.0)) if rows.size
                 else np.zeros((0, len(classes))))
        predicted = np.ones(len(xyz), dtype=np.uint8)
        predicted[rows] = np.asarray(classes, dtype=np.uint8)[np.argmax(proba, axis=1)]  # as Model.predict
        ground = np.zeros(len(xyz), dtype=np.float32)
        if GROUND_CLASS in classes:
            ground[rows] = proba[:, classes.index(GROUND_CLASS)]
        steps.report(1.0)
        return ModelResult(predicted == GROUND_CLASS, ground, predicted)


def _value(v: float) -> str:
    """A feature's value for a message: whole digits where large (GPS seconds: 19,200.3, not 1.92e+04)."""
    return f"{v:,.1f}" if abs(v) >= 1000 else f"{v:.4g}"


def check_model_unit(model, model_path: str, input_path: str, crs_wkt: Optional[str], log) -> None:
    """Refuse a cloud whose CRS unit is not the one the model was trained in (its features' radii
    and heights would be read in another unit: 'metres' against 'US survey foot' misclassifies most
    points without an error); warn when the model does not say and the cloud is not in metres."""
    from ..raster.crs import horizontal_unit, unit_warning
    unit, trained = horizontal_unit(crs_wkt), model.meta.get("crs_unit")
    if unit and trained and unit != trained:
        raise InputError(f"{input_path}: the CRS's unit is {unit}, but the model {model_path} was trained on a "
                         f"cloud in {trained}: its features (neighbourhood radii, heights) would be read in "
                         f"another unit. Reproject the cloud to a CRS in {trained} first")
    if not trained and unit and unit != "metres":
        log(WARNING_PREFIX + unit_warning(input_path, crs_wkt, "the model's features (radii and heights, learnt "
                                       "in the training cloud's unit)",
                                       converted="nothing is converted: they are read as the model learnt them."))


#: Memory a point costs rfclassify's whole run (the cloud read whole, its feature matrix, the forest), beyond a
#: ground filter's point (core/engine/tiles.whole_run_bytes): the peaks of a reviewer's UAV flights, 3.5 M
#: points (LAS point format 3) with C2 (colour and returns), C5 (and eigen features) and 9.5 M points with C2,
#: were 131-190 bytes a point beyond the process's own 0.25 GB, where the ground filters' figure (330 bytes,
#: core/engine/tiles.BYTES_PER_POINT) had tiled a file of 6.5 M points or more (where such models were refused
#: until 2026-11-26)
RF_EXTRA_BYTES_PER_POINT = 40


class _WholeModelRun:
    """What core/engine/tiles.whole_run_bytes prices for rfclassify's whole run of ``model`` (its own path:
    the cloud read whole, the feature matrix, the forest): RF_EXTRA_BYTES_PER_POINT a point beyond a ground
    filter's, and the grids of the hybrid's features where the model has them (its SMRF and PTD surfaces,
    priced as the hybrid filter prices them), no grid otherwise."""

    def __init__(self, model):
        from ..learn.hybrid import CELL_KEY, GRID_FEATURES, PTD_FEATURES, opening_radius
        grid = [n for n in model.features if n in GRID_FEATURES or n in PTD_FEATURES or opening_radius(n) is not None]
        self.makes_grids = bool(grid)
        if grid:  # (the hybrid features' grid, as Hybrid.cell_size_m reads it)
            self.cell_size_m = float(model.meta.get(CELL_KEY, 1.0))
        self.extra_bytes_per_point = RF_EXTRA_BYTES_PER_POINT + (
            120 if any(n in PTD_FEATURES for n in model.features) else 0)  # (as Hybrid.extra_bytes_per_point)


def _depth_words(factor: float, model_path: str) -> str:
    """What the log says of colour of the other depth, read in the model's by ``factor``."""
    if factor > 1:
        return (f"8-bit (every value at most 255) and the model {model_path} learnt 16-bit colour: the colour is read "
                "multiplied by 257 (255 becomes 65,535)")
    return (f"16-bit (values beyond 255) and the model {model_path} learnt 8-bit colour: the colour is read divided "
            "by 257 (65,535 becomes 255)")


def read_attributes(model, names, cloud, colour_factor: float = 1.0) -> dict:
    """{feature: float32 values} of the attribute features ``names`` of ``cloud`` (its ``las`` holding the
    records: a tile's part, a survey's sample), read as rfclassify's whole run reads them from its file
    (learn/rf.attribute_values, the model's GPS-time mode), colour multiplied by ``colour_factor`` (the whole
    run's X[:, colours] *= factor, in float32)."""
    from ..learn.rf import COLOURS, GPS_TIME_MODES, attribute_values
    mode = GPS_TIME_MODES.get(model.meta.get("gps_time"), "raw")
    out = {}
    for name in names:
        values = attribute_values(cloud, name, mode)
        out[name] = values * colour_factor if name in COLOURS and colour_factor != 1.0 else values
    return out


def say_features_here(model, model_path: str, where: str, X: np.ndarray, log, depth: bool = True) -> float:
    """Warn of what ``X`` (the features of the cloud ``where``, or of a survey's sample; NaN where not
    known) holds that the model did not learn: colour of the other depth, which is then read in the
    model's (``X``'s colour columns multiplied by the factor returned,
    :func:`core.learn.rf.colour_depth_factor`), features outside their learnt range on half the points
    or more, features of one value. ``depth`` False: the colour's depth is judged elsewhere (a survey's,
    file by file)."""
    from ..learn.rf import COLOURS, colour_depth_factor, constant_features, out_of_range_features
    factor = colour_depth_factor(model, X) if depth else 1.0
    if factor != 1.0:  # (a reviewer's 16-bit model on an 8-bit flight: every point class 5, no ground, "done")
        X[:, [j for j, name in enumerate(model.features) if name in COLOURS]] *= factor
        log(f"{WARNING_PREFIX}{where}: its colour is {_depth_words(factor, model_path)}.")
    for name, part_out, (low, high), median in out_of_range_features(model, X):
        if name in ("red", "green", "blue"):
            example = "; e.g. colour of another camera, exposure or light"
        elif name == "intensity":
            example = "; e.g. intensity of another sensor, flying height or scaling"
        elif name == "gps_time":
            # (a patch cut from a flight learns a few seconds of it: the time stands for where the patch lies, and
            # the rest of the same flight is beyond it; a reviewer's C3 model called 65 % of the objects ground)
            example = ("; the time a point was measured stands for where the training patch lay: the rest of a "
                       "flight, or a flight of another day, lies beyond it. Prefer a model without GPS time")
        elif name == "scan_angle":
            example = "; the scan angle stands for where in its strip the training patch lay"
        else:
            example = ""
        log(f"{WARNING_PREFIX}{where}: the feature '{name}' lies outside the range the model learnt it in on "
            f"{part_out:.0%} of the points (learnt: {_value(low)} to {_value(high)}; here the median is "
            f"{_value(median)}{example}): its predictions may mean little.")
    for name, value, (low, high) in constant_features(model, X):
        log(f"{WARNING_PREFIX}{where}: the feature '{name}' is {value:g} on every point (the model learnt it from "
            f"{low:g} to {high:g}): it carries no information here, and the predictions lean on the other "
            "features alone (e.g. a single-return cloud given a model trained on multi-return LiDAR).")
    return factor


#: a survey's attributes are sampled from at most this many of its files, spread over it
SAMPLE_FILES = 16
#: ... this many points of each, in SAMPLE_PIECES runs spread over the file (one LAZ chunk is 50,000 points)
SAMPLE_POINTS = 50_000
SAMPLE_PIECES = 4


def _colour_max(path: str, ignored, check=None) -> int:
    """The largest red, green or blue value of a file's points that a run classifies (neither withheld nor of
    an ``ignored`` class), every point read: as a whole run of the file judges its colour's depth and whether
    it has colour at all (a first chunk had judged 16-bit colour whose first points were dark 8-bit, and
    classified 62,436 of 142,315 points otherwise, and refused a file whose first points lay outside the
    orthophoto: a code reviewer)."""
    import laspy
    from ..io.lasfiles import CHUNK_POINTS
    top = 0
    with laspy.open(path) as reader:
        for chunk in reader.chunk_iterator(CHUNK_POINTS):
            if check is not None:
                check()
            keep = ~np.asarray(chunk.withheld, dtype=bool) & ~np.isin(np.asarray(chunk.classification), ignored)
            for name in ("red", "green", "blue"):
                values = np.asarray(chunk[name])[keep]
                if values.size:
                    top = max(top, int(values.max()))
    return top


@dataclass(frozen=True)
class SurveyAttributes:
    """What :func:`survey_attributes` found for :class:`ModelGround`."""
    colour_factors: tuple = ()   #: ((file, factor), ...) for the files whose colour is read in another depth
    stored: tuple = ()           #: features of x, y, z that every file stores (read, as a whole run reads them)


def survey_attributes(model, model_path: str, input_path: str, files, ignored=(), log=None,
                      check=None, colour_of=None) -> SurveyAttributes:
    """Check that every file of a survey gives the model's features as a whole run of it would: its
    attributes (colour, GPS time, a dimension) present; colour neither 0 on every point nor there where the
    model learnt intensity instead (rftrain's radiometry on a file without colour). Each file's colour
    depth is judged from all its points, as a whole run judges it (:func:`_colour_max`), and its colour
    read in the model's depth; features of x, y, z that the files store (groundsieve:features) are read,
    not computed, as a whole run reads them. Warns as a whole run does (:func:`say_features_here`), once
    for the survey, from a sample: :data:`SAMPLE_POINTS` points in runs spread over each of
    :data:`SAMPLE_FILES` files spread over the survey.
    ``colour_of``: the files whose colour is read (None: all; a job of an array, ``--only``: its file and
    the neighbours that lend it points, not the whole survey in every job: a reviewer)."""
    import types
    import laspy
    from ..learn.hybrid import GRID_FEATURES, opening_radius, unknown_features
    from ..learn.rf import COLOURS, RADIOMETRY, colour_depth_factor
    log = log or (lambda _msg: None)
    features = list(model.features)
    read = unknown_features(features)
    # (a whole run reads a stored feature of a radius; the hybrid's grid features it computes whatever is stored)
    computed = [n for n in features if n not in read and n not in GRID_FEATURES and opening_radius(n) is None]
    need = {n: ("red", "green", "blue") if n in COLOURS else (n,) for n in read
            if n not in ("intensity", "return_number", "number_of_returns", "scan_angle")}
    colour_model = any(n in COLOURS for n in features)
    radiometry = RADIOMETRY in model.meta.get("preset_features", ())
    stored_in: dict = {n: 0 for n in computed}
    coloured = []
    for path in files:
        with laspy.open(path) as reader:
            pf = reader.header.point_format
        dims = set(pf.dimension_names)
        missing = sorted(n for n, wanted in need.items() if not set(wanted) <= dims)
        if missing:
            raise InputError(f"{path}: the model {model_path} reads {', '.join(missing)}, which this file does not "
                             f"have (point format {pf.id}" + (", no colour" if any(n in COLOURS for n in missing)
                                                              else "")
                             + "): classify the files that have them, or train a model without them")
        for n in computed:
            stored_in[n] += n in dims
        if (colour_model or radiometry) and "red" in dims and (colour_of is None or path in colour_of):
            coloured.append(path)
    stored = tuple(n for n in computed if stored_in[n] == len(files) and files)
    partly = [n for n in computed if 0 < stored_in[n] < len(files)]
    if partly:
        log(f"{WARNING_PREFIX}{input_path}: {stored_in[partly[0]]:,} of its {len(files):,} files store the feature(s) "
            f"{', '.join(partly)} (groundsieve:features), the others do not: they are computed for every file, where "
            "a run of a file alone would read those stored.")
    factors, depths = [], {}
    if coloured:
        t0 = time.perf_counter()
        columns = [features.index(n) for n in COLOURS if n in features]
        for path in coloured:
            top = _colour_max(path, tuple(ignored), check)
            if radiometry and not colour_model and top > 0:
                raise InputError(f"{path}: the file has colour (RGB), and the model {model_path} learnt the intensity "
                                 "in its place (its training cloud had none): a run of the file alone refuses it too; "
                                 "train a model on a cloud with colour, or name intensity instead of radiometry")
            if colour_model and top == 0:
                raise InputError(f"{path}: its colour (RGB) is 0 on every point: the file has no colour, and the "
                                 f"model {model_path} learnt colour; classify the files that have it, or train a "
                                 "model without colour")
            if colour_model:
                probe = np.full((1, len(features)), np.nan, dtype=np.float32)
                probe[0, columns] = top
                factor = colour_depth_factor(model, probe)
                if factor != 1.0:
                    factors.append((path, factor))
                    depths.setdefault(factor, []).append(path)
        log(f"Read the colour of {len(coloured):,} file(s) in {time.perf_counter() - t0:.1f} s: each file's colour "
            "depth is judged from all its points, as a run of the file alone judges it.")
    for factor, paths in depths.items():
        shown = ", ".join(os.path.basename(p) for p in paths[:3]) + (", ..." if len(paths) > 3 else "")
        log(f"{WARNING_PREFIX}{len(paths):,} of the {len(files):,} files ({shown}): their colour is "
            f"{_depth_words(factor, model_path)}.")
    if not read:
        return SurveyAttributes((), stored)
    picked = sorted({files[int(k)] for k in np.linspace(0, len(files) - 1, min(SAMPLE_FILES, len(files)))})
    rows, by_path = [], dict(factors)
    for path in picked:
        with laspy.open(path) as reader:
            total = int(reader.header.point_count)
            per = min(SAMPLE_POINTS // SAMPLE_PIECES, total)
            # runs spread over the file, not its first points: a flight's GPS time grows through a file (a
            # reviewer's survey warning said 67 % out of range where the whole run said 89 %)
            for start in sorted({int(s) for s in np.linspace(0, total - per, SAMPLE_PIECES)} if per else ()):
                reader.seek(start)
                las = laspy.LasData(header=reader.header, points=reader.read_points(per))
                cloud = types.SimpleNamespace(path=path, las=las, return_number=np.asarray(las.return_number),
                                              number_of_returns=np.asarray(las.number_of_returns))
                X = np.full((len(las.points), len(features)), np.nan, dtype=np.float32)
                for name, values in read_attributes(model, read, cloud, by_path.get(path, 1.0)).items():
                    X[:, features.index(name)] = values
                # (the points a run classifies: as its whole run judges them)
                rows.append(X[~np.asarray(las.withheld, dtype=bool)
                              & ~np.isin(np.asarray(las.classification), ignored)])
    if rows:
        what = (f"{input_path} (a sample of {len(picked):,} of its {len(files):,} files)" if len(files) > 1
                else input_path)
        say_features_here(model, model_path, what, np.concatenate(rows), log, depth=False)
    return SurveyAttributes(tuple(factors), stored)


def classify_survey(input_path: str, output_path: Optional[str], model_path: str, *, dtm_path: Optional[str] = None,
                    dtm=None, ignore_classes=(7, 18), tiling=None, progress=None, is_cancelled=None, log=None):
    """rfclassify on a survey (a folder, a .vpc, a tile size set or a cloud beyond the memory
    budget): the model runs as a ground filter in the buffered-tile engine (core/engine/tiles.py),
    through :class:`ModelGround` (rfclassify's rule: the predicted class; its reach, from the model's
    features, is the tiles' buffer), any model: its attributes are read from each tile's records as a
    whole run of each file reads them (:func:`survey_attributes`)."""
    from .tiles import TileOptions
    from .workflow import DTMOptions, FilterOptions, run_ground_filter
    from ..io.lasfiles import expand_inputs, scan_header
    from ..raster.crs import metres_per_unit
    from ..progress import Steps
    say = log or (lambda _msg: None)
    files = expand_inputs(input_path)
    crs_wkt = scan_header(files[0]).crs_wkt if files else None
    ground = ModelGround(model_path=model_path, metres_per_unit=metres_per_unit(crs_wkt) or 1.0, dtm=bool(dtm_path))
    model = ground.model
    check_model_unit(model, model_path, input_path, crs_wkt, say)
    options = FilterOptions(ignore_classes=ignore_classes if ignore_classes is not None else (),
                            tiling=tiling or TileOptions())
    colour_of = None
    if options.tiling.only is not None and str(options.tiling.only).strip():  # (a job of an array: see colour_of)
        from .one_file import header_box, neighbours, only_index
        infos = [scan_header(f) for f in files]
        k = only_index(options.tiling.only, files, input_path)
        pad = ground.reach_m + max(float(options.tiling.tile_size_m), 0.0) + 1.0
        x0, y0, x1, y1 = header_box(infos[k])
        colour_of = {files[m] for m in neighbours(infos, k, (x0 - pad, y0 - pad, x1 + pad, y1 + pad))}
    found = survey_attributes(model, model_path, input_path, files, options.ignored, say,
                              Steps(None, is_cancelled).check, colour_of)
    if _density_matters(model):
        # (said once, from the first file's sample, as the tiles are planned: a tile's warnings stay in the tile)
        from .tiles import sample_density
        first = next((info for info in map(scan_header, files) if info.count), None)
        if first is not None:
            _say_density(model, model_path, first.path, sample_density(first.path), first.crs_wkt, say)
    ground = dataclasses.replace(ground, colour_factors=found.colour_factors, stored=found.stored)
    run = run_ground_filter(input_path, output_path, ground,
                            options=options, dtm_path=dtm_path, dtm=dtm or DTMOptions(), progress=progress,
                            is_cancelled=is_cancelled, log=log)
    if run.class_counts:  # (as the whole run says them)
        say(", ".join(f"class {c}: {run.class_counts.get(int(c), 0):,}" for c in model.classes))
    return run


def classified_counts(run, ignore_classes=(7, 18)) -> tuple:
    """(ground, points) of what :func:`classify_file` returned, as the ground filters count them: the
    points predicted ground (class 2; neither withheld nor of an ignored class) and the points read."""
    if not isinstance(run, tuple):  # a survey's TiledRun
        return int(run.ground_count), int(run.point_count)
    from .workflow import FilterOptions, processable
    cloud, predicted = run
    may = processable(cloud, FilterOptions(ignore_classes=ignore_classes if ignore_classes is not None else ()))
    return int(np.count_nonzero(predicted[may] == 2)), len(cloud)


def classify_file(input_path: str, output_path: Optional[str], model_path: str, *, dtm_path: Optional[str] = None,
                  dtm=None, ignore_classes=(7, 18), tiling=None, progress=None, is_cancelled=None, log=None):
    """Apply a saved model to ``input_path``; write the classified cloud (the model's ASPRS codes)
    and, optionally, a DTM from the points predicted as ground (class 2). With ``output_path`` None
    only the DTM is written (on a survey with a DTM extent, only the tiles that make the extent's
    cells are classified, as the ground filters do); with neither, nothing is written and the
    predictions are returned.

    The ground filters' rules on marked points hold here too: withheld points and points of
    ``ignore_classes`` (noise 7 and 18 by default; a list or text such as "7,18,20-25") keep their
    class and flags, and stay out of the features' neighbourhoods, the prediction and the DTM,
    whose grid spans only the other points.

    A survey (a folder or .vpc of LAS/LAZ, a ``tiling`` tile size, or a cloud beyond the memory
    budget) is classified tile by tile by :func:`classify_survey` (any model: its attributes are read
    from each tile's records); the
    result is then the engine's ``TiledRun``, not ``(cloud, predicted)``."""
    from ..io import CLASS_GROUND, read_cloud
    from ..progress import Steps
    from .workflow import (DTMOptions, FilterOptions, check_dtm_memory, check_outputs, dtm_points, make_dtm,
                           processable, write_outputs)
    from .tiles import TileOptions, needs_tiling, refuse_in_a_workers_import
    refuse_in_a_workers_import()
    input_path, model_path = os.fspath(input_path), os.fspath(model_path)
    output_path = os.fspath(output_path) if output_path is not None else None
    dtm_path = os.fspath(dtm_path) if dtm_path is not None else None
    from .one_file import check_only
    check_only(tiling, input_path, output_path, dtm_path)
    tiling = tiling or TileOptions()
    from .tiles import is_survey_input
    if not is_survey_input(input_path) and not (output_path or "").lower().endswith(".vpc"):
        check_outputs(input_path, output_path, [dtm_path])  # a wrong output refused before the model is read
        # (a .vpc output of one file tiled is the engine's to check, as the filters' is)
    model = load_model(model_path)
    if dtm_path and CLASS_GROUND not in model.classes:  # found before any work, as groundsieve:hybrid does
        raise InputError(f"{model_path}: this model has no ground class (2) (its classes: "
                         f"{', '.join(map(str, model.classes))}): it cannot make a DTM; leave the DTM out or "
                         "train a model with ground points")
    # the whole run priced as its own path's (the model loaded once: a code reviewer)
    estimate = _WholeModelRun(model)
    whole_dtm = (dtm or DTMOptions()) if dtm_path else None
    if needs_tiling(input_path, tiling, algorithm=estimate, dtm=whole_dtm):  # (why: said by the engine's own check)
        return classify_survey(input_path, output_path, model_path, dtm_path=dtm_path, dtm=dtm,
                               ignore_classes=ignore_classes, tiling=tiling, progress=progress,
                               is_cancelled=is_cancelled, log=log)
    steps = Steps(progress, is_cancelled)
    log = log or (lambda _msg: None)
    dtm = dtm or DTMOptions()
    options = FilterOptions(ignore_classes=ignore_classes if ignore_classes is not None else ())
    check_outputs(input_path, output_path, [dtm_path])
    if input_path.lower().endswith((".las", ".laz")) and os.path.isfile(input_path):
        from ..io.lasfiles import scan_header  # before reading the points: a wrong unit is said at once
        from .workflow import defaults_in_crs_unit, warn_about_units
        header = scan_header(input_path)
        crs_wkt = header.crs_wkt
        warn_about_units(input_path, [header], log)  # (as the tiled run said it: a code reviewer)
        check_model_unit(model, model_path, input_path, crs_wkt, log)
        # the DTM cell's default (1 m) in feet for a cloud in feet, as a tiled run converts it (a code reviewer:
        # 1 ft whole, 3.28 ft tiled)
        _same, dtm = defaults_in_crs_unit(None, dtm, crs_wkt, input_path, log)
    cloud = read_cloud(input_path)
    for note in cloud.notes:
        log(note)
    may = processable(cloud, options)
    n_may = int(may.sum())
    if n_may == 0:
        raise InputError(f"{input_path}: every point is withheld or of an ignored class "
                         f"({', '.join(map(str, options.ignored)) or 'none'}): nothing to classify")
    if n_may < len(cloud):
        log(f"Classifying {n_may:,} of {len(cloud):,} points: {int(cloud.withheld_mask.sum()):,} withheld and "
            f"{int((~may & ~cloud.withheld_mask).sum()):,} of an ignored class keep their class and are "
            "left out of the features, the prediction and the DTM.")
    part = cloud if n_may == len(cloud) else cloud.subset(may)
    if dtm_path:  # a DTM too large for the memory is refused before the features' work
        check_dtm_memory(part.x, part.y, dtm)
    names = resolve_features(model.meta.get("preset_features", model.features), part, log)
    if _density_matters(model):
        from .tiles import points_density
        _say_density(model, model_path, input_path, points_density(part.x, part.y), part.crs_wkt, log)
    if names != list(model.features):
        raise InputError(f"{input_path}: this cloud gives the features {names} but the model "
                         f"{model_path} was trained on {list(model.features)} (e.g. colour present in one "
                         "and not the other)")
    from ..learn.rf import GPS_TIME_MODES
    X = feature_matrix(part, names, steps.sub(0.0, 0.5), gps_time=GPS_TIME_MODES.get(model.meta.get("gps_time"), "raw"))
    say_features_here(model, model_path, input_path, X, log)
    if _ground_model(model):  # (as its tiled run says it)
        import types
        from .workflow import replaced_classes, replaced_note
        note = replaced_note(replaced_classes(cloud.classification, may), types.SimpleNamespace(keeps_classes=False))
        if note:
            log(note)
    predicted_part = model.predict(X, steps=steps.sub(0.5, 0.7)).astype(np.uint8)
    predicted = cloud.classification.astype(np.uint8)  # a copy: withheld and ignored points as read
    predicted[may] = predicted_part
    steps.report(0.7)
    log(", ".join(f"class {c}: {int((predicted_part == c).sum()):,}" for c in model.classes))
    rasters = []
    if dtm_path:
        ground = predicted_part == CLASS_GROUND
        if not ground.any():
            raise InputError(f"{input_path}: no point was predicted as ground (class 2): no DTM can be made")
        grid, values = make_dtm(part.x, part.y, part.z, dtm_points(part, ground, np.ones(len(part), bool), dtm), dtm,
                                path=input_path, log=log)  # (its notes, as a tiled run's: a reviewer)
        rasters.append((dtm_path, values, grid, {"elevation": True}))
    write_outputs(cloud, predicted, output_path, rasters, steps.sub(0.7, 1.0))
    steps.report(1.0)
    return cloud, predicted
