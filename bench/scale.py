"""Survey scale through ``qgis_process`` (issue #10): memory and speed at 20, 50 and 200 M points.

Generate, in ONE streamed pass of the project's scene generator (2 M point blocks at 10 pulses/m²,
never a whole cloud in memory), nested LAZ files of the first 10, 25 and 100 blocks (the blocks are
laid out on the 200 M file's 10-block columns, so the smaller files are strips of it):

    .venv/bin/python bench/scale.py generate --work /path/with/room --sizes 20 50 200

Then for each size, in the same run: the floor (a plain streamed laspy decode + encode of the LAZ,
laspy's default LAZ backend), and ``scripts/qgis-process run groundsieve:smrf`` with a 1 m DTM, each
with wall time and the peak RSS of the whole process tree (workers included, from /proc every
0.2 s), the 1-minute load average before and after each measurement (the machine is shared), and
the CPU time (user + system) of each process tree, floor / run (ratio): a figure other engineers'
load changes less than the wall time:

    .venv/bin/python bench/scale.py run --work /path/with/room --sizes 20 50 200

DTM assembly alone (issue #11): the client's peak RSS while ``raster.geotiff.BlockGeoTIFF`` assembles
a 2 x 2 km DTM at 0.25 m (8000 x 8000 = 64 M cells) from 100 x 100 m blocks, as the tiled engine
feeds it (no filtering: the blocks are computed planes):

    .venv/bin/python bench/scale.py assembly --work /path/with/room
"""
import argparse
import math
import os
import resource
import sys
import time

from _checkout import REPO  # noqa: E402 (puts this checkout's groundsieve on sys.path)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tiles import FLOOR, timed  # noqa: E402

BLOCK_POINTS = 2_000_000


def load():
    return os.getloadavg()[0]


def generate(work, sizes, density=10.0):
    import laspy
    import numpy as np
    import pyproj

    from groundsieve.core.synthetic import SceneSpec, make_scene, scene_crs_wkt
    spec = SceneSpec.for_points(BLOCK_POINTS, density_per_m2=density)
    blocks = {m: max(1, int(round(m * 1e6 / BLOCK_POINTS))) for m in sizes}
    most = max(blocks.values())
    per_row = int(math.ceil(math.sqrt(most)))
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = np.array([0.01, 0.01, 0.01])
    header.offsets = np.array([500000.0, 5400000.0, 0.0])
    header.add_crs(pyproj.CRS.from_wkt(scene_crs_wkt()))
    os.makedirs(work, exist_ok=True)
    paths = {m: os.path.join(work, f"gen_{m}M.laz") for m in sizes}
    writers = {m: laspy.open(paths[m] + ".part", mode="w", header=header, do_compress=True) for m in sizes}
    counts = dict.fromkeys(sizes, 0)
    t = time.perf_counter()
    try:
        for k in range(most):
            scene = make_scene(SceneSpec(size_m=spec.size_m, density_per_m2=density, seed=k))
            i, j = divmod(k, per_row)
            rec = laspy.ScaleAwarePointRecord.zeros(len(scene), header=header)
            x0, y0 = scene.x.min(), scene.y.min()
            rec.x = scene.x - x0 + 500000.0 + i * spec.size_m
            rec.y = scene.y - y0 + 5400000.0 + j * spec.size_m
            rec.z = scene.z
            for name in ("classification", "return_number", "number_of_returns", "intensity", "gps_time"):
                rec[name] = getattr(scene, name)
            for m in sizes:
                if k < blocks[m]:
                    writers[m].write_points(rec)
                    counts[m] += len(scene)
            print(f"block {k + 1}/{most} ({time.perf_counter() - t:.0f} s, load {load():.1f})", flush=True)
    finally:
        for w in writers.values():
            w.close()
    for m in sizes:
        os.replace(paths[m] + ".part", paths[m])
        print(f"{paths[m]}: {counts[m]:,} points, {os.path.getsize(paths[m]) / 1e6:.0f} MB")


