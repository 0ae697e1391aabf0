"""One file of a survey at a time (``TileOptions.only``, ``--only``): the jobs of a job array, each
classifying its file on the survey's tiles with its neighbours' points in the buffers, give the
classified files and the DTM of one run of the whole survey (engine/one_file.py)."""
from __future__ import annotations

import json
import os

import laspy
import numpy as np
import pytest

from groundsieve.core.engine.tiles import TileOptions, _fingerprint
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
from groundsieve.core.errors import GroundSieveError, InputError, InvalidParameterError, OutputError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.io.lasfiles import TileGrid, bin_file, scan_header, write_vpc
from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
from groundsieve.tests.core.scenes import four_file_survey

NAMES = "abcd"


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    """A 120 m scene cut into 4 files of 60 x 60 m, and the run of the whole survey (tiles of 30 m with a
    10 m buffer cross the files' edges)."""
    root = tmp_path_factory.mktemp("one_file")
    folder = four_file_survey(str(root))
    out = root / "whole"
    out.mkdir()
    run_ground_filter(str(folder), str(out / "classified.vpc"), SMRF(), options=_options(),
                      dtm_path=str(out / "dtm.tif"), dtm=DTMOptions(cell_size_m=1.0))
    return dict(folder=str(folder), classified=str(out / "classified"), dtm=str(out / "dtm.tif"), root=root)


def _options(**tiling):
    return FilterOptions(tiling=TileOptions(**{**dict(tile_size_m=30.0, buffer_m=10.0, workers=1), **tiling}))


def _raster(path):
    from osgeo import gdal
    ds = gdal.Open(str(path))
    return ds.GetGeoTransform(), ds.GetRasterBand(1).ReadAsArray(), ds.GetProjection()


def _same_cells(part_path, whole_path):
    """The cells of the DTM ``part_path`` equal those of ``whole_path`` where it lies (both on one lattice)."""
    (g, part, crs), (wg, whole, wcrs) = _raster(part_path), _raster(whole_path)
    assert g[1] == wg[1] and crs == wcrs
    col, row = round((g[0] - wg[0]) / wg[1]), round((g[3] - wg[3]) / wg[5])
    assert col >= 0 and row >= 0 and row + part.shape[0] <= whole.shape[0] and col + part.shape[1] <= whole.shape[1]
    assert np.array_equal(part, whole[row:row + part.shape[0], col:col + part.shape[1]])
    return part


def test_each_files_job_gives_the_whole_surveys_classes_and_dtm(survey, tmp_path):
    covered = 0
    for k, name in enumerate(NAMES):
        logs = []
        run = run_ground_filter(survey["folder"], str(tmp_path / "classified"), SMRF(), options=_options(only=k),
                                dtm_path=str(tmp_path / "dtm"), dtm=DTMOptions(cell_size_m=1.0), log=logs.append)
        mine = tmp_path / "classified" / f"{name}.laz"
        assert run.inputs == [os.path.join(survey["folder"], f"{name}.laz")] and run.outputs == [str(mine)]
        assert run.dtm_path == str(tmp_path / "dtm" / f"{name}.tif")
        job, whole = laspy.read(mine), laspy.read(os.path.join(survey["classified"], f"{name}.laz"))
        assert run.point_count == len(job.points) == len(whole.points) > 5000
        assert np.array_equal(job.classification, whole.classification)
        assert run.ground_count == int(np.count_nonzero(job.classification == 2))
        assert np.array_equal(job.gps_time, laspy.read(os.path.join(survey["folder"], f"{name}.laz")).gps_time)
        cells = _same_cells(run.dtm_path, survey["dtm"])
        covered += int(np.count_nonzero(cells != -9999))
        # its neighbours lent their points: the log says how many, and nothing of theirs is written
        assert any(f"{name}.laz, file {k} of the survey's 4" in line and "from 3 neighbouring file(s)" in line
                   for line in logs)
    assert sorted(os.listdir(tmp_path / "classified")) == [f"{n}.laz" for n in NAMES]
    # the four DTMs cover the whole run's valued cells (they share the edge column or row they both touch)
    assert covered >= int(np.count_nonzero(_raster(survey["dtm"])[1] != -9999))


