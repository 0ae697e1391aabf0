"""A folder and a .vpc as INPUT, a .vpc as OUTPUT, through processing.run (toolbox, batch,
modeler) and qgis_process: the INPUT parameter's type lets all three through on QGIS 3.22."""
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from .conftest import classes_of

WRAPPER = Path(__file__).resolve().parents[2] / "scripts" / "qgis-process"


def _split(src, folder):
    """The scene as two files, west and east of its middle."""
    import laspy
    las = laspy.read(str(src))
    folder.mkdir()
    mid = float(np.median(las.x))
    for name, keep in (("west.laz", las.x < mid), ("east.laz", las.x >= mid)):
        part = laspy.LasData(las.header)
        part.points = las.points[np.asarray(keep)]
        part.write(str(folder / name))
    return [str(folder / "west.laz"), str(folder / "east.laz")]


def test_input_parameter_accepts_a_file_a_folder_and_a_vpc(groundsieve_provider, tmp_path):
    from qgis.core import QgsApplication
    alg = QgsApplication.processingRegistry().algorithmById("groundsieve:smrf")
    param = alg.parameterDefinition("INPUT")
    for value in ("/data/a.laz", str(tmp_path), "/data/survey.vpc"):
        assert param.checkValueIsAcceptable(value), value


def test_folder_in_vpc_out_through_processing(groundsieve_provider, scene_laz, tmp_path):
    import processing
    src, _scene = scene_laz
    _split(src, tmp_path / "in")
    out = tmp_path / "out" / "classified.vpc"
    out.parent.mkdir()
    result = processing.run("groundsieve:smrf", {"INPUT": str(tmp_path / "in"), "OUTPUT": str(out),
                                                 "TILE_SIZE": 50.0, "DTM": str(tmp_path / "dtm.tif")})
    doc = json.loads(out.read_text())
    hrefs = sorted(f["assets"]["data"]["href"] for f in doc["features"])
    assert hrefs == ["./classified/east.laz", "./classified/west.laz"]
    total = sum(len(classes_of(tmp_path / "out" / "classified" / n)) for n in ("east.laz", "west.laz"))
    assert result["POINT_COUNT"] == total == len(classes_of(src))
    assert result["GROUND_COUNT"] == sum(int((classes_of(tmp_path / "out" / "classified" / n) == 2).sum())
                                         for n in ("east.laz", "west.laz"))
    assert os.path.exists(tmp_path / "dtm.tif")


def test_a_temporary_output_of_several_files_is_a_vpc(groundsieve_provider, scene_laz, tmp_path):
    """The dialog's default "[Save to temporary file]" (TEMPORARY_OUTPUT) and a model's intermediate
    step give no extension to choose: for a folder or .vpc input the classified cloud is then a .vpc."""
    import processing
    from groundsieve.core.io.lasfiles import read_vpc
    src, _scene = scene_laz
    _split(src, tmp_path / "in")
    for alg, extra in (("groundsieve:smrf", {}), ("groundsieve:echogrid", {"DTM": "TEMPORARY_OUTPUT"})):
        result = processing.run(alg, dict(extra, INPUT=str(tmp_path / "in"), OUTPUT="TEMPORARY_OUTPUT"))
        out = result["OUTPUT"]
        assert out.endswith(".vpc") and os.path.isfile(out), out
        members = read_vpc(out)
        assert sorted(os.path.basename(m) for m in members) == ["east.laz", "west.laz"]
        assert sum(len(classes_of(m)) for m in members) == len(classes_of(src)) == result["POINT_COUNT"]
    # one file behind a folder: one classified LAZ, as the core writes it for a named .laz
    (tmp_path / "one").mkdir()
    os.link(os.path.join(tmp_path, "in", "west.laz"), tmp_path / "one" / "west.laz")
    one = processing.run("groundsieve:smrf", {"INPUT": str(tmp_path / "one"), "OUTPUT": "TEMPORARY_OUTPUT"})["OUTPUT"]
    assert one.endswith(".laz") and len(classes_of(one)) == len(classes_of(tmp_path / "in" / "west.laz"))
    # one file in: a temporary output stays one LAZ; a named non-.vpc output of a folder is still refused
    single = processing.run("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": "TEMPORARY_OUTPUT"})["OUTPUT"]
    assert single.endswith(".laz") and len(classes_of(single)) == len(classes_of(src))
    from qgis.core import QgsProcessingException
    with pytest.raises(QgsProcessingException, match="the output must name a .vpc"):
        processing.run("groundsieve:smrf", {"INPUT": str(tmp_path / "in"), "OUTPUT": str(tmp_path / "c.laz")})


