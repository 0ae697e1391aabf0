"""IGNORE_CLASSES and the older IGNORE_NOISE through processing.run (the toolbox and the modeler):
the new parameter is in every ground filter, and a saved model or script that sets
IGNORE_NOISE=false still filters the noise."""
import numpy as np
import pytest

from groundsieve.tests.core.test_marked_points import write_scene

from .conftest import classes_of

GROUND_FILTERS = ("smrf", "pmf", "csf", "ptd", "echogrid", "evc", "evcrasters")


def test_every_ground_filter_has_ignore_classes(groundsieve_provider):
    from qgis.core import QgsApplication, QgsProcessingParameterDefinition
    for name in GROUND_FILTERS:
        alg = QgsApplication.processingRegistry().algorithmById(f"groundsieve:{name}")
        param = alg.parameterDefinition("IGNORE_CLASSES")
        assert param is not None and param.defaultValue() == "7,18", name
        hidden = alg.parameterDefinition("IGNORE_NOISE")
        assert hidden.flags() & QgsProcessingParameterDefinition.Flag.FlagHidden, name


@pytest.mark.parametrize("params, noise_class", [({}, "kept"), ({"IGNORE_NOISE": False}, "filtered"),
                                                 ({"IGNORE_CLASSES": ""}, "filtered"),
                                                 ({"IGNORE_CLASSES": "7"}, "18 filtered")])
def test_noise_rules_through_processing_run(groundsieve_provider, tmp_path, params, noise_class):
    import processing
    src = tmp_path / "in.las"
    kind, cls_in = write_scene(src)
    out = tmp_path / "out.las"
    processing.run("groundsieve:pmf", {"INPUT": str(src), "OUTPUT": str(out), **params})
    cls = classes_of(out)
    n7, n18 = kind == "noise7", kind == "noise18"
    if noise_class == "kept":
        assert (cls[n7] == 7).all() and (cls[n18] == 18).all()
    elif noise_class == "filtered":  # given to the filter: 1 or 2 (PMF takes low outliers for ground)
        assert np.isin(cls[n7 | n18], [1, 2]).all()
    else:
        assert (cls[n7] == 7).all() and np.isin(cls[n18], [1, 2]).all()
    np.testing.assert_array_equal(cls[kind == "withheld"], cls_in[kind == "withheld"])


def test_dtm_classes_in_every_ground_filter_and_rfclassify(groundsieve_provider, tmp_path):
    """DTM_CLASSES: offered by every ground filter and rfclassify, empty by default; a class named
    enters the DTM (the water of tests/core/test_dtm_classes.py, through processing.run with the
    vendor's classes kept); a bad list is refused in the dialog's words."""
    import processing
    from osgeo import gdal
    from qgis.core import QgsApplication, QgsProcessingException
    from groundsieve.tests.core.test_dtm_classes import BANK_Z, RIVER, WATER_Z
    from groundsieve.core.io import new_las, write_las
    for name in GROUND_FILTERS + ("hybrid", "rfclassify"):
        param = QgsApplication.processingRegistry().algorithmById(f"groundsieve:{name}").parameterDefinition(
            "DTM_CLASSES")
        assert param is not None and not param.defaultValue(), name
        gap = QgsApplication.processingRegistry().algorithmById(f"groundsieve:{name}").parameterDefinition(
            "DTM_MAX_DISTANCE")
        assert gap is not None and gap.defaultValue() == 0, name
    rng = np.random.default_rng(3)
    x, y = rng.uniform(0, 120, 20_000), rng.uniform(0, 120, 20_000)
    wet = (x > RIVER[0]) & (x < RIVER[1])
    src = tmp_path / "river.las"
    write_las(new_las(x, y, np.where(wet, WATER_Z, BANK_Z), classification=np.where(wet, 9, 2).astype(np.uint8)),
              str(src))
    medians = {}
    for classes in ("", "9"):
        dtm = tmp_path / f"dtm{classes}.tif"
        processing.run("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": str(tmp_path / f"o{classes}.las"),
                                            "KEEP_CLASSES": True, "DTM": str(dtm), "DTM_CLASSES": classes})
        ds = gdal.Open(str(dtm))
        values, (x0, cell) = ds.ReadAsArray(), ds.GetGeoTransform()[:2]
        centres = x0 + (np.arange(values.shape[1]) + 0.5) * cell
        medians[classes] = float(np.median(values[:, (centres > RIVER[0] + 3) & (centres < RIVER[1] - 3)]))
    assert medians[""] == pytest.approx(BANK_Z, abs=0.1) and medians["9"] == pytest.approx(WATER_Z, abs=0.1)
    with pytest.raises(QgsProcessingException, match="DTM classes: 'water' is not a class code"):
        processing.run("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": str(tmp_path / "x.las"),
                                            "DTM": str(tmp_path / "x.tif"), "DTM_CLASSES": "water"})
    assert not (tmp_path / "x.las").exists()
