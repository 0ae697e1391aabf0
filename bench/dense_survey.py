"""A dense UAV survey cut into a few files against its whole file: what tiling costs where the survey fits
the memory budget whole.

    .venv/bin/python bench/dense_survey.py [--side 100] [--density 400] [--files 2] [--preset uav-photogrammetry-smrf]

A generated photogrammetric scene (bench/presets.py's ``uav-photo-mixed`` kind: low vegetation, some buildings
and trees) of ``--side`` m at ``--density`` points/m² is written whole and cut into ``--files`` x ``--files``
LAZ files. SMRF with the preset (its 44 m window reads a 90 m buffer) and a 0.25 m DTM then runs through the
command line on the whole file and on the folder, each in a fresh process, with the default memory budget and
workers. Said: wall seconds, peak resident memory (the run with its workers), the tiles, and whether the two
runs' classes and DTMs are the same.
"""
import argparse
import os
import re
import tempfile

from _checkout import REPO  # noqa: F401,E402 (puts this checkout's groundsieve on sys.path)
from rf_tiles import run  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--side", type=float, default=100.0)
    parser.add_argument("--density", type=float, default=400.0)
    parser.add_argument("--files", type=int, default=2)
    parser.add_argument("--preset", default="uav-photogrammetry-smrf")
    args = parser.parse_args()
    import laspy
    import numpy as np
    from groundsieve.core.synthetic import SceneSpec, make_scene, photogrammetric, write_scene
    work = tempfile.mkdtemp(prefix="dense_survey_")
    scene = photogrammetric(make_scene(SceneSpec(size_m=args.side, density_per_m2=args.density, trees_per_ha=10.0,
                                                 shrub_fraction=0.3, buildings_per_ha=2.0, relief_m=2.0,
                                                 slope_pct=3.0, seed=5)))
    whole = os.path.join(work, "whole.laz")
    write_scene(scene, whole)
    las = laspy.read(whole)
    folder = os.path.join(work, "files")
    os.makedirs(folder)
    k, step = args.files, args.side / args.files
    fx = np.minimum(((las.x - las.x.min()) // step).astype(int), k - 1)
    fy = np.minimum(((las.y - las.y.min()) // step).astype(int), k - 1)
    for i in range(k):
        for j in range(k):
            part = laspy.LasData(las.header)
            part.points = las.points[(fx == i) & (fy == j)]
            part.write(os.path.join(folder, f"f{i}{j}.laz"))
    print(f"{len(las.points):,} points, {args.side:g} m at {args.density:g} points/m², {k * k} files; SMRF with "
          f"{args.preset}, a 0.25 m DTM")
    print("| input | tiles | wall s | peak MB |\n|---|---:|---:|---:|")
    for label, source, out in (("whole file", whole, "whole_out.laz"), ("folder of files", folder, "out.vpc")):
        seconds, peak, log = run(["smrf", "--input", source, "--output", os.path.join(work, out), "--preset",
                                  args.preset + ".json", "--dtm", os.path.join(work, out.split(".")[0] + ".tif"),
                                  "--dtm-cell", "0.25"], keep_log=True)
        tiles = re.search(r"Filtered ([\d,]+) tile", log)
        print(f"| {label} | {tiles.group(1) if tiles else 'whole'} | {seconds:.1f} | {peak:,.0f} |", flush=True)
    from osgeo import gdal
    a = gdal.Open(os.path.join(work, "whole_out.tif")).ReadAsArray()
    b = gdal.Open(os.path.join(work, "out.tif")).ReadAsArray()
    cls = np.asarray(laspy.read(os.path.join(work, "whole_out.laz")).classification)
    got = {name: np.asarray(laspy.read(os.path.join(work, "out", name)).classification)
           for name in os.listdir(os.path.join(work, "out"))}
    same = all(np.array_equal(got[f"f{i}{j}.laz"], cls[(fx == i) & (fy == j)]) for i in range(k) for j in range(k))
    print(f"classes: {'the same' if same else 'different'}; DTM: "
          f"{'the same, cell for cell' if a.shape == b.shape and np.allclose(a, b, atol=1e-3) else 'different'}")


if __name__ == "__main__":
    main()
