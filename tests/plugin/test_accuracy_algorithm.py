"""groundsieve:accuracy through processing.run (as the toolbox calls it) and qgis_process: a DTM plane
of known heights (written by the core's own write_geotiff, so bilinear interpolation is exact), point
layers of checkpoints with known offsets (PointZ, or 2D with a height field, or in another CRS), and
the figures, report and residual layer checked against those offsets."""
import html
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
X0, TOP, CELL, N = 500000.0, 5000200.0, 2.0, 100  # EPSG:32633, 200 m x 200 m


def plane(x, y):
    return 150.0 + 0.03 * (x - X0) - 0.02 * (y - (TOP - N * CELL))


@pytest.fixture(scope="module")
def dtm(tmp_path_factory):
    """A tilted plane in EPSG:32633 (float64), with one nodata cell at row 50, column 50."""
    from osgeo import osr

    from groundsieve.core.grids.spec import GridSpec
    from groundsieve.core.raster.geotiff import write_geotiff
    grid = GridSpec(x0=X0, top=TOP, cell=CELL, nrows=N, ncols=N)
    cx = X0 + (np.arange(N) + 0.5) * CELL
    cy = TOP - (np.arange(N) + 0.5) * CELL
    values = plane(cx[None, :], cy[:, None])
    values[50, 50] = np.nan
    ref = osr.SpatialReference()
    ref.ImportFromEPSG(32633)
    path = tmp_path_factory.mktemp("accuracy") / "dtm.tif"
    write_geotiff(str(path), values, grid, crs_wkt=ref.ExportToWkt(), dtype="float64", elevation=True)
    return str(path)


def checkpoints():
    """20 NVA checkpoints dz = +-0.05 (RMSEz 0.05, mean 0), 20 VVA dz = 0.01 .. 0.20, one outside the
    DTM, one on the nodata cell's centre (its own cell nodata: skipped) and one beside it (its
    neighbour nodata: the value of its own cell)."""
    rng = np.random.default_rng(5)
    x = rng.uniform(X0 + 10, X0 + 90, 40)  # west half: far from the nodata cell at x0 + 101 m
    y = rng.uniform(TOP - 190, TOP - 10, 40)
    dz = np.concatenate([np.where(np.arange(20) % 2 == 0, 0.05, -0.05), np.arange(1, 21) * 0.01])
    cover = ["NVA"] * 20 + ["VVA"] * 20
    nodata_centre = (X0 + 50.5 * CELL, TOP - 50.5 * CELL)
    beside = (X0 + 51.2 * CELL, TOP - 50.5 * CELL)  # in cell (50, 51), whose west neighbour is nodata
    x = np.append(x, [X0 - 500.0, nodata_centre[0], beside[0]])
    y = np.append(y, [TOP - 100.0, nodata_centre[1], beside[1]])
    cell_value = plane(X0 + 51.5 * CELL, TOP - 50.5 * CELL)
    z = np.append(plane(x[:40], y[:40]) - dz, [100.0, 100.0, cell_value - 0.05])
    ids = [f"CP{i + 1}" for i in range(len(x))]
    return x, y, z, ids, cover + ["NVA", "NVA", "NVA"], dz


def memory_layer(crs, fields, z_geometry=True):
    from qgis.core import QgsVectorLayer
    kind = "PointZ" if z_geometry else "Point"
    return QgsVectorLayer(f"{kind}?crs={crs}&" + "&".join(f"field={f}" for f in fields), "checkpoints", "memory")


def add_points(layer, rows):
    from qgis.core import QgsFeature, QgsGeometry, QgsPoint
    features = []
    for geometry, attributes in rows:
        feature = QgsFeature(layer.fields())
        feature.setGeometry(QgsGeometry(QgsPoint(*geometry)))
        feature.setAttributes(attributes)
        features.append(feature)
    assert layer.dataProvider().addFeatures(features)[0]
    return layer


def read_layer(path):
    from qgis.core import QgsVectorLayer
    layer = QgsVectorLayer(str(path), "dz", "ogr")
    assert layer.isValid()
    return {f["id"]: f for f in layer.getFeatures()}, layer


