"""A run under a batch job's address-space limit (``ulimit -v``, Grid Engine's h_vmem, PBS's vmem): the
command line's SMRF with a 0.5 m DTM on a generated cloud, at each limit, with the default memory budget
(and optionally a set one). Says per limit the exit status, the --json document's kind, the budget the run
took and its time: the figures behind ``tiles.default_memory_budget_mb`` and ``machine.fit_address_space``.

    .venv/bin/python bench/ulimit.py [--points 3600000] [--limits 1000000,1200000,1500000,2000000] [--budget MB]

The cloud is a generated scene (core/synthetic.py) of about ``--points`` points, written once to a
temporary folder.
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


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=3_600_000)
    parser.add_argument("--limits", default="1000000,1200000,1500000,2000000", help="ulimit -v values (kB)")
    parser.add_argument("--budget", type=float, default=0.0, help="--memory-budget of the runs (MB; 0 = default)")
    args = parser.parse_args()
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    folder = tempfile.mkdtemp(prefix="gs-ulimit-")
    src = os.path.join(folder, "scene.laz")
    scene = make_scene(SceneSpec.for_points(args.points, density_per_m2=14.0, seed=7))
    write_scene(scene, src)
    print(f"{len(scene):,} points in {src}")
    print("| ulimit -v (kB) | exit | kind | memory budget | tiles | seconds |")
    print("|---:|---:|---|---:|---:|---:|")
    for limit in (int(v) for v in args.limits.split(",")):
        cmd = [sys.executable, "-m", "groundsieve", "smrf", "--input", src, "--output", os.path.join(folder, "o.laz"),
               "--dtm", os.path.join(folder, "o.tif"), "--dtm-cell", "0.5", "--json"]
        if args.budget:
            cmd += ["--memory-budget", str(args.budget)]
        env = dict(os.environ, PYTHONPATH=str(PLUGINS))
        start = time.perf_counter()
        proc = subprocess.run(["bash", "-c", f'ulimit -v {limit} && exec "$@"', "bash", *cmd], capture_output=True,
                              text=True, env=env, timeout=900)
        seconds = time.perf_counter() - start
        try:
            doc = json.loads(proc.stdout or "{}")
        except json.JSONDecodeError:
            doc = {}
        budget = re.search(r"memory budget \(([\d,]+) MB\)", proc.stderr)
        kind = doc.get("kind", "done" if doc.get("status") == "done" else "no JSON")
        print(f"| {limit:,} | {proc.returncode} | {kind} | {budget.group(1) + ' MB' if budget else 'whole run'} | "
              f"{doc.get('tiles') or '-'} | {seconds:.1f} |")


if __name__ == "__main__":
    main()
