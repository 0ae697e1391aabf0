"""Fixtures of the plugin tests: QGIS with Processing (pytest-qgis) and GroundSieve's provider."""
import numpy as np
import pytest


@pytest.fixture(scope="session")
def groundsieve_plugin(qgis_app, qgis_processing):
    """The plugin as qgis_process loads it: classFactory(iface=None), then initProcessing()."""
    from qgis.core import QgsApplication

    import groundsieve
    plugin = groundsieve.classFactory(None)
    plugin.initProcessing()  # the plugin keeps the Python reference the registry needs
    yield plugin
    plugin.unload()
    assert QgsApplication.processingRegistry().providerById("groundsieve") is None


@pytest.fixture(scope="session")
def groundsieve_provider(groundsieve_plugin):
    return groundsieve_plugin.provider


@pytest.fixture(scope="session")
def scene_laz(tmp_path_factory):
    """A generated scene with known truth, written as LAZ with a CRS."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, scene_crs_wkt, write_scene
    scene = make_scene(SceneSpec(size_m=120.0, density_per_m2=6.0, seed=7))
    path = tmp_path_factory.mktemp("scene") / "scene.laz"
    write_scene(scene, str(path), crs_wkt=scene_crs_wkt())
    return path, scene


def add_child(model, alg_id, child_id, sources, outputs, static=None):
    """Add the step ``alg_id`` (named ``child_id``) to a QgsProcessingModelAlgorithm: ``sources`` its
    wired inputs (name -> QgsProcessingModelChildParameterSource), ``outputs`` its model outputs
    (model name -> its output's name), ``static`` values for any of its other parameters; every
    parameter left gets its default as a static value, as the modeler's dialog does."""
    from qgis.core import (QgsApplication, QgsProcessingModelChildAlgorithm,
                           QgsProcessingModelChildParameterSource as Source, QgsProcessingModelOutput)
    child = QgsProcessingModelChildAlgorithm(alg_id)
    child.setChildId(child_id)
    sources = dict(sources)
    definitions = QgsApplication.processingRegistry().algorithmById(alg_id).parameterDefinitions()
    for definition in definitions:
        if definition.name() in (static or {}):
            sources[definition.name()] = Source.fromStaticValue(static[definition.name()])
        elif not definition.isDestination() and definition.name() not in sources:
            sources[definition.name()] = Source.fromStaticValue(definition.defaultValue())
    for name, source in sources.items():
        child.addParameterSources(name, [source])
    model_outputs = {}
    for model_name, child_output in outputs.items():
        out = QgsProcessingModelOutput(model_name)
        out.setChildId(child_id)
        out.setChildOutputName(child_output)
        model_outputs[model_name] = out
    child.setModelOutputs(model_outputs)
    model.addChildAlgorithm(child)


def vpc_survey(scene_laz, tmp_path, name="classified.vpc"):
    """The scene split into a folder of two files, and a .vpc output path in a folder made for it;
    skips the test where this QGIS opens no .vpc (before 3.32)."""
    from groundsieve.algorithms import pointclouds
    from .test_survey_inputs import _split
    if not pointclouds.providers_opening("x.vpc"):
        pytest.skip("this QGIS has no point-cloud provider for .vpc (QGIS < 3.32)")
    src, _scene = scene_laz
    _split(src, tmp_path / "in")
    out = tmp_path / "out" / name
    out.parent.mkdir()
    return tmp_path / "in", out


def classes_of(path):
    import laspy
    return np.asarray(laspy.read(str(path)).classification)


def pytest_collection_modifyitems(items):
    """A QGIS API call that this QGIS deprecates, made from the plugin's own code, fails the test:
    users would see its warning in every run's log (QGIS 3.40 deprecates what 3.22 offered)."""
    for item in items:
        if "tests/plugin/" in str(item.fspath).replace("\\", "/"):
            item.add_marker(pytest.mark.filterwarnings("error::DeprecationWarning:groundsieve.*"))