def test_a_folder_step_feeds_the_next_step_of_a_model(groundsieve_provider, scene_laz, tmp_path):
    """A graphical model whose first step filters a folder and whose classified cloud only feeds a
    second step (not a model output, so a temporary one): it runs, the second step reads the .vpc."""
    from qgis.core import (QgsProcessingContext, QgsProcessingFeedback, QgsProcessingModelAlgorithm,
                           QgsProcessingModelChildAlgorithm, QgsProcessingModelChildParameterSource,
                           QgsProcessingModelOutput, QgsProcessingModelParameter, QgsProcessingParameterFile)
    src, _scene = scene_laz
    _split(src, tmp_path / "in")
    model = QgsProcessingModelAlgorithm("chain", "tests")
    model.addModelParameter(QgsProcessingParameterFile("tiles", "Tiles", behavior=QgsProcessingParameterFile.Behavior.Folder),
                            QgsProcessingModelParameter("tiles"))
    first = QgsProcessingModelChildAlgorithm("groundsieve:smrf")
    first.setChildId("smrf")
    first.addParameterSources("INPUT", [QgsProcessingModelChildParameterSource.fromModelParameter("tiles")])
    model.addChildAlgorithm(first)
    second = QgsProcessingModelChildAlgorithm("groundsieve:echogrid")
    second.setChildId("echo")
    second.addParameterSources("INPUT", [QgsProcessingModelChildParameterSource.fromChildOutput("smrf", "OUTPUT")])
    output = QgsProcessingModelOutput("classified", "classified")
    output.setChildOutputName("OUTPUT")
    second.setModelOutputs({"classified": output})
    second.setDependencies([])
    model.addChildAlgorithm(second)
    out = tmp_path / "final.vpc"
    context, feedback = QgsProcessingContext(), QgsProcessingFeedback()
    results, ok = model.run({"tiles": str(tmp_path / "in"), "echo:classified": str(out)}, context, feedback)
    assert ok and str(out) in results.values(), results
    from groundsieve.core.io.lasfiles import read_vpc
    assert sum(len(classes_of(m)) for m in read_vpc(str(out))) == len(classes_of(src))


