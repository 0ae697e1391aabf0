"""groundsieve:smrf through processing.run, as the toolbox and the modeler call it."""
import hashlib
import os

import numpy as np
import pytest

from .conftest import classes_of


def _run(params):
    import processing
    return processing.run("groundsieve:smrf", params)


def _sha(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def test_provider_lists_smrf(groundsieve_provider):
    from qgis.core import QgsApplication
    alg = QgsApplication.processingRegistry().algorithmById("groundsieve:smrf")
    assert alg is not None
    assert alg.displayName() == "Ground filter (SMRF)"
    assert alg.group() == "Ground filters"
    names = {p.name() for p in alg.parameterDefinitions()}
    assert {"INPUT", "OUTPUT", "DTM", "DTM_CELL", "GROUND_POINTS", "CELL", "SLOPE", "WINDOW",
            "THRESHOLD", "SCALAR", "LAST_RETURNS", "IGNORE_NOISE", "KEEP_CLASSES"} <= names
    assert groundsieve_provider.id() == "groundsieve"
    assert not alg.icon().isNull()


def test_smrf_classifies_scene_and_writes_dtm(groundsieve_provider, scene_laz, tmp_path):
    from osgeo import gdal
    from groundsieve.core.metrics import ground_accuracy
    src, scene = scene_laz
    before = _sha(src)
    out, dtm = tmp_path / "out.laz", tmp_path / "dtm.tif"
    result = _run({"INPUT": str(src), "OUTPUT": str(out), "DTM": str(dtm), "DTM_CELL": 2.0})
    assert _sha(src) == before, "the input file must not change"
    cls = classes_of(out)
    assert set(np.unique(cls)) <= {1, 2}
    assert result["GROUND_COUNT"] == int((cls == 2).sum())
    # every result is a declared output, as native algorithms have them (the counts were returned but not
    # declared: a model's next step could not take them, and the dialog and qgis_process help hid them)
    from qgis.core import QgsApplication
    for alg_id in ("smrf", "csf", "ptd", "pmf", "evc", "evcrasters", "echogrid", "hybrid"):
        alg = QgsApplication.processingRegistry().algorithmById(f"groundsieve:{alg_id}")
        declared = {o.name() for o in alg.outputDefinitions()}
        assert {"GROUND_COUNT", "POINT_COUNT"} <= declared, (alg_id, declared)
    assert set(result) <= {o.name() for o in QgsApplication.processingRegistry().algorithmById(
        "groundsieve:smrf").outputDefinitions()}, result
    acc = ground_accuracy(scene.classification == 2, cls == 2)
    assert acc.total < 0.05, acc.summary()
    ds = gdal.Open(str(dtm))
    assert ds.RasterXSize == int(np.ceil(120.0 / 2.0)) or abs(ds.RasterXSize - 60) <= 1
    assert "32632" in ds.GetProjection() or "UTM zone 32N" in ds.GetProjection()
    band = ds.GetRasterBand(1)
    assert band.GetNoDataValue() == -9999.0
    values = band.ReadAsArray()
    assert (values != -9999.0).mean() > 0.9
    assert not [p for p in os.listdir(tmp_path) if ".part" in p]


def test_ground_points_layer(groundsieve_provider, scene_laz, tmp_path):
    from qgis.core import QgsVectorLayer, QgsWkbTypes
    src, _scene = scene_laz
    gpkg = tmp_path / "ground.gpkg"
    result = _run({"INPUT": str(src), "OUTPUT": str(tmp_path / "o.las"), "GROUND_POINTS": str(gpkg)})
    layer = QgsVectorLayer(result["GROUND_POINTS"], "ground", "ogr")
    assert layer.isValid()
    assert layer.featureCount() == result["GROUND_COUNT"]
    assert QgsWkbTypes.hasZ(layer.wkbType())
    assert [f.name() for f in layer.fields()][-2:] == ["return_number", "intensity"]


@pytest.mark.parametrize("case", ["missing", "not_las", "same_as_input", "dtm_cell_zero", "bad_slope"])
def test_bad_input_is_a_processing_error(groundsieve_provider, scene_laz, tmp_path, case):
    from qgis.core import QgsProcessingException
    src, _scene = scene_laz
    out = tmp_path / "out.laz"
    params = {"INPUT": str(src), "OUTPUT": str(out)}
    expect = ""
    if case == "missing":
        params["INPUT"] = str(tmp_path / "nope.laz")
        # the label without "this or a loaded layer below is needed" (a modeller reviewer's batch row said it)
        expect = r"Input point cloud \(LAS/LAZ[^:]*\): [^:]*nope.laz does not exist or is not a file"
    elif case == "not_las":
        bogus = tmp_path / "bogus.las"
        bogus.write_text("this is not a point cloud\n")
        params["INPUT"] = str(bogus)
        expect = "bogus.las"
    elif case == "same_as_input":
        params["OUTPUT"] = str(src)
        expect = "must not be the input"
    elif case == "dtm_cell_zero":
        params.update(DTM=str(tmp_path / "d.tif"), DTM_CELL=0.0)
        expect = "cell size"
    elif case == "bad_slope":
        params["WINDOW"] = 0.5  # the form allows it; smaller than the 1 m cell, the core refuses it
        expect = "window_m"
    with pytest.raises(QgsProcessingException, match=expect):
        _run(params)
    assert not out.exists()
    assert not (tmp_path / "d.tif").exists()


def test_missing_dependency_is_reported_clearly(groundsieve_provider, scene_laz, tmp_path, monkeypatch):
    from qgis.core import QgsProcessingException
    import groundsieve.dependencies as deps
    monkeypatch.setattr(deps, "missing_dependencies", lambda extra=None: ["numba"])
    src, _scene = scene_laz
    with pytest.raises(QgsProcessingException, match="numba.*pip install"):
        _run({"INPUT": str(src), "OUTPUT": str(tmp_path / "o.laz")})


def test_plugin_registers_its_provider_without_iface(groundsieve_plugin):
    from qgis.core import QgsApplication
    registry = QgsApplication.processingRegistry()
    assert groundsieve_plugin.iface is None
    assert registry.providerById("groundsieve") is groundsieve_plugin.provider
    groundsieve_plugin.initProcessing()  # a second call must not register a second provider
    assert [p.id() for p in registry.providers()].count("groundsieve") == 1


def test_the_crs_unit_is_said_before_the_work_and_degrees_are_refused(groundsieve_provider, scene_laz, tmp_path):
    """A cloud in feet is warned about as a warning of the dialog's log, before the filtering (it came
    after the outputs); a cloud in longitudes and latitudes is refused, with nothing written."""
    import laspy
    import pyproj
    import processing
    from qgis.core import QgsProcessingContext, QgsProcessingException, QgsProcessingFeedback
    src, _scene = scene_laz

    class Recorder(QgsProcessingFeedback):
        def __init__(self):
            super().__init__()
            self.lines = []

        def pushWarning(self, text):
            self.lines.append(("warning", text))

        def pushInfo(self, text):
            self.lines.append(("info", text))
    las = laspy.read(str(src))
    las.header.add_crs(pyproj.CRS.from_epsg(2263))  # NY Long Island, US survey foot
    feet = tmp_path / "feet.laz"
    las.write(str(feet))
    feedback = Recorder()
    processing.run("groundsieve:smrf", {"INPUT": str(feet), "OUTPUT": str(tmp_path / "f.laz")},
                   context=QgsProcessingContext(), feedback=feedback)
    warned = [i for i, (kind, text) in enumerate(feedback.lines)
              if kind == "warning" and "the CRS's unit is US survey foot, not metres" in text]
    filtering = [i for i, (_kind, text) in enumerate(feedback.lines) if text.startswith("Filtering")]
    assert len(warned) == 1 and filtering and warned[0] < filtering[0], feedback.lines
    lonlat = laspy.read(str(src))
    lonlat.header.offsets, lonlat.header.scales = [9.0, 47.0, 0.0], [1e-7, 1e-7, 0.01]
    x, y = np.asarray(las.x), np.asarray(las.y)
    lonlat.x, lonlat.y = 9.0 + (x - x.min()) * 1e-5, 47.0 + (y - y.min()) * 1e-5
    lonlat.header.add_crs(pyproj.CRS.from_epsg(4326))
    lonlat.write(str(tmp_path / "lonlat.laz"))
    with pytest.raises(QgsProcessingException, match=r"lonlat\.laz: its coordinates are longitudes and latitudes"):
        _run({"INPUT": str(tmp_path / "lonlat.laz"), "OUTPUT": str(tmp_path / "l.laz")})
    assert not (tmp_path / "l.laz").exists()


def test_ground_points_of_a_cloud_without_crs_are_not_said_to_be_geographic(groundsieve_provider, tmp_path):
    """The ground-point GeoPackage of a LAZ without a CRS carried "Undefined geographic SRS" (srs_id
    0) over coordinates in metres, which QGIS takes for a valid geographic CRS (a reviewer): it is
    the GeoPackage's undefined Cartesian SRS (srs_id -1)."""
    import sqlite3
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    src = tmp_path / "nocrs.laz"
    write_scene(make_scene(SceneSpec(size_m=40.0, density_per_m2=2.0, seed=2)), str(src), crs_wkt="")
    gpkg = tmp_path / "ground.gpkg"
    _run({"INPUT": str(src), "OUTPUT": str(tmp_path / "o.laz"), "GROUND_POINTS": str(gpkg)})
    with sqlite3.connect(str(gpkg)) as db:
        (srs_id,), = db.execute("select srs_id from gpkg_geometry_columns").fetchall()
    assert srs_id == -1


class _Watching:
    """A feedback that runs ``hook`` when the ground points layer's writing starts (its progress text)."""

    def __new__(cls, hook):
        from qgis.core import QgsProcessingFeedback

        class Feedback(QgsProcessingFeedback):
            def setProgressText(self, text):
                super().setProgressText(text)
                if "ground points layer" in text:
                    hook(self)
        return Feedback()


def test_a_cancel_while_the_ground_points_are_written_leaves_no_output(groundsieve_provider, scene_laz, tmp_path):
    """A cancel while the ground-point layer was written stopped its loop and the run said it was done: a
    modeller reviewer's GeoPackage held 201,278 of 2,496,477 ground points. The run now fails as cancelled
    and removes its outputs: the classified cloud, the DTM and the layer."""
    import processing
    from qgis.core import QgsProcessingException
    src, _scene = scene_laz
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(QgsProcessingException, match="cancelled .* ground points layer was written; the run's "
                                                     "outputs were removed"):
        processing.run("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": str(out / "c.laz"),
                                            "DTM": str(out / "d.tif"), "GROUND_POINTS": str(out / "g.gpkg")},
                       feedback=_Watching(lambda feedback: feedback.cancel()))
    assert os.listdir(out) == []


