#!/usr/bin/env python3
"""Issue 12's rftrain criterion: ``groundsieve:rftrain`` with its defaults, trained on the shared ISPRS
samples merged into one LAS (ground 2, other 1), applied with ``groundsieve:rfclassify`` to a sample
it has not seen. Leave one sample out: for each of the 8 shared samples, train on the 7 others merged,
classify this one; through the core engine the two algorithms call (core/engine/learning.py
train_file and classify_file), with rftrain's defaults (TrainOptions()) unless ``--preset`` is given.

    .venv/bin/python bench/rftrain_isprs.py --data ../shared/data/isprs [--preset C5H] [--work /tmp/x]
"""
from __future__ import annotations

import argparse
import glob
import os
import sys
import tempfile
import time

from _checkout import REPO  # noqa: E402,F401

import numpy as np  # noqa: E402

from groundsieve.core.engine import learning  # noqa: E402
from groundsieve.core.io import new_las, read_cloud, write_las  # noqa: E402
from groundsieve.core.learn import rf  # noqa: E402
from groundsieve.core.metrics import ground_accuracy  # noqa: E402


def to_las(path, out):
    """The ISPRS sample as LAS 1.2 point format 0, class 2 for its ground label (0), 1 otherwise."""
    cloud = read_cloud(path)
    ground = cloud.reference_label == 0
    write_las(new_las(cloud.x, cloud.y, cloud.z, point_format=0,
                      classification=np.where(ground, 2, 1).astype(np.uint8)), out)
    return ground


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.path.join(REPO, "..", "shared", "data", "isprs"))
    ap.add_argument("--preset", default=None, help=f"a preset instead of the default ({rf.DEFAULT_PRESET})")
    ap.add_argument("--work", default=None)
    args = ap.parse_args()
    work = args.work or tempfile.mkdtemp(prefix="rftrain_isprs_")
    options = (learning.TrainOptions() if args.preset is None
               else learning.TrainOptions(features=rf.PRESETS[args.preset]))
    paths = sorted(glob.glob(os.path.join(args.data, "samp*.txt")))
    names = [os.path.basename(p).split(".")[0] for p in paths]
    truth = {n: to_las(p, os.path.join(work, n + ".las")) for n, p in zip(names, paths)}
    clouds = {n: read_cloud(os.path.join(work, n + ".las")) for n in names}
    rows = []
    t0 = time.perf_counter()
    for held in names:
        others = [n for n in names if n != held]
        merged = os.path.join(work, f"without_{held}.las")
        write_las(new_las(np.concatenate([clouds[n].x for n in others]), np.concatenate([clouds[n].y for n in others]),
                          np.concatenate([clouds[n].z for n in others]), point_format=0,
                          classification=np.concatenate([clouds[n].classification for n in others])), merged)
        model = os.path.join(work, f"model_without_{held}.npz")
        learning.train_file(merged, model, None, options)
        out = os.path.join(work, f"{held}_classified.las")
        _cloud, predicted = learning.classify_file(os.path.join(work, held + ".las"), out, model)
        acc = ground_accuracy(truth[held], predicted == 2)
        rows.append((held, len(predicted), acc))
        print(f"  {held}: total {100 * acc.total:.2f} % ({time.perf_counter() - t0:.0f} s)", file=sys.stderr,
              flush=True)
    print(f"\nrftrain ({'defaults: ' + rf.DEFAULT_PRESET if args.preset is None else args.preset}, "
          f"{options.params.n_trees} trees) on the 7 other samples merged, rfclassify on this one\n")
    print("| Sample | Points | Type I % | Type II % | Total % | Kappa % |\n|---|---:|---:|---:|---:|---:|")
    for n, k, a in rows:
        print(f"| {n} | {k} | {100 * a.type1:.2f} | {100 * a.type2:.2f} | {100 * a.total:.2f} | {100 * a.kappa:.2f} |")
    mean = lambda f: 100 * np.mean([f(a) for _n, _k, a in rows])  # noqa: E731
    print(f"| **mean** | | {mean(lambda a: a.type1):.2f} | {mean(lambda a: a.type2):.2f} | "
          f"**{mean(lambda a: a.total):.2f}** | {mean(lambda a: a.kappa):.2f} |")


if __name__ == "__main__":
    main()
