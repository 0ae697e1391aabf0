"""groundsieve:tune through processing.run (as the toolbox calls it), and the PRESET helpers of
algorithms/presets.py on a filter algorithm (the lead wires them into algorithms/base.py)."""
import json
import os

import pytest


@pytest.fixture(scope="module")
def patch(tmp_path_factory):
    """A small labelled LAZ (ground = class 2)."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, scene_crs_wkt, write_scene
    path = tmp_path_factory.mktemp("tune") / "patch.laz"
    write_scene(make_scene(SceneSpec(size_m=50.0, density_per_m2=2.0, seed=11)), str(path), crs_wkt=scene_crs_wkt())
    return str(path)


def test_tune_writes_the_preset_and_a_report_for_the_results_viewer(groundsieve_provider, patch, tmp_path):
    import processing
    from qgis.core import QgsApplication

    algorithm = QgsApplication.processingRegistry().algorithmById("groundsieve:tune")
    assert algorithm.outputDefinition("OUTPUT_HTML").type() == "outputHtml"  # opens in the results viewer
    preset, report = str(tmp_path / "p.json"), str(tmp_path / "r.html")
    result = processing.run("groundsieve:tune", {"INPUT": patch, "FILTER": 0, "METRIC": 1, "BUDGET": 4,
                                                 "BLOCKS": 2, "OUTPUT_PRESET": preset, "OUTPUT_HTML": report})
    assert result["OUTPUT_PRESET"] == preset and result["OUTPUT_HTML"] == report
    data = json.load(open(preset, encoding="utf-8"))
    assert data["filter"] == "smrf" and data["source"]["metric"] == "kappa"
    assert abs(data["source"]["cv_kappa"] - result["CV_KAPPA"]) < 1e-5
    assert "<svg" in open(report, encoding="utf-8").read()


def test_tune_refuses_a_patch_without_non_ground_naming_it(groundsieve_provider, tmp_path):
    import processing
    from qgis.core import QgsProcessingException
    path = tmp_path / "flat.txt"
    path.write_text("".join(f"{i % 30} {i // 30} 100 0\n" for i in range(900)))
    with pytest.raises(QgsProcessingException, match=r"flat\.txt: the tuning patch holds no non-ground points"):
        processing.run("groundsieve:tune", {"INPUT": str(path), "FILTER": 0, "BUDGET": 4,
                                            "OUTPUT_PRESET": str(tmp_path / "p.json"),
                                            "OUTPUT_HTML": str(tmp_path / "r.html")})
    assert not os.path.exists(tmp_path / "p.json")


def test_preset_helpers_on_a_filter_algorithm(groundsieve_provider, tmp_path):
    from qgis.core import QgsProcessingContext

    from groundsieve.algorithms import presets
    from groundsieve.algorithms.smrf import SMRFAlgorithm
    from groundsieve.core.engine.presets import PresetError, write_preset
    from groundsieve.core.filters.smrf import SMRF

    class WithPreset(SMRFAlgorithm):  # what base.py does once wired
        def initFilterParameters(self):  # noqa: N802
            super().initFilterParameters()
            presets.add_preset_parameter(self)

        def buildFilter(self, parameters, context):  # noqa: N802
            return presets.build_filter(self, parameters, context)

    algorithm = WithPreset()
    algorithm.initAlgorithm()
    assert algorithm.parameterDefinition("PRESET").flags() & algorithm.parameterDefinition("PRESET").FlagOptional
    context = QgsProcessingContext()
    path = str(tmp_path / "smrf.json")
    write_preset(path, "smrf", {"slope": 0.2, "window_m": 16.0, "elevation_threshold_m": 0.45})
    dialog = {"CELL": 1.0, "SLOPE": 0.15, "WINDOW": 18.0, "THRESHOLD": 0.5, "SCALAR": 1.25, "LOW_OUTLIER_FILL": True}
    assert algorithm.buildFilter(dialog, context) == SMRF()
    assert algorithm.buildFilter(dict(dialog, PRESET=path), context) == \
        SMRF(slope=0.2, window_m=16.0, elevation_threshold_m=0.45)
    assert algorithm.buildFilter(dict(dialog, PRESET=path, SCALAR=2.0), context) == \
        SMRF(slope=0.2, window_m=16.0, elevation_threshold_m=0.45, elevation_scalar=2.0)
    other = str(tmp_path / "pmf.json")
    write_preset(other, "pmf", {"slope": 0.5})
    with pytest.raises(PresetError, match=r"pmf\.json: a preset for PMF \(pmf\), not for SMRF"):
        algorithm.buildFilter(dict(dialog, PRESET=other), context)
