#!/usr/bin/env python3
"""Every ground filter on lidR's labelled files (forest plots and a steep valley), as a user runs
them: the command line with its defaults (and the forest preset), a 0.5 m DTM; scored on the
files' own classes 1 and 2 (total, Type I, Type II error) and the DTM against a linear TIN of the
reference ground points, at the cell centres within 3 m of one (bias, RMSE, cells more than 2 m
too high).

    .venv/bin/python bench/lidr_plots.py [--data ../shared/data/lidR] [--files Megaplot ...] [--methods 'ptd' ...]

Markdown rows on stdout (docs/BENCHMARKS.md, "Real forest plots").
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

from _checkout import PLUGINS, REPO  # noqa: E402

import laspy  # noqa: E402
import numpy as np  # noqa: E402

METHODS = ["smrf", "smrf --preset forest-smrf", "csf", "ptd", "pmf", "hybrid --shipped fast",
           "hybrid --shipped accurate", "echogrid", "echogrid --mode evidence"]
FILES = ["MixedConifer", "Megaplot", "Topography"]
DTM_CELL = 0.5
NEAR_M = 3.0


def score(reference: str, classified: str, dtm: str) -> dict:
    from osgeo import gdal
    from scipy.interpolate import LinearNDInterpolator
    from scipy.spatial import cKDTree
    ref, out = laspy.read(reference), laspy.read(classified)
    rc, oc = np.asarray(ref.classification), np.asarray(out.classification)
    scored = np.isin(rc, [1, 2])
    truth, said = rc[scored] == 2, oc[scored] == 2
    res = dict(total=100 * np.mean(truth != said), type1=100 * np.sum(truth & ~said) / max(truth.sum(), 1),
               type2=100 * np.sum(~truth & said) / max((~truth).sum(), 1))
    ds = gdal.Open(dtm)
    band = ds.GetRasterBand(1)
    values = band.ReadAsArray().astype(float)
    x0, dx, _, y0, _, dy = ds.GetGeoTransform()
    ny, nx = values.shape
    X, Y = np.meshgrid(x0 + (np.arange(nx) + 0.5) * dx, y0 + (np.arange(ny) + 0.5) * dy)
    ground = rc == 2
    xy = np.column_stack([np.asarray(ref.x)[ground], np.asarray(ref.y)[ground]])
    reference_dtm = LinearNDInterpolator(xy, np.asarray(ref.z)[ground])(X, Y)
    near = (cKDTree(xy).query(np.column_stack([X.ravel(), Y.ravel()]))[0] < NEAR_M).reshape(X.shape)
    valid = (values != band.GetNoDataValue()) & np.isfinite(reference_dtm) & near
    err = (values - reference_dtm)[valid]
    res.update(bias=float(err.mean()), rmse=float(np.sqrt(np.mean(err ** 2))), high=int((err > 2).sum()))
    return res


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=os.path.join(REPO, "..", "shared", "data", "lidR"))
    parser.add_argument("--files", nargs="+", default=FILES)
    parser.add_argument("--methods", nargs="+", default=METHODS, help="e.g. 'ptd' 'ptd --low-outlier-support 0.2'")
    args = parser.parse_args()
    print("| file | method | total % | Type I % | Type II % | DTM bias m | DTM RMSE m | cells > 2 m high |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.files:
            src = os.path.abspath(os.path.join(args.data, name + ".laz"))
            for method in args.methods:
                out, dtm = os.path.join(tmp, "o.laz"), os.path.join(tmp, "o.tif")
                done = subprocess.run([sys.executable, "-m", "groundsieve", *method.split(), "--input", src,
                                       "--output", out, "--dtm", dtm, "--dtm-cell", str(DTM_CELL)],
                                      cwd=str(PLUGINS), capture_output=True, text=True)
                if done.returncode:
                    print(f"| {name} | `{method}` | failed: {done.stderr.strip().splitlines()[-1]} |||||| ")
                    continue
                r = score(src, out, dtm)
                print(f"| {name} | `{method}` | {r['total']:.2f} | {r['type1']:.2f} | {r['type2']:.2f} | "
                      f"{r['bias']:+.2f} | {r['rmse']:.2f} | {r['high']} |", flush=True)


if __name__ == "__main__":
    main()
