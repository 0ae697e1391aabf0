"""Survey scale: seams and cost of buffered tiles (core/engine/tiles.py).

Seams, on the two adjacent bcts tiles of ../shared/data (seam at y = 629400):

    .venv/bin/python bench/tiles.py seams [--filters smrf pmf csf csf-startz] [--tile 100] [--buffers 60 90]

Each filter runs (1) on the merged cloud in memory (the reference), (2) through a .vpc over both
files in tiles of ``--tile`` m with the filter's reach as buffer, (3) the same without buffer, and
(4) on each file alone (what pdal_wrench's classify_ground does on a .vpc); the table gives the
agreement with (1) for the points within 20 m of the seam and for all points. ``--buffers`` adds
tiled runs with those buffers (m); ``csf-startz`` is CSF whose cloth falls from the merged cloud's
lowest z in every run (``cloth_start_z``), as a tiled run could with the survey's lowest z.

Scale, on a generated LAZ of N million points (blocks of the project's scene generator streamed to
disk, so no whole cloud is in memory):

    .venv/bin/python bench/tiles.py scale --millions 20 [--keep]

measures, in the same run, the floor (a plain streamed laspy decode + encode of the LAZ, laspy's
default LAZ backend) and ``scripts/qgis-process run groundsieve:smrf`` with a 1 m DTM, each with
wall time and the peak RSS of the whole process tree (worker processes included), sampled from /proc
every 0.2 s.
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

from _checkout import REPO  # noqa: E402 (puts this checkout's groundsieve on sys.path)

SEAM_Y = 629400.0


def seams(filters, tile, buffers=()):
    import numpy as np
    import laspy

    from filters import make_filter
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import FilterOptions, classify_cloud, run_ground_filter
    from groundsieve.core.io import read_cloud
    from groundsieve.core.io.lasfiles import read_vpc, scan_header, tile_cloud, write_vpc
    from groundsieve.tests.shared_data import shared_data_dir

    data = shared_data_dir("lasR_bcts/bcts_1.laz", "lasR_bcts/bcts_2.laz") / "lasR_bcts"
    files = [str(data / "bcts_1.laz"), str(data / "bcts_2.laz")]
    clouds = [read_cloud(p) for p in files]
    merged = tile_cloud(clouds)
    near = np.abs(merged.y - SEAM_Y) <= 20.0
    print(f"{len(merged):,} points, {int(near.sum()):,} within 20 m of the seam; tiles of {tile:g} m")
    print("| filter | buffer (reach) | tiled + buffer: seam / all | tiled, no buffer: seam / all | "
          "per file, no buffer: seam / all | time merged / tiled (s) |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as work:
        vpc = os.path.join(work, "bcts.vpc")
        write_vpc(vpc, [scan_header(p) for p in files], files)
        for name in filters:
            if name == "csf-startz":  # the cloth falls from the survey's lowest z in every tile
                from groundsieve.core.filters.csf import CSF
                algorithm = CSF(cloth_start_z=float(merged.z.min()))
            else:
                algorithm = make_filter(name, None)
            t = time.perf_counter()
            ref = classify_cloud(merged, algorithm).classification
            t_merged = time.perf_counter() - t

            def score(got):
                return f"{100 * np.mean(got[near] == ref[near]):.3f} / {100 * np.mean(got == ref):.3f} %"

            row = []
            t_tiled = None
            for buffer in (None, 0.0):
                out = os.path.join(work, f"out_{name}_{buffer}", "classified.vpc")
                os.makedirs(os.path.dirname(out))
                t = time.perf_counter()
                run_ground_filter(vpc, out, algorithm,
                                  options=FilterOptions(tiling=TileOptions(tile_size_m=tile, buffer_m=buffer)))
                t_tiled = t_tiled or time.perf_counter() - t
                got = np.concatenate([np.asarray(laspy.read(f).classification) for f in read_vpc(out)])
                row.append(score(got))
            per_file = np.concatenate([classify_cloud(c, algorithm).classification for c in clouds])
            row.append(score(per_file))
            print(f"| {name} | {algorithm.reach_m:g} m | {row[0]} | {row[1]} | {row[2]} | "
                  f"{t_merged:.1f} / {t_tiled:.1f} |", flush=True)
            for buffer in buffers:  # larger buffers than the reach: what they buy
                out = os.path.join(work, f"out_{name}_b{buffer:g}", "classified.vpc")
                os.makedirs(os.path.dirname(out))
                t = time.perf_counter()
                run_ground_filter(vpc, out, algorithm,
                                  options=FilterOptions(tiling=TileOptions(tile_size_m=tile, buffer_m=buffer)))
                got = np.concatenate([np.asarray(laspy.read(f).classification) for f in read_vpc(out)])
                print(f"| {name} | {buffer:g} m (given) | {score(got)} | | | - / {time.perf_counter() - t:.1f} |",
                      flush=True)


def generate(path, millions, density=10.0, block_points=2_000_000):
    """A LAZ of about ``millions`` M points: scene blocks of about ``block_points`` points side by
    side, each generated and written on its own (laspy's chunked writer)."""
    import math

    import laspy
    import numpy as np
    import pyproj

    from groundsieve.core.synthetic import SceneSpec, make_scene, scene_crs_wkt
    spec = SceneSpec.for_points(block_points, density_per_m2=density)
    blocks = max(1, int(round(millions * 1e6 / block_points)))
    per_row = int(math.ceil(math.sqrt(blocks)))
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = np.array([0.01, 0.01, 0.01])
    header.offsets = np.array([500000.0, 5400000.0, 0.0])
    header.add_crs(pyproj.CRS.from_wkt(scene_crs_wkt()))
    n = 0
    with laspy.open(path, mode="w", header=header) as writer:
        for k in range(blocks):
            scene = make_scene(SceneSpec(size_m=spec.size_m, density_per_m2=density, seed=k))
            i, j = divmod(k, per_row)
            rec = laspy.ScaleAwarePointRecord.zeros(len(scene), header=header)
            x0, y0 = scene.x.min(), scene.y.min()
            rec.x = scene.x - x0 + 500000.0 + i * spec.size_m
            rec.y = scene.y - y0 + 5400000.0 + j * spec.size_m
            rec.z = scene.z
            for name in ("classification", "return_number", "number_of_returns", "intensity", "gps_time"):
                rec[name] = getattr(scene, name)
            writer.write_points(rec)
            n += len(scene)
    return n


FLOOR = r"""
import sys, laspy
with laspy.open(sys.argv[1]) as r, laspy.open(sys.argv[2], mode="w", header=r.header) as w:
    for chunk in r.chunk_iterator(1_000_000):
        w.write_points(chunk)
"""


def _tree_rss_kib(root):
    """Sum of the resident sets of ``root`` and all its descendants (from /proc)."""
    children, rss = {}, {}
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            with open(f"/proc/{pid}/status") as f:
                rss[int(pid)] = next((int(line.split()[1]) for line in f if line.startswith("VmRSS:")), 0)
            children.setdefault(ppid, []).append(int(pid))
        except (OSError, ValueError, IndexError):
            continue
    total, todo = 0, [root]
    while todo:
        pid = todo.pop()
        total += rss.get(pid, 0)
        todo.extend(children.get(pid, []))
    return total


def timed(cmd):
    """Wall time and peak RSS of the whole process tree (sampled every 0.2 s; worker processes
    included), the command's stdout, and the CPU time (user + system) of the tree (the command's and
    that of every descendant it waited for: its worker processes)."""
    import resource
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    out = tempfile.TemporaryFile(mode="w+")
    proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, text=True)
    peak = 0
    while proc.poll() is None:
        peak = max(peak, _tree_rss_kib(proc.pid))
        time.sleep(0.2)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    out.seek(0)
    text = out.read()
    if proc.returncode:
        sys.exit(f"{' '.join(cmd)} failed:\n{text[-3000:]}")
    return wall, peak / 1024 / 1024, text, cpu