@pytest.mark.parametrize("name", ["g.gpkg", "g.shp"])
def test_the_ground_points_layer_is_written_under_a_temporary_name_then_moved(groundsieve_provider, scene_laz,
                                                                              tmp_path, name):
    """QGIS writes a feature sink straight to its destination: a killed run left a broken GeoPackage under
    the final name. It is now written beside it under a temporary name, and renamed into place complete
    (a shapefile with its sidecars); the layer the dialog loads at the end is the final one."""
    import processing
    from qgis.core import (QgsProcessingContext, QgsProcessingOutputLayerDefinition, QgsProject,
                           QgsVectorLayer)
    src, _scene = scene_laz
    out = tmp_path / "out"
    out.mkdir()
    seen = []
    if name.endswith(".shp"):  # an older layer's spatial index and style beside it (the index answered extent
        (out / "g.qix").write_bytes(b"old index")  # queries on the new layer with none of its features)
        (out / "g.qml").write_text("<qgis/>")
    context = QgsProcessingContext()
    context.setProject(QgsProject.instance())
    result = processing.run("groundsieve:smrf", {
        "INPUT": str(src), "OUTPUT": str(out / "c.laz"),
        "GROUND_POINTS": QgsProcessingOutputLayerDefinition(str(out / name), QgsProject.instance())},
        feedback=_Watching(lambda _f: seen.extend(os.listdir(out))), context=context)
    assert name not in seen and any(n.startswith(f".{name}.") and n.endswith(".sink") for n in seen), seen
    assert result["GROUND_POINTS"].split("|")[0] == str(out / name)
    layer = QgsVectorLayer(result["GROUND_POINTS"], "ground", "ogr")
    assert layer.isValid() and layer.featureCount() == result["GROUND_COUNT"] > 0
    left = sorted(os.listdir(out))
    assert not [n for n in left if n.startswith(".")], left
    if name.endswith(".shp"):
        assert {"g.shp", "g.shx", "g.dbf", "g.prj", "g.qml"} <= set(left) and "g.qix" not in left, left
    else:  # the layer is named after the file, as QGIS names it (a temporary name had left it empty: a reviewer)
        import sqlite3
        with sqlite3.connect(str(out / name)) as db:
            assert db.execute("select table_name from gpkg_contents").fetchall() == [("g",)]
    loads = [str(k) for k in context.layersToLoadOnCompletion()]
    assert any(k.split("|")[0] == str(out / name) for k in loads) and not any(".part" in k for k in loads), loads


