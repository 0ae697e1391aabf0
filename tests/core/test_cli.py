"""The headless command (python -m groundsieve, core/engine/cli.py): the Processing parameters
under the same names, defaults and units, from one definition (core/engine/parameters.py)."""
from __future__ import annotations

import dataclasses
import io
import json
import os
import subprocess
import sys

import laspy
import numpy as np
import pytest

from groundsieve.core.engine import parameters as P
from groundsieve.core.engine.cli import build_parser, main, options_from
from groundsieve.core.engine.workflow import run_ground_filter
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene

PLUGINS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), ".build",
                       "plugins")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "scene.laz"
    write_scene(make_scene(SceneSpec(size_m=60.0, density_per_m2=2.0, seed=3)), path)
    return str(path)


def help_of(name):
    out = io.StringIO()
    sub = [a for a in build_parser()._actions if a.dest == "==SUPPRESS==" or a.choices][-1].choices[name]
    sub.print_help(out)
    return " ".join(out.getvalue().split())


@pytest.mark.parametrize("name", list(P.FILTERS))
def test_every_field_of_every_filter_is_an_option_with_its_default_and_unit(name):
    text = help_of(name)
    for p in P.params(name):
        assert p.option in text and p.title() in text
    for f in P.filter_fields(name):
        args = build_parser().parse_args([name, "--input", "x.laz", "--output", "y.laz"])
        assert getattr(args, "f_" + f.name) == f.default
    assert "--scheduler" in text and "--dtm-cell M DTM cell size (m" in text
    # the defaults build the filter's own defaults
    algorithm, _options, _dtm = options_from(build_parser().parse_args([name, "--input", "x", "--output", "y"]))
    assert algorithm == P.filter_class(name)()


def test_options_reach_the_filter_and_the_tiles():
    args = build_parser().parse_args(["smrf", "--input", "a", "--output", "b", "--cell", "0.5", "--no-low-outlier-fill",
                                      "--tile-size", "100", "--tile-buffer", "20", "--scheduler", "local:2"])
    algorithm, options, dtm = options_from(args)
    assert algorithm == SMRF(cell_size_m=0.5, low_outlier_fill=False)
    assert options.tiling.tile_size_m == 100 and options.tiling.buffer_m == 20
    assert options.tiling.scheduler == "local:2" and dtm.cell_size_m == 1.0


def test_the_command_classifies_as_the_core(scene, tmp_path):
    out = io.StringIO()
    code = main(["smrf", "--input", scene, "--output", str(tmp_path / "c.laz"), "--dtm", str(tmp_path / "d.tif"),
                 "--slope", "0.2"], out=out)
    assert code == 0, out.getvalue()
    ref = run_ground_filter(scene, str(tmp_path / "ref.laz"), SMRF(slope=0.2))
    assert np.array_equal(laspy.read(tmp_path / "c.laz").classification, laspy.read(tmp_path / "ref.laz").classification)
    assert f"{ref.ground_count:,} ground" in out.getvalue() and (tmp_path / "d.tif").exists()


def test_errors_are_one_line_without_traceback(tmp_path):
    out = io.StringIO()
    assert main(["pmf", "--input", str(tmp_path / "missing.laz"), "--output", str(tmp_path / "o.laz")], out=out) == 1
    assert "missing.laz" in out.getvalue() and "Traceback" not in out.getvalue()
    out = io.StringIO()
    assert main(["smrf", "--input", "a.laz", "--output", "o.laz", "--scheduler", "nowhere"], out=out) == 1
    assert "tcp://host:port" in out.getvalue()


