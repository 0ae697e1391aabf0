"""The tiles of a survey on a Dask LocalCluster (core/engine/cluster.py): scaling from 1 to 2
workers and the scheduler's cost per tile, all measured in the same run.

    .venv/bin/python bench/cluster.py [--millions 2] [--files 64] [--tile 50] [--filter smrf]
    .venv/bin/python bench/cluster.py --blocks --millions 100 --files 50 --tile 0 --dir /big/disk

A generated scene of about N million points is cut into a grid of ``--files`` LAZ files (a survey);
with ``--blocks``, each file is its own generated scene block of N/files million points, side by side
(streamed: no whole survey in memory, for 100 M points and more);
then SMRF with a 1 m DTM runs over the folder four ways: in this process one tile after the other
(no Dask: the reference), on a LocalCluster of 1 worker process, of 2 worker processes, and with
local worker processes (no Dask, 2 workers). From the engine's log lines: the tile phase alone
("Filtered N tile(s) in X s"), the binning and writing phases (one job per file, on the workers);
and this process's CPU time (the client, with a LocalCluster's scheduler, which runs in it):

* scheduler cost per tile = (Dask 1 worker - in process) / tiles;
* scaling efficiency = (Dask 1 worker / Dask 2 workers) / 2.

Outputs are checked identical between the runs. The bench needs dask[distributed].
"""
import argparse
import os
import re
import shutil
import sys
import tempfile
import time

from _checkout import REPO  # noqa: F401,E402 (puts this checkout's groundsieve on sys.path)


def make_survey(folder, millions, files):
    import laspy
    import numpy as np
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    density = 10.0
    side = (millions * 1e6 / (density * 1.25)) ** 0.5  # ~1.25 points per pulse
    whole = os.path.join(folder, "whole.laz")
    write_scene(make_scene(SceneSpec(size_m=round(side), density_per_m2=density, seed=1)), whole)
    las = laspy.read(whole)
    k = int(round(files ** 0.5))
    x0, y0 = las.header.mins[:2]
    ix = np.minimum(((las.x - x0) / (side / k)).astype(int), k - 1)
    iy = np.minimum(((las.y - y0) / (side / k)).astype(int), k - 1)
    survey = os.path.join(folder, "survey")
    os.makedirs(survey)
    for i in range(k):
        for j in range(k):
            sel = (ix == i) & (iy == j)
            if sel.any():
                out = laspy.LasData(las.header)
                out.points = las.points[sel]
                out.write(os.path.join(survey, f"f{i:02d}_{j:02d}.laz"))
    os.remove(whole)
    return survey, len(las.points), k * k


def make_blocks(folder, millions, files):
    """``files`` LAZ files, each a generated scene block of about millions/files M points, on a grid."""
    import math

    import laspy
    import numpy as np
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    per_file = millions * 1e6 / files
    spec = SceneSpec.for_points(int(per_file), density_per_m2=10.0)
    per_row = int(math.ceil(math.sqrt(files)))
    survey = os.path.join(folder, "survey")
    os.makedirs(survey)
    total = 0
    for k in range(files):
        scene = make_scene(SceneSpec(size_m=spec.size_m, density_per_m2=10.0, seed=k))
        i, j = divmod(k, per_row)
        scene.x[:] = scene.x - scene.x.min() + 500000.0 + i * spec.size_m
        scene.y[:] = scene.y - scene.y.min() + 5400000.0 + j * spec.size_m
        write_scene(scene, os.path.join(survey, f"f{i:02d}_{j:02d}.laz"))
        total += len(scene)
    return survey, total, files


