"""The headless command: ``python -m groundsieve <filter> --input X --output Y [options]``.

No QGIS: the core alone, for servers and cluster jobs. The options are the Processing
algorithms' parameters under the same names (``DTM_CELL`` -> ``--dtm-cell``), defaults and
units, made from one definition (``parameters.py`` and the core's option dataclasses); the
filters' finer settings the dialog does not show are offered too. ``--scheduler`` sends the
tiles to a Dask cluster (``local:N`` or ``tcp://host:port``; engine/cluster.py).

``--preset FILE`` (every filter) takes a preset (engine/presets.py): it replaces the filter's
defaults; the options typed win over it, even at their default value (argparse knows what was typed).
``python -m groundsieve tune --input patch.laz --filter smrf --preset-out smrf.json --report
tune.html`` tunes a filter on a labelled patch (engine/tune.py).

``python -m groundsieve accuracy DTM.tif CHECKPOINTS.csv [--report r.html] [--csv residuals.csv]`` checks a
DTM's vertical accuracy against surveyed checkpoints (core/raster/accuracy.py; ASPRS NVA/VVA).

``--json`` (every command) writes one JSON document to stdout at the end, for scripts and job
schedulers: what the run made (:func:`filter_document`, :func:`tune_document`), or
``{"status": "failed" | "interrupted", "kind": ..., "error": "..."}``; the log stays on stderr, and while the run
works whatever else would reach stdout goes to stderr, so stdout holds the document alone.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import sys
import time
from typing import List, Optional

from ..errors import GroundSieveError, InvalidParameterError
from . import parameters as P
from .tiles import TileOptions
from .workflow import DTMOptions, FilterOptions


class UsageExit(SystemExit):
    """argparse's exit on bad usage (status 2, the message already on stderr), with its message."""

    def __init__(self, code, message: str):
        super().__init__(code)
        self.message = message


class _Parser(argparse.ArgumentParser):
    """argparse's parser (its subcommands' too) whose bad-usage exit keeps the message (``--json``)."""

    def error(self, message):
        try:
            super().error(message)
        except SystemExit as err:
            raise UsageExit(err.code, message) from None


def _defaults(cls):
    return {f.name: f.default for f in dataclasses.fields(cls)}


def _number(kind):
    return {int: int, float: float}.get(kind, str)


def _add_dtm_options(io, dt: dict, dtm_classes: bool) -> None:
    """The DTM's options, the filters' and the DTM from classes' (``dtm_classes``: the filters' --dtm-classes,
    the classes added to their ground; the DTM from classes names its own with --classes)."""
    io.add_argument("--dtm-cell", type=float, default=dt["cell_size_m"], metavar="M", action=_TYPED_CELL,
                    help="DTM cell size (m; default %(default)s, 3 ft in a CRS in feet; typed, in the CRS's unit)")
    io.add_argument("--dtm-fill", action=argparse.BooleanOptionalAction, default=dt["fill_outside_hull"],
                    help="fill DTM cells outside the ground hull (nearest value; default %(default)s)")
    io.add_argument("--dtm-extent", default="", metavar="XMIN,YMIN,XMAX,YMAX",
                    help="the DTM's extent in the cloud's CRS, widened to whole cells on multiples of the cell "
                         "size: two epochs' DTMs or a model's domain on one grid of one size (default: the points'); "
                         "with a negative first number write --dtm-extent=-100,-100,100,100")
    if dtm_classes:
        io.add_argument("--dtm-classes", default="", metavar="LIST",
                        help="classes of the input whose points enter the DTM with the ground, e.g. 9 (water) for "
                             "a flood model; a list or ranges as --ignore-classes (default none)")
    io.add_argument("--dtm-max-distance", type=float, default=dt["max_distance_m"], metavar="M",
                    help="leave DTM cells farther than this from any ground point empty, so that data gaps are "
                         "not bridged (m; 0 = no limit; default %(default)s)")


def _add_common(parser: argparse.ArgumentParser) -> None:
    fo, dt = _defaults(FilterOptions), _defaults(DTMOptions)
    io = parser.add_argument_group("input and outputs")
    io.add_argument("--input", required=True, metavar="PATH",
                    help="LAS/LAZ (1.0-1.4, point formats 0-10), a folder of them, a .vpc, or an ISPRS .txt")
    io.add_argument("--output", metavar="PATH", help="classified LAS/LAZ (a .vpc for several input files)")
    io.add_argument("--dtm", metavar="PATH", help="DTM GeoTIFF (optional)")
    _add_json(io)
    _add_dtm_options(io, dt, dtm_classes=True)
    io.add_argument("--last-returns", action=argparse.BooleanOptionalAction, default=fo["last_returns_only"],
                    help="filter only last returns (others become non-ground; default %(default)s)")
    io.add_argument("--ignore-classes", default=None, metavar="LIST",
                    help="classes never filtered, never ground, kept as they are and left out of the DTM: a list "
                         "or ranges, 7,18,20-25 or PDAL's [7:18]; '' = none (default 7,18)")
    # IGNORE_NOISE's former switch, still accepted (an explicit --ignore-classes wins)
    io.add_argument("--ignore-noise", action=argparse.BooleanOptionalAction, default=fo["ignore_noise"],
                    help=argparse.SUPPRESS)
    io.add_argument("--keep-classes", action=argparse.BooleanOptionalAction, default=fo["keep_existing_classes"],
                    help="keep every class other than 0, 1, 2 as it is (never made ground, so out of the DTM "
                         "unless named in --dtm-classes; default %(default)s)")
    _add_tiles(parser)


