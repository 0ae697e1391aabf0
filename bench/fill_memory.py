"""Peak memory of SMRF's harmonic hole filling (core/grids/inpaint.py) per empty cell, the figure
behind ``core/grids/spec.py::FILL_BYTES_PER_EMPTY_CELL`` (the memory guard's estimate for grids that
points leave mostly empty, e.g. one stray point kilometres away).

    .venv/bin/python bench/fill_memory.py [--sizes 500 1000] [--known 0.0 0.5] [--dtm 4000]
        [--tiled 0.05 0.035]

``--tiled CELL ...``: a tiled run (SMRF, tiles of 120 m, one worker) of a generated 240 m scene
with a DTM at each cell size, against the same run with a 1 m DTM; the extra peak per cell of one
tile's DTM block as ``core/engine/tiles.fit_dtm_blocks`` counts it (the tile and its buffer), the
figure it checks against ``workflow.DTM_BYTES_PER_CELL``.

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

DTM_CHILD = """
import resource, sys, tempfile, os
sys.path.insert(0, {plugins!r})
import numpy as np
from groundsieve.core.engine.workflow import DTMOptions, make_dtm
from groundsieve.core.raster.geotiff import write_geotiff
n, fill = int(sys.argv[1]), sys.argv[2] == "1"
rng = np.random.default_rng(0)
x, y, z = rng.uniform(0, n - 1, 20000), rng.uniform(0, n - 1, 20000), rng.normal(0, 1, 20000)
x[:4], y[:4] = [0, n - 1, 0, n - 1], [0, 0, n - 1, n - 1]
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
grid, values = make_dtm(x, y, z, np.ones(x.size, bool), DTMOptions(cell_size_m=1.0, fill_outside_hull=fill))
with tempfile.TemporaryDirectory() as folder:
    write_geotiff(os.path.join(folder, "dtm.tif"), values, grid)
extra = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) * 1024
print(grid.nrows * grid.ncols, extra)
"""

TILED_CHILD = """
import math, os, resource, sys, tempfile
sys.path.insert(0, {plugins!r})
from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
cell, fill = float(sys.argv[1]), sys.argv[2] == "1"
with tempfile.TemporaryDirectory() as folder:
    cloud = os.path.join(folder, "scene.laz")
    write_scene(make_scene(SceneSpec(size_m=240.0, density_per_m2=3.0, seed=5)), cloud)
    opts = FilterOptions(tiling=TileOptions(tile_size_m=120.0, workers=1, parallel="threads"))
    lines = []
    run = run_ground_filter(cloud, os.path.join(folder, "o.laz"), SMRF(), options=opts,
                            dtm_path=os.path.join(folder, "d.tif"),
                            dtm=DTMOptions(cell_size_m=cell, fill_outside_hull=fill), log=lines.append)
pad = math.ceil(run.buffer_m / cell - 1e-9) + 1
side = math.ceil(run.tile_size_m / cell - 1e-9) + 2 * pad
print(side * side, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
"""


def tiled(plugins, cells):
    print("\n| tiled run, DTM cell (m) | fill outside the hull | cells of one tile's block | extra peak over a 1 m DTM (MB) "
          "| bytes per block cell |")
    print("|---|---|---:|---:|---:|")
    for fill in (False, True):
        def peak(cell):
            out = subprocess.run([sys.executable, "-c", TILED_CHILD.format(plugins=plugins), str(cell),
                                  "1" if fill else "0"], capture_output=True, text=True, check=True).stdout.split()
            return int(out[0]), int(out[1])
        _, base = peak(1.0)
        for cell in cells:
            block, rss = peak(cell)
            print(f"| {cell:g} | {'yes' if fill else 'no'} | {block:,} | {(rss - base) / 2**20:,.0f} | "
                  f"{(rss - base) / block:.1f} |", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="*", default=[500, 1000])
    ap.add_argument("--known", type=float, nargs="*", default=[0.0, 0.5])
    ap.add_argument("--dtm", type=int, default=0, help="also an N x N DTM's peak per cell")
    ap.add_argument("--tiled", type=float, nargs="*", default=[], help="also tiled runs with these DTM cells")
    args = ap.parse_args()
    import groundsieve
    import os
    plugins = os.path.dirname(os.path.dirname(os.path.abspath(groundsieve.__file__)))
    if args.sizes and args.known:
        print("| grid | known cells | empty cells | extra peak memory (MB) | bytes per empty cell | fill (s) |")
        print("|---|---:|---:|---:|---:|---:|")
    for n in args.sizes:
        for known in args.known:
            out = subprocess.run([sys.executable, "-c", CHILD.format(plugins=plugins), str(n), str(known)],
                                 capture_output=True, text=True, check=True).stdout.split()
            cells, empty, extra, seconds = int(out[0]), int(out[1]), int(out[2]), float(out[3])
            print(f"| {n} x {n} | {'1' if known == 0 else f'{known:.0%}'} | {empty:,} | {extra / 2**20:,.0f} | "
                  f"{extra / empty:,.0f} | {seconds:.1f} |", flush=True)
    if args.dtm:
        print("\n| DTM | fill outside the hull | extra peak memory (MB) | bytes per cell |")
        print("|---|---|---:|---:|")
        for fill in (False, True):
            out = subprocess.run([sys.executable, "-c", DTM_CHILD.format(plugins=plugins), str(args.dtm),
                                  "1" if fill else "0"], capture_output=True, text=True, check=True).stdout.split()
            cells, extra = int(out[0]), int(out[1])
            print(f"| {args.dtm} x {args.dtm} | {'yes' if fill else 'no'} | {extra / 2**20:,.0f} | "
                  f"{extra / cells:.1f} |", flush=True)
    if args.tiled:
        tiled(plugins, args.tiled)


if __name__ == "__main__":
    main()
