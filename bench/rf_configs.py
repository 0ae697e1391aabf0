"""The paper's Random Forest study (matrone2024, Tables 8-16) on labelled clouds of your own.

    .venv/bin/python bench/rf_configs.py --train ../shared/data/lasR_bcts/bcts_1.laz \\
        --test ../shared/data/lasR_bcts/bcts_2.laz [--configs C1 C2 C3 C4 C5 C5H] [--trees 100]

    .venv/bin/python bench/rf_configs.py --isprs samp21 samp23 samp31 samp41 samp51 samp52 samp54

For each feature configuration: train on --train (every class present but 0, 7, 18, or
--classes), test on --test, and print the per-class precision / recall / F1, the overall accuracy
and the weighted averages, with the times; then one line per configuration to compare, e.g. C1
against C2 (does the return number help?). Clouds without colour use the intensity in place of
RGB, as the plugin does. Features are computed once per cloud and reused by every configuration.

--isprs: the ISPRS raw sites with first and last pulse, joined to the reference labels as in
bench/returns.py (label 0 -> ASPRS 2, 1 -> 1). The features are computed on every record of both
pulses in the sample's box; the joined reference points are the labelled samples, split per
sample into spatial blocks of --block m (60 % train, 40 % test), pooled over the samples. The
files have no colour and no GPS time, so the radiometric feature is the intensity and C3/C4 are
skipped.
"""
import argparse
import sys
import time

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core import errors  # noqa: E402
from groundsieve.core.engine import learning  # noqa: E402
from groundsieve.core.learn import rf  # noqa: E402
from groundsieve.core.io import read_cloud  # noqa: E402
from groundsieve.core.metrics import class_report  # noqa: E402
from groundsieve.core.learn.report import class_name  # noqa: E402


def columns(cloud, names, cache):
    """Feature columns of ``cloud``, computed once per name."""
    todo = [n for n in names if n not in cache]
    if todo:
        X = rf.feature_matrix(cloud, todo)
        for j, name in enumerate(todo):
            cache[name] = X[:, j]
    return np.column_stack([cache[n] for n in names]).astype(np.float32)