def _add_tiles(parser: argparse.ArgumentParser) -> None:
    """The options of tiled runs (every filter's, and the DTM from classes')."""
    to = _defaults(TileOptions)
    tiles = parser.add_argument_group("survey scale: tiles")
    tiles.add_argument("--tile-size", type=float, default=to["tile_size_m"], metavar="M",
                       help="tile size (m; 0 = from the memory budget; default %(default)s)")
    tiles.add_argument("--tile-buffer", type=float, default=-1.0, metavar="M",
                       help="tile buffer (m; -1 = the filter's own reach, 40 m for the DTM from classes; default "
                            "%(default)s)")
    tiles.add_argument("--memory-budget", type=float, default=to["memory_budget_mb"], metavar="MB",
                       help="memory budget (MB; 0 = a quarter of the job's memory (the RAM, or its control group's limit "
                            "under SLURM or a container), at most 2048, and below ulimit -v; default %(default)s): "
                            "the tiles' points and grids; each worker process also holds Python and its libraries "
                            "(130-250 MB, measured), outside it")
    tiles.add_argument("--workers", type=int, default=to["workers"], metavar="N",
                       help="tiles at the same time on this machine (0 = every core this process may use: its CPU set, "
                            "e.g. SLURM's, and quota; default %(default)s); with no tile size set, the tiles are "
                            "planned from the memory budget shared by the workers, so other workers plan other "
                            "tiles: set --tile-size for the same results on any machine")
    tiles.add_argument("--work-folder", metavar="PATH",
                       help="working folder for temporary tiles (default: beside the output); with a Dask "
                            "scheduler, on a file system every worker sees at the same path")
    tiles.add_argument("--only", default=None, metavar="FILE",
                       help="one file of a survey input (a folder or a .vpc): its number from 0 (a job array's task id, "
                            "e.g. $SLURM_ARRAY_TASK_ID), its name or its path; only its points are classified, on the "
                            "survey's tiles buffered by its neighbours' points. --output and --dtm are then folders "
                            "(the file's copy and DTM there under its name), paths with {name} (the file's name), or "
                            "a .las/.laz and a .tif")
    tiles.add_argument("--scheduler", default=to["scheduler"], metavar="ADDRESS",
                       help="Dask scheduler: empty = this machine, local:N = a local Dask cluster of N worker "
                            "processes, tcp://host:port = a running scheduler (needs dask[distributed]; the "
                            "workers must see the input and working folder at the same paths)")


#: the kinds of a failed run's JSON document (:func:`error_kind`)
JSON_KINDS = "usage, input, parameter, memory, output, cluster, cancelled, interrupted, other"
JSON_HELP = ("write one JSON document to stdout at the end, nothing else (the log stays on stderr): "
             "{\"status\": \"done\", %s}, or {\"status\": \"failed\" or \"interrupted\", \"kind\" ("
             + JSON_KINDS + "), \"error\": the one-line message} when the exit status is not 0")
FILTER_JSON = ("\"input\", \"output\" (or null), \"outputs\" (the classified files), \"dtm\" (or null), \"points\", "
               "\"ground\", \"seconds\", \"tiles\" (null without tiles), \"algorithm\", \"parameters\" (the "
               "filter's, as run), \"warnings\"")
DTM_JSON = ("\"input\", \"dtm\", \"points\", \"ground\" (the points of the ground classes), \"seconds\", \"tiles\" "
            "(null without tiles), \"algorithm\" (dtm), \"parameters\" (the ground classes), \"warnings\"")
ACCURACY_JSON = ("\"dtm\", \"checkpoints\", \"unit\", \"crs\", \"sign\", \"count\", \"skipped\" ([{id, reason}]), "
                 "\"all\", \"nva\", \"vva\" (each null or {count, mean, std, rmse, min, max, p95_abs, ed1_95, "
                 "ed1_95_method, ed2_rmse}), \"outliers\", \"report\", \"csv\", \"warnings\"")
TUNE_JSON = ("\"input\", \"filter\", \"metric\", \"parameters\" (chosen), \"searched\", \"cv\" (cross-validated "
             "total_error, kappa, f1), \"patch\" (in-sample), \"sets\", \"runs\", \"seconds\", \"stopped\", "
             "\"preset\", \"report\", \"warnings\"")


RFTRAIN_JSON = ("\"input\", \"model\", \"report\", \"features\", \"classes\" (learnt), \"test_accuracy\", "
                "\"seconds\", \"warnings\"")
FEATURES_JSON = ("\"input\", \"output\", \"features\" (the names written), \"points\", \"seconds\", "
                 "\"warnings\"")
RFCLASSIFY_JSON = ("\"input\", \"output\" (or null), \"outputs\" (the classified files), \"model\", \"dtm\" (or null), "
                   "\"points\", \"ground\" (predicted 2), \"seconds\", \"tiles\" (null without tiles), \"warnings\"")


def _add_json(group, fields: str = FILTER_JSON) -> None:
    group.add_argument("--json", action="store_true", help=(JSON_HELP % fields).replace("%", "%%"))


def _add_filter(sub, name: str) -> None:
    summary = P.SUMMARY[name]
    parser = sub.add_parser(name, help=summary, description=f"{summary}. Lengths in metres; for a cloud in feet the defaults and a "
                                "preset's values are converted, and the options you type are read in feet.")
    _add_common(parser)
    group = parser.add_argument_group(f"{name} parameters (as in the Processing dialog)")
    group.add_argument("--preset", metavar="FILE",
                       help="a preset file of this filter (groundsieve tune, or a shipped preset's name): it "
                            "replaces the defaults; the options you type win, even at their default value")
    for p in P.params(name):
        _add_param(group, name, p.field, p.option, p.title() + (
            " (" + " | ".join(f"{v} = {label}" for v, label in zip(p.choices, p.choice_labels)) + ")"
            if p.choices else "") + (f": {p.help}" if p.help else ""), p.choices)
    if name == "evc":  # groundsieve:evcrasters's rasters (core/filters/evc.py EVC_RASTERS)
        from ..filters.evc import EVC_RASTERS
        rasters = parser.add_argument_group("evc rasters (groundsieve:evcrasters's; GeoTIFF, optional)")
        for key, (label, _make) in EVC_RASTERS.items():  # (--class-raster, as the dialog's CLASS_RASTER)
            option = "class" if key == "classes" else key.replace("_", "-")
            rasters.add_argument(f"--{option}-raster", metavar="PATH", dest=f"raster_{key}", help=label)
    extra = P.core_only_fields(name)
    if extra:
        group = parser.add_argument_group(f"{name}: finer settings (core only, not in the dialog)")
        for f in extra:
            _add_param(group, name, f.name, "--" + f.name.replace("_", "-"), f.name.replace("_", " "), ())
    parser.set_defaults(filter=name)