def test_a_file_named_or_by_path_of_a_vpc_with_its_outputs_named(survey, tmp_path):
    files = [os.path.join(survey["folder"], f"{n}.laz") for n in NAMES]
    vpc = tmp_path / "survey.vpc"
    write_vpc(str(vpc), [scan_header(p) for p in files], files)
    for only in ("d.laz", files[3]):
        out, dtm = tmp_path / f"d{len(only)}.las", tmp_path / f"d{len(only)}.tif"
        run = run_ground_filter(str(vpc), str(out), SMRF(), options=_options(only=only), dtm_path=str(dtm),
                                dtm=DTMOptions(cell_size_m=1.0))
        assert run.outputs == [str(out)] and run.dtm_path == str(dtm)
        assert np.array_equal(laspy.read(out).classification,
                              laspy.read(os.path.join(survey["classified"], "d.laz")).classification)
        _same_cells(dtm, survey["dtm"])


def test_a_dtm_extent_is_cut_to_the_file_and_a_file_outside_it_gets_no_dtm(survey, tmp_path):
    g, whole, _ = _raster(survey["dtm"])
    x0, top = g[0], g[3]
    extent = (x0 + 20.0, top - 110.0, x0 + 50.0, top - 80.0)  # inside file a (south-west), 30 x 30 cells
    wdir = tmp_path / "whole"
    wdir.mkdir()
    run_ground_filter(survey["folder"], None, SMRF(), options=_options(), dtm_path=str(wdir / "dtm.tif"),
                      dtm=DTMOptions(cell_size_m=1.0, extent=extent))
    run = run_ground_filter(survey["folder"], None, SMRF(), options=_options(only="a.laz"),
                            dtm_path=str(tmp_path / "a.tif"), dtm=DTMOptions(cell_size_m=1.0, extent=extent))
    assert _raster(run.dtm_path)[1].shape == (30, 30)
    _same_cells(run.dtm_path, wdir / "dtm.tif")
    logs = []
    run = run_ground_filter(survey["folder"], str(tmp_path / "cls"), SMRF(), options=_options(only="d.laz"),
                            dtm_path=str(tmp_path / "dtm"), dtm=DTMOptions(cell_size_m=1.0, extent=extent),
                            log=logs.append)
    assert run.dtm_path is None and not (tmp_path / "dtm" / "d.tif").exists()
    assert (tmp_path / "cls" / "d.laz").exists()
    assert any("d.laz: the file lies outside the DTM's extent: no DTM is written for it" in line for line in logs)
    with pytest.raises(InputError, match=r"d\.laz: the file lies outside the DTM's extent"):
        run_ground_filter(survey["folder"], None, SMRF(), options=_options(only=3), dtm_path=str(tmp_path / "x.tif"),
                          dtm=DTMOptions(cell_size_m=1.0, extent=extent))


def _row_survey(tmp_path):
    """Three files in a row, 60 m each, their edges on multiples of 30 m (a 180 m generated scene at 1 point
    a m²): the folder, and the south-west corner (x on 30 m, y on whole metres)."""
    write_scene(make_scene(SceneSpec(size_m=180.0, density_per_m2=1.0, seed=3)), tmp_path / "whole.laz")
    las = laspy.read(tmp_path / "whole.laz")
    folder = tmp_path / "row"
    folder.mkdir()
    x = np.asarray(las.x)
    x0 = float(np.floor(las.header.mins[0] / 30.0) * 30.0)  # (the files' edges on the tiles' edges)
    y0 = float(np.floor(las.header.mins[1]))
    for k in range(3):
        part = laspy.LasData(las.header)
        part.points = las.points[(x >= x0 + 60 * k) & (x < x0 + 60 * (k + 1))]
        part.write(folder / f"f{k}.laz")
    return folder, x0, y0


def test_a_far_file_is_not_read_and_the_neighbours_are_binned_only_where_the_tiles_reach(tmp_path):
    """Three files in a row, 60 m each: the tiles of the first (30 m, buffer 10 m) reach into the second,
    not into the third; of the second only the points within reach are binned."""
    folder, _x0, _y0 = _row_survey(tmp_path)
    logs = []
    run_ground_filter(str(folder), str(tmp_path / "out"), SMRF(), options=_options(only=0), log=logs.append)
    assert any("f0.laz, file 0 of the survey's 3" in line and "from 1 neighbouring file(s)" in line for line in logs)
    assert any(line.startswith("2 file(s), ") for line in logs)
    # the binning of a neighbour keeps the points in the box only, numbered among themselves
    info = scan_header(str(folder / "f1.laz"))
    box = (info.mins[0] - 1.0, info.mins[1] - 50.0, info.mins[0] + 11.0, info.maxs[1] + 50.0)
    grid = TileGrid(30.0, 10.0)
    (tmp_path / "w1").mkdir()
    (tmp_path / "w2").mkdir()
    clipped = bin_file(str(folder / "f1.laz"), 1, grid, str(tmp_path / "w1"), clip=box)
    full = bin_file(str(folder / "f1.laz"), 1, grid, str(tmp_path / "w2"))
    px = np.asarray(laspy.read(folder / "f1.laz").x)
    inside = int(np.count_nonzero(px <= box[2]))
    assert 0 < inside < len(px) // 3
    record = clipped[next(iter(clipped))].record_size
    assert os.path.getsize(tmp_path / "w1" / "f00001.rec") == inside * record
    # a tile wholly inside the box has the same points as in the full binning
    key = (int(np.floor(info.mins[0] / 30.0)) - 1, int(np.floor(info.mins[1] / 30.0)) + 1)
    assert clipped[key].count == full[key].count > 0 and clipped[key].own_count == full[key].own_count == 0


