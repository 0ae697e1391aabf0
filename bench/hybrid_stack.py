#!/usr/bin/env python3
"""A second stage for the hybrid filter, estimated by the same leave-one-sample-out (LOSO) protocol
as bench/hybrid_train.py (issue 12): does a forest that sees the first stage's ground do better?

Stage 1 is the shipped hybrid feature set and forest (bench/hybrid_train.py PARAMS). Stage 2 adds,
per point, features relative to the ground the first stage found:

* ``p1``: the stage-1 ground probability of the point;
* ``above_g1``: z minus the surface of the stage-1 ground points (lowest stage-1 ground point per
  1 m cell, empty cells inpainted harmonically), bilinear at the point;
* ``g1_slope``: the slope of that surface;
* ``p1_around``: the mean stage-1 probability of the points of the 3 x 3 (and ``p1_wide``: 9 x 9)
  cells around the point (the neighbours' opinion).

Stacked out of fold, so that stage 2 learns from honest stage-1 outputs: for a scored sample h,
stage 1 is trained on the 7 others; the stage-1 probabilities of each training sample s are those
of a stage-1 model trained on the 6 samples other than h and s. Nothing is fitted or chosen on h.

    .venv/bin/python bench/hybrid_stack.py --data ../shared/data/isprs
"""
from __future__ import annotations

import argparse
import os
import sys
import time

from _checkout import REPO  # noqa: E402,F401

import numpy as np  # noqa: E402
from scipy.ndimage import uniform_filter  # noqa: E402

import hybrid_train as ht  # noqa: E402
from groundsieve.core.grids.inpaint import inpaint_harmonic  # noqa: E402
from groundsieve.core.grids.rasterize import cell_mean, cell_min  # noqa: E402
from groundsieve.core.grids.spec import GridSpec  # noqa: E402
from groundsieve.core.learn._hybrid_kernels import _point_features_kernel  # noqa: E402
from groundsieve.core.learn.hybrid import DEFAULT_FEATURES, _slope  # noqa: E402
from groundsieve.core.learn.rf import train_forest  # noqa: E402
from groundsieve.core.metrics import ground_accuracy  # noqa: E402

STAGE2 = ("p1", "above_g1", "g1_slope", "p1_around", "p1_wide")


def stage2_features(xyz, p1, cell=1.0, confident=0.5):
    x, y, z = (np.ascontiguousarray(xyz[:, i]) for i in range(3))
    grid = GridSpec.covering(x, y, cell, what="stage-2 grid")
    keep = p1 >= confident
    if keep.sum() < 3:
        keep = p1 >= np.quantile(p1, 0.5)
    g1 = cell_min(x[keep], y[keep], z[keep], grid)
    g1 = inpaint_harmonic(g1)
    slope, _curv = _slope(g1, cell)
    pm, count = cell_mean(x, y, p1.astype(np.float64), grid)
    total = np.nan_to_num(pm) * count
    around = uniform_filter(total, 3, mode="nearest") / np.maximum(uniform_filter(count.astype(float), 3,
                                                                                   mode="nearest"), 1e-9)
    wide = uniform_filter(total, 9, mode="nearest") / np.maximum(uniform_filter(count.astype(float), 9,
                                                                                 mode="nearest"), 1e-9)
    surfaces = np.stack([g1, slope, around, wide]).astype(np.float64)
    out = np.empty((len(x), 7), dtype=np.float32)
    _point_features_kernel(x, y, z, surfaces, np.array([1, 0, 0, 0], dtype=np.int64), g1, g1,
                           grid.x0, grid.top, grid.cell, out)
    return np.column_stack([p1.astype(np.float32), out[:, :4]])


def fit(samples, names, X_of, params=ht.PARAMS):
    X = np.concatenate([X_of[s] for s in names])
    y = np.concatenate([samples[s][1] for s in names])
    return train_forest(X, y, ["f%d" % i for i in range(X.shape[1])], params, n_jobs=1)


def proba(model, X):
    return model.predict_proba(X)[:, [int(c) for c in model.classes].index(2)]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=os.path.join(REPO, "..", "shared", "data", "isprs"))
    parser.add_argument("--only-stage2", action="store_true", help="stage 2 without the stage-1 features")
    args = parser.parse_args()
    t0 = time.perf_counter()
    samples = ht.load_samples(args.data, list(DEFAULT_FEATURES))
    names = list(samples)
    X1 = {s: samples[s][0] for s in names}
    print(f"features: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    rows1, rows2 = [], []
    for h in names:
        train = [s for s in names if s != h]
        m1 = fit(samples, train, X1)
        p_h = proba(m1, X1[h])
        X2 = {}
        for s in train:
            inner = fit(samples, [t for t in train if t != s], X1)
            f2 = stage2_features(samples[s][3], proba(inner, X1[s]))
            X2[s] = f2 if args.only_stage2 else np.hstack([X1[s], f2])
        f2h = stage2_features(samples[h][3], p_h)
        X2[h] = f2h if args.only_stage2 else np.hstack([X1[h], f2h])
        m2 = fit(samples, train, X2)
        truth = samples[h][2]
        a1 = ground_accuracy(truth, p_h >= 0.5)
        a2 = ground_accuracy(truth, proba(m2, X2[h]) >= 0.5)
        rows1.append((h, len(truth), a1))
        rows2.append((h, len(truth), a2))
        print(f"  {h}: stage 1 {100 * a1.total:.2f} %, stage 2 {100 * a2.total:.2f} % "
              f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    print("\nStage 1 (the shipped features and forest)\n")
    print(ht.table(rows1))
    print("\nStage 2 (" + ("stage-2 features only" if args.only_stage2 else "stage-1 features + " + ", ".join(STAGE2))
          + "), stacked out of fold\n")
    print(ht.table(rows2, ht.smrf_rows(samples)))


if __name__ == "__main__":
    main()
