"""groundsieve:rfclassify through the real qgis_process (scripts/qgis-process) with crafted model
files that gave a segmentation fault or a traceback before (issue 14): each run fails with the
core's message naming the model file, no traceback, nothing written, the inputs unchanged."""
import hashlib
import subprocess
from pathlib import Path

import numpy as np
import pytest

from groundsieve.core.learn import model_file, rf

from .test_model_fuzz import _arrays, _write

WRAPPER = Path(__file__).resolve().parents[2] / "scripts" / "qgis-process"


@pytest.fixture(scope="module")
def cloud_and_model(tmp_path_factory):
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    folder = tmp_path_factory.mktemp("crafted")
    cloud = folder / "cloud.laz"
    write_scene(make_scene(SceneSpec(size_m=40.0, density_per_m2=4.0, seed=3)), str(cloud))
    rng = np.random.default_rng(0)
    X = rng.normal(size=(500, 2)).astype(np.float32)
    model = rf.train_forest(X, np.where(X[:, 0] > 0, 2, 1), ["intensity", "return_number"],
                            rf.ForestParams(n_trees=3, scaler="standard"), n_jobs=1)
    good = folder / "good.npz"
    model_file.save_model(model, str(good))
    return cloud, good


def _crafted(good, case, path):
    arrays, header = _arrays(good)
    if case == "header-list":
        header = [header]
    elif case == "root-out-of-range":
        arrays["roots"] = arrays["roots"].copy()
        arrays["roots"][0] = 10 ** 6
    elif case == "cycle":
        arrays["right"] = arrays["right"].copy()
        arrays["right"][0] = 0  # the first root is its own child: a walk would loop for ever
    elif case == "scaler-arrays-missing":
        del arrays["scaler_center"], arrays["scaler_scale"]
    _write(path, arrays, header)


def _sha(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.mark.parametrize("case, words", [
    ("header-list", "its header is a JSON list, not an object"),
    ("root-out-of-range", "'roots' holds 1000000"),
    ("cycle", "the root node 0 is also a child of a node"),
    ("scaler-arrays-missing", "scaler's centre and scale arrays are missing"),
])
def test_rfclassify_refuses_a_crafted_model_cleanly(cloud_and_model, tmp_path, case, words):
    cloud, good = cloud_and_model
    model = tmp_path / f"{case}.npz"
    _crafted(good, case, model)
    out_folder = tmp_path / "out"
    out_folder.mkdir()
    before = {p: _sha(p) for p in (cloud, model)}
    proc = subprocess.run([str(WRAPPER), "run", "groundsieve:rfclassify", f"--INPUT={cloud}", f"--MODEL={model}",
                           f"--OUTPUT={out_folder / 'classified.laz'}"], capture_output=True, text=True,
                          timeout=300)
    text = proc.stdout + proc.stderr
    assert proc.returncode != 0, text
    assert f"{model}: " in text and words in text, text
    assert "Traceback" not in text
    assert list(out_folder.iterdir()) == []
    assert {p: _sha(p) for p in (cloud, model)} == before
