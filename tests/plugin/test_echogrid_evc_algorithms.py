"""groundsieve:echogrid, groundsieve:evc and groundsieve:evcrasters through processing.run and
the qgis_process wrapper, checked on the written files."""
import subprocess
from pathlib import Path

import numpy as np
import pytest

from .conftest import classes_of

REPO = Path(__file__).resolve().parents[2]


def _read(path):
    """Band 1 and geotransform; keeps the dataset alive while reading (GDAL 3.6 crashes if a
    band outlives its dataset)."""
    from osgeo import gdal
    ds = gdal.Open(str(path))
    return ds.GetRasterBand(1).ReadAsArray(), ds.GetGeoTransform()


def _run(alg, params):
    import processing
    return processing.run(f"groundsieve:{alg}", params)


@pytest.mark.parametrize("alg", ["smrf", "echogrid", "evc", "evcrasters", "pmf", "csf", "ptd"])
def test_registered_with_the_shared_interface(groundsieve_provider, alg):
    from qgis.core import QgsApplication
    algorithm = QgsApplication.processingRegistry().algorithmById(f"groundsieve:{alg}")
    assert algorithm is not None
    names = {p.name() for p in algorithm.parameterDefinitions()}
    assert {"INPUT", "OUTPUT", "DTM", "DTM_CELL", "GROUND_POINTS"} <= names
    assert not algorithm.icon().isNull()
    assert algorithm.shortHelpString()


@pytest.mark.parametrize("mode", [0, 1])
def test_echogrid_on_scene(groundsieve_provider, scene_laz, tmp_path, mode):
    from groundsieve.core.metrics import ground_accuracy
    src, scene = scene_laz
    out = tmp_path / "echo.laz"
    result = _run("echogrid", {"INPUT": str(src), "OUTPUT": str(out), "MODE": mode})
    cls = classes_of(out)
    assert result["GROUND_COUNT"] == int((cls == 2).sum())
    acc = ground_accuracy(scene.classification == 2, cls == 2)
    assert acc.type1 < 0.01  # the height test keeps the terrain
    if mode == 1:  # evidence: roofs and non-last returns are no longer ground
        assert acc.type2 < 0.15, acc.summary()


def test_echogrid_warns_without_return_information(groundsieve_provider, tmp_path):
    from qgis.core import QgsProcessingFeedback
    import processing
    xyz = np.random.default_rng(0).uniform(0, 50, (2000, 3))
    src = tmp_path / "flat.txt"
    np.savetxt(src, np.column_stack([xyz[:, 0], xyz[:, 1], xyz[:, 2] * 0.01, np.zeros(len(xyz))]))
    messages = []

    class Feedback(QgsProcessingFeedback):
        def pushInfo(self, info):  # noqa: N802
            messages.append(("info", info))

        def pushWarning(self, warning):  # noqa: N802
            messages.append(("warning", warning))

    processing.run("groundsieve:echogrid", {"INPUT": str(src), "OUTPUT": str(tmp_path / "o.laz")},
                   feedback=Feedback())
    assert any(kind == "warning" and "no return information" in m for kind, m in messages), messages


def test_evc_with_defaults_only(groundsieve_provider, scene_laz, tmp_path):
    src, scene = scene_laz
    out = tmp_path / "evc.las"
    result = _run("evc", {"INPUT": str(src), "OUTPUT": str(out)})
    cls = classes_of(out)
    assert len(cls) == len(scene.x)
    assert set(np.unique(cls)) <= {1, 2}
    assert result["GROUND_COUNT"] == int((cls == 2).sum())


@pytest.mark.parametrize("params, message", [
    ({"RADIUS": 0}, r"Neighbourhood radius \(cells\) must be at least 1 \(got 0\)"),  # refused before the run, by its label
    ({"SMALL_SCALE": 2.0, "LARGE_SCALE": 2.0}, "large_scale_m"),
    ({"LARGE_SCALE": 5000.0}, "larger than the cloud"),
])
def test_evc_bad_parameters(groundsieve_provider, scene_laz, tmp_path, params, message):
    from qgis.core import QgsProcessingException
    src, _scene = scene_laz
    out = tmp_path / "evc.laz"
    with pytest.raises(QgsProcessingException, match=message):
        _run("evc", {"INPUT": str(src), "OUTPUT": str(out), **params})
    assert not out.exists()


