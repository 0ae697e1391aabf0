"""GroundSieve's algorithms as children of a graphical-modeler model: outputs flow from one
child to the next (classified cloud -> another filter; DTM -> a QGIS raster algorithm)."""
import numpy as np

from .conftest import add_child, classes_of


def _model():
    from qgis.core import (QgsProcessingModelAlgorithm, QgsProcessingModelChildParameterSource as Source,
                           QgsProcessingModelParameter, QgsProcessingParameterFile)
    model = QgsProcessingModelAlgorithm("groundsieve chain", "tests")
    model.addModelParameter(QgsProcessingParameterFile("cloud", "Point cloud"), QgsProcessingModelParameter("cloud"))

    def child(alg_id, child_id, sources, outputs):
        add_child(model, alg_id, child_id, sources, outputs)

    child("groundsieve:smrf", "smrf", {"INPUT": Source.fromModelParameter("cloud")},
          {"classified": "OUTPUT", "dtm": "DTM"})
    child("groundsieve:echogrid", "echo", {"INPUT": Source.fromChildOutput("smrf", "OUTPUT"),
                                           "MODE": Source.fromStaticValue(1)}, {"reclassified": "OUTPUT"})
    child("native:rasterlayerstatistics", "stats", {"INPUT": Source.fromChildOutput("smrf", "DTM")}, {})
    child("groundsieve:evcrasters", "evc", {"INPUT": Source.fromModelParameter("cloud"),
                                            "SMALL_SCALE": Source.fromStaticValue(0.5),
                                            "LARGE_SCALE": Source.fromStaticValue(4.0)},
          {"evc": "EVC_RASTER", "evc_classified": "OUTPUT"})
    child("native:rasterlayerstatistics", "evcstats", {"INPUT": Source.fromChildOutput("evc", "EVC_RASTER")}, {})
    return model


def test_model_chains_groundsieve_outputs(groundsieve_provider, scene_laz, tmp_path):
    from qgis.core import QgsProcessingContext, QgsProcessingFeedback
    src, scene = scene_laz
    model = _model()
    ok, problems = model.validate()
    assert ok, problems
    first, second, dtm = tmp_path / "smrf.laz", tmp_path / "echo.laz", tmp_path / "dtm.tif"
    context, feedback = QgsProcessingContext(), QgsProcessingFeedback()
    results, ok = model.run({"cloud": str(src), "smrf:classified": str(first), "smrf:dtm": str(dtm),
                             "echo:reclassified": str(second), "evc:evc": str(tmp_path / "evc.tif"),
                             "evc:evc_classified": str(tmp_path / "evc.laz")}, context, feedback)
    assert ok
    assert first.exists() and second.exists() and dtm.exists()
    assert (classes_of(second) == 2).sum() > 0.3 * len(scene.x)
    stats = results["CHILD_RESULTS"]["stats"]
    assert scene.z.min() - 1 < stats["MIN"] < stats["MAX"] < scene.z.max() + 1
    assert (tmp_path / "evc.tif").exists() and (tmp_path / "evc.laz").exists()
    assert results["CHILD_RESULTS"]["evcstats"]["MAX"] > 0  # the EVC raster fed a QGIS algorithm


def _offers_model():
    """A model whose children make every kind of output: smrf (classified cloud, DTM raster,
    ground-point vector layer), rftrain (an .npz model, an HTML report), a QGIS raster algorithm;
    echogrid is the child whose point-cloud input is offered sources. Built, never run."""
    from qgis.core import (QgsProcessingModelAlgorithm, QgsProcessingModelChildAlgorithm,
                           QgsProcessingModelChildParameterSource as Source, QgsProcessingModelParameter,
                           QgsProcessingParameterFile, QgsProcessingParameterNumber)
    model = QgsProcessingModelAlgorithm("offers", "tests")
    model.addModelParameter(QgsProcessingParameterFile("cloud", "Point cloud"), QgsProcessingModelParameter("cloud"))
    model.addModelParameter(QgsProcessingParameterNumber("cell", "Cell"), QgsProcessingModelParameter("cell"))
    for alg_id, child_id, sources in [
            ("groundsieve:smrf", "smrf", {"INPUT": Source.fromModelParameter("cloud")}),
            ("groundsieve:rftrain", "rf", {"INPUT": Source.fromModelParameter("cloud")}),
            ("native:slope", "slope", {"INPUT": Source.fromChildOutput("smrf", "DTM")}),
            ("groundsieve:echogrid", "echo", {"INPUT": Source.fromChildOutput("smrf", "OUTPUT")})]:
        child = QgsProcessingModelChildAlgorithm(alg_id)
        child.setChildId(child_id)
        for name, source in sources.items():
            child.addParameterSources(name, [source])
        model.addChildAlgorithm(child)
    return model


#: every output of the model's children that is no point cloud
_NOT_CLOUDS = {("smrf", "DTM"), ("smrf", "GROUND_POINTS"), ("rf", "MODEL"), ("slope", "OUTPUT")}


def _child_outputs(sources):
    return {(s.outputChildId(), s.outputName()) for s in sources if s.outputChildId()}


