"""groundsieve:tune through processing.run (as the toolbox calls it), and the PRESET input of every
ground filter of the parameter table (algorithms/presets.py, wired in algorithms/base.py)."""
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
    assert 0.5 < result["CV_F1"] <= 1.0  # the third metric is returned too (only two were)
    assert "<svg" in open(report, encoding="utf-8").read()
    assert data["source"]["selection"] == "best"


def test_tune_chooses_by_the_one_standard_error_rule_when_asked(groundsieve_provider, patch, tmp_path):
    import processing
    preset, report = str(tmp_path / "p.json"), str(tmp_path / "r.html")
    processing.run("groundsieve:tune", {"INPUT": patch, "FILTER": 0, "BUDGET": 4, "BLOCKS": 4, "SELECTION": 1,
                                        "OUTPUT_PRESET": preset, "OUTPUT_HTML": report})
    assert json.load(open(preset, encoding="utf-8"))["source"]["selection"] == "one-se"
    assert "one-standard-error rule" in open(report, encoding="utf-8").read()


def test_tune_refuses_a_preset_name_the_filters_cannot_take_before_the_search(groundsieve_provider, patch, tmp_path):
    """p.txt was written after the search, then refused by every filter's PRESET (a modeler reviewer)."""
    import processing
    from qgis.core import QgsProcessingException
    with pytest.raises(QgsProcessingException, match=r"p\.txt: the preset must end in \.json"):
        processing.run("groundsieve:tune", {"INPUT": patch, "FILTER": 0, "BUDGET": 4, "BLOCKS": 2,
                                            "OUTPUT_PRESET": str(tmp_path / "p.txt"),
                                            "OUTPUT_HTML": str(tmp_path / "r.html")})
    assert os.listdir(tmp_path) == []


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


