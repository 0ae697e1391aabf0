"""Points the user (or a previous pass) marked stay as marked (issue 16): withheld points, ignored
classes and kept classes, through the core driver, on small generated LAS files in point formats 1
(withheld = bit 7 of the classification byte) and 6 (LAS 1.4 classification flags)."""
from __future__ import annotations

import laspy
import numpy as np
import pytest

from groundsieve.core.errors import InvalidParameterError
from groundsieve.core.engine.workflow import (FilterOptions, classify_cloud, processable, run_ground_filter,
                                              select_points)
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.io import read_cloud
from groundsieve.core.io.clouds import parse_classes

X0, Y0 = 512000.0, 5403000.0
N_MARKED = 100


def write_scene(path, *, fmt=6, marked=True, seed=0, far_noise=False):
    """A 40 x 40 m plane (z = 0 +- 0.05 m, class 1) with a 10 m high 8 x 8 m block; with
    ``marked``: 100 withheld points 5 m below (classes 1 and 6, some also synthetic), 100 water
    points (class 9) at z = 0, 100 low noise (7) at -20 m and 100 high noise (18) at +40 m, all
    inside the plane's extent; ``far_noise`` adds one class 7 point 5 km away. Returns the kinds."""
    rng = np.random.default_rng(seed)
    n = 40 * 40 * 4
    x = rng.uniform(0, 40, n)
    y = rng.uniform(0, 40, n)
    z = rng.uniform(-0.05, 0.05, n)
    block = (x > 15) & (x < 23) & (y > 15) & (y < 23)
    z[block] += 10.0
    kind = np.where(block, "block", "ground").astype(object)
    cls = np.ones(n, dtype=np.uint8)
    withheld = np.zeros(n, dtype=bool)
    synthetic = np.zeros(n, dtype=bool)
    if marked:
        def add(k, zval, c, w=False):
            nonlocal x, y, z, cls, kind, withheld, synthetic
            ax = rng.uniform(2, 38, N_MARKED)
            ay = rng.uniform(2, 12, N_MARKED)  # away from the block
            x = np.r_[x, ax]
            y = np.r_[y, ay]
            z = np.r_[z, np.full(N_MARKED, zval)]
            cls = np.r_[cls, np.full(N_MARKED, c, dtype=np.uint8)]
            kind = np.r_[kind, np.full(N_MARKED, k, dtype=object)]
            withheld = np.r_[withheld, np.full(N_MARKED, w)]
            synthetic = np.r_[synthetic, np.arange(N_MARKED) % 2 == 0]
        add("withheld", -5.0, 1, True)
        add("water", 0.0, 9)
        add("noise7", -20.0, 7)
        add("noise18", 40.0, 18)
        if far_noise:
            x, y, z = np.r_[x, 5040.0], np.r_[y, 20.0], np.r_[z, 0.0]
            cls = np.r_[cls, np.uint8(7)]
            kind = np.r_[kind, np.array(["far"], dtype=object)]
            withheld, synthetic = np.r_[withheld, False], np.r_[synthetic, False]
    wh = kind == "withheld"
    cls[np.flatnonzero(wh)[::3]] = 6
    header = laspy.LasHeader(point_format=fmt, version="1.4" if fmt >= 6 else "1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([X0, Y0, 0.0])
    las = laspy.LasData(header)
    las.x, las.y, las.z = x + X0, y + Y0, z
    las.classification = cls
    las.withheld = withheld.astype(np.uint8)
    las.synthetic = synthetic.astype(np.uint8)
    las.write(str(path))
    return kind, cls


def read(path):
    las = laspy.read(str(path))
    return (np.asarray(las.classification), np.asarray(las.withheld).astype(bool),
            np.asarray(las.synthetic).astype(bool))


@pytest.mark.parametrize("fmt", [1, 6])
def test_withheld_and_ignored_points_keep_class_and_flags_and_stay_out(tmp_path, fmt):
    src = tmp_path / "in.las"
    kind, cls_in = write_scene(src, fmt=fmt)
    _, wh_in, syn_in = read(src)
    out = tmp_path / "out.las"
    run = run_ground_filter(str(src), str(out), SMRF(), dtm_path=str(tmp_path / "dtm.tif"))
    cls, wh, syn = read(out)
    marked = np.isin(kind, ["withheld", "noise7", "noise18"])
    np.testing.assert_array_equal(cls[marked], cls_in[marked])      # class as read, point by point
    np.testing.assert_array_equal(wh, wh_in)                         # withheld flag as read
    np.testing.assert_array_equal(syn, syn_in)                       # other flags as read
    assert wh[kind == "withheld"].all() and (cls[kind == "withheld"] == 6).sum() == 34
    assert not run.filtered[marked].any() and not run.ground[marked].any()
    assert (cls[kind == "ground"] == 2).mean() > 0.99
    assert (cls[kind == "block"] == 1).all()
    # The DTM is the one made without the marked points: the same raster, cell for cell.
    clean = tmp_path / "clean.las"
    las = laspy.read(str(src))
    las[~marked].write(str(clean))
    ref = run_ground_filter(str(clean), str(tmp_path / "clean_out.las"), SMRF(), dtm_path=str(tmp_path / "d2.tif"))
    assert run.dtm_grid == ref.dtm_grid
    np.testing.assert_array_equal(run.dtm, ref.dtm)
    assert np.nanmin(run.dtm) > -0.06


def test_keep_classes_leaves_every_other_class_as_it_was(tmp_path):
    src = tmp_path / "in.las"
    kind, cls_in = write_scene(src)
    out = tmp_path / "out.las"
    run = run_ground_filter(str(src), str(out), SMRF(), options=FilterOptions(keep_existing_classes=True))
    cls, _, _ = read(out)
    other = ~np.isin(cls_in, [0, 1, 2])
    assert other.sum() == 34 + 3 * N_MARKED
    np.testing.assert_array_equal(cls[other], cls_in[other])
    water = kind == "water"
    assert (cls[water] == 9).all() and not run.ground[water].any()
    assert run.filtered[water].all()  # water is seen by the filter (it shapes the surface), never ground
    # Without the option, water on the ground becomes ground: the option is what keeps it.
    run2 = run_ground_filter(str(src), str(tmp_path / "o2.las"), SMRF())
    assert (run2.classification[water] == 2).all()


def test_ignore_classes_option_generalises_ignore_noise(tmp_path):
    src = tmp_path / "in.las"
    kind, cls_in = write_scene(src)
    cloud = read_cloud(str(src))
    assert FilterOptions().ignored == (7, 18)
    assert FilterOptions(ignore_noise=False).ignored == ()
    assert FilterOptions(ignore_noise=False, ignore_classes="9").ignored == (9,)
    water = kind == "water"
    keep = select_points(cloud, FilterOptions(ignore_classes="7, 9, 18"))
    assert not keep[water | (kind == "withheld")].any()
    run = run_ground_filter(str(src), str(tmp_path / "o.las"), SMRF(),
                            options=FilterOptions(ignore_classes=[7, 9, 18]))
    assert (run.classification[water] == 9).all()
    # Ignoring nothing: noise is filtered, withheld stay out whatever. The high noise is not ground; the
    # low noise here (100 points at one depth over 28 % of a 36 x 10 m strip's cells) is too dense for
    # SMRF's low-outlier refill, which then takes it for ground seen through a canopy's gaps
    # (docs/BENCHMARKS.md, "The low-outlier refill under a closed canopy"): it is told apart by its
    # class only, ignored by default (above).
    run = run_ground_filter(str(src), str(tmp_path / "o3.las"), SMRF(), options=FilterOptions(ignore_classes=""))
    assert run.filtered[np.isin(kind, ["noise7", "noise18"])].all()
    assert (run.classification[kind == "noise18"] == 1).all()
    assert not run.filtered[kind == "withheld"].any()
    np.testing.assert_array_equal(run.classification[kind == "withheld"], cls_in[kind == "withheld"])


def test_ignored_far_noise_does_not_span_the_dtm(tmp_path):
    src = tmp_path / "far.las"
    write_scene(src, far_noise=True)
    run = run_ground_filter(str(src), str(tmp_path / "o.las"), SMRF(), dtm_path=str(tmp_path / "dtm.tif"))
    assert run.dtm_grid.ncols <= 41


def test_every_point_withheld_or_ignored_is_refused_with_the_counts(tmp_path):
    src = tmp_path / "in.las"
    write_scene(src)
    cloud = read_cloud(str(src))
    cloud.withheld = np.ones(len(cloud), dtype=bool)
    with pytest.raises(InvalidParameterError, match=r"no point is left to filter \(6,800 withheld"):
        classify_cloud(cloud, SMRF(), FilterOptions())
    assert not processable(cloud, FilterOptions()).any()


@pytest.mark.parametrize("text, codes", [("7,18", (7, 18)), ("7 18", (7, 18)), ("[7:9]", (7, 8, 9)),
                                         ("2-4, 9", (2, 3, 4, 9)), ("", ()), ([18, 7, 7], (7, 18))])
def test_parse_classes(text, codes):
    assert parse_classes(text) == codes


@pytest.mark.parametrize("text", ["seven", "7-", "9-2", "300", [1.5]])
def test_parse_classes_refuses(text):
    with pytest.raises(InvalidParameterError, match="class"):
        parse_classes(text)


def train_block_model(tmp_path):
    """A model of ground (2) against the block (1) from the height above the lowest point within
    2.5 m, trained on an unmarked scene; returns its path."""
    from groundsieve.core.engine import learning
    from groundsieve.core.learn import rf
    train = tmp_path / "train.las"
    kind, _ = write_scene(train, marked=False, seed=5)
    las = laspy.read(str(train))
    las.classification = np.where(kind == "block", 1, 2).astype(np.uint8)
    las.write(str(train))
    model = tmp_path / "m.npz"
    learning.train_file(str(train), str(model), None,
                        learning.TrainOptions(features=("height_above_min_r2p5",), classes=(1, 2), block_m=10.0,
                                              params=rf.ForestParams(n_trees=5)))
    return model


def test_rfclassify_keeps_marked_points_out_of_features_prediction_and_dtm(tmp_path):
    from groundsieve.core.engine import learning
    # A withheld point 5 m below would change the model's feature for its neighbours if it were used.
    model = train_block_model(tmp_path)
    src = tmp_path / "in.las"
    kind, cls_in = write_scene(src, far_noise=True)
    _, wh_in, syn_in = read(src)
    out, dtm = tmp_path / "out.las", tmp_path / "dtm.tif"
    cloud, predicted = learning.classify_file(str(src), str(out), str(model), dtm_path=str(dtm))
    cls, wh, syn = read(out)
    np.testing.assert_array_equal(cls, predicted)
    marked = np.isin(kind, ["withheld", "noise7", "noise18", "far"])
    np.testing.assert_array_equal(cls[marked], cls_in[marked])
    np.testing.assert_array_equal(wh, wh_in)
    np.testing.assert_array_equal(syn, syn_in)
    assert (cls[kind == "ground"] == 2).mean() > 0.95
    # Exactly what the file without the marked points gives: the same predictions, the same DTM.
    clean = tmp_path / "clean.las"
    laspy.read(str(src))[~marked].write(str(clean))
    _, predicted_clean = learning.classify_file(str(clean), str(tmp_path / "c.las"), str(model),
                                                dtm_path=str(tmp_path / "c.tif"))
    np.testing.assert_array_equal(predicted[~marked], predicted_clean)
    from osgeo import gdal
    a, b = gdal.Open(str(dtm)), gdal.Open(str(tmp_path / "c.tif"))
    assert a.GetGeoTransform() == b.GetGeoTransform() and a.RasterXSize <= 41
    np.testing.assert_array_equal(a.ReadAsArray(), b.ReadAsArray())
    # Ignoring nothing: the noise is predicted (and the far point then spans the DTM's grid).
    _, predicted_all = learning.classify_file(str(src), str(tmp_path / "all.las"), str(model), ignore_classes="")
    assert np.isin(predicted_all[np.isin(kind, ["noise7", "noise18"])], [1, 2]).all()
    np.testing.assert_array_equal(predicted_all[kind == "withheld"], cls_in[kind == "withheld"])


@pytest.mark.parametrize("fmt", [1, 6])
def test_marked_points_stay_as_marked_in_a_tiled_run(tmp_path, fmt):
    """The survey-scale path (buffered tiles, streamed output) applies the same rules: withheld,
    ignored and kept classes as in the whole-cloud run, point by point, and the same DTM."""
    from osgeo import gdal

    from groundsieve.core.engine.tiles import TileOptions
    src = tmp_path / "in.las"
    kind, cls_in = write_scene(src, fmt=fmt)
    _, wh_in, syn_in = read(src)
    whole_opts = FilterOptions(keep_existing_classes=True)
    tiled_opts = FilterOptions(keep_existing_classes=True,
                               tiling=TileOptions(tile_size_m=15.0, workers=1, parallel="threads"))
    run_ground_filter(str(src), str(tmp_path / "whole.las"), SMRF(), options=whole_opts,
                      dtm_path=str(tmp_path / "whole.tif"))
    logged = []
    run = run_ground_filter(str(src), str(tmp_path / "tiled.las"), SMRF(), options=tiled_opts,
                            dtm_path=str(tmp_path / "tiled.tif"), log=logged.append)
    assert run.cloud is None and any("tile" in line.lower() for line in logged)  # really tiled
    cls_w, _, _ = read(tmp_path / "whole.las")
    cls_t, wh_t, syn_t = read(tmp_path / "tiled.las")
    marked = np.isin(kind, ["withheld", "noise7", "noise18", "water"])
    np.testing.assert_array_equal(cls_t[marked], cls_in[marked])
    np.testing.assert_array_equal(wh_t, wh_in)
    np.testing.assert_array_equal(syn_t, syn_in)
    assert (cls_t == cls_w).mean() > 0.999
    whole = gdal.Open(str(tmp_path / "whole.tif")).ReadAsArray()
    tiled = gdal.Open(str(tmp_path / "tiled.tif")).ReadAsArray()
    assert whole.shape == tiled.shape
    inside = (whole != -9999) & (tiled != -9999)
    assert inside.mean() > 0.8 and np.nanmin(tiled[inside]) > -0.06
    assert np.abs(whole[inside] - tiled[inside]).max() < 0.001
