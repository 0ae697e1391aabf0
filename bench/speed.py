"""Speed and memory of the ground filters on generated clouds (file I/O excluded).

Two timings per size: the filter alone on an (n, 3) array, and the driver's whole job without
file I/O (core.engine.workflow.classify_cloud: point selection, filter, ASPRS classes) plus the 1 m
TIN DTM from the ground points (core.engine.workflow.make_dtm).

    .venv/bin/python bench/speed.py [--filter smrf] [--millions 1 5 10] [--density 10] [--no-dtm]

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

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)


def _rss_kib(field):
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


def child(filter_name, n_points, density, seed, dtm=True):
    import numpy as np

    from groundsieve.core.synthetic import SceneSpec, make_scene
    from filters import make_filter
    algorithm = make_filter(filter_name, None)
    scene = make_scene(SceneSpec.for_points(n_points, density_per_m2=density, seed=seed))
    xyz = np.column_stack([scene.x, scene.y, scene.z])
    rn, nr = scene.return_number, scene.number_of_returns
    del scene
    # Filters that use return numbers (point_fields) get the scene's.
    fields = {name: {"return_number": rn, "number_of_returns": nr}[name]
              for name in getattr(algorithm, "point_fields", ())}
    from groundsieve.core.io import PointCloud
    from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, classify_cloud, make_dtm
    # Compile the numba kernels (cached on disk after the first run).
    algorithm(xyz[:20000], **{name: values[:20000] for name, values in fields.items()})
    with open("/proc/self/clear_refs", "w") as refs:
        refs.write("5")  # reset the peak resident set (VmHWM)
    before = _rss_kib("VmRSS")
    load = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), time.process_time()
    ground = algorithm(xyz, **fields)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = _rss_kib("VmHWM")
    n = len(xyz)
    del ground
    cloud = PointCloud("generated", np.ascontiguousarray(xyz[:, 0]), np.ascontiguousarray(xyz[:, 1]),
                       np.ascontiguousarray(xyz[:, 2]), np.zeros(n, dtype=np.uint8), rn, nr,
                       has_return_info=True)
    del xyz
    t0 = time.perf_counter()
    ground = classify_cloud(cloud, algorithm, FilterOptions()).ground
    t1 = time.perf_counter()
    if dtm:
        make_dtm(cloud.x, cloud.y, cloud.z, ground, DTMOptions(cell_size_m=1.0))
    t2 = time.perf_counter()
    print(json.dumps({"filter": filter_name, "points": n, "seconds": seconds, "points_per_s": n / seconds,
                      "cpu_seconds": cpu, "load": load,
                      "extra_bytes_per_point": (peak - before) * 1024 / n,
                      "driver_seconds": t1 - t0, "dtm_seconds": t2 - t1,
                      "ground_fraction": float(ground.mean())}))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--filter", default="smrf")
    parser.add_argument("--millions", type=float, nargs="+", default=[1, 5, 10])
    parser.add_argument("--density", type=float, default=10.0, help="pulses per m² of the scene")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-dtm", action="store_true", help="skip the TIN DTM (column left empty)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.filter, int(args.millions[0] * 1e6), args.density, args.seed, dtm=not args.no_dtm)
        return
    print("| filter | points | filter (s) | filter points/s | filter CPU (s) | load average (1 min) at its start "
          "| extra memory (bytes/point) | driver without I/O (s) | driver points/s | 1 m TIN DTM (s) | ground % |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for m in args.millions:
        proc = subprocess.run([sys.executable, __file__, "--child", "--filter", args.filter,
                               "--millions", str(m), "--density", str(args.density), "--seed", str(args.seed)]
                              + (["--no-dtm"] if args.no_dtm else []),
                              capture_output=True, text=True,
                              # A fixed malloc mmap threshold: freed arrays go back to the system and
                              # new ones are counted, so the peak-memory figure is not hidden by reuse.
                              env=dict(os.environ, PYTHONWARNINGS="ignore", MALLOC_MMAP_THRESHOLD_="131072",
                                       MALLOC_TRIM_THRESHOLD_="131072"))
        if proc.returncode != 0:
            sys.exit(proc.stderr)
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        dtm = f"{r['dtm_seconds']:.2f}" if not args.no_dtm else ""
        print(f"| {r['filter']} | {r['points']:,} | {r['seconds']:.2f} | {r['points_per_s']:,.0f} | "
              f"{r['cpu_seconds']:.2f} | {r['load']:.1f} | {r['extra_bytes_per_point']:.1f} | {r['driver_seconds']:.2f} | "
              f"{r['points'] / r['driver_seconds']:,.0f} | {dtm} | "
              f"{100 * r['ground_fraction']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