def run(work, sizes, workers, params=()):
    import re

    import laspy
    for m in sizes:
        src = os.path.join(work, f"gen_{m}M.laz")
        with laspy.open(src) as r:
            n = r.header.point_count
        floor_out = os.path.join(work, "floor.laz")
        l0 = load()
        floor_s, floor_gb, _, floor_cpu = timed([sys.executable, "-c", FLOOR, src, floor_out])
        l1 = load()
        os.remove(floor_out)
        out, dtm = os.path.join(work, "smrf.laz"), os.path.join(work, "dtm.tif")
        cmd = [str(REPO / "scripts" / "qgis-process"), "run", "groundsieve:smrf", f"--INPUT={src}",
               f"--OUTPUT={out}", f"--DTM={dtm}", "--DTM_CELL=1"]
        if workers:
            cmd.append(f"--WORKERS={workers}")
        cmd += [f"--{p}" for p in params]
        run_s, run_gb, log, run_cpu = timed(cmd)
        l2 = load()
        for line in log.splitlines():
            found = re.search(r"(Binned|Filtered|Wrote|Done in|file\(s\),|tile\(s\) on).*", line)
            if found:
                print("   ", found.group(0))
        print(f"| {n / 1e6:.1f} M | {floor_s:.0f} s, {floor_gb:.2f} GB | {run_s:.0f} s, {run_gb:.2f} GB | "
              f"{run_s / floor_s:.2f} | {n / run_s / 1e6:.2f} M/s | {l0:.1f} / {l1:.1f} / {l2:.1f} | "
              f"{floor_cpu:.0f} / {run_cpu:.0f} s ({run_cpu / floor_cpu:.2f}) |", flush=True)
        for p in (out, dtm):
            if os.path.exists(p):
                os.remove(p)


def assembly(work, side_m=2000.0, cell=0.25, block_m=100.0):
    import numpy as np

    from groundsieve.core.grids.spec import GridSpec
    from groundsieve.core.raster.geotiff import BlockGeoTIFF
    os.makedirs(work, exist_ok=True)
    x0, y0 = 500000.0, 5400000.0
    grid = GridSpec.covering(np.array([x0, x0 + side_m - cell / 2]), np.array([y0, y0 + side_m - cell / 2]), cell,
                             what="DTM")
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t = time.perf_counter()
    writer = BlockGeoTIFF(os.path.join(work, "assembly_tmp.tif"), grid, crs_wkt=None)
    nb = int(round(block_m / cell))
    for row0 in range(0, grid.nrows, nb):
        for col0 in range(0, grid.ncols, nb):
            rows, cols = min(nb, grid.nrows - row0), min(nb, grid.ncols - col0)
            r, c = np.mgrid[row0:row0 + rows, col0:col0 + cols]
            writer.write_block(row0, col0, (100.0 + 0.01 * r + 0.02 * c).astype(np.float32))
    out = os.path.join(work, "assembly.tif")
    writer.finish(out)
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{grid.nrows} x {grid.ncols} = {grid.nrows * grid.ncols / 1e6:.0f} M cells in {nb} x {nb} blocks: "
          f"{time.perf_counter() - t:.1f} s, peak RSS {rss1:.0f} MB (before: {rss0:.0f} MB), "
          f"output {os.path.getsize(out) / 1e6:.0f} MB, load {load():.1f}")
    os.remove(out)
    os.remove(os.path.join(work, "assembly_tmp.tif"))  # the work raster (the engine's is in its working folder)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("what", choices=["generate", "run", "assembly"])
    parser.add_argument("--work", default=os.path.join(str(REPO), ".build", "bench-scale"))
    parser.add_argument("--sizes", type=int, nargs="+", default=[20, 50, 200])
    parser.add_argument("--workers", type=int, default=0)
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="another parameter of groundsieve:smrf for the run, e.g. --param TILE_SIZE=500")
    args = parser.parse_args()
    if args.what == "generate":
        generate(args.work, args.sizes)
    elif args.what == "run":
        run(args.work, args.sizes, args.workers, args.param)
    else:
        assembly(args.work)


if __name__ == "__main__":
    main()
