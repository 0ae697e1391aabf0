"""rfclassify of a model of colour and returns (matrone2024's C2) in buffered tiles, against its whole run.

    .venv/bin/python bench/rf_tiles.py [--points 4000000] [--tile-size 100] [--workers 2] [--dtm]

A generated scene (core/synthetic.py) of about ``--points`` points at 20 points/m² is written as LAS 1.4
point format 7 (LAZ) with colour that tells the classes apart only roughly, as in tests/core/test_rf.py. A
model of the classes present (C2: colour and return number, 20 trees) is trained on a 60 m patch of another
scene of the same kind. The command line's rfclassify then runs, each in a fresh process: (1) whole, (2) in
tiles of ``--tile-size`` m, and, for the tiles' floor, (3) a model of x, y, z features alone (the HYBRID
preset's ground model, which needs no attribute of the records) in the same tiles. Said: wall seconds, the
peak resident memory of each process, and how the tiled classes compare with the whole run's. With ``--dtm`` every run also writes a 1 m DTM (the tiles then predict their buffers too,
whose ground the DTM needs, and read at least 30 m around each tile).
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

from _checkout import PLUGINS  # noqa: E402 (puts this checkout's groundsieve on sys.path)


def _tree_rss_kb(pgid: int) -> int:
    """Resident memory (kB) of every process of the process group ``pgid`` (the run and its workers)."""
    total = 0
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            if int(fields[2]) != pgid:  # (field 5 of stat: the process group)
                continue
            with open(f"/proc/{pid}/status") as f:
                total += next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))
        except (OSError, StopIteration, ValueError, IndexError):
            continue
    return total


def run(cmd, keep_log=False):
    """(wall seconds, peak resident MB of the run with its worker processes, sampled every 0.1 s), and its
    log (stderr) with ``keep_log``. (The log goes to a file: a pipe left unread while the run goes on
    stops it once 64 kB of tile lines fill it.)"""
    start = time.perf_counter()
    with tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen([sys.executable, "-m", "groundsieve"] + cmd, stdout=subprocess.DEVNULL,
                                stderr=err, text=True, env=dict(os.environ, PYTHONPATH=str(PLUGINS)),
                                start_new_session=True)
        peak = 0
        while proc.poll() is None:
            peak = max(peak, _tree_rss_kb(proc.pid))
            time.sleep(0.1)
        seconds = time.perf_counter() - start
        err.seek(0)
        log = err.read()
    if proc.returncode:
        sys.exit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{log[-3000:]}")
    return (seconds, peak / 1024.0) + ((log,) if keep_log else ())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=4_000_000)
    parser.add_argument("--tile-size", type=float, default=100.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--folder", default=None, help="keep the files here (default: a temporary folder)")
    parser.add_argument("--dtm", action="store_true", help="each run writes a 1 m DTM too")
    args = parser.parse_args()
    import laspy
    import numpy as np
    from groundsieve.core.engine import learning
    from groundsieve.core.learn import rf
    from groundsieve.tests.core.test_rf import _coloured_scene
    work = args.folder or tempfile.mkdtemp(prefix="rf_tiles_")
    os.makedirs(work, exist_ok=True)
    scene = os.path.join(work, "scene.laz")
    side = (args.points / 20.0) ** 0.5
    _coloured_scene(scene, size_m=side, seed=8, density=20.0)
    _coloured_scene(os.path.join(work, "patch.laz"), size_m=60.0, seed=3, density=20.0)
    models = {}
    for name, features, vs_rest in (("c2", ("radiometry", "return_number"), False), ("xyz", tuple(rf.PRESETS["HYBRID"]), True)):
        models[name] = os.path.join(work, f"{name}.npz")
        learning.train_file(os.path.join(work, "patch.laz"), models[name], None,
                            learning.TrainOptions(features=features, params=rf.ForestParams(n_trees=20),
                                                  block_m=15.0, ground_vs_rest=vs_rest))
    points = int(laspy.open(scene).header.point_count)
    print(f"{points:,} points, {side:.0f} m square, tiles of {args.tile_size:g} m, {args.workers} workers")
    rows = []
    common = ["--workers", str(args.workers), "--tile-size", str(args.tile_size)]
    for label, model, out, tiled in (("C2 whole", "c2", "whole.laz", False), ("C2 tiles", "c2", "tiled.laz", True),
                                     ("x, y, z ground model, whole", "xyz", "xyz_whole.laz", False),
                                     ("x, y, z ground model, tiles", "xyz", "xyz.laz", True)):
        target = os.path.join(work, out)
        dtm = ["--dtm", target[:-4] + ".tif"] if args.dtm else []
        for old in [target] + dtm[1:]:
            if os.path.exists(old):
                os.remove(old)
        seconds, peak = run(["rfclassify", "--input", scene, "--model", models[model], "--output", target]
                            + dtm + (common if tiled else []))
        rows.append((label, seconds, peak))
    whole = np.asarray(laspy.read(os.path.join(work, "whole.laz")).classification)
    tiled = np.asarray(laspy.read(os.path.join(work, "tiled.laz")).classification)
    print("| run | wall s | peak MB |\n|---|---:|---:|")
    for label, seconds, peak in rows:
        print(f"| {label} | {seconds:.1f} | {peak:,.0f} |")
    print(f"C2 tiles against C2 whole: {np.mean(tiled == whole):.6%} of the points the same class "
          f"(classes {sorted(int(c) for c in np.unique(whole))})")
    if args.dtm:
        from osgeo import gdal
        a, b = (gdal.Open(os.path.join(work, n)).ReadAsArray() for n in ("whole.tif", "tiled.tif"))
        same = a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))
        print(f"C2 tiles' DTM against the whole run's: {'the same, cell for cell' if same else 'different'}")


if __name__ == "__main__":
    main()
