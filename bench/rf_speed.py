"""Speed of the classification chain on generated clouds (issue 5's targets).

    .venv/bin/python bench/rf_speed.py [--features-millions 1] [--rf-millions 5] [--trees 100]

1. Features (the default preset's geometric features) for --features-millions points.
2. Random Forest with the defaults (100 trees, at most 100,000 samples per tree) trained on
   every point of a --rf-millions cloud (ground / non-ground) and predicting all of them, each
   timed, features excluded. Prints one markdown table.
"""
import argparse
import time

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core.learn import rf  # noqa: E402
from groundsieve.core.learn.features import FeatureSpec, compute_features  # noqa: E402
from groundsieve.core.synthetic import SceneSpec, make_scene  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--features-millions", type=float, default=1.0)
    ap.add_argument("--rf-millions", type=float, default=5.0)
    ap.add_argument("--trees", type=int, default=100)
    args = ap.parse_args()
    geometric = [n for n in rf.PRESETS["C5H"] if "_r" in n]  # the point features (C5H)
    spec = FeatureSpec.from_names(geometric)
    compute_features(make_scene(SceneSpec(size_m=30, seed=9)).xyz, spec)  # compile
    rows = []

    scene = make_scene(SceneSpec.for_points(int(args.features_millions * 1e6), density_per_m2=10, seed=1))
    t0 = time.perf_counter()
    compute_features(scene.xyz, spec)
    rows.append((f"features {', '.join(geometric)}", len(scene.x), time.perf_counter() - t0))

    scene = make_scene(SceneSpec.for_points(int(args.rf_millions * 1e6), density_per_m2=10, seed=2))
    feats = compute_features(scene.xyz, spec)
    X = np.column_stack([scene.intensity.astype(np.float32), scene.return_number.astype(np.float32)]
                        + [feats[n] for n in geometric]).astype(np.float32)
    y = np.where(scene.classification == 2, 2, 1).astype(np.uint8)
    del feats
    names = ["intensity", "return_number"] + geometric
    t0 = time.perf_counter()
    model = rf.train_forest(X, y, names, rf.ForestParams(n_trees=args.trees))
    t1 = time.perf_counter()
    predicted = model.predict(X)
    t2 = time.perf_counter()
    rows.append((f"training, {args.trees} trees", len(y), t1 - t0))
    rows.append(("prediction", len(y), t2 - t1))
    rows.append(("training + prediction", len(y), t2 - t0))
    print("| step | points | seconds | points/s |")
    print("|---|---:|---:|---:|")
    for step, n, seconds in rows:
        print(f"| {step} | {n:,} | {seconds:.1f} | {n / seconds:,.0f} |")
    print(f"\n(training accuracy {np.mean(predicted == y):.3f}; forest of {model.left.size:,} nodes)")


if __name__ == "__main__":
    main()