def test_every_table_filter_takes_a_preset_and_the_dialog_values_set_win(groundsieve_provider, tmp_path):
    from qgis.core import QgsApplication, QgsProcessingContext

    from groundsieve.core.engine.presets import PresetError, write_preset
    from groundsieve.core.filters.evc import EVC
    from groundsieve.core.filters.smrf import SMRF

    registry = QgsApplication.processingRegistry()
    for name in ("smrf", "pmf", "csf", "ptd", "echogrid", "evc", "evcrasters"):
        preset = registry.algorithmById(f"groundsieve:{name}").parameterDefinition("PRESET")
        assert preset is not None and preset.flags() & preset.FlagOptional, name
    assert registry.algorithmById("groundsieve:hybrid").parameterDefinition("PRESET") is None  # not a table filter

    algorithm = registry.algorithmById("groundsieve:smrf").create()
    context = QgsProcessingContext()
    path = str(tmp_path / "smrf.json")
    write_preset(path, "smrf", {"slope": 0.2, "window_m": 16.0, "elevation_threshold_m": 0.45})
    # the dialog (and a model's step, the batch dialog) gives every parameter, at its default when untouched
    dialog = {d.name(): d.defaultValue() for d in algorithm.parameterDefinitions()}
    dialog.update({"CELL": 1.0, "SLOPE": 0.15, "WINDOW": 18.0, "THRESHOLD": 0.5, "SCALAR": 1.25, "LOW_OUTLIER_FILL": True})
    assert algorithm.buildFilter(dialog, context) == SMRF()
    assert algorithm.buildFilter(dict(dialog, PRESET=path), context) == \
        SMRF(slope=0.2, window_m=16.0, elevation_threshold_m=0.45)
    assert algorithm.buildFilter(dict(dialog, PRESET=path, SCALAR=2.0), context) == \
        SMRF(slope=0.2, window_m=16.0, elevation_threshold_m=0.45, elevation_scalar=2.0)
    # what the user set is noted (in the cloud's CRS unit; the preset's values and the defaults are metres)
    from groundsieve.core.engine.parameters import user_set
    assert user_set(algorithm.buildFilter(dict(dialog, PRESET=path, SCALAR=2.0), context)) == {"elevation_scalar"}
    # and the DTM cell: set in a filled dialog when not the default, in typed parameters when given at all
    from groundsieve.algorithms.base import dtm_cell_set
    assert not dtm_cell_set(algorithm, dict(dialog, DTM_CELL=1.0), context, "DTM_CELL")
    assert dtm_cell_set(algorithm, dict(dialog, DTM_CELL=2.0), context, "DTM_CELL")
    assert dtm_cell_set(algorithm, {"INPUT": "a.laz", "DTM_CELL": 1.0}, context, "DTM_CELL")
    assert not dtm_cell_set(algorithm, {"INPUT": "a.laz"}, context, "DTM_CELL")
    lines = []
    algorithm.buildFilter(dict(dialog, PRESET=path, SCALAR=2.0, THRESHOLD=0.3), context, lines.append)
    assert lines == ["SMRF parameters: CELL 1 m, SLOPE 0.2, WINDOW 16 m, THRESHOLD 0.3 m, SCALAR 2, "
                     "LOW_OUTLIER_FILL True, LOW_OUTLIER_SLOPE 5, LOW_OUTLIER_MAX_SHARE 0.05",
                     "From the preset smrf.json: SLOPE 0.2, WINDOW 16 m; changed from the preset: THRESHOLD 0.3 m "
                     "(a value equal to the filter's default never replaces the preset's)"]
    # a model saved before LOW_OUTLIER_SLOPE was a parameter lacks it and is still filled by QGIS: the
    # preset's values stay (under qgis_process they were all taken for typed: a reviewer's old model)
    old_model = {k: v for k, v in dialog.items() if k != "LOW_OUTLIER_SLOPE"}
    assert algorithm.buildFilter(dict(old_model, PRESET=path), context) == \
        SMRF(slope=0.2, window_m=16.0, elevation_threshold_m=0.45)
    # a script's processing.run dict holds what it gives: a default given there wins, as on qgis_process
    script = {"INPUT": "a.laz", "OUTPUT": "b.laz", "PRESET": path, "THRESHOLD": 0.5}
    assert algorithm.buildFilter(script, context) == SMRF(slope=0.2, window_m=16.0, elevation_threshold_m=0.5)
    other = str(tmp_path / "pmf.json")
    write_preset(other, "pmf", {"slope": 0.5})
    with pytest.raises(PresetError, match=r"pmf\.json: a preset for PMF \(pmf\), not for SMRF"):
        algorithm.buildFilter(dict(dialog, PRESET=other), context)

    # EVC completes its arguments after the preset: a dialog radius above the preset's maximum grows it
    evc = registry.algorithmById("groundsieve:evc").create()
    evc_preset = str(tmp_path / "evc.json")
    write_preset(evc_preset, "evc", {"radius": 2, "max_radius": 3, "threshold": 1.2})
    built = evc.buildFilter({"PRESET": evc_preset, "RADIUS": 4}, context)
    assert isinstance(built, EVC) and (built.radius, built.max_radius, built.threshold) == (4, 4, 1.2)