def test_the_jobs_of_an_array_use_working_folders_of_their_own(survey, tmp_path):
    """Two jobs sharing a working folder: a stopped job's tiles are kept for it alone; another file's job
    does not resume from them, and the stopped job run again does."""
    from groundsieve.tests.core.scenes import flaky_smrf
    Flaky = flaky_smrf(budget=1)
    work = tmp_path / "work"
    work.mkdir()

    def options(only):
        return FilterOptions(tiling=TileOptions(tile_size_m=30.0, buffer_m=10.0, workers=1, work_dir=str(work),
                                                only=only))
    with pytest.raises(GroundSieveError, match="killed"):
        run_ground_filter(survey["folder"], str(tmp_path / "cls"), Flaky(), options=options(0))
    assert len(os.listdir(work)) == 1
    Flaky.failing = False
    logs = []
    run_ground_filter(survey["folder"], str(tmp_path / "cls"), Flaky(), options=options(1), log=logs.append)
    assert not any("Resuming" in line for line in logs) and len(os.listdir(work)) == 1
    run_ground_filter(survey["folder"], str(tmp_path / "cls"), Flaky(), options=options(0), log=logs.append)
    assert any("Resuming the interrupted run" in line for line in logs) and os.listdir(work) == []
    # (the name holds the one file: whatever the files read, a job's folder is its own)
    infos = [scan_header(os.path.join(survey["folder"], f"{n}.laz")) for n in NAMES]
    prints = {_fingerprint(infos, TileGrid(30.0, 10.0), SMRF(), _options(), None, only)
              for only in [None] + [i.path for i in infos]}
    assert len(prints) == 5


def test_bad_choices_of_the_one_file_are_refused_in_words(survey, tmp_path):
    folder = survey["folder"]

    def run(only, output=str(tmp_path / "o"), path=folder):
        return run_ground_filter(path, output, SMRF(), options=_options(only=only))
    with pytest.raises(InvalidParameterError, match=r"in: no file 4 in the survey: it has 4 file\(s\), numbered 0 to 3 "
                                                    r"\(for a job array: --array=0-3\)"):
        run(4)
    with pytest.raises(InvalidParameterError, match=r"no file of the survey is named e\.laz \(its 4 "
                                                    r"file\(s\): a\.laz, b\.laz, c\.laz, \.\.\.\)"):
        run("e.laz")
    with pytest.raises(InvalidParameterError, match=r"a\.laz: one file of a survey is chosen in a survey input"):
        run(0, path=os.path.join(folder, "a.laz"))
    # a single file that fits in memory runs whole: only is refused there too, before "{name}" is written as such
    with pytest.raises(InvalidParameterError, match=r"a\.laz: one file of a survey is chosen in a survey input"):
        run_ground_filter(os.path.join(folder, "a.laz"), str(tmp_path / "o" / "{name}.laz"), SMRF(),
                          options=FilterOptions(tiling=TileOptions(only=2)))
    with pytest.raises(OutputError, match=r"classified\.vpc: a run of one file of the survey writes that file's "):
        run(0, output=str(tmp_path / "classified.vpc"))
    with pytest.raises(OutputError, match=r"a_c\.laz: the classified copy would go into .*in, which holds the "
                                          r"survey's files: the array's other jobs would take it for one of them"):
        run(0, output=os.path.join(folder, "{name}_c.laz"))
    assert sorted(os.listdir(folder)) == [f"{n}.laz" for n in NAMES]
    with pytest.raises(InvalidParameterError, match="only must be one file of the survey"):
        TileOptions(only=-1)
    assert not (tmp_path / "o").exists() or not os.listdir(tmp_path / "o")


