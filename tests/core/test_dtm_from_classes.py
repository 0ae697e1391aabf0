"""A DTM from the classes a cloud already has (``filters.classes.ClassGround``; groundsieve:dtm, the CLI's
``dtm``): a vendor's class 2 becomes the DTM without being filtered again. The roofs and the canopy
stay out of it, the water enters it when named, a whole run and a tiled run give the same DTM, the
input is only read, and a cloud without the classes is refused with the classes it holds, whole or
tiled, leaving nothing behind."""
from __future__ import annotations

import io
import os

import numpy as np
import pytest

from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
from groundsieve.core.errors import Cancelled, GroundSieveError, InputError, InvalidParameterError
from groundsieve.core.filters.classes import ClassGround
from groundsieve.core.io import new_las, write_las
from groundsieve.core.progress import WARNING_PREFIX, Steps

from groundsieve.tests.core.test_dtm_classes import BANK_Z, RIVER, WATER_Z, _channel_values, river_points
from groundsieve.tests.core.test_tiles import _dtm_values

#: the building's footprint (x, y) and how far its roof is above the terrain
HOUSE = (100.0, 130.0, 100.0, 140.0)
ROOF = 8.0


def terrain(x, y):
    return 100.0 + 0.05 * x - 0.02 * y


@pytest.fixture(scope="module")
def delivery(tmp_path_factory):
    """A vendor's classified delivery over 300 x 300 m: a tilted plane of ground (2), one building (6),
    trees (5) over 10 % of it, a few low-noise points (7) far below."""
    rng = np.random.default_rng(1)
    n = 120_000
    x, y = rng.uniform(0, 300, n), rng.uniform(0, 300, n)
    z = terrain(x, y) + rng.normal(0, 0.02, n)
    cls = np.full(n, 2, np.uint8)
    house = (x > HOUSE[0]) & (x < HOUSE[1]) & (y > HOUSE[2]) & (y < HOUSE[3])
    z[house] += ROOF
    cls[house] = 6
    tree = ~house & (rng.random(n) < 0.1)
    z[tree] += rng.uniform(2, 15, tree.sum())
    cls[tree] = 5
    noise = rng.choice(np.flatnonzero(cls == 2), 20, replace=False)
    z[noise] -= 30.0
    cls[noise] = 7
    path = tmp_path_factory.mktemp("delivery") / "delivery.laz"
    write_las(new_las(x, y, z, classification=cls), str(path))
    return path


def _read(path):
    """The DTM's values (NaN = nodata), its west edge, top and cell (test_tiles reads it)."""
    values, transform = _dtm_values(path)
    return values, transform[0], transform[3], transform[1]


def _tiling(tiled):
    return TileOptions(tile_size_m=100.0, workers=2, parallel="threads") if tiled else TileOptions()


@pytest.mark.parametrize("tiled", [False, True], ids=["whole", "tiled"])
def test_the_dtm_is_the_ground_class_under_roofs_and_trees(delivery, tmp_path, tiled):
    before = delivery.read_bytes()
    logs = []
    dtm_path = tmp_path / "dtm.tif"
    run = run_ground_filter(str(delivery), None, ClassGround(),
                            options=FilterOptions(keep_existing_classes=True, tiling=_tiling(tiled)),
                            dtm_path=str(dtm_path), log=logs.append)
    assert delivery.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["dtm.tif"]  # no classified copy, no temporary left
    values, x0, top, cell = _read(dtm_path)
    rows, cols = np.indices(values.shape)
    cx, cy = x0 + (cols + 0.5) * cell, top - (rows + 0.5) * cell
    inside = np.isfinite(values)
    assert inside.mean() > 0.95
    # the terrain everywhere, under the roof and the trees too (noise 7 is ignored: not 30 m below)
    error = np.abs(values - terrain(cx, cy))[inside]
    assert np.percentile(error, 99) < 0.1 and error.max() < 0.5
    under = inside & (cx > HOUSE[0] + 2) & (cx < HOUSE[1] - 2) & (cy > HOUSE[2] + 2) & (cy < HOUSE[3] - 2)
    assert under.sum() > 500 and np.abs(values - terrain(cx, cy))[under].max() < 0.2
    ground = run.ground_count
    assert ground == int(np.sum(_classes(delivery) == 2))
    text = "\n".join(logs)
    assert "points of other classes stay out of it" in text and "5 (high vegetation)" in text and "6 (building)" in text


def _classes(path):
    import laspy
    return np.asarray(laspy.read(str(path)).classification)


def test_a_whole_run_and_a_tiled_run_give_the_same_dtm(delivery, tmp_path):
    made, lines = [], []
    for tiled in (False, True):
        path = tmp_path / f"dtm{int(tiled)}.tif"
        run_ground_filter(str(delivery), None, ClassGround(),
                          options=FilterOptions(keep_existing_classes=True, tiling=_tiling(tiled)),
                          dtm_path=str(path), log=lines.append)
        made.append(_read(path)[0])
    assert not [line for line in lines if "an unclassified survey?" in line]  # (a classified one is not asked)
    assert made[0].shape == made[1].shape
    np.testing.assert_allclose(made[0], made[1], atol=1e-4)