def test_figures_report_and_layer_of_a_pointz_layer_with_land_cover(groundsieve_provider, dtm, tmp_path):
    import processing
    from qgis.core import NULL, QgsApplication
    x, y, z, ids, cover, dz = checkpoints()
    layer = add_points(memory_layer("EPSG:32633", ["name:string", "lc:string"]),
                       [((x[i], y[i], z[i]), [ids[i], cover[i]]) for i in range(len(x))])
    algorithm = QgsApplication.processingRegistry().algorithmById("groundsieve:accuracy")
    assert algorithm.outputDefinition("OUTPUT_HTML").type() == "outputHtml"  # opens in the results viewer
    report, out = tmp_path / "accuracy.html", tmp_path / "dz.gpkg"
    result = processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": layer, "ID_FIELD": "name",
                                                     "LAND_COVER_FIELD": "lc", "OUTPUT_HTML": str(report),
                                                     "OUTPUT": str(out)})
    used = np.append(dz, 0.05)  # the checkpoint beside the nodata cell: its own cell's value, 0.05 above it
    nva = np.append(dz[:20], 0.05)
    assert result["COUNT"] == 41 and result["SKIPPED"] == 2
    assert result["RMSEZ"] == pytest.approx(np.sqrt(np.mean(used ** 2)), abs=1e-9)
    assert result["MEAN"] == pytest.approx(used.mean(), abs=1e-9)
    assert result["NVA_RMSEZ"] == pytest.approx(np.sqrt(np.mean(nva ** 2)), abs=1e-9)
    assert result["NVA95"] == pytest.approx(1.96 * np.sqrt(np.mean(nva ** 2)), abs=1e-9)
    assert result["VVA_RMSEZ"] == pytest.approx(np.sqrt(np.mean(dz[20:] ** 2)), abs=1e-9)
    assert result["VVA95"] == pytest.approx(np.percentile(dz[20:], 95), abs=1e-9)  # 0.1905
    text = report.read_text(encoding="utf-8")
    assert "dz = DTM - checkpoint z" in text and "Edition 1 (2014)" in text and "Edition 2 (2023)" in text
    assert f"{result['VVA95']:.4f}" in text and f"{result['NVA_RMSEZ']:.4f}" in text
    assert "CP41" in text and "outside the DTM" in text and "CP42" in text and "nodata" in text
    features, written = read_layer(out)
    assert written.crs().authid() == "EPSG:32633" and len(features) == 43
    assert features["CP1"]["dz"] == pytest.approx(dz[0], abs=1e-9) and features["CP1"]["sampling"] == "bilinear"
    assert features["CP1"]["land_cover"] == "NVA" and features["CP1"]["cover_given"] == cover[0]
    assert features["CP43"]["sampling"] == "cell" and features["CP43"]["dz"] == pytest.approx(0.05, abs=1e-9)
    assert features["CP41"]["sampling"] == "outside" and features["CP42"]["sampling"] == "nodata"
    assert features["CP42"]["z_dtm"] in (None, NULL) and features["CP42"]["dz"] in (None, NULL)


def test_heights_from_a_field_of_a_2d_layer_without_land_cover(groundsieve_provider, dtm, tmp_path):
    import processing
    x, y, z, _ids, _cover, dz = checkpoints()
    layer = add_points(memory_layer("EPSG:32633", ["h:double"], z_geometry=False),
                       [((x[i], y[i]), [float(z[i])]) for i in range(40)])
    report = tmp_path / "r.html"
    result = processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": layer, "Z_FIELD": "h",
                                                     "OUTPUT_HTML": str(report)})
    assert result["COUNT"] == 40 and result["SKIPPED"] == 0
    assert result["RMSEZ"] == pytest.approx(np.sqrt(np.mean(dz ** 2)), abs=1e-9)
    for name in ("NVA95", "VVA95", "NVA_RMSEZ", "VVA_RMSEZ"):  # no land cover: absent, not NaN, no crash
        assert result[name] is None, name
    assert "no land cover given" in report.read_text(encoding="utf-8")