def _add_hybrid(sub) -> None:
    """The learned hybrid filter (core/learn/hybrid.py): its model, not parameters, decides; the
    options are groundsieve:hybrid's (MODEL, SHIPPED, PROBABILITY)."""
    from ..learn.hybrid import SHIPPED_MODELS, Hybrid
    d = _defaults(Hybrid)
    summary = "learned hybrid: a Random Forest on heights above SMRF's (and optionally PTD's) ground surfaces"
    parser = sub.add_parser("hybrid", help=summary, description=f"{summary}. x, y, z only.")
    _add_common(parser)
    group = parser.add_argument_group("hybrid parameters (as in the Processing dialog)")
    group.add_argument("--model", dest="f_model_path", default=d["model_path"], metavar="PATH",
                       help="a model file trained on the hybrid features (.npz); empty = the shipped model "
                            "chosen by --shipped")
    group.add_argument("--shipped", dest="f_shipped_model", default=d["shipped_model"], choices=list(SHIPPED_MODELS),
                       help="the shipped model used when no --model is given: fast = SMRF surfaces (the default), "
                            "accurate = SMRF + PTD surfaces (lower error on the ISPRS samples, about 2.4x slower); "
                            "default %(default)s")
    group.add_argument("--probability", dest="f_ground_probability", type=float, default=d["ground_probability"],
                       metavar="X", help="ground probability threshold; default %(default)s")
    parser.set_defaults(filter="hybrid")


def _typed_action(base):
    """``base`` (an argparse action class) that also notes its field in ``namespace.typed``: a value
    typed on the command line wins over a preset even when it equals the filter's default."""
    class Typed(base):
        def __call__(self, parser, namespace, values, option_string=None):
            super().__call__(parser, namespace, values, option_string)
            typed = set(getattr(namespace, "typed", None) or ())
            typed.add(self.dest[2:])
            namespace.typed = typed
    return Typed


_TYPED_STORE = _typed_action(argparse._StoreAction)


class _TYPED_CELL(argparse._StoreAction):  # noqa: N801
    """--dtm-cell, noting that it was typed: then in the CRS's unit even at the default (DTMOptions.cell_set)."""
    def __call__(self, parser, namespace, values, option_string=None):
        super().__call__(parser, namespace, values, option_string)
        namespace.dtm_cell_typed = True
_TYPED_BOOL = _typed_action(argparse.BooleanOptionalAction)


def _add_param(group, name, field, option, title, choices) -> None:
    value = P.default(name, field)
    kind = P.field_type(name, field)
    if kind is bool:
        group.add_argument(option, dest="f_" + field, action=_TYPED_BOOL, default=value,
                           help=f"{title}; default {'on' if value else 'off'}")
    else:
        group.add_argument(option, dest="f_" + field, action=_TYPED_STORE, type=_number(kind), default=value,
                           choices=list(choices) or None, metavar=None if choices else "X",
                           help=f"{title}; default {value}")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="python -m groundsieve",
        description="Ground filtering of point clouds (LAS/LAZ, folders, .vpc) without QGIS: classified "
                    "LAS/LAZ (ground = 2, other = 1) and an optional DTM GeoTIFF. Lengths in metres; for a "
                    "cloud in feet the defaults and a preset's values are converted, and the options you "
                    "type are read in feet. `python -m groundsieve FILTER --help` lists "
                    "a filter's parameters.",
        epilog="Exit status: 0 done, 1 refused or failed (one line saying why), 2 bad usage, 3 an internal error "
               "(a traceback: a bug to report), 75 the Dask cluster failed (worth a retry once it is back), 130 interrupted "
               "(Ctrl-C or SIGTERM; a survey's finished tiles are kept in --work-folder, when given, for the "
               "next run to resume). The log goes to stderr. With --json, stdout holds one JSON document "
               f"alone: for a filter {{\"status\": \"done\", {FILTER_JSON}}}; for tune the chosen \"parameters\" "
               "and the cross-validated \"cv\" figures; for accuracy the \"all\", \"nva\" and \"vva\" figures; when the exit status is not 0, {\"status\": \"failed\" "
               f"(1, 2, 3, 75) or \"interrupted\" (130), \"kind\" ({JSON_KINDS}), \"error\": the one-line message}}.")
    sub = parser.add_subparsers(title="filters", metavar="FILTER", required=True)
    for name in P.FILTERS:
        _add_filter(sub, name)
    _add_hybrid(sub)
    _add_tune(sub)
    _add_dtm(sub)
    _add_accuracy(sub)
    _add_rftrain(sub)
    _add_rfclassify(sub)
    _add_features(sub)
    return parser


def _add_features(sub) -> None:
    """``features``: groundsieve:features, point features written as extra bytes (core/engine/features_run.py)."""
    from ..learn.features import FEATURES, PAPER_FEATURES
    summary = "compute point features (matrone2024's eigen features and others) and write them as extra bytes"
    parser = sub.add_parser("features", help=summary, description=f"{summary}, named FEATURE_rRADIUS with p as the "
                            "decimal mark (verticality_r0p6): what rftrain's presets compute, to look at or to train "
                            "on elsewhere. Radii in the cloud's CRS unit.")
    io = parser.add_argument_group("input and output")
    io.add_argument("--input", required=True, metavar="PATH", help="LAS/LAZ (1.0-1.4) or ISPRS text")
    io.add_argument("--output", required=True, metavar="PATH", help="LAS/LAZ with the features as extra bytes")
    io.add_argument("--features", default=",".join(f"{f}:{r:g}" for f, r in PAPER_FEATURES), metavar="LIST",
                    help=f"FEATURE:RADIUS pairs, of {', '.join(FEATURES)} (default %(default)s, the paper's)")
    io.add_argument("--ignore-classes", default="7,18", metavar="LIST",
                    help="classes left out of the neighbourhoods, with no value (NaN); '' = none (default %(default)s)")
    _add_json(io, FEATURES_JSON)
    parser.set_defaults(filter="features")


def run_features_command(args, out) -> dict:
    """Run ``features``; return its JSON document."""
    from ..learn.features import FeatureSpec, parse_feature_name
    from .features_run import run_features
    pairs = []
    for item in (i.strip() for i in args.features.split(",") if i.strip()):
        feature, colon, radius = item.partition(":")
        try:
            pairs.append((feature.strip(), float(radius)) if colon else parse_feature_name(item))
        except (ValueError, GroundSieveError):
            raise _Usage(f"--features: {item!r} is not FEATURE:RADIUS (planarity:0.6) or a feature's name "
                         "(planarity_r0p6)") from None
    if not pairs:
        raise _Usage("--features: name at least one FEATURE:RADIUS, e.g. planarity:0.6")
    warnings, log = _collecting_log(out)
    start = time.monotonic()
    with _kernels_of("features", out):
        run = run_features(args.input, args.output, FeatureSpec(tuple(pairs)), ignore_classes=args.ignore_classes,
                           progress=_progress_printer(out), is_cancelled=_interrupt_seen, log=log)
    print(f"{len(run.cloud):,} points, features {', '.join(run.names)}.", file=out)
    return {"status": "done", "input": args.input, "output": args.output, "features": list(run.names),
            "points": len(run.cloud), "seconds": round(time.monotonic() - start, 3), "warnings": list(warnings)}


