"""How soon a filter stops after a cancel, at ten moments of a run on a generated cloud.

    .venv/bin/python bench/cancel_latency.py [--filter hybrid|hybrid-accurate|smrf|... (bench/filters.py)] [--millions 10]

The filter is run once whole (after a warm-up on 20,000 points) to time it, then ten times with a
cancel callable that turns true at 5 %, 15 %, ... 95 % of that time; each line gives the progress
reached and how long after the cancel the Cancelled exception came (or "finished" when the run
ended first). The promise (PROMISES.md, USER_GUIDE): within about a second. A cancelled numba
kernel left in a worker thread finishes in the background, so the script waits before the next run.
"""
import argparse
import time

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core.errors import Cancelled  # noqa: E402
from groundsieve.core.progress import Steps  # noqa: E402
from groundsieve.core.synthetic import SceneSpec, make_scene  # noqa: E402
from filters import make_filter  # noqa: E402 (bench/filters.py: the benches' filter names)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--filter", default="hybrid")
    parser.add_argument("--millions", type=float, default=10.0)
    parser.add_argument("--density", type=float, default=10.0)
    args = parser.parse_args()
    scene = make_scene(SceneSpec.for_points(int(args.millions * 1e6), density_per_m2=args.density, seed=0))
    xyz = np.column_stack([scene.x, scene.y, scene.z])
    del scene
    algorithm = make_filter(args.filter)
    algorithm(xyz[:20000])
    t0 = time.perf_counter()
    algorithm(xyz)
    whole = time.perf_counter() - t0
    print(f"{args.filter}, {len(xyz):,} points: the whole run {whole:.2f} s")
    worst = 0.0
    for share in np.arange(0.05, 1.0, 0.1):
        shown = [0.0]
        flip = time.perf_counter() + share * whole
        try:
            algorithm.run(xyz, Steps(lambda v: shown.__setitem__(0, v), lambda: time.perf_counter() >= flip))
            late, what = time.perf_counter() - flip, "finished"
        except Cancelled:
            late, what = time.perf_counter() - flip, "cancelled"
        worst = max(worst, late)
        print(f"  at {share:.0%} of the run (progress {shown[0]:.2f}): {what} {late:.3f} s after the cancel",
              flush=True)
        time.sleep(max(0.0, 1.5 - late))
    print(f"  worst {worst:.3f} s")


if __name__ == "__main__":
    main()
