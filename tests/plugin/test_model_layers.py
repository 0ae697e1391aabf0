"""What a graphical model loads into the project (the ground filters and rfclassify, one rule): as
QGIS does for its own algorithms, the output of a step that is not a model output (QGIS gives it a
temporary destination) is never loaded; a model output is loaded as in a plain run. QgsProcessingModelAlgorithm passes such a step
``generateTemporaryDestination()`` (a plain path in Processing's temporary folder), its final outputs
the model's own values (algorithms/pointclouds.py ``is_model_intermediate``).

A model output's layer is named after the model output, as QGIS names its own (the model gives its
value the output's name, ``QgsProcessingOutputLayerDefinition.destinationName``); elsewhere the layer
keeps the output's label, "Classified point cloud".

The classified cloud loads only where a point-cloud provider opens it: LAS/LAZ with PDAL (Windows and
macOS builds, simulated here by its declared patterns), .vpc with QGIS >= 3.32 (3.40 here, for real)."""
import pytest

from .conftest import add_child, classes_of, vpc_survey

#: what a build with PDAL declares (test_layers.py): the same code then loads .laz outputs
PDAL = {"pdal": ["*.las", "*.laz"]}


def _model(first_is_output, first="smrf", **static):
    """``first`` (smrf) -> pmf on its classified cloud, and its DTM -> a QGIS raster algorithm. pmf's
    cloud is a model output; the first step's cloud only when ``first_is_output``; its DTM never.
    ``static``: values of both steps' other parameters (each takes those it has)."""
    from qgis.core import (QgsProcessingModelAlgorithm, QgsProcessingModelChildParameterSource as Source,
                           QgsProcessingModelParameter, QgsProcessingParameterFile)
    model = QgsProcessingModelAlgorithm("two steps", "tests")
    model.addModelParameter(QgsProcessingParameterFile("cloud", "Point cloud"), QgsProcessingModelParameter("cloud"))
    steps = [(f"groundsieve:{first}", first, {"INPUT": Source.fromModelParameter("cloud")},
              {"classified": "OUTPUT"} if first_is_output else {}),
             ("groundsieve:pmf", "pmf", {"INPUT": Source.fromChildOutput(first, "OUTPUT")},
              {"second": "OUTPUT"}),
             ("native:rasterlayerstatistics", "stats", {"INPUT": Source.fromChildOutput(first, "DTM")}, {})]
    for alg_id, child_id, sources, outputs in steps:
        add_child(model, alg_id, child_id, sources, outputs, static)
    ok, problems = model.validate()
    assert ok, problems
    return model


def _context():
    from qgis.core import QgsProcessingContext, QgsProject
    context = QgsProcessingContext()
    context.setProject(QgsProject.instance())
    return context


def _to_load(context):
    return {path: details.outputName for path, details in context.layersToLoadOnCompletion().items()}


def _names(context):
    """{path: the name its layer will have} of the layers to load."""
    return {path: details.name for path, details in context.layersToLoadOnCompletion().items()}


def _run(model, params):
    from qgis.core import QgsProcessingFeedback
    context = _context()
    results, ok = model.run(params, context, QgsProcessingFeedback())
    assert ok
    return results, context


def _as_dialog(path):
    """A destination as the dialog passes it, "Open output file after running" ticked."""
    from qgis.core import QgsProcessingOutputLayerDefinition, QgsProject
    return QgsProcessingOutputLayerDefinition(str(path), QgsProject.instance())


