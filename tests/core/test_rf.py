"""Random Forest core: the array model matches scikit-learn, the model file round-trips and refuses
tampered or foreign files, spatial blocks do not leak, reports are right."""
import json
import os

import numpy as np
import pytest

from groundsieve.core.engine import learning
from groundsieve.core.learn import model_file
from groundsieve.core.learn import rf
from groundsieve.core.errors import InputError, InvalidParameterError
from groundsieve.core.metrics import class_report
from groundsieve.core.io import new_las, write_las


def _data(seed=0, n=4000):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, 4)).astype(np.float32)
    X[:, 3] = np.round(X[:, 3], 1)  # ties at thresholds
    y = np.where(X[:, 0] + 0.5 * X[:, 3] + 0.3 * rng.normal(size=n) > 0, 2, np.where(X[:, 1] > 0, 1, 6))
    return X, y.astype(np.uint8)


@pytest.mark.parametrize("with_nan", [False, True])
def test_array_forest_equals_scikit_learn(with_nan):
    from sklearn.ensemble import RandomForestClassifier
    X, y = _data()
    if with_nan:  # missing values (features undefined for too few neighbours) in training and test
        X[np.random.default_rng(5).random(X.shape) < 0.1] = np.nan
    forest = RandomForestClassifier(n_estimators=25, random_state=0).fit(X, y)
    model = rf.from_sklearn(forest, ["a", "b", "c", "d"], forest.classes_, rf.Scaler(), {})
    Xt, _ = _data(1)
    if with_nan:
        Xt[np.random.default_rng(6).random(Xt.shape) < 0.1] = np.nan
    np.testing.assert_array_equal(model.predict_proba(Xt), forest.predict_proba(Xt))
    np.testing.assert_array_equal(model.predict(Xt), forest.predict(Xt))


@pytest.mark.parametrize("max_depth", [1, 4, 10, 12, 14])
def test_shallow_forests_walked_as_complete_trees_equal_the_node_walk(max_depth):
    """Trees at most MAX_COMPLETE_DEPTH deep (the hybrid filter's) run on complete trees without
    branches; deeper ones node by node. Both give the same probabilities bit for bit, also with
    missing values and values on the thresholds, and scikit-learn's (to its own order of summing the
    impure leaves' probabilities)."""
    from sklearn.ensemble import RandomForestClassifier
    from groundsieve.core.learn import _rf_kernels as K
    X, y = _data(n=6000)
    X[np.random.default_rng(5).random(X.shape) < 0.05] = np.nan
    forest = RandomForestClassifier(n_estimators=12, max_depth=max_depth, min_samples_leaf=2,
                                    random_state=0).fit(X, y)
    model = rf.from_sklearn(forest, ["a", "b", "c", "d"], forest.classes_, rf.Scaler(), {})
    depth = K._max_depth(model.roots, model.left, model.right, K.MAX_COMPLETE_DEPTH)
    assert (depth >= 0) == (max_depth <= K.MAX_COMPLETE_DEPTH)
    Xt, _ = _data(1, n=5000)
    Xt[np.random.default_rng(6).random(Xt.shape) < 0.05] = np.nan
    Xt[:50] = X[:50]  # on the training values: some exactly on a threshold
    proba = model.predict_proba(Xt)
    np.testing.assert_allclose(proba, forest.predict_proba(Xt), rtol=0, atol=1e-15)
    node_walk = np.empty_like(proba)
    assert not K._forest_block(Xt, 0, len(Xt), model.roots, model.left, model.right, model.feature,
                               model.threshold, model.missing_left, model.value, node_walk)
    np.testing.assert_array_equal(proba, node_walk)


@pytest.mark.parametrize("scaler", rf.SCALERS)
@pytest.mark.parametrize("criterion", rf.CRITERIA)
def test_trained_model_separates_and_round_trips(tmp_path, scaler, criterion):
    X, y = _data()
    model = rf.train_forest(X, y, ["a", "b", "c", "d"], rf.ForestParams(n_trees=15, scaler=scaler,
                                                                      criterion=criterion))
    Xt, yt = _data(2)
    assert (model.predict(Xt) == yt).mean() > 0.85
    path = tmp_path / "model.npz"
    model_file.save_model(model, str(path))
    again = model_file.load_model(str(path))
    np.testing.assert_array_equal(again.predict_proba(Xt), model.predict_proba(Xt))
    assert again.features == ["a", "b", "c", "d"]
    assert again.classes.tolist() == [1, 2, 6]
    assert again.meta["params"]["scaler"] == scaler
    assert len(again.meta["impurity_importance"]) == 4


def _saved(tmp_path):
    X, y = _data()
    model = rf.train_forest(X, y, ["a", "b", "c", "d"], rf.ForestParams(n_trees=5))
    path = tmp_path / "model.npz"
    model_file.save_model(model, str(path))
    return path


def _rewrite(path, change):
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name].copy() for name in data.files}
    change(arrays)
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)


def test_tampered_threshold_is_refused(tmp_path):
    path = _saved(tmp_path)
    _rewrite(path, lambda a: a["threshold"].__setitem__(0, 1e9))
    with pytest.raises(InputError, match="checksum"):
        model_file.load_model(str(path))


def test_edited_header_is_refused(tmp_path):
    path = _saved(tmp_path)

    def edit(arrays):
        header = json.loads(bytes(arrays["header"]).decode())
        header["features"] = ["x", "y", "z", "w"]
        arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    _rewrite(path, edit)
    with pytest.raises(InputError, match="checksum"):
        model_file.load_model(str(path))


def test_pickled_content_is_never_executed(tmp_path):
    path = tmp_path / "evil.npz"
    with open(path, "wb") as handle:
        np.savez(handle, header=np.array([{"format": "groundsieve-rf"}], dtype=object))
    with pytest.raises(InputError, match="evil.npz"):
        model_file.load_model(str(path))


@pytest.mark.parametrize("content", [b"", b"not a zip at all", None])
def test_foreign_files_are_refused(tmp_path, content):
    path = tmp_path / "other.npz"
    if content is None:
        with open(path, "wb") as handle:
            np.savez(handle, a=np.arange(3))
    else:
        path.write_bytes(content)
    with pytest.raises(InputError, match="other.npz") as err:
        model_file.load_model(str(path))
    if content is not None:  # a text file named .npz was said to hold "pickled data" (a surveyor)
        assert "pickled" not in str(err.value) and "not an .npz archive" in str(err.value)


def test_unsupported_format_version_is_refused(tmp_path):
    path = _saved(tmp_path)

    def edit(arrays):
        header = json.loads(bytes(arrays["header"]).decode())
        header["format_version"] = 99
        arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    _rewrite(path, edit)
    with pytest.raises(InputError, match="version 99"):
        model_file.load_model(str(path))


def test_missing_model_and_wrong_extension(tmp_path):
    with pytest.raises(InputError, match="no such model file"):
        model_file.load_model(str(tmp_path / "none.npz"))
    X, y = _data()
    model = rf.train_forest(X, y, ["a", "b", "c", "d"], rf.ForestParams(n_trees=2))
    with pytest.raises(InvalidParameterError, match=".npz"):
        model_file.save_model(model, str(tmp_path / "model.pkl"))
    assert os.listdir(tmp_path) == []