def test_the_command_line_runs_one_file_of_a_survey(survey, tmp_path, capsys):
    from groundsieve.core.engine.cli import main
    code = main(["smrf", "--input", survey["folder"], "--output", str(tmp_path / "cls"), "--dtm", str(tmp_path / "dtm"),
                 "--tile-size", "30", "--tile-buffer", "10", "--workers", "1", "--only", "2", "--json"])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["outputs"] == [str(tmp_path / "cls" / "c.laz")] and doc["dtm"] == str(tmp_path / "dtm" / "c.tif")
    assert doc["points"] == len(laspy.read(tmp_path / "cls" / "c.laz").points)
    assert np.array_equal(laspy.read(tmp_path / "cls" / "c.laz").classification,
                          laspy.read(os.path.join(survey["classified"], "c.laz")).classification)


def test_the_outputs_paths_of_one_file():
    from groundsieve.core.engine.one_file import fixed_names_warning, only_outputs
    # a fixed file path, the same in every job of an array, is warned about; a folder or {name} is not
    warning = fixed_names_warning("/s/t1.laz", "out/all.laz", "dtm/{name}.tif")
    assert warning.startswith("Warning: out/all.laz: not named after t1.laz: the jobs of an array")
    assert "and" not in warning.split(":")[0]
    assert "out/all.laz and dtm.tif" in fixed_names_warning("/s/t1.laz", "out/all.laz", "dtm.tif")
    assert not fixed_names_warning("/s/t1.laz", "out", "dtm") and not fixed_names_warning("/s/t1.laz", "t1_c.laz", None)
    assert fixed_names_warning("/s/a.laz", "/out/data.laz", None)  # (a's name within another: not a's)
    assert only_outputs("/s/t1.laz", "out", "dtm") == ("out/t1.laz", "dtm/t1.tif")
    assert only_outputs("/s/t1.las", "out/{name}.laz", "dtm/{name}_dtm.tif") == ("out/t1.laz", "dtm/t1_dtm.tif")
    assert only_outputs("/s/t1.copc.laz", "out", None) == ("out/t1.laz", None)  # (a copy is plain LAZ)
    assert only_outputs("/s/t1.laz", "one.las", "one.tif") == ("one.las", "one.tif")


class _Header:
    def __init__(self, side, other=None):
        self.mins, self.maxs, self.count = (0.0, 0.0, 0.0), (side, side if other is None else other, 10.0), 1


@pytest.mark.parametrize("planned, side, cell, fitted", [
    (390.0, 1000.0, 1.0, 250.0),     # a divisor of the files' side: a file is whole tiles
    (600.0, 999.99, 1.0, 500.0),     # (a 1 km file's points span 999.99 m)
    (2000.0, 1000.0, 1.0, 1000.0),   # never wider than the files
    (2000.0, 1000.0, 3.0, 999.0),    # (a DTM cell that does not divide them: the largest multiple within)
    (400.0, "slivers", 1.0, 110.0),  # a delivery of 110 m files with partial ones on its edges: their long side
    (700.0, 122.0, 1.0, 120.0),
    (390.0, 1230.0, 1.0, 390.0),     # no divisor of 1230 m between 195 and 390 m on whole 10 m: as planned
    (50.0, 1000.0, 1.0, 50.0),
    (390.0, 1000.0, 0.3, 390.0),     # 250 m is no multiple of the DTM's 0.3 m cell
])
def test_planned_tiles_are_fitted_to_the_files(planned, side, cell, fitted):
    from groundsieve.core.engine.one_file import fit_to_files
    headers = [_Header(side)] * 3
    if side == "slivers":  # 4 whole files, 6 slivers of 110 x 8 m and 60 x 110 m
        headers = [_Header(110.0)] * 4 + [_Header(110.0, 8.0)] * 3 + [_Header(60.0, 110.0)] * 3
    assert fit_to_files(planned, headers, multiple_of=cell) == pytest.approx(fitted)


def test_a_file_without_ground_gets_the_dtm_its_neighbours_ground_makes(survey, tmp_path):
    """A file all roofs (class 6): the DTM from classes of its job is made from its neighbours' ground
    there, as the run of the whole survey makes it, not refused for want of ground of its own."""
    from groundsieve.core.filters.classes import ClassGround
    folder = tmp_path / "roofs"
    folder.mkdir()
    for name in NAMES:
        las = laspy.read(os.path.join(survey["folder"], f"{name}.laz"))
        if name == "b":
            las.classification[:] = 6
        las.write(folder / f"{name}.laz")
    options = FilterOptions(keep_existing_classes=True, tiling=TileOptions(tile_size_m=30.0, buffer_m=10.0, workers=1))
    run_ground_filter(str(folder), None, ClassGround("2"), options=options, dtm_path=str(tmp_path / "whole.tif"),
                      dtm=DTMOptions(cell_size_m=1.0))
    one = FilterOptions(keep_existing_classes=True,
                        tiling=TileOptions(tile_size_m=30.0, buffer_m=10.0, workers=1, only="b.laz"))
    run = run_ground_filter(str(folder), None, ClassGround("2"), options=one, dtm_path=str(tmp_path / "b.tif"),
                            dtm=DTMOptions(cell_size_m=1.0))
    assert run.ground_count == 0
    cells = _same_cells(tmp_path / "b.tif", tmp_path / "whole.tif")
    assert np.count_nonzero(cells != -9999) > 100