def _add_rftrain(sub) -> None:
    """``rftrain``: groundsieve:rftrain's Random Forest training (core/engine/learning.py train_file)."""
    from ..learn.rf import CRITERIA, DEFAULT_PRESET, PRESETS, SCALERS, ForestParams
    from .learning import TrainOptions
    fp = _defaults(ForestParams)
    summary = "train a Random Forest on a labelled cloud (its classes): a model file for rfclassify and hybrid"
    parser = sub.add_parser("rftrain", help=summary, description=f"{summary}; the features of --features (matrone2024's "
                            "C1-C5, or HYBRID: the learned hybrid filter's, x, y, z only, whose ground model also runs "
                            "in hybrid --model), a spatial split into training, validation and test blocks, and an "
                            "HTML report.")
    io = parser.add_argument_group("input and outputs")
    io.add_argument("--input", required=True, metavar="PATH", help="the labelled LAS/LAZ (its classification is the label)")
    io.add_argument("--model", required=True, metavar="PATH", help="the model file to write (.npz)")
    io.add_argument("--report", metavar="PATH", help="the HTML report to write")
    io.add_argument("--validation", metavar="PATH", help="a labelled file for validation (default: blocks of the input)")
    io.add_argument("--test", metavar="PATH", help="a labelled file for the test (default: blocks of the input)")
    _add_json(io, RFTRAIN_JSON)
    forest = parser.add_argument_group("features and forest")
    forest.add_argument("--features", choices=list(PRESETS), default=DEFAULT_PRESET,
                        help="the features: HYBRID (x, y, z only: heights above SMRF's surface and 2, 6, 18 m "
                             "openings; the model also runs in hybrid --model and on surveys), or matrone2024's C1 "
                             "(RGB), C2 (+ return number), C3 (+ scan angle, GPS time), C4 (C3 + verticality, "
                             "planarity, eigenentropy, surface variation), C5 (RGB, return number and the four), C5H "
                             "(C5 + height above the ground minimum and density) (default %(default)s)")
    forest.add_argument("--custom-features", default="", metavar="LIST",
                        help="features by name instead, e.g. intensity,return_number,planarity_r0p6")
    forest.add_argument("--ground-vs-rest", action="store_true",
                        help="learn ground (2) against all other classes (a ground model, for a DTM), whatever the "
                             "features (HYBRID with no --classes does so by default)")
    forest.add_argument("--grid", action="store_true",
                        help="train the paper's 18 combinations (criterion x trees x scaler) and keep the best on "
                             "the validation set (18 times as long)")
    forest.add_argument("--classes", default="", metavar="LIST",
                        help="the ASPRS classes to learn, e.g. 2,3,5,6 ('' = every class present but 0, 7 and 18; "
                             "with HYBRID: ground against the rest)")
    forest.add_argument("--trees", type=int, default=fp["n_trees"], metavar="N", help="trees (default %(default)s)")
    forest.add_argument("--criterion", choices=list(CRITERIA), default=fp["criterion"])
    forest.add_argument("--scaler", choices=list(SCALERS), default=fp["scaler"])
    forest.add_argument("--max-depth", type=int, default=0, metavar="N", help="tree depth (0 = none; default %(default)s)")
    forest.add_argument("--samples-per-tree", type=int, default=fp["max_samples"], metavar="N",
                        help="points drawn per tree (0 = all; default %(default)s)")
    forest.add_argument("--block", type=float, default=_defaults(TrainOptions)["block_m"], metavar="M",
                        help="block size of the spatial split (m; default %(default)s)")
    parser.set_defaults(filter="rftrain")


def run_rftrain(args, out) -> dict:
    """Run ``rftrain``; return its JSON document."""
    from ..io.clouds import parse_classes
    from ..learn.rf import PRESETS, ForestParams
    from ..progress import warning_of
    from .learning import TrainOptions, train_file
    warnings, log = _collecting_log(out)
    custom = tuple(n.strip() for n in args.custom_features.split(",") if n.strip())
    options = TrainOptions(features=custom or PRESETS[args.features], classes=parse_classes(args.classes) or None,
                           grid=args.grid, ground_vs_rest=True if args.ground_vs_rest else None,
                           params=ForestParams(n_trees=args.trees, criterion=args.criterion, scaler=args.scaler,
                                               max_depth=args.max_depth or None,
                                               max_samples=args.samples_per_tree or None),
                           block_m=args.block)
    start = time.monotonic()
    with _kernels_of("rftrain", out):
        run = train_file(args.input, args.model, args.report, options, validation_path=args.validation,
                         test_path=args.test, progress=_progress_printer(out), is_cancelled=_interrupt_seen, log=log)
    accuracy = run.model.meta.get("test_accuracy")
    print(f"Model {args.model}: {len(run.features)} features, classes "
          f"{', '.join(str(int(c)) for c in run.model.classes)}; test accuracy "
          f"{'-' if accuracy is None else f'{100 * accuracy:.2f} %'}.", file=out)
    return {"status": "done", "input": args.input, "model": args.model, "report": args.report,
            "features": list(run.features), "classes": [int(c) for c in run.model.classes],
            "test_accuracy": accuracy, "seconds": round(time.monotonic() - start, 3),
            "warnings": list(warnings) + [w for w in (warning_of(w) or w for w in run.warnings or ())
                                          if w not in warnings]}


def _add_rfclassify(sub) -> None:
    """``rfclassify``: groundsieve:rfclassify, a saved model applied (core/engine/learning.py classify_file)."""
    dt = _defaults(DTMOptions)
    summary = "classify a cloud with a model from rftrain (its ASPRS classes), and optionally make a DTM"
    parser = sub.add_parser("rfclassify", help=summary, description=f"{summary} from the points predicted as "
                            "ground (2). A folder, a .vpc, a tile size or a cloud beyond the memory budget runs in "
                            "buffered tiles (any model: its colour, returns, scan angle or GPS time are read from each tile's "
                            "points).")
    io = parser.add_argument_group("input and outputs")
    io.add_argument("--input", required=True, metavar="PATH", help="LAS/LAZ (1.0-1.4), a folder of them, or a .vpc")
    io.add_argument("--model", required=True, metavar="PATH", help="the model file (.npz) from rftrain")
    io.add_argument("--output", metavar="PATH", help="classified LAS/LAZ (a .vpc for several inputs); leave it out "
                    "for the DTM alone")
    io.add_argument("--dtm", metavar="PATH", help="DTM GeoTIFF of the predicted ground (optional)")
    _add_json(io, RFCLASSIFY_JSON)
    io.add_argument("--ignore-classes", default="7,18", metavar="LIST",
                    help="classes kept as they are, not predicted, out of the DTM; '' = none (default %(default)s)")
    _add_dtm_options(io, dt, dtm_classes=True)
    _add_tiles(parser)
    parser.set_defaults(filter="rfclassify")