def test_a_model_loads_its_outputs_not_its_intermediate_steps(groundsieve_provider, scene_laz, tmp_path, monkeypatch):
    from groundsieve.algorithms import pointclouds
    monkeypatch.setattr(pointclouds, "point_cloud_patterns", lambda: PDAL)
    src, scene = scene_laz
    second = tmp_path / "second.laz"
    results, context = _run(_model(first_is_output=False), {"cloud": str(src), "pmf:second": _as_dialog(second)})
    intermediate = results["CHILD_INPUTS"]["smrf"]["OUTPUT"]
    assert pointclouds.is_model_intermediate(intermediate, context)
    assert classes_of(intermediate).size == len(scene.x)  # written, and read by the next step
    dtm = results["CHILD_RESULTS"]["smrf"]["DTM"]
    assert results["CHILD_RESULTS"]["stats"]["MAX"] > results["CHILD_RESULTS"]["stats"]["MIN"]
    # only the model's output: neither smrf's cloud nor its DTM (QGIS's own rule for rasters)
    assert _to_load(context) == {str(second): "OUTPUT"}, (intermediate, dtm)
    assert not context.willLoadLayerOnCompletion(intermediate) and not context.willLoadLayerOnCompletion(dtm)

    # The same model with smrf's cloud a model output: it loads, named by the user or by path.
    first = tmp_path / "first.laz"
    for value in (_as_dialog(first), str(first)):
        results, context = _run(_model(first_is_output=True),
                                {"cloud": str(src), "smrf:classified": value, "pmf:second": str(second)})
        assert results["CHILD_INPUTS"]["pmf"]["INPUT"] == str(first)
        assert _to_load(context) == {str(first): "OUTPUT", str(second): "OUTPUT"}
        assert not context.willLoadLayerOnCompletion(results["CHILD_RESULTS"]["smrf"]["DTM"])
    # A model output left at "[Save to temporary file]" in the dialog loads too.
    results, context = _run(_model(first_is_output=True), {"cloud": str(src), "smrf:classified":
                                                           _as_dialog("TEMPORARY_OUTPUT"), "pmf:second": str(second)})
    assert context.willLoadLayerOnCompletion(results["smrf:classified"])


def test_a_plain_run_still_loads_its_cloud(groundsieve_provider, scene_laz, tmp_path, monkeypatch):
    """Outside a model nothing changes: a named path, the dialog's value and its temporary output
    (``TEMPORARY_OUTPUT``, resolved into the same temporary folder a model's steps write to) load."""
    import processing
    from qgis.core import QgsProcessingFeedback
    from groundsieve.algorithms import pointclouds
    monkeypatch.setattr(pointclouds, "point_cloud_patterns", lambda: PDAL)
    src, _scene = scene_laz
    for value in (str(tmp_path / "a.laz"), _as_dialog(tmp_path / "b.laz"), "TEMPORARY_OUTPUT",
                  _as_dialog("TEMPORARY_OUTPUT")):
        context = _context()
        out = processing.run("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": value},
                             context=context, feedback=QgsProcessingFeedback())["OUTPUT"]
        assert _to_load(context) == {out: "OUTPUT"}, value
        assert _names(context) == {out: "Classified point cloud"}, value  # nothing names it: the label


def test_a_model_does_not_load_an_intermediate_vpc(groundsieve_provider, scene_laz, tmp_path):
    """Where QGIS opens .vpc for real (3.40 here), a survey's intermediate step (a temporary .vpc) is
    not loaded into the project when the model's results are handled as the dialog does; the
    model's output is."""
    from processing.gui.Postprocessing import handleAlgorithmResults
    from qgis.core import QgsProcessingFeedback, QgsProject
    from groundsieve.algorithms import pointclouds
    folder, second = vpc_survey(scene_laz, tmp_path, "second.vpc")
    model = _model(first_is_output=False, TILE_SIZE=50.0)
    results, context = _run(model, {"cloud": str(folder), "pmf:second": _as_dialog(second)})
    intermediate = results["CHILD_RESULTS"]["smrf"]["OUTPUT"]
    assert intermediate.endswith(".vpc") and pointclouds.is_model_intermediate(
        results["CHILD_INPUTS"]["smrf"]["OUTPUT"], context)
    assert _to_load(context) == {str(second): "OUTPUT"}
    try:
        assert handleAlgorithmResults(model, context, QgsProcessingFeedback())
        sources = [layer.source().split("|")[0] for layer in QgsProject.instance().mapLayers().values()]
        assert sources == [str(second)]
    finally:
        QgsProject.instance().removeAllMapLayers()


