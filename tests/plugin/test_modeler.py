"""GroundSieve's algorithms as children of a graphical-modeler model: outputs flow from one
child to the next (classified cloud -> another filter; DTM -> a QGIS raster algorithm)."""
import numpy as np

from .conftest import classes_of


def _model():
    from qgis.core import (QgsProcessingModelAlgorithm, QgsProcessingModelChildAlgorithm,
                           QgsProcessingModelChildParameterSource as Source, QgsProcessingModelOutput,
                           QgsProcessingModelParameter, QgsProcessingParameterFile)
    model = QgsProcessingModelAlgorithm("groundsieve chain", "tests")
    model.addModelParameter(QgsProcessingParameterFile("cloud", "Point cloud"), QgsProcessingModelParameter("cloud"))

    def child(alg_id, child_id, sources, outputs):
        from qgis.core import QgsApplication
        c = QgsProcessingModelChildAlgorithm(alg_id)
        c.setChildId(child_id)
        # As the modeler's dialog does: every parameter not wired gets its default as a static value.
        for definition in QgsApplication.processingRegistry().algorithmById(alg_id).parameterDefinitions():
            if not definition.isDestination() and definition.name() not in sources:
                sources[definition.name()] = Source.fromStaticValue(definition.defaultValue())
        for name, source in sources.items():
            c.addParameterSources(name, [source])
        model_outputs = {}
        for model_name, child_output in outputs.items():
            out = QgsProcessingModelOutput(model_name)
            out.setChildId(child_id)
            out.setChildOutputName(child_output)
            model_outputs[model_name] = out
        c.setModelOutputs(model_outputs)
        model.addChildAlgorithm(c)

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