def test_python_m_groundsieve_runs_without_qgis_and_without_dask(scene, tmp_path):
    probe = ("import runpy, sys; sys.argv = ['groundsieve'] + sys.argv[1:]\n"
             "try:\n    runpy.run_module('groundsieve', run_name='__main__')\n"
             "except SystemExit as e:\n"
             "    bad = [m for m in sys.modules if m.split('.')[0] in ('qgis', 'PyQt5', 'distributed')]\n"
             "    print('IMPORTED', bad); raise\n")
    done = subprocess.run([sys.executable, "-c", probe, "pmf", "--input", scene, "--output", str(tmp_path / "p.laz")],
                          cwd=PLUGINS, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "IMPORTED []" in done.stdout and "ground." in done.stderr


@pytest.mark.parametrize("name", list(P.FILTERS))
def test_defaults_read_without_importing_the_filter_are_the_filter_s(name):
    """The dialog reads the defaults from the filter's source (no numpy needed to list the
    algorithms); they must be the dataclass's."""
    assert P.source_defaults(name) == {f.name: f.default for f in P.filter_fields(name)}
    assert {p.field for p in P.params(name)} <= set(P.source_defaults(name))


def test_tune_writes_a_preset_that_every_run_of_the_filter_takes(scene, tmp_path):
    preset, report = str(tmp_path / "smrf.json"), str(tmp_path / "tune.html")
    out, stdout = io.StringIO(), io.StringIO()
    assert main(["tune", "--input", scene, "--filter", "smrf", "--budget", "4", "--blocks", "2",
                 "--preset-out", preset, "--report", report, "--json"], out=out, stdout=stdout) == 0, out.getvalue()
    assert "cross-validated total error" in out.getvalue()
    assert "<svg" in open(report, encoding="utf-8").read()
    from groundsieve.core.engine.presets import load_preset
    # --json: the chosen set and the cross-validated figures the preset records
    doc = json.loads(stdout.getvalue())
    saved = json.load(open(preset, encoding="utf-8"))
    assert doc["status"] == "done" and doc["filter"] == "smrf" and doc["preset"] == preset
    assert doc["parameters"] == load_preset(preset, "smrf").values
    assert round(doc["cv"]["total_error"], 5) == saved["source"]["cv_total_error"]
    assert round(doc["cv"]["kappa"], 5) == saved["source"]["cv_kappa"] and doc["cv"]["blocks"] == 2
    assert doc["sets"] == saved["source"]["sets_tried"] and doc["runs"] <= 4
    assert f"cross-validated total error {100 * doc['cv']['total_error']:.2f} %" in out.getvalue()
    tuned = load_preset(preset, "smrf").build()
    algorithm, _options, _dtm = options_from(build_parser().parse_args(
        ["smrf", "--input", scene, "--output", "o.laz", "--preset", preset]))
    assert algorithm == tuned
    algorithm, _options, _dtm = options_from(build_parser().parse_args(
        ["smrf", "--input", scene, "--output", "o.laz", "--preset", preset, "--threshold", "0.31"]))
    assert algorithm == dataclasses.replace(tuned, elevation_threshold_m=0.31)  # a value given wins
    lines = []
    options_from(build_parser().parse_args(["smrf", "--input", scene, "--output", "o.laz", "--preset", preset,
                                            "--threshold", "0.31"]), lines.append)
    assert lines[0].startswith("SMRF parameters: CELL ") and "THRESHOLD 0.31 m" in lines[0]
    assert f"WINDOW {tuned.window_m:g} m" in lines[0]
    assert lines[1].startswith("From the preset smrf.json: ") and lines[1].count("THRESHOLD") == 1
    assert "; changed from the preset: THRESHOLD 0.31 m" in lines[1]
    out = io.StringIO()
    assert main(["pmf", "--input", scene, "--output", str(tmp_path / "o.laz"), "--preset", preset], out=out) == 1
    assert out.getvalue().strip() == f"groundsieve: {preset}: a preset for SMRF (smrf), not for PMF (pmf)"
    assert not os.path.exists(tmp_path / "o.laz")


def test_tune_refuses_a_patch_without_labels_in_one_line(tmp_path):
    path = tmp_path / "unlabelled.txt"
    path.write_text("".join(f"{i % 30} {i // 30} 100\n" for i in range(900)))
    out = io.StringIO()
    assert main(["tune", "--input", str(path), "--filter", "smrf", "--report", str(tmp_path / "r.html")],
                out=out) == 1
    assert out.getvalue().startswith(f"groundsieve: {path}: the tuning patch has no labels")


def test_tune_refuses_outputs_the_filters_cannot_take_before_the_search(scene, tmp_path):
    """A preset named p.txt was written after minutes of search, then refused by every filter's
    PRESET (.json only): a modeler reviewer. Now the outputs are checked before the search."""
    for option, name, said in (("--preset-out", "p.txt", "the preset must end in .json (got '.txt')"),
                               ("--report", "r.pdf", "the report must end in .html or .htm (got '.pdf')"),
                               ("--preset-out", "nowhere/p.json", "does not exist")):
        out = io.StringIO()
        assert main(["tune", "--input", scene, "--filter", "smrf", option, str(tmp_path / name)], out=out) == 1
        assert said in out.getvalue() and "sets in" not in out.getvalue(), out.getvalue()
    out = io.StringIO()
    assert main(["tune", "--input", str(tmp_path / "typo.laz"), "--filter", "smrf", "--preset-out",
                 str(tmp_path / "p.txt")], out=out) == 1
    assert f"{tmp_path / 'typo.laz'}: no such file" in out.getvalue()
    assert os.listdir(tmp_path) == []


def test_a_mistyped_input_is_named_before_the_outputs(tmp_path):
    """A missing input given with a .vpc output: the error is the missing input, not the output's
    extension (which only follows from the input not being found)."""
    out = io.StringIO()
    (tmp_path / "out").mkdir()
    assert main(["smrf", "--input", str(tmp_path / "survey_typo"), "--output",
                 str(tmp_path / "out" / "classified.vpc")], out=out) == 1
    assert f"{tmp_path / 'survey_typo'}: no such file or folder" in out.getvalue()
    assert ".vpc" not in out.getvalue()


def test_hybrid_on_the_command_line_with_the_shipped_models(scene, tmp_path):
    """`python -m groundsieve hybrid`: groundsieve:hybrid's MODEL, SHIPPED and PROBABILITY as --model,
    --shipped fast|accurate and --probability; the defaults build Hybrid()."""
    from groundsieve.core.learn.hybrid import PTD_FEATURES, Hybrid
    text = help_of("hybrid")
    assert "--shipped {fast,accurate}" in text and "--model PATH" in text and "--probability X" in text
    algorithm, _o, _d = options_from(build_parser().parse_args(["hybrid", "--input", "x", "--output", "y"]))
    assert algorithm == Hybrid() and algorithm.shipped_model == "fast"
    args = build_parser().parse_args(["hybrid", "--input", "x", "--output", "y", "--shipped", "accurate",
                                      "--probability", "0.6"])
    algorithm, _o, _d = options_from(args)
    assert algorithm == Hybrid(shipped_model="accurate", ground_probability=0.6)
    assert set(PTD_FEATURES) <= set(algorithm.features)
    out = io.StringIO()
    assert main(["hybrid", "--input", scene, "--output", str(tmp_path / "h.laz"), "--shipped", "accurate"],
                out=out) == 0, out.getvalue()
    classes = np.asarray(laspy.read(tmp_path / "h.laz").classification)
    assert set(np.unique(classes)) <= {1, 2} and (classes == 2).any()
    with pytest.raises(SystemExit):
        build_parser().parse_args(["hybrid", "--input", "x", "--output", "y", "--shipped", "best"])


def test_ignored_classes_a_degree_crs_and_a_dtm_cell_without_dtm_as_in_the_dialog(scene, tmp_path):
    """--ignore-classes is IGNORE_CLASSES (the dialog's words, its default 7,18); a cloud whose CRS is
    in degrees is warned about as qgis_process does; --dtm-cell without --dtm says no DTM is made."""
    las = laspy.read(scene)
    las.classification = np.where(np.arange(len(las.points)) % 10 == 0, 20, 1).astype(np.uint8)
    marked = tmp_path / "marked.laz"
    las.write(str(marked))
    args = build_parser().parse_args(["smrf", "--input", "a", "--output", "b", "--ignore-classes", "7,18,20-25"])
    assert tuple(options_from(args)[1].ignored) == (7, 18, 20, 21, 22, 23, 24, 25)
    assert tuple(options_from(build_parser().parse_args(["smrf", "--input", "a", "--output", "b"]))[1].ignored) \
        == (7, 18)
    out = io.StringIO()
    assert main(["smrf", "--input", str(marked), "--output", str(tmp_path / "c.laz"), "--ignore-classes", "20"],
                out=out) == 0, out.getvalue()
    classes = np.asarray(laspy.read(tmp_path / "c.laz").classification)
    assert np.array_equal(classes == 20, np.asarray(las.classification) == 20)  # kept as they were
    assert "WARNING" not in out.getvalue()  # the scene's CRS is in metres
    out = io.StringIO()
    assert main(["smrf", "--input", "a.laz", "--output", "b.laz", "--ignore-classes", "7,x"], out=out) == 1
    assert "ignored classes" in out.getvalue() and "Traceback" not in out.getvalue()

    import pyproj
    las.header.add_crs(pyproj.CRS.from_epsg(4326))
    degrees = tmp_path / "degrees.laz"
    las.write(str(degrees))
    out = io.StringIO()
    assert main(["smrf", "--input", str(degrees), "--output", str(tmp_path / "d.laz"), "--dtm-cell", "0.5"],
                out=out) == 0, out.getvalue()
    text = out.getvalue()
    # UTM coordinates under a geographic CRS: the CRS is wrong, the run goes on, and says so before the work
    assert f"Warning: {degrees}: the file's CRS is geographic (degrees), but its coordinates (x 500,000 to" in text
    assert text.index("Warning: ") < text.index("Filtering")
    assert "--dtm-cell is set but no --dtm is named: no DTM is made" in text
    # longitudes and latitudes: refused before any work (a reviewer's run wrote a 1 x 1 cell DTM)
    lonlat = laspy.read(scene)
    lonlat.header.offsets, lonlat.header.scales = [9.0, 47.0, 0.0], [1e-7, 1e-7, 0.01]
    lonlat.x, lonlat.y = 9.0 + (np.asarray(las.x) - las.x.min()) * 1e-5, 47.0 + (np.asarray(las.y) - las.y.min()) * 1e-5
    lonlat.header.add_crs(pyproj.CRS.from_epsg(4326))
    lonlat.write(str(tmp_path / "lonlat.laz"))
    out = io.StringIO()
    assert main(["smrf", "--input", str(tmp_path / "lonlat.laz"), "--output", str(tmp_path / "l.laz")], out=out) == 1
    assert out.getvalue().strip().splitlines()[-1] == (
        f"groundsieve: {tmp_path / 'lonlat.laz'}: its coordinates are longitudes and latitudes in degrees (a geographic "
        "CRS), and every length parameter (cells, windows, thresholds) are lengths in metres: reproject the cloud to "
        "a projected CRS in metres (its UTM zone, e.g. with PDAL's filters.reprojection or LAStools' las2las) first")
    assert not (tmp_path / "l.laz").exists() and "Reading" not in out.getvalue()
    # the DTM classes: a bad list in words; named without --dtm, said
    out = io.StringIO()
    assert main(["smrf", "--input", str(degrees), "--dtm", str(tmp_path / "e.tif"), "--dtm-classes", "water"],
                out=out) == 1
    assert "DTM classes: 'water' is not a class code" in out.getvalue() and "Traceback" not in out.getvalue()
    out = io.StringIO()
    assert main(["smrf", "--input", str(degrees), "--output", str(tmp_path / "f.laz"), "--dtm-classes", "9"],
                out=out) == 0
    assert "--dtm-classes is set but no --dtm is named: no DTM is made" in out.getvalue()


def test_the_command_runs_without_gdal_and_then_says_nothing_of_the_crs(scene, tmp_path, monkeypatch):
    """The command line is the core alone: without GDAL (a pip-only Dask client) the CRS's unit
    cannot be read, and the run ends as usual instead of a traceback after its output."""
    from groundsieve.core.raster.crs import unit_warning
    monkeypatch.setitem(sys.modules, "osgeo", None)
    assert unit_warning("x.laz", 'GEOGCS["WGS 84"]') is None
    out = io.StringIO()
    assert main(["smrf", "--input", scene, "--output", str(tmp_path / "c.laz")], out=out) == 0, out.getvalue()
    assert "ground." in out.getvalue() and "WARNING" not in out.getvalue()


def test_sigterm_ends_the_command_as_ctrl_c_does(tmp_path):
    """systemd, timeout and batch schedulers stop a job with SIGTERM, which Python does not turn
    into cleanup (the run died at once, its workers orphaned): `python -m groundsieve` treats it as
    Ctrl-C, says so in one line and exits with 130."""
    import signal
    import subprocess
    import sys
    import time
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    cloud = tmp_path / "big.laz"
    write_scene(make_scene(SceneSpec(size_m=400.0, density_per_m2=10.0, seed=3)), str(cloud))
    proc = subprocess.Popen([sys.executable, "-m", "groundsieve", "ptd", "--input", str(cloud), "--output",
                             str(tmp_path / "o.laz"), "--dtm", str(tmp_path / "d.tif")], cwd=PLUGINS,
                            stderr=subprocess.PIPE, text=True)
    text = ""
    while "Filtering" not in text:  # the run is under way
        line = proc.stderr.readline()
        assert line, text
        text += line
    time.sleep(0.3)
    proc.send_signal(signal.SIGTERM)
    rest = proc.stderr.read()
    assert proc.wait(30) == 130, text + rest
    assert "groundsieve: interrupted" in rest and "Traceback" not in rest, rest
    assert not (tmp_path / "o.laz").exists() and not (tmp_path / "d.tif").exists()


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_signal_while_the_laz_is_written_is_an_interrupt(tmp_path, sig):
    """Ctrl-C or SIGTERM while lazrs compressed the classified LAZ came back as "LazrsError: IoError:
    Failed to call write", a traceback and exit 1 (a QA reviewer, 6 of 7 signals). `python -m
    groundsieve`'s handler notes the interrupt: 130, one line, nothing left behind."""
    import signal
    import subprocess
    import sys
    import time
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    cloud = tmp_path / "big.laz"
    write_scene(make_scene(SceneSpec.for_points(3_000_000, density_per_m2=20.0, seed=3)), str(cloud))
    out = tmp_path / "out"
    out.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "groundsieve", "pmf", "--input", str(cloud), "--output",
                             str(out / "o.laz"), "--json"], cwd=PLUGINS, stderr=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # (as a terminal's)
    text = ""
    while "classified points to" not in text:  # "Writing 3,000,000 classified points to ...": lazrs at work
        line = proc.stderr.readline()
        assert line, text
        text += line
    time.sleep(0.2)
    proc.send_signal(getattr(signal, sig))
    document, rest = proc.communicate(timeout=60)
    if proc.returncode == 0:  # the write ended before the signal came (a fast machine): nothing to judge
        pytest.skip("the run ended before the signal")
    assert proc.returncode == 130, text + rest
    assert json.loads(document) == {"status": "interrupted", "kind": "interrupted", "error": "interrupted"}
    assert "groundsieve: interrupted" in rest and "Traceback" not in rest, rest
    assert os.listdir(out) == []