def test_checkpoints_in_another_crs_are_reprojected_to_the_dtm(groundsieve_provider, dtm, tmp_path):
    import processing
    from qgis.core import QgsCoordinateReferenceSystem, QgsCoordinateTransform, QgsPointXY, QgsProject
    x, y, z, _ids, _cover, dz = checkpoints()
    to_wgs84 = QgsCoordinateTransform(QgsCoordinateReferenceSystem("EPSG:32633"),
                                      QgsCoordinateReferenceSystem("EPSG:4326"), QgsProject.instance())
    lonlat = [to_wgs84.transform(QgsPointXY(x[i], y[i])) for i in range(40)]
    assert 14.9 < lonlat[0].x() < 15.1 and 45 < lonlat[0].y() < 45.2  # near UTM 33's central meridian
    layer = add_points(memory_layer("EPSG:4326", ["n:integer"]),
                       [((p.x(), p.y(), z[i]), [i]) for i, p in enumerate(lonlat)])
    result = processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": layer,
                                                     "OUTPUT_HTML": str(tmp_path / "r.html")})
    assert result["COUNT"] == 40
    assert result["RMSEZ"] == pytest.approx(np.sqrt(np.mean(dz ** 2)), abs=1e-6)
    assert result["MEAN"] == pytest.approx(dz.mean(), abs=1e-6)
    # the report says the reprojection, the DTM's CRS and what made it (a flood modeller: in the log alone)
    text = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert "reprojected from EPSG:4326" in text
    assert "UTM zone 33N" in text and "GroundSieve " in text
    # taken as they are, without reprojection, degrees miss the DTM by 500 km: said so
    from qgis.core import QgsProcessingException
    wrong = add_points(memory_layer("EPSG:32633", ["n:integer"]),
                       [((p.x(), p.y(), z[i]), [i]) for i, p in enumerate(lonlat)])
    with pytest.raises(QgsProcessingException, match=r"none of the 40 checkpoints .* another CRS"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": wrong,
                                                "OUTPUT_HTML": str(tmp_path / "r2.html")})
    assert not (tmp_path / "r2.html").exists()


def test_bad_input_is_refused_in_the_dialog_s_words(groundsieve_provider, dtm, tmp_path):
    import processing
    from qgis.core import QgsProcessingException
    x, y, z, _ids, _cover, _dz = checkpoints()
    report = str(tmp_path / "r.html")
    flat = add_points(memory_layer("EPSG:32633", ["h:string"], z_geometry=False),
                      [((x[i], y[i]), ["abc" if i == 3 else str(z[i])]) for i in range(5)])
    with pytest.raises(QgsProcessingException, match=r"the points have no Z; choose the field .*Checkpoint elevation field"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": flat, "OUTPUT_HTML": report})
    meadow = add_points(memory_layer("EPSG:32633", ["lc:string"]),
                        [((x[i], y[i], z[i]), ["meadow" if i == 2 else "NVA"]) for i in range(5)])
    with pytest.raises(QgsProcessingException, match=r"feature \d+, Land cover field 'lc': 'meadow' is not a land "
                                                     r"cover.*meadow=NVA or meadow=VVA in 'Land cover values"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": meadow, "LAND_COVER_FIELD": "lc",
                                                "OUTPUT_HTML": report})
    # ... and mapped, it runs
    result = processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": meadow, "LAND_COVER_FIELD": "lc",
                                                     "LAND_COVER_MAP": "meadow=VVA", "OUTPUT_HTML": report,
                                                     "OUTPUT": str(tmp_path / "dz.gpkg")})
    assert result["COUNT"] == 5 and result["VVA_RMSEZ"] is not None
    # the residuals keep the layer's own word beside the land cover it maps to
    features = read_layer(tmp_path / "dz.gpkg")[0]  # (the layer not kept: alive at QGIS's exit, it crashes it)
    assert sorted((f["land_cover"], f["cover_given"]) for f in features.values()) == \
        [("NVA", "NVA")] * 4 + [("VVA", "meadow")]
    with pytest.raises(QgsProcessingException, match=r"land cover mapping: 'meadow' has no '='"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": meadow, "LAND_COVER_FIELD": "lc",
                                                "LAND_COVER_MAP": "meadow", "OUTPUT_HTML": report})
    with pytest.raises(QgsProcessingException, match=r"feature \d+, Checkpoint elevation field 'h': 'abc' is not a number"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": flat, "Z_FIELD": "h", "OUTPUT_HTML": report})
    with pytest.raises(QgsProcessingException, match=r"has no band 2 \(it has 1 band\)"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "BAND": 2, "CHECKPOINTS": meadow, "LAND_COVER_MAP":
                                                "meadow=VVA", "LAND_COVER_FIELD": "lc", "OUTPUT_HTML": report})
    with pytest.raises(QgsProcessingException, match=r"DTM band must be at least 1 \(got 0\)"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "BAND": 0, "CHECKPOINTS": meadow, "OUTPUT_HTML": report})
    with pytest.raises(QgsProcessingException, match=r"the report must end in \.html"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": meadow, "LAND_COVER_MAP": "meadow=VVA",
                                                "LAND_COVER_FIELD": "lc", "OUTPUT_HTML": str(tmp_path / "r.pdf")})