def test_a_killed_run_s_ground_points_folder_is_removed_by_the_next_run(groundsieve_provider, scene_laz, tmp_path):
    """A run killed while it wrote the layer leaves its hidden folder beside the destination (the layer and its
    sidecars, never under the final name); the next run writing that layer removes it."""
    import socket
    import re as _re
    from groundsieve.core.io.outputs import temporary_folder_beside
    src, _scene = scene_laz
    out = tmp_path / "out"
    out.mkdir()
    live = temporary_folder_beside(str(out / "g.shp"))  # (this process's: alive, kept)
    host = _re.sub(r"[^A-Za-z0-9-]", "", socket.gethostname())[:24] or "host"
    dead = out / f".g.shp.gs{host}.999999999-abcd.sink"
    dead.mkdir()
    for side in ("g.shp", "g.shx", "g.dbf"):
        (dead / side).write_bytes(b"half")
    _run({"INPUT": str(src), "OUTPUT": str(out / "c.laz"), "GROUND_POINTS": str(out / "g.shp")})
    assert not dead.exists() and os.path.isdir(live)
    os.rmdir(live)


def test_appending_the_ground_points_to_an_existing_layer_keeps_its_features(groundsieve_provider, scene_laz,
                                                                              tmp_path):
    """The dialog's "Append to Layer..." (a remapping definition): QGIS adds to the existing layer in place. A
    layer staged in a folder and moved into place had replaced it, its features lost (a code reviewer)."""
    import processing
    from qgis.core import (QgsCoordinateReferenceSystem, QgsCoordinateTransformContext, QgsFeature, QgsField,
                           QgsFields, QgsGeometry, QgsPoint, QgsProcessingOutputLayerDefinition, QgsProperty,
                           QgsRemappingSinkDefinition, QgsVectorFileWriter, QgsVectorLayer, QgsWkbTypes)
    from qgis.PyQt.QtCore import QVariant
    src, _scene = scene_laz
    dest = str(tmp_path / "existing.shp")
    fields = QgsFields()
    for name in ("return_number", "intensity"):
        fields.append(QgsField(name, QVariant.Int))
    crs = QgsCoordinateReferenceSystem("EPSG:32632")
    options = QgsVectorFileWriter.SaveVectorOptions()
    options.driverName = "ESRI Shapefile"
    writer = QgsVectorFileWriter.create(dest, fields, QgsWkbTypes.PointZ, crs, QgsCoordinateTransformContext(), options)
    for i in range(5):
        feature = QgsFeature(fields)
        feature.setGeometry(QgsGeometry(QgsPoint(500000.0 + i, 5400000.0, 100.0)))
        feature.setAttributes([9, 9])
        writer.addFeature(feature)
    del writer
    remap = QgsRemappingSinkDefinition()
    remap.setDestinationFields(fields)
    remap.setDestinationWkbType(QgsWkbTypes.PointZ)
    remap.setDestinationCrs(crs)
    remap.setSourceCrs(crs)
    remap.setFieldMap({name: QgsProperty.fromField(name) for name in ("return_number", "intensity")})
    target = QgsProcessingOutputLayerDefinition(dest)
    target.setRemappingDefinition(remap)
    result = _run({"INPUT": str(src), "OUTPUT": str(tmp_path / "c.laz"), "GROUND_POINTS": target})
    layer = QgsVectorLayer(dest, "existing", "ogr")
    assert layer.featureCount() == 5 + result["GROUND_COUNT"]
    assert sum(1 for f in layer.getFeatures() if f.attributes()[0] == 9) == 5