def test_a_dtm_of_an_extent_alone_filters_only_its_tiles_and_reads_only_the_files_within_reach(tmp_path):
    """No classified copy, a DTM extent over part of a survey (a flood model's domain): only the tiles
    making its cells are filtered, only the files within their reach are read (of them only the points
    within reach), and the DTM is the one a run classifying every point makes."""
    folder, x0, y0 = _row_survey(tmp_path)
    # in file f0, in its second column of 30 m tiles, whose buffer reaches into f1, not f2
    extent = (x0 + 35.0, y0 + 40.0, x0 + 55.0, y0 + 70.0)
    options = _options()
    dtm = DTMOptions(cell_size_m=1.0, extent=extent)
    ref = run_ground_filter(str(folder), str(tmp_path / "ref.vpc"), SMRF(), options=options,
                            dtm_path=str(tmp_path / "ref.tif"), dtm=dtm)
    logs = []
    run = run_ground_filter(str(folder), None, SMRF(), options=options, dtm_path=str(tmp_path / "area.tif"), dtm=dtm,
                            log=logs.append)
    assert any("reading 2 of the 3 file(s), those within their reach" in line for line in logs)
    assert run.inputs == [str(folder / "f0.laz"), str(folder / "f1.laz")]
    assert 0 < run.tiles < ref.tiles and 0 < run.point_count < ref.point_count
    area, whole = _raster(tmp_path / "area.tif")[1], _raster(tmp_path / "ref.tif")[1]
    assert area.shape == whole.shape == (30, 20) and np.count_nonzero(area != -9999) > 300
    assert np.array_equal(area, whole)


def test_dtm_cells_beside_a_lake_across_the_files_are_the_whole_runs(survey, tmp_path):
    """A 40 m lake (no points) where the four files meet: each file's DTM, cut to its cells, is the whole
    run's there too, and two files' DTMs agree on the cells they share. A tile's surface was made from the
    ground within its cells in the file's grid only: beside the lake's long triangles, DTMs differed by
    millimetres (an HPC reviewer: up to 19 mm)."""
    folder = tmp_path / "lake"
    folder.mkdir()
    first = laspy.read(os.path.join(survey["folder"], "a.laz"))
    cx, cy = float(first.header.maxs[0]), float(first.header.maxs[1])  # where the files meet
    for name in NAMES:
        las = laspy.read(os.path.join(survey["folder"], f"{name}.laz"))
        dry = (np.asarray(las.x) - cx) ** 2 + (np.asarray(las.y) - cy) ** 2 > 20.0 ** 2
        las.points = las.points[dry]
        las.write(folder / f"{name}.laz")
    run_ground_filter(str(folder), None, SMRF(), options=_options(), dtm_path=str(tmp_path / "whole.tif"),
                      dtm=DTMOptions(cell_size_m=1.0))
    parts = {}
    for name in NAMES:
        run = run_ground_filter(str(folder), None, SMRF(), options=_options(only=f"{name}.laz"),
                                dtm_path=str(tmp_path / "dtm"), dtm=DTMOptions(cell_size_m=1.0))
        parts[name] = _same_cells(run.dtm_path, tmp_path / "whole.tif")
    assert np.array_equal(parts["a"][:, -1], parts["b"][:, 0])  # (a's east column is b's west one)


