"""DTM classes (``DTMOptions.classes``, the dialog's DTM_CLASSES, the CLI's --dtm-classes): points of
the named input classes enter the DTM with the ground. A flood modeller's delivery has the river's
surface classified water (9): with the vendor's classes kept, water is never ground, and without
the DTM classes the DTM bridges the channel from bank to bank; with ``classes=9`` it holds the
water surface, in a whole-cloud run and in a tiled one alike. The run says how many kept points
stay out of the DTM."""
from __future__ import annotations

import numpy as np
import pytest

from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
from groundsieve.core.errors import InvalidParameterError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.io import new_las, write_las

BANK_Z, WATER_Z = 10.0, 6.0
#: the river: a channel 20 m wide, x from 50 to 70 m, its surface 4 m below the banks
RIVER = (50.0, 70.0)


def river_points(rng, n):
    """x, y, z, classes and the channel mask of flat banks at 10 m (ground) and a 20 m channel of
    water points at 6 m (class 9) over 120 x 120 m."""
    x, y = rng.uniform(0, 120, n), rng.uniform(0, 120, n)
    wet = (x > RIVER[0]) & (x < RIVER[1])
    z = np.where(wet, WATER_Z, BANK_Z) + rng.normal(0, 0.02, n)
    return x, y, z, np.where(wet, 9, 2).astype(np.uint8), wet


@pytest.fixture(scope="module")
def river(tmp_path_factory):
    """Flat banks at 10 m (ground), a 20 m channel of water points at 6 m (class 9), a few trees."""
    rng = np.random.default_rng(3)
    n = 24_000
    x, y, z, cls, wet = river_points(rng, n)
    tree = (~wet) & (rng.random(n) < 0.05)
    z[tree] += rng.uniform(3, 12, tree.sum())
    cls[tree] = 5
    path = tmp_path_factory.mktemp("river") / "river.laz"
    write_las(new_las(x, y, z, classification=cls), str(path))
    return path


def _channel_values(dtm_path):
    from osgeo import gdal
    ds = gdal.Open(str(dtm_path))
    values = ds.ReadAsArray().astype(float)
    x0, cell = ds.GetGeoTransform()[0], ds.GetGeoTransform()[1]
    cols = x0 + (np.arange(values.shape[1]) + 0.5) * cell
    inside = (cols > RIVER[0] + 3) & (cols < RIVER[1] - 3)
    return values[5:-5, inside]


@pytest.mark.parametrize("tiled", [False, True], ids=["whole", "tiled"])
def test_water_enters_the_dtm_when_named_and_the_run_says_what_stays_out(river, tmp_path, tiled):
    tiling = TileOptions(tile_size_m=50.0, workers=1, parallel="threads") if tiled else TileOptions()
    options = FilterOptions(keep_existing_classes=True, tiling=tiling)
    logs = {}
    for name, classes in (("without", ()), ("with", "9")):
        lines = []
        run_ground_filter(str(river), str(tmp_path / f"{name}.laz"), SMRF(), options=options,
                          dtm_path=str(tmp_path / f"{name}.tif"), dtm=DTMOptions(classes=classes), log=lines.append)
        logs[name] = lines
    bridged = _channel_values(tmp_path / "without.tif")
    held = _channel_values(tmp_path / "with.tif")
    # without: the channel is interpolated between the banks (10 m); with 9: the water surface (6 m)
    assert np.nanmedian(bridged) == pytest.approx(BANK_Z, abs=0.1)
    assert np.nanmedian(held) == pytest.approx(WATER_Z, abs=0.1) and np.nanmax(np.abs(held - WATER_Z)) < 0.2
    note = [line for line in logs["without"] if line.startswith("DTM: ") and "stay out" in line]
    assert len(note) == 1 and "9 (water): " in note[0] and "5 (high vegetation): " in note[0], logs["without"]
    assert "name it in the DTM classes" in note[0]
    # with 9 named only the trees stay out
    note = [line for line in logs["with"] if line.startswith("DTM: ") and "stay out" in line]
    assert len(note) == 1 and "9 (water)" not in note[0] and "5 (high vegetation)" in note[0]
    assert "name it in the DTM classes" not in note[0]  # (9 is named: no advice to name one; a flood modeller)
    # the classified cloud keeps the vendor's water either way
    import laspy
    las = laspy.read(str(tmp_path / "with.laz"))
    assert (np.asarray(las.classification)[np.asarray(las.x) > RIVER[0] + 1] != 2).any()
    assert set(np.unique(np.asarray(las.classification))) >= {9, 5}