def test_model_outputs_are_named_after_the_model_outputs(groundsieve_provider, scene_laz, tmp_path, monkeypatch):
    """Two classified clouds of one model, both model outputs: each layer carries its model output's
    name (as QGIS's own outputs do), not twice "Classified point cloud"."""
    from groundsieve.algorithms import pointclouds
    monkeypatch.setattr(pointclouds, "point_cloud_patterns", lambda: PDAL)
    src, _scene = scene_laz
    first, second = tmp_path / "first.laz", tmp_path / "second.laz"
    model = _model(first_is_output=True)
    _results, context = _run(model, {"cloud": str(src), "smrf:classified": _as_dialog(first),
                                     "pmf:second": _as_dialog(second)})
    assert _names(context) == {str(first): "classified", str(second): "second"}
    # "[Save to temporary file]" on a model output: named the same way
    results, context = _run(model, {"cloud": str(src), "smrf:classified": _as_dialog("TEMPORARY_OUTPUT"),
                                    "pmf:second": _as_dialog(second)})
    assert _names(context) == {results["smrf:classified"]: "classified", str(second): "second"}
    # A plain path (a script, qgis_process) carries no name: the layer keeps the output's label.
    _results, context = _run(model, {"cloud": str(src), "smrf:classified": str(first),
                                     "pmf:second": _as_dialog(second)})
    assert _names(context) == {str(first): "Classified point cloud", str(second): "second"}


def test_a_model_loads_its_vpc_outputs_under_their_names(groundsieve_provider, scene_laz, tmp_path):
    """Where QGIS opens .vpc for real (3.40 here), the project holds the two model outputs' layers,
    each named after its model output, once the results are handled as the dialog does."""
    from processing.gui.Postprocessing import handleAlgorithmResults
    from qgis.core import QgsProcessingFeedback, QgsProject
    from groundsieve.algorithms import pointclouds
    from .test_survey_inputs import _split
    if not pointclouds.providers_opening("x.vpc"):
        pytest.skip("this QGIS has no point-cloud provider for .vpc (QGIS < 3.32)")
    src, _scene = scene_laz
    _split(src, tmp_path / "in")
    (tmp_path / "out").mkdir()
    first, second = tmp_path / "out" / "first.vpc", tmp_path / "out" / "second.vpc"
    model = _model(first_is_output=True, TILE_SIZE=50.0)
    _results, context = _run(model, {"cloud": str(tmp_path / "in"), "smrf:classified": _as_dialog(first),
                                     "pmf:second": _as_dialog(second)})
    try:
        assert handleAlgorithmResults(model, context, QgsProcessingFeedback())
        layers = {layer.source().split("|")[0]: layer.name() for layer in QgsProject.instance().mapLayers().values()}
        assert layers == {str(first): "classified", str(second): "second"}
    finally:
        QgsProject.instance().removeAllMapLayers()


@pytest.fixture(scope="module")
def rf_model(scene_laz, tmp_path_factory):
    """A small ground model (rftrain's default features, x, y, z: it runs on surveys too)."""
    import processing
    from qgis.core import QgsProcessingFeedback
    src, _scene = scene_laz
    folder = tmp_path_factory.mktemp("rf")
    model = folder / "model.npz"
    processing.run("groundsieve:rftrain", {"INPUT": str(src), "MODEL": str(model), "TREES": 4,
                                           "REPORT": str(folder / "r.html")}, feedback=QgsProcessingFeedback())
    return model