def test_modeler_offers_point_clouds_only(groundsieve_provider):
    """What QGIS's modeler would offer to a file input (every file, raster and vector output:
    it keys on output types alone) against what our point-cloud input offers: the classified
    cloud of a previous child and the file model input, never a DTM, ground points, an .npz
    model or another algorithm's raster."""
    from qgis.core import (QgsProcessingOutputFile, QgsProcessingOutputMapLayer, QgsProcessingOutputRasterLayer,
                           QgsProcessingOutputVectorLayer)

    from groundsieve.algorithms import pointclouds
    model = _offers_model()
    qgis_default = model.availableSourcesForChild("echo", ["file"], [
        t.typeName() for t in (QgsProcessingOutputFile, QgsProcessingOutputRasterLayer,
                               QgsProcessingOutputVectorLayer, QgsProcessingOutputMapLayer)], [])
    assert _NOT_CLOUDS | {("smrf", "OUTPUT")} <= _child_outputs(qgis_default)
    offered = pointclouds.point_cloud_sources(model, "echo")
    assert _child_outputs(offered) == {("smrf", "OUTPUT")}
    assert [s.parameterName() for s in offered if not s.outputChildId()] == ["cloud"]
    # a child never offers its own outputs nor those of children depending on it
    assert ("echo", "OUTPUT") not in _child_outputs(pointclouds.point_cloud_sources(model, "smrf"))


def _modeler_dialog_offers(model, child_id, alg_id):
    """{parameter name: [child id, output name] offered} in the modeler's own dialog (Processing's
    ModelerParametersDialog, as when a child is double-clicked)."""
    from processing.modeler.ModelerParametersDialog import ModelerParametersDialog
    from qgis.core import QgsApplication
    from qgis.PyQt.QtWidgets import QComboBox
    dialog = ModelerParametersDialog(QgsApplication.processingRegistry().algorithmById(alg_id), model, child_id)
    offers = {}
    for name, wrapper in dialog.widget.widget.wrappers.items():
        items = [combo.itemData(i) for combo in wrapper.findChildren(QComboBox) for i in range(combo.count())]
        offers[name] = {tuple(d) for d in items if isinstance(d, list) and len(d) == 2}
    dialog.deleteLater()
    return offers


def test_modeler_dialog_offers_point_clouds_only(groundsieve_provider):
    """The dialog the modeler opens for a GroundSieve child: its point-cloud inputs (INPUT, and
    INPUT_LAYER where this QGIS opens point clouds) offer the classified cloud of the previous
    child and none of _NOT_CLOUDS; another algorithm's raster input still offers the DTM (the
    widget of every other parameter is QGIS's own, untouched)."""
    model = _offers_model()
    offers = _modeler_dialog_offers(model, "echo", "groundsieve:echogrid")
    for name in ("INPUT", "INPUT_LAYER"):
        if name in offers:
            assert offers[name] == {("smrf", "OUTPUT")}, name
    assert ("smrf", "DTM") in _modeler_dialog_offers(model, "slope", "native:slope")["INPUT"]


def test_point_cloud_input_keeps_qgis_widgets_outside_the_modeler(groundsieve_provider):
    """Outside the modeler the input's widget is exactly the one QGIS gives a file parameter
    (the algorithm and batch dialogs); the parameter's type and name are unchanged, so saved
    models and qgis_process read it as before."""
    from processing.gui.wrappers import DIALOG_BATCH, DIALOG_STANDARD, WidgetWrapperFactory
    from qgis.core import QgsApplication
    from qgis.gui import QgsAbstractProcessingParameterWidgetWrapper
    from qgis.PyQt.QtWidgets import QDialog

    class AlgorithmDialog(QDialog):  # Processing tells its dialogs apart by class name
        pass

    class BatchAlgorithmDialog(QDialog):
        pass

    alg = QgsApplication.processingRegistry().algorithmById("groundsieve:smrf")
    param = alg.parameterDefinition("INPUT")
    assert (param.type(), param.name()) == ("file", "INPUT")
    assert param.metadata()["widget_wrapper"]["class"].endswith("pointclouds.PointCloudInputWidget")
    for dialog, kind in ((AlgorithmDialog(), DIALOG_STANDARD), (BatchAlgorithmDialog(), DIALOG_BATCH)):
        wrapper = WidgetWrapperFactory.create_wrapper(param, dialog)
        assert isinstance(wrapper, QgsAbstractProcessingParameterWidgetWrapper)
        assert wrapper.type() == kind and wrapper.parameterDefinition().name() == "INPUT"
        dialog.deleteLater()