def test_qgis_process_runs_it_on_files(groundsieve_provider, dtm, tmp_path):
    """As a user runs it: a GeoPackage of checkpoints, the numbers in qgis_process's JSON."""
    from qgis.core import QgsVectorFileWriter, QgsProject
    x, y, z, ids, cover, dz = checkpoints()
    layer = add_points(memory_layer("EPSG:32633", ["name:string", "lc:string"]),
                       [((x[i], y[i], z[i]), [ids[i], cover[i]]) for i in range(40)])
    gpkg = tmp_path / "checkpoints.gpkg"
    options = QgsVectorFileWriter.SaveVectorOptions()
    options.driverName = "GPKG"
    error = QgsVectorFileWriter.writeAsVectorFormatV3(layer, str(gpkg), QgsProject.instance().transformContext(),
                                                      options)
    assert error[0] == QgsVectorFileWriter.WriterError.NoError, error
    report = tmp_path / "r.html"
    proc = subprocess.run([str(REPO / "scripts" / "qgis-process"), "--json", "run", "groundsieve:accuracy",
                           f"--DTM={dtm}", f"--CHECKPOINTS={gpkg}", "--ID_FIELD=name", "--LAND_COVER_FIELD=lc",
                           f"--OUTPUT_HTML={report}"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    results = json.loads(proc.stdout)["results"]
    assert results["COUNT"] == 40
    assert results["NVA_RMSEZ"] == pytest.approx(0.05, abs=1e-9)
    assert results["VVA95"] == pytest.approx(np.percentile(dz[20:], 95), abs=1e-9)
    assert report.exists()


def test_a_run_that_cannot_write_its_layer_leaves_no_report_and_a_null_height_is_named(groundsieve_provider, dtm,
                                                                                       tmp_path):
    """A residual layer in a missing folder failed after the report was written, which stayed behind (a
    surveyor); it is refused before the work now. An empty (NULL) height stopped the run: the checkpoint (a
    mark not observed) is left out and named with its id, in the log and the report; when every height is
    empty the field is asked about."""
    import processing
    from qgis.core import NULL, QgsProcessingException
    x, y, z, ids, _cover, _dz = checkpoints()
    layer = add_points(memory_layer("EPSG:32633", ["name:string"]), [((x[i], y[i], z[i]), [ids[i]]) for i in range(30)])
    report = tmp_path / "r.html"
    with pytest.raises(QgsProcessingException, match="does not exist"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": layer, "OUTPUT_HTML": str(report),
                                                "OUTPUT": str(tmp_path / "nowhere" / "dz.gpkg")})
    assert os.listdir(tmp_path) == []
    flat = add_points(memory_layer("EPSG:32633", ["name:string", "h:double"], z_geometry=False),
                      [((x[i], y[i]), [ids[i], NULL if i == 2 else float(z[i])]) for i in range(5)])
    result = processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": flat, "Z_FIELD": "h",
                                                     "ID_FIELD": "name", "OUTPUT_HTML": str(report)})
    assert result["COUNT"] == 4
    assert "1 checkpoint(s) with an empty (NULL) 'h' left out: CP3" in html.unescape(report.read_text())
    empty = add_points(memory_layer("EPSG:32633", ["name:string", "h:double"], z_geometry=False),
                       [((x[i], y[i]), [ids[i], NULL]) for i in range(3)])
    with pytest.raises(QgsProcessingException, match=r"every checkpoint's Checkpoint elevation field 'h' is empty "
                                                     r"\(NULL\): is it the field of their heights\?"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": empty, "Z_FIELD": "h",
                                                "OUTPUT_HTML": str(tmp_path / "r5.html")})
    text = add_points(memory_layer("EPSG:32633", ["name:string", "h:string"], z_geometry=False),
                      [((x[i], y[i]), [ids[i], "n/a" if i == 1 else str(z[i])]) for i in range(3)])
    with pytest.raises(QgsProcessingException, match=r"feature \d+ \('CP2'\), Checkpoint elevation field 'h': 'n/a' "
                                                     r"is not a number"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": text, "Z_FIELD": "h", "ID_FIELD": "name",
                                                "OUTPUT_HTML": str(tmp_path / "r5.html")})
    assert not (tmp_path / "r5.html").exists()