# -- --json: one document on stdout for scripts and job schedulers ------------------------------

def counts_of(path):
    classes = np.asarray(laspy.read(path).classification)
    return len(classes), int((classes == 2).sum())


@pytest.mark.parametrize("name", [*P.FILTERS, "hybrid", "tune"])
def test_json_is_in_every_command_s_help(name):
    text = help_of(name)
    assert "--json write one JSON document to stdout" in text and '"status": "failed" or "interrupted"' in text


def test_json_reports_the_run_as_the_output_file_holds_it(scene, tmp_path):
    out, stdout = io.StringIO(), io.StringIO()
    output, dtm = str(tmp_path / "c.laz"), str(tmp_path / "d.tif")
    assert main(["smrf", "--input", scene, "--output", output, "--dtm", dtm, "--slope", "0.2", "--json"],
                out=out, stdout=stdout) == 0, out.getvalue()
    doc = json.loads(stdout.getvalue())  # the document alone: any other text would not parse
    points, ground = counts_of(output)
    assert (doc["points"], doc["ground"]) == (points, ground) and 0 < ground < points
    assert doc["status"] == "done" and doc["input"] == scene and doc["output"] == output and doc["dtm"] == dtm
    assert doc["outputs"] == [output] and doc["tiles"] is None and doc["algorithm"] == "smrf"
    assert doc["parameters"] == dataclasses.asdict(SMRF(slope=0.2)) and doc["warnings"] == []
    assert 0 < doc["seconds"] < 300
    assert f"{points:,} points, {ground:,} ground." in out.getvalue()  # the log as without --json

    # a tiled run: its tiles counted, its counts those of its file; no DTM: null
    out, stdout = io.StringIO(), io.StringIO()
    tiled = str(tmp_path / "t.laz")
    assert main(["pmf", "--input", scene, "--output", tiled, "--tile-size", "30", "--json"], out=out,
                stdout=stdout) == 0, out.getvalue()
    doc = json.loads(stdout.getvalue())
    assert (doc["points"], doc["ground"]) == counts_of(tiled) and doc["dtm"] is None
    assert doc["tiles"] >= 4 and doc["tile_size"] == 30.0 and doc["algorithm"] == "pmf"
    assert f"{doc['tiles']} tile(s) on" in out.getvalue()


