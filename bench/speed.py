"""Speed and memory of the ground filters on generated clouds (file I/O excluded).

    .venv/bin/python bench/speed.py [--filter smrf] [--millions 1 5 10] [--density 10]

Each size runs in a fresh child process: the scene is generated (core/synthetic.py), the
filter is compiled on a small cloud, then the peak resident memory is reset
(/proc/self/clear_refs) and the filter is timed on the whole cloud. "Extra memory" is the
peak resident set during the filter minus the resident set before it, divided by the number of
points: the memory the filter needs beyond its input arrays.
"""
import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / ".build" / "plugins"))


def _rss_kib(field):
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


def child(filter_name, n_points, density, seed):
    import numpy as np
    from groundsieve.core.synthetic import SceneSpec, make_scene
    sys.path.insert(0, str(REPO / "bench"))
    from filters import make_filter
    algorithm = make_filter(filter_name, None)
    scene = make_scene(SceneSpec.for_points(n_points, density_per_m2=density, seed=seed))
    xyz = np.column_stack([scene.x, scene.y, scene.z])
    del scene
    algorithm(xyz[:20000])  # compile the numba kernels (cached on disk after the first run)
    with open("/proc/self/clear_refs", "w") as refs:
        refs.write("5")  # reset the peak resident set (VmHWM)
    before = _rss_kib("VmRSS")
    t0 = time.perf_counter()
    ground = algorithm(xyz)
    seconds = time.perf_counter() - t0
    peak = _rss_kib("VmHWM")
    n = len(xyz)
    print(json.dumps({"filter": filter_name, "points": n, "seconds": seconds, "points_per_s": n / seconds,
                      "extra_bytes_per_point": (peak - before) * 1024 / n,
                      "ground_fraction": float(ground.mean())}))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--filter", default="smrf")
    parser.add_argument("--millions", type=float, nargs="+", default=[1, 5, 10])
    parser.add_argument("--density", type=float, default=10.0, help="pulses per m² of the scene")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.filter, int(args.millions[0] * 1e6), args.density, args.seed)
        return
    print(f"| filter | points | time (s) | points/s | extra memory (bytes/point) | ground % |")
    print(f"|---|---:|---:|---:|---:|---:|")
    for m in args.millions:
        proc = subprocess.run([sys.executable, __file__, "--child", "--filter", args.filter,
                               "--millions", str(m), "--density", str(args.density), "--seed", str(args.seed)],
                              capture_output=True, text=True, env=dict(os.environ, PYTHONWARNINGS="ignore"))
        if proc.returncode != 0:
            sys.exit(proc.stderr)
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        print(f"| {r['filter']} | {r['points']:,} | {r['seconds']:.2f} | {r['points_per_s']:,.0f} | "
              f"{r['extra_bytes_per_point']:.1f} | {100 * r['ground_fraction']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