def test_files_whose_outputs_would_clash_are_refused_as_the_whole_run_refuses_them(survey, tmp_path):
    """Two files of one name in a .vpc, a.las beside a.laz (one DTM name): every job would write the
    other's output, the last one's kept, without a word (an HPC reviewer)."""
    other = tmp_path / "second_delivery"
    other.mkdir()
    laspy.read(os.path.join(survey["folder"], "d.laz")).write(other / "a.laz")
    files = [os.path.join(survey["folder"], f"{n}.laz") for n in "abc"] + [str(other / "a.laz")]
    vpc = tmp_path / "two.vpc"
    write_vpc(str(vpc), [scan_header(p) for p in files], files)
    with pytest.raises(InputError, match=r"a\.laz and .*second_delivery/a\.laz would both have the classified copy "
                                         r".*cls/a\.laz: each one's job would overwrite the other's"):
        run_ground_filter(str(vpc), str(tmp_path / "cls"), SMRF(), options=_options(only=0))
    pair = tmp_path / "pair"
    pair.mkdir()
    laspy.read(os.path.join(survey["folder"], "a.laz")).write(pair / "a.las")
    laspy.read(os.path.join(survey["folder"], "b.laz")).write(pair / "a.laz")
    with pytest.raises(InputError, match=r"a\.las and .*a\.laz would both have the DTM .*dtm/a\.tif"):
        run_ground_filter(str(pair), str(tmp_path / "cls2"), SMRF(), options=_options(only="a.las"),
                          dtm_path=str(tmp_path / "dtm"), dtm=DTMOptions(cell_size_m=1.0))
    # their copies do not clash (a.las, a.laz): without a DTM the job runs
    run = run_ground_filter(str(pair), str(tmp_path / "cls2"), SMRF(), options=_options(only="a.las"))
    assert run.outputs == [str(tmp_path / "cls2" / "a.las")]


def test_a_file_is_named_by_its_name_without_extension_and_a_path_elsewhere_is_refused(survey, tmp_path):
    run = run_ground_filter(survey["folder"], str(tmp_path / "o"), SMRF(), options=_options(only="c"))
    assert run.inputs == [os.path.join(survey["folder"], "c.laz")]
    elsewhere = tmp_path / "copy"
    elsewhere.mkdir()
    laspy.read(os.path.join(survey["folder"], "c.laz")).write(elsewhere / "c.laz")
    with pytest.raises(InvalidParameterError, match=r"copy/c\.laz is not one of the survey's files; give one of them"):
        run_ground_filter(survey["folder"], str(tmp_path / "o2"), SMRF(), options=_options(only=str(elsewhere / "c.laz")))


def test_name_fields_without_one_file_are_refused(survey, tmp_path):
    with pytest.raises(InvalidParameterError, match=r"dtm/\{name\}\.tif: \{name\} stands for the name of the one file"):
        run_ground_filter(survey["folder"], None, SMRF(), options=_options(), dtm_path=str(tmp_path / "dtm" / "{name}.tif"))
    assert not os.path.exists(tmp_path / "dtm")


def test_an_empty_file_of_the_survey_gets_its_empty_copy_and_no_dtm(survey, tmp_path):
    folder = tmp_path / "with_empty"
    folder.mkdir()
    las = laspy.read(os.path.join(survey["folder"], "a.laz"))
    las.write(folder / "a.laz")
    none = laspy.read(os.path.join(survey["folder"], "b.laz"))
    none.points = none.points[:0]
    none.write(folder / "b.laz")
    logs = []
    run = run_ground_filter(str(folder), str(tmp_path / "cls"), SMRF(), options=_options(only="b.laz"),
                            dtm_path=str(tmp_path / "dtm"), dtm=DTMOptions(cell_size_m=1.0), log=logs.append)
    assert run.point_count == 0 and run.dtm_path is None and run.outputs == [str(tmp_path / "cls" / "b.laz")]
    copy = laspy.read(tmp_path / "cls" / "b.laz")
    assert len(copy.points) == 0 and copy.header.point_format.id == none.header.point_format.id
    assert not os.path.exists(tmp_path / "dtm")
    assert any("b.laz: the file holds no points: its classified copy is empty, and no DTM is made for it" in line
               for line in logs)