def test_json_failures_give_the_message_and_the_exit_status(tmp_path, monkeypatch):
    missing = str(tmp_path / "missing.laz")
    out, stdout = io.StringIO(), io.StringIO()
    assert main(["pmf", "--input", missing, "--output", str(tmp_path / "o.laz"), "--json"], out=out,
                stdout=stdout) == 1
    doc = json.loads(stdout.getvalue())
    assert doc == {"status": "failed", "kind": "input", "error": f"{missing}: no such file or folder"}
    assert out.getvalue().strip().endswith(f"groundsieve: {doc['error']}")
    # bad usage, found by argparse or after it: 2, as without --json
    stdout = io.StringIO()
    assert main(["smrf", "--input", missing, "--json"], out=io.StringIO(), stdout=stdout) == 2
    assert json.loads(stdout.getvalue()) == {"status": "failed", "kind": "usage", "error": "give --output and/or --dtm"}
    stdout = io.StringIO()
    with pytest.raises(SystemExit) as exit_:
        main(["smrf", "--input", missing, "--output", "o.laz", "--cell", "wide", "--json"], stdout=stdout)
    assert exit_.value.code == 2
    assert json.loads(stdout.getvalue()) == {"status": "failed", "kind": "usage",
                                             "error": "argument --cell: invalid float value: 'wide'"}
    # without --json, nothing on stdout
    stdout = io.StringIO()
    assert main(["pmf", "--input", missing, "--output", "o.laz"], out=io.StringIO(), stdout=stdout) == 1
    assert stdout.getvalue() == ""
    # interrupted: 130
    from groundsieve.core.engine import workflow

    def interrupted(*_a, **_k):
        raise KeyboardInterrupt
    monkeypatch.setattr(workflow, "run_ground_filter", interrupted)
    out, stdout = io.StringIO(), io.StringIO()
    assert main(["smrf", "--input", missing, "--output", "o.laz", "--json"], out=out, stdout=stdout) == 130
    assert json.loads(stdout.getvalue()) == {"status": "interrupted", "kind": "interrupted", "error": "interrupted"}
    assert "groundsieve: interrupted" in out.getvalue()
    # not a refusal (a bug): the traceback as without --json, and the document still says failed
    def broken(*_a, **_k):
        raise RuntimeError("a bug")
    monkeypatch.setattr(workflow, "run_ground_filter", broken)
    stdout = io.StringIO()
    with pytest.raises(RuntimeError):
        main(["smrf", "--input", missing, "--output", "o.laz", "--json"], out=io.StringIO(), stdout=stdout)
    assert json.loads(stdout.getvalue()) == {"status": "failed", "kind": "other", "error": "RuntimeError: a bug"}