def test_feature_count_mismatch_is_refused():
    X, y = _data()
    model = rf.train_forest(X, y, ["a", "b", "c", "d"], rf.ForestParams(n_trees=2))
    with pytest.raises(InputError, match="expects 4 features"):
        model.predict(X[:, :3])


def test_one_class_or_no_sample_is_refused():
    X, y = _data()
    with pytest.raises(InputError, match="two classes"):
        rf.train_forest(X, np.full(len(X), 2), ["a", "b", "c", "d"])
    with pytest.raises(InputError, match="labelled points"):
        rf.train_forest(X[:0], y[:0], ["a", "b", "c", "d"])


@pytest.mark.parametrize("kwargs, name", [({"n_trees": 0}, "n_trees"), ({"criterion": "log"}, "criterion"),
                                          ({"scaler": "minmax"}, "scaler"), ({"max_depth": 0}, "max_depth"),
                                          ({"max_samples": 0}, "max_samples"), ({"n_trees": 1.5}, "n_trees")])
def test_forest_parameters_are_validated(kwargs, name):
    with pytest.raises(InvalidParameterError, match=name):
        rf.ForestParams(**kwargs)


def test_spatial_split_keeps_blocks_together():
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0, 200, 20000), rng.uniform(0, 200, 20000)
    sets = rf.spatial_split(x, y, 20.0, (0.6, 0.2, 0.2), seed=3)
    block = np.floor(x / 20.0).astype(int) * 100 + np.floor(y / 20.0).astype(int)
    for b in np.unique(block):
        assert np.unique(sets[block == b]).size == 1
    shares = np.bincount(sets, minlength=3) / sets.size
    np.testing.assert_allclose(shares, [0.6, 0.2, 0.2], atol=0.06)
    np.testing.assert_array_equal(sets, rf.spatial_split(x, y, 20.0, (0.6, 0.2, 0.2), seed=3))
    with pytest.raises(InvalidParameterError, match="block size"):
        rf.spatial_split(x, y, 0.0)
    with pytest.raises(InvalidParameterError, match="fractions"):
        rf.spatial_split(x, y, 10.0, (0.5, 0.5, 0.5))


def test_class_report_matches_hand_counts():
    ref = np.array([2, 2, 2, 1, 1, 6, 6, 6, 6])
    pred = np.array([2, 2, 1, 1, 2, 6, 6, 2, 6])
    report = class_report(ref, pred)
    assert report.classes == (1, 2, 6)
    np.testing.assert_array_equal(report.confusion, [[1, 1, 0], [1, 2, 0], [0, 1, 3]])
    assert report.accuracy == pytest.approx(6 / 9)
    np.testing.assert_allclose(report.precision, [1 / 2, 2 / 4, 3 / 3])
    np.testing.assert_allclose(report.recall, [1 / 2, 2 / 3, 3 / 4])
    assert report.weighted(report.recall) == pytest.approx(report.accuracy)


# -- file to file ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def labelled_files(tmp_path_factory):
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    folder = tmp_path_factory.mktemp("rf_files")
    paths = []
    for seed in (31, 32, 33):
        scene = make_scene(SceneSpec(size_m=60.0, density_per_m2=6.0, seed=seed))
        scene.classification[:] = np.where(scene.classification == 2, 2, 1)
        path = folder / f"s{seed}.laz"
        write_scene(scene, str(path))
        paths.append(path)
    return paths


def test_train_file_with_separate_validation_and_test_files(labelled_files, tmp_path):
    train, validation, test = labelled_files
    run = learning.train_file(str(train), str(tmp_path / "m.npz"), str(tmp_path / "r.html"),
                        learning.TrainOptions(params=rf.ForestParams(n_trees=10)),
                        validation_path=str(validation), test_path=str(test))
    from groundsieve.core.io import read_cloud
    n_test = len(read_cloud(str(test)))
    assert int(run.evaluations["test set"].support.sum()) == n_test
    assert run.evaluations["test set"].accuracy > 0.9
    assert "separate files" in (tmp_path / "r.html").read_text()


def test_train_file_runs_the_paper_grid_and_keeps_the_best(labelled_files, tmp_path):
    train = labelled_files[0]
    run = learning.train_file(str(train), str(tmp_path / "m.npz"), None,
                        learning.TrainOptions(features=rf.PRESETS["C2"], grid=True, block_m=10.0,
                                        params=rf.ForestParams(max_samples=2000)))
    assert len(run.grid) == 18
    assert {(g["criterion"], g["n_trees"], g["scaler"]) for g in run.grid} == set(learning.PAPER_GRID)
    best = max(run.grid, key=lambda g: g["f1"])
    kept = run.model.meta["params"]
    assert (kept["criterion"], kept["n_trees"], kept["scaler"]) == (best["criterion"], best["n_trees"],
                                                                   best["scaler"])


def test_classify_file_refuses_a_cloud_without_the_model_features(labelled_files, tmp_path):
    from groundsieve.core.io import new_las, write_las
    train = labelled_files[0]
    learning.train_file(str(train), str(tmp_path / "m.npz"), None,
                  learning.TrainOptions(features=("intensity", "return_number", "gps_time"),
                                  params=rf.ForestParams(n_trees=3)))
    rng = np.random.default_rng(0)
    xyz = rng.uniform(0, 50, (500, 3))
    bare = tmp_path / "format0.las"  # point format 0: no GPS time
    write_las(new_las(xyz[:, 0], xyz[:, 1], xyz[:, 2], point_format=0), str(bare))
    with pytest.raises(InputError, match="gps_time"):
        learning.classify_file(str(bare), str(tmp_path / "o.laz"), str(tmp_path / "m.npz"))
    assert not (tmp_path / "o.laz").exists()


