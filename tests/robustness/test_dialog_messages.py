"""Issue 14, items 2-4, through QGIS: what the dialog, processing.run and qgis_process show.

- wrong parameter values (a DTM cell of -1, inf, text or 1e300; an ISPRS .txt given to rftrain or
  rfclassify) are explained by checkParameterValues in the dialog's words, before the run, not with
  QGIS's generic "An error was encountered while checking parameter values" alone;
- a ground-point layer in a folder that does not exist is refused before the work: nothing is
  written (before, the classified cloud was left behind);
- outputs in a read-only folder fail with a message, no traceback, nothing written."""
from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from .folders import everything_in, read_only_folder, sha256

WRAPPER = Path(__file__).resolve().parents[2] / "scripts" / "qgis-process"


@pytest.fixture(scope="module")
def groundsieve_provider(qgis_app, qgis_processing):
    """GroundSieve's provider: the one tests/plugin's session fixture registered when those tests ran
    first in this session, else the plugin loaded here for this module and unloaded after it."""
    from qgis.core import QgsApplication

    import groundsieve
    registered = QgsApplication.processingRegistry().providerById("groundsieve")
    if registered is not None:
        yield registered
        return
    plugin = groundsieve.classFactory(None)
    plugin.initProcessing()
    yield plugin.provider
    plugin.unload()


@pytest.fixture(scope="module")
def cloud(tmp_path_factory):
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    folder = tmp_path_factory.mktemp("dialog")
    path = folder / "cloud.laz"
    write_scene(make_scene(SceneSpec(size_m=40.0, density_per_m2=4.0, seed=3)), str(path))
    text = folder / "isprs.txt"
    rng = np.random.default_rng(0)
    np.savetxt(text, np.column_stack([rng.uniform(0, 10, (50, 3)), rng.integers(0, 2, 50)]), fmt="%.2f")
    (folder / "model.npz").write_bytes(b"")  # only its name and existence are checked here
    return path, text


def _check(alg_id, parameters):
    from qgis.core import QgsApplication, QgsProcessingContext
    alg = QgsApplication.processingRegistry().algorithmById(alg_id)
    return alg.checkParameterValues(parameters, QgsProcessingContext())


@pytest.mark.parametrize("alg_id", ["groundsieve:smrf", "groundsieve:rfclassify"])
@pytest.mark.parametrize("cell, words", [
    (-1, "DTM cell size (m) must be > 0 (got -1)"),
    (0, "DTM cell size (m) must be > 0 (got 0)"),
    ("inf", "DTM cell size (m) must be a finite number (got inf)"),
    ("text", "DTM cell size (m): 'text' is not a number"),
    (1e300, "DTM cell size (m): 1e+300 is larger than any map"),
])
def test_dtm_cell_sizes_are_explained_in_the_dialogs_words(groundsieve_provider, cloud, tmp_path, alg_id,
                                                           cell, words):
    path, _text = cloud
    params = {"INPUT": str(path), "OUTPUT": str(tmp_path / "o.laz"), "DTM": str(tmp_path / "d.tif"),
              "DTM_CELL": cell, "MODEL": str(path.parent / "model.npz")}
    ok, message = _check(alg_id, params)
    assert not ok and words in message, message
    assert "cell_size_m" not in message


@pytest.mark.parametrize("alg_id, label, accepted", [
    ("groundsieve:rftrain", "Labelled point cloud (LAS/LAZ)", ".las or .laz"),
    ("groundsieve:rfclassify", "Point cloud (LAS/LAZ, a folder of them, or a .vpc survey)", ".las or .laz or .vpc")])
def test_an_isprs_text_given_to_the_random_forest_is_explained(groundsieve_provider, cloud, tmp_path, alg_id,
                                                               label, accepted):
    path, text = cloud
    ok, message = _check(alg_id, {"INPUT": str(text), "MODEL": str(tmp_path / "m.npz"),
                                  "OUTPUT": str(tmp_path / "o.laz"), "REPORT": str(tmp_path / "r.html")})
    assert not ok
    assert message.startswith(f"{label}: {text} is not a {accepted} file (it ends in '.txt')"), message
    assert "ISPRS text files are read by the ground filters only" in message


def test_good_values_still_pass(groundsieve_provider, cloud, tmp_path):
    path, _text = cloud
    assert _check("groundsieve:smrf", {"INPUT": str(path), "OUTPUT": str(tmp_path / "o.laz"),
                                       "DTM_CELL": 0.5}) == (True, "")