@contextlib.contextmanager
def _kernels_of(name: str, out):
    """Around a run of algorithm ``name``: the note that it is about to compile its kernels, before the
    work, and once it finished, that they are compiled (core/engine/kernels.py)."""
    from .kernels import COMPILING, about_to_compile, remember_run
    if about_to_compile(name):  # (the progress then waits 20-60 s: a release engineer saw 8 s at 21.5 %)
        print(COMPILING, file=out, flush=True)
    yield
    remember_run(name)


def run_rfclassify(args, out) -> dict:
    """Run ``rfclassify``; return its JSON document."""
    from .learning import classify_file
    _check_outputs_named(args, out)
    warnings, log = _collecting_log(out)
    dtm = dtm_options(args)
    start = time.monotonic()
    with _kernels_of("rfclassify", out):
        result = classify_file(args.input, args.output, args.model, dtm_path=args.dtm, dtm=dtm,
                               ignore_classes=args.ignore_classes, tiling=_tiling(args),
                               progress=_progress_printer(out), is_cancelled=_interrupt_seen, log=log)
    if isinstance(result, tuple):  # one cloud in memory: (cloud, predicted classes)
        cloud, predicted = result
        points, ground, tiles, outputs = len(cloud), int((predicted == 2).sum()), None, [p for p in [args.output] if p]
        dtm_path = args.dtm or None
    else:
        points, ground, tiles, outputs = result.point_count, result.ground_count, result.tiles, list(result.outputs)
        dtm_path = result.dtm_path
    print(f"{points:,} points, {ground:,} predicted ground.", file=out)
    return {"status": "done", "input": args.input, "output": args.output, "outputs": outputs, "model": args.model,
            "dtm": dtm_path, "points": int(points), "ground": int(ground),
            "seconds": round(time.monotonic() - start, 3), "tiles": tiles, "warnings": list(warnings)}


def _add_dtm(sub) -> None:
    """``dtm``: a DTM from the classes the cloud already has (filters/classes.py ClassGround),
    groundsieve:dtm's options."""
    dt = _defaults(DTMOptions)
    summary = "a DTM from the points a classification already made ground, without filtering them again"
    parser = sub.add_parser("dtm", help=summary, description=f"{summary}: the points of --classes (2 by default) "
                            "are triangulated as the ground filters' DTMs are. A folder or a .vpc runs in buffered "
                            "tiles (a buffer of 40 m unless --tile-buffer says otherwise).")
    io = parser.add_argument_group("input and output")
    io.add_argument("--input", required=True, metavar="PATH", help="LAS/LAZ (1.0-1.4), a folder of them, or a .vpc")
    io.add_argument("--dtm", required=True, metavar="PATH", help="the DTM GeoTIFF")
    _add_json(io, DTM_JSON)
    io.add_argument("--classes", default="2", metavar="LIST",
                    help="the classes of the DTM's points: 2 (ground), e.g. 2,9 with water, 2,9,11 with the road "
                         "surface the vendor classed apart; a list or ranges as --ignore-classes (default %(default)s)")
    io.add_argument("--ignore-classes", default="7,18", metavar="LIST",
                    help="classes left out of the DTM and of its extent, e.g. noise; '' = none (default %(default)s)")
    _add_dtm_options(io, dt, dtm_classes=False)
    _add_tiles(parser)
    parser.set_defaults(filter="dtm", output=None)


def run_dtm(args, out) -> dict:
    """Run ``dtm``; return its JSON document, as a filter's (``filter_document``)."""
    from ..filters.classes import ClassGround
    warnings, log = _collecting_log(out)
    ground = ClassGround(args.classes)
    options = FilterOptions(ignore_classes=args.ignore_classes, keep_existing_classes=True, tiling=_tiling(args))
    dtm = dtm_options(args, classes=False)
    return _run_documented(args, out, ground, options, dtm, warnings, log, "of the ground classes")


def _add_accuracy(sub) -> None:
    """``accuracy``: a DTM's vertical accuracy against surveyed checkpoints (core/raster/accuracy.py),
    groundsieve:accuracy's figures and report."""
    parser = sub.add_parser(
        "accuracy", help="check a DTM's vertical accuracy against surveyed checkpoints (ASPRS NVA/VVA)",
        description="Check a DTM GeoTIFF (ours or any other) against independently surveyed checkpoints: RMSEz, "
                    "mean error, standard deviation, min/max, and per land cover NVA and VVA as ASPRS Edition 1 "
                    "(2014: 1.96 x RMSEz, 95th percentile of |dz|) and Edition 2 (2023: RMSEz) report them. "
                    "dz = DTM - checkpoint z, the DTM sampled bilinearly between its four cell centres around each "
                    "checkpoint (the checkpoint's own cell when one of them is nodata; skipped when that is nodata "
                    "too or it lies outside). The checkpoints must be in the DTM's CRS and vertical datum.",
        epilog="Checkpoint file: text or CSV, the delimiter found on the first line (semicolon, tab, comma, else "
               "spaces; a decimal comma with semicolons or tabs). An optional header names the columns: x/easting/e, "
               "y/northing/n, z/elevation/height/h, id/name/point, class/landcover/cover; without one the columns "
               "are x y z, x y z class, or id x y z [class]. Land cover: NVA, VVA, non-vegetated, vegetated, or "
               "any value mapped with --land-cover-map. Other header words: name the column with --z-column, "
               "--id-column or --land-cover-column.")
    parser.add_argument("dtm", metavar="DTM", help="the DTM: a GeoTIFF or any raster GDAL reads")
    parser.add_argument("checkpoints", metavar="CHECKPOINTS", help="the checkpoints: a text or CSV file")
    parser.add_argument("--band", type=int, default=1, metavar="N", help="the DTM's band (default %(default)s)")
    parser.add_argument("--land-cover-map", default="", metavar="MAP",
                        help="land-cover values of the file as NVA or VVA, e.g. 'road=NVA,grass=NVA,forest=VVA'")
    for column, what in (("z", "the checkpoints' heights"), ("id", "their ids"), ("land-cover", "their land cover")):
        parser.add_argument(f"--{column}-column", default="", metavar="NAME",
                            help=f"the header's column of {what}, when its name is not one of the known words")
    parser.add_argument("--report", metavar="PATH", help="the HTML report to write")
    parser.add_argument("--csv", metavar="PATH", dest="residuals_csv",
                        help="the residuals to write as CSV (every checkpoint, skipped ones with empty dz)")
    _add_json(parser, ACCURACY_JSON)
    parser.set_defaults(filter="accuracy")