def isprs_sets(samples, configs, block_m, data):
    """(train X, train y, test X, test y) per configuration, pooled over the ISPRS samples."""
    from returns import SiteCache, load_isprs

    from groundsieve.core.learn.features import FeatureSpec, compute_features
    sites = SiteCache()
    pooled = {c: ([], [], [], []) for c in configs}
    for name in samples:
        sets, stats = load_isprs(name, data, ("file",), sites, lambda m: print(m))
        if not sets:
            continue
        ds = sets[0]
        geometric = sorted({n for c in configs for n in rf.PRESETS[c] if "_r" in n})
        feats = compute_features(ds.xyz, FeatureSpec.from_names(geometric)) if geometric else {}
        cols = dict(feats, intensity=ds.intensity.astype(np.float32),
                    return_number=ds.return_number.astype(np.float32))
        x, y = ds.xyz[ds.scored, 0], ds.xyz[ds.scored, 1]
        split = rf.spatial_split(x, y, block_m, (0.6, 0.0, 0.4), seed=0)
        labels = np.where(ds.reference_ground, 2, 1).astype(np.uint8)
        for c in configs:
            names = ["intensity" if n == rf.RADIOMETRY else n for n in rf.PRESETS[c]]
            X = np.column_stack([cols[n][ds.scored] for n in names]).astype(np.float32)
            for k, part in ((0, split == 0), (2, split == 2)):
                pooled[c][k].append(X[part])
                pooled[c][k + 1].append(labels[part])
        print(f"{name}: {len(ds.scored):,} labelled points, {len(ds.xyz):,} records in the box")
    return {c: tuple(np.concatenate(v) for v in parts) for c, parts in pooled.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--train")
    ap.add_argument("--test")
    ap.add_argument("--isprs", nargs="+", help="ISPRS samples (raw sites joined to the reference labels)")
    ap.add_argument("--block", type=float, default=25.0, help="--isprs: block size of the split (m)")
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"))
    ap.add_argument("--configs", nargs="+", default=["C1", "C2", "C3", "C4", "C5", "C5H"],
                    choices=sorted(rf.PRESETS))
    ap.add_argument("--classes", default="", help="ASPRS codes to learn, comma-separated (default: all present)")
    ap.add_argument("--trees", type=int, default=100)
    ap.add_argument("--criterion", default="gini", choices=rf.CRITERIA)
    ap.add_argument("--scaler", default="none", choices=rf.SCALERS)
    ap.add_argument("--samples-per-tree", type=int, default=100_000)
    args = ap.parse_args()
    params = rf.ForestParams(n_trees=args.trees, criterion=args.criterion, scaler=args.scaler,
                             max_samples=args.samples_per_tree or None)
    if args.isprs:
        configs = [c for c in args.configs if c not in ("C3", "C4")]
        sets = isprs_sets(args.isprs, configs, args.block, args.data)
        print()
        rows = []
        for config in configs:
            Xtr, ytr, Xte, yte = sets[config]
            names = ["intensity" if n == rf.RADIOMETRY else n for n in rf.PRESETS[config]]
            t0 = time.perf_counter()
            model = rf.train_forest(Xtr, ytr, names, params)
            t1 = time.perf_counter()
            report = class_report(yte, model.predict(Xte), (1, 2))
            print(f"### {config}: {', '.join(names)} ({len(ytr):,} train, {len(yte):,} test points)\n")
            print(report.table({c: class_name(c) for c in (1, 2)}) + "\n")
            rows.append((config, report.accuracy, report.weighted(report.f1), report.f1[1], t1 - t0))
        print("| configuration | overall accuracy | weighted F1 | ground F1 | training (s) |")
        print("|---|---:|---:|---:|---:|")
        for config, acc, f1, gf1, tt in rows:
            print(f"| {config} | {acc:.3f} | {f1:.3f} | {gf1:.3f} | {tt:.1f} |")
        return
    if not (args.train and args.test):
        ap.error("give --train and --test, or --isprs")
    train, test = read_cloud(args.train), read_cloud(args.test)
    if args.classes:
        classes = tuple(int(c) for c in args.classes.split(","))
    else:
        classes = tuple(int(c) for c in np.unique(train.classification) if c not in learning.EXCLUDED_BY_DEFAULT)
    keep_train = np.isin(train.classification, classes)
    keep_test = np.isin(test.classification, classes)
    print(f"Train {args.train}: {int(keep_train.sum()):,} points; test {args.test}: {int(keep_test.sum()):,} "
          f"points; classes {', '.join(class_name(c) for c in classes)}; {args.trees} trees, {args.criterion}, "
          f"scaler {args.scaler}, at most {args.samples_per_tree:,} samples per tree\n")
    cache_train, cache_test, summary = {}, {}, []
    for config in args.configs:
        names = rf.resolve_features(rf.PRESETS[config], train)
        if names != rf.resolve_features(rf.PRESETS[config], test):
            sys.exit(f"{config}: the two clouds give different features")
        try:
            t0 = time.perf_counter()
            Xtr = columns(train, names, cache_train)[keep_train]
            Xte = columns(test, names, cache_test)[keep_test]
            t1 = time.perf_counter()
            model = rf.train_forest(Xtr, train.classification[keep_train], names, params)
            t2 = time.perf_counter()
            predicted = model.predict(Xte)
            t3 = time.perf_counter()
        except errors.InputError as err:
            print(f"### {config}: skipped ({err})\n")
            continue
        report = class_report(test.classification[keep_test], predicted, classes)
        print(f"### {config}: {', '.join(names)}\n")
        print(report.table({c: class_name(c) for c in classes}))
        print(f"\nfeatures {t1 - t0:.1f} s (cached across configurations), training {t2 - t1:.1f} s, "
              f"prediction {t3 - t2:.1f} s\n")
        g = classes.index(2) if 2 in classes else None
        summary.append((config, report.accuracy, report.weighted(report.f1),
                        report.f1[g] if g is not None else float("nan"), t2 - t1, t3 - t2))
    print("| configuration | overall accuracy | weighted F1 | ground F1 | training (s) | prediction (s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for config, acc, f1, gf1, tt, tp in summary:
        print(f"| {config} | {acc:.3f} | {f1:.3f} | {gf1:.3f} | {tt:.1f} | {tp:.1f} |")


if __name__ == "__main__":
    main()
