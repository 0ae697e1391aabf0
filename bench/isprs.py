#!/usr/bin/env python3
"""Accuracy of a ground filter on the ISPRS WG III/3 reference samples.

Usage (from the repository root):

    .venv/bin/python bench/isprs.py --filter smrf --data ../shared/data/isprs \
        [--params ../shared/data/isprs/isprs_smrf_settings.txt] [--csv OUT.csv]

``--data`` is a folder of samples: ISPRS text files ``samp*.txt`` (column 4:
0 = ground, 1 = object) or LAS/LAZ files ``samp*.las|laz`` (class 2 = ground).
``--params`` is a per-sample parameter CSV in the layout of Pingel's
``isprs_smrf_settings.txt`` (filename, slope_threshold, windows,
elevation_threshold, elevation_scaler); rows are matched by sample name
(``samp11`` for ``samp11.txt`` and ``samp11-utm.laz``). Without it, every sample
runs with the filter's default parameters.

Prints a markdown table of Type I, Type II, total error and Cohen's kappa (ISPRS
definitions, in %) per sample and their means, and the filter time per sample.

A new filter is added by one entry in :data:`FILTERS`: a name mapped to a
function ``(params row or None) -> filter``, where the filter is a callable
``filter(xyz) -> bool ground mask`` (as :class:`groundsieve.core.filters.smrf.SMRF`).
"""
from __future__ import annotations

import argparse
import csv
import glob
import os
import re
import sys
import time
from pathlib import Path
from typing import Callable, Dict, List, Optional

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core.io import CLASS_GROUND, read_cloud  # noqa: E402
from groundsieve.core.metrics import GroundAccuracy, ground_accuracy  # noqa: E402

from filters import FILTERS  # noqa: E402

ParamsRow = Optional[Dict[str, str]]


# ---------------------------------------------------------------------------------------------
# Samples and parameters
# ---------------------------------------------------------------------------------------------

_SAMPLE_RE = re.compile(r"^(samp\d+)", re.IGNORECASE)


def sample_name(path: str) -> str:
    """``samp11`` for ``samp11.txt``, ``samp11-utm.laz``, ...; else the file's stem."""
    stem = Path(path).name.split(".")[0]
    m = _SAMPLE_RE.match(stem)
    return m.group(1).lower() if m else stem


def find_samples(folder: str) -> List[str]:
    files = []
    for pattern in ("samp*.txt", "samp*.las", "samp*.laz"):
        files += glob.glob(os.path.join(folder, pattern))
    return sorted(files, key=lambda p: (sample_name(p), p))


def read_params(path: str) -> Dict[str, Dict[str, str]]:
    """Rows of a per-sample parameter CSV keyed by sample name."""
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        rows = {}
        for row in reader:
            row = {k.strip(): (v or "").strip() for k, v in row.items() if k is not None}
            if row.get("filename"):
                rows[sample_name(row["filename"])] = row
    if not rows:
        raise SystemExit(f"{path}: no parameter rows found")
    return rows


def reference_ground(cloud) -> np.ndarray:
    """ISPRS text: label 0 = ground; LAS/LAZ: class 2 = ground."""
    if cloud.reference_label is not None:
        return cloud.reference_label == 0
    return cloud.classification == CLASS_GROUND


# ---------------------------------------------------------------------------------------------

def run(filter_name: str, data: str, params: Optional[str]) -> List[dict]:
    factory = FILTERS[filter_name]
    rows = read_params(params) if params else None
    samples = find_samples(data)
    if not samples:
        raise SystemExit(f"{data}: no samp*.txt / samp*.las / samp*.laz file found")
    results = []
    for path in samples:
        name = sample_name(path)
        row = None
        if rows is not None:
            row = rows.get(name)
            if row is None:
                print(f"warning: {name}: no row in {params}; skipped", file=sys.stderr)
                continue
        algorithm = factory(row)
        cloud = read_cloud(path)
        ref = reference_ground(cloud)
        t0 = time.perf_counter()
        ground = np.asarray(algorithm(cloud.xyz), dtype=bool)
        seconds = time.perf_counter() - t0
        acc = ground_accuracy(ref, ground)
        results.append({"sample": name, "file": os.path.basename(path), "points": len(cloud),
                        "type1": 100 * acc.type1, "type2": 100 * acc.type2,
                        "total": 100 * acc.total, "kappa": 100 * acc.kappa,
                        "seconds": seconds, "accuracy": acc})
    return results


def markdown_table(results: List[dict]) -> str:
    lines = ["| Sample | Points | Type I % | Type II % | Total % | Kappa % | Time s |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        lines.append(f"| {r['sample']} | {r['points']} | {r['type1']:.2f} | {r['type2']:.2f} | "
                     f"{r['total']:.2f} | {r['kappa']:.2f} | {r['seconds']:.2f} |")
    if results:
        mean = {k: float(np.mean([r[k] for r in results])) for k in ("type1", "type2", "total", "kappa")}
        total_s = sum(r["seconds"] for r in results)
        lines.append(f"| **mean** | {sum(r['points'] for r in results)} | {mean['type1']:.2f} | "
                     f"{mean['type2']:.2f} | {mean['total']:.2f} | {mean['kappa']:.2f} | "
                     f"{total_s:.2f} (sum) |")
    return "\n".join(lines)


def write_csv(results: List[dict], path: str) -> None:
    keys = ["sample", "file", "points", "type1", "type2", "total", "kappa", "seconds"]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys + ["tp", "fn", "fp", "tn"])
        for r in results:
            acc: GroundAccuracy = r["accuracy"]
            w.writerow([r[k] if not isinstance(r[k], float) else f"{r[k]:.4f}" for k in keys]
                       + [acc.tp, acc.fn, acc.fp, acc.tn])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--filter", default="smrf", choices=sorted(FILTERS), help="ground filter to run")
    ap.add_argument("--data", required=True, help="folder of samp*.txt or samp*.las/laz files")
    ap.add_argument("--params", help="per-sample parameter CSV (Pingel's isprs_smrf_settings.txt layout)")
    ap.add_argument("--csv", help="also write the per-sample results to this CSV file")
    args = ap.parse_args(argv)
    if not os.path.isdir(args.data):
        ap.error(f"--data {args.data}: not a folder")
    if args.params and not os.path.isfile(args.params):
        ap.error(f"--params {args.params}: no such file")
    # Compile the numba kernels before timing the first sample.
    # Warm-up (numba compilation) on a small random cloud wide enough for every filter's grids.
    warm = np.random.default_rng(0).uniform(0.0, 60.0, (3000, 3)) * [1.0, 1.0, 0.05]
    FILTERS[args.filter](None)(warm)
    results = run(args.filter, args.data, args.params)
    print(f"Filter: {args.filter}; data: {args.data}; parameters: "
          f"{args.params or 'defaults'}\n")
    print(markdown_table(results))
    if args.csv:
        write_csv(results, args.csv)
        print(f"\nWrote {args.csv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
