"""groundsieve:dtm (DTM from classified points) as a QGIS user runs it: a classified delivery's ground
class as a DTM from the toolbox (processing.run), from a folder of tiles, and from qgis_process; a
cloud without ground and bad ground classes refused in the dialog's words, with nothing written."""
import json
import os
import subprocess

import numpy as np
import pytest

from groundsieve.tests.core.test_tiles import _dtm_values

from .test_qgis_process import WRAPPER
from .test_survey_inputs import _split


def _dtm(path):
    """The DTM's values (NaN = nodata), its geotransform and its CRS's WKT."""
    from osgeo import gdal
    values, transform = _dtm_values(path)
    return values, transform, gdal.Open(str(path)).GetProjection()


def test_the_ground_class_becomes_a_dtm_and_the_input_is_only_read(groundsieve_provider, scene_laz, tmp_path):
    import processing
    src, scene = scene_laz
    before = src.read_bytes()
    out = tmp_path / "dtm.tif"
    result = processing.run("groundsieve:dtm", {"INPUT": str(src), "DTM": str(out), "DTM_CELL": 2.0})
    assert src.read_bytes() == before
    assert result["DTM"] == str(out)
    assert result["GROUND_COUNT"] == int(np.sum(scene.classification == 2))
    assert result["POINT_COUNT"] == len(scene.x)
    values, transform, projection = _dtm(out)
    assert transform[1] == 2.0 and ("32632" in projection or "UTM zone 32N" in projection)
    # the ground's heights, not the roofs' or the canopy's: every cell within the ground points' range
    ground_z = scene.z[scene.classification == 2]
    assert np.isfinite(values).mean() > 0.9
    assert np.nanmin(values) >= ground_z.min() - 0.01 and np.nanmax(values) <= ground_z.max() + 0.01
    assert sorted(os.listdir(tmp_path)) == ["dtm.tif"]


def test_a_folder_of_tiles_gives_the_dtm_of_the_whole_file(groundsieve_provider, scene_laz, tmp_path):
    import processing
    src, scene = scene_laz
    _split(src, tmp_path / "in")
    whole, survey = tmp_path / "whole.tif", tmp_path / "survey.tif"
    processing.run("groundsieve:dtm", {"INPUT": str(src), "DTM": str(whole)})
    result = processing.run("groundsieve:dtm", {"INPUT": str(tmp_path / "in"), "DTM": str(survey),
                                                "TILE_SIZE": 50.0})
    a, b = _dtm(whole)[0], _dtm(survey)[0]
    assert a.shape == b.shape
    np.testing.assert_allclose(a, b, atol=1e-3)
    assert result["POINT_COUNT"] == len(scene.x)
    assert sorted(os.listdir(tmp_path)) == ["in", "survey.tif", "whole.tif"]


