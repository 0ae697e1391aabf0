"""Point-cloud layers and the outputs every filter offers, on the running QGIS (3.22 and 3.40 here):
the capability is read from the registered point-cloud providers (algorithms/pointclouds.py), the
classified cloud is loaded where one opens it and logged where none does, the EVC class raster
and the DTM are styled when they load. Run on 3.40 with
``env $(scripts/qgis-340 --env) GROUNDSIEVE_EXPECT_QGIS=3.40 .venv/bin/python -m pytest tests/plugin/test_layers.py``."""
import json
import os

import pytest

from .conftest import vpc_survey

FILTERS = ["smrf", "csf", "ptd", "pmf", "echogrid", "evc", "evcrasters", "hybrid"]


def _alg(name):
    from qgis.core import QgsApplication
    return QgsApplication.processingRegistry().algorithmById(f"groundsieve:{name}")


def _advanced(param):
    from qgis.core import QgsProcessingParameterDefinition as D
    return bool(param.flags() & D.Flag.FlagAdvanced)


@pytest.mark.parametrize("name", FILTERS)
def test_one_output_rule_for_every_filter(groundsieve_provider, name):
    from qgis.core import QgsProcessingParameterDefinition as D
    alg = _alg(name)
    params = alg.parameterDefinitions()
    dtm, ground = alg.parameterDefinition("DTM"), alg.parameterDefinition("GROUND_POINTS")
    assert dtm.createByDefault() and dtm.flags() & D.Flag.FlagOptional  # offered, may be skipped
    assert not ground.createByDefault() and _advanced(ground)  # 740,000 points would hide the DTM
    # The DTM's options close the inputs the dialog shows, right above the outputs it lists last.
    shown = [p.name() for p in params if not p.isDestination() and not _advanced(p)
             and not p.flags() & D.Flag.FlagHidden]
    assert shown[-3:] == ["DTM_CELL", "DTM_FILL", "DTM_CLASSES"]
    assert any(_advanced(p) for p in params if not p.isDestination())  # an Advanced section
    for extra in (p for p in params if p.isDestination() and p.name() not in ("OUTPUT", "DTM", "GROUND_POINTS")):
        assert not extra.createByDefault(), extra.name()  # intermediate rasters are opt-in


def test_capability_comes_from_the_providers(groundsieve_provider):
    from qgis.core import Qgis
    from groundsieve.algorithms import pointclouds
    patterns = pointclouds.point_cloud_patterns()
    offered = pointclouds.reads_loaded_layers()
    for name in FILTERS:
        assert (_alg(name).parameterDefinition("INPUT_LAYER") is not None) == offered
    # What the two QGIS here register (QGIS_ENV.md): 3.22 only ept; 3.40 copc, ept, vpc; neither pdal.
    assert "pdal" not in patterns and "*.json" not in str(patterns)
    if Qgis.QGIS_VERSION_INT < 32400:
        assert set(patterns) == {"ept"} and not offered
        assert pointclouds.providers_opening("/x/out.vpc") == []
    else:
        assert {"copc", "vpc"} <= set(patterns) and offered
        assert pointclouds.providers_opening("/x/OUT.VPC") == ["vpc"]
        assert pointclouds.providers_opening("/x/out.copc.laz") == ["copc"]
    assert pointclouds.providers_opening("/x/out.laz") == []
    # A build with PDAL (Windows, macOS) declares LAS/LAZ: the same code then loads .laz outputs.
    pdal = {"pdal": ["*.las", "*.laz", "*.e57"]}
    assert pointclouds.providers_opening("/x/OUT.LAZ", pdal) == ["pdal"] and pointclouds.reads_loaded_layers(pdal)
    assert not pointclouds.reads_loaded_layers({"ept": ["ept.json"]})


class _Feedback:
    def __new__(cls):
        from qgis.core import QgsProcessingFeedback

        class Feedback(QgsProcessingFeedback):
            def __init__(self):
                super().__init__()
                self.infos, self.warnings = [], []

            def pushInfo(self, info):  # noqa: N802
                self.infos.append(info)
                super().pushInfo(info)

            def pushWarning(self, warning):  # noqa: N802
                self.warnings.append(warning)
                super().pushWarning(warning)
        return Feedback()


def _context():
    from qgis.core import QgsProcessingContext, QgsProject
    context = QgsProcessingContext()
    context.setProject(QgsProject.instance())
    return context