def test_a_damaged_first_file_fails_only_the_jobs_that_read_it(tmp_path):
    """The tiles are planned from the first file's density: a damaged first file failed every job of the
    array; now the next file's plans them, and only the jobs reading the damaged file fail."""
    folder, _x0, _y0 = _row_survey(tmp_path)
    data = (folder / "f0.laz").read_bytes()
    (folder / "f0.laz").write_bytes(data[:len(data) // 2])  # truncated: its header still says every point
    logs = []
    run = run_ground_filter(str(folder), str(tmp_path / "out"), SMRF(), options=_options(only=2), log=logs.append)
    assert run.point_count == scan_header(str(folder / "f2.laz")).count
    assert any("f0.laz" in line and "the tiles are planned from the next file's points" in line for line in logs)
    with pytest.raises(InputError, match=r"f0\.laz"):
        run_ground_filter(str(folder), str(tmp_path / "out"), SMRF(), options=_options(only=1))


def test_hidden_point_clouds_in_a_survey_folder_are_left_out_and_said(survey, tmp_path):
    """A job killed while writing leaves .NAME.laz.gs<host>.<pid>-<random>.part.laz beside the classified
    files; that folder, a survey input, then failed every run on it (an HPC reviewer)."""
    folder = tmp_path / "cls"
    folder.mkdir()
    for name in NAMES:
        laspy.read(os.path.join(survey["folder"], f"{name}.laz")).write(folder / f"{name}.laz")
    (folder / ".a.laz.gsnode17.4242-abc.part.laz").write_bytes(b"")
    logs = []
    run = run_ground_filter(str(folder), str(tmp_path / "o"), SMRF(), options=_options(only=0), log=logs.append)
    assert run.inputs == [str(folder / "a.laz")]
    assert any("1 hidden point cloud file(s) left out (.a.laz.gsnode17.4242-abc.part.laz)" in line for line in logs)


def test_an_empty_only_on_the_command_line_is_refused(survey, tmp_path, capsys):
    """An array's task id unset (--only "") had run every file of the survey."""
    from groundsieve.core.engine.cli import main
    code = main(["smrf", "--input", survey["folder"], "--output", str(tmp_path / "cls"), "--only", "", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 1 and doc["kind"] == "parameter"
    assert doc["error"].startswith("--only is empty: give one file of the survey") and "SLURM_ARRAY_TASK_ID" in doc["error"]
    assert not (tmp_path / "cls").exists()


def test_a_file_named_by_a_number_is_not_taken_for_another_files_number(survey, tmp_path):
    """A delivery of tiles named 1.laz, 2.laz, ...: --only 1 had run 2.laz (file number 1)."""
    folder = tmp_path / "numbered"
    folder.mkdir()
    for k, name in enumerate("abc", 1):
        laspy.read(os.path.join(survey["folder"], f"{name}.laz")).write(folder / f"{k}.laz")
    with pytest.raises(InvalidParameterError, match=r"1 is both a file's number and a file's name \(1\.laz, number 0\)"):
        run_ground_filter(str(folder), str(tmp_path / "o"), SMRF(), options=_options(only=1))
    run = run_ground_filter(str(folder), str(tmp_path / "o"), SMRF(), options=_options(only="1.laz"))
    assert run.inputs == [str(folder / "1.laz")]
    assert TileOptions(only=np.int64(2)).only == 2  # (a task id from a numpy array)


def test_a_dtm_extent_past_the_surveys_edge_is_the_whole_runs(survey, tmp_path):
    """An extent reaching beyond the survey (a model's domain, two epochs on one grid), its DTM alone: the
    cells beyond the points filtered are cut by the survey's box, not by the filtered tiles' (a code reviewer:
    615 cells the whole run has were empty)."""
    folder = tmp_path / "ragged"
    folder.mkdir()
    west = float(laspy.read(os.path.join(survey["folder"], "a.laz")).header.mins[0])
    for name in NAMES:
        las = laspy.read(os.path.join(survey["folder"], f"{name}.laz"))
        if name == "c":  # (the survey's west edge uneven: c's points start 15 m further east)
            las.points = las.points[np.asarray(las.x) >= west + 15.0]
        las.write(folder / f"{name}.laz")
    south = float(laspy.read(folder / "a.laz").header.mins[1])
    x0, y0 = np.floor(west), np.floor(south)
    extent = (x0 - 20.0, y0 + 70.0, x0 + 25.0, y0 + 110.0)  # north-west, past the west edge: a and c read
    for fill in (False, True):
        dtm = DTMOptions(cell_size_m=1.0, extent=extent, fill_outside_hull=fill)
        run_ground_filter(str(folder), str(tmp_path / f"all{fill}.vpc"), SMRF(), options=_options(),
                          dtm_path=str(tmp_path / f"whole{fill}.tif"), dtm=dtm)
        logs = []
        run_ground_filter(str(folder), None, SMRF(), options=_options(), dtm_path=str(tmp_path / f"area{fill}.tif"),
                          dtm=dtm, log=logs.append)
        assert any("A DTM of its extent alone" in line for line in logs)
        area, whole = _raster(tmp_path / f"area{fill}.tif")[1], _raster(tmp_path / f"whole{fill}.tif")[1]
        assert np.count_nonzero(whole != -9999) > 300 and np.array_equal(area, whole)


def test_jobs_left_to_the_planner_match_a_whole_run_with_the_tile_size_their_log_names(survey, tmp_path):
    """No tile size set: each job fits its tiles to the files (60 m here, the budget planning far larger
    ones); a whole run given that size has the same classes."""
    sizes = set()
    for k, name in enumerate(NAMES):
        logs = []
        run_ground_filter(survey["folder"], str(tmp_path / "jobs"), SMRF(),
                          options=FilterOptions(tiling=TileOptions(buffer_m=10.0, workers=1, only=k)), log=logs.append)
        fitted = [line for line in logs if "fitted to the survey's files" in line]
        assert fitted and fitted[0].startswith("Tiles of 60 instead of ")
        sizes.add(fitted[0].split()[2])
    assert sizes == {"60"}
    run_ground_filter(survey["folder"], str(tmp_path / "whole.vpc"), SMRF(),
                      options=FilterOptions(tiling=TileOptions(tile_size_m=60.0, buffer_m=10.0, workers=1)))
    for name in NAMES:
        assert np.array_equal(laspy.read(tmp_path / "jobs" / f"{name}.laz").classification,
                              laspy.read(tmp_path / "whole" / f"{name}.laz").classification)


def test_the_working_folders_disk_is_priced_on_the_points_binned():
    """A job reads its neighbours within reach only: their share of points binned is their header's area
    within the box (a job had been priced its 8 neighbours whole, and refused on a node's scratch disk)."""
    from groundsieve.core.engine.one_file import clip_shares
    inside, half, away = _Header(100.0), _Header(100.0), _Header(100.0)
    half.mins, half.maxs = (100.0, 0.0, 0.0), (200.0, 100.0, 10.0)
    away.mins, away.maxs = (1000.0, 0.0, 0.0), (1100.0, 100.0, 10.0)
    assert clip_shares([inside, half, away], 0, (-10.0, -10.0, 150.0, 110.0)) == pytest.approx([1.0, 0.5, 0.0])


def test_an_extent_on_the_tiles_edges_reads_no_files_beyond_its_cells(tmp_path):
    """An extent ending on a tile's edge (a domain on round numbers): the tile beginning there makes none
    of its cells, and its files are not read (a flood modeller's domain read a row and a column more)."""
    folder, x0, y0 = _row_survey(tmp_path)
    logs = []
    run_ground_filter(str(folder), None, SMRF(), options=_options(), dtm_path=str(tmp_path / "d.tif"), log=logs.append,
                      dtm=DTMOptions(cell_size_m=1.0, extent=(x0 + 65.0, y0 + 40.0, x0 + 90.0, y0 + 70.0)))
    assert any("reading 2 of the 3 file(s)" in line for line in logs)


def test_an_extent_in_a_gap_of_the_data_and_one_within_reach_of_every_file(survey, tmp_path):
    """A domain inside a gap (a missing tile's corner): its DTM is made from the ground around it, as the
    whole run's, not refused for want of points of its own; a domain whose tiles reach every file filters
    its tiles only, every file binned whole."""
    folder = tmp_path / "gap"
    folder.mkdir()
    west = float(laspy.read(os.path.join(survey["folder"], "a.laz")).header.mins[0])
    south = float(laspy.read(os.path.join(survey["folder"], "a.laz")).header.mins[1])
    x0, y0 = np.floor(west), np.floor(south)
    tx, ty = np.ceil(west / 30.0) * 30.0, np.ceil(south / 30.0) * 30.0  # a whole 30 m tile of file a, emptied
    for name in NAMES:
        las = laspy.read(os.path.join(survey["folder"], f"{name}.laz"))
        x, y = np.asarray(las.x), np.asarray(las.y)
        las.points = las.points[~((x >= tx) & (x < tx + 30) & (y >= ty) & (y < ty + 30))]
        las.write(folder / f"{name}.laz")
    for extent in ((tx + 10.0, ty + 10.0, tx + 20.0, ty + 20.0), (x0 + 50.0, y0 + 50.0, x0 + 70.0, y0 + 70.0)):
        dtm = DTMOptions(cell_size_m=1.0, extent=extent)
        ref = run_ground_filter(str(folder), str(tmp_path / "all.vpc"), SMRF(), options=_options(),
                                dtm_path=str(tmp_path / "whole.tif"), dtm=dtm)
        logs = []
        run = run_ground_filter(str(folder), None, SMRF(), options=_options(), dtm_path=str(tmp_path / "area.tif"),
                                dtm=dtm, log=logs.append)
        assert run.tiles < ref.tiles
        whole, area = _raster(tmp_path / "whole.tif")[1], _raster(tmp_path / "area.tif")[1]
        assert np.count_nonzero(whole != -9999) >= 100 and np.array_equal(area, whole)
        os.remove(tmp_path / "whole.tif")
        os.remove(tmp_path / "area.tif")
    assert any("in the 4 file(s), all within their reach" in line for line in logs)