def run(survey, out, scheduler, workers, tile, algorithm):
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
    import resource
    lines = []
    t0 = time.perf_counter()
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    done = run_ground_filter(survey, os.path.join(out, "c.vpc"), algorithm,
                             options=FilterOptions(tiling=TileOptions(tile_size_m=tile, workers=workers,
                                                                      parallel="processes", scheduler=scheduler)),
                             dtm_path=os.path.join(out, "dtm.tif"), dtm=DTMOptions(cell_size_m=1.0), log=lines.append)
    wall = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    client_cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    def phase(pattern):
        return next((float(m.group(1)) for line in lines for m in [re.match(pattern, line)] if m), float("nan"))
    filtered = phase(r"Filtered \d+ tile\(s\) in ([\d.]+) s")
    binned, wrote = phase(r"Binned into .* in ([\d.]+) s"), phase(r"Wrote .* in ([\d.]+) s")
    print(f"    binning {binned:.1f} s, writing {wrote:.1f} s, this process's CPU {client_cpu:.1f} s "
          f"(the client, and on a LocalCluster its scheduler), load {os.getloadavg()[0]:.1f}", flush=True)
    return done, wall, filtered


def digest(out):
    import hashlib
    import numpy as np
    import laspy
    from osgeo import gdal
    h = hashlib.sha1()
    folder = os.path.join(out, "c")
    for name in sorted(os.listdir(folder)):
        h.update(np.asarray(laspy.read(os.path.join(folder, name)).classification).tobytes())
    h.update(gdal.Open(os.path.join(out, "dtm.tif")).ReadAsArray().tobytes())
    return h.hexdigest()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--millions", type=float, default=2.0)
    ap.add_argument("--files", type=int, default=64)
    ap.add_argument("--tile", type=float, default=50.0)
    ap.add_argument("--filter", default="smrf")
    ap.add_argument("--blocks", action="store_true", help="one generated scene block per file (streamed)")
    ap.add_argument("--dir", default=None, help="working folder (default: a temporary one)")
    ap.add_argument("--runs", default="serial,dask1,dask2,local2",
                    help="which runs, comma-separated, of serial, dask1, dask2, local2 (default: all)")
    args = ap.parse_args()
    wanted = args.runs.split(",")
    from groundsieve.core.engine import parameters
    algorithm = parameters.filter_class(args.filter)()
    base = tempfile.mkdtemp(prefix="gs-cluster-", dir=args.dir)
    try:
        t0 = time.perf_counter()
        survey, points, files = (make_blocks if args.blocks else make_survey)(base, args.millions, args.files)
        print(f"survey: {points:,} points in {files} files ({time.perf_counter() - t0:.0f} s to make)", flush=True)
        rows = {}
        for key, label, scheduler, workers in (("serial", "in process, 1 tile at a time", "", 1),
                                               ("dask1", "Dask LocalCluster, 1 worker", "local:1", 1),
                                               ("dask2", "Dask LocalCluster, 2 workers", "local:2", 2),
                                               ("local2", "local processes, 2 workers (no Dask)", "", 2)):
            if key not in wanted:
                continue
            out = os.path.join(base, f"out-{key}")
            os.makedirs(out)
            t_load = os.getloadavg()[0]
            done, wall, filtered = run(survey, out, scheduler, workers, args.tile, algorithm)
            rows[key] = (label, done.tiles, wall, filtered, digest(out))
            print(f"{label:40s} tiles {done.tiles:4d}  tile phase {filtered:7.1f} s  whole run {wall:7.1f} s  "
                  f"(load before {t_load:.1f}, after {os.getloadavg()[0]:.1f})", flush=True)
        print(f"identical outputs: {len({r[4] for r in rows.values()}) == 1}")
        if "serial" in rows and "dask1" in rows:
            tiles = rows["serial"][1]
            print(f"scheduler cost per tile: ({rows['dask1'][3]:.1f} - {rows['serial'][3]:.1f}) s / {tiles} = "
                  f"{(rows['dask1'][3] - rows['serial'][3]) / tiles * 1000:.0f} ms")
        if "dask1" in rows and "dask2" in rows:
            one, two = rows["dask1"], rows["dask2"]
            print(f"scaling efficiency 1 -> 2 Dask workers, tile phase: ({one[3]:.1f} / {two[3]:.1f}) / 2 = "
                  f"{one[3] / two[3] / 2:.2f}; whole run: ({one[2]:.1f} / {two[2]:.1f}) / 2 = {one[2] / two[2] / 2:.2f}")
            print(f"per tile, 1 worker: {one[3] / one[1]:.2f} s ({points / one[1]:,.0f} points a tile)")
    finally:
        shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