def test_an_interrupt_a_library_turned_into_its_own_error_or_swallowed_is_still_an_interrupt(monkeypatch):
    """Ctrl-C or SIGTERM while lazrs wrote a LAZ came back as "LazrsError: IoError: Failed to call write",
    a traceback and "failed / other" (a QA reviewer, 6 of 7 signals); GDAL's writer swallowed one and the
    run ended "done". The handler of `python -m groundsieve` notes the interrupt: a library's error after
    it is the interrupt (130), and the run's cancel check sees it before the outputs are put in place."""
    from groundsieve.core.engine import cli, workflow
    from groundsieve.core.errors import Cancelled
    monkeypatch.setattr(cli, "INTERRUPT_SEEN", [False])  # (the module's own list back after the test)
    seen = {}

    def lazrs_wrapped(*_a, **_k):
        cli.INTERRUPT_SEEN[0] = True  # what the handler does, then its KeyboardInterrupt comes back as:
        raise RuntimeError("LazrsError: IoError: Failed to call write")

    def swallowed(*_a, is_cancelled=None, **_k):
        cli.INTERRUPT_SEEN[0] = True  # ... and GDAL ate the KeyboardInterrupt: the run goes on to its check
        seen["cancel"] = is_cancelled()
        raise Cancelled("cancelled by the user")
    for fake in (lazrs_wrapped, swallowed):
        monkeypatch.setattr(workflow, "run_ground_filter", fake)
        out, stdout = io.StringIO(), io.StringIO()
        assert main(["smrf", "--input", "x.laz", "--output", "o.laz", "--json"], out=out, stdout=stdout) == 130
        assert json.loads(stdout.getvalue()) == {"status": "interrupted", "kind": "interrupted", "error": "interrupted"}
        assert "Traceback" not in out.getvalue()
    assert seen == {"cancel": True}
    # without an interrupt, a library's error is still a bug shown as one
    monkeypatch.setattr(workflow, "run_ground_filter", lambda *_a, **_k: (_ for _ in ()).throw(RuntimeError("bug")))
    with pytest.raises(RuntimeError):
        main(["smrf", "--input", "x.laz", "--output", "o.laz"], out=io.StringIO())