def run_accuracy(args, out) -> dict:
    """Run ``accuracy``; return its JSON document (the figures are also logged to ``out``)."""
    from ..io.checkpoints import UnknownLandCover, parse_land_cover_mapping, read_checkpoints
    from ..raster import accuracy as A
    try:
        checkpoints = read_checkpoints(args.checkpoints, mapping=parse_land_cover_mapping(args.land_cover_map),
                                       columns={"z": args.z_column, "id": args.id_column,
                                                "land_cover": args.land_cover_column})
    except UnknownLandCover as err:
        raise UnknownLandCover(f"{err} with --land-cover-map") from None
    A.check_accuracy_outputs([args.dtm, args.checkpoints], args.report, args.residuals_csv)
    result = A.check_accuracy_of(args.dtm, checkpoints, band=args.band)
    A.write_outputs(result, args.report, args.residuals_csv)
    for line in A.summary_lines(result):
        print(line, file=out)
    for text in result.warnings:
        print(f"WARNING: {text}", file=out)
    return dict({"status": "done"}, **A.document(result), report=args.report, csv=args.residuals_csv)


def _add_tune(sub) -> None:
    from .tune import METRICS, SELECTIONS, TuneOptions
    d = _defaults(TuneOptions)
    parser = sub.add_parser("tune", help="tune a filter on a labelled patch: a preset file and an HTML report",
                            description="Search a filter's parameters on a labelled patch (class 2 = ground, or "
                                        "ISPRS text label 0 = ground) with spatial-block cross-validation; write "
                                        "the best set as a preset (--preset of every filter) and an HTML report.")
    parser.add_argument("--input", required=True, metavar="PATH", help="labelled LAS/LAZ or ISPRS .txt patch")
    parser.add_argument("--filter", required=True, choices=list(P.FILTERS), dest="tune_filter")
    parser.add_argument("--metric", choices=list(METRICS), default=d["metric"],
                        help="total = total error (ISPRS), kappa, f1 = F1 of ground (default %(default)s)")
    parser.add_argument("--budget", type=int, default=d["budget"], metavar="N",
                        help="filter runs to spend (SMRF re-scores threshold and scalar on each run for "
                             "free; default %(default)s)")
    parser.add_argument("--blocks", type=int, default=d["blocks"], metavar="K",
                        help="spatial blocks of the cross-validation (default %(default)s)")
    parser.add_argument("--seconds", type=float, default=d["seconds"], metavar="S",
                        help="stop starting new sets after this long (0 = no limit; default %(default)s)")
    parser.add_argument("--selection", choices=SELECTIONS, default=d["selection"],
                        help="best: the set with the lowest error; one-se: of the sets within one standard "
                             "error of it, the one nearest the starting set (default %(default)s)")
    parser.add_argument("--start", metavar="FILE", help="a preset to start from (its other parameters are kept)")
    parser.add_argument("--preset-out", metavar="PATH", help="the preset file to write (.json)")
    parser.add_argument("--report", metavar="PATH", help="the HTML report to write")
    _add_json(parser, TUNE_JSON)
    parser.set_defaults(filter="tune")


class _Usage(Exception):
    """Bad usage found after parsing (exit status 2), with its one-line message."""


def run_tune(args, out) -> dict:
    """Run ``tune``; return its JSON document (the summary is also logged to ``out``)."""
    from .presets import load_preset, write_preset
    from .tune import TuneOptions, check_tune_outputs, preset_source, preset_values, tune
    from .tune_report import write_report
    if not args.preset_out and not args.report:
        raise _Usage("give --preset-out and/or --report")
    check_tune_outputs(args.input, args.preset_out, args.report)
    base = load_preset(args.start, args.tune_filter).values if args.start else None
    result = tune(args.input, args.tune_filter,
                  TuneOptions(metric=args.metric, budget=args.budget, blocks=args.blocks, seconds=args.seconds,
                              selection=args.selection),
                  base=base, progress=_progress_printer(out), is_cancelled=_interrupt_seen,
                  log=lambda msg: print(msg, file=out, flush=True))
    if args.preset_out:
        write_preset(args.preset_out, args.tune_filter, preset_values(result), source=preset_source(result),
                     description=f"tuned on {result.patch} ({result.metric}, {len(result.trials)} sets)")
    if args.report:
        write_report(args.report, result)
    table = P.by_name(args.tune_filter)
    best = ", ".join(f"{table[dim.name].option} {result.best_values[dim.field]}" for dim in result.dims)
    print(f"{len(result.trials)} sets in {result.runs} filter runs, {result.seconds:.0f} s; cross-validated total error "
          f"{100 * result.cv.total:.2f} % (kappa {100 * result.cv.kappa:.2f} %); chosen: {best}", file=out)
    for _title, text in result.warnings:
        print(f"WARNING: {text}", file=out)
    return tune_document(args, result)


def tune_document(args, result) -> dict:
    """The ``--json`` document of a tune run: the preset's parameters (field -> value), the searched
    fields, the cross-validated figures (the honest ones) and the in-sample ones on the patch."""
    from .tune import preset_values
    cv, fit = result.cv, result.best_accuracy
    return {"status": "done", "input": args.input, "filter": result.filter, "metric": result.metric,
            "selection": result.selection, "parameters": preset_values(result),
            "searched": [dim.field for dim in result.dims],
            "cv": {"total_error": cv.total, "kappa": cv.kappa, "f1": cv.f1, "blocks": len(result.folds)},
            "patch": {"points": result.points, "total_error": fit.total, "kappa": fit.kappa, "f1": fit.f1},
            "sets": len(result.trials), "runs": result.runs, "budget": result.budget,
            "seconds": round(result.seconds, 3), "stopped": result.stopped or None,
            "preset": args.preset_out, "report": args.report, "warnings": [text for _t, text in result.warnings]}


def _raster_outputs(args) -> dict:
    """{path: f(run) -> (values, grid[, format])} of the evc rasters asked for (``--KEY-raster PATH``)."""
    from ..filters.evc import EVC_RASTERS
    return {getattr(args, f"raster_{key}"): (lambda run, make=make: make(run.detail))
            for key, (_label, make) in EVC_RASTERS.items() if getattr(args, f"raster_{key}", None)}


