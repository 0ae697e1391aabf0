#!/usr/bin/env python3
"""Progress over time of one whole-cloud run, as the dialog would see it: every progress value
and log line with its time, the longest time the bar stood still, and when it reached 100 %
against when the last output appeared. Used to weight the stages (core/engine/workflow.py
stage_weights) and to check them.

    .venv/bin/python scripts/desktop_profile.py --input .build/desktop/cloud5m.laz --filter smrf
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".build", "plugins"))


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--input", required=True)
    ap.add_argument("--filter", default="smrf", choices=["smrf", "csf", "pmf"])
    ap.add_argument("--cell", type=float, default=1.0)
    ap.add_argument("--out", default=None, help="folder for the outputs (a temporary one by default)")
    args = ap.parse_args()
    from groundsieve.core.engine.workflow import DTMOptions, run_ground_filter
    from groundsieve.core.filters.csf import CSF
    from groundsieve.core.filters.pmf import PMF
    from groundsieve.core.filters.smrf import SMRF
    algorithm = {"smrf": SMRF, "csf": CSF, "pmf": PMF}[args.filter]()
    out = args.out or tempfile.mkdtemp(prefix="gs-profile-")
    laz, tif = os.path.join(out, "classified.laz"), os.path.join(out, "dtm.tif")
    events = []
    t0 = time.perf_counter()
    run_ground_filter(args.input, laz, algorithm, dtm_path=tif, dtm=DTMOptions(cell_size_m=args.cell),
                      progress=lambda f: events.append((time.perf_counter() - t0, f, None)),
                      log=lambda m: events.append((time.perf_counter() - t0, None, m)))
    total = time.perf_counter() - t0
    for t, f, msg in events:
        if msg is not None:
            print(f"{t:7.2f} s  log  {msg}")
        else:
            print(f"{t:7.2f} s  {100 * f:5.1f} %")
    values = [(t, f) for t, f, msg in events if msg is None]
    for name, shown in (("value", lambda f: f), ("whole percent (what the dialog's bar shows)", lambda f: int(100 * f))):
        stall, stall_at = stand_still(values, total, shown)
        print(f"total {total:.2f} s; longest stand-still of the {name}: {stall:.2f} s "
              f"({100 * stall / total:.1f} % of the run) from {stall_at:.2f} s")
    return 0


def stand_still(values, total, shown):
    """The longest time ``shown(value)`` did not change, and when it began."""
    last, stall, stall_at, prev = 0.0, 0.0, 0.0, None
    for t, f in values:
        if prev is None or shown(f) > prev:
            if t - last > stall:
                stall, stall_at = t - last, last
            last, prev = t, shown(f)
    if total - last > stall:
        stall, stall_at = total - last, last
    return stall, stall_at


if __name__ == "__main__":
    sys.exit(main())