@pytest.mark.parametrize("tiled", [False, True], ids=["whole", "tiled"])
def test_water_enters_the_dtm_when_named_among_the_ground_classes(tmp_path, tiled):
    rng = np.random.default_rng(3)
    x, y, z, cls, _wet = river_points(rng, 24_000)
    src = tmp_path / "river.laz"
    write_las(new_las(x, y, z, classification=cls), str(src))
    levels = {}
    for classes in ("2", "2,9"):
        out = tmp_path / f"dtm{classes.replace(',', '_')}.tif"
        run_ground_filter(str(src), None, ClassGround(classes),
                          options=FilterOptions(keep_existing_classes=True, tiling=_tiling(tiled)),
                          dtm_path=str(out))
        levels[classes] = _channel_values(out)
    assert RIVER  # the channel's middle: bridged from bank to bank, or the water surface
    assert np.nanmedian(levels["2"]) == pytest.approx(BANK_Z, abs=0.05)
    assert np.nanmedian(levels["2,9"]) == pytest.approx(WATER_Z, abs=0.05)


@pytest.mark.parametrize("tiled", [False, True], ids=["whole", "tiled"])
def test_a_cloud_without_the_ground_classes_is_refused_and_nothing_is_written(tmp_path, tiled):
    rng = np.random.default_rng(2)
    n = 20_000
    x, y = rng.uniform(0, 200, n), rng.uniform(0, 200, n)
    src = tmp_path / "unclassified.laz"
    write_las(new_las(x, y, 50 + rng.normal(0, 0.02, n), classification=np.ones(n, np.uint8)), str(src))
    out = tmp_path / "dtm.tif"
    lines = []
    with pytest.raises(InputError if tiled else InvalidParameterError) as err:
        run_ground_filter(str(src), None, ClassGround(),
                          options=FilterOptions(keep_existing_classes=True, tiling=_tiling(tiled)),
                          dtm_path=str(out), log=lines.append)
    if tiled:  # said before the tiles, from the files' first points (it was refused after the last tile alone)
        first_tile = next(k for k, line in enumerate(lines) if line.startswith("Tile 1/"))
        said = [k for k, line in enumerate(lines) if "hold no point of class 2 (1 (unclassified): 20,000)" in line]
        assert len(said) == 1 and said[0] < first_tile and "an unclassified survey?" in lines[said[0]], lines
    text = str(err.value)
    assert str(src) in text and "no point of class 2" in text and "ground filter" in text
    assert tiled == ("the filter" not in text)  # (a tiled run of the DTM from classes names no filter)
    if not tiled:
        assert "1 (unclassified): 20,000" in text
    assert sorted(os.listdir(tmp_path)) == ["unclassified.laz"]


def test_the_dtm_cell_default_follows_a_cloud_in_feet(tmp_path):
    """The default 1 m cell becomes 3 ft (whole feet) on a cloud in feet (workflow.defaults_in_crs_unit), as for
    the filters; a cell set by the user is read in feet."""
    import pyproj
    feet = pyproj.CRS.from_epsg(2264).to_wkt()  # NAD83 / North Carolina (ftUS)
    rng = np.random.default_rng(4)
    n = 20_000
    x, y = 1_000_000 + rng.uniform(0, 300, n), 500_000 + rng.uniform(0, 300, n)
    las = new_las(x, y, 300 + rng.normal(0, 0.05, n), classification=np.full(n, 2, np.uint8), crs_wkt=feet)
    src = tmp_path / "feet.laz"
    write_las(las, str(src))
    for dtm, cell in ((DTMOptions(), 3.0), (DTMOptions(cell_size_m=2.0, cell_set=True), 2.0)):
        out, logs = tmp_path / "dtm.tif", []
        run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True),
                          dtm_path=str(out), dtm=dtm, log=logs.append)
        assert _read(out)[3] == pytest.approx(cell, rel=1e-4)
        # the log's lengths in feet too (the triangulation's line said "cells of 3.28083 m": a surveyor)
        (line,) = [text for text in logs if text.startswith("DTM: triangulating")]
        assert line.endswith(f"cells of {cell:g} ft ..."), line


@pytest.mark.parametrize("given, message", [("", "name at least one class"), ("2,x", "'x' is not a class code"),
                                            (300, "0-255"), ("5-3", "ends before it starts")])
def test_bad_ground_classes_are_refused_in_words(given, message):
    with pytest.raises(InvalidParameterError, match=message):
        ClassGround(given)


def test_classes_are_parsed_as_the_ignored_classes_are():
    assert ClassGround("2, 8-9").classes == (2, 8, 9)
    assert ClassGround([9, 2]).classes == (2, 9)