def test_rfclassify_loads_its_cloud_as_the_filters_do(groundsieve_provider, scene_laz, rf_model, tmp_path,
                                                     monkeypatch):
    """rfclassify's classified cloud loads where a provider opens it (it once never did), by the
    filters' rules: a plain run loads it as "Classified point cloud"; a model's intermediate step
    does not; a model output loads under the model output's name."""
    import processing
    from qgis.core import QgsProcessingFeedback
    from groundsieve.algorithms import pointclouds
    monkeypatch.setattr(pointclouds, "point_cloud_patterns", lambda: PDAL)
    src, _scene = scene_laz
    for value in (str(tmp_path / "a.laz"), _as_dialog(tmp_path / "b.laz"), "TEMPORARY_OUTPUT"):
        context = _context()
        out = processing.run("groundsieve:rfclassify", {"INPUT": str(src), "MODEL": str(rf_model), "OUTPUT": value},
                             context=context, feedback=QgsProcessingFeedback())["OUTPUT"]
        assert _to_load(context) == {out: "OUTPUT"} and _names(context) == {out: "Classified point cloud"}, value
    first, second = tmp_path / "first.laz", tmp_path / "second.laz"
    results, context = _run(_model(first_is_output=False, first="rfclassify", MODEL=str(rf_model)),
                            {"cloud": str(src), "pmf:second": _as_dialog(second)})
    intermediate = results["CHILD_INPUTS"]["rfclassify"]["OUTPUT"]
    assert pointclouds.is_model_intermediate(intermediate, context)
    assert classes_of(results["CHILD_RESULTS"]["rfclassify"]["OUTPUT"]).size == classes_of(src).size
    assert _to_load(context) == {str(second): "OUTPUT"}
    _results, context = _run(_model(first_is_output=True, first="rfclassify", MODEL=str(rf_model)),
                             {"cloud": str(src), "rfclassify:classified": _as_dialog(first),
                              "pmf:second": _as_dialog(second)})
    assert _names(context) == {str(first): "classified", str(second): "second"}


def test_rfclassify_loads_a_survey_vpc(groundsieve_provider, scene_laz, rf_model, tmp_path):
    """Where QGIS opens .vpc for real (3.40 here), rfclassify's survey output is in the project once
    the results are handled as the dialog does."""
    import processing
    from processing.gui.Postprocessing import handleAlgorithmResults
    from qgis.core import QgsApplication, QgsPointCloudLayer, QgsProcessingFeedback, QgsProject
    folder, out = vpc_survey(scene_laz, tmp_path, "classified.vpc")
    context, feedback = _context(), QgsProcessingFeedback()
    processing.run("groundsieve:rfclassify", {"INPUT": str(folder), "MODEL": str(rf_model),
                                              "OUTPUT": _as_dialog(out)}, context=context, feedback=feedback)
    try:
        assert handleAlgorithmResults(QgsApplication.processingRegistry().algorithmById("groundsieve:rfclassify"),
                                      context, feedback)
        layers = list(QgsProject.instance().mapLayers().values())
        assert [(layer.source().split("|")[0], layer.name()) for layer in layers] == [
            (str(out), "Classified point cloud")]
        assert isinstance(layers[0], QgsPointCloudLayer) and layers[0].isValid()
    finally:
        QgsProject.instance().removeAllMapLayers()


def test_the_user_guide_says_what_a_model_loads():
    """The guide's modeler paragraph and its rfclassify section say what the tests above check."""
    import re
    from pathlib import Path
    guide = (Path(__file__).resolve().parents[2] / "docs" / "USER_GUIDE.md").read_text()
    text = re.sub(r"\s+", " ", guide)
    modeler = text[text.index("In the **graphical modeler**"):text.index("Where your QGIS opens point clouds")]
    assert "intermediate classified clouds are not loaded" in modeler
    assert "named after its model output" in modeler
    rfclassify = text[text.index("*Classify with Random Forest model* applies"):text.index("## Tune")]
    assert "classified cloud is loaded as the filters' is" in rfclassify
