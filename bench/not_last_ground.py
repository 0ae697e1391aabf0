"""How many of a filter's ground points are not their pulse's last return, on the real labelled clouds
with returns in ../shared/data (lidR's plots and Topography, lasR's bcts tiles): the figures behind
``workflow.NOT_LAST_GROUND_SHARE``, above which a run warns that its ground holds canopy.

    .venv/bin/python bench/not_last_ground.py [--data ../shared/data]

Per file: its points, the share among the labelled ground (class 2), and for SMRF, CSF, PMF and PTD at
their defaults the share among the points each made ground.
"""
import argparse
import glob
import os

import numpy as np

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=os.path.join(os.path.dirname(REPO), "shared", "data"))
    args = parser.parse_args()
    from groundsieve.core.engine.workflow import FilterOptions, classify_cloud
    from groundsieve.core.filters.csf import CSF
    from groundsieve.core.filters.pmf import PMF
    from groundsieve.core.filters.ptd import PTD
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.io import read_cloud
    files = sorted(glob.glob(os.path.join(args.data, "lidR", "*.la[sz]"))
                   + glob.glob(os.path.join(args.data, "lasR_bcts", "*.la[sz]")))
    if not files:
        raise SystemExit(f"no lidR or lasR_bcts clouds under {args.data}")
    print("| file | points | labelled ground | SMRF | CSF | PMF | PTD |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for path in files:
        cloud = read_cloud(path)
        not_last = cloud.return_number < cloud.number_of_returns
        truth = np.asarray(cloud.classification) == 2
        cells = [f"{100 * not_last[truth].mean():.1f} %" if truth.any() else "-"]
        for algorithm in (SMRF(), CSF(), PMF(), PTD()):
            ground = classify_cloud(cloud, algorithm, FilterOptions()).ground
            cells.append(f"{100 * not_last[ground].mean():.1f} %")
        print(f"| {os.path.basename(path)} | {len(cloud):,} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