def test_the_filter_needs_the_classes_and_honours_steps():
    xyz = np.column_stack([np.arange(10.0), np.zeros(10), np.zeros(10)])
    cls = np.array([2, 1] * 5, np.uint8)
    with pytest.raises(InputError, match="classes"):
        ClassGround().run(xyz)
    with pytest.raises(InputError, match="9 values for 10 points"):
        ClassGround().run(xyz, classification=cls[:9])
    with pytest.raises(Cancelled):
        ClassGround().run(xyz, Steps(is_cancelled=lambda: True), classification=cls)
    seen = []
    result = ClassGround().run(xyz, Steps(progress=seen.append).sub(0.2, 0.6), classification=cls)
    np.testing.assert_array_equal(result.ground, cls == 2)
    assert seen and seen[-1] == pytest.approx(0.6) and min(seen) >= 0.2


def test_the_command_line_makes_the_dtm_and_reports_it_in_json(delivery, tmp_path):
    import io
    import json

    from groundsieve.core.engine.cli import main
    out, stdout = io.StringIO(), io.StringIO()
    dtm = tmp_path / "dtm.tif"
    code = main(["dtm", "--input", str(delivery), "--dtm", str(dtm), "--classes", "2,6", "--json"], out=out,
                stdout=stdout)
    assert code == 0, out.getvalue()
    document = json.loads(stdout.getvalue())
    classes = _classes(delivery)
    assert document["status"] == "done" and document["algorithm"] == "dtm" and document["dtm"] == str(dtm)
    assert document["ground"] == int(np.isin(classes, (2, 6)).sum()) and document["points"] == len(classes)
    assert document["parameters"]["classes"] == [2, 6] and document["outputs"] == []
    values, *_ = _read(dtm)
    assert np.nanmax(values) > terrain(0.0, 300.0) + ROOF - 1.0  # the roofs (class 6) are in it
    # a cloud without the classes: exit 1, the reason on one line, nothing written
    out, stdout = io.StringIO(), io.StringIO()
    code = main(["dtm", "--input", str(delivery), "--dtm", str(tmp_path / "none.tif"), "--classes", "9", "--json"],
                out=out, stdout=stdout)
    failed = json.loads(stdout.getvalue())
    assert code == 1 and failed["status"] == "failed" and "no point of class 9" in failed["error"]
    assert "Traceback" not in out.getvalue() and not (tmp_path / "none.tif").exists()


@pytest.mark.parametrize("algorithm", [ClassGround(), "smrf"], ids=["classes", "smrf"])
def test_a_tiled_dtm_spans_the_points_it_may_hold_as_a_whole_run(tmp_path, algorithm):
    """5 noise points (class 7, ignored) 2 km away stretched a tiled DTM to 2,300 x 300 cells, and the
    log said to class them as noise, which they were; the whole run's DTM was 300 x 300 (a surveyor).
    The tiled DTM is now cut to the points that may enter it: the same grid as the whole run's, without
    the warning; a stray point that is not ignored still stretches both, and is still named."""
    from groundsieve.core.filters.smrf import SMRF
    algorithm = SMRF() if algorithm == "smrf" else algorithm
    rng = np.random.default_rng(6)
    n = 90_000
    x, y = rng.uniform(0, 300, n), rng.uniform(0, 300, n)
    z = terrain(x, y) + rng.normal(0, 0.02, n)
    cls = np.full(n, 2, np.uint8)
    x[:5], y[:5], cls[:5] = 2300.0 - rng.uniform(0, 5, 5), 150.0, 7
    src = tmp_path / "stray.laz"
    write_las(new_las(x, y, z, classification=cls), str(src))
    shapes, logs = {}, {}
    for tiled in (False, True):
        out, said = tmp_path / f"dtm{int(tiled)}.tif", []
        run_ground_filter(str(src), None, algorithm, options=FilterOptions(keep_existing_classes=True,
                                                                           tiling=_tiling(tiled)),
                          dtm_path=str(out), log=said.append)
        values, x0, top, cell = _read(out)
        shapes[tiled], logs[tiled] = (values.shape, x0, top), "\n".join(said)
    assert shapes[True] == shapes[False] and shapes[False][0] == (300, 300)
    assert "lie far from the others" not in logs[True] and "cut to the 300 x 300 cells" in logs[True]
    # not ignored: the stray points stretch the DTM, whole and tiled, and both say so
    cls[:5] = 1
    write_las(new_las(x, y, z, classification=cls), str(src))
    for tiled in (False, True):
        out, said = tmp_path / f"far{int(tiled)}.tif", []
        run_ground_filter(str(src), None, algorithm, options=FilterOptions(keep_existing_classes=True,
                                                                           tiling=_tiling(tiled)),
                          dtm_path=str(out), log=said.append)
        assert _read(out)[0].shape[1] > 2000, tiled
        assert any("lie far from the others" in line for line in said), tiled


