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