def test_a_survey_s_text_or_csv_file_is_read_as_the_command_line_reads_it(groundsieve_provider, dtm, tmp_path):
    """A CSV given as it is (a table, no geometry) was refused with 'a table without geometries' (a surveyor),
    and a space-delimited text file QGIS does not open was 'no point layer': both are read as the command line
    reads them, in the DTM's CRS, with the figures of the same checkpoints as a point layer. A header word the
    reader does not know is named in the field parameters; a column the file lacks is named with the file."""
    import processing
    from qgis.core import QgsProcessingException, QgsVectorLayer
    x, y, z, ids, cover, dz = checkpoints()
    csv = tmp_path / "cp.csv"
    csv.write_text("Name,East,North,Elev_ortho,Surface\n" + "".join(
        f"{ids[i]},{x[i]!r},{y[i]!r},{z[i]!r},{'road' if cover[i] == 'NVA' else 'forest'}\n" for i in range(40)))
    txt = tmp_path / "cp.txt"
    txt.write_text("".join(f"{x[i]!r} {y[i]!r} {z[i]!r} {cover[i]}\n" for i in range(43)))
    layer_out = tmp_path / "dz.gpkg"
    result = processing.run("groundsieve:accuracy", {
        "DTM": dtm, "CHECKPOINTS": str(csv), "Z_FIELD": "Elev_ortho", "LAND_COVER_FIELD": "Surface",
        "LAND_COVER_MAP": "road=NVA,forest=VVA", "OUTPUT_HTML": str(tmp_path / "r.html"), "OUTPUT": str(layer_out)})
    assert result["COUNT"] == 40 and result["SKIPPED"] == 0
    assert result["NVA_RMSEZ"] == pytest.approx(0.05, abs=1e-9)
    assert result["VVA95"] == pytest.approx(np.percentile(dz[20:], 95), abs=1e-9)
    rows, written = read_layer(layer_out)
    assert written.crs().authid() == "EPSG:32633"  # (the DTM's)
    assert rows["CP7"]["dz"] == pytest.approx(dz[6], abs=1e-9) and rows["CP7"]["land_cover"] == "NVA"
    assert "in the DTM's CRS" in html.unescape((tmp_path / "r.html").read_text())
    del rows, written
    result = processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": str(txt),
                                                     "OUTPUT_HTML": str(tmp_path / "r2.html")})
    assert result["COUNT"] == 41 and result["SKIPPED"] == 2  # (the one outside the DTM, the one on nodata)
    assert result["NVA95"] is not None and result["VVA_RMSEZ"] == pytest.approx(np.sqrt(np.mean(dz[20:] ** 2)))
    with pytest.raises(QgsProcessingException, match=r"Checkpoint elevation field: the layer 'cp' has no field 'Elev' "
                                                     r"\(its fields: Name, East, North, Elev_ortho, Surface\)"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": str(csv), "Z_FIELD": "Elev",
                                                "OUTPUT_HTML": str(tmp_path / "r3.html")})
    with pytest.raises(QgsProcessingException, match=r"cp\.txt: has no header line, so it has no column 'h'"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": str(txt), "Z_FIELD": "h",
                                                "OUTPUT_HTML": str(tmp_path / "r3.html")})
    assert not (tmp_path / "r3.html").exists()
    # a table that is no file (a memory table without geometries) is still named as such
    table = QgsVectorLayer("None?field=x:double&field=y:double&field=z:double", "cp", "memory")
    with pytest.raises(QgsProcessingException, match=r"a table without geometries .*delimited text layer with "
                                                     r"its X and Y fields"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": table, "Z_FIELD": "z",
                                                "OUTPUT_HTML": str(tmp_path / "r4.html")})


def test_a_field_the_layer_lacks_is_named(groundsieve_provider, dtm, tmp_path):
    """A Z field the layer lacks (a batch row, a model reused with another layer) ran into a KeyError
    traceback (a QGIS power user): it is named, with the layer's fields, before the run and in it."""
    import processing
    from qgis.core import QgsApplication, QgsProcessingContext, QgsProcessingException
    x, y, z, ids, _cover, _dz = checkpoints()
    layer = add_points(memory_layer("EPSG:32633", ["name:string"]), [((x[i], y[i], z[i]), [ids[i]]) for i in range(5)])
    alg = QgsApplication.processingRegistry().algorithmById("groundsieve:accuracy")
    for name in ("Z_FIELD", "ID_FIELD", "LAND_COVER_FIELD"):
        ok, message = alg.checkParameterValues({"DTM": dtm, "CHECKPOINTS": layer, name: "nope",
                                                "OUTPUT_HTML": str(tmp_path / "r.html")}, QgsProcessingContext())
        assert not ok and "has no field 'nope' (its fields: name)" in message, (name, message)
        with pytest.raises(QgsProcessingException, match="has no field 'nope'"):
            processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": layer, name: "nope",
                                                    "OUTPUT_HTML": str(tmp_path / "r.html")})