def test_evcrasters_writes_every_raster(groundsieve_provider, scene_laz, tmp_path):
    from osgeo import gdal, osr
    src, scene = scene_laz
    names = ["SMALL_MEAN", "LARGE_MEAN", "DIFFERENCE_RASTER", "EVC_RASTER", "CLASS_RASTER"]
    params = {"INPUT": str(src), "OUTPUT": str(tmp_path / "c.laz"), "DTM": str(tmp_path / "dtm.tif"),
              "SMALL_SCALE": 0.5, "LARGE_SCALE": 4.0}
    params.update({name: str(tmp_path / f"{name.lower()}.tif") for name in names})
    result = _run("evcrasters", params)
    for name in names + ["DTM"]:
        ds = gdal.Open(result[name])
        assert ds is not None, name
        srs = osr.SpatialReference(wkt=ds.GetProjection())
        assert srs.GetAuthorityCode(None) == "32632", name
        gt = ds.GetGeoTransform()
        assert gt[5] < 0 and gt[2] == gt[4] == 0, name  # north up
        expected = {"LARGE_MEAN": 4.0, "DTM": 1.0}.get(name, 0.5)
        assert gt[1] == expected, name
    small, _ = _read(result["SMALL_MEAN"])
    large, _ = _read(result["LARGE_MEAN"])
    valid = small != -9999.0
    zmin, zmax = scene.z.min(), scene.z.max()
    assert (small[valid] >= zmin - 1e-3).all() and (small[valid] <= zmax + 1e-3).all()
    assert (large != -9999.0).mean() > 0.95
    classes, gt = _read(result["CLASS_RASTER"])
    assert set(np.unique(classes)) <= {0, 1, 2, 3}  # 0: an empty small cell, the no data
    # bytes, its classes named and coloured in the file: any GIS shows the legend
    ds = gdal.Open(result["CLASS_RASTER"])  # kept open while its band is read (GDAL 3.6)
    band = ds.GetRasterBand(1)
    assert band.DataType == gdal.GDT_Byte and band.GetNoDataValue() == 0
    assert band.GetDescription() == "1 Ground, 2 Vegetation area, 3 Vegetation boundary"
    assert band.GetMetadata() == {"CLASS_1": "Ground", "CLASS_2": "Vegetation area", "CLASS_3": "Vegetation boundary"}
    assert not list(tmp_path.glob("*.aux.xml"))  # all in the TIFF
    table = band.GetColorTable()
    assert [table.GetColorEntry(v)[:3] for v in (1, 2, 3)] == [(0xb0, 0x7d, 0x3c), (0x1a, 0x7f, 0x2e),
                                                               (0x9b, 0xd3, 0x5a)]
    # Points take their small cell's class: ground points == points in class-1 cells.
    import laspy
    las = laspy.read(str(tmp_path / "c.laz"))  # the coordinates as stored (0.01 m steps), as filtered
    col = np.floor((np.asarray(las.x) - gt[0]) / gt[1]).astype(int)
    row = np.floor((gt[3] - np.asarray(las.y)) / -gt[5]).astype(int)
    np.testing.assert_array_equal(np.asarray(las.classification) == 2, classes[row, col] == 1)


def test_evcrasters_and_echogrid_from_the_command_line(scene_laz, tmp_path):
    src, _scene = scene_laz
    wrapper = str(REPO / "scripts" / "qgis-process")
    proc = subprocess.run([wrapper, "run", "groundsieve:evcrasters", f"--INPUT={src}",
                           f"--OUTPUT={tmp_path / 'c.laz'}", f"--EVC_RASTER={tmp_path / 'evc.tif'}",
                           "--SMALL_SCALE=0.5"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    evc, _ = _read(tmp_path / "evc.tif")
    assert evc.shape[1] > 100
    proc = subprocess.run([wrapper, "run", "groundsieve:echogrid", f"--INPUT={src}",
                           f"--OUTPUT={tmp_path / 'e.laz'}"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (classes_of(tmp_path / "e.laz") == 2).any()


@pytest.mark.parametrize("alg", ["smrf", "echogrid", "evc", "pmf", "csf", "ptd"])
def test_every_filter_runs_with_input_and_output_only(alg, scene_laz, tmp_path):
    """The shared interface: `scripts/qgis-process run groundsieve:<id> --INPUT=a.laz --OUTPUT=b.laz`."""
    src, scene = scene_laz
    out = tmp_path / f"{alg}.laz"
    proc = subprocess.run([str(REPO / "scripts" / "qgis-process"), "run", f"groundsieve:{alg}", f"--INPUT={src}",
                           f"--OUTPUT={out}"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    cls = classes_of(out)
    assert len(cls) == len(scene.x) and set(np.unique(cls)) <= {1, 2} and (cls == 2).any()


@pytest.mark.parametrize("index, scheme", [(0, "library"), (1, "2016")])
def test_csf_form_maps_to_the_core_filter(groundsieve_provider, index, scheme):
    """The CSF form's enums reach the core parameters (rigidness option i is rigidness i + 1)."""
    from qgis.core import QgsApplication, QgsProcessingContext
    algorithm = QgsApplication.processingRegistry().createAlgorithmById("groundsieve:csf")
    f = algorithm.buildFilter({"CONSTRAINT_SCHEME": index, "RIGIDNESS": 0, "RESOLUTION": 0.5,
                               "INTERSECTION_HEIGHT": 1, "SWEEP_ORDER": index}, QgsProcessingContext())
    assert (f.constraint_scheme, f.rigidness, f.cloth_resolution_m, f.intersection_height, f.sweep_order) == \
        (scheme, 1, 0.5, "cell", ("rotating", "fixed")[index])
    assert (f.time_step, f.class_threshold_m, f.iterations, f.low_outlier_m) == (0.65, 0.5, 500, 5.0)
    f = algorithm.buildFilter({}, QgsProcessingContext())  # the form's defaults are the core's
    from groundsieve.core.filters.csf import CSF
    assert f == CSF(rigidness=3)


def test_help_is_one_line_per_paragraph(groundsieve_provider):
    """QGIS's algorithm dialog turns every line of shortHelpString into a paragraph, so the help
    of every algorithm must have no line breaks (its paragraphs are HTML tags)."""
    algorithms = groundsieve_provider.algorithms()
    assert len(algorithms) >= 10
    for algorithm in algorithms:
        text = algorithm.shortHelpString()
        assert text.startswith("<p>") and "</p>" in text, algorithm.id()
        assert "\n" not in text, algorithm.id()
        assert "  " not in text, algorithm.id()