def test_ground_points_in_a_missing_folder_write_nothing(groundsieve_provider, cloud, tmp_path):
    import processing
    from qgis.core import QgsProcessingException
    path, _text = cloud
    out = tmp_path / "out"
    out.mkdir()
    before = sha256(path)
    with pytest.raises(QgsProcessingException) as err:
        processing.run("groundsieve:smrf", {"INPUT": str(path), "OUTPUT": str(out / "c.laz"),
                                            "DTM": str(out / "d.tif"),
                                            "GROUND_POINTS": str(tmp_path / "missing" / "g.gpkg")})
    assert f"the folder {tmp_path / 'missing'} of the output 'Ground points as a vector layer (small clouds only)' does not exist" in str(err.value)
    assert everything_in(out) == [] and sha256(path) == before


def _qgis_process(*args):
    proc = subprocess.run([str(WRAPPER), "run", *args], capture_output=True, text=True, timeout=300)
    return proc.returncode, proc.stdout + proc.stderr


@pytest.mark.parametrize("alg, extra", [("smrf", []), ("smrf", ["--DTM={out}/dtm.tif"]),
                                        ("rftrain", ["--REPORT={out}/r.html"])],
                         ids=["smrf", "smrf+dtm", "rftrain"])
def test_qgis_process_into_a_read_only_folder(cloud, tmp_path, alg, extra):
    path, _text = cloud
    with read_only_folder(tmp_path) as out:
        before = sha256(path)
        target = out / ("m.npz" if alg == "rftrain" else "c.laz")
        args = [f"groundsieve:{alg}", f"--INPUT={path}",
                f"--{'MODEL' if alg == 'rftrain' else 'OUTPUT'}={target}", *(a.format(out=out) for a in extra)]
        code, text = _qgis_process(*args)
        assert code != 0, text
        assert f"{target}: the folder {out} cannot be written to" in text, text
        assert "Traceback" not in text
        assert everything_in(out) == [] and sha256(path) == before


def test_qgis_process_ground_points_in_a_missing_folder(cloud, tmp_path):
    path, _text = cloud
    out = tmp_path / "out"
    out.mkdir()
    code, text = _qgis_process("groundsieve:smrf", f"--INPUT={path}", f"--OUTPUT={out / 'c.laz'}",
                               f"--GROUND_POINTS={tmp_path / 'missing' / 'g.gpkg'}")
    assert code != 0 and "of the output 'Ground points as a vector layer (small clouds only)' does not exist" in text, text
    assert "Traceback" not in text and everything_in(out) == []


def test_qgis_process_dtm_cell_of_minus_one(cloud, tmp_path):
    path, _text = cloud
    code, text = _qgis_process("groundsieve:smrf", f"--INPUT={path}", f"--OUTPUT={tmp_path / 'c.laz'}",
                               f"--DTM={tmp_path / 'd.tif'}", "--DTM_CELL=-1")
    assert code != 0 and "DTM cell size (m) must be > 0 (got -1)" in text, text
    assert "Traceback" not in text and everything_in(tmp_path) == []


def test_ground_points_failing_after_the_core_run_remove_the_other_outputs(groundsieve_provider, cloud, tmp_path,
                                                                          monkeypatch):
    """Should writing the ground-point layer fail after its folder was checked (a full disk), the
    classified cloud and the DTM this run committed are removed: all or nothing."""
    import processing
    from qgis.core import QgsProcessingException

    from groundsieve.algorithms.base import GroundFilterAlgorithm
    path, _text = cloud

    def full(*_args):
        raise QgsProcessingException("Could not create layer g.gpkg: No space left on device")

    monkeypatch.setattr(GroundFilterAlgorithm, "_write_ground_points", full)
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(QgsProcessingException, match="No space left on device; the ground points could not be "
                                                     "written, so the run's other outputs were removed"):
        processing.run("groundsieve:smrf", {"INPUT": str(path), "OUTPUT": str(out / "c.laz"),
                                            "DTM": str(out / "d.tif"), "GROUND_POINTS": str(out / "g.gpkg")})
    assert everything_in(out) == []


def test_qgis_process_rftrain_on_a_full_disk(cloud, tmp_path):
    """rftrain's model and report on a 16 KiB tmpfs (root only): the message, no traceback, none of
    the model, the report, the CSV nor a temporary left."""
    from .folders import full_disk
    path, _text = cloud
    with full_disk(tmp_path, "16k") as out:
        before = sha256(path)
        code, text = _qgis_process("groundsieve:rftrain", f"--INPUT={path}", "--TREES=3",
                                   f"--MODEL={out / 'm.npz'}", f"--REPORT={out / 'r.html'}")
        # 16 KiB (in 4 KiB pages) hold the model (4.4 KB with the default features) but not the report
        # (8.8 KB) too: the issue's case, model left alone
        assert code != 0 and f"{out / 'r.html'} (or its CSV {out / 'r.csv'}): cannot be written (No space left on " \
            f"device); nothing was written: neither the model {out / 'm.npz'} nor its report" in text, text
        assert "Traceback" not in text
        assert everything_in(out) == [] and sha256(path) == before