def _check_outputs_named(args, out) -> None:
    """A filter's or rfclassify's outputs: at least one of --output and --dtm (or an evc raster); the DTM's
    options typed without a --dtm are said to do nothing."""
    if not args.output and not args.dtm and not _raster_outputs(args):
        raise _Usage("give --output and/or --dtm" + (" (or an evc raster)" if args.filter == "evc" else ""))
    for flag, unset in (("--dtm-cell", not getattr(args, "dtm_cell_typed", False)),
                        ("--dtm-classes", not args.dtm_classes), ("--dtm-max-distance", not args.dtm_max_distance),
                        ("--dtm-extent", not args.dtm_extent)):
        if not args.dtm and not unset:
            print(f"groundsieve: {flag} is set but no --dtm is named: no DTM is made", file=out)


def run_filter(args, out) -> dict:
    """Run a filter (or the hybrid); return its JSON document (the summary is also logged to ``out``)."""
    _check_outputs_named(args, out)
    warnings, log = _collecting_log(out)
    algorithm, options, dtm = options_from(args, log)
    return _run_documented(args, out, algorithm, options, dtm, warnings, log, "ground")


def _collecting_log(out):
    """(the run's warnings, a log that prints each line to ``out`` and collects the warnings): the CRS's unit,
    said before the work, and the rest, for --json too."""
    from ..progress import collecting_warnings
    return collecting_warnings(lambda msg: print(msg, file=out, flush=True))


def _run_documented(args, out, algorithm, options, dtm, warnings, log, ground_words: str) -> dict:
    """Run ``algorithm`` on ``args.input`` as the filters and the DTM from classes run (the compile note,
    progress, interrupts); its JSON document, its summary logged to ``out``."""
    from .workflow import run_ground_filter
    start = time.monotonic()
    rasters = _raster_outputs(args)
    with _kernels_of(args.filter, out):
        run = run_ground_filter(args.input, args.output, algorithm, options=options, dtm_path=args.dtm, dtm=dtm,
                                rasters=rasters or None, progress=_progress_printer(out),
                                is_cancelled=_interrupt_seen, log=log)
    document = filter_document(args, algorithm, run, time.monotonic() - start, warnings)
    if rasters:
        document["rasters"] = list(rasters)
    print(f"{document['points']:,} points, {document['ground']:,} {ground_words}.", file=out)
    return document


def filter_document(args, algorithm, run, seconds: float, warnings=()) -> dict:
    """The ``--json`` document of a filter run, from what the run returned: a ``FilterRun`` (one
    cloud in memory: ``tiles`` is null) or a tiled run's ``TiledRun``."""
    tiled = run.cloud is None
    return {"status": "done", "input": args.input, "output": args.output,
            "outputs": list(run.outputs) if tiled else [p for p in [args.output] if p],
            "dtm": run.dtm_path if tiled else (args.dtm or None),
            "points": int(run.point_count if tiled else len(run.cloud)), "ground": int(run.ground_count),
            "seconds": round(seconds, 3), "tiles": int(run.tiles) if tiled else None,
            "tile_size": float(run.tile_size_m) if tiled else None,
            "tile_buffer": float(run.buffer_m) if tiled else None,
            "algorithm": args.filter, "parameters": filter_parameters(getattr(run, "algorithm", None) or algorithm),
            "warnings": list(warnings)}


def filter_parameters(algorithm) -> dict:
    """field -> value of a filter object's parameters (its dataclass fields set by the caller)."""
    return {f.name: getattr(algorithm, f.name) for f in dataclasses.fields(algorithm) if f.init}


def _jsonable(value):
    """``value`` as plain JSON: numpy scalars as Python numbers, NaN and infinities as null, tuples
    and sets as lists, paths as text."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [_jsonable(v) for v in value]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if type(value).__module__ == "numpy" and hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(stream, document: dict) -> None:
    """Write ``document`` as one line of strict JSON (no NaN) to ``stream``."""
    stream.write(json.dumps(_jsonable(document), allow_nan=False) + "\n")
    stream.flush()


@contextlib.contextmanager
def _stdout_to(log):
    """While a ``--json`` run works, whatever would reach stdout goes to ``log`` instead: Python's
    prints, and (when stdout is a real file descriptor, as under ``python -m groundsieve``) what
    a library or a worker process started meanwhile writes to descriptor 1; stdout is then left
    to the JSON document alone."""
    moved = None
    try:
        fd, log_fd = sys.stdout.fileno(), log.fileno()
    except (AttributeError, OSError, ValueError):  # a StringIO (tests), a closed stream: Python's level only
        fd = log_fd = None
    if fd is not None and fd != log_fd:
        sys.stdout.flush()
        moved = os.dup(fd)
        os.dup2(log_fd, fd)
    try:
        with contextlib.redirect_stdout(log):
            yield
    finally:
        if moved is not None:
            sys.stdout.flush()
            os.dup2(moved, fd)
            os.close(moved)


def _progress_printer(out):
    last = [0.0]

    def progress(fraction):
        now = time.monotonic()
        if now - last[0] > 5 or fraction >= 1:
            last[0] = now
            print(f"{100 * fraction:5.1f} %", file=out, flush=True)
    return progress


def options_from(args, log=None):
    """(algorithm, FilterOptions, DTMOptions) from parsed arguments; ``log`` gets the parameters
    the run uses (and which came from the preset)."""
    from .presets import describe, load_preset
    given = {k[2:]: v for k, v in vars(args).items() if k.startswith("f_")}
    preset = None
    if args.filter == "hybrid":
        from ..learn.hybrid import Hybrid
        algorithm = Hybrid(**given)
    elif getattr(args, "preset", None):
        preset = load_preset(args.preset, args.filter)
        algorithm = preset.build(given, typed=getattr(args, "typed", None) or ())
    else:
        algorithm = P.mark_user_set(P.filter_class(args.filter)(**given), getattr(args, "typed", None) or ())
    if log is not None and args.filter != "hybrid":
        for line in describe(args.filter, algorithm, preset, typed_wins=True):  # (what is typed wins)
            log(line)
    tiling = _tiling(args)
    options = FilterOptions(last_returns_only=args.last_returns, ignore_noise=args.ignore_noise,
                            ignore_classes=args.ignore_classes, keep_existing_classes=args.keep_classes,
                            tiling=tiling)
    return algorithm, options, dtm_options(args)


def dtm_options(args, classes: bool = True) -> DTMOptions:
    """The DTM's options of the command line (_add_dtm_options), ``classes``: with --dtm-classes."""
    return DTMOptions(cell_size_m=args.dtm_cell, cell_set=bool(getattr(args, "dtm_cell_typed", False)),
                      fill_outside_hull=args.dtm_fill, classes=args.dtm_classes if classes else (),
                      max_distance_m=args.dtm_max_distance, extent=args.dtm_extent or None)