def test_classified_laz_is_logged_where_no_provider_opens_it(groundsieve_provider, scene_laz, tmp_path):
    import processing
    src, _scene = scene_laz
    out = tmp_path / "classified.laz"
    context, feedback = _context(), _Feedback()
    processing.run("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": str(out)}, context=context, feedback=feedback)
    assert out.exists()
    assert not context.willLoadLayerOnCompletion(str(out))
    said = [i for i in feedback.infos if str(out) in i and "Not loaded" in i]
    assert len(said) == 1 and "no point-cloud provider that opens .laz files" in said[0]
    assert not [w for w in feedback.warnings if "temporary" in w]  # a file the user named stays


def test_a_temporary_classified_cloud_not_loaded_is_said_to_be_deleted_at_exit(groundsieve_provider, scene_laz):
    """The dialog's default "[Save to temporary file]" where no provider opens .laz (no PDAL, both
    QGIS here): the cloud is written to Processing's temporary folder, which QGIS deletes when it
    closes; the log warns so, and says how to keep it."""
    import processing
    from qgis.core import QgsProcessing, QgsProcessingOutputLayerDefinition
    src, _scene = scene_laz
    context, feedback = _context(), _Feedback()
    dialog_value = QgsProcessingOutputLayerDefinition(QgsProcessing.TEMPORARY_OUTPUT, context.project())
    result = processing.run("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": dialog_value, "DTM": None},
                            context=context, feedback=feedback)
    out = result["OUTPUT"]
    assert out.endswith(".laz") and os.path.isfile(out) and not context.willLoadLayerOnCompletion(out)
    warned = [w for w in feedback.warnings if out in w]
    assert len(warned) == 1, feedback.warnings
    assert "temporary file" in warned[0] and "deletes it when it closes" in warned[0]
    assert "give the output a file name" in warned[0]


def test_temporary_warning_follows_the_output_value(groundsieve_provider, tmp_path):
    """Which runs are warned: the temporary outputs (the dialog's, qgis_process's TEMPORARY_OUTPUT),
    not a named file, nor a model's intermediate step (QGIS loads none of those)."""
    from qgis.core import QgsProcessing, QgsProcessingOutputLayerDefinition, QgsProcessingUtils
    from groundsieve.algorithms import pointclouds
    temp = QgsProcessingUtils.generateTempFilename("OUTPUT.laz")
    named = str(tmp_path / "kept.laz")

    def warnings(path, value):
        feedback = _Feedback()
        assert pointclouds.load_or_log(_context(), feedback, path, "Classified point cloud", "OUTPUT", value) is None
        return feedback.warnings

    assert len(warnings(temp, QgsProcessingOutputLayerDefinition(QgsProcessing.TEMPORARY_OUTPUT))) == 1
    assert len(warnings(temp, QgsProcessing.TEMPORARY_OUTPUT)) == 1  # qgis_process
    assert warnings(named, named) == [] and warnings(named, QgsProcessingOutputLayerDefinition(named)) == []
    assert warnings(temp, temp) == []  # a model's intermediate step: not loaded by design, nothing to keep


def _load_results(alg_id, context, feedback):
    """What the dialog does when the run ends: load the layers to load and run their post-processors."""
    from processing.gui.Postprocessing import handleAlgorithmResults
    from qgis.core import QgsApplication
    assert handleAlgorithmResults(QgsApplication.processingRegistry().algorithmById(alg_id), context, feedback)


def _project_layer(path):
    from qgis.core import QgsProject
    found = [lay for lay in QgsProject.instance().mapLayers().values() if lay.source().split("|")[0] == str(path)]
    assert len(found) == 1, [lay.source() for lay in QgsProject.instance().mapLayers().values()]
    return found[0]