def test_a_shipped_preset_runs_through_processing_and_a_foreign_one_is_refused(groundsieve_provider, patch,
                                                                             tmp_path):
    import laspy
    import numpy as np
    import processing
    from qgis.core import QgsApplication, QgsProcessingContext, QgsProcessingException

    from groundsieve.algorithms.presets import shipped_folder
    from groundsieve.core.engine.presets import load_preset, write_preset

    forest = os.path.join(shipped_folder(), "forest-smrf.json")
    values = load_preset(forest, "smrf").values
    by_preset, by_hand = str(tmp_path / "preset.laz"), str(tmp_path / "hand.laz")
    processing.run("groundsieve:smrf", {"INPUT": patch, "PRESET": forest, "OUTPUT": by_preset})
    from groundsieve.core.engine import parameters as table
    hand = {p.name: values[p.field] for p in table.params("smrf") if p.field in values}
    processing.run("groundsieve:smrf", dict(hand, INPUT=patch, OUTPUT=by_hand))
    a, b = laspy.read(by_preset).classification, laspy.read(by_hand).classification
    assert np.array_equal(np.asarray(a), np.asarray(b))
    default = str(tmp_path / "default.laz")
    processing.run("groundsieve:smrf", {"INPUT": patch, "OUTPUT": default})
    assert not np.array_equal(np.asarray(a), np.asarray(laspy.read(default).classification))  # the preset acts
    by_name = str(tmp_path / "by-name.laz")  # a shipped preset by its name, as on the command line
    processing.run("groundsieve:smrf", {"INPUT": patch, "PRESET": "forest-smrf.json", "OUTPUT": by_name})
    assert np.array_equal(np.asarray(laspy.read(by_name).classification), np.asarray(a))
    with pytest.raises(QgsProcessingException, match=r"forest-smrff.json does not exist or is not a file \(the shipped "
                                                     r"presets, which can be given by name: forest-smrf.json, "):
        processing.run("groundsieve:smrf", {"INPUT": patch, "PRESET": "forest-smrff.json", "OUTPUT": by_name})
    algorithm = QgsApplication.processingRegistry().algorithmById("groundsieve:smrf")
    ok, message = algorithm.checkParameterValues({"INPUT": patch, "PRESET": "forest-smrf", "OUTPUT": by_name},
                                                 QgsProcessingContext())
    assert not ok and message.endswith("give the shipped preset's name with .json: forest-smrf.json")
    # tune's starting preset takes a shipped name the same way (it was refused as 'not a file')
    tune = QgsApplication.processingRegistry().algorithmById("groundsieve:tune")
    common = {"INPUT": patch, "OUTPUT_PRESET": str(tmp_path / "t.json"), "OUTPUT_HTML": str(tmp_path / "t.html")}
    assert tune.checkParameterValues(dict(common, START_PRESET="uav-lidar-smrf.json"), QgsProcessingContext())[0]
    ok, message = tune.checkParameterValues(dict(common, START_PRESET="uav-lidar-smrf"), QgsProcessingContext())
    assert not ok and message.endswith("give the shipped preset's name with .json: uav-lidar-smrf.json")

    pmf = str(tmp_path / "for-pmf.json")
    write_preset(pmf, "pmf", {"slope": 0.5})
    out = str(tmp_path / "refused.laz")
    with pytest.raises(QgsProcessingException, match=r"for-pmf\.json: a preset for PMF"):
        processing.run("groundsieve:csf", {"INPUT": patch, "PRESET": pmf, "OUTPUT": out})
    assert not os.path.exists(out)


def test_the_dialog_defaults_are_the_core_defaults(groundsieve_provider):
    """The dialog's defaults are written out (the plugin loads without the core's packages); they
    must stay those of core.engine.tune.TuneOptions."""
    from qgis.core import QgsApplication

    from groundsieve.core.engine.tune import TuneOptions
    algorithm = QgsApplication.processingRegistry().algorithmById("groundsieve:tune")
    assert algorithm.parameterDefinition("BLOCKS").defaultValue() == TuneOptions.blocks
    assert algorithm.parameterDefinition("BUDGET").defaultValue() == TuneOptions.budget
    assert algorithm.parameterDefinition("SECONDS").defaultValue() == TuneOptions.seconds
    from groundsieve.algorithms import tune as dialog
    from groundsieve.core.engine import tune as core
    assert dialog.SELECTIONS == core.SELECTIONS and dialog.METRICS == core.METRICS
    assert dialog.SELECTIONS[algorithm.parameterDefinition("SELECTION").defaultValue()] == TuneOptions.selection