def _tiling(args) -> TileOptions:
    return TileOptions(tile_size_m=args.tile_size, buffer_m=None if args.tile_buffer < 0 else args.tile_buffer,
                       memory_budget_mb=args.memory_budget, workers=args.workers,
                       work_dir=args.work_folder or None, scheduler=args.scheduler or "", only=_only(args.only))


def _only(value) -> str:
    """--only's file, refused when given empty: an array's task id unset would run every file."""
    if value is not None and not value.strip():
        raise InvalidParameterError("--only is empty: give one file of the survey (its number from 0, its name or its "
                                    "path); in a job array, is $SLURM_ARRAY_TASK_ID set (sbatch --array)?")
    return value or ""


#: set once the run has ended (its outputs in place or its error said): a SIGTERM then changes nothing
#: (``python -m groundsieve`` ignores it instead of ending a finished run as killed)
FINISHED = [False]
#: set by ``python -m groundsieve``'s handler when Ctrl-C or SIGTERM came during the run: its
#: KeyboardInterrupt, raised inside lazrs's writer, came back as "LazrsError: IoError: Failed to call
#: write" (a QA reviewer: a traceback and "failed / other" for 6 of 7 signals while a LAZ was written)
INTERRUPT_SEEN = [False]


def _interrupt_seen() -> bool:
    """The run's cancel check: an interrupt whose KeyboardInterrupt a library swallowed (GDAL's writer:
    a Ctrl-C during the DTM's write ended "done") still stops the run before its outputs are put in place."""
    return INTERRUPT_SEEN[0]

#: the exit status of an interrupted run (128 + SIGINT, as shells report Ctrl-C)
INTERRUPTED = 130
#: the exit status of a run the Dask cluster failed (sysexits' EX_TEMPFAIL: a job wrapper may retry it once the
#: cluster is back; a refusal, 1, would fail again: a research software engineer's SLURM --requeue)
EXIT_RETRY = 75
#: the exit status of an internal error (an exception that is no refusal of ours: a traceback, a bug)
EXIT_BUG = 3


def _wants_json(argv: List[str]) -> bool:
    """Whether the raw arguments ask for ``--json`` (or an abbreviation argparse takes for it)."""
    return any(a.startswith("--j") and "--json".startswith(a) for a in argv)


def _run(args, out):
    """(exit status, JSON document) of the command, the log and the one-line errors on ``out``."""
    try:
        run = {"tune": run_tune, "dtm": run_dtm, "accuracy": run_accuracy, "rftrain": run_rftrain,
               "rfclassify": run_rfclassify, "features": run_features_command}.get(args.filter, run_filter)
        return 0, run(args, out)
    except _Usage as err:
        print(f"groundsieve: {err}", file=out)
        return 2, {"status": "failed", "kind": "usage", "error": str(err)}
    except KeyboardInterrupt:
        return _interrupted(out)
    except GroundSieveError as err:  # Cancelled too
        if INTERRUPT_SEEN[0]:  # (the interrupt came back as a library's error, wrapped as ours)
            return _interrupted(out)
        print(f"groundsieve: {err}", file=out)
        kind = error_kind(err)
        return EXIT_RETRY if kind == "cluster" else 1, {"status": "failed", "kind": kind, "error": str(err)}
    except MemoryError as err:  # (out of memory where no step of ours named it: a ulimit -v or a cgroup's limit)
        if INTERRUPT_SEEN[0]:
            return _interrupted(out)
        from ..errors import out_of_memory
        message = str(out_of_memory(args.input if hasattr(args, "input") else "the run", err))
        print(f"groundsieve: {message}", file=out)
        return 1, {"status": "failed", "kind": "memory", "error": message}
    except Exception:
        if INTERRUPT_SEEN[0]:  # the interrupt, come back as a library's error (lazrs: LazrsError)
            return _interrupted(out)
        raise


def _interrupted(out):
    print("groundsieve: interrupted", file=out)
    return INTERRUPTED, {"status": "interrupted", "kind": "interrupted", "error": "interrupted"}


def error_kind(err: BaseException) -> str:
    """A failure's kind for scripts (``--json``'s "kind"): "input", "parameter", "memory", "output",
    "cluster" (the Dask cluster: often worth a retry once it is back), "cancelled" or "other"."""
    from ..errors import Cancelled, InputError, InvalidParameterError, MemoryBudgetError, OutputError
    from .cluster import ClusterError
    for cls, kind in ((Cancelled, "cancelled"), (MemoryBudgetError, "memory"), (ClusterError, "cluster"),
                      (InputError, "input"), (InvalidParameterError, "parameter"), (OutputError, "output")):
        if isinstance(err, cls):
            return kind
    return "other"


def main(argv: Optional[List[str]] = None, out=None, stdout=None) -> int:
    """Run the command; 0 = done, 1 = refused or failed (the message, no traceback), 2 = bad usage,
    75 = the Dask cluster failed, 130 = interrupted (Ctrl-C; SIGTERM too under ``python -m groundsieve``;
    an internal error raises, which ``python -m groundsieve`` ends with EXIT_BUG). The log goes to ``out``
    (stderr); with ``--json`` one JSON document goes to ``stdout`` (sys.stdout) at the end."""
    out = out or sys.stderr
    FINISHED[0] = INTERRUPT_SEEN[0] = False
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        args = build_parser().parse_args(argv)
    except UsageExit as err:  # bad usage (2): argparse has said why on stderr
        if _wants_json(argv):
            write_json(stdout or sys.stdout, {"status": "failed", "kind": "usage", "error": err.message})
        raise
    if not args.json:
        code = _run(args, out)[0]
        FINISHED[0] = True
        return code
    try:
        with _stdout_to(out):
            code, document = _run(args, out)
            FINISHED[0] = True
    except Exception as err:  # not a refusal: the traceback as without --json, and the document still
        write_json(stdout or sys.stdout, {"status": "failed", "kind": "other", "error": f"{type(err).__name__}: {err}"})
        raise
    write_json(stdout or sys.stdout, document)
    return code