def test_evc_class_raster_and_dtm_load_styled(groundsieve_provider, scene_laz, tmp_path):
    import processing
    from qgis.core import QgsProcessingOutputLayerDefinition, QgsProject
    src, _scene = scene_laz
    classes, dtm, evc = tmp_path / "classes.tif", tmp_path / "dtm.tif", tmp_path / "evc_values.tif"
    context, feedback = _context(), _Feedback()
    # As the dialog passes outputs with "Open output file after running" ticked.
    params = {"INPUT": str(src), "OUTPUT": str(tmp_path / "c.laz"), "SMALL_SCALE": 0.5, "LARGE_SCALE": 4.0,
              "THRESHOLD": 1.7,
              "CLASS_RASTER": QgsProcessingOutputLayerDefinition(str(classes), QgsProject.instance()),
              "EVC_RASTER": QgsProcessingOutputLayerDefinition(str(evc), QgsProject.instance()),
              "DTM": QgsProcessingOutputLayerDefinition(str(dtm), QgsProject.instance())}
    processing.run("groundsieve:evcrasters", params, context=context, feedback=feedback)
    assert not (tmp_path / "evc.tif").exists() and len(list(tmp_path.glob("*.tif"))) == 3  # only what was asked
    _load_results("groundsieve:evcrasters", context, feedback)
    try:
        layer = _project_layer(classes)
        assert layer.renderer().type() == "paletted"
        legend = layer.renderer().legendSymbologyItems()
        assert [label for label, _colour in legend] == ["Ground", "Vegetation area", "Vegetation boundary"]
        assert len({colour.name() for _label, colour in legend}) == 3
        assert [c.value for c in layer.renderer().classes()] == [1, 2, 3]
        # the EVC values in the three intervals of the classes, split at 0 and at this run's threshold
        values = _project_layer(evc)
        assert values.renderer().type() == "singlebandpseudocolor"
        items = values.renderer().shader().rasterShaderFunction().colorRampItemList()
        assert [i.value for i in items] == [0.0, 1.7, float("inf")]
        assert [i.label for i in items] == ["EVC <= 0: vegetation area", "0 < EVC <= 1.7: ground",
                                            "EVC > 1.7: vegetation boundary"]
        assert [i.color.name() for i in items] == ["#1a7f2e", "#b07d3c", "#9bd35a"]  # the class raster's
        dtm_layer = _project_layer(dtm)
        assert dtm_layer.renderer().type() == "singlebandpseudocolor"
        shader = dtm_layer.renderer().shader().rasterShaderFunction()
        stats = dtm_layer.dataProvider().bandStatistics(1)
        assert shader.minimumValue() == pytest.approx(stats.minimumValue)
        assert shader.maximumValue() == pytest.approx(stats.maximumValue)
    finally:
        QgsProject.instance().removeAllMapLayers()


def test_every_run_of_a_session_loads_its_dtm_styled(groundsieve_provider, scene_laz, tmp_path):
    """QGIS takes the ownership of a layer post-processor and deletes it once its layer is loaded:
    the second run of a desktop session that loads a DTM once failed ('wrapped C/C++ object of type
    _Styler has been deleted') after writing its outputs. Three runs in one session, each with its
    own context as the dialog makes them, the last of rfclassify: each DTM loads styled."""
    import gc

    import processing
    from qgis.core import QgsProcessingOutputLayerDefinition, QgsProject
    src, _scene = scene_laz
    model = tmp_path / "model.npz"
    processing.run("groundsieve:rftrain", {"INPUT": str(src), "MODEL": str(model), "TREES": 4,
                                           "REPORT": str(tmp_path / "r.html")}, feedback=_Feedback())
    try:
        for k, (alg_id, extra) in enumerate([("groundsieve:smrf", {}), ("groundsieve:smrf", {}),
                                             ("groundsieve:rfclassify", {"MODEL": str(model)})]):
            dtm = tmp_path / f"dtm{k}.tif"
            context, feedback = _context(), _Feedback()
            processing.run(alg_id, {"INPUT": str(src), "OUTPUT": str(tmp_path / f"c{k}.laz"), **extra,
                                    "DTM": QgsProcessingOutputLayerDefinition(str(dtm), QgsProject.instance())},
                           context=context, feedback=feedback)
            _load_results(alg_id, context, feedback)
            assert _project_layer(dtm).renderer().type() == "singlebandpseudocolor", (k, alg_id)
            del context
            gc.collect()
    finally:
        QgsProject.instance().removeAllMapLayers()