def test_a_csv_s_text_columns_a_selection_and_a_delimited_text_table(groundsieve_provider, dtm, tmp_path):
    """A code reviewer: the elevation field offered only numeric fields, none of a CSV's (QGIS reads them all
    as text); a CSV table sent with 'selected features only' was refused as if no file had been given; a
    table added through the delimited-text provider was not found; x and y under other words were a dead end.
    The field takes any column, a selection is refused in words (the file is read whole), the delimited-text
    table's file is read, and unknown x and y point to the delimited text layer."""
    import processing
    from qgis.core import (QgsProcessingException, QgsProcessingFeatureSourceDefinition, QgsProcessingParameterField,
                           QgsProject, QgsVectorLayer)
    from qgis.PyQt.QtCore import QUrl
    alg = groundsieve_provider.algorithm("accuracy")
    assert alg.parameterDefinition("Z_FIELD").dataType() == QgsProcessingParameterField.DataType.Any
    x, y, z, ids, _cover, _dz = checkpoints()
    csv = tmp_path / "cp.csv"
    csv.write_text("Name,East,North,Elev_ortho\n" + "".join(f"{ids[i]},{x[i]!r},{y[i]!r},{z[i]!r}\n"
                                                            for i in range(40)))
    url = QUrl.fromLocalFile(str(csv)).toString() + "?type=csv&geomType=none&detectTypes=no"
    table = QgsVectorLayer(url, "cp", "delimitedtext")
    assert table.isValid()
    QgsProject.instance().addMapLayer(table)
    try:
        result = processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": table.id(), "Z_FIELD": "Elev_ortho",
                                                         "OUTPUT_HTML": str(tmp_path / "r.html")})
        assert result["COUNT"] == 40
        selected = QgsProcessingFeatureSourceDefinition(table.id(), True)
        table.selectByIds([1, 2])
        with pytest.raises(QgsProcessingException, match=r"only some rows are asked for .* its file is read whole"):
            processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": selected, "Z_FIELD": "Elev_ortho",
                                                    "OUTPUT_HTML": str(tmp_path / "r2.html")})
        table.removeSelection()
        assert table.setSubsetString('"Name" = \'CP1\'')  # (a layer's filter was ignored: 40 used for 1, a reviewer)
        with pytest.raises(QgsProcessingException, match=r"only some rows are asked for .* its file is read whole"):
            processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": table.id(), "Z_FIELD": "Elev_ortho",
                                                    "OUTPUT_HTML": str(tmp_path / "r2.html")})
    finally:
        QgsProject.instance().removeMapLayer(table.id())
    # the table as a layer object (a script, the Python console), and a cover column nobody chose
    table = QgsVectorLayer(url, "cp", "delimitedtext")
    result = processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": table, "Z_FIELD": "Elev_ortho",
                                                     "OUTPUT_HTML": str(tmp_path / "r4.html")})
    assert result["COUNT"] == 40
    del table
    covered = tmp_path / "covered.csv"
    covered.write_text("x,y,z,cover\n" + "".join(f"{x[i]!r},{y[i]!r},{z[i]!r},forest\n" for i in range(30)))
    result = processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": str(covered),
                                                     "OUTPUT_HTML": str(tmp_path / "r5.html")})
    assert result["COUNT"] == 30 and result["NVA_RMSEZ"] is None  # (its words unknown and no field chosen: left out)
    assert "the file's land-cover column is left out" in html.unescape((tmp_path / "r5.html").read_text())
    # a land-cover map typed for it: its typo is said, as for a layer (a code reviewer)
    with pytest.raises(QgsProcessingException, match="'forest' is not a land cover this check knows"):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": str(covered), "LAND_COVER_MAP": "forrest=VVA",
                                                "OUTPUT_HTML": str(tmp_path / "r6.html")})
    other = tmp_path / "gk.csv"
    other.write_text("Rechtswert;Hochwert;Hoehe\n" + "".join(f"{x[i]!r};{y[i]!r};{z[i]!r}\n" for i in range(5)))
    with pytest.raises(QgsProcessingException, match="names no x and no y and no z column.*delimited text layer with its X "):
        processing.run("groundsieve:accuracy", {"DTM": dtm, "CHECKPOINTS": str(other),
                                                "OUTPUT_HTML": str(tmp_path / "r3.html")})