def test_rfclassify_on_a_folder_and_in_tiles_equals_the_whole_run(tmp_path):
    """rfclassify on surveys (issue 12): a ground model of the HYBRID preset runs in the buffered-tile
    engine; a folder of two LAZ and one LAZ cut into 80 m tiles give the whole run's classes on
    >= 99.9 % of the points. So does a model of three classes."""
    import laspy
    from groundsieve.core.engine.tiles import TileOptions, TiledRun
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    train = make_scene(SceneSpec(size_m=80.0, density_per_m2=4.0, seed=41))
    train.classification[:] = np.where(train.classification == 2, 2, 1)
    write_scene(train, str(tmp_path / "train.laz"))
    model = tmp_path / "ground.npz"
    learning.train_file(str(tmp_path / "train.laz"), str(model), None,
                        learning.TrainOptions(params=rf.ForestParams(n_trees=8, max_depth=10), block_m=20.0))
    scene = tmp_path / "scene.laz"
    write_scene(make_scene(SceneSpec(size_m=240.0, density_per_m2=3.0, seed=5)), str(scene))
    _cloud, whole = learning.classify_file(str(scene), str(tmp_path / "whole.laz"), str(model))
    run = learning.classify_file(str(scene), str(tmp_path / "tiled.laz"), str(model),
                                 tiling=TileOptions(tile_size_m=80.0, workers=2, parallel="threads"))
    assert isinstance(run, TiledRun) and run.tiles >= 9
    assert np.mean(np.asarray(laspy.read(tmp_path / "tiled.laz").classification) == whole) >= 0.999
    from groundsieve.tests.core.scenes import split_west_east
    folder = tmp_path / "survey"
    west = split_west_east(laspy.read(scene), folder)
    run = learning.classify_file(str(folder), str(tmp_path / "classified.vpc"), str(model))
    assert isinstance(run, TiledRun)
    for name, part in (("west.laz", west), ("east.laz", ~west)):
        got = np.asarray(laspy.read(tmp_path / "classified" / name).classification)
        assert np.mean(got == whole[part]) >= 0.999, name
    # A model of three classes runs tile by tile too, each point its predicted class (it had been refused).
    three = make_scene(SceneSpec(size_m=60.0, density_per_m2=4.0, seed=42))
    write_scene(three, str(tmp_path / "three.laz"))
    assert len(set(np.unique(three.classification))) >= 3
    learning.train_file(str(tmp_path / "three.laz"), str(tmp_path / "three.npz"), None,
                        learning.TrainOptions(params=rf.ForestParams(n_trees=3), block_m=15.0, ground_vs_rest=False))
    _cloud, whole3 = learning.classify_file(str(scene), None, str(tmp_path / "three.npz"))
    assert len(np.unique(whole3)) >= 3
    learning.classify_file(str(folder), str(tmp_path / "again.vpc"), str(tmp_path / "three.npz"))
    for name, part in (("west.laz", west), ("east.laz", ~west)):
        got = np.asarray(laspy.read(tmp_path / "again" / name).classification)
        assert np.mean(got == whole3[part]) >= 0.999, name
    # With the defaults (HYBRID features, no classes named) the same labels make a ground model:
    # ground against the rest, which runs on the survey (a reviewer's 2/3/5 labels were refused)
    lines = []
    learning.train_file(str(tmp_path / "three.laz"), str(tmp_path / "ground.npz"), None,
                        learning.TrainOptions(params=rf.ForestParams(n_trees=3), block_m=15.0), log=lines.append)
    from groundsieve.core.learn.model_file import load_model
    assert sorted(int(c) for c in load_model(str(tmp_path / "ground.npz")).classes) == [1, 2]
    assert any("Learning ground (2) against the other classes" in line for line in lines), lines
    run = learning.classify_file(str(folder), str(tmp_path / "ground.vpc"), str(tmp_path / "ground.npz"))
    assert isinstance(run, TiledRun) and run.ground_count > 0


def test_rfclassify_makes_a_dtm_alone_whole_and_of_a_surveys_extent(tmp_path):
    """rfclassify without a classified cloud (output None) writes its DTM alone: on one file, the DTM of the
    run that writes the cloud; on a survey with a DTM extent, only the tiles that make the extent's cells are
    classified (fewer points read), with the whole run's DTM cell for cell there."""
    import laspy
    from osgeo import gdal
    from groundsieve.core.engine.tiles import TileOptions, TiledRun
    from groundsieve.core.engine.workflow import DTMOptions
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    train = make_scene(SceneSpec(size_m=60.0, density_per_m2=4.0, seed=43))
    train.classification[:] = np.where(train.classification == 2, 2, 1)
    write_scene(train, str(tmp_path / "train.laz"))
    model = str(tmp_path / "ground.npz")
    learning.train_file(str(tmp_path / "train.laz"), model, None,
                        learning.TrainOptions(params=rf.ForestParams(n_trees=4, max_depth=8), block_m=15.0))
    scene = tmp_path / "scene.laz"
    write_scene(make_scene(SceneSpec(size_m=160.0, density_per_m2=2.0, seed=6)), str(scene))
    learning.classify_file(str(scene), str(tmp_path / "c.laz"), model, dtm_path=str(tmp_path / "a.tif"))
    learning.classify_file(str(scene), None, model, dtm_path=str(tmp_path / "b.tif"))
    assert sorted(os.listdir(tmp_path)) == ["a.tif", "b.tif", "c.laz", "ground.npz", "scene.laz", "train.laz"]
    assert np.array_equal(gdal.Open(str(tmp_path / "a.tif")).ReadAsArray(), gdal.Open(str(tmp_path / "b.tif")).ReadAsArray())
    las = laspy.read(scene)
    folder = tmp_path / "survey"
    folder.mkdir()
    x = np.asarray(las.x)
    x0, y0 = float(np.floor(x.min())), float(np.floor(np.asarray(las.y).min()))
    for i in range(4):  # four strips of 40 m
        piece = laspy.LasData(las.header)
        piece.points = las.points[(x >= x0 + 40 * i) & (x < x0 + 40 * (i + 1))]
        piece.write(folder / f"s{i}.laz")
    tiling = TileOptions(tile_size_m=40.0, workers=1)
    dtm = DTMOptions(extent=(x0 + 5, y0 + 50, x0 + 35, y0 + 90))
    full = learning.classify_file(str(folder), str(tmp_path / "all.vpc"), model, dtm_path=str(tmp_path / "full.tif"),
                                  dtm=dtm, tiling=tiling)
    alone = learning.classify_file(str(folder), None, model, dtm_path=str(tmp_path / "alone.tif"), dtm=dtm,
                                   tiling=tiling)
    assert isinstance(alone, TiledRun) and alone.tiles < full.tiles and alone.point_count < full.point_count
    assert not alone.outputs
    a, b = (gdal.Open(str(tmp_path / n)).ReadAsArray() for n in ("full.tif", "alone.tif"))
    assert a.shape == (40, 30) and np.array_equal(a, b)


def test_gps_time_keeps_its_resolution_as_seconds_of_the_week(tmp_path):
    """Adjusted standard GPS time is about 3e8-1e9 s: cast to float32 (the forest's type) a
    flight's 8 s became one or two values (a reviewer's C3 importance of 0); the feature is the
    time within its GPS week, at 0.06 s or better. A model records it; one that does not (trained
    before) is fed the raw time as it was."""
    from groundsieve.core.io import read_cloud
    from groundsieve.core.learn.model_file import load_model
    rng = np.random.default_rng(2)
    n = 5000
    x, y = rng.uniform(0, 50, n), rng.uniform(0, 50, n)
    times = 3.2e8 + np.sort(rng.uniform(0, 8, n))
    cls = np.where(rng.random(n) < 0.5, 2, 1).astype(np.uint8)
    path = tmp_path / "timed.las"
    write_las(new_las(x, y, rng.normal(0, 0.1, n), point_format=1, classification=cls, gps_time=times), str(path))
    cloud = read_cloud(str(path))
    week = rf.feature_matrix(cloud, ["gps_time"])[:, 0]
    raw = rf.feature_matrix(cloud, ["gps_time"], gps_time="raw")[:, 0]
    assert np.unique(raw).size <= 2
    assert np.unique(week).size > 1000  # 8 s at the float32 step near 60,800 s (4 ms)
    np.testing.assert_allclose(week, np.mod(times, rf.GPS_WEEK_S), atol=0.07)
    model = tmp_path / "c3.npz"
    learning.train_file(str(path), str(model), None,
                        learning.TrainOptions(features=("gps_time", "intensity"), params=rf.ForestParams(n_trees=2),
                                              block_m=10.0))
    assert load_model(str(model)).meta["gps_time"] == rf.GPS_TIME_OF_WEEK


