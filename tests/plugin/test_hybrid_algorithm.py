"""groundsieve:hybrid through processing.run and through qgis_process, as users call it."""
import subprocess
from pathlib import Path

import numpy as np
import pytest

from .conftest import classes_of

REPO = Path(__file__).resolve().parents[2]
WRAPPER = REPO / "scripts" / "qgis-process"


def test_provider_lists_hybrid(groundsieve_provider):
    from qgis.core import QgsApplication
    alg = QgsApplication.processingRegistry().algorithmById("groundsieve:hybrid")
    assert alg is not None
    assert alg.displayName() == "Ground filter (learned hybrid)"
    assert alg.group() == "Ground filters"
    names = {p.name() for p in alg.parameterDefinitions()}
    assert {"INPUT", "OUTPUT", "DTM", "MODEL", "PROBABILITY", "LAST_RETURNS"} <= names
    assert alg.parameterDefinition("MODEL").flags() & alg.parameterDefinition("MODEL").FlagOptional


def test_hybrid_with_the_shipped_model(groundsieve_provider, scene_laz, tmp_path):
    import processing
    from groundsieve.core.metrics import ground_accuracy
    src, scene = scene_laz
    out = tmp_path / "out.laz"
    result = processing.run("groundsieve:hybrid", {"INPUT": str(src), "OUTPUT": str(out)})
    cls = classes_of(out)
    assert set(np.unique(cls)) <= {1, 2}
    assert result["GROUND_COUNT"] == int((cls == 2).sum())
    acc = ground_accuracy(scene.classification == 2, cls == 2)
    assert acc.total < 0.05, acc


def test_hybrid_refuses_a_model_for_other_features(groundsieve_provider, scene_laz, tmp_path):
    import processing
    from qgis.core import QgsProcessingException
    from groundsieve.core.learn.model_file import save_model
    from groundsieve.core.learn.rf import ForestParams, train_forest
    X = np.random.default_rng(0).normal(size=(100, 1)).astype(np.float32)
    model = train_forest(X, np.where(X[:, 0] > 0, 2, 1), ["intensity"], ForestParams(n_trees=2), n_jobs=1)
    path = tmp_path / "intensity_model.npz"
    save_model(model, str(path))
    src, _scene = scene_laz
    out = tmp_path / "never.laz"
    with pytest.raises(QgsProcessingException, match="intensity_model.npz.*does not compute"):
        processing.run("groundsieve:hybrid", {"INPUT": str(src), "OUTPUT": str(out), "MODEL": str(path)})
    assert not out.exists()


def test_qgis_process_runs_hybrid_with_only_input_and_output(scene_laz, tmp_path):
    """The command the issue promises: x, y, z only, no model given."""
    import laspy
    src, scene = scene_laz
    xyz_only = tmp_path / "xyz.laz"
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.offsets = [scene.x.min(), scene.y.min(), 0.0]
    header.scales = [0.01, 0.01, 0.01]
    las = laspy.LasData(header)
    las.x, las.y, las.z = scene.x, scene.y, scene.z
    las.write(str(xyz_only))
    out = tmp_path / "b.laz"
    proc = subprocess.run([str(WRAPPER), "run", "groundsieve:hybrid", f"--INPUT={xyz_only}", f"--OUTPUT={out}"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    cls = classes_of(out)
    assert len(cls) == len(scene.x)
    truth = scene.classification == 2
    assert ((cls == 2) == truth).mean() > 0.95


def test_the_plugin_zip_ships_the_default_model(tmp_path):
    """`make zip` (git archive) must carry the shipped model, or groundsieve:hybrid fails out of the box."""
    import zipfile
    from groundsieve.core.learn.hybrid import DEFAULT_MODEL
    archive = tmp_path / "groundsieve.zip"
    subprocess.run(["git", "archive", "--format=zip", "--prefix=groundsieve/", "-o", str(archive), "HEAD"],
                   cwd=REPO, check=True)
    relative = Path(DEFAULT_MODEL).resolve().relative_to(REPO).as_posix()
    assert "groundsieve/" + relative in zipfile.ZipFile(archive).namelist()


def test_an_rftrain_model_on_the_hybrid_preset_runs_in_hybrid(groundsieve_provider, scene_laz, tmp_path):
    """Train on the user's labelled cloud with rftrain's HYBRID preset (ground 2 against the rest),
    then filter with that model: the issue's promise that rftrain models work in groundsieve:hybrid."""
    import processing
    from groundsieve.core.metrics import ground_accuracy
    src, scene = scene_laz
    model = tmp_path / "mine.npz"
    result = processing.run("groundsieve:rftrain", {"INPUT": str(src), "MODEL": str(model), "PRESET": 7,
                                                     "REPORT": str(tmp_path / "report.html"),
                                                     "TREES": 8, "CLASSES": "2,3,5,6"})
    assert result["TEST_ACCURACY"] > 0.9
    out = tmp_path / "filtered.laz"
    processing.run("groundsieve:hybrid", {"INPUT": str(src), "OUTPUT": str(out), "MODEL": str(model)})
    acc = ground_accuracy(scene.classification == 2, classes_of(out) == 2)
    assert acc.total < 0.05, acc


def test_hybrid_with_the_accurate_shipped_model(groundsieve_provider, scene_laz, tmp_path):
    """SHIPPED = 1 (accurate: SMRF + PTD surfaces) when no model file is given; a model file wins."""
    import processing
    from groundsieve.core.metrics import ground_accuracy
    from qgis.core import QgsApplication
    alg = QgsApplication.processingRegistry().algorithmById("groundsieve:hybrid")
    shipped = alg.parameterDefinition("SHIPPED")
    assert shipped.defaultValue() == 0 and len(shipped.options()) == 2 and "accurate" in shipped.options()[1]
    src, scene = scene_laz
    out = tmp_path / "accurate.laz"
    processing.run("groundsieve:hybrid", {"INPUT": str(src), "OUTPUT": str(out), "SHIPPED": 1})
    acc = ground_accuracy(scene.classification == 2, classes_of(out) == 2)
    assert acc.total < 0.05, acc
    from qgis.core import QgsProcessingContext
    context = QgsProcessingContext()
    assert alg.buildFilter({"SHIPPED": 1}, context).shipped_model == "accurate"
    assert alg.buildFilter({}, context).shipped_model == "fast"
