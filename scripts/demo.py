"""`make demo`: generate a synthetic scene with known truth, run groundsieve:smrf on it through
qgis_process (scripts/qgis-process), and print the accuracy against the truth; then check the DTM as a
surveyor does, against 60 checkpoints surveyed on the true terrain (groundsieve:accuracy), beside the DTM
of the scene's own classes (groundsieve:dtm, as from a vendor's classified delivery).

Leaves in the output folder: scene.laz (the generated cloud, truth in its classification),
scene_smrf.laz (classified), scene_dtm.tif (DTM), checkpoints.gpkg, accuracy.html (the report),
scene_dtm_classes.tif, and prints Type I/II/total error, kappa, the DTM's error against the true
terrain and the checkpoints' RMSEz, NVA and VVA.
"""
import argparse
import json
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
    ds = None

    # A surveyor's check: checkpoints on the true terrain (1.5 cm of survey noise), open (NVA) or under
    # vegetation (VVA), never on a roof; the SMRF DTM, and the DTM of the scene's own classes (a vendor's
    # delivery made into a DTM without filtering again), checked against them through qgis_process.
    points = out / "checkpoints.gpkg"
    write_checkpoints(scene, points, args.seed)
    classes_dtm = out / "scene_dtm_classes.tif"
    run([str(REPO / "scripts" / "qgis-process"), "run", "groundsieve:dtm", f"--INPUT={scene_path}",
         f"--DTM={classes_dtm}", "--DTM_CELL=1.0"])
    for name, raster, report in (("SMRF's DTM", dtm, out / "accuracy.html"),
                                 ("the DTM of the scene's classes (groundsieve:dtm)", classes_dtm,
                                  out / "accuracy_classes.html")):
        results = json.loads(run([str(REPO / "scripts" / "qgis-process"), "--json", "run", "groundsieve:accuracy",
                                  f"--DTM={raster}", f"--CHECKPOINTS={points}", "--ID_FIELD=name",
                                  "--LAND_COVER_FIELD=cover", f"--OUTPUT_HTML={report}"]))["results"]
        print(f"{name} against {int(results['COUNT'])} checkpoints (groundsieve:accuracy -> {report}):")
        print(f"  RMSEz {results['RMSEZ']:.3f} m, mean {results['MEAN']:+.3f} m; NVA: RMSEz {results['NVA_RMSEZ']:.3f} m "
              f"(ASPRS Ed. 2), {results['NVA95']:.3f} m at 95 % (Ed. 1); VVA: RMSEz {results['VVA_RMSEZ']:.3f} m, "
              f"95th percentile {results['VVA95']:.3f} m")


def run(cmd):
    """Run a command (qgis_process), exit with its output on failure; its stdout."""
    print("Running:", " ".join(cmd).replace(str(REPO) + "/", ""))
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout + proc.stderr)
        sys.exit("qgis_process failed")
    return proc.stdout


def write_checkpoints(scene, path, seed, per_cover=30):
    """``per_cover`` checkpoints in the open (no object point within 2 m: NVA) and as many under
    vegetation (a vegetation point within 1 m, no building within 3 m: VVA), at least 10 m inside the
    scene, their heights the true terrain's with 1.5 cm of survey noise, as a PointZ GeoPackage."""
    from osgeo import ogr, osr
    from scipy.spatial import cKDTree
    rng = np.random.default_rng(seed + 1000)
    objects = scene.classification != 2
    trees = {name: cKDTree(np.column_stack([scene.x[mask], scene.y[mask]])) for name, mask in
             (("object", objects), ("vegetation", np.isin(scene.classification, (3, 4, 5))),
              ("building", scene.classification == 6))}
    x0, x1, y0, y1 = scene.x.min() + 10, scene.x.max() - 10, scene.y.min() + 10, scene.y.max() - 10
    chosen = {"NVA": [], "VVA": []}
    while min(len(v) for v in chosen.values()) < per_cover:
        x, y = rng.uniform(x0, x1), rng.uniform(y0, y1)
        if not trees["object"].query_ball_point((x, y), 2.0):
            cover = "NVA"
        elif trees["vegetation"].query_ball_point((x, y), 1.0) and not trees["building"].query_ball_point((x, y), 3.0):
            cover = "VVA"
        else:
            continue
        if len(chosen[cover]) < per_cover:
            chosen[cover].append((x, y))
    if path.exists():
        path.unlink()
    ds = ogr.GetDriverByName("GPKG").CreateDataSource(str(path))
    srs = osr.SpatialReference()
    srs.ImportFromWkt(scene_crs_wkt())
    layer = ds.CreateLayer("checkpoints", srs, ogr.wkbPoint25D)
    layer.CreateField(ogr.FieldDefn("name", ogr.OFTString))
    layer.CreateField(ogr.FieldDefn("cover", ogr.OFTString))
    k = 0
    for cover, places in chosen.items():
        for x, y in places:
            k += 1
            feature = ogr.Feature(layer.GetLayerDefn())
            feature.SetField("name", f"CP{k:02d}")
            feature.SetField("cover", cover)
            z = float(scene.ground_z(np.array([x]), np.array([y]))[0]) + rng.normal(0.0, 0.015)
            point = ogr.Geometry(ogr.wkbPoint25D)
            point.AddPoint(float(x), float(y), z)
            feature.SetGeometry(point)
            layer.CreateFeature(feature)
    ds = None


if __name__ == "__main__":
    main()
