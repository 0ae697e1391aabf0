"""Prediction kernel of this checkout against the kernel of another git revision, interleaved in
one process on the same forest and points (so that a shared machine's load hits both alike).

    .venv/bin/python bench/rf_kernel_ab.py --against REV [--millions 0.1] [--trees 100] [--repeats 11]

REV's ``core/learn/_rf_kernels.py`` is read with ``git show`` and compiled beside this one. The
forest is trained on 100,000 generated samples of 8 features (noisy labels: deep trees). Prints
each run's seconds (process CPU time, wall time) and the median and minimum ratios this/REV; the
two answers must be identical.
"""
import argparse
import importlib.util
import subprocess
import tempfile
import time
from pathlib import Path

from _checkout import REPO  # noqa: E402 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core.learn import _rf_kernels as this  # noqa: E402
from groundsieve.core.learn import rf  # noqa: E402


def _kernel_at(rev, folder):
    source = subprocess.run(["git", "-C", str(REPO), "show", f"{rev}:core/learn/_rf_kernels.py"],
                            capture_output=True, text=True, check=True).stdout
    path = Path(folder) / "rf_kernels_at_rev.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("rf_kernels_at_rev", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--against", required=True)
    ap.add_argument("--millions", type=float, default=0.1)
    ap.add_argument("--trees", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=11)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        other = _kernel_at(args.against, folder)
        rng = np.random.default_rng(0)
        n = int(args.millions * 1e6)
        X = rng.normal(size=(max(n, 100_000), 8)).astype(np.float32)
        y = np.where(X[:, 0] + 0.5 * X[:, 1] + 0.5 * rng.normal(size=len(X)) > 0, 2, 1).astype(np.uint8)
        model = rf.train_forest(X[:100_000], y[:100_000], [f"f{i}" for i in range(8)],
                                rf.ForestParams(n_trees=args.trees))
        X = X[:n]
        arrays = (model.roots, model.left, model.right, model.feature, model.threshold, model.missing_left,
                  model.value)
        outs = {name: np.empty((n, model.classes.size)) for name in ("this", "rev")}
        kernels = {"this": this._forest_proba_kernel, "rev": other._forest_proba_kernel}
        for name, kernel in kernels.items():  # compile
            kernel(X[:10], *arrays, outs[name][:10])
        cpu = {"this": [], "rev": []}
        wall = {"this": [], "rev": []}
        for r in range(args.repeats):
            for name in (("rev", "this") if r % 2 == 0 else ("this", "rev")):
                t0, w0 = time.process_time(), time.perf_counter()
                kernels[name](X, *arrays, outs[name])
                cpu[name].append(time.process_time() - t0)
                wall[name].append(time.perf_counter() - w0)
        assert np.array_equal(outs["this"], outs["rev"]), "the two kernels disagree"
    print(f"{n:,} points, {model.n_trees} trees, {model.left.size:,} nodes, {args.repeats} runs each")
    for label, times in (("CPU", cpu), ("wall", wall)):
        print(f"{label} s this: {[round(v, 2) for v in times['this']]}")
        print(f"{label} s {args.against}: {[round(v, 2) for v in times['rev']]}")
        print(f"{label}: median this/{args.against} = {np.median(times['this']) / np.median(times['rev']):.3f}, "
              f"min this/{args.against} = {min(times['this']) / min(times['rev']):.3f}")


if __name__ == "__main__":
    main()
