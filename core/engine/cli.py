"""The headless command: ``python -m groundsieve <filter> --input X --output Y [options]``.

No QGIS: the core alone, for servers and cluster jobs. The options are the Processing
algorithms' parameters under the same names (``DTM_CELL`` -> ``--dtm-cell``), defaults and
units, made from one definition (``parameters.py`` and the core's option dataclasses); the
filters' finer settings the dialog does not show are offered too. ``--scheduler`` sends the
tiles to a Dask cluster (``local:N`` or ``tcp://host:port``; engine/cluster.py).

``--preset FILE`` (every filter) takes a preset (engine/presets.py): it replaces the filter's
defaults; options given with a value other than the default win over it.
``python -m groundsieve tune --input patch.laz --filter smrf --preset-out smrf.json --report
tune.html`` tunes a filter on a labelled patch (engine/tune.py).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from typing import List, Optional

from ..errors import Cancelled, GroundSieveError
from . import parameters as P
from .tiles import TileOptions
from .workflow import DTMOptions, FilterOptions


def _defaults(cls):
    return {f.name: f.default for f in dataclasses.fields(cls)}


def _number(kind):
    return {int: int, float: float}.get(kind, str)


def _add_common(parser: argparse.ArgumentParser) -> None:
    fo, dt, to = _defaults(FilterOptions), _defaults(DTMOptions), _defaults(TileOptions)
    io = parser.add_argument_group("input and outputs")
    io.add_argument("--input", required=True, metavar="PATH",
                    help="LAS/LAZ (1.2-1.4, point formats 0-10), a folder of them, a .vpc, or an ISPRS .txt")
    io.add_argument("--output", metavar="PATH", help="classified LAS/LAZ (a .vpc for several input files)")
    io.add_argument("--dtm", metavar="PATH", help="DTM GeoTIFF (optional)")
    io.add_argument("--dtm-cell", type=float, default=dt["cell_size_m"], metavar="M",
                    help="DTM cell size (m; default %(default)s)")
    io.add_argument("--dtm-fill", action=argparse.BooleanOptionalAction, default=dt["fill_outside_hull"],
                    help="fill DTM cells outside the ground hull (nearest value; default %(default)s)")
    io.add_argument("--dtm-classes", default="", metavar="LIST",
                    help="classes of the input whose points enter the DTM with the ground, e.g. 9 (water) for "
                         "a flood model; a list or ranges as --ignore-classes (default none)")
    io.add_argument("--dtm-max-distance", type=float, default=dt["max_distance_m"], metavar="M",
                    help="leave DTM cells farther than this from any ground point empty, so that data gaps are "
                         "not bridged (m; 0 = no limit; default %(default)s)")
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
    tiles = parser.add_argument_group("survey scale: tiles")
    tiles.add_argument("--tile-size", type=float, default=to["tile_size_m"], metavar="M",
                       help="tile size (m; 0 = from the memory budget; default %(default)s)")
    tiles.add_argument("--tile-buffer", type=float, default=-1.0, metavar="M",
                       help="tile buffer (m; -1 = the filter's own reach; default %(default)s)")
    tiles.add_argument("--memory-budget", type=float, default=to["memory_budget_mb"], metavar="MB",
                       help="memory budget (MB; 0 = a quarter of the RAM, at most 2048; default %(default)s)")
    tiles.add_argument("--workers", type=int, default=to["workers"], metavar="N",
                       help="tiles at the same time on this machine (0 = every core; default %(default)s)")
    tiles.add_argument("--work-folder", metavar="PATH",
                       help="working folder for temporary tiles (default: beside the output); with a Dask "
                            "scheduler, on a file system every worker sees at the same path")
    tiles.add_argument("--scheduler", default=to["scheduler"], metavar="ADDRESS",
                       help="Dask scheduler: empty = this machine, local:N = a local Dask cluster of N worker "
                            "processes, tcp://host:port = a running scheduler (needs dask[distributed]; the "
                            "workers must see the input and working folder at the same paths)")


def _add_filter(sub, name: str) -> None:
    summary = P.SUMMARY[name]
    parser = sub.add_parser(name, help=summary, description=f"{summary}. Lengths in the unit of the cloud's CRS.")
    _add_common(parser)
    group = parser.add_argument_group(f"{name} parameters (as in the Processing dialog)")
    group.add_argument("--preset", metavar="FILE",
                       help="a preset file of this filter (groundsieve tune, or a shipped preset's name): it "
                            "replaces the defaults; options set to other values than the defaults win")
    for p in P.params(name):
        _add_param(group, name, p.field, p.option, p.title() + (
            " (" + " | ".join(f"{v} = {label}" for v, label in zip(p.choices, p.choice_labels)) + ")"
            if p.choices else ""), p.choices)
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


def _add_param(group, name, field, option, title, choices) -> None:
    value = P.default(name, field)
    kind = P.field_type(name, field)
    if kind is bool:
        group.add_argument(option, dest="f_" + field, action=argparse.BooleanOptionalAction, default=value,
                           help=f"{title}; default {'on' if value else 'off'}")
    else:
        group.add_argument(option, dest="f_" + field, type=_number(kind), default=value,
                           choices=list(choices) or None, metavar=None if choices else "X",
                           help=f"{title}; default {value}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m groundsieve",
        description="Ground filtering of point clouds (LAS/LAZ, folders, .vpc) without QGIS: classified "
                    "LAS/LAZ (ground = 2, other = 1) and an optional DTM GeoTIFF. Lengths in the unit of "
                    "the cloud's CRS (metres for a metric CRS). `python -m groundsieve FILTER --help` lists "
                    "a filter's parameters.",
        epilog="Exit status: 0 done, 1 refused or failed (one line saying why), 2 bad usage, 130 interrupted "
               "(Ctrl-C or SIGTERM; a survey's finished tiles are kept in --work-folder, when given, for the "
               "next run to resume). The log goes to stderr.")
    sub = parser.add_subparsers(title="filters", metavar="FILTER", required=True)
    for name in P.FILTERS:
        _add_filter(sub, name)
    _add_hybrid(sub)
    _add_tune(sub)
    return parser


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
    parser.set_defaults(filter="tune")


def run_tune(args, out) -> int:
    from .presets import load_preset, write_preset
    from .tune import TuneOptions, preset_source, preset_values, tune
    from .tune_report import write_report
    if not args.preset_out and not args.report:
        print("groundsieve: give --preset-out and/or --report", file=out)
        return 2
    base = load_preset(args.start, args.tune_filter).values if args.start else None
    result = tune(args.input, args.tune_filter,
                  TuneOptions(metric=args.metric, budget=args.budget, blocks=args.blocks, seconds=args.seconds,
                              selection=args.selection),
                  base=base, progress=_progress_printer(out), log=lambda msg: print(msg, file=out, flush=True))
    if args.preset_out:
        write_preset(args.preset_out, args.tune_filter, preset_values(result), source=preset_source(result),
                     description=f"tuned on {result.patch} ({result.metric}, {len(result.trials)} sets)")
    if args.report:
        write_report(args.report, result)
    table = P.by_name(args.tune_filter)
    best = ", ".join(f"{table[dim.name].option} {result.best_values[dim.field]}" for dim in result.dims)
    print(f"{len(result.trials)} sets in {result.seconds:.0f} s; cross-validated total error "
          f"{100 * result.cv.total:.2f} % (kappa {100 * result.cv.kappa:.2f} %); chosen: {best}", file=out)
    for _title, text in result.warnings:
        print(f"WARNING: {text}", file=out)
    return 0


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
        algorithm = preset.build(given)
    else:
        algorithm = P.filter_class(args.filter)(**given)
    if log is not None and args.filter != "hybrid":
        for line in describe(args.filter, algorithm, preset):
            log(line)
    tiling = TileOptions(tile_size_m=args.tile_size, buffer_m=None if args.tile_buffer < 0 else args.tile_buffer,
                         memory_budget_mb=args.memory_budget, workers=args.workers,
                         work_dir=args.work_folder or None, scheduler=args.scheduler or "")
    options = FilterOptions(last_returns_only=args.last_returns, ignore_noise=args.ignore_noise,
                            ignore_classes=args.ignore_classes, keep_existing_classes=args.keep_classes,
                            tiling=tiling)
    return algorithm, options, DTMOptions(cell_size_m=args.dtm_cell, fill_outside_hull=args.dtm_fill,
                                          classes=args.dtm_classes, max_distance_m=args.dtm_max_distance)


#: the exit status of an interrupted run (128 + SIGINT, as shells report Ctrl-C)
INTERRUPTED = 130


def main(argv: Optional[List[str]] = None, out=None) -> int:
    """Run the command; 0 = done, 1 = refused or failed (the message, no traceback), 2 = bad usage,
    130 = interrupted (Ctrl-C; SIGTERM too under ``python -m groundsieve``)."""
    from .workflow import run_ground_filter
    out = out or sys.stderr
    args = build_parser().parse_args(argv)
    if args.filter == "tune":
        try:
            return run_tune(args, out)
        except KeyboardInterrupt:
            print("groundsieve: interrupted", file=out)
            return INTERRUPTED
        except GroundSieveError as err:
            print(f"groundsieve: {err}", file=out)
            return 1
    if not args.output and not args.dtm:
        print("groundsieve: give --output and/or --dtm", file=out)
        return 2
    for flag, unset in (("--dtm-cell", args.dtm_cell == _defaults(DTMOptions)["cell_size_m"]),
                        ("--dtm-classes", not args.dtm_classes), ("--dtm-max-distance", not args.dtm_max_distance)):
        if not args.dtm and not unset:
            print(f"groundsieve: {flag} is set but no --dtm is named: no DTM is made", file=out)
    progress = _progress_printer(out)
    try:
        log = lambda msg: print(msg, file=out, flush=True)  # noqa: E731
        algorithm, options, dtm = options_from(args, log)
        run = run_ground_filter(args.input, args.output, algorithm, options=options, dtm_path=args.dtm, dtm=dtm,
                                progress=progress, log=log)
    except KeyboardInterrupt:
        print("groundsieve: interrupted", file=out)
        return INTERRUPTED
    except Cancelled as err:
        print(f"groundsieve: {err}", file=out)
        return 1
    except GroundSieveError as err:
        print(f"groundsieve: {err}", file=out)
        return 1
    from ..raster.crs import unit_warning
    warning = unit_warning(args.input, run.crs_wkt, "every length parameter (cell sizes, windows, thresholds)")
    if warning:
        print(f"WARNING: {warning}", file=out)
    points = run.point_count if run.cloud is None else len(run.cloud)
    print(f"{points:,} points, {run.ground_count:,} ground.", file=out)
    return 0