def test_the_algorithm_dialog_input_picks_a_folder_or_a_file(groundsieve_provider, tmp_path, monkeypatch):
    """QGIS's file parameter picks files or folders, never both: in the algorithm dialog, the
    ground filters' and rfclassify's input has a folder button beside QGIS's own file widget.
    Picking a folder sets the parameter's value to it (and tells the dialog); cancelling the
    chooser changes nothing; a file set stays a file. Inputs that take no folder (features), and
    the batch dialog, keep QGIS's widget as it is."""
    from processing.gui.wrappers import WidgetWrapperFactory
    from qgis.core import QgsApplication, QgsProcessingContext
    from qgis.PyQt.QtWidgets import QDialog, QFileDialog, QToolButton

    class AlgorithmDialog(QDialog):
        pass

    class BatchAlgorithmDialog(QDialog):
        pass

    def folder_buttons(widget):
        return [b for b in widget.findChildren(QToolButton) if "folder of LAS/LAZ" in b.toolTip()]

    tiles = tmp_path / "tiles"
    tiles.mkdir()
    context = QgsProcessingContext()
    registry = QgsApplication.processingRegistry()
    keep = []  # the dialogs, wrappers and widgets live together, as in Processing's dialog
    for alg_id in ("groundsieve:smrf", "groundsieve:hybrid", "groundsieve:rfclassify"):
        dialog = AlgorithmDialog()
        wrapper = WidgetWrapperFactory.create_wrapper(registry.algorithmById(alg_id).parameterDefinition("INPUT"),
                                                      dialog)
        widget = wrapper.createWrappedWidget(context)
        keep.append((dialog, wrapper, widget))
        buttons = folder_buttons(widget)
        assert len(buttons) == 1, alg_id
        changes = []
        wrapper.widgetValueHasChanged.connect(lambda w, changes=changes: changes.append(w.parameterValue()))
        monkeypatch.setattr(QFileDialog, "getExistingDirectory", staticmethod(lambda *a, **k: str(tiles)))
        buttons[0].click()
        assert wrapper.parameterValue() == str(tiles) and changes[-1] == str(tiles), alg_id
        monkeypatch.setattr(QFileDialog, "getExistingDirectory", staticmethod(lambda *a, **k: ""))
        buttons[0].click()  # cancelled: the folder stays
        assert wrapper.parameterValue() == str(tiles)
        wrapper.setParameterValue(str(tmp_path / "a.laz"), context)
        assert wrapper.parameterValue() == str(tmp_path / "a.laz")
    for alg_id, dialog in (("groundsieve:features", AlgorithmDialog()), ("groundsieve:smrf", BatchAlgorithmDialog())):
        wrapper = WidgetWrapperFactory.create_wrapper(registry.algorithmById(alg_id).parameterDefinition("INPUT"),
                                                      dialog)
        widget = wrapper.createWrappedWidget(context)
        keep.append((dialog, wrapper, widget))
        assert widget is not None and folder_buttons(widget) == [], (alg_id, type(dialog).__name__)


def test_model_chains_the_classified_cloud_into_the_layer_input(groundsieve_provider, scene_laz, tmp_path):
    """Where the point-cloud-layer input exists (QGIS opens some point clouds), the modeler offers
    it the classified cloud of a previous child too: the model runs with it, the file read as is
    even where no provider of this QGIS opens a .laz as a layer."""
    import pytest
    from qgis.core import (QgsApplication, QgsProcessingContext, QgsProcessingFeedback,
                           QgsProcessingModelAlgorithm, QgsProcessingModelChildAlgorithm,
                           QgsProcessingModelChildParameterSource as Source, QgsProcessingModelOutput,
                           QgsProcessingModelParameter, QgsProcessingParameterFile)
    if QgsApplication.processingRegistry().algorithmById("groundsieve:echogrid").parameterDefinition(
            "INPUT_LAYER") is None:
        pytest.skip("this QGIS opens no point-cloud format the filters read: no layer input")
    src, scene = scene_laz
    model = QgsProcessingModelAlgorithm("layer chain", "tests")
    model.addModelParameter(QgsProcessingParameterFile("cloud", "Point cloud"), QgsProcessingModelParameter("cloud"))
    for alg_id, child_id, sources in [("groundsieve:smrf", "smrf", {"INPUT": Source.fromModelParameter("cloud")}),
                                      ("groundsieve:echogrid", "echo", {"INPUT_LAYER": Source.fromChildOutput(
                                          "smrf", "OUTPUT"), "MODE": Source.fromStaticValue(1)})]:
        child = QgsProcessingModelChildAlgorithm(alg_id)
        child.setChildId(child_id)
        for definition in QgsApplication.processingRegistry().algorithmById(alg_id).parameterDefinitions():
            if not definition.isDestination() and definition.name() not in sources:
                sources[definition.name()] = Source.fromStaticValue(definition.defaultValue())
        for name, source in sources.items():
            child.addParameterSources(name, [source])
        out = QgsProcessingModelOutput("classified")
        out.setChildId(child_id)
        out.setChildOutputName("OUTPUT")
        child.setModelOutputs({"classified": out})
        model.addChildAlgorithm(child)
    first, second = tmp_path / "smrf.laz", tmp_path / "echo.laz"
    results, ok = model.run({"cloud": str(src), "smrf:classified": str(first), "echo:classified": str(second)},
                            QgsProcessingContext(), QgsProcessingFeedback())
    assert ok
    assert (classes_of(second) == 2).sum() > 0.3 * len(scene.x)