@pytest.mark.parametrize("tiled", [False, True], ids=["whole", "tiled"])
def test_every_class_left_out_is_counted_and_a_contradiction_is_refused(delivery, tmp_path, tiled):
    """With --classes 9 the log named the classes 3-17 left out but not the 2 (nor 1 and 0), and
    --classes 2 --ignore-classes 2 ran and said the file had no class 2 (a surveyor); a text file, which
    has no classes, was read as points of class 0. The counts now name every class of the input left out;
    the other two are refused before any work."""
    logs = []
    out = tmp_path / "dtm.tif"
    run_ground_filter(str(delivery), None, ClassGround("5"), options=FilterOptions(keep_existing_classes=True,
                                                                                 tiling=_tiling(tiled)),
                      dtm_path=str(out), log=logs.append)
    classes = _classes(delivery)
    (line,) = [text for text in logs if "points of other classes stay out of it" in text]
    assert f"2 (ground): {int(np.sum(classes == 2)):,}" in line and f"6 (building): {int(np.sum(classes == 6)):,}" in line
    assert "5 (high vegetation)" not in line and "7 (" not in line  # the ground class; the ignored noise
    assert any(text.startswith("Taking the points of the classes 5 as the ground") for text in logs) or tiled
    with pytest.raises(InvalidParameterError, match=r"the ground classes and the ignored classes both name \(2\)"):
        run_ground_filter(str(delivery), None, ClassGround("2"),
                          options=FilterOptions(keep_existing_classes=True, ignore_classes="2,7",
                                                tiling=_tiling(tiled)), dtm_path=str(tmp_path / "no.tif"))
    text = tmp_path / "isprs.txt"
    text.write_text("0 0 1 0\n1 0 1 0\n0 1 1 1\n")
    with pytest.raises(InputError, match="a text file carries no classes"):
        run_ground_filter(str(text), None, ClassGround(), dtm_path=str(tmp_path / "t.tif"))
    assert not (tmp_path / "no.tif").exists() and not (tmp_path / "t.tif").exists()


def test_a_gap_in_the_data_is_named_whole_and_tiled(tmp_path):
    """A 60 m hole without points was named by a whole run, and not by a tiled one whose buffer (40 m)
    bridged it all the same (a surveyor): both name it now, once (it lies across two tiles), with its size."""
    rng = np.random.default_rng(9)
    n = 150_000
    x, y = rng.uniform(0, 300, n), rng.uniform(0, 300, n)
    keep = ~((np.abs(x - 103) < 30) & (np.abs(y - 160) < 30))  # across the tile edge at x = 100 m
    src = tmp_path / "hole.laz"
    write_las(new_las(x[keep], y[keep], terrain(x[keep], y[keep]), classification=np.full(int(keep.sum()), 2,
                                                                                           np.uint8)), str(src))
    said = {}
    for tiled in (False, True):
        logs = []
        run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True,
                                                                               tiling=_tiling(tiled)),
                          dtm_path=str(tmp_path / f"d{int(tiled)}.tif"), log=logs.append)
        (said[tiled],) = [line for line in logs if "gap(s)" in line]
    for line in said.values():
        assert "the data have 1 gap(s)" in line, line
        area = float(line.split("the largest about ")[1].split(" m²")[0].replace(",", ""))
        assert 0.8 * 3600 <= area <= 3600, line


@pytest.mark.parametrize("tiled", [False, True], ids=["whole", "tiled"])
def test_spikes_in_the_ground_class_are_named(tmp_path, tiled):
    """Three points 20 m up classed ground went into the DTM without a word, while pits were named (a
    surveyor). Isolated spikes are named now, with the highest and where it is; a clean cloud says nothing."""
    rng = np.random.default_rng(10)
    n = 90_000
    x, y = rng.uniform(0, 300, n), rng.uniform(0, 300, n)
    z = terrain(x, y) + rng.normal(0, 0.02, n)
    said = {}
    for name, spikes in (("clean", ()), ("spiky", ((60.2, 60.3), (150.4, 220.6), (240.5, 80.5)))):
        xs, ys = np.r_[x, [p[0] for p in spikes]], np.r_[y, [p[1] for p in spikes]]
        zs = np.r_[z, terrain(np.array([p[0] for p in spikes]), np.array([p[1] for p in spikes])) + 20.0]
        src = tmp_path / f"{name}.laz"
        write_las(new_las(xs, ys, zs, classification=np.full(xs.size, 2, np.uint8)), str(src))
        logs = []
        run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True,
                                                                               tiling=_tiling(tiled)),
                          dtm_path=str(tmp_path / f"{name}.tif"), log=logs.append)
        said[name] = [line for line in logs if "isolated spike(s)" in line]
    assert said["clean"] == []
    (line,) = said["spiky"]
    # (a spike whose triangles raise two neighbouring cells is not isolated: the pits' rule, 5 x 5 cells)
    count = int(line.split("DTM: ")[1].split(" isolated spike(s)")[0])
    assert line.startswith(WARNING_PREFIX) and 1 <= count <= 3 and "cells more than 0.5 m above" in line, line
    assert float(line.split("the highest ")[1].split(" m")[0]) > 5.0, line