def test_json_stdout_holds_the_document_alone_even_when_something_writes_to_it(scene, tmp_path):
    """Under `python -m groundsieve`, a print or a library writing to descriptor 1 during the run
    goes to stderr: stdout is the JSON document and nothing else."""
    probe = ("import os, runpy, sys\n"
             "from groundsieve.core.engine import workflow\n"
             "real = workflow.run_ground_filter\n"
             "def noisy(*a, **k):\n"
             "    print('PRINTED'); sys.stdout.flush(); os.write(1, b'FD1\\n')\n"
             "    return real(*a, **k)\n"
             "workflow.run_ground_filter = noisy\n"
             "sys.argv = ['groundsieve'] + sys.argv[1:]\n"
             "runpy.run_module('groundsieve', run_name='__main__')\n")
    output = str(tmp_path / "c.laz")
    done = subprocess.run([sys.executable, "-c", probe, "smrf", "--input", scene, "--output", output, "--json"],
                          cwd=PLUGINS, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    assert (doc["points"], doc["ground"]) == counts_of(output)
    assert "PRINTED" in done.stderr and "FD1" in done.stderr and "ground." in done.stderr
    # a refusal: the document, and the exit status
    done = subprocess.run([sys.executable, "-m", "groundsieve", "smrf", "--input", str(tmp_path / "none.laz"),
                           "--output", output, "--json"], cwd=PLUGINS, capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and json.loads(done.stdout)["status"] == "failed", done.stderr


def test_an_option_typed_with_a_preset_wins_even_at_its_default(scene):
    """With a preset, `--threshold 1.5 --large-scale 2` (EVC's defaults) were dropped for the preset's
    values (a reviewer's comparison of the preset with the paper's settings ran the preset's): the
    command line knows what was typed, and a typed value wins; an option not typed keeps the preset's."""
    from groundsieve.core.engine.presets import load_preset
    preset = load_preset("uav-photogrammetry-evc", "evc")
    assert preset.values["threshold"] != 1.5 and preset.values["large_scale_m"] != 2.0  # (else no test)
    assert P.default("evc", "threshold") == 1.5 and P.default("evc", "large_scale_m") == 2.0
    args = build_parser().parse_args(["evc", "--input", scene, "--output", "o.laz", "--preset",
                                      "uav-photogrammetry-evc", "--threshold", "1.5", "--large-scale", "2"])
    lines = []
    algorithm, _options, _dtm = options_from(args, lines.append)
    assert algorithm.threshold == 1.5 and algorithm.large_scale_m == 2.0
    assert algorithm.small_scale_m == preset.values["small_scale_m"]
    assert "changed from the preset: " in lines[1] and "never replaces" not in lines[1]
    args = build_parser().parse_args(["evc", "--input", scene, "--output", "o.laz", "--preset", "uav-photogrammetry-evc"])
    assert options_from(args)[0] == preset.build()


def test_a_sigterm_once_the_run_has_ended_does_not_make_it_killed(scene, tmp_path):
    """A SIGTERM in the fraction of a second between the `done` document and the process's exit
    (the interpreter's shutdown) ended a finished run as killed (143) in 6 of 30 of a reviewer's
    runs, so a scheduler marked a finished job as failed: once the run has ended, SIGTERM is
    ignored."""
    import signal
    import subprocess
    import sys
    proc = subprocess.Popen([sys.executable, "-m", "groundsieve", "smrf", "--input", scene, "--output",
                             str(tmp_path / "o.laz"), "--json"], cwd=PLUGINS, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    line = proc.stdout.readline()  # the document: the run has ended
    assert json.loads(line)["status"] == "done"
    for _ in range(5):
        proc.send_signal(signal.SIGTERM)
    assert proc.wait(30) == 0
    assert (tmp_path / "o.laz").exists()


def test_json_failures_say_their_kind(scene, tmp_path):
    """A script could tell a retryable failure (the cluster gone) from a permanent one only by the
    message's words (a reviewer): --json's failures carry a kind."""
    from groundsieve.core.engine.cli import error_kind
    from groundsieve.core.engine.cluster import ClusterError
    from groundsieve.core.engine.presets import PresetError
    from groundsieve.core.errors import (Cancelled, GroundSieveError, InputError, InvalidParameterError,
                                         MemoryBudgetError, OutputError)
    kinds = {InputError: "input", PresetError: "input", InvalidParameterError: "parameter",
             MemoryBudgetError: "memory", OutputError: "output", ClusterError: "cluster", Cancelled: "cancelled",
             GroundSieveError: "other"}
    assert {cls: error_kind(cls("x")) for cls in kinds} == kinds
    stdout = io.StringIO()
    assert main(["smrf", "--input", scene, "--output", str(tmp_path / "o.laz"), "--slope", "-1", "--json"],
                out=io.StringIO(), stdout=stdout) == 1
    assert json.loads(stdout.getvalue())["kind"] == "parameter"
    stdout = io.StringIO()
    assert main(["smrf", "--input", scene, "--output", str(tmp_path / "no" / "o.laz"), "--json"],
                out=io.StringIO(), stdout=stdout) == 1
    assert json.loads(stdout.getvalue())["kind"] == "output"


def test_a_filter_parameter_s_help_is_in_the_command_s_help_too():
    """The parameters' help written for the dialog's tooltips (core/engine/parameters.py) is the command
    line's too."""
    text = " ".join(help_of("smrf").split())
    assert "Elevation scalar (m per unit slope): a point is ground within the elevation threshold" in text
    assert "Kernel size (m): the side of the square kernels" in " ".join(help_of("echogrid").split())


def test_rftrain_and_rfclassify_run_from_the_shell_whole_and_tiled(scene, tmp_path):
    """Training and applying a classifier were QGIS's only (groundsieve:rftrain, rfclassify): a shell user
    had no route (a research software engineer)."""
    model, report = str(tmp_path / "m.npz"), str(tmp_path / "r.html")
    out, stdout = io.StringIO(), io.StringIO()
    assert main(["rftrain", "--input", scene, "--model", model, "--report", report, "--trees", "8", "--max-depth", "8",
                 "--json"], out=out, stdout=stdout) == 0, out.getvalue()
    trained = json.loads(stdout.getvalue())
    assert trained["status"] == "done" and trained["classes"] == [1, 2] and len(trained["features"]) == 6
    assert 0.8 < trained["test_accuracy"] <= 1 and os.path.exists(model) and os.path.exists(report)
    truth = np.asarray(laspy.read(scene).classification) == 2
    for tiled in (False, True):
        output, dtm = str(tmp_path / f"c{tiled}.laz"), str(tmp_path / f"d{tiled}.tif")
        out, stdout = io.StringIO(), io.StringIO()
        args = ["rfclassify", "--input", scene, "--model", model, "--output", output, "--dtm", dtm, "--json"]
        assert main(args + (["--tile-size", "30"] if tiled else []), out=out, stdout=stdout) == 0, out.getvalue()
        done = json.loads(stdout.getvalue())
        assert done["points"] == len(truth) and (done["tiles"] is not None) == tiled and os.path.exists(dtm)
        predicted = np.asarray(laspy.read(output).classification) == 2
        assert done["ground"] == int(predicted.sum()) and (predicted == truth).mean() > 0.9
    out, stdout = io.StringIO(), io.StringIO()
    assert main(["rfclassify", "--input", scene, "--model", str(tmp_path / "none.npz"), "--output",
                 str(tmp_path / "x.laz"), "--json"], out=out, stdout=stdout) == 1
    failed = json.loads(stdout.getvalue())
    assert failed["kind"] in ("input", "parameter") and "none.npz" in failed["error"]
    # the DTM alone, as the filters make it (--output had been required); the same DTM as the run with the cloud
    out, stdout = io.StringIO(), io.StringIO()
    dtm = str(tmp_path / "alone.tif")
    before = set(os.listdir(tmp_path))
    assert main(["rfclassify", "--input", scene, "--model", model, "--dtm", dtm, "--json"], out=out,
                stdout=stdout) == 0, out.getvalue()
    done = json.loads(stdout.getvalue())
    assert done["output"] is None and done["outputs"] == [] and done["dtm"] == dtm
    assert set(os.listdir(tmp_path)) - before == {"alone.tif"}
    from osgeo import gdal
    assert np.array_equal(gdal.Open(dtm).ReadAsArray(), gdal.Open(str(tmp_path / "dFalse.tif")).ReadAsArray())
    out = io.StringIO()
    assert main(["rfclassify", "--input", scene, "--model", model], out=out) == 2
    assert "give --output and/or --dtm" in out.getvalue()


def test_rftrain_takes_the_dialogs_custom_features_ground_against_the_rest_and_grid(scene, tmp_path):
    """The command line's rftrain had neither the dialog's custom feature list nor its grid, and no route (in
    either) to a ground model of other features than the hybrid's (a UAV surveyor relabelled a patch with laspy)."""
    assert {"--custom-features", "--ground-vs-rest", "--grid"} <= set(help_of("rftrain").split()) | {
        w.strip("[],") for w in help_of("rftrain").split()}
    assert "C3 (+ scan angle, GPS time)" in " ".join(help_of("rftrain").split())
    classes = set(np.unique(np.asarray(laspy.read(scene).classification)))
    assert len(classes - {1, 2}) >= 1  # (other classes than ground and 1: what ground against the rest merges)
    for extra, learnt in (([], sorted(c for c in classes if c not in (0, 7, 18))), (["--ground-vs-rest"], [1, 2])):
        out, stdout = io.StringIO(), io.StringIO()
        model = str(tmp_path / f"m{len(extra)}.npz")
        assert main(["rftrain", "--input", scene, "--model", model, "--custom-features", "verticality_r0p6,intensity",
                     "--trees", "3", "--json"] + extra, out=out, stdout=stdout) == 0, out.getvalue()
        done = json.loads(stdout.getvalue())
        assert done["features"] == ["verticality_r0p6", "intensity"] and done["classes"] == learnt, done
        assert len(done["warnings"]) == len(set(done["warnings"]))


def test_features_run_from_the_shell(scene, tmp_path):
    """groundsieve:features had no command (a new user: 12 of the 14 algorithms): the paper's four by default,
    FEATURE:RADIUS pairs otherwise, the values of the core's run."""
    from groundsieve.core.engine.features_run import run_features
    from groundsieve.core.learn.features import FeatureSpec
    out, stdout = io.StringIO(), io.StringIO()
    output = str(tmp_path / "f.laz")
    assert main(["features", "--input", scene, "--output", output, "--json"], out=out, stdout=stdout) == 0, \
        out.getvalue()
    done = json.loads(stdout.getvalue())
    assert done["features"] == ["verticality_r0p6", "planarity_r0p6", "eigenentropy_r0p4", "surface_variation_r0p6"]
    out = io.StringIO()
    assert main(["features", "--input", scene, "--output", str(tmp_path / "g.laz"), "--features",
                 "height_above_min:2.5,planarity_r1"], out=out) == 0, out.getvalue()  # (a name as it writes them)
    direct = run_features(scene, str(tmp_path / "h.laz"), FeatureSpec((("height_above_min", 2.5), ("planarity", 1.0))))
    got = laspy.read(str(tmp_path / "g.laz"))
    for name, values in direct.features.items():
        np.testing.assert_array_equal(np.asarray(got[name]), values)
    out = io.StringIO()
    assert main(["features", "--input", scene, "--output", str(tmp_path / "x.laz"), "--features", "planarity"],
                out=out) == 2 and "is not FEATURE:RADIUS" in out.getvalue()
    assert not os.path.exists(tmp_path / "x.laz")


def test_evc_writes_the_evc_workflows_rasters_from_the_shell(scene, tmp_path):
    """groundsieve:evcrasters had no command (a new user): evc takes its five rasters, the core's (the same
    table as the dialog's), with or without a classified cloud."""
    from osgeo import gdal
    from groundsieve.core.engine.workflow import run_ground_filter
    from groundsieve.core.filters.evc import EVC, EVC_RASTERS
    out, stdout = io.StringIO(), io.StringIO()
    paths = {key: str(tmp_path / f"{key}.tif") for key in EVC_RASTERS}
    flags = {key: "--" + ("class" if key == "classes" else key.replace("_", "-")) + "-raster" for key in paths}
    options = [a for key, path in paths.items() for a in (flags[key], path)]
    assert main(["evc", "--input", scene, "--json"] + options, out=out, stdout=stdout) == 0, out.getvalue()
    done = json.loads(stdout.getvalue())
    assert sorted(done["rasters"]) == sorted(paths.values()) and done["output"] is None
    direct = run_ground_filter(scene, None, EVC())
    for key, (_label, make) in EVC_RASTERS.items():
        values = make(direct.detail)[0]
        got = gdal.Open(paths[key]).ReadAsArray()
        if key == "classes":
            np.testing.assert_array_equal(got, values)
        else:
            np.testing.assert_allclose(got, np.where(np.isfinite(values), values, got), rtol=1e-6)
    assert gdal.Open(paths["classes"]).GetRasterBand(1).GetDescription().startswith("1 Ground")
    out = io.StringIO()
    assert main(["evc", "--input", scene], out=out) == 2 and "(or an evc raster)" in out.getvalue()


def _python_m_groundsieve_with(run_code: str, scene, output):
    """``python -m groundsieve smrf`` on ``scene``, in a process of its own whose run_ground_filter is the function
    ``run`` that ``run_code`` defines."""
    code = ("import sys, runpy\n"
            "import groundsieve.core.engine.workflow as w\n"
            + run_code +
            "w.run_ground_filter = run\n"
            f"sys.argv = ['groundsieve', 'smrf', '--input', {str(scene)!r}, '--output', {str(output)!r}]\n"
            "runpy.run_module('groundsieve', run_name='__main__')\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=PLUGINS), timeout=120)


def test_a_cluster_failure_and_an_internal_error_have_exit_statuses_of_their_own(scene, tmp_path, monkeypatch):
    """A refusal, a bug and a lost Dask cluster all exited 1: a job wrapper could not tell "retry" from "do
    not" (a research software engineer). The cluster's is 75 (EX_TEMPFAIL), a bug's 3 (with its traceback)."""
    from groundsieve.core.engine import cli, workflow
    from groundsieve.core.engine.cluster import ClusterError

    def lost(*_a, **_k):
        raise ClusterError("the connection to the Dask scheduler tcp://10.0.0.5:8786 was lost")
    monkeypatch.setattr(workflow, "run_ground_filter", lost)
    stdout = io.StringIO()
    assert main(["smrf", "--input", scene, "--output", str(tmp_path / "o.laz"), "--json"], out=io.StringIO(),
                stdout=stdout) == cli.EXIT_RETRY == 75
    assert json.loads(stdout.getvalue())["kind"] == "cluster"
    proc = _python_m_groundsieve_with("def run(*a, **k):\n    raise RuntimeError('a bug')\n", scene, tmp_path / "b.laz")
    assert proc.returncode == cli.EXIT_BUG == 3, proc.stderr[-2000:]
    assert "Traceback" in proc.stderr and "RuntimeError: a bug" in proc.stderr


def test_a_thread_the_run_could_not_stop_does_not_hold_the_command_line(scene, tmp_path):
    """A tile thread stuck in C (OpenBLAS retrying an allocation for ever under ulimit -v) held the interpreter's
    shutdown after the run had said it failed, SIGTERM ignored, for ever (a code reviewer)."""
    proc = _python_m_groundsieve_with("import threading, time\n"
                                      "from groundsieve.core.errors import InputError\n"
                                      "def run(*a, **k):\n"
                                      "    threading.Thread(target=time.sleep, args=(3600,), daemon=False).start()\n"
                                      "    raise InputError('a refusal, a thread left behind')\n",
                                      scene, tmp_path / "o.laz")
    assert proc.returncode == 1 and "a refusal, a thread left behind" in proc.stderr, proc.stderr[-2000:]
