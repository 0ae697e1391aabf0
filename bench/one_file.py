"""A survey run as a job array, one job per file (``--only``), against one run of the whole survey.

    .venv/bin/python bench/one_file.py [--files 4] [--points 4000000] [--tile-size 0] [--workers 2] [--copc]

A generated scene (core/synthetic.py) of about ``--points`` points is cut into about ``--files`` x
``--files`` LAZ files on multiples of their side (as a vendor's delivery); the command line's SMRF with a
1 m DTM, in tiles of ``--tile-size`` (the files' side by default), runs (1) on the whole survey (a folder), (2) on each
file with ``--only K``, one after the other (a job array on one node; on a cluster the jobs run at
once on nodes of their own), and (3) on each file alone, without its neighbours (what a job array
without ``--only`` gives). With ``--copc`` the files are LAS 1.4 point format 6, and the jobs with
``--only`` run twice: on them, and on the same points written as COPC (copclib, as in
tests/core/test_copc.py; requirements-dev.txt), whose neighbours are read by bounds. Said: the wall times (the jobs' sum and their longest), the points each job
read and filtered, and how the jobs' classes and DTM cells compare with the whole run's. The floor: a
plain laspy read of every file, in the same run.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time

from _checkout import PLUGINS  # noqa: E402 (puts this checkout's groundsieve on sys.path)


def run(args, extra):
    cmd = [sys.executable, "-m", "groundsieve", "smrf", "--json", "--workers", str(args.workers)] + extra
    if args.tile_size:
        cmd += ["--tile-size", str(args.tile_size)]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(PLUGINS)),
                          timeout=3600)
    seconds = time.perf_counter() - start
    if proc.returncode:
        sys.exit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout), proc.stderr, seconds


def compare(folder_a, folder_b, names, dtm_a, dtms_b):
    """Points whose class differs, and DTM cells that differ (and by how much at most)."""
    import laspy
    import numpy as np
    from osgeo import gdal
    differ = 0
    for name in names:
        other = os.path.join(folder_b, name)
        if not os.path.exists(other):  # a COPC input's copy: its own name, its points in the octree's order
            other = os.path.join(folder_b, name[:-4] + ".copc.laz")
        a, b = laspy.read(os.path.join(folder_a, name)), laspy.read(other)
        if "gps_time" in a.point_format.dimension_names:  # (--copc: each point's number in gps_time)
            a_cls = np.asarray(a.classification)[np.argsort(np.asarray(a.gps_time), kind="stable")]
            b_cls = np.asarray(b.classification)[np.argsort(np.asarray(b.gps_time), kind="stable")]
        else:
            a_cls, b_cls = np.asarray(a.classification), np.asarray(b.classification)
        differ += int(np.count_nonzero(a_cls != b_cls))
    whole = gdal.Open(dtm_a)
    wg, w = whole.GetGeoTransform(), whole.ReadAsArray()
    cells, worst = 0, 0.0
    for path in dtms_b:
        ds = gdal.Open(path)
        g, v = ds.GetGeoTransform(), ds.ReadAsArray()
        col, row = round((g[0] - wg[0]) / wg[1]), round((g[3] - wg[3]) / wg[5])
        sub = w[row:row + v.shape[0], col:col + v.shape[1]]
        if sub.shape != v.shape:  # (a file's DTM beyond the whole one's cut: compare what both hold)
            v = v[:sub.shape[0], :sub.shape[1]]
        both = (v != -9999) & (sub != -9999)
        bad = (v != sub)
        cells += int(np.count_nonzero(bad))
        if both.any():
            worst = max(worst, float(np.max(np.abs(v[both] - sub[both]))))
    return differ, cells, worst


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--files", type=int, default=4, help="files along each side (default 4: 16 files)")
    parser.add_argument("--points", type=int, default=4_000_000)
    parser.add_argument("--tile-size", type=float, default=0.0,
                        help="set for every run (0 = the files' side: one tile a file)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--copc", action="store_true",
                        help="point format 6 files, and the jobs run on them as COPC too (needs copclib)")
    args = parser.parse_args()
    import laspy
    import numpy as np
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    root = tempfile.mkdtemp(prefix="gs-one-file-")
    src = os.path.join(root, "scene.laz")
    write_scene(make_scene(SceneSpec.for_points(args.points, density_per_m2=14.0, seed=11)), src)
    las = laspy.read(src)
    if args.copc:  # COPC's point formats are 6-8; each point's number in gps_time, to match the COPC copies' points
        las = laspy.convert(las, point_format_id=6, file_version="1.4")
        las.gps_time = np.arange(len(las.points), dtype=np.float64)
    survey = os.path.join(root, "survey")
    os.makedirs(survey)
    x, y = np.asarray(las.x), np.asarray(las.y)
    (x0, y0), (x1, y1) = las.header.mins[:2], las.header.maxs[:2]
    # files on multiples of their side, as a vendor's delivery (e.g. 1 km files on whole kilometres)
    side = max(10.0, round(max(x1 - x0, y1 - y0) / args.files / 10.0) * 10.0)
    ix, iy = np.floor(x / side).astype(int), np.floor(y / side).astype(int)
    names = []
    for i in np.unique(ix):
        for j in np.unique(iy):
            sel = (ix == i) & (iy == j)
            if not sel.any():
                continue
            part = laspy.LasData(las.header)
            part.points = las.points[sel]
            names.append(f"t{i}_{j}.laz")
            part.write(os.path.join(survey, names[-1]))
    if not args.tile_size:
        args.tile_size = side
    del las, x, y
    copc = None
    if args.copc:
        sys.path.insert(0, str(PLUGINS))
        from groundsieve.tests.core.test_copc import write_copc
        copc = os.path.join(root, "copc")
        os.makedirs(copc)
        start = time.perf_counter()
        for name in names:
            write_copc(os.path.join(copc, name[:-4] + ".copc.laz"), laspy.read(os.path.join(survey, name)))
        print(f"COPC copies written in {time.perf_counter() - start:.1f} s, in {copc}")
    print(f"{args.points:,} points in {len(names)} files of about {side:.0f} m, in {survey}")
    start = time.perf_counter()
    for name in names:
        laspy.read(os.path.join(survey, name))
    floor = time.perf_counter() - start
    os.makedirs(os.path.join(root, "whole"))
    whole, log, whole_s = run(args, ["--input", survey, "--output", os.path.join(root, "whole", "c.vpc"),
                                     "--dtm", os.path.join(root, "whole", "dtm.tif")])
    print(f"floor (laspy reads every file): {floor:.1f} s")
    print(f"whole survey: {whole_s:.1f} s, tiles of {whole['tile_size']:g} m, {whole['tiles']} tiles")
    rows = []
    modes = [("with --only (neighbours' buffers)", lambda k, n: ["--only", str(k)], survey),
             ("each file alone", lambda k, n: [], survey)]
    if copc:
        modes.insert(1, ("with --only on the COPC copies", lambda k, n: ["--only", str(k)], copc))
    for label, extra, folder in modes:
        out = os.path.join(root, re.sub(r"\W+", "_", label))
        times, tiles, read = [], 0, 0
        for k, name in enumerate(names):
            src_k = folder if label.startswith("with") else os.path.join(folder, name)
            dtm = os.path.join(out, "dtm") if label.startswith("with") else os.path.join(out, "dtm",
                                                                                        name[:-4] + ".tif")
            cls = os.path.join(out, "cls") if label.startswith("with") else os.path.join(out, "cls", name)
            os.makedirs(os.path.join(out, "dtm"), exist_ok=True)
            os.makedirs(os.path.join(out, "cls"), exist_ok=True)
            doc, log, seconds = run(args, ["--input", src_k, "--output", cls, "--dtm", dtm] + extra(k, name))
            times.append(seconds)
            tiles += doc["tiles"] or 0
            m = re.search(r"^(\d+) file\(s\), ([\d,]+) points", log, re.M)
            read += int(m.group(1)) if m else 1
        differ, cells, worst = compare(os.path.join(root, "whole", "c"), os.path.join(out, "cls"), names,
                                       os.path.join(root, "whole", "dtm.tif"),
                                       [os.path.join(out, "dtm", n[:-4] + ".tif") for n in names])
        rows.append((label, sum(times), max(times), tiles, read, differ, cells, worst))
    print("| run | seconds (sum of jobs) | longest job | x whole | tiles filtered | files read | points whose class "
          "differs from the whole run | DTM cells that differ | largest DTM difference (m) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    print(f"| whole survey | {whole_s:.1f} | - | 1.00 | {whole['tiles']} | {len(names)} | - | - | - |")
    for label, total, longest, tiles, read, differ, cells, worst in rows:
        print(f"| {len(names)} jobs, {label} | {total:.1f} | {longest:.1f} | {total / whole_s:.2f} | {tiles} | {read} "
              f"| {differ:,} | {cells:,} | {worst:.2f} |")


if __name__ == "__main__":
    main()
