"""Issue 16 through the real qgis_process: withheld points, ignored classes and kept classes stay
as marked, the DTM is the one made without the withheld and noise points, a bad class list is
refused with a message and no output."""
import subprocess
from pathlib import Path

import laspy
import numpy as np

from groundsieve.tests.core.test_marked_points import train_block_model, write_scene

REPO = Path(__file__).resolve().parents[2]
WRAPPER = REPO / "scripts" / "qgis-process"


def _run(*args):
    proc = subprocess.run([str(WRAPPER), "run", *args], capture_output=True, text=True, timeout=600)
    return proc.returncode, proc.stdout + proc.stderr


def _read(path):
    las = laspy.read(str(path))
    return np.asarray(las.classification), np.asarray(las.withheld).astype(bool), np.asarray(las.synthetic)


def _dtm(path):
    from osgeo import gdal
    ds = gdal.Open(str(path))
    return ds.GetGeoTransform(), ds.GetRasterBand(1).ReadAsArray()


def test_smrf_keeps_withheld_noise_and_kept_classes(tmp_path):
    src = tmp_path / "in.las"
    kind, cls_in = write_scene(src, fmt=6, far_noise=True)
    _, wh_in, syn_in = _read(src)
    out, dtm = tmp_path / "out.laz", tmp_path / "dtm.tif"
    rc, text = _run("groundsieve:smrf", f"--INPUT={src}", f"--OUTPUT={out}", f"--DTM={dtm}",
                    "--KEEP_CLASSES=true")
    assert rc == 0, text
    cls, wh, syn = _read(out)
    other = ~np.isin(cls_in, [0, 1, 2])       # withheld class 6, water 9, noise 7 and 18
    np.testing.assert_array_equal(cls[other], cls_in[other])
    np.testing.assert_array_equal(cls[kind == "withheld"], cls_in[kind == "withheld"])
    np.testing.assert_array_equal(wh, wh_in)
    np.testing.assert_array_equal(syn, syn_in)
    assert (cls[kind == "ground"] == 2).mean() > 0.99
    # The same DTM, cell for cell, as from the file without the withheld and noise points (the one
    # 5 km away included: the grid spans the 40 m plane only).
    las = laspy.read(str(src))
    clean = tmp_path / "clean.las"
    las[~np.isin(kind, ["withheld", "noise7", "noise18", "far"])].write(str(clean))
    rc, text = _run("groundsieve:smrf", f"--INPUT={clean}", f"--OUTPUT={tmp_path / 'c.las'}",
                    f"--DTM={tmp_path / 'c.tif'}", "--KEEP_CLASSES=true")
    assert rc == 0, text
    (gt, a), (gt_ref, ref) = _dtm(dtm), _dtm(tmp_path / "c.tif")
    assert gt == gt_ref
    assert a.shape[1] == 40  # the 40 m plane (points on both edges) in 40 cells of 1 m
    np.testing.assert_array_equal(a, ref)
    assert a[a != -9999].min() > -0.06


def test_ignore_classes_parameter_and_its_refusal(tmp_path):
    src = tmp_path / "in.las"
    kind, cls_in = write_scene(src, fmt=1)
    out = tmp_path / "out.las"
    rc, text = _run("groundsieve:pmf", f"--INPUT={src}", f"--OUTPUT={out}", "--IGNORE_CLASSES=7,9,18")
    assert rc == 0, text
    cls, wh, _ = _read(out)
    keep = np.isin(kind, ["water", "noise7", "noise18", "withheld"])
    np.testing.assert_array_equal(cls[keep], cls_in[keep])
    assert wh[kind == "withheld"].all()
    bad = tmp_path / "bad.las"
    rc, text = _run("groundsieve:pmf", f"--INPUT={src}", f"--OUTPUT={bad}", "--IGNORE_CLASSES=seven")
    assert rc != 0
    assert "Ignored classes: 'seven' is not a class code" in text
    assert "Traceback" not in text
    assert not bad.exists() and not list(tmp_path.glob(".bad.las*"))


def test_rfclassify_keeps_withheld_and_noise(tmp_path):
    model = train_block_model(tmp_path)
    src = tmp_path / "in.las"
    kind, cls_in = write_scene(src, fmt=1, far_noise=True)
    _, wh_in, syn_in = _read(src)
    out, dtm = tmp_path / "out.laz", tmp_path / "dtm.tif"
    rc, text = _run("groundsieve:rfclassify", f"--INPUT={src}", f"--MODEL={model}", f"--OUTPUT={out}",
                    f"--DTM={dtm}")
    assert rc == 0, text
    cls, wh, syn = _read(out)
    marked = np.isin(kind, ["withheld", "noise7", "noise18", "far"])
    np.testing.assert_array_equal(cls[marked], cls_in[marked])
    np.testing.assert_array_equal(wh, wh_in)
    np.testing.assert_array_equal(syn, syn_in)
    gt, a = _dtm(dtm)
    assert a.shape[1] <= 41 and a[a != -9999].min() > -0.06   # neither the far point nor the -5 m points


def test_two_outputs_on_one_file_are_refused_before_any_work(tmp_path):
    src = tmp_path / "in.las"
    write_scene(src, fmt=6, marked=False)
    same = tmp_path / "same.tif"
    rc, text = _run("groundsieve:evcrasters", f"--INPUT={src}", f"--OUTPUT={tmp_path / 'out.las'}",
                    f"--EVC_RASTER={same}", f"--CLASS_RASTER={same}")
    assert rc != 0
    assert ("same.tif: chosen for two outputs (Elevation variation coefficient (EVC) and EVC classes "
            "(1 ground, 2 vegetation area, 3 vegetation boundary))") in text, text
    assert "Traceback" not in text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.las"]


def test_a_stray_point_far_away_runs_in_tiles_and_is_said_with_its_place(tmp_path):
    # 6,400 points on 40 x 40 m and one point 1000 km east: a whole run's SMRF grid would be 40 x 1,000,041
    # cells (about 90 GB with its fill), which was refused with the stray point's place. The estimate of a
    # whole run (its grid cells counted) now sends such a file to the tiles, which exist only where points
    # are: the run works in bounded memory, and says where the stray point is and why the DTM is mostly empty.
    src = tmp_path / "in.las"
    write_scene(src, fmt=6, marked=False)
    las = laspy.read(str(src))
    x = np.asarray(las.x)
    x[-1] = 512000.0 + 1_000_040.0
    las.x = x
    las.write(str(src))
    out = tmp_path / "out.laz"
    rc, text = _run("groundsieve:smrf", f"--INPUT={src}", f"--OUTPUT={out}", f"--DTM={tmp_path / 'dtm.tif'}")
    assert rc == 0, text
    assert "run whole it would take about" in text and "run in buffered tiles" in text, text
    assert ("DTM: 1 point(s) in 1 tile(s) lie far from the others (e.g. 1 in the tile at x 1,511,840, y "
            "5,402,320): the DTM spans them, 1,000,040 x 40 cells, mostly empty") in text, text
    cls, _withheld, _synthetic = _read(out)
    assert cls[-1] != 2 and (cls[:-1] == 2).mean() > 0.5 and "Traceback" not in text