def test_sparse_key_points_make_the_same_dtm_tiled(tmp_path):
    """2,500 model key points (class 8) on a 40 m grid: a tiled run threw away the ground of every tile of
    fewer than 50 points (the filters' minimum) and refused the survey, 'no point of class 8' (a code
    reviewer). A tile of a few points is ground here: the tiled DTM is the whole run's."""
    gx, gy = np.meshgrid(np.arange(0.0, 2000.0, 40.0), np.arange(0.0, 2000.0, 40.0))
    x, y = gx.ravel() + 0.5, gy.ravel() + 0.5
    src = tmp_path / "keys.laz"
    write_las(new_las(x, y, terrain(x, y), classification=np.full(x.size, 8, np.uint8)), str(src))
    made = []
    for tiled in (False, True):
        out = tmp_path / f"d{int(tiled)}.tif"
        tiling = TileOptions(tile_size_m=100.0, buffer_m=100.0, workers=2, parallel="threads") if tiled else TileOptions()
        run_ground_filter(str(src), None, ClassGround("8"), options=FilterOptions(keep_existing_classes=True,
                                                                                  tiling=tiling),
                          dtm_path=str(out), dtm=DTMOptions(cell_size_m=10.0, cell_set=True))
        made.append(_read(out)[0])
    assert made[0].shape == made[1].shape and np.isfinite(made[0]).mean() > 0.95
    # (a regular grid has many equally good triangulations; the heights are stored in 1 cm steps)
    np.testing.assert_allclose(made[0], made[1], atol=0.01)


def test_the_tile_buffer_is_40_m_in_a_cloud_in_feet(tmp_path):
    """The DTM from classes' buffer was 40 ft (12 m) on a cloud in feet, where the help says 40 m (a code
    reviewer)."""
    import pyproj
    rng = np.random.default_rng(11)
    n = 30_000
    x, y = 2_000_000 + rng.uniform(0, 1000, n), 600_000 + rng.uniform(0, 1000, n)
    src = tmp_path / "feet.laz"
    write_las(new_las(x, y, 300 + rng.normal(0, 0.05, n), classification=np.full(n, 2, np.uint8),
                      crs_wkt=pyproj.CRS.from_epsg(2264).to_wkt()), str(src))
    logs = []
    run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(
        keep_existing_classes=True, tiling=TileOptions(tile_size_m=400.0, workers=1, parallel="threads")),
        dtm_path=str(tmp_path / "d.tif"), log=logs.append)
    (line,) = [text for text in logs if "with a buffer of" in text]
    assert "with a buffer of 132 ft (the default of a DTM from classes)" in line, line  # 40 m = 131.23 ft, rounded up


def test_a_survey_grid_stretched_by_one_far_noise_point_names_it(tmp_path):
    """One ignored noise point at (0, 0, 0) beside a survey at UTM 500,000 / 4,000,000: the headers' bounds
    make the DTM's grid, which is refused; the refusal said only 'use a larger cell size' (a code reviewer).
    It now names the headers' span and the likely far point."""
    rng = np.random.default_rng(12)
    n = 20_000
    x, y = 500_000 + rng.uniform(0, 300, n), 4_000_000 + rng.uniform(0, 300, n)
    z, cls = 100 + rng.normal(0, 0.1, n), np.full(n, 2, np.uint8)
    x[0] = y[0] = z[0] = 0.0
    cls[0] = 7
    src = tmp_path / "zero.laz"
    write_las(new_las(x, y, z, classification=cls), str(src))
    with pytest.raises(InvalidParameterError, match=r"use a larger cell size\. The files' headers span x 0\.00-500,3.*"
                                                     r"a point far from the others"):
        run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True,
                                                                               tiling=_tiling(True)),
                          dtm_path=str(tmp_path / "d.tif"))


def test_a_bridge_deck_among_the_ground_classes_is_warned_about(delivery, tmp_path):
    """--classes 2,17 put a bridge deck in the terrain without a word (a flood modeller); 6 (building)
    here: the run warns, and still runs as asked."""
    logs = []
    run_ground_filter(str(delivery), None, ClassGround("2,6"), options=FilterOptions(keep_existing_classes=True),
                      dtm_path=str(tmp_path / "d.tif"), log=logs.append)
    said = [line for line in logs if "the ground classes hold" in line]
    assert len(said) == 1 and said[0].startswith(WARNING_PREFIX) and "6 (building)" in said[0]
    # the ignored noise left out: the run says it takes the others, not that it filters them
    assert any(line.startswith("Taking ") and "of an ignored class" in line for line in logs), logs
    logs = []
    run_ground_filter(str(delivery), None, ClassGround("2"), options=FilterOptions(keep_existing_classes=True),
                      dtm_path=str(tmp_path / "e.tif"), log=logs.append)
    assert not any("the ground classes hold" in line for line in logs)