def test_vpc_output_loads_and_a_loaded_layer_is_an_input(groundsieve_provider, scene_laz, tmp_path):
    """Where a provider opens .vpc (QGIS >= 3.32: 3.40 here), the survey's .vpc comes back as a
    point-cloud layer, and that loaded layer can be the next run's input."""
    import processing
    from qgis.core import QgsPointCloudLayer, QgsProject
    from groundsieve.algorithms import pointclouds
    folder, out = vpc_survey(scene_laz, tmp_path, "classified.vpc")
    context, feedback = _context(), _Feedback()
    processing.run("groundsieve:smrf", {"INPUT": str(folder), "OUTPUT": str(out), "TILE_SIZE": 50.0},
                   context=context, feedback=feedback)
    assert context.willLoadLayerOnCompletion(str(out))
    assert not [i for i in feedback.infos if "Not loaded" in i]
    # its LAZ files draw only where a provider opens LAZ (PDAL): not in Debian's builds, and the log says so
    extents_only = [i for i in feedback.infos if str(out) in i and "the files' extents only" in i]
    assert len(extents_only) == (0 if pointclouds.providers_opening("x.laz") else 1), feedback.infos
    if extents_only:
        assert "opens its .laz files" in extents_only[0]
    _load_results("groundsieve:smrf", context, feedback)
    try:
        layer = _project_layer(out)
        assert isinstance(layer, QgsPointCloudLayer) and layer.isValid() and layer.providerType() == "vpc"
        again = tmp_path / "again.vpc"
        result = processing.run("groundsieve:echogrid", {"INPUT_LAYER": layer.id(), "OUTPUT": str(again)},
                                context=_context(), feedback=_Feedback())
        assert result["POINT_COUNT"] == sum(f["properties"]["pc:count"]
                                            for f in json.loads(out.read_text())["features"])
        assert len(json.loads(again.read_text())["features"]) == 2
    finally:
        QgsProject.instance().removeAllMapLayers()


def test_no_input_at_all_is_refused_by_its_label(groundsieve_provider, tmp_path):
    """The file input is optional only where a loaded layer may replace it; given neither, the
    run is refused by the labels of both."""
    import processing
    from qgis.core import QgsProcessingException, QgsProcessingParameterDefinition as D
    optional = bool(_alg("smrf").parameterDefinition("INPUT").flags() & D.Flag.FlagOptional)
    assert optional == (_alg("smrf").parameterDefinition("INPUT_LAYER") is not None)
    if not optional:
        pytest.skip("INPUT is mandatory on this QGIS (no loaded point-cloud layer to replace it)")
    with pytest.raises(QgsProcessingException) as err:
        processing.run("groundsieve:smrf", {"OUTPUT": str(tmp_path / "c.laz")})
    assert "Input point cloud" in str(err.value) and "or a loaded point-cloud layer" in str(err.value)


def test_loaded_vpc_has_the_survey_extent(groundsieve_provider, scene_laz, tmp_path):
    import math
    from qgis.core import QgsPointCloudLayer
    from groundsieve.algorithms import pointclouds
    from groundsieve.core.io.lasfiles import scan_header, write_vpc
    from groundsieve.core.raster.crs import lonlat_box
    from .test_survey_inputs import _split
    if not pointclouds.providers_opening("x.vpc"):
        pytest.skip("this QGIS has no point-cloud provider for .vpc (QGIS < 3.32)")
    src, _scene = scene_laz
    files = _split(src, tmp_path / "in")
    vpc = tmp_path / "in" / "survey.vpc"
    write_vpc(str(vpc), [scan_header(f) for f in files], files, lonlat=lonlat_box)  # as the engine writes it
    extent = QgsPointCloudLayer(str(vpc), "survey", "vpc").extent()
    assert math.isfinite(extent.xMinimum()) and math.isfinite(extent.yMaximum())
    infos = [scan_header(f) for f in files]
    native = (min(i.mins[0] for i in infos), min(i.mins[1] for i in infos),
              max(i.maxs[0] for i in infos), max(i.maxs[1] for i in infos))
    got = (extent.xMinimum(), extent.yMinimum(), extent.xMaximum(), extent.yMaximum())
    assert all(abs(a - b) < 1.0 for a, b in zip(got, native)), (got, native)


def test_a_loaded_copc_layer_is_an_input_read_by_bounds(groundsieve_provider, scene_laz, tmp_path):
    """Where a provider opens COPC (3.40's ``copc``), a loaded COPC layer is the input of a tiled
    run: its tiles read it by bounds (no binning), with the classes of the same run on the file."""
    import laspy
    import numpy as np
    import processing
    from qgis.core import QgsPointCloudLayer, QgsProject
    from groundsieve.algorithms import pointclouds
    if not pointclouds.providers_opening("x.copc.laz"):
        pytest.skip("this QGIS has no point-cloud provider for COPC (QGIS < 3.26)")
    from groundsieve.tests.core.test_copc import scene_las, write_copc
    _src, scene = scene_laz
    copc = tmp_path / "scene.copc.laz"
    write_copc(copc, scene_las(scene))
    layer = QgsPointCloudLayer(str(copc), "scene", "copc")
    assert layer.isValid() and layer.providerType() == "copc"
    QgsProject.instance().addMapLayer(layer)
    try:
        params = {"TILE_SIZE": 50.0}
        feedback = _Feedback()
        processing.run("groundsieve:smrf", {"INPUT_LAYER": layer.id(), "OUTPUT": str(tmp_path / "a.laz"), **params},
                       context=_context(), feedback=feedback)
        processing.run("groundsieve:smrf", {"INPUT": str(copc), "OUTPUT": str(tmp_path / "b.laz"), **params},
                       context=_context(), feedback=_Feedback())
    finally:
        QgsProject.instance().removeAllMapLayers()
    assert any("COPC file(s) read by bounds" in line for line in feedback.infos), feedback.infos
    a, b = laspy.read(tmp_path / "a.laz"), laspy.read(tmp_path / "b.laz")
    assert len(a.points) == len(scene.x) and np.array_equal(a.classification, b.classification)
    assert 0.3 < np.mean(a.classification == 2) < 0.95