def test_vpc_through_qgis_process(scene_laz, tmp_path):
    from groundsieve.core.io.lasfiles import scan_header, write_vpc
    src, _scene = scene_laz
    files = _split(src, tmp_path / "in")
    vpc = tmp_path / "in" / "survey.vpc"
    write_vpc(str(vpc), [scan_header(f) for f in files], files)
    out = tmp_path / "classified.vpc"
    proc = subprocess.run([str(WRAPPER), "--json", "run", "groundsieve:smrf", f"--INPUT={vpc}", f"--OUTPUT={out}",
                           "--TILE_SIZE=50", "--WORKERS=2"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    results = json.loads(proc.stdout)["results"]
    assert results["POINT_COUNT"] == len(classes_of(src))
    assert sorted(os.listdir(tmp_path / "classified")) == ["east.laz", "west.laz"]


def test_one_file_of_a_survey_through_processing_with_name_fields(groundsieve_provider, scene_laz, tmp_path):
    """ONLY (advanced): one job of a job array; {name} in the outputs' paths is the file's name, and the
    run's results name its own files. Its classes are those of the run of the whole survey."""
    import processing
    src, _scene = scene_laz
    _split(src, tmp_path / "in")
    whole = tmp_path / "whole" / "classified.vpc"
    whole.parent.mkdir()
    common = {"INPUT": str(tmp_path / "in"), "TILE_SIZE": 50.0, "WORKERS": 1}
    processing.run("groundsieve:smrf", dict(common, OUTPUT=str(whole), DTM=str(tmp_path / "whole" / "dtm.tif")))
    for only in ("1", "east.laz"):  # (a folder's files by name: east is 0, west 1)
        result = processing.run("groundsieve:smrf", dict(common, ONLY=only, OUTPUT=str(tmp_path / "jobs" / "{name}.laz"),
                                                         DTM=str(tmp_path / "dtm" / "{name}.tif")))
        name = "west" if only == "1" else "east"
        assert result["OUTPUT"] == str(tmp_path / "jobs" / f"{name}.laz")
        assert result["DTM"] == str(tmp_path / "dtm" / f"{name}.tif") and os.path.exists(result["DTM"])
        assert result["POINT_COUNT"] == len(classes_of(result["OUTPUT"]))
        assert np.array_equal(classes_of(result["OUTPUT"]), classes_of(tmp_path / "whole" / "classified" / f"{name}.laz"))
    assert sorted(os.listdir(tmp_path / "jobs")) == ["east.laz", "west.laz"]


def test_a_job_array_through_qgis_process(scene_laz, tmp_path):
    """What a SLURM array's job runs: qgis_process with --ONLY=$SLURM_ARRAY_TASK_ID; a number beyond the
    survey's files is refused in words."""
    src, _scene = scene_laz
    _split(src, tmp_path / "in")
    for task in ("0", "1"):
        proc = subprocess.run([str(WRAPPER), "--json", "run", "groundsieve:smrf", f"--INPUT={tmp_path / 'in'}",
                               f"--OUTPUT={tmp_path / 'jobs' / '{name}.laz'}", "--TILE_SIZE=50", f"--ONLY={task}"],
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stdout + proc.stderr
    assert sorted(os.listdir(tmp_path / "jobs")) == ["east.laz", "west.laz"]
    proc = subprocess.run([str(WRAPPER), "run", "groundsieve:smrf", f"--INPUT={tmp_path / 'in'}",
                           f"--OUTPUT={tmp_path / 'jobs' / '{name}.laz'}", "--ONLY=2"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode != 0
    assert "no file 2 in the survey: it has 2 file(s), numbered 0 to 1" in proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr


def test_the_classified_cloud_skipped_gives_the_dtm_of_an_extent_alone(groundsieve_provider, scene_laz, tmp_path):
    """OUTPUT is optional (made by default): skipped, a survey's DTM of an extent filters the extent's tiles
    only, and equals the DTM of a run that writes the classified cloud; both skipped is refused in words."""
    import processing
    from osgeo import gdal
    from qgis.core import QgsProcessingException
    src, _scene = scene_laz
    files = _split(src, tmp_path / "in")
    import laspy
    west = laspy.read(files[0]).header
    x0, y0 = float(np.floor(west.mins[0])), float(np.floor(west.mins[1]))
    extent = f"{x0 + 5},{x0 + 25},{y0 + 5},{y0 + 25}"  # (QGIS's xmin,xmax,ymin,ymax)
    common = {"INPUT": str(tmp_path / "in"), "TILE_SIZE": 20.0, "WORKERS": 1, "DTM_EXTENT": extent}
    full = processing.run("groundsieve:smrf", dict(common, OUTPUT=str(tmp_path / "c.vpc"), DTM=str(tmp_path / "a.tif")))
    alone = processing.run("groundsieve:smrf", dict(common, OUTPUT=None, DTM=str(tmp_path / "b.tif")))
    assert "OUTPUT" not in alone and alone["DTM"] == str(tmp_path / "b.tif")
    assert alone["POINT_COUNT"] < full["POINT_COUNT"]
    a, b = (gdal.Open(str(tmp_path / n)).ReadAsArray() for n in ("a.tif", "b.tif"))
    assert a.shape == (20, 20) and np.array_equal(a, b)
    with pytest.raises(QgsProcessingException, match="Classified point cloud and DTM are both skipped"):
        processing.run("groundsieve:smrf", dict(common, OUTPUT=None, DTM=None))


def test_rfclassify_offers_the_filters_tiles_a_job_array_and_the_dtm_alone(groundsieve_provider, scene_laz, tmp_path):
    """rfclassify on a survey takes the ground filters' advanced tile parameters (it had none: a UAV surveyor
    could not set its tiles, workers, memory or a job array's file in QGIS), and its classified cloud is optional
    as theirs: skipped, a survey's DTM of an extent classifies the extent's tiles only, with the DTM of a run
    that writes the cloud; ONLY runs one file with {name}; both skipped is refused in words."""
    import processing
    from osgeo import gdal
    from qgis.core import QgsApplication, QgsProcessingException, QgsProcessingParameterDefinition
    registry = QgsApplication.processingRegistry()
    smrf, rfc = registry.algorithmById("groundsieve:smrf"), registry.algorithmById("groundsieve:rfclassify")
    for name in ("TILE_SIZE", "TILE_BUFFER", "MEMORY_BUDGET", "WORKERS", "WORK_FOLDER", "SCHEDULER", "ONLY"):
        ours, theirs = rfc.parameterDefinition(name), smrf.parameterDefinition(name)
        assert ours is not None and ours.type() == theirs.type(), name
        assert ours.flags() & QgsProcessingParameterDefinition.Flag.FlagAdvanced, name
        assert ours.description() == theirs.description() or name == "TILE_BUFFER", name
    assert "model" in rfc.parameterDefinition("TILE_BUFFER").description()
    assert rfc.parameterDefinition("OUTPUT").flags() & QgsProcessingParameterDefinition.Flag.FlagOptional
    src, _scene = scene_laz
    model = tmp_path / "model.npz"
    processing.run("groundsieve:rftrain", {"INPUT": str(src), "MODEL": str(model), "TREES": 4,
                                           "REPORT": str(tmp_path / "r.html")})
    files = _split(src, tmp_path / "in")
    import laspy
    west = laspy.read(files[0]).header
    x0, y0 = float(np.floor(west.mins[0])), float(np.floor(west.mins[1]))
    extent = f"{x0 + 5},{x0 + 25},{y0 + 5},{y0 + 25}"  # (QGIS's xmin,xmax,ymin,ymax)
    common = {"INPUT": str(tmp_path / "in"), "MODEL": str(model), "TILE_SIZE": 20.0, "WORKERS": 1}
    full = processing.run("groundsieve:rfclassify", dict(common, OUTPUT=str(tmp_path / "c.vpc"),
                                                         DTM=str(tmp_path / "a.tif"), DTM_EXTENT=extent))
    alone = processing.run("groundsieve:rfclassify", dict(common, OUTPUT=None, DTM=str(tmp_path / "b.tif"),
                                                          DTM_EXTENT=extent))
    assert "OUTPUT" not in alone and alone["DTM"] == str(tmp_path / "b.tif")
    assert 0 < alone["POINT_COUNT"] < full["POINT_COUNT"]
    a, b = (gdal.Open(str(tmp_path / n)).ReadAsArray() for n in ("a.tif", "b.tif"))
    assert a.shape == (20, 20) and np.array_equal(a, b)
    # one job of an array: the west file (a folder's files by name: east is 0, west 1), its classes the whole run's
    job = processing.run("groundsieve:rfclassify", dict(common, ONLY="1", OUTPUT=str(tmp_path / "jobs" / "{name}.laz")))
    assert job["OUTPUT"] == str(tmp_path / "jobs" / "west.laz")
    assert np.array_equal(classes_of(job["OUTPUT"]), classes_of(tmp_path / "c" / "west.laz"))
    with pytest.raises(QgsProcessingException, match="Classified point cloud and DTM are both skipped"):
        processing.run("groundsieve:rfclassify", dict(common, OUTPUT=None, DTM=None))


def test_rfclassify_runs_a_model_of_the_points_attributes_and_classes_on_a_survey(groundsieve_provider, scene_laz,
                                                                                   tmp_path):
    """matrone2024's models read the points' attributes (here C2 without colour: intensity and the return number)
    and learn several classes; on a survey folder they had been refused ("only a ground model ... x, y, z"). Through
    processing.run they now give each file the classes of the whole cloud's run, and the log counts them."""
    import processing
    from qgis.core import QgsProcessingContext, QgsProcessingFeedback
    from groundsieve.algorithms.rf import PRESET_NAMES
    src, _scene = scene_laz
    model = tmp_path / "c2.npz"
    processing.run("groundsieve:rftrain", {"INPUT": str(src), "MODEL": str(model), "TREES": 4,
                                           "PRESET": PRESET_NAMES.index("C2"), "REPORT": str(tmp_path / "r.html")})
    from groundsieve.core.learn.model_file import load_model
    trained = load_model(str(model))
    assert "intensity" in trained.features and len(trained.classes) >= 3
    whole = processing.run("groundsieve:rfclassify", {"INPUT": str(src), "MODEL": str(model),
                                                      "OUTPUT": str(tmp_path / "whole.laz")})
    _split(src, tmp_path / "in")

    class Said(QgsProcessingFeedback):
        lines = []

        def pushInfo(self, info):  # noqa: N802
            self.lines.append(info)
    said = Said()
    survey = processing.run("groundsieve:rfclassify", {"INPUT": str(tmp_path / "in"), "MODEL": str(model),
                                                       "OUTPUT": str(tmp_path / "c.vpc"), "WORKERS": 1},
                            context=QgsProcessingContext(), feedback=said)
    import laspy
    las = laspy.read(str(src))
    mid = float(np.median(las.x))
    got = np.empty(len(las.points), dtype=np.uint8)
    for name, keep in (("west.laz", las.x < mid), ("east.laz", las.x >= mid)):
        got[np.asarray(keep)] = classes_of(tmp_path / "c" / name)
    np.testing.assert_array_equal(got, classes_of(whole["OUTPUT"]))
    assert survey["POINT_COUNT"] == whole["POINT_COUNT"]
    assert any(line.startswith("class 2: ") and line.count("class ") == len(trained.classes) for line in said.lines), \
        said.lines