def test_a_river_without_returns_across_the_survey_is_said_when_tiles_leave_it_empty(tmp_path):
    """A 100 m river without returns running through the survey, along a tile line: the whole run fills it,
    the tiles (40 m buffer) left 40,002 cells empty without a word, no cell of it having a value on both
    sides in its column (a flood modeller). The run says so now, with the count."""
    rng = np.random.default_rng(14)
    n = 120_000
    x, y = rng.uniform(0, 400, n), rng.uniform(0, 300, n)
    keep = np.abs(x - 200) > 50
    src = tmp_path / "river.laz"
    write_las(new_las(x[keep], y[keep], terrain(x[keep], y[keep]),
                      classification=np.full(int(keep.sum()), 2, np.uint8)), str(src))
    made, logs = [], []
    for tiled in (False, True):
        out = tmp_path / f"d{int(tiled)}.tif"
        run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True,
                                                                               tiling=_tiling(tiled)),
                          dtm_path=str(out), log=logs.append)
        made.append(_read(out)[0])
    empty = int(np.isnan(made[1]).sum() - np.isnan(made[0]).sum())
    assert empty > 5000  # the river's middle, empty in tiles only
    (note,) = [line for line in logs if "stayed nodata in bays or channels" in line]
    said = int(note.split("DTM: ")[1].split(" cell(s)")[0].replace(",", ""))
    assert 0.9 * empty <= said <= empty, (said, empty)


@pytest.mark.parametrize("tiled", [False, True], ids=["whole", "tiled"])
def test_each_ground_class_is_counted_and_one_without_points_said(delivery, tmp_path, tiled):
    """--classes 2,9 said neither how many points each gave nor that the cloud had no 9 (a flood modeller)."""
    logs = []
    run_ground_filter(str(delivery), None, ClassGround("2,9"), options=FilterOptions(keep_existing_classes=True,
                                                                                    tiling=_tiling(tiled)),
                      dtm_path=str(tmp_path / "d.tif"), log=logs.append)
    classes = _classes(delivery)
    (line,) = [text for text in logs if text.startswith("Ground: ") and "of the ground classes" in text]
    assert line.endswith(f"(2 (ground): {int(np.sum(classes == 2)):,}, 9 (water): 0)."), line


def test_a_tiled_dtm_cut_to_its_points_has_the_whole_run_s_geotransform_to_the_bit(tmp_path):
    """With 0.3 m cells a whole run's origin was 500001.89999999997 and a tiled run's cut could differ from it
    in its last bit (a geomorphologist: two epochs' DTMs, one run whole and one tiled): both are the decimal
    on the cell's lattice now."""
    from osgeo import gdal
    rng = np.random.default_rng(9)
    n = 40_000
    x, y = 500001.95 + rng.uniform(0, 150, n), 4000001.25 + rng.uniform(0, 150, n)
    cls = np.full(n, 2, np.uint8)
    x[:3], y[:3], cls[:3] = 498765.4, 4000345.6, 7  # (ignored, far away: the tiled survey grid is cut to the others)
    src = tmp_path / "epoch.laz"
    write_las(new_las(x, y, terrain(x - 500000, y - 4000000), classification=cls, scale=0.001), str(src))
    transforms = []
    for tiled in (False, True):
        out = tmp_path / f"dtm{int(tiled)}.tif"
        run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True,
                                                                               tiling=_tiling(tiled)),
                          dtm_path=str(out), dtm=DTMOptions(cell_size_m=0.3, cell_set=True))
        ds = gdal.Open(str(out))
        transforms.append(ds.GetGeoTransform())
        del ds
    assert transforms[0] == transforms[1], transforms
    assert repr(transforms[0][0]) == "500001.9"