def test_qgis_process_makes_the_dtm_and_names_its_counts(scene_laz, tmp_path):
    src, scene = scene_laz
    out = tmp_path / "dtm.tif"
    proc = subprocess.run([str(WRAPPER), "--json", "run", "groundsieve:dtm", f"--INPUT={src}", f"--DTM={out}",
                           "--CLASSES=2,6"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    results = json.loads(proc.stdout)["results"]
    assert results["GROUND_COUNT"] == int(np.sum(np.isin(scene.classification, (2, 6))))
    # with the buildings' class 6 among the ground classes, the roofs are in the DTM
    values = _dtm(out)[0]
    assert np.nanmax(values) > scene.z[scene.classification == 2].max() + 2.0


def test_a_cloud_without_ground_is_refused_with_its_classes(groundsieve_provider, tmp_path):
    import processing
    from qgis.core import QgsProcessingException
    from groundsieve.core.io import new_las, write_las
    rng = np.random.default_rng(0)
    src = tmp_path / "unclassified.laz"
    n = 5_000
    write_las(new_las(rng.uniform(0, 100, n), rng.uniform(0, 100, n), rng.uniform(0, 1, n),
                      classification=np.ones(n, np.uint8)), str(src))
    with pytest.raises(QgsProcessingException) as err:
        processing.run("groundsieve:dtm", {"INPUT": str(src), "DTM": str(tmp_path / "dtm.tif")})
    text = str(err.value)
    assert "unclassified.laz" in text and "no point of class 2" in text and "1 (unclassified): 5,000" in text
    assert os.listdir(tmp_path) == ["unclassified.laz"]


@pytest.mark.parametrize("classes, words", [("", "name at least one class"), ("2,ground", "'ground' is not a class"),
                                            ("999", "0-255")])
def test_bad_ground_classes_are_refused_in_the_dialogs_words(groundsieve_provider, scene_laz, tmp_path, classes,
                                                               words):
    from qgis.core import QgsApplication, QgsProcessingContext
    alg = QgsApplication.processingRegistry().algorithmById("groundsieve:dtm")
    src, _scene = scene_laz
    ok, message = alg.checkParameterValues({"INPUT": str(src), "DTM": str(tmp_path / "d.tif"), "CLASSES": classes},
                                           QgsProcessingContext())
    assert not ok and "Ground classes" in message and words in message


@pytest.mark.parametrize("params, words", [({"IGNORE_CLASSES": "7,x"}, "Ignored classes: 'x' is not a class"),
                                           ({"IGNORE_CLASSES": "2,7"}, "Ground classes and Ignored classes both "
                                                                       "name 2"),
                                           ({"CLASSES": "2-9"}, "both name 7")])
def test_ignored_classes_are_checked_before_the_run(groundsieve_provider, scene_laz, tmp_path, params, words):
    """A batch row with IGNORE_CLASSES 7,x or 2,7 passed the dialog's check and failed at its run (a QGIS
    power user)."""
    from qgis.core import QgsApplication, QgsProcessingContext
    alg = QgsApplication.processingRegistry().algorithmById("groundsieve:dtm")
    src, _scene = scene_laz
    ok, message = alg.checkParameterValues({"INPUT": str(src), "DTM": str(tmp_path / "d.tif"), **params},
                                           QgsProcessingContext())
    assert not ok and words in message, message


def test_a_dtm_extent_from_the_dialog_is_reprojected_to_the_cloud_s_crs(groundsieve_provider, scene_laz, tmp_path):
    """The DTM extent (an extent parameter: typed, drawn on the canvas or a layer's) in the cloud's CRS gives
    the DTM that grid; one in another CRS (the canvas in EPSG:4326) is reprojected to the cloud's first."""
    import processing
    from qgis.core import QgsCoordinateReferenceSystem, QgsCoordinateTransform, QgsProject, QgsRectangle
    src, scene = scene_laz
    x0, y0 = float(np.floor(scene.x.min())) + 10.3, float(np.floor(scene.y.min())) + 20.6
    out = tmp_path / "dtm.tif"
    processing.run("groundsieve:dtm", {"INPUT": str(src), "DTM": str(out), "DTM_CELL": 1.0,
                                       "DTM_EXTENT": f"{x0},{x0 + 50},{y0},{y0 + 40}"})  # (QGIS: xmin,xmax,ymin,ymax)
    values, transform, _crs = _dtm(out)
    assert transform == (np.floor(x0), 1.0, 0.0, np.ceil(y0 + 40), 0.0, -1.0)
    assert values.shape == (41, 51) and np.isfinite(values).all()  # (widened to whole cells)
    utm, wgs = QgsCoordinateReferenceSystem("EPSG:32632"), QgsCoordinateReferenceSystem("EPSG:4326")
    box = QgsCoordinateTransform(utm, wgs, QgsProject.instance()).transformBoundingBox(
        QgsRectangle(x0, y0, x0 + 50, y0 + 40))
    out = tmp_path / "dtm_wgs.tif"
    from qgis.core import QgsProcessingFeedback
    said = []

    class Feedback(QgsProcessingFeedback):
        def pushInfo(self, info):  # noqa: N802
            said.append(info)
    processing.run("groundsieve:dtm", {"INPUT": str(src), "DTM": str(out), "DTM_CELL": 1.0,
                                       "DTM_EXTENT": f"{box.xMinimum()!r},{box.xMaximum()!r},{box.yMinimum()!r},"
                                                     f"{box.yMaximum()!r} [EPSG:4326]"}, feedback=Feedback())
    assert any(line.startswith("DTM extent: given in EPSG:4326, reprojected to the cloud's EPSG:32632: the box "
                               "around it, x ") for line in said), said
    values, transform, _crs = _dtm(out)
    assert abs(transform[0] - x0) < 3 and abs(transform[3] - (y0 + 40)) < 3  # (the box of the reprojected box)
    assert 48 <= values.shape[1] <= 54 and 39 <= values.shape[0] <= 45


def test_an_empty_extent_and_degrees_over_a_cloud_without_crs_are_refused(groundsieve_provider, scene_laz, tmp_path):
    """A power user: a zero-width extent fell back to the points' extent without a word, and a canvas extent
    in EPSG:4326 over a cloud without a CRS was taken as metres (refused as far points). Both are refused in
    the dialog's words, before any work."""
    import processing
    from qgis.core import QgsProcessingException

    from groundsieve.core.io import new_las, read_cloud, write_las
    src, scene = scene_laz
    x0, y0 = float(scene.x.min()) + 10, float(scene.y.min()) + 10
    with pytest.raises(QgsProcessingException, match=r"DTM extent: x .* is empty \(zero width or height\)"):
        processing.run("groundsieve:dtm", {"INPUT": str(src), "DTM": str(tmp_path / "a.tif"),
                                           "DTM_EXTENT": f"{x0},{x0},{y0},{y0 + 40}"})
    cloud = read_cloud(str(src))
    bare = tmp_path / "nocrs.laz"
    write_las(new_las(cloud.x, cloud.y, cloud.z, classification=cloud.classification), str(bare))
    with pytest.raises(QgsProcessingException, match=r"given in EPSG:4326 \(degrees\), but the cloud has no CRS"):
        processing.run("groundsieve:dtm", {"INPUT": str(bare), "DTM": str(tmp_path / "b.tif"),
                                           "DTM_EXTENT": "9.17,9.18,48.78,48.79 [EPSG:4326]"})
    assert sorted(os.listdir(tmp_path)) == ["nocrs.laz"]
