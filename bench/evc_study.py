"""The parameter study of Fan et al. (2023, Figures 9, 11 and 12) on a labelled cloud of your own.

    .venv/bin/python bench/evc_study.py --data labelled.laz          # ASPRS class 2 = ground
    .venv/bin/python bench/evc_study.py --data samp11.txt            # ISPRS text, label 0 = ground
    .venv/bin/python bench/evc_study.py --synthetic                  # a generated low-vegetation scene

Three sweeps, each keeping the best value of the one before (lowest total error), as the paper
chose its parameters: (1) the large-scale grid with radius 1 and threshold 1.5; (2) the
neighbourhood radius 1-6; (3) the threshold 1.0-2.0 (and natural breaks). Every other EVC
parameter can be fixed with --small, --offset, --difference.
"""
import argparse
import time

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core.filters.evc import EVC  # noqa: E402
from groundsieve.core.io import CLASS_GROUND, NOISE_CLASSES, read_cloud  # noqa: E402
from groundsieve.core.metrics import ground_accuracy  # noqa: E402


def load(args):
    if args.synthetic:
        from groundsieve.core.synthetic import SceneSpec, make_scene
        scene = make_scene(SceneSpec(size_m=args.size, density_per_m2=args.density, seed=args.seed,
                                     buildings_per_ha=0.0, trees_per_ha=0.0, shrub_fraction=0.3))
        return (f"generated low-vegetation scene ({args.size:g} m, {args.density:g} pulses/m², seed {args.seed})",
                scene.xyz, scene.classification == CLASS_GROUND)
    cloud = read_cloud(args.data)
    if cloud.reference_label is not None:
        return args.data, cloud.xyz, cloud.reference_label == 0
    keep = ~np.isin(cloud.classification, NOISE_CLASSES)
    return args.data, cloud.xyz[keep], cloud.classification[keep] == CLASS_GROUND


def row(label, evc, xyz, truth):
    t0 = time.perf_counter()
    result = evc.run(xyz)
    seconds = time.perf_counter() - t0
    acc = ground_accuracy(truth, result.ground)
    print(f"| {label} | {100 * acc.type1:.2f} | {100 * acc.type2:.2f} | {100 * acc.total:.2f} | "
          f"{100 * acc.kappa:.2f} | {result.threshold:.3g} | {seconds:.2f} |", flush=True)
    return acc.total


def header(title):
    print(f"\n### {title}\n")
    print("| value | Type I % | Type II % | Total % | Kappa % | threshold | time (s) |")
    print("|---|---:|---:|---:|---:|---:|---:|")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", help="labelled LAS/LAZ (class 2 = ground) or ISPRS .txt (label 0 = ground)")
    src.add_argument("--synthetic", action="store_true", help="use a generated low-vegetation scene")
    ap.add_argument("--size", type=float, default=100.0)
    ap.add_argument("--density", type=float, default=100.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--small", type=float, default=0.2, help="small-scale grid (m), default 0.2")
    ap.add_argument("--large", type=float, nargs="+", default=[0.8, 1.2, 1.6, 2.0, 2.4, 2.8, 3.2])
    ap.add_argument("--radii", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6])
    ap.add_argument("--thresholds", type=float, nargs="+", default=[1.0, 1.2, 1.4, 1.5, 1.6, 1.8, 2.0])
    ap.add_argument("--offset", type=float, default=0.0, help="ground_offset_m (0 = the paper)")
    ap.add_argument("--difference", default="large_minus_small", choices=["large_minus_small", "small_minus_large"])
    args = ap.parse_args()
    name, xyz, truth = load(args)
    base = dict(small_scale_m=args.small, ground_offset_m=args.offset, difference=args.difference)
    EVC(**base).run(xyz[:2000])  # compile
    print(f"EVC parameter study on {name}: {len(xyz):,} points, {100 * truth.mean():.1f} % ground; "
          f"small scale {args.small:g} m, offset {args.offset:g} m, difference {args.difference}")

    header("1. Large-scale grid (m), radius 1, threshold 1.5 (paper Figure 9)")
    totals = {large: row(f"{large:g} m", EVC(**base, large_scale_m=large), xyz, truth)
              for large in args.large if large > args.small}
    best_large = min(totals, key=totals.get)

    header(f"2. Neighbourhood radius (cells), large scale {best_large:g} m, threshold 1.5 (paper Figure 11)")
    totals = {r: row(f"{r}", EVC(**base, large_scale_m=best_large, radius=r, max_radius=max(r, 5)), xyz, truth)
              for r in args.radii}
    best_radius = min(totals, key=totals.get)

    header(f"3. Threshold, large scale {best_large:g} m, radius {best_radius} (paper Figure 12)")
    common = dict(base, large_scale_m=best_large, radius=best_radius, max_radius=max(best_radius, 5))
    totals = {t: row(f"{t:g}", EVC(**common, threshold=t), xyz, truth) for t in args.thresholds}
    row("natural breaks", EVC(**common, auto_threshold=True), xyz, truth)
    best_t = min(totals, key=totals.get)
    print(f"\nBest by total error: large scale {best_large:g} m, radius {best_radius}, threshold {best_t:g}")


if __name__ == "__main__":
    main()