@pytest.mark.parametrize("algorithm", [ClassGround(), "smrf"], ids=["classes", "smrf"])
def test_a_dtm_extent_gives_one_grid_whole_and_tiled(tmp_path, algorithm):
    """Two epochs of different coverage gave DTMs of different sizes, and no parameter made them one grid (a
    geomorphologist's DEM of difference): an extent gives the DTM its cells, widened to whole cells on the
    cell's lattice, whole and tiled alike; beyond the data it is nodata, within it the values are the DTM's."""
    from osgeo import gdal

    from groundsieve.core.engine.cli import main
    from groundsieve.core.filters.smrf import SMRF
    algorithm = SMRF() if algorithm == "smrf" else algorithm
    rng = np.random.default_rng(12)
    n = 60_000
    x, y = 1000.0 + rng.uniform(0, 200, n), 2000.0 + rng.uniform(0, 200, n)
    src = tmp_path / "epoch.laz"
    write_las(new_las(x, y, terrain(x - 1000, y - 2000), classification=np.full(n, 2, np.uint8)), str(src))
    extent = (1050.2, 1950.0, 1260.0, 2120.9)  # (beyond the data south and east)
    results = {}
    for tiled in (False, True):
        for name, ext in (("free", None), ("extent", extent)):
            out, lines = tmp_path / f"{name}{int(tiled)}.tif", []
            run_ground_filter(str(src), None, algorithm, options=FilterOptions(keep_existing_classes=True,
                                                                               tiling=_tiling(tiled)),
                              dtm_path=str(out), dtm=DTMOptions(cell_size_m=0.5, extent=ext), log=lines.append)
            ds = gdal.Open(str(out))
            band = ds.GetRasterBand(1)
            values = band.ReadAsArray().astype(float)
            values[values == band.GetNoDataValue()] = np.nan
            results[name, tiled] = (ds.GetGeoTransform(), values, lines)
            del band, ds
    for tiled in (False, True):
        transform, values, lines = results["extent", tiled]
        assert transform == (1050.0, 0.5, 0.0, 2121.0, 0.0, -0.5)  # (widened to whole cells)
        assert values.shape == ((2121 - 1950) * 2, (1260 - 1050) * 2)
        assert np.isnan(values[-1, :]).all() and np.isnan(values[:, -1]).all()  # (beyond the data)
        assert any(line.startswith("DTM: the extent given, x 1,050.00 to 1,260.00") for line in lines), lines
        free_transform, free, _ = results["free", tiled]  # (the points' own DTM: x from 1000, y to 2200)
        col0, row0 = int(round((1050.0 - free_transform[0]) / 0.5)), int(round((free_transform[3] - 2121.0) / 0.5))
        assert col0 > 0 and row0 > 0
        rows, cols = min(values.shape[0], free.shape[0] - row0), min(values.shape[1], free.shape[1] - col0)
        np.testing.assert_allclose(values[:rows, :cols], free[row0:row0 + rows, col0:col0 + cols], atol=1e-6)
    np.testing.assert_allclose(results["extent", False][1], results["extent", True][1], atol=1e-3)
    # the command line's --dtm-extent, and an extent that is no extent
    out = tmp_path / "cli.tif"
    code = main(["dtm", "--input", str(src), "--dtm", str(out), "--dtm-cell", "0.5",
                 "--dtm-extent", "1050.2,1950,1260,2120.9"], out=io.StringIO(), stdout=io.StringIO())
    assert code == 0
    ds = gdal.Open(str(out))
    assert ds.GetGeoTransform() == results["extent", False][0]
    del ds
    with pytest.raises(InvalidParameterError, match="DTM extent: .* is empty"):
        DTMOptions(extent=(10, 0, 5, 1))
    with pytest.raises(InvalidParameterError, match="is not xmin,ymin,xmax,ymax"):
        DTMOptions(extent="1,2,3")


@pytest.mark.parametrize("tiled", [False, True], ids=["whole", "tiled"])
def test_an_extent_in_the_other_order_or_elsewhere_is_refused_before_the_work(tmp_path, tiled):
    """QGIS writes an extent xmin,xmax,ymin,ymax, the command line takes XMIN,YMIN,XMAX,YMAX: one typed in the
    other's order made a valid box thousands of km wide, refused as '2 points lie 4890.7 km from the others'
    (a power user). Such an extent, and one that misses the points, is refused in its own words."""
    rng = np.random.default_rng(4)
    n = 20_000
    x, y = 512700.0 + rng.uniform(0, 140, n), 5403540.0 + rng.uniform(0, 310, n)
    src = tmp_path / "s.laz"
    write_las(new_las(x, y, 300 + rng.normal(0, 0.05, n), classification=np.full(n, 2, np.uint8)), str(src))
    for extent, why in (((512700, 512841, 5403540, 5403851), "times their area"),  # (QGIS's order, read as ours)
                        ((600000, 5403540, 600141, 5403851), "does not meet them")):
        with pytest.raises(InvalidParameterError, match=why + r".*QGIS writes an extent xmin,xmax,ymin,ymax"):
            run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True,
                                                                                   tiling=_tiling(tiled)),
                              dtm_path=str(tmp_path / "d.tif"), dtm=DTMOptions(extent=extent))
    assert sorted(os.listdir(tmp_path)) == ["s.laz"]


def test_an_extent_beyond_the_points_is_nodata_filled_or_not_whole_and_tiled(tmp_path):
    """With the fill on, a whole run filled the whole extent (33,600 cells of one invented value beyond the data)
    where a tiled run left it nodata (a code reviewer): the DTM is made over its points and placed in the
    extent, so beyond them both are nodata; within, both are filled."""
    from osgeo import gdal
    rng = np.random.default_rng(3)
    n = 30_000
    x, y = 1000.0 + rng.uniform(0, 160, n), 2000.0 + rng.uniform(0, 160, n)
    src = tmp_path / "s.laz"
    write_las(new_las(x, y, terrain(x - 1000, y - 2000), classification=np.full(n, 2, np.uint8)), str(src))
    made = []
    for tiled in (False, True):
        out = tmp_path / f"d{int(tiled)}.tif"
        run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True,
                                                                               tiling=_tiling(tiled)),
                          dtm_path=str(out), dtm=DTMOptions(cell_size_m=1.0, fill_outside_hull=True,
                                                            extent=(960.0, 1960.0, 1200.0, 2200.0)))
        ds = gdal.Open(str(out))
        band = ds.GetRasterBand(1)
        values = band.ReadAsArray().astype(float)
        values[values == band.GetNoDataValue()] = np.nan
        made.append(values)
        del band, ds
    for values in made:  # rows from y 2200 down, columns from x 960
        assert np.isnan(values[:, :40]).all() and np.isnan(values[:40, :]).all()  # beyond the points
        assert np.isfinite(values[41:199, 41:199]).all()  # their own DTM, filled
    np.testing.assert_allclose(made[0][41:199, 41:199], made[1][41:199, 41:199], atol=1e-3)


