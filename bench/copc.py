"""COPC inputs read by bounds against the same points in a plain LAZ (core/io/copc.py).

    .venv/bin/python bench/copc.py [--millions 3] [--tile 250] [--workers 2] [--keep DIR]

Generates a scene of about N million points (core/synthetic.py), writes it as COPC with copclib
(the octree of tests/core/test_copc.py: one point per ``--grid`` x ``--grid`` cell of each node, the
rest deeper, nodes in random order) and the same points in the same order as a plain LAZ, then runs on each the
same tiled SMRF with a 1 m DTM (``--tile`` m tiles, SMRF's reach as buffer, ``--workers`` threads)
and prints the time of each phase as the engine logs it: planning and binning (the plain LAZ is
binned into tile parts; the COPC is not, its tiles' candidates come from its hierarchy), the tiles
(a COPC tile decompresses the nodes meeting its buffered box), the writing, and the whole run; the
ratio COPC / LAZ; the points decompressed by the COPC tiles in all; and whether the classes and the
DTMs are identical. The machine's load average (``uptime``) is printed before and after.
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

from _checkout import REPO  # noqa: E402 (puts this checkout's groundsieve on sys.path)


def phases(lines):
    out = {}
    for line in lines:
        for name, pattern in (("bin", r"Binned into .* in ([\d.]+) s"), ("tiles", r"Filtered .* in ([\d.]+) s"),
                              ("write", r"Wrote .* in ([\d.]+) s"), ("total", r"Done in ([\d.]+) s")):
            m = re.search(pattern, line)
            if m:
                out[name] = float(m.group(1))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--millions", type=float, default=3.0)
    ap.add_argument("--tile", type=float, default=250.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--grid", type=int, default=128,
                    help="cells along a node's side (an octree level keeps one point per cell)")
    ap.add_argument("--keep", default=None, help="folder for the files (kept); default a temporary one")
    args = ap.parse_args()
    import laspy
    import numpy as np
    from osgeo import gdal
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.synthetic import SceneSpec, make_scene
    from groundsieve.tests.core.test_copc import plain_copy, scene_las, write_copc

    print("uptime:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    folder = args.keep or tempfile.mkdtemp(prefix="copc-bench-")
    os.makedirs(folder, exist_ok=True)
    copc, plain = os.path.join(folder, "scene.copc.laz"), os.path.join(folder, "scene.laz")
    if not (os.path.exists(copc) and os.path.exists(plain)):
        t = time.perf_counter()
        scene = make_scene(SceneSpec.for_points(int(args.millions * 1e6), density_per_m2=4.0, seed=1))
        las = scene_las(scene)
        del scene
        nodes = write_copc(copc, las, grid=args.grid)
        del las
        plain_copy(copc, plain)
        print(f"made the files in {time.perf_counter() - t:.0f} s ({nodes} COPC nodes)")
    import numpy as _np
    from groundsieve.core.io.copc import open_index
    counts = open_index(copc).nodes["point_count"]
    print(f"COPC: {counts.size} nodes, points per node: median {int(_np.median(counts))}, max {int(counts.max())}")
    sizes = {p: os.path.getsize(p) / 1e6 for p in (copc, plain)}
    options = FilterOptions(tiling=TileOptions(tile_size_m=args.tile, workers=args.workers, parallel="threads"))
    results = {}
    for name, src in (("LAZ", plain), ("COPC", copc)):
        lines = []
        t = time.perf_counter()
        run = run_ground_filter(src, os.path.join(folder, f"out-{name}.laz"), SMRF(), options=options,
                                dtm_path=os.path.join(folder, f"dtm-{name}.tif"), dtm=DTMOptions(cell_size_m=1.0),
                                log=lines.append)
        results[name] = (run, dict(phases(lines), wall=time.perf_counter() - t))
        print(name, f"{run.point_count:,} points, {run.tiles} tiles:", results[name][1])
    same_classes = np.array_equal(laspy.read(os.path.join(folder, "out-LAZ.laz")).classification,
                                  laspy.read(os.path.join(folder, "out-COPC.laz")).classification)
    a = gdal.Open(os.path.join(folder, "dtm-LAZ.tif")).ReadAsArray()
    b = gdal.Open(os.path.join(folder, "dtm-COPC.tif")).ReadAsArray()
    run = results["COPC"][0]
    decompressed = sum(t["copc_read"] for t in run.tile_log)
    print()
    print(f"| phase | LAZ (s) | COPC (s) | COPC / LAZ |")
    print(f"|---|---:|---:|---:|")
    for phase, label in (("bin", "plan + bin (LAZ) / plan (COPC)"), ("tiles", "tiles"), ("write", "write"),
                         ("total", "whole run (engine)"), ("wall", "wall, with header scan and density")):
        x, y = results["LAZ"][1].get(phase), results["COPC"][1].get(phase)
        print(f"| {label} | {x:.1f} | {y:.1f} | {y / x:.2f} |")
    print()
    print(f"files: LAZ {sizes[plain]:.1f} MB, COPC {sizes[copc]:.1f} MB; COPC tiles decompressed "
          f"{decompressed:,} points in all ({decompressed / run.point_count:.2f} times the file), at most "
          f"{max(t['copc_read'] for t in run.tile_log) / run.point_count:.1%} of it for one tile")
    print(f"identical classes: {same_classes}; identical DTM: {a.shape == b.shape and np.array_equal(a, b)}")
    print("uptime:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())


if __name__ == "__main__":
    sys.exit(main())
