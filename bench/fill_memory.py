"""Peak memory of SMRF's harmonic hole filling (core/grids/inpaint.py) per empty cell, the figure
behind ``core/grids/spec.py::FILL_BYTES_PER_EMPTY_CELL`` (the memory guard's estimate for grids that
points leave mostly empty, e.g. one stray point kilometres away).

    .venv/bin/python bench/fill_memory.py [--sizes 500 1000] [--known 0.0 0.5]

Each case runs in a fresh process: an n x n grid with a share --known of random cells known (0 =
one known cell: a single hole, the stray-point case); peak resident set during the fill minus
before it, per empty cell. Prints one markdown table.
"""
import argparse
import subprocess
import sys

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)

CHILD = """
import resource, sys, time
sys.path.insert(0, {plugins!r})
import numpy as np
from groundsieve.core.grids.inpaint import inpaint_harmonic
n, known = int(sys.argv[1]), float(sys.argv[2])
grid = np.full((n, n), np.nan)
rng = np.random.default_rng(0)
grid.flat[rng.choice(n * n, max(1, int(known * n * n)), replace=False)] = 1.0
empty = int(np.isnan(grid).sum())
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.perf_counter()
inpaint_harmonic(grid)
seconds = time.perf_counter() - t
extra = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) * 1024
print(n * n, empty, extra, seconds)
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[500, 1000])
    ap.add_argument("--known", type=float, nargs="+", default=[0.0, 0.5])
    args = ap.parse_args()
    import groundsieve
    import os
    plugins = os.path.dirname(os.path.dirname(os.path.abspath(groundsieve.__file__)))
    print("| grid | known cells | empty cells | extra peak memory (MB) | bytes per empty cell | fill (s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for n in args.sizes:
        for known in args.known:
            out = subprocess.run([sys.executable, "-c", CHILD.format(plugins=plugins), str(n), str(known)],
                                 capture_output=True, text=True, check=True).stdout.split()
            cells, empty, extra, seconds = int(out[0]), int(out[1]), int(out[2]), float(out[3])
            print(f"| {n} x {n} | {'1' if known == 0 else f'{known:.0%}'} | {empty:,} | {extra / 2**20:,.0f} | "
                  f"{extra / empty:,.0f} | {seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