def test_a_damaged_file_is_named_in_words_by_the_tiled_dtm_from_classes(delivery, tmp_path):
    """The sample of the first points before the tiles read a truncated LAZ with no guard: lazrs's own error
    and a traceback, where a filter's run names the damaged file (a code reviewer)."""
    folder = tmp_path / "survey"
    folder.mkdir()
    (folder / "cut.laz").write_bytes(delivery.read_bytes()[:4000])
    with pytest.raises(GroundSieveError) as err:
        run_ground_filter(str(folder), None, ClassGround(), options=FilterOptions(keep_existing_classes=True),
                          dtm_path=str(tmp_path / "d.tif"))
    assert "cut.laz" in str(err.value)


def test_an_extent_in_the_other_order_is_refused_in_a_national_grid_and_a_model_domain_is_not(tmp_path):
    """In the British National Grid (x and y within 316 km of each other) the other order of a plot's extent
    made a valid 14 x 14 km box, which a size rule of 100,000 km² let through (a code reviewer); a model's
    domain of 2.5 x 2 km around a 60 m plot had been refused by a rule of 1 km² (a technical writer). The
    other order is refused where its numbers fit the points; a large extent that fits no other way is taken."""
    rng = np.random.default_rng(8)
    n = 8_000
    x, y = 384000.0 + rng.uniform(0, 100, n), 398000.0 + rng.uniform(0, 100, n)
    src = tmp_path / "bng.laz"
    write_las(new_las(x, y, 50 + rng.normal(0, 0.05, n), classification=np.full(n, 2, np.uint8)), str(src))
    with pytest.raises(InvalidParameterError, match=r"where its numbers in the other order, x 384,000.00 to "
                                                     r"384,100.00, y 398,000.00 to 398,100.00, fit them"):
        run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True),
                          dtm_path=str(tmp_path / "d.tif"),
                          dtm=DTMOptions(cell_size_m=5.0, extent=(384000, 384100, 398000, 398100)))  # (QGIS's order)
    domain = (383000.0, 397000.0, 385500.0, 399000.0)  # (2.5 x 2 km around the plot: 500 times its area)
    run_ground_filter(str(src), None, ClassGround(), options=FilterOptions(keep_existing_classes=True),
                      dtm_path=str(tmp_path / "domain.tif"), dtm=DTMOptions(cell_size_m=5.0, extent=domain))
    values, x0, top, cell = _read(tmp_path / "domain.tif")
    assert (x0, top, cell) == (383000.0, 399000.0, 5.0) and values.shape == (400, 500)


def test_a_dtm_floating_above_its_points_is_warned_about_whole_and_tiled(tmp_path):
    """CSF's defaults on a steep forest made a DTM about 4 m too high with a clean log (a forester): 36 % of the
    last returns lay more than 1 m below it. A DTM with more than 2 % of its points that far below is warned
    about, whole and tiled; a DTM on its ground is not."""
    rng = np.random.default_rng(5)
    n = 40_000
    x, y = rng.uniform(0, 120, n), rng.uniform(0, 120, n)
    z = 100.0 + 0.1 * x + rng.normal(0, 0.03, n)
    cls = np.ones(n, np.uint8)
    cls[rng.random(n) < 0.3] = 2
    lifted = z.copy()
    lifted[cls == 2] += 3.0  # (the "ground" on the canopy, 3 m above the points)
    for name, heights in (("floating", lifted), ("sound", z)):
        path = tmp_path / f"{name}.laz"
        write_las(new_las(x + 500_000.0, y + 5_400_000.0, heights, classification=cls), str(path))
        for mode, options in (("whole", FilterOptions()),
                              ("tiled", FilterOptions(tiling=TileOptions(tile_size_m=50.0, workers=2,
                                                                         parallel="threads")))):
            lines = []
            run_ground_filter(str(path), None, ClassGround(), options=options,
                              dtm_path=str(tmp_path / f"{name}_{mode}.tif"), dtm=DTMOptions(cell_size_m=1.0),
                              log=lines.append)
            said = [line for line in lines if "below it: the DTM floats above the ground" in line]
            assert bool(said) == (name == "floating"), (name, mode, lines)
            if said:
                share = float(said[0].split("(")[1].split(" %")[0])
                assert 60.0 <= share <= 75.0, said  # (the 70 % of points not lifted)
