"""The paper's Random Forest study (matrone2024, Tables 8-16) on labelled clouds of your own.

    .venv/bin/python bench/rf_configs.py --train ../shared/data/lasR_bcts/bcts_1.laz \\
        --test ../shared/data/lasR_bcts/bcts_2.laz [--configs C1 C2 C3 C4 C5 C5H] [--trees 100]

For each feature configuration: train on --train (every class present but 0, 7, 18, or
--classes), test on --test, and print the per-class precision / recall / F1, the overall accuracy
and the weighted averages, with the times; then one line per configuration to compare, e.g. C1
against C2 (does the return number help?). Clouds without colour use the intensity in place of
RGB, as the plugin does. Features are computed once per cloud and reused by every configuration.
"""
import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / ".build" / "plugins"))

import numpy as np  # noqa: E402

from groundsieve.core import rf  # noqa: E402
from groundsieve.core.io import read_cloud  # noqa: E402
from groundsieve.core.metrics import class_report  # noqa: E402
from groundsieve.core.report import class_name  # noqa: E402


def columns(cloud, names, cache):
    """Feature columns of ``cloud``, computed once per name."""
    todo = [n for n in names if n not in cache]
    if todo:
        X = rf.feature_matrix(cloud, todo)
        for j, name in enumerate(todo):
            cache[name] = X[:, j]
    return np.column_stack([cache[n] for n in names]).astype(np.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--train", required=True)
    ap.add_argument("--test", required=True)
    ap.add_argument("--configs", nargs="+", default=["C1", "C2", "C3", "C4", "C5", "C5H"],
                    choices=sorted(rf.PRESETS))
    ap.add_argument("--classes", default="", help="ASPRS codes to learn, comma-separated (default: all present)")
    ap.add_argument("--trees", type=int, default=100)
    ap.add_argument("--criterion", default="gini", choices=rf.CRITERIA)
    ap.add_argument("--scaler", default="none", choices=rf.SCALERS)
    ap.add_argument("--samples-per-tree", type=int, default=100_000)
    args = ap.parse_args()

    train, test = read_cloud(args.train), read_cloud(args.test)
    if args.classes:
        classes = tuple(int(c) for c in args.classes.split(","))
    else:
        classes = tuple(int(c) for c in np.unique(train.classification) if c not in rf.EXCLUDED_BY_DEFAULT)
    keep_train = np.isin(train.classification, classes)
    keep_test = np.isin(test.classification, classes)
    print(f"Train {args.train}: {int(keep_train.sum()):,} points; test {args.test}: {int(keep_test.sum()):,} "
          f"points; classes {', '.join(class_name(c) for c in classes)}; {args.trees} trees, {args.criterion}, "
          f"scaler {args.scaler}, at most {args.samples_per_tree:,} samples per tree\n")
    cache_train, cache_test, summary = {}, {}, []
    params = rf.ForestParams(n_trees=args.trees, criterion=args.criterion, scaler=args.scaler,
                             max_samples=args.samples_per_tree or None)
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
        except rf.InputError as err:
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