def test_temporary_layer_outputs_load_without_a_false_error(groundsieve_provider, scene_laz, tmp_path):
    """The dialog's temporary 'Ground points' and accuracy 'Checkpoints with their dz' layers: the check of
    their folder before the run (parameterAsOutputLayer) registered a second layer to load, 'memory:<label>',
    which no run made, and every successful run ended in red with "The following layers were not correctly
    generated" (a QGIS plugin reviewer). What the dialog loads at the end is all there now."""
    import gc

    from qgis.core import (QgsApplication, QgsProcessing, QgsProcessingOutputLayerDefinition, QgsProcessingUtils,
                           QgsProject)
    src, _scene = scene_laz
    dtm = tmp_path / "dtm.tif"
    try:
        for alg_id, params, sink in (
                ("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": str(tmp_path / "c.laz"), "DTM": str(dtm)},
                 "GROUND_POINTS"),
                ("groundsieve:accuracy", {"DTM": str(dtm), "CHECKPOINTS": None, "OUTPUT_HTML": str(tmp_path / "r.html")},
                 "OUTPUT")):
            if params.get("CHECKPOINTS", 1) is None:
                from osgeo import gdal
                ds = gdal.Open(str(dtm))
                x0, cell, _r, top, _r2, _c = ds.GetGeoTransform()
                values = ds.GetRasterBand(1).ReadAsArray()
                del ds
                rows = [(x0 + (c + 0.5) * cell, top - (r + 0.5) * cell, values[r, c] + 0.02)
                        for r in range(5, 50, 9) for c in range(5, 50, 9)] + [(x0 - 500.0, top + 500.0, 100.0)]
                checkpoints = tmp_path / "cp.txt"
                checkpoints.write_text("".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in rows))
                params["CHECKPOINTS"] = str(checkpoints)
            context, feedback = _context(), _Feedback()
            params[sink] = QgsProcessingOutputLayerDefinition(QgsProcessing.TEMPORARY_OUTPUT, context.project())
            # (as the dialog runs it: processing.run takes the result layers out of the context)
            alg = QgsApplication.processingRegistry().createAlgorithmById(alg_id)
            result, ok = alg.run(params, context, feedback)
            assert ok, alg_id
            keys = list(context.layersToLoadOnCompletion().keys())
            assert keys, alg_id
            missing = [k for k in keys if QgsProcessingUtils.mapLayerFromString(k, context) is None]
            assert missing == [], (alg_id, missing, result)
            _load_results(alg_id, context, feedback)
            if alg_id == "groundsieve:accuracy":  # loaded coloured by dz (it had a plain symbol of a random colour)
                [layer] = QgsProject.instance().mapLayersByName("Checkpoints with their dz")
                renderer = layer.renderer()
                assert renderer.type() == "RuleRenderer"
                rules = renderer.rootRule().children()
                assert len(rules) == 7 and rules[-1].filterExpression() == '"dz" IS NULL'
                assert f'"dz" >= {result["RMSEZ"]!r}' in rules[4].filterExpression()
                # every checkpoint is drawn, the skipped ones (no dz) too: each falls in exactly one rule
                from qgis.core import QgsRenderContext
                context_r = QgsRenderContext()
                renderer.startRender(context_r, layer.fields())
                drawn = [len(renderer.symbolsForFeature(f, context_r)) for f in layer.getFeatures()]
                renderer.stopRender(context_r)
                assert drawn and set(drawn) == {1}
                assert [f["sampling"] for f in layer.getFeatures()].count("outside") == 1  # (drawn grey)
                del layer, renderer, rules
            del context
            gc.collect()
    finally:
        QgsProject.instance().removeAllMapLayers()