def test_adjusted_standard_gps_time_is_put_back_on_its_week(tmp_path):
    """Adjusted standard GPS time (global encoding bit 0: GPS time less 1e9 s, the rule for LAS 1.4's
    formats 6-10) was taken modulo a week as stored, so its "week" turned over at 265,600 s of the real
    one (Wednesday 01:46:40 GPS, late morning in Australia): a flight then got times near 604,800 and
    near 0 in one pass. It is put back on the week first; a model trained before gets the old values."""
    import laspy
    from groundsieve.core.io import read_cloud
    rng = np.random.default_rng(4)
    n = 2000
    week_s = np.sort(rng.uniform(265_590.0, 265_610.0, n))  # a 20 s pass across the old turn-over
    adjusted = 2300 * rf.GPS_WEEK_S + week_s - rf.ADJUSTED_STANDARD_OFFSET_S
    las = new_las(rng.uniform(0, 50, n), rng.uniform(0, 50, n), rng.normal(0, 0.1, n), point_format=1,
                  gps_time=adjusted)
    las.header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
    path = tmp_path / "adjusted.las"
    write_las(las, str(path))
    cloud = read_cloud(str(path))
    week = rf.feature_matrix(cloud, ["gps_time"])[:, 0]
    np.testing.assert_allclose(week, week_s, atol=0.05)
    assert np.all(np.diff(week) >= 0)  # one pass, one run of times
    old = rf.feature_matrix(cloud, ["gps_time"], gps_time="mod")[:, 0]
    assert old.max() > 604_700 and old.min() < 100  # the old turn-over, kept for the models trained with it
    assert rf.GPS_TIME_MODES[rf.GPS_TIME_MOD_WEEK] == "mod" and rf.GPS_TIME_MODES[rf.GPS_TIME_OF_WEEK] == "week"
    # a file of GPS week time (bit 0 clear) is read as before
    las.header.global_encoding.gps_time_type = laspy.header.GpsTimeType.WEEK_TIME
    las.gps_time = week_s
    write_las(las, str(tmp_path / "week.las"))
    np.testing.assert_allclose(rf.feature_matrix(read_cloud(str(tmp_path / "week.las")), ["gps_time"])[:, 0], week_s,
                               atol=0.05)


def test_a_colour_model_is_priced_as_its_whole_run_and_runs_in_tiles_beyond_the_budget(tmp_path):
    """A colour model on one file of a UAV flight (9.5 M points) was refused as "a survey: classify each file on
    its own", the file being priced at a ground filter's 330 bytes a point and so tiled: such a model's whole run is
    now priced at its own measured cost (a reviewer). Beyond the budget, with a tile size, or with a stray point
    far away, the file runs in buffered tiles, which read the colour from their records: the whole run's classes."""
    from groundsieve.core.engine.tiles import BYTES_PER_POINT, TileOptions, needs_tiling, whole_run_bytes
    from groundsieve.core.io.lasfiles import scan_header
    rng = np.random.default_rng(3)
    n = 20000
    x, y = rng.uniform(0, 60, n), rng.uniform(0, 60, n)
    cls = np.where(rng.random(n) < 0.5, 2, 1).astype(np.uint8)
    red = np.where(cls == 2, rng.uniform(20000, 40000, n), rng.uniform(40000, 65000, n)).astype(np.uint16)
    path = str(tmp_path / "flight.las")
    write_las(new_las(x, y, rng.normal(0, 0.1, n), point_format=3, classification=cls, red=red, green=red, blue=red),
              path)
    model = str(tmp_path / "c1.npz")
    learning.train_file(path, model, None, learning.TrainOptions(features=("red", "green", "blue"),
                                                                 params=rf.ForestParams(n_trees=2), block_m=10.0))
    estimate = learning._WholeModelRun(model_file.load_model(model))
    assert not estimate.makes_grids  # (colour alone: no grid, whatever the extent)
    need = whole_run_bytes(scan_header(path), estimate)
    assert need < 0.7 * n * BYTES_PER_POINT
    budget_mb = 1.2 * need / 2 ** 20  # between its own price and a ground filter's
    assert not needs_tiling(path, TileOptions(memory_budget_mb=budget_mb), algorithm=estimate)
    _cloud, predicted = learning.classify_file(path, str(tmp_path / "whole.las"), model,
                                               tiling=TileOptions(memory_budget_mb=budget_mb))
    assert len(predicted) == n
    import laspy
    from groundsieve.core.engine.tiles import TiledRun
    for name, tiling in (("budget", TileOptions(memory_budget_mb=budget_mb / 4)), ("size", TileOptions(tile_size_m=20.0))):
        said = []
        run = learning.classify_file(path, str(tmp_path / f"{name}.las"), model, tiling=tiling, log=said.append)
        assert isinstance(run, TiledRun), name
        # one figure for the file (a reviewer read 28 MB from rfclassify, then 45 MB from the engine)
        figures = [line for line in said if "run whole it would take about" in line]
        assert len(figures) == (name == "budget"), said
        np.testing.assert_array_equal(np.asarray(laspy.read(tmp_path / f"{name}.las").classification), predicted)
    # one point 20 km away: tiled for its extent, which no memory budget changes (a code reviewer's "22,901 MB,
    # more than the memory budget (30,000 MB)")
    stray = str(tmp_path / "stray.las")
    write_las(new_las(np.r_[x, 20000.0], np.r_[y, 20000.0], np.r_[rng.normal(0, 0.1, n), 0.0], point_format=3,
                      classification=np.r_[cls, 1], red=np.r_[red, 30000], green=np.r_[red, 30000],
                      blue=np.r_[red, 30000]), stray)
    run = learning.classify_file(stray, str(tmp_path / "stray_classified.las"), model,
                                 tiling=TileOptions(memory_budget_mb=30000))
    assert isinstance(run, TiledRun)
    got = np.asarray(laspy.read(tmp_path / "stray_classified.las").classification)
    np.testing.assert_array_equal(got[:n], predicted)


