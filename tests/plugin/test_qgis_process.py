"""The command-line wrapper: scripts/qgis-process list / run, checked on the written files."""
import json
import os
import subprocess
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
WRAPPER = REPO / "scripts" / "qgis-process"


def _wrapper(*args, cwd=None):
    return subprocess.run([str(WRAPPER), *args], capture_output=True, text=True, cwd=cwd, timeout=600)


def test_list_shows_the_provider():
    proc = _wrapper("list")
    assert proc.returncode == 0, proc.stderr
    assert "groundsieve:smrf" in proc.stdout


def test_run_smrf_writes_laz_and_geotiff(scene_laz, tmp_path):
    import laspy
    from osgeo import gdal
    src, scene = scene_laz
    out, dtm = tmp_path / "out.laz", tmp_path / "dtm.tif"
    proc = _wrapper("--json", "run", "groundsieve:smrf", f"--INPUT={src}", f"--OUTPUT={out}",
                    f"--DTM={dtm}", "--DTM_CELL=1.5")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    results = json.loads(proc.stdout)["results"]
    las = laspy.read(str(out))
    cls = np.asarray(las.classification)
    assert len(cls) == len(scene.x)
    assert results["GROUND_COUNT"] == int((cls == 2).sum())
    assert int((cls == 1).sum()) + int((cls == 2).sum()) == len(cls)
    assert las.header.parse_crs().to_epsg() == 32632
    ds = gdal.Open(str(dtm))
    gt = ds.GetGeoTransform()
    assert gt[1] == 1.5 and gt[5] == -1.5
    assert abs(ds.RasterXSize * 1.5 - (scene.x.max() - scene.x.min())) <= 3.0
    assert ds.GetRasterBand(1).GetNoDataValue() == -9999.0
    assert "32632" in ds.GetProjection() or "UTM zone 32N" in ds.GetProjection()


def test_run_with_only_input_and_output_uses_defaults(scene_laz, tmp_path):
    src, _ = scene_laz
    out = tmp_path / "only.las"
    proc = _wrapper("run", "groundsieve:smrf", f"--INPUT={src}", f"--OUTPUT={out}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert out.exists()


def test_bad_input_fails_with_message_and_no_output(tmp_path):
    bad = tmp_path / "truncated.laz"
    bad.write_bytes(b"LASF" + b"\0" * 50)
    out = tmp_path / "out.laz"
    proc = _wrapper("run", "groundsieve:smrf", f"--INPUT={bad}", f"--OUTPUT={out}")
    assert proc.returncode != 0
    text = proc.stdout + proc.stderr
    assert "truncated.laz" in text
    assert "Traceback" not in text
    assert not out.exists()
    assert os.listdir(tmp_path) == ["truncated.laz"]


def test_help_is_plain_text_in_paragraphs():
    """`qgis_process help` printed each algorithm's help as one line of HTML thousands of characters long
    (a power user reading it in a terminal, or through R's qgisprocess): it is now plain text, each
    paragraph and heading on lines of their own, wrapped at 100 characters; the dialog keeps its HTML."""
    for alg in ("groundsieve:smrf", "groundsieve:dtm", "groundsieve:accuracy", "groundsieve:tune"):
        proc = _wrapper("help", alg)
        assert proc.returncode == 0, proc.stderr
        text = proc.stdout.split("Description\n----------------\n", 1)[1].split("\n----------------\nArguments", 1)[0]
        assert "<p>" not in text and "<b>" not in text and "&amp;" not in text, alg
        lines = text.strip().splitlines()
        assert len(lines) > 10 and max(len(line) for line in lines[1:]) <= 100, alg  # (line 0: QGIS's summary)
        assert "\n\n" in text.strip(), alg
    # links keep their address; each parameter's label starts a paragraph
    proc = _wrapper("help", "groundsieve:hybrid")
    assert "the benchmarks (https://" in " ".join(proc.stdout.split()) and "\n\nModel file (optional):" in proc.stdout