def test_the_dialog_and_the_core_agree_on_which_names_are_shipped_presets(groundsieve_provider, tmp_path,
                                                                          monkeypatch):
    """The dialog checks a PRESET name without the core (algorithms/presets.shipped_preset_problem); the
    core resolves it (core/engine/presets.shipped_path, load_preset). A name the dialog passes must load,
    and a name ending in .json (any case) that the core resolves must pass the dialog."""
    from groundsieve.algorithms.presets import shipped_folder, shipped_names, shipped_preset_problem
    from groundsieve.core.engine.presets import SHIPPED_DIR, PresetError, load_preset, shipped_path

    assert os.path.samefile(shipped_folder(), SHIPPED_DIR)
    names = shipped_names()
    assert names == sorted(f[:-5] for f in os.listdir(SHIPPED_DIR) if f.endswith(".json")) and names
    monkeypatch.chdir(tmp_path)  # no file of these names in the working folder
    candidates = []
    for name in names:
        candidates += [name, name + ".json", name + ".JSON", name.upper() + ".json", name + ".json.json",
                       "presets/" + name + ".json", name + " .json", name[:-1] + ".json"]
    for value in candidates:
        dialog_ok = shipped_preset_problem("Preset", value) is None
        try:
            load_preset(value)
            core_ok = True
        except PresetError:
            core_ok = False
        if dialog_ok:
            assert core_ok, value
        if value.lower().endswith(".json") and "/" not in value:
            assert dialog_ok == (shipped_path(value) is not None) == core_ok, value
    assert sum(shipped_preset_problem("Preset", v) is None for v in candidates) == len(names)


def test_in_qgis_process_a_typed_value_equal_to_the_default_wins_over_the_preset(patch, tmp_path):
    """qgis_process passes only the parameters typed on its command line: a forester's --THRESHOLD=0.5
    (SMRF's default) against the forest preset's 0.1 was shown in the inputs and silently dropped.
    There a given value now wins, as on GroundSieve's own command line (the dialog cannot tell a
    typed default from an untouched one, so its rule is unchanged: the test above)."""
    import subprocess
    from pathlib import Path
    wrapper = str(Path(__file__).resolve().parents[2] / "scripts" / "qgis-process")
    runs = {}
    for name, extra in (("typed", ["--THRESHOLD=0.5"]), ("untyped", [])):
        proc = subprocess.run([wrapper, "run", "groundsieve:smrf", f"--INPUT={patch}", "--PRESET=forest-smrf.json",
                               f"--OUTPUT={tmp_path / (name + '.laz')}", *extra], capture_output=True, text=True,
                              timeout=600)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        runs[name] = next(line for line in proc.stdout.splitlines() if line.startswith("SMRF parameters:"))
    assert "THRESHOLD 0.5 m" in runs["typed"] and "THRESHOLD 0.1 m" in runs["untyped"], runs


def test_in_qgis_process_a_models_step_keeps_the_preset(groundsieve_provider, patch, tmp_path):
    """A model's step holds every parameter (the modeler fills them all, as a dialog does): run by
    qgis_process it must keep the dialog's rule, not take each default for a typed value and drop
    the preset (a reviewer: forest-smrf's THRESHOLD 0.1 replaced by 0.5 in a model run by qgis_process)."""
    import subprocess
    from pathlib import Path

    from qgis.core import (QgsProcessingModelAlgorithm, QgsProcessingModelChildParameterSource as Source,
                           QgsProcessingModelParameter, QgsProcessingParameterFile)
    from groundsieve.tests.plugin.conftest import add_child
    model = QgsProcessingModelAlgorithm("preset model", "tests")
    model.addModelParameter(QgsProcessingParameterFile("cloud", "Point cloud"), QgsProcessingModelParameter("cloud"))
    add_child(model, "groundsieve:smrf", "smrf", {"INPUT": Source.fromModelParameter("cloud")},
              {"classified": "OUTPUT"}, static={"PRESET": "forest-smrf.json"})
    path = str(tmp_path / "preset.model3")
    assert model.toFile(path)
    wrapper = str(Path(__file__).resolve().parents[2] / "scripts" / "qgis-process")
    proc = subprocess.run([wrapper, "run", path, f"--cloud={patch}", f"--smrf:classified={tmp_path / 'm.laz'}"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    line = next(x for x in (proc.stdout + proc.stderr).splitlines() if "SMRF parameters:" in x)
    assert "SLOPE 0.3" in line and "THRESHOLD 0.1 m" in line, line
