#!/usr/bin/env python3
"""groundsieve:tune on the ISPRS samples: cross-validated error of the tuned SMRF against the
error of Pingel's published per-sample optimum (isprs_smrf_settings.txt) run in the same script.

Usage (from the repository root):

    .venv/bin/python bench/tune.py --data ../shared/data/isprs [--filter smrf] [--budget 120]
        [--blocks 4] [--metric total] [--samples samp11,samp21] [--out FOLDER]

Prints a markdown table per sample: points; total error of Pingel's set (our SMRF, cell 1 m);
the tuned filter's cross-validated total error (pooled held-out blocks, the honest figure) and
the target (Pingel + 0.3 points); the chosen set's in-sample error on the whole patch; the
defaults' error; sets tried and seconds of the search. ``--out`` keeps each preset and report.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

from _checkout import REPO  # noqa: F401 (puts this checkout's groundsieve on sys.path)

from isprs import find_samples, read_params, sample_name  # noqa: E402

from groundsieve.core.engine import tune as T  # noqa: E402
from groundsieve.core.engine.presets import write_preset  # noqa: E402
from groundsieve.core.engine.tune_report import write_report  # noqa: E402
from groundsieve.core.filters.smrf import SMRF  # noqa: E402
from groundsieve.core.io import read_cloud  # noqa: E402
from groundsieve.core.metrics import ground_accuracy  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--filter", default="smrf")
    ap.add_argument("--budget", type=int, default=T.TuneOptions.budget, help="filter runs per sample")
    ap.add_argument("--blocks", type=int, default=T.TuneOptions.blocks)
    ap.add_argument("--seconds", type=float, default=T.TuneOptions.seconds, help="time limit per sample (0 = none)")
    ap.add_argument("--metric", default="total", choices=T.METRICS)
    ap.add_argument("--selection", default=T.TuneOptions.selection, choices=T.SELECTIONS)
    ap.add_argument("--samples", default="")
    ap.add_argument("--out", default="")
    args = ap.parse_args(argv)
    settings = os.path.join(args.data, "isprs_smrf_settings.txt")
    rows = read_params(settings) if os.path.exists(settings) else {}
    wanted = {s for s in args.samples.split(",") if s}
    print(f"filter {args.filter}, metric {args.metric}, budget {args.budget} sets, {args.blocks} blocks, "
          f"time limit {args.seconds:g} s\n")
    print("| Sample | Points | Pingel's set total % | target % | tuned CV total % | met | tuned in-sample % "
          "| defaults % | runs / sets | seconds | CPU s |")
    print("|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|")
    sums = [0.0, 0.0, 0.0, 0.0]
    met_all, n = True, 0
    for path in find_samples(args.data):
        name = sample_name(path)
        if wanted and name not in wanted:
            continue
        cloud = read_cloud(path)
        ref = cloud.reference_label == 0
        row = rows.get(name)
        pingel = None
        if row:
            algo = SMRF(cell_size_m=1.0, slope=float(row["slope_threshold"]), window_m=float(row["windows"]),
                        elevation_threshold_m=float(row["elevation_threshold"]),
                        elevation_scalar=float(row["elevation_scaler"]))
            pingel = ground_accuracy(ref, algo(cloud.xyz)).total
        t0, c0 = time.perf_counter(), time.process_time()
        result = T.tune(cloud, args.filter, T.TuneOptions(metric=args.metric, budget=args.budget,
                                                          blocks=args.blocks, seconds=args.seconds,
                                                          selection=args.selection))
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        cv, fit, start = result.cv.total, result.best_accuracy.total, result.start_accuracy.total
        target = None if pingel is None else pingel + 0.003
        met = "" if target is None else ("yes" if cv <= target + 1e-12 else "NO")
        met_all &= met != "NO"
        if args.out:
            os.makedirs(args.out, exist_ok=True)
            write_preset(os.path.join(args.out, f"{name}-{args.filter}.json"), args.filter,
                         T.preset_values(result), source=T.preset_source(result))
            write_report(os.path.join(args.out, f"{name}-{args.filter}.html"), result)
        f = (lambda v: "" if v is None else f"{100 * v:.2f}")
        print(f"| {name} | {result.points} | {f(pingel)} | {f(target)} | {f(cv)} | {met} | {f(fit)} | {f(start)} "
              f"| {result.runs} / {len(result.trials)} | {seconds:.0f} | {cpu:.0f} |", flush=True)
        for i, v in enumerate((pingel or 0.0, cv, fit, start)):
            sums[i] += v
        n += 1
    if n:
        print(f"| **mean** | | {100 * sums[0] / n:.2f} | | {100 * sums[1] / n:.2f} | | {100 * sums[2] / n:.2f} "
              f"| {100 * sums[3] / n:.2f} | | | |")
    return 0 if met_all else 1


if __name__ == "__main__":
    sys.exit(main())
