"""What a DTM from the classes a cloud already has costs (groundsieve:dtm, ``ClassGround``), against
the floor (reading the file alone) and against filtering it again with SMRF for the same DTM, in one
process on one generated LAZ with its truth classes.

    .venv/bin/python bench/dtm_classes.py [--millions 10] [--cell 1] [--repeats 2]

Per run: seconds of the read alone (``read_cloud``), of the class DTM run whole
(``run_ground_filter`` with ``ClassGround``: read, select, triangulate, write the COG), and of SMRF
with its DTM; the ratios to the read; the largest difference between the class DTM and the truth
terrain at the cell centres inside the ground hull. The kernels are compiled on a small cloud first;
the best of ``--repeats`` runs of each is kept (the machine is noisy).
"""
import argparse
import os
import tempfile
import time

import numpy as np

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)


def best_of(repeats, fn):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--millions", type=float, default=10.0)
    parser.add_argument("--cell", type=float, default=1.0)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()

    from osgeo import gdal

    from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
    from groundsieve.core.filters.classes import ClassGround
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.io import read_cloud
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene

    work = tempfile.mkdtemp(prefix="gs-dtm-classes-")
    warm = os.path.join(work, "warm.laz")
    write_scene(make_scene(SceneSpec.for_points(50_000, seed=1)), warm)
    dtm = DTMOptions(cell_size_m=args.cell)
    for algorithm in (ClassGround(), SMRF()):
        run_ground_filter(warm, None, algorithm, options=FilterOptions(keep_existing_classes=True),
                          dtm_path=os.path.join(work, "warm.tif"), dtm=dtm)
    scene = make_scene(SceneSpec.for_points(args.millions * 1e6, seed=args.seed))
    src = os.path.join(work, "scene.laz")
    write_scene(scene, src)
    terrain = scene.terrain
    n, ground = len(scene), int(scene.ground.sum())
    del scene
    out = os.path.join(work, "dtm.tif")
    t_read = best_of(args.repeats, lambda: read_cloud(src))
    t_class = best_of(args.repeats, lambda: run_ground_filter(
        src, None, ClassGround(), options=FilterOptions(keep_existing_classes=True), dtm_path=out, dtm=dtm))
    ds = gdal.Open(out)
    band = ds.GetRasterBand(1)
    values = band.ReadAsArray().astype(float)
    values[values == band.GetNoDataValue()] = np.nan
    x0, cell, _, top, _, _ = ds.GetGeoTransform()
    rows, cols = np.indices(values.shape)
    cx, cy = x0 + (cols + 0.5) * cell, top - (rows + 0.5) * cell
    inside = np.isfinite(values)
    error = np.abs(values[inside] - terrain(cx[inside], cy[inside]))
    ds = None
    t_smrf = best_of(args.repeats, lambda: run_ground_filter(
        src, None, SMRF(), options=FilterOptions(), dtm_path=out, dtm=dtm))
    print(f"| points | ground | cell | read s | class DTM s | SMRF + DTM s | class DTM / read | SMRF + DTM / class DTM "
          f"| p99 / max abs error vs truth m |")
    print("|---|---|---|---|---|---|---|---|---|")
    print(f"| {n:,} | {ground:,} | {args.cell:g} | {t_read:.2f} | {t_class:.2f} | {t_smrf:.2f} | "
          f"{t_class / t_read:.2f} | {t_smrf / t_class:.2f} | {np.percentile(error, 99):.3f} / {error.max():.3f} |")
    for name in os.listdir(work):
        os.remove(os.path.join(work, name))
    os.rmdir(work)


if __name__ == "__main__":
    main()