def test_without_kept_classes_nothing_is_said_and_named_classes_still_enter(river, tmp_path):
    """Without kept classes every point is filtered (water becomes 2 or 1): no note; a named class
    enters the DTM by its class in the input, whatever the filter made of it."""
    lines = []
    run_ground_filter(str(river), str(tmp_path / "o.laz"), SMRF(), dtm_path=str(tmp_path / "d.tif"),
                      dtm=DTMOptions(classes=[9]), log=lines.append)
    assert not [line for line in lines if "stay out" in line]
    assert np.nanmedian(_channel_values(tmp_path / "d.tif")) == pytest.approx(WATER_Z, abs=0.1)


@pytest.mark.parametrize("bad, words", [("water", "DTM classes: 'water' is not a class code"),
                                        ("300", "DTM classes: class codes are 0-255 (got 300)")])
def test_bad_dtm_classes_are_refused_in_words(bad, words):
    with pytest.raises(InvalidParameterError) as err:
        DTMOptions(classes=bad)
    assert str(err.value).startswith(words)


def test_a_data_gap_is_left_empty_beyond_the_maximum_distance(tmp_path):
    """A survey with a 60 m square hole (a missing tile): without a limit the triangulation bridges
    it (a whole run; a tiled run bridges it only where a tile has points of its own, so its DTM
    there depends on the tiling); with a maximum distance of 10 m the cells farther than that from
    every ground point are nodata, those near the gap's edge are interpolated as before, and a
    tiled run (buffer larger than the distance) gives the same DTM as a whole run. (Tiles of 40 m:
    each holds points of its own; a tile without any gives no DTM block at all.)"""
    from osgeo import gdal
    rng = np.random.default_rng(8)
    x, y = rng.uniform(0, 150, 40_000), rng.uniform(0, 150, 40_000)
    hole = (np.abs(x - 75) < 30) & (np.abs(y - 75) < 30)
    x, y = x[~hole], y[~hole]
    z = 100 + 0.05 * x + rng.normal(0, 0.01, x.size)
    src = tmp_path / "holey.laz"
    write_las(new_las(x, y, z, classification=np.full(x.size, 2, np.uint8)), str(src))
    arrays = {}
    for name, limit, tiling in (("bridged", 0.0, TileOptions()), ("limited", 10.0, TileOptions()),
                                ("tiled", 10.0, TileOptions(tile_size_m=40.0, workers=1, parallel="threads"))):
        dtm = tmp_path / f"{name}.tif"
        run_ground_filter(str(src), str(tmp_path / f"{name}.laz"), SMRF(), dtm_path=str(dtm),
                          dtm=DTMOptions(max_distance_m=limit), options=FilterOptions(tiling=tiling))
        ds = gdal.Open(str(dtm))
        arrays[name], gt = ds.ReadAsArray(), ds.GetGeoTransform()
    bridged, limited = arrays["bridged"], arrays["limited"]
    cx = gt[0] + (np.arange(bridged.shape[1]) + 0.5) * gt[1]
    cy = gt[3] + (np.arange(bridged.shape[0]) + 0.5) * gt[5]
    # the distance of each cell centre to the hole's edge, inside the hole
    inside = np.minimum.outer(30 - np.abs(cy - 75), 30 - np.abs(cx - 75))
    deep, rim = inside > 12, (inside > 0) & (inside < 8)
    assert (bridged[deep] != -9999).all()          # bridged without a limit
    assert (limited[deep] == -9999).all()          # left empty with one
    np.testing.assert_array_equal(limited[rim], bridged[rim])  # near the edge, as before
    outside = inside < -1
    np.testing.assert_array_equal(limited[outside], bridged[outside])
    assert arrays["tiled"].shape == limited.shape
    np.testing.assert_allclose(arrays["tiled"], limited, atol=1e-4)


def test_a_negative_maximum_distance_is_refused():
    with pytest.raises(InvalidParameterError, match="DTM maximum distance must be >= 0 m"):
        DTMOptions(max_distance_m=-1)


def test_the_input_classes_a_run_replaces_are_said(river, tmp_path):
    """Without KEEP_CLASSES a vendor's classes are replaced by 1 and 2 (the documented rule), and a
    forester's 3,897 water points became ground and entered his DTM without a line in the log."""
    lines = []
    run_ground_filter(str(river), str(tmp_path / "o.laz"), SMRF(), log=lines.append)
    said = [line for line in lines if line.startswith("Classes of the input replaced")]
    assert len(said) == 1 and "5 (high vegetation): " in said[0] and "9 (water): " in said[0], lines
    lines = []
    run_ground_filter(str(river), str(tmp_path / "k.laz"), SMRF(), log=lines.append,
                      options=FilterOptions(keep_existing_classes=True))
    assert not any(line.startswith("Classes of the input replaced") for line in lines)
    # a tiled run says it once, with the counts of the whole (the tiles' own points)
    tiled_lines = []
    run_ground_filter(str(river), str(tmp_path / "t.laz"), SMRF(), log=tiled_lines.append,
                      options=FilterOptions(tiling=TileOptions(tile_size_m=50.0, workers=1, parallel="threads")))
    tiled_said = [line for line in tiled_lines if line.startswith("Classes of the input replaced")]
    assert tiled_said == said, (tiled_said, said)
    # rfclassify on a survey has no keep option: its advice names the filter that has (a surveyor was
    # told to tick an option rfclassify does not offer)
    from groundsieve.core.engine import learning
    from groundsieve.core.learn.hybrid import DEFAULT_MODEL
    rf_lines = []
    learning.classify_file(str(river), str(tmp_path / "r.laz"), DEFAULT_MODEL, log=rf_lines.append,
                           tiling=TileOptions(tile_size_m=50.0, workers=1, parallel="threads"))
    rf_said = [line for line in rf_lines if line.startswith("Classes of the input replaced")]
    assert len(rf_said) == 1 and "run the model in the learned hybrid filter (groundsieve:hybrid" in rf_said[0]
    # ... and its whole run says the same (it had said nothing)
    whole_lines = []
    learning.classify_file(str(river), str(tmp_path / "rw.laz"), DEFAULT_MODEL, log=whole_lines.append)
    assert [line for line in whole_lines if line.startswith("Classes of the input replaced")] == rf_said