def test_colour_of_the_other_depth_is_rescaled_and_a_feature_outside_its_range_is_warned_about(tmp_path):
    """A model trained on 16-bit colour given 8-bit colour had predicted one class for every point, "done" (a
    reviewer's case): the colour is now read in the model's depth (x 257, or / 257 the other way), said in the
    log, and the predictions are those of the same cloud in the model's depth. A feature whose values lie outside
    the range the model learnt it in (1st-99th percentile) on half the points or more, on either side, is warned
    about: intensity of another scaling, and the GPS time of the rest of a flight (82 % outside, 81 % after the
    patch and 1 % before, had passed a test of 90 % on one side)."""
    rng = np.random.default_rng(5)
    n = 4000
    x, y = rng.uniform(0, 60, n), rng.uniform(0, 60, n)
    cls = np.where(rng.random(n) < 0.5, 2, 1).astype(np.uint8)
    red = np.where(cls == 2, rng.uniform(20000, 40000, n), rng.uniform(40000, 65000, n)).astype(np.uint16)
    z = rng.normal(0, 0.1, n)
    kw = dict(point_format=3, classification=cls)
    write_las(new_las(x, y, z, red=red, green=red, blue=red, intensity=red, gps_time=100 + 10 * rng.random(n), **kw),
              str(tmp_path / "sixteen.las"))
    low = red // 256
    before_after = np.where(rng.random(n) < 0.5, 50.0, 200.0) + 10 * rng.random(n)
    write_las(new_las(x, y, z, red=low, green=low, blue=low, intensity=low, gps_time=before_after, **kw),
              str(tmp_path / "eight.las"))
    models = {}
    for features, source in ((("red", "green", "blue"), "sixteen"), (("red", "green", "blue"), "eight"),
                             (("intensity",), "sixteen"), (("gps_time", "red"), "sixteen")):
        models[features, source] = str(tmp_path / f"{'_'.join(features)}_{source}.npz")
        learning.train_file(str(tmp_path / f"{source}.las"), models[features, source], None,
                            learning.TrainOptions(features=features, params=rf.ForestParams(n_trees=2),
                                                  block_m=10.0))

    def run(features, source, name):
        lines = []
        _cloud, predicted = learning.classify_file(str(tmp_path / f"{name}.las"), str(tmp_path / f"out_{name}.las"),
                                                   models[features, source], log=lines.append)
        return predicted, [line for line in lines if "outside the range" in line], \
            [line for line in lines if "its colour is" in line]

    colour = ("red", "green", "blue")
    same, warned, depth = run(colour, "sixteen", "sixteen")
    assert not warned and not depth
    other, warned, depth = run(colour, "sixteen", "eight")
    assert not warned and len(depth) == 1 and "8-bit" in depth[0] and "multiplied by 257" in depth[0]
    assert np.mean(other == same) > 0.99 and set(np.unique(other)) == {1, 2}
    back, warned, depth = run(colour, "eight", "sixteen")  # an 8-bit model given 16-bit colour
    assert len(depth) == 1 and "divided by 257" in depth[0] and set(np.unique(back)) == {1, 2}
    _p, warned, depth = run(("intensity",), "sixteen", "eight")  # (intensity has no depth to mend)
    assert not depth and len(warned) == 1 and "the feature 'intensity'" in warned[0]
    assert "100% of the points" in warned[0] and "another sensor" in warned[0]
    # large values whole, not 2.04e+04 (a surveyor read "learnt: 1.92e+04 to 1.92e+04" for GPS seconds)
    assert "(learnt: 20," in warned[0] and "e+0" not in warned[0]
    _p, warned, depth = run(("gps_time", "red"), "sixteen", "eight")  # half before the patch's time, half after
    assert [w for w in warned if "the feature 'gps_time'" in w and "the rest of a flight" in w], warned
    # on a survey, once for the survey from a sample of its files' first points (the tiles' own logs go nowhere)
    from groundsieve.core.engine.tiles import TileOptions
    (tmp_path / "survey").mkdir()
    import shutil
    shutil.copy(tmp_path / "eight.las", tmp_path / "survey" / "eight.las")
    lines = []
    learning.classify_file(str(tmp_path / "survey"), str(tmp_path / "survey_out.vpc"), models[("gps_time", "red"),
                                                                                            "sixteen"],
                           tiling=TileOptions(workers=1), log=lines.append)
    gps = [line for line in lines if "the feature 'gps_time'" in line]
    assert len(gps) == 1 and str(tmp_path / "survey") in gps[0], lines
    assert sum("multiplied by 257" in line for line in lines) == 1, lines


def test_a_cloud_of_another_density_is_warned_about_for_a_model_of_radius_features(tmp_path):
    """Features counted within fixed spheres (the paper's eigen features) change with the point density: a C5
    model of 150 points/m² applied to a flight of 20 lost 2 points of total error without a word (a reviewer).
    The model keeps its training density; rfclassify warns from 3 times denser or sparser."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    for name, density, seed in (("dense", 12.0, 1), ("same", 12.0, 2), ("sparse", 2.0, 3)):
        scene = make_scene(SceneSpec(size_m=50.0, density_per_m2=density, seed=seed))
        scene.classification[:] = np.where(scene.classification == 2, 2, 1)
        write_scene(scene, str(tmp_path / f"{name}.laz"))
    model = str(tmp_path / "m.npz")
    learning.train_file(str(tmp_path / "dense.laz"), model, None,
                        learning.TrainOptions(features=("planarity_r0p6", "intensity"),
                                              params=rf.ForestParams(n_trees=2), block_m=10.0))
    trained = model_file.load_model(model).meta["points_per_unit2"]
    assert 8 < trained < 20
    for name, warned in (("same", False), ("sparse", True)):
        lines = []
        learning.classify_file(str(tmp_path / f"{name}.laz"), str(tmp_path / f"out_{name}.laz"), model,
                               log=lines.append)
        said = [line for line in lines if "points/m² where it has points" in line]
        assert bool(said) == warned, (name, lines)
    assert "planarity_r0p6" in said[0] and "HYBRID" in said[0]
    # a tiled run (a ground model of x, y, z features) says it once, from the first file's sample
    from groundsieve.core.engine.tiles import TileOptions
    geometric = str(tmp_path / "g.npz")
    learning.train_file(str(tmp_path / "dense.laz"), geometric, None,
                        learning.TrainOptions(features=("planarity_r0p6", "verticality_r0p6"),
                                              params=rf.ForestParams(n_trees=2), block_m=10.0))
    for name, warned in (("same", False), ("sparse", True)):
        lines = []
        learning.classify_file(str(tmp_path / f"{name}.laz"), str(tmp_path / f"tiled_{name}.laz"), geometric,
                               tiling=TileOptions(tile_size_m=25.0, workers=1), log=lines.append)
        assert len([line for line in lines if "points/m² where it has points" in line]) == warned, (name, lines)
    # the measure holds on sparse clouds too (2 m cells had a floor of about 0.25 a m²: 0.1 read as 0.3, a code
    # reviewer), and a stray point does not thin it
    from groundsieve.core.engine.tiles import points_density
    rng = np.random.default_rng(0)
    for density in (0.1, 0.5, 4.0):
        n = int(density * 500 * 500)
        x, y = rng.uniform(0, 500, n), rng.uniform(0, 500, n)
        assert abs(points_density(x, y) / density - 1) < 0.1, density
        assert abs(points_density(np.r_[x, 20000.0], np.r_[y, 20000.0]) / density - 1) < 0.1, density


def test_the_split_as_made_is_reported_and_a_set_far_below_its_share_is_warned_about(tmp_path):
    """The report showed the planned fractions (60/20/20) where a reviewer's patch, few blocks across, made
    49/8/43 %: the report gives both, and a set under half its planned share is warned about."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    scene = make_scene(SceneSpec(size_m=80.0, density_per_m2=4.0, seed=41))
    scene.classification[:] = np.where(scene.classification == 2, 2, 1)
    write_scene(scene, str(tmp_path / "patch.laz"))
    for block, warned in ((20.0, False), (35.0, True)):
        report = tmp_path / f"r{block:g}.html"
        run = learning.train_file(str(tmp_path / "patch.laz"), str(tmp_path / f"m{block:g}.npz"), str(report),
                                  learning.TrainOptions(params=rf.ForestParams(n_trees=2), block_m=block))
        said = [w for w in run.warnings if "the spatial split made" in w]
        assert bool(said) == warned, (block, run.warnings)
        assert "planned 60/20/20 %, made " in report.read_text()