def test_ground_points_as_csv_hold_their_coordinates(groundsieve_provider, scene_laz, tmp_path):
    """A CSV (a table without geometry) had the return number and intensity alone, and the run said it was done
    (a dense-UAV reviewer): it has x, y and z columns first, the ground points' coordinates."""
    import csv
    import laspy
    src, _scene = scene_laz
    result = _run({"INPUT": str(src), "OUTPUT": str(tmp_path / "c.laz"), "GROUND_POINTS": str(tmp_path / "g.csv")})
    with open(tmp_path / "g.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0])[:5] == ["x", "y", "z", "return_number", "intensity"] and len(rows) == result["GROUND_COUNT"]
    las = laspy.read(tmp_path / "c.laz")
    ground = np.asarray(las.classification) == 2
    got = np.array([[float(r["x"]), float(r["y"]), float(r["z"])] for r in rows])
    assert np.allclose(got, np.c_[las.x[ground], las.y[ground], las.z[ground]], atol=1e-6)


def test_the_ground_points_layer_alone(groundsieve_provider, scene_laz, tmp_path):
    """The classified cloud and the DTM skipped, the ground points layer given: it was refused as a run that
    writes nothing (a dense-UAV reviewer). A cloud run whole writes it alone; a survey, run in tiles, which
    write no such layer, is refused in words before any work."""
    from qgis.core import QgsProcessingException, QgsVectorLayer
    src, _scene = scene_laz
    out = tmp_path / "out"
    out.mkdir()
    result = _run({"INPUT": str(src), "OUTPUT": None, "DTM": None, "GROUND_POINTS": str(out / "g.gpkg")})
    assert QgsVectorLayer(result["GROUND_POINTS"], "g", "ogr").featureCount() == result["GROUND_COUNT"] > 0
    assert os.listdir(out) == ["g.gpkg"]
    survey = tmp_path / "survey"
    survey.mkdir()
    import shutil
    shutil.copy(src, survey / "a.laz")
    with pytest.raises(QgsProcessingException, match="Ground points as a vector layer alone: .*survey runs in tiles"):
        _run({"INPUT": str(survey), "OUTPUT": None, "DTM": None, "GROUND_POINTS": str(tmp_path / "s.gpkg")})
    assert not (tmp_path / "s.gpkg").exists()
