"""rftrain and rfclassify refuse what cannot work before the work, in words: a training cloud with
fewer than two classes that can be learnt, a DTM asked of a model without ground."""
from __future__ import annotations

import os

import laspy
import numpy as np
import pytest

from groundsieve.core.engine import learning
from groundsieve.core.errors import InputError
from groundsieve.core.learn.model_file import save_model
from groundsieve.core.learn.rf import ForestParams, train_forest
from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("learning") / "scene.laz"
    write_scene(make_scene(SceneSpec(size_m=40.0, density_per_m2=2.0, seed=11)), path)
    return str(path)


def _with_classes(src, path, classes):
    las = laspy.read(src)
    las.classification = np.resize(np.asarray(classes, dtype=np.uint8), len(las.points))
    las.write(str(path))
    return str(path)


def test_training_without_two_learnable_classes_says_what_the_file_holds(scene, tmp_path):
    unclassified = _with_classes(scene, tmp_path / "unclassified.laz", [0])
    with pytest.raises(InputError, match=r"unclassified\.laz: at least two classes are needed to train, and the file "
                                         r"holds only classes never learnt \(0 = never classified\); classify a "
                                         r"training area first"):
        learning.train_file(unclassified, str(tmp_path / "m.npz"))
    ground_only = _with_classes(scene, tmp_path / "ground.laz", [2, 2, 7])
    with pytest.raises(InputError, match=r"ground\.laz: .* holds only class 2 besides classes never learnt "
                                         r"\(7 = low point \(noise\)\)"):
        learning.train_file(ground_only, str(tmp_path / "m.npz"))
    assert not os.path.exists(tmp_path / "m.npz")


def test_a_dtm_from_a_model_without_ground_is_refused_before_the_work(scene, tmp_path):
    X = np.random.default_rng(1).normal(size=(100, 1)).astype(np.float32)
    model = train_forest(X, np.where(X[:, 0] > 0, 6, 5), ["above_smrf"], ForestParams(n_trees=2), n_jobs=1)
    path = tmp_path / "no_ground.npz"
    save_model(model, str(path))
    stages = []
    with pytest.raises(InputError, match=r"no_ground\.npz: this model has no ground class \(2\) \(its classes: 5, 6\)"):
        learning.classify_file(scene, str(tmp_path / "c.laz"), str(path), dtm_path=str(tmp_path / "d.tif"),
                               progress=stages.append)
    assert stages == [] and sorted(os.listdir(tmp_path)) == ["no_ground.npz"]


def test_rfclassify_reports_and_honours_cancel_while_it_predicts(tmp_path):
    """The forest's prediction (rfclassify's longest stage on a big file after the features) moves
    the bar within its range (0.5-0.7 of a run) and stops on a cancel there."""
    from groundsieve.core.errors import Cancelled
    from groundsieve.core.learn.hybrid import DEFAULT_MODEL
    path = tmp_path / "cloud.laz"
    write_scene(make_scene(SceneSpec.for_points(400_000, density_per_m2=10.0, seed=4)), path)
    seen = []
    learning.classify_file(str(path), str(tmp_path / "c.laz"), DEFAULT_MODEL, progress=seen.append)
    inside = [v for v in seen if 0.5 < v < 0.7]
    assert inside and seen == sorted(seen) and seen[-1] == 1.0
    seen.clear()
    with pytest.raises(Cancelled):
        learning.classify_file(str(path), str(tmp_path / "d.laz"), DEFAULT_MODEL, progress=seen.append,
                               is_cancelled=lambda: bool(seen) and seen[-1] > 0.5)
    assert max(seen) < 0.7 and not os.path.exists(tmp_path / "d.laz")


def test_a_cloud_in_another_unit_than_the_models_is_refused_before_the_work(scene, tmp_path):
    """A model trained on a cloud in metres, applied to the same points in a CRS in feet or degrees,
    would read its features' radii and heights in another unit and misclassify most points without
    an error (a reviewer saw 87 % Type I): rftrain now records the unit, rfclassify refuses the
    other, before reading the points (file and survey alike). A model that does not say (trained
    before, or on a cloud without CRS) gets a warning in the log instead."""
    import pyproj
    from groundsieve.core.learn.model_file import load_model
    from groundsieve.core.engine.learning import TrainOptions
    from groundsieve.core.learn.rf import ForestParams
    model = str(tmp_path / "m.npz")
    learning.train_file(scene, model, options=TrainOptions(params=ForestParams(n_trees=4)))
    assert load_model(model).meta["crs_unit"] == "metres"
    for epsg, unit in ((2263, "US survey foot"), (4326, "degrees")):
        las = laspy.read(scene)
        las.header.add_crs(pyproj.CRS.from_epsg(epsg))
        other = str(tmp_path / f"in_{epsg}.laz")
        las.write(other)
        stages = []
        with pytest.raises(InputError, match=rf"in_{epsg}\.laz: the CRS's unit is {unit}, but the model .*m\.npz "
                                             r"was trained on a cloud in metres"):
            learning.classify_file(other, str(tmp_path / "c.laz"), model, progress=stages.append)
        assert stages == [] and not os.path.exists(tmp_path / "c.laz")
        if epsg == 4326:  # training on it says which unit its lengths are read in
            lines = []
            learning.train_file(other, str(tmp_path / "deg.npz"), log=lines.append,
                                options=TrainOptions(params=ForestParams(n_trees=2), block_m=0.0002))
            assert any("the CRS's unit is degrees, not metres: the features' radii and the blocks' size" in line
                       for line in lines), lines
        # the learned hybrid filter with the same model refuses it too (a surveyor: it ran a model of feet
        # on metres without a word, 10 times the error), whole and tiled
        from groundsieve.core.engine.tiles import TileOptions
        from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
        from groundsieve.core.learn.hybrid import Hybrid
        for options in (FilterOptions(), FilterOptions(tiling=TileOptions(tile_size_m=50.0, workers=1,
                                                                           parallel="threads"))):
            with pytest.raises(InputError, match=rf"in_{epsg}\.laz: the CRS's unit is {unit}, but the model "):
                run_ground_filter(other, str(tmp_path / "h.laz"), Hybrid(model_path=model), options=options)
        assert not os.path.exists(tmp_path / "h.laz")
        with pytest.raises(InputError, match="was trained on a cloud in metres"):  # a folder survey too
            folder = tmp_path / f"survey_{epsg}"
            folder.mkdir()
            os.replace(other, folder / "a.laz")
            learning.classify_file(str(folder), str(tmp_path / "c.vpc"), model)
    # a model without the unit (trained on a cloud without CRS): a warning, and the run goes on
    las = laspy.read(scene)
    las.header.add_crs(pyproj.CRS.from_epsg(2263))
    feet = str(tmp_path / "feet.laz")
    las.write(feet)
    X = np.random.default_rng(1).normal(size=(200, 1)).astype(np.float32)
    bare = train_forest(X, np.where(X[:, 0] > 0, 2, 1), ["above_smrf"], ForestParams(n_trees=2), n_jobs=1)
    save_model(bare, str(tmp_path / "bare.npz"))
    lines = []
    learning.classify_file(feet, str(tmp_path / "d.laz"), str(tmp_path / "bare.npz"), log=lines.append)
    assert any(line.startswith("Warning: ") and "the CRS's unit is US survey foot, not metres" in line
               for line in lines), lines