def test_a_feature_of_a_radius_is_taken_under_any_spelling_of_its_radius(tmp_path):
    """'planarity_r2p0' (what rftrain's note once suggested) passed the name check and crashed the training with a
    KeyError, the feature being computed as 'planarity_r2' (a code reviewer): names are taken as computed."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    scene = make_scene(SceneSpec(size_m=40.0, density_per_m2=4.0, seed=8))
    scene.classification[:] = np.where(scene.classification == 2, 2, 1)
    write_scene(scene, str(tmp_path / "p.laz"))
    run = learning.train_file(str(tmp_path / "p.laz"), str(tmp_path / "m.npz"), None,
                              learning.TrainOptions(features=("intensity", "planarity_r2p0"),
                                                    params=rf.ForestParams(n_trees=2), block_m=10.0))
    assert run.features == ["intensity", "planarity_r2"]
    _cloud, predicted = learning.classify_file(str(tmp_path / "p.laz"), str(tmp_path / "o.laz"), str(tmp_path / "m.npz"))
    assert set(np.unique(predicted)) <= {1, 2}


def test_one_file_in_tiles_may_write_a_vpc_and_a_wrong_output_is_refused_before_the_model_is_read(tmp_path):
    """As the filters: one file in tiles takes a .vpc output (its classified file in the folder of its name); a run
    whole refuses it; a wrong output is refused before the model is read (a missing model is not what is said)."""
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    scene = make_scene(SceneSpec(size_m=60.0, density_per_m2=2.0, seed=9))
    scene.classification[:] = np.where(scene.classification == 2, 2, 1)
    write_scene(scene, str(tmp_path / "s.laz"))
    model = str(tmp_path / "m.npz")
    learning.train_file(str(tmp_path / "s.laz"), model, None,
                        learning.TrainOptions(params=rf.ForestParams(n_trees=2), block_m=15.0))
    run = learning.classify_file(str(tmp_path / "s.laz"), str(tmp_path / "c.vpc"), model,
                                 tiling=TileOptions(tile_size_m=30.0, workers=1))
    assert run.outputs and os.path.exists(tmp_path / "c" / "s.laz")
    from groundsieve.core.errors import OutputError
    with pytest.raises(OutputError, match="must end in .las or .laz"):
        learning.classify_file(str(tmp_path / "s.laz"), str(tmp_path / "w.vpc"), model)
    with pytest.raises(OutputError, match="must end in .las or .laz"):
        learning.classify_file(str(tmp_path / "s.laz"), str(tmp_path / "w.txt"), str(tmp_path / "none.npz"))


def test_rftrain_says_where_a_ground_model_runs_and_warns_of_features_that_stand_for_the_patch(tmp_path):
    """A reviewer's C5 ground model was told it ran in the hybrid filter and on surveys, which both refused it,
    and the survey's refusal told it to train a ground model; GPS time and scan angle were found misleading only
    after classifying the flight; in feet, 'a preset's lengths are converted' stood before C5's radii read in feet."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    scene = make_scene(SceneSpec(size_m=60.0, density_per_m2=3.0, seed=12))
    assert len(set(np.unique(scene.classification)) - {1, 2}) >= 1
    write_scene(scene, str(tmp_path / "patch.laz"))
    said = {}
    for name, features in (("hybrid", tuple(rf.PRESETS["HYBRID"])), ("attributes", ("intensity", "return_number"))):
        lines = []
        learning.train_file(str(tmp_path / "patch.laz"), str(tmp_path / f"{name}.npz"), None,
                            learning.TrainOptions(features=features, params=rf.ForestParams(n_trees=2), block_m=15.0,
                                                  ground_vs_rest=True), log=lines.append)
        said[name] = [line for line in lines if line.startswith("Learning ground (2) against")]
    assert "it runs in the learned hybrid filter too" in said["hybrid"][0]
    assert "would run in the learned hybrid filter too; rfclassify runs these on files and surveys" in \
        said["attributes"][0]
    (tmp_path / "survey").mkdir()
    import shutil
    shutil.copy(tmp_path / "patch.laz", tmp_path / "survey" / "a.laz")
    run = learning.classify_file(str(tmp_path / "survey"), str(tmp_path / "o.vpc"), str(tmp_path / "attributes.npz"))
    assert run.ground_count > 0  # (a model of intensity and returns on a survey had been refused)
    from groundsieve.core.learn.hybrid import Hybrid
    with pytest.raises(InputError, match="features the hybrid filter does not compute"):
        Hybrid(model_path=str(tmp_path / "attributes.npz"))
    # in feet, a training converts nothing, and says so (a filter's words had promised converted lengths)
    import pyproj
    write_scene(scene, str(tmp_path / "feet.laz"), crs_wkt=pyproj.CRS("EPSG:2249").to_wkt())
    lines = []
    learning.train_file(str(tmp_path / "feet.laz"), str(tmp_path / "f.npz"), None,
                        learning.TrainOptions(params=rf.ForestParams(n_trees=2), block_m=15.0), log=lines.append)
    unit = [line for line in lines if "the CRS's unit is US survey foot" in line]
    assert unit and "nothing is converted" in unit[0] and "are converted to it" not in unit[0], lines
    lines = []  # (the scene's LAS has GPS time; every format has a scan angle)
    learning.train_file(str(tmp_path / "patch.laz"), str(tmp_path / "g.npz"), None,
                        learning.TrainOptions(features=("intensity", "gps_time", "scan_angle"),
                                              params=rf.ForestParams(n_trees=2), block_m=15.0), log=lines.append)
    assert [line for line in lines if "gps_time and scan_angle stand for where the patch lies" in line], lines


def _coloured_scene(path, *, size_m=120.0, seed=21, density=3.0):
    """A generated scene as LAS 1.4 with colour that tells the classes apart only roughly (ground brown,
    vegetation green, buildings grey, with noise), scan angle and GPS time; its points and colours."""
    from groundsieve.core.io import new_las
    from groundsieve.core.synthetic import SceneSpec, make_scene, scene_crs_wkt
    scene = make_scene(SceneSpec(size_m=size_m, density_per_m2=density, seed=seed))
    rng = np.random.default_rng(seed)
    cls = scene.classification
    base = np.stack([np.where(cls == 2, v[0], np.where(np.isin(cls, (3, 4, 5)), v[1], v[2]))
                     for v in ((140, 60, 120), (110, 130, 120), (70, 50, 125))], axis=1)
    rgb = np.clip(base + rng.normal(0, 35, base.shape), 0, 255).astype(np.uint16) * 257
    las = new_las(scene.x, scene.y, scene.z, point_format=7, version="1.4", scale=0.001,
                  crs_wkt=scene_crs_wkt(), classification=cls, return_number=scene.return_number,
                  number_of_returns=scene.number_of_returns, intensity=scene.intensity,
                  gps_time=scene.gps_time, scan_angle=np.round(scene.x % 60 - 30).astype(np.int16) * 166,
                  red=rgb[:, 0], green=rgb[:, 1], blue=rgb[:, 2])
    las.write(str(path))
    return las