def scale(millions, keep, work):
    os.makedirs(work, exist_ok=True)
    src = os.path.join(work, f"gen_{millions}M.laz")
    if not os.path.exists(src):
        t = time.perf_counter()
        n = generate(src, millions)
        print(f"generated {src}: {n:,} points in {time.perf_counter() - t:.0f} s")
    import laspy
    with laspy.open(src) as r:
        n = r.header.point_count
    floor_out = os.path.join(work, "floor.laz")
    floor_s, floor_gb, _, _ = timed([sys.executable, "-c", FLOOR, src, floor_out])
    os.remove(floor_out)
    out, dtm = os.path.join(work, "smrf.laz"), os.path.join(work, "dtm.tif")
    cmd = [str(REPO / "scripts" / "qgis-process"), "run", "groundsieve:smrf", f"--INPUT={src}", f"--OUTPUT={out}",
           f"--DTM={dtm}", "--DTM_CELL=1"]
    run_s, run_gb, log, _ = timed(cmd)
    for line in log.splitlines():
        found = re.search(r"(Binned|Filtered|Done in|file\(s\),).*", line)
        if found:
            print("   ", found.group(0))
    print(f"| {n / 1e6:.1f} M | {floor_s:.0f} s, {floor_gb:.2f} GB | {run_s:.0f} s, {run_gb:.2f} GB | "
          f"{run_s / floor_s:.1f} | {n / run_s / 1e6:.2f} M/s |")
    for p in (out, dtm) + (() if keep else (src,)):
        if os.path.exists(p):
            os.remove(p)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    s = sub.add_parser("seams")
    s.add_argument("--filters", nargs="+", default=["smrf"])
    s.add_argument("--tile", type=float, default=100.0)
    s.add_argument("--buffers", type=float, nargs="*", default=[],
                   help="also run the tiles with these buffers (m), e.g. larger than the filter's reach")
    g = sub.add_parser("scale")
    g.add_argument("--millions", type=float, default=20)
    g.add_argument("--keep", action="store_true", help="keep the generated LAZ")
    g.add_argument("--work", default=os.path.join(str(REPO), ".build", "bench-tiles"))
    args = parser.parse_args()
    if args.what == "seams":
        seams(args.filters, args.tile, args.buffers)
    else:
        scale(args.millions, args.keep, args.work)


if __name__ == "__main__":
    main()