def test_a_bridge_deck_made_ground_is_warned_whole_and_tiled(tmp_path):
    """A vendor's bridge deck (17) over the river: without KEEP_CLASSES its points are refiltered,
    those made ground enter the DTM as a dam across the channel, and a flood modeller was told only by
    the note on replaced classes (not a warning, not in --json's warnings). The run now warns with
    the count; kept classes keep the deck out and say nothing."""
    from groundsieve.core.progress import WARNING_PREFIX
    x, y, z, cls, _wet = river_points(np.random.default_rng(5), 30_000)
    deck = (x > RIVER[0] - 10) & (x < RIVER[1] + 10) & (y > 55) & (y < 65)
    z[deck], cls[deck] = BANK_Z + 0.8, 17  # a deck 8 m wide on low abutments: terrain to a filter
    path = tmp_path / "bridge.laz"
    write_las(new_las(x, y, z, classification=cls), str(path))
    for tiling in (TileOptions(), TileOptions(tile_size_m=50.0, workers=1, parallel="threads")):
        lines = []
        out = tmp_path / "o.laz"
        run_ground_filter(str(path), str(out), SMRF(), options=FilterOptions(tiling=tiling), log=lines.append)
        from groundsieve.core.io import read_cloud
        made = int(np.sum(read_cloud(str(out)).classification[deck] == 2))
        assert made > 0  # the case this guards: a filter takes a low deck for terrain
        warned = [line for line in lines if line.startswith(WARNING_PREFIX) and "bridge deck (17)" in line]
        assert len(warned) == 1, lines
        assert f"{made:,} of {int(deck.sum()):,} bridge deck (17) point(s) of the input became ground" in warned[0]
        assert "--keep-classes" in warned[0] and str(path) in warned[0]
    lines = []
    run_ground_filter(str(path), str(tmp_path / "k.laz"), SMRF(), options=FilterOptions(keep_existing_classes=True),
                      log=lines.append)
    assert not any("bridge deck" in line for line in lines if line.startswith(WARNING_PREFIX)), lines


@pytest.mark.parametrize("tiled", [False, True], ids=["whole", "tiled"])
def test_the_vendor_s_ground_a_filter_makes_non_ground_is_counted(tmp_path, tiled):
    """SMRF with the vendor's classes kept made 35 of their ground points 1 at an embankment's end and the DTM
    there 1.9 m lower, without a word (a flood modeller). The run counts them, whole and tiled alike: here
    a roof the vendor left in class 2."""
    import laspy
    rng = np.random.default_rng(5)
    n = 40_000
    x, y = rng.uniform(0, 150, n), rng.uniform(0, 150, n)
    z = 10.0 + rng.normal(0, 0.02, n)
    roof = (np.abs(x - 75) < 10) & (np.abs(y - 75) < 10)
    z[roof] += 8.0
    src = tmp_path / "vendor.laz"
    write_las(new_las(x, y, z, classification=np.full(n, 2, np.uint8)), str(src))
    tiling = TileOptions(tile_size_m=50.0, workers=1, parallel="threads") if tiled else TileOptions()
    logs = []
    out = tmp_path / "out.laz"
    run_ground_filter(str(src), str(out), SMRF(), options=FilterOptions(keep_existing_classes=True, tiling=tiling),
                      log=logs.append)
    after = np.asarray(laspy.read(str(out)).classification)
    demoted = int(np.sum(after != 2))
    assert demoted >= 0.9 * roof.sum()
    said = [line for line in logs if "the input had as ground (2) are not ground now" in line]
    assert said == [f"{demoted:,} of the {n:,} points the input had as ground (2) are not ground now: the filter "
                    "decided again. To make a DTM from the input's ground as it is, use 'DTM from classified "
                    "points' (groundsieve:dtm)."], said
