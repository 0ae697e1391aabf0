"""`make demo`: generate a synthetic scene with known truth, run groundsieve:smrf on it through
qgis_process (scripts/qgis-process), and print the accuracy against the truth.

Leaves in the output folder: scene.laz (the generated cloud, truth in its classification),
scene_smrf.laz (classified), scene_dtm.tif (DTM), and prints Type I/II/total error, kappa and
the DTM's error against the true terrain.
"""
import argparse
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / ".build" / "plugins"))

import numpy as np  # noqa: E402

from groundsieve.core.io import read_cloud  # noqa: E402
from groundsieve.core.metrics import ground_accuracy  # noqa: E402
from groundsieve.core.synthetic import SceneSpec, make_scene, scene_crs_wkt, write_scene  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="out", help="output folder (default: out)")
    parser.add_argument("--size", type=float, default=300.0, help="scene side in m (default 300)")
    parser.add_argument("--density", type=float, default=10.0, help="pulses per m² (default 10)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    scene = make_scene(SceneSpec(size_m=args.size, density_per_m2=args.density, seed=args.seed))
    scene_path, classified, dtm = out / "scene.laz", out / "scene_smrf.laz", out / "scene_dtm.tif"
    write_scene(scene, str(scene_path), crs_wkt=scene_crs_wkt())
    print(f"Generated {len(scene.x):,} points ({args.size:g} m x {args.size:g} m, "
          f"{args.density:g} pulses/m², seed {args.seed}) -> {scene_path}")

    cmd = [str(REPO / "scripts" / "qgis-process"), "run", "groundsieve:smrf",
           f"--INPUT={scene_path}", f"--OUTPUT={classified}", f"--DTM={dtm}", "--DTM_CELL=1.0"]
    print("Running:", " ".join(cmd).replace(str(REPO) + "/", ""))
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout + proc.stderr)
        sys.exit("qgis_process failed")

    result = read_cloud(str(classified))
    acc = ground_accuracy(scene.classification == 2, result.classification == 2)
    print(f"qgis_process run took {elapsed:.1f} s (QGIS start-up included)")
    print(f"SMRF against the known truth ({acc.n:,} points):")
    print(f"  Type I  {100 * acc.type1:6.2f} %   (ground called object)")
    print(f"  Type II {100 * acc.type2:6.2f} %   (object called ground)")
    print(f"  Total   {100 * acc.total:6.2f} %   kappa {100 * acc.kappa:.2f} %")

    from osgeo import gdal
    ds = gdal.Open(str(dtm))
    values = ds.GetRasterBand(1).ReadAsArray().astype(float)
    gt = ds.GetGeoTransform()
    cols = gt[0] + (np.arange(ds.RasterXSize) + 0.5) * gt[1]
    rows = gt[3] + (np.arange(ds.RasterYSize) + 0.5) * gt[5]
    gx, gy = np.meshgrid(cols, rows)
    valid = values != ds.GetRasterBand(1).GetNoDataValue()
    err = values[valid] - scene.ground_z(gx[valid], gy[valid])
    print(f"DTM {ds.RasterXSize} x {ds.RasterYSize} cells of {gt[1]:g} m -> {dtm}")
    print(f"  against the true terrain: RMSE {np.sqrt(np.mean(err ** 2)):.3f} m, "
          f"|error| 95th percentile {np.percentile(np.abs(err), 95):.3f} m, "
          f"{100 * valid.mean():.1f} % of cells filled")


if __name__ == "__main__":
    main()
