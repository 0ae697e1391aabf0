"""Reading an ISPRS ``x y z label`` text cloud: time, peak memory and cancel latency of
``read_cloud`` against one ``np.loadtxt`` call on the same file (the peer: what the reader did before
it read in chunks).

    .venv/bin/python bench/text_read.py [--millions 4] [--folder /tmp] [--against REV]

Each measurement runs in a child process of its own (the peak resident memory, ``ru_maxrss``, is the
process's). The file is written once with ``np.savetxt`` (2 decimals, as the ISPRS samples). Then a
cancel at 0.3 s: how long after it ``Cancelled`` came. With ``--against REV``, ``read_cloud`` of that
git revision too (a temporary worktree), interleaved with this checkout's.
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

from _checkout import PLUGINS, REPO  # noqa: F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

CHILD = r"""
import resource, sys, time
sys.path.insert(0, {plugins!r})
import numpy as np
how, path = sys.argv[1], sys.argv[2]
start = time.perf_counter()
if how == "loadtxt":
    rows = np.loadtxt(path, ndmin=2, encoding="utf-8-sig")
    n = len(rows)
elif how == "read_cloud":
    from groundsieve.core.io import read_cloud
    n = len(read_cloud(path))
else:
    from groundsieve.core.errors import Cancelled
    from groundsieve.core.io import read_cloud
    from groundsieve.core.progress import Steps
    flip = [None]
    def cancelled():
        now = time.perf_counter()
        return now - start >= 0.3 and (flip.__setitem__(0, flip[0] or now) or True)
    try:
        n = len(read_cloud(path, Steps(is_cancelled=cancelled)))
        print(f"finished before the cancel: {{time.perf_counter() - start:.2f}} s")
    except Cancelled:
        print(f"cancelled {{time.perf_counter() - flip[0]:.3f}} s after the cancel")
    sys.exit(0)
seconds = time.perf_counter() - start
print(f"{{n:,}} rows in {{seconds:.2f}} s, peak {{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f}} MB")
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--millions", type=float, default=4.0)
    parser.add_argument("--folder", default="/tmp")
    parser.add_argument("--against", help="a git revision whose read_cloud is measured too")
    args = parser.parse_args()
    n = int(args.millions * 1e6)
    path = os.path.join(args.folder, f"gs_text_{n}.txt")
    if not os.path.exists(path):
        rng = np.random.default_rng(0)
        rows = np.column_stack([rng.uniform(0, 1000, n), rng.uniform(0, 1000, n), rng.uniform(0, 50, n),
                                rng.integers(0, 2, n)])
        np.savetxt(path, rows, fmt="%.2f %.2f %.2f %d")
    print(f"{path}: {os.path.getsize(path) / 2**20:,.0f} MB, {n:,} lines; the array alone "
          f"{n * 4 * 8 / 2**20:,.0f} MB")
    code = {"this": CHILD.format(plugins=str(PLUGINS))}
    with tempfile.TemporaryDirectory() as other:
        runs = [("this", "loadtxt"), ("this", "read_cloud")]
        if args.against:
            subprocess.run(["git", "-C", str(REPO), "worktree", "add", "-q", "--detach",
                            os.path.join(other, "groundsieve"), args.against], check=True)
            code[args.against] = CHILD.format(plugins=other)
            runs.append((args.against, "read_cloud"))
        try:
            for label, how in runs * 2 + [("this", "cancel")]:
                t0 = time.perf_counter()
                out = subprocess.run([sys.executable, "-c", code[label], how, path], capture_output=True, text=True,
                                     check=True)
                print(f"{label:>8} {how:>10}: {out.stdout.strip()} (process {time.perf_counter() - t0:.1f} s)")
        finally:
            if args.against:
                subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force",
                                os.path.join(other, "groundsieve")], check=True)


if __name__ == "__main__":
    main()