def test_rfclassify_runs_a_model_of_colour_and_several_classes_tile_by_tile(tmp_path):
    """matrone2024's models (colour, returns, scan angle; ground, vegetation, buildings) on a survey: a
    UAV surveyor's C2 model was refused on the tile folder ("only a ground model ... of x, y, z features"). The
    tiles now read each model's attributes from their records as the whole run reads them from its file and
    write the model's classes: a tiled run, a folder of two files and a COPC copy give the whole run's classes
    and DTM exactly. A file without the model's colour is refused by name; 8-bit colour given to a 16-bit model
    is read in the model's depth, as a whole run of the file reads it."""
    import laspy
    import shutil
    from osgeo import gdal
    from groundsieve.core.engine.tiles import TileOptions, TiledRun
    from groundsieve.core.io import new_las
    train = _coloured_scene(tmp_path / "train.las", seed=3)
    model = str(tmp_path / "c2.npz")
    learning.train_file(str(tmp_path / "train.las"), model, None,
                        learning.TrainOptions(features=("radiometry", "return_number", "number_of_returns",
                                                        "scan_angle", "planarity_r2"),
                                              params=rf.ForestParams(n_trees=6, max_depth=12), block_m=20.0,
                                              ground_vs_rest=False))
    from groundsieve.core.learn.model_file import load_model
    assert len(load_model(model).classes) >= 3 and len(train.points) > 20_000
    las = _coloured_scene(tmp_path / "scene.laz", seed=8)
    scene = str(tmp_path / "scene.laz")
    said = []
    _cloud, whole = learning.classify_file(scene, str(tmp_path / "whole.laz"), model,
                                           dtm_path=str(tmp_path / "whole.tif"), log=said.append)
    assert len(np.unique(whole)) >= 3
    counts = [line for line in said if line.startswith("class ")]

    def dtm(name):
        return gdal.Open(str(tmp_path / name)).ReadAsArray()
    lines = []
    run = learning.classify_file(scene, str(tmp_path / "tiled.laz"), model, dtm_path=str(tmp_path / "tiled.tif"),
                                 tiling=TileOptions(tile_size_m=40.0, workers=2, parallel="threads"), log=lines.append)
    assert isinstance(run, TiledRun) and run.tiles >= 9
    np.testing.assert_array_equal(np.asarray(laspy.read(tmp_path / "tiled.laz").classification), whole)
    np.testing.assert_array_equal(dtm("tiled.tif"), dtm("whole.tif"))
    # the filters' notes on the input's classes, not said by the whole run, are not said in tiles (a reviewer read
    # --last-returns advice there); the DTM's notes are said by both (the whole run had said none)
    assert not any("Classes of the input replaced" in line or "--last-returns" in line or "became ground" in line
                   for line in lines), lines
    dtm_notes = [line for line in lines if "isolated spike" in line or "isolated pit" in line]
    assert dtm_notes and [line for line in said if "isolated spike" in line or "isolated pit" in line] == dtm_notes
    assert [line for line in lines if line.startswith("class ")] == counts and len(counts) == 1  # (as the whole run)
    # a folder of two files, with worker processes
    from groundsieve.tests.core.scenes import split_west_east
    folder = tmp_path / "survey"
    west = split_west_east(las, folder)
    run = learning.classify_file(str(folder), str(tmp_path / "classified.vpc"), model,
                                 tiling=TileOptions(workers=2, parallel="processes"))
    for name, part in (("west.laz", west), ("east.laz", ~west)):
        np.testing.assert_array_equal(np.asarray(laspy.read(tmp_path / "classified" / name).classification),
                                      whole[part], err_msg=name)
    # a COPC copy, read by bounds with every layer decompressed
    from groundsieve.tests.core.test_copc import write_copc
    write_copc(tmp_path / "scene.copc.laz", laspy.read(scene))
    cloud, whole_copc = learning.classify_file(str(tmp_path / "scene.copc.laz"), None, model)
    run = learning.classify_file(str(tmp_path / "scene.copc.laz"), str(tmp_path / "copc_tiled.laz"), model,
                                 tiling=TileOptions(tile_size_m=40.0, workers=1))
    np.testing.assert_array_equal(np.asarray(laspy.read(tmp_path / "copc_tiled.laz").classification), whole_copc)
    # 8-bit colour: read in the model's depth, said once for the survey (not in every tile)
    eight = new_las(las.x, las.y, las.z, point_format=7, version="1.4", scale=0.001, crs_wkt=las.header.parse_crs().to_wkt(),
                    classification=las.classification, return_number=las.return_number,
                    number_of_returns=las.number_of_returns, intensity=las.intensity, gps_time=las.gps_time,
                    scan_angle=las.scan_angle, red=np.asarray(las.red) // 257, green=np.asarray(las.green) // 257,
                    blue=np.asarray(las.blue) // 257)
    eight.write(str(tmp_path / "eight.laz"))
    said = []
    _cloud, whole8 = learning.classify_file(str(tmp_path / "eight.laz"), None, model, log=said.append)
    assert any("multiplied by 257" in line for line in said), said
    said = []
    learning.classify_file(str(tmp_path / "eight.laz"), str(tmp_path / "eight_tiled.laz"), model,
                           tiling=TileOptions(tile_size_m=40.0, workers=1), log=said.append)
    assert sum("multiplied by 257" in line for line in said) == 1, said
    np.testing.assert_array_equal(np.asarray(laspy.read(tmp_path / "eight_tiled.laz").classification), whole8)
    # a file of the survey without colour: refused by name before any tile, nothing written
    plain = new_las(las.x[west], las.y[west], las.z[west], point_format=1, scale=0.001,
                    crs_wkt=las.header.parse_crs().to_wkt(), classification=las.classification[west])
    shutil.rmtree(folder)
    folder.mkdir()
    plain.write(str(folder / "a_plain.laz"))
    shutil.copy(tmp_path / "scene.laz", folder / "b.laz")
    with pytest.raises(InputError, match=r"a_plain.laz: the model .*c2.npz reads blue, green, red, which this file "
                                         r"does not have \(point format 1, no colour\)"):
        learning.classify_file(str(folder), str(tmp_path / "refused.vpc"), model)
    assert not (tmp_path / "refused.vpc").exists() and not (tmp_path / "refused").exists()


def test_a_surveys_files_give_the_features_of_their_own_whole_runs(tmp_path):
    """A code reviewer broke the tiles' equality with whole runs: colour depth judged from each file's first
    points (a 16-bit file starting dark read as 8-bit: 62,436 of 142,315 points otherwise), one depth for a folder
    of 8-bit and 16-bit files, a file whose first points have no colour refused, stored features read whole and
    computed in tiles (DTM cells 16 m apart), a model of intensity in place of colour refused whole and run in
    tiles, and the DTM's 30 m buffer read as 30 ft in feet. Each file is now judged from all its points."""
    import laspy
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.io import new_las
    las = _coloured_scene(tmp_path / "train.laz", seed=3)
    model = str(tmp_path / "c.npz")
    learning.train_file(str(tmp_path / "train.laz"), model, None,
                        learning.TrainOptions(features=("radiometry", "return_number", "planarity_r2"),
                                              params=rf.ForestParams(n_trees=4, max_depth=10), block_m=20.0,
                                              ground_vs_rest=False))
    scene = _coloured_scene(tmp_path / "scene.laz", seed=8)
    n = len(scene.points)
    rgb = {c: np.asarray(scene[c]) for c in ("red", "green", "blue")}

    def variant(name, colour, stored=None):
        out = new_las(scene.x, scene.y, scene.z, point_format=7, version="1.4", scale=0.001,
                      crs_wkt=scene.header.parse_crs().to_wkt(), classification=scene.classification,
                      return_number=scene.return_number, number_of_returns=scene.number_of_returns,
                      intensity=scene.intensity, gps_time=scene.gps_time, scan_angle=scene.scan_angle,
                      extra=None if stored is None else {"planarity_r2": stored}, **colour)
        out.write(str(tmp_path / name))
        return str(tmp_path / name)
    dark = {c: np.r_[v[:-10] // 257, v[-10:]] for c, v in rgb.items()}  # 16-bit, dark but for its last points
    eight = {c: v // 257 for c, v in rgb.items()}
    zero = {c: np.r_[np.zeros(n - 10, dtype=np.uint16), v[-10:]] for c, v in rgb.items()}
    stored = np.random.default_rng(0).random(n).astype(np.float32)
    cases = {"dark.laz": variant("dark.laz", dark), "eight.laz": variant("eight.laz", eight),
             "zero.laz": variant("zero.laz", zero), "stored.laz": variant("stored.laz", rgb, stored)}
    wholes = {name: learning.classify_file(path, None, model)[1] for name, path in cases.items()}
    for name, path in cases.items():
        learning.classify_file(path, str(tmp_path / f"t_{name}"), model, tiling=TileOptions(tile_size_m=40.0, workers=1))
        np.testing.assert_array_equal(np.asarray(laspy.read(tmp_path / f"t_{name}").classification), wholes[name],
                                      err_msg=name)
    # a folder of an 8-bit file (the west half) and a 16-bit one (the east): each read in its own depth
    folder = tmp_path / "mixed"
    folder.mkdir()
    west = np.asarray(scene.x) < np.median(np.asarray(scene.x))
    _c, sixteen = learning.classify_file(str(tmp_path / "scene.laz"), None, model)
    for name, source, part in (("a.laz", cases["eight.laz"], west), ("b.laz", str(tmp_path / "scene.laz"), ~west)):
        full = laspy.read(source)
        piece = laspy.LasData(full.header)
        piece.points = full.points[part]
        piece.write(folder / name)
    said = []
    learning.classify_file(str(folder), str(tmp_path / "out.vpc"), model, tiling=TileOptions(workers=1),
                           log=said.append)
    for name, whole, part in (("a.laz", wholes["eight.laz"], west), ("b.laz", sixteen, ~west)):
        np.testing.assert_array_equal(np.asarray(laspy.read(tmp_path / "out" / name).classification),
                                      whole[part], err_msg=name)
    assert [line for line in said if "1 of the 2 files (a.laz): their colour is 8-bit" in line], said
    # a model that learnt intensity in place of colour (its training cloud had none): refused on a coloured file,
    # whole and on a survey
    plain = new_las(las.x, las.y, las.z, point_format=1, scale=0.001, classification=las.classification,
                    intensity=las.intensity, return_number=las.return_number, number_of_returns=las.number_of_returns)
    plain.write(str(tmp_path / "plain.laz"))
    learning.train_file(str(tmp_path / "plain.laz"), str(tmp_path / "i.npz"), None,
                        learning.TrainOptions(features=("radiometry", "return_number"),
                                              params=rf.ForestParams(n_trees=2), block_m=20.0))
    with pytest.raises(InputError, match="trained on"):
        learning.classify_file(cases["eight.laz"], None, str(tmp_path / "i.npz"))
    with pytest.raises(InputError, match="eight.laz: the file has colour .RGB., and the model .*learnt the intensity"):
        learning.classify_file(cases["eight.laz"], str(tmp_path / "i.laz"), str(tmp_path / "i.npz"),
                               tiling=TileOptions(tile_size_m=40.0))
    # the DTM's least buffer is 30 m in the CRS's unit; without a DTM the features' reach alone (none for attributes)
    assert learning.ModelGround(model_path=model, metres_per_unit=0.3048).reach_m >= 30 / 0.3048 - 1e-9
    assert learning.ModelGround(model_path=model, dtm=False).reach_m < 10
    learning.train_file(str(tmp_path / "plain.laz"), str(tmp_path / "a.npz"), None,
                        learning.TrainOptions(features=("intensity", "return_number"), params=rf.ForestParams(n_trees=2),
                                              block_m=20.0, ground_vs_rest=False))
    attributes = learning.ModelGround(model_path=str(tmp_path / "a.npz"), dtm=False)
    assert attributes.reach_m == 0 and attributes.min_tile_points == 1
    # a few points far off, in a tile of their own with no buffer: classified (they had kept their input class)
    far = new_las(np.r_[las.x, las.x[:5] + 500], np.r_[las.y, las.y[:5]], np.r_[las.z, las.z[:5]], point_format=1,
                  scale=0.001, classification=np.r_[las.classification, np.full(5, 9, np.uint8)],
                  intensity=np.r_[las.intensity, las.intensity[:5]],
                  return_number=np.r_[las.return_number, las.return_number[:5]],
                  number_of_returns=np.r_[las.number_of_returns, las.number_of_returns[:5]])
    far.write(str(tmp_path / "far.laz"))
    _c, whole_far = learning.classify_file(str(tmp_path / "far.laz"), None, str(tmp_path / "a.npz"))
    learning.classify_file(str(tmp_path / "far.laz"), str(tmp_path / "far_t.laz"), str(tmp_path / "a.npz"),
                           tiling=TileOptions(tile_size_m=40.0, buffer_m=0.0, workers=1))
    got = np.asarray(laspy.read(tmp_path / "far_t.laz").classification)
    np.testing.assert_array_equal(got, whole_far)
    assert not np.any(got[-5:] == 9)
    # one job of an array reads its file's colour and its neighbours', not the survey's (a reviewer)
    apart = tmp_path / "apart"
    apart.mkdir()
    for name, shift in (("a.laz", 0.0), ("b.laz", 5000.0)):
        moved = laspy.read(str(tmp_path / "scene.laz"))
        moved.x = np.asarray(moved.x) + shift
        moved.write(str(apart / name))
    said = []
    learning.classify_file(str(apart), str(tmp_path / "job" / "{name}.laz"), model,
                           tiling=TileOptions(only="a.laz", workers=1), log=said.append)
    assert [line for line in said if line.startswith("Read the colour of 1 file(s)")], said


def test_a_surveys_range_warning_samples_each_file_throughout(tmp_path):
    """A flight's GPS time grows through each file: the survey's warning, taken from each file's first points,
    said 67 % of the points lay outside the model's learnt range where the whole run said 89 % (a UAV reviewer);
    here the first points are all within it, and the warning did not come. It is now sampled throughout."""
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.io import new_las
    rng = np.random.default_rng(5)

    def flight(path, n, t0, t1):
        x, y = rng.uniform(0, 100, n), rng.uniform(0, 100, n)
        cls = np.where(rng.random(n) < 0.5, 2, 1).astype(np.uint8)
        write_las(new_las(x, y, rng.normal(0, 0.1, n), point_format=1, classification=cls,
                          intensity=np.where(cls == 2, 100, 200).astype(np.uint16), gps_time=np.linspace(t0, t1, n)),
                  str(path))
    flight(tmp_path / "patch.las", 5_000, 1000.0, 1040.0)
    model = str(tmp_path / "m.npz")
    learning.train_file(str(tmp_path / "patch.las"), model, None,
                        learning.TrainOptions(features=("intensity", "gps_time"), params=rf.ForestParams(n_trees=2),
                                              block_m=10.0))
    (tmp_path / "survey").mkdir()
    flight(tmp_path / "survey" / "a.las", 120_000, 1000.0, 1100.0)  # the first 40 % within the patch's time
    for where, tiling in ((str(tmp_path / "survey" / "a.las"), None), (str(tmp_path / "survey"), TileOptions(workers=1))):
        said = []
        learning.classify_file(where, None if tiling is None else str(tmp_path / "o.vpc"), model, tiling=tiling,
                               log=said.append)
        assert [line for line in said if "the feature 'gps_time' lies outside" in line], (where, said)
