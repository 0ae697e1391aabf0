"""A DTM's vertical accuracy against checkpoints (core/raster/accuracy.py, core/io/checkpoints.py, the
`accuracy` command): a DTM plane written by the core's own write_geotiff (bilinear interpolation is exact
on a plane, so every figure is known), checkpoints with known offsets, nodata and the raster's edge,
the checkpoint files as survey software writes them, and their errors naming file and line."""
from __future__ import annotations

import io
import json
import math
import os

import numpy as np
import pytest

from groundsieve.core.engine.cli import main
from groundsieve.core.errors import InputError, InvalidParameterError, OutputError
from groundsieve.core.io.checkpoints import parse_land_cover_mapping, read_checkpoints
from groundsieve.core.raster import accuracy as A

X0, TOP, CELL, N = 600000.0, 4100100.0, 1.0, 100  # EPSG:32633, 100 m x 100 m


def plane(x, y):
    return 80.0 + 0.05 * (x - X0) + 0.02 * (TOP - y)


def write_dtm(path, values=None, *, dtype="float64", crs=True, cell=CELL):
    from osgeo import osr

    from groundsieve.core.grids.spec import GridSpec
    from groundsieve.core.raster.geotiff import write_geotiff
    grid = GridSpec(x0=X0, top=TOP, cell=cell, nrows=N, ncols=N)
    if values is None:
        cx = X0 + (np.arange(N) + 0.5) * cell
        cy = TOP - (np.arange(N) + 0.5) * cell
        values = plane(cx[None, :], cy[:, None])
    wkt = None
    if crs:
        ref = osr.SpatialReference()
        ref.ImportFromEPSG(32633)
        wkt = ref.ExportToWkt()
    write_geotiff(str(path), values, grid, crs_wkt=wkt, dtype=dtype, elevation=True)
    return str(path)


@pytest.fixture(scope="module")
def dtm(tmp_path_factory):
    return write_dtm(tmp_path_factory.mktemp("accuracy") / "dtm.tif")


def points(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(X0 + 2, X0 + 98, n), rng.uniform(TOP - 98, TOP - 2, n)


def oracle(dz):
    dz = np.asarray(dz, dtype=float)
    return dict(mean=dz.mean(), std=dz.std(ddof=1), rmse=math.sqrt(np.mean(dz ** 2)), min=dz.min(), max=dz.max(),
                p95=np.percentile(np.abs(dz), 95))


def test_bilinear_is_exact_on_a_plane_and_the_figures_are_the_offsets(dtm):
    x, y = points(50)
    dz = np.concatenate([np.tile([0.1, -0.1], 15), np.linspace(0.02, 0.4, 20)])
    cover = ["NVA"] * 30 + ["VVA"] * 20
    r = A.check_accuracy(dtm, x, y, plane(x, y) - dz, land_cover=cover)
    assert r.count == 50 and r.skipped == () and set(r.status) == {"bilinear"}
    assert np.allclose(r.dz, dz, atol=1e-9) and np.allclose(r.dtm_z, plane(x, y), atol=1e-9)
    for figs, part in ((r.overall, dz), (r.nva, dz[:30]), (r.vva, dz[30:])):
        o = oracle(part)
        assert figs.count == len(part)
        for name in ("mean", "std", "rmse", "min", "max"):
            assert getattr(figs, name) == pytest.approx(o[name], abs=1e-9), name
        assert figs.p95_abs == pytest.approx(o["p95"], abs=1e-9)
    # NVA: RMSEz exactly 0.1; Edition 1's 95 % figure 1.96 x RMSEz, Edition 2's RMSEz itself
    assert r.nva.rmse == pytest.approx(0.1, abs=1e-9) and r.nva.ed1_95 == pytest.approx(0.196, abs=1e-9)
    # VVA: Edition 1 takes the 95th percentile of |dz| (not 1.96 x RMSEz)
    assert r.vva.ed1_95 == pytest.approx(np.percentile(np.linspace(0.02, 0.4, 20), 95), abs=1e-9)
    assert r.vva.ed1_95 != pytest.approx(1.96 * r.vva.rmse, abs=1e-3)
    assert r.outliers == () and r.warnings == ()  # 30 and 20 checkpoints: no warning


def test_sign_convention_dtm_minus_checkpoint(dtm):
    x, y = points(3)
    r = A.check_accuracy(dtm, x, y, plane(x, y) - 0.25)  # checkpoints below the DTM: the DTM is too high
    assert r.overall.mean == pytest.approx(0.25, abs=1e-9) and "DTM - checkpoint" in A.SIGN_CONVENTION


def test_cell_centres_of_a_pixel_is_area_grid(tmp_path):
    """A raster of distinct values: a checkpoint on a cell's centre reads that cell; halfway between two
    centres, their mean; near the raster's edge (outer half cell) the cell it lies in."""
    values = np.arange(N * N, dtype=np.float64).reshape(N, N)
    path = write_dtm(tmp_path / "ramp.tif", values)
    centre = (X0 + 10.5, TOP - 20.5)  # row 20, column 10
    between = (X0 + 11.0, TOP - 20.5)  # halfway to column 11
    edge = (X0 + 0.2, TOP - 0.2)  # row 0, column 0, west of its centre: no four neighbours
    xs, ys = zip(centre, between, edge)
    r = A.check_accuracy(path, xs, ys, [0.0, 0.0, 0.0])
    assert r.dtm_z[0] == pytest.approx(20 * N + 10) and r.status[0] == "bilinear"
    assert r.dtm_z[1] == pytest.approx(20 * N + 10.5)
    assert r.dtm_z[2] == 0.0 and r.status[2] == "cell"


def test_nodata_falls_back_to_the_own_cell_or_skips(tmp_path):
    cx = X0 + (np.arange(N) + 0.5)
    cy = TOP - (np.arange(N) + 0.5)
    values = plane(cx[None, :], cy[:, None])
    values[40, 40] = np.nan
    path = write_dtm(tmp_path / "holes.tif", values)
    on_hole = (X0 + 40.5, TOP - 40.5)  # its own cell is nodata: skipped
    beside = (X0 + 41.3, TOP - 40.6)  # in cell (40, 41); its four neighbours include (40, 40): its own cell
    far = (X0 + 70.2, TOP - 70.7)
    outside = (X0 - 3.0, TOP - 50.0)
    xs, ys = zip(on_hole, beside, far, outside)
    z = np.array([100.0, plane(X0 + 41.5, TOP - 40.5) - 0.3, plane(*far) + 0.2, 100.0])
    r = A.check_accuracy(path, xs, ys, z, ids=["hole", "beside", "far", "west"])
    assert r.status == ("nodata", "cell", "bilinear", "outside")
    assert r.skipped == (("hole", "nodata"), ("west", "outside")) and r.count == 2
    assert r.dz[1] == pytest.approx(0.3, abs=1e-9) and r.dz[2] == pytest.approx(-0.2, abs=1e-9)
    assert np.isnan(r.dz[0]) and np.isnan(r.dz[3])
    assert r.overall.rmse == pytest.approx(math.sqrt((0.09 + 0.04) / 2), abs=1e-9)
    said = " ".join(r.warnings)
    assert "1 of the 4 checkpoints lie outside the DTM and were skipped: west" in said
    assert "1 of the 4 checkpoints lie on the DTM's nodata and were skipped: hole" in said


def test_nodata_value_of_a_foreign_float32_dtm(tmp_path):
    """A DTM of another program: float32 with the USGS's nodata -999999, no CRS."""
    values = np.full((N, N), 12.5, dtype=np.float64)
    values[:, 60:] = np.nan
    from groundsieve.core.grids.spec import GridSpec
    from groundsieve.core.raster.geotiff import write_geotiff
    path = str(tmp_path / "usgs.tif")
    write_geotiff(path, values, GridSpec(x0=X0, top=TOP, cell=CELL, nrows=N, ncols=N), nodata=-999999.0)
    r = A.check_accuracy(path, [X0 + 10.5, X0 + 80.5], [TOP - 10.5, TOP - 10.5], [12.0, 12.0])
    assert r.status == ("bilinear", "nodata") and r.dz[0] == pytest.approx(0.5)
    assert any("height unit is not recorded" in w for w in r.warnings)


def test_outliers_are_named_and_kept(dtm):
    x, y = points(30, seed=3)
    dz = np.tile([0.05, -0.05], 15)
    dz[7] = 2.0
    r = A.check_accuracy(dtm, x, y, plane(x, y) - dz, ids=[f"P{i}" for i in range(30)], land_cover=["NVA"] * 30)
    assert r.outliers == ("P7",) and r.count == 30  # named, not removed
    assert r.nva.rmse == pytest.approx(oracle(dz)["rmse"], abs=1e-9)
    assert any("1 outlier(s)" in w and "P7" in w for w in r.warnings)
    assert list(np.flatnonzero(r.outlier_mask())) == [7]


def test_fewer_than_edition_2_s_thirty_checkpoints_are_said(dtm):
    """25 labelled checkpoints passed without a word, where ASPRS Edition 2 asks for 30 for a product's
    assessment (a surveyor); 30 say nothing of it."""
    for n, said in ((25, True), (30, False)):
        x, y = points(n, seed=5)
        r = A.check_accuracy(dtm, x, y, plane(x, y) + 0.05, land_cover=["NVA"] * n)
        assert any(f"{n} checkpoint(s) used, fewer than the 30 ASPRS Edition 2" in w for w in r.warnings) == said, n


def test_few_checkpoints_an_absent_class_and_unlabelled_ones_are_said(dtm):
    x, y = points(12, seed=4)
    cover = ["NVA"] * 10 + ["", ""]
    r = A.check_accuracy(dtm, x, y, plane(x, y) + 0.1, land_cover=cover)
    assert r.vva is None and r.nva.count == 10 and r.overall.count == 12 and r.unlabelled == 2
    said = " ".join(r.warnings)
    assert "NVA: 10 checkpoint(s), fewer than the 20" in said and "2 checkpoint(s) have no land cover" in said
    doc = A.document(r)
    assert doc["vva"] is None and doc["nva"]["count"] == 10
    one = A.check_accuracy(dtm, x[:1], y[:1], plane(x[:1], y[:1]) + 0.1)  # one checkpoint: no std, no crash
    assert math.isnan(one.overall.std) and one.overall.rmse == pytest.approx(0.1, abs=1e-9)
    assert "no land cover given" in " ".join(one.warnings)


def test_errors_name_the_dtm_and_the_problem(dtm, tmp_path):
    x, y = points(25)
    with pytest.raises(InputError, match=r"none of the 25 checkpoints of checkpoints falls on .*dtm.tif \(the DTM "
                                         r"covers x 600,000.00-600,100.00, y 4,100,000.00-4,100,100.00; the "
                                         r"checkpoints x .*\): are they in another CRS"):
        A.check_accuracy(dtm, x + 2e5, y, plane(x, y))
    with pytest.raises(InputError, match=r"dtm.tif has no band 2 \(it has 1 band\)"):
        A.check_accuracy(dtm, x, y, plane(x, y), band=2)
    with pytest.raises(InputError, match=r"missing.tif: no such file"):
        A.check_accuracy(str(tmp_path / "missing.tif"), x, y, plane(x, y))
    (tmp_path / "notes.tif").write_text("not a raster")
    with pytest.raises(InputError, match=r"notes.tif: not a raster GDAL can read"):
        A.check_accuracy(str(tmp_path / "notes.tif"), x, y, plane(x, y))
    with pytest.raises(InputError, match=r"2 checkpoint\(s\) have NaN"):
        A.check_accuracy(dtm, x, y, np.where(np.arange(25) < 2, np.nan, 1.0))
    with pytest.raises(InputError, match=r"land cover must be NVA, VVA or empty \(got 'forest'\)"):
        A.check_accuracy(dtm, x, y, plane(x, y), land_cover=["forest"] * 25)


def test_outputs_are_written_atomically_and_checked_before(dtm, tmp_path):
    x, y = points(20)
    r = A.check_accuracy(dtm, x, y, plane(x, y) - 0.1, land_cover=["NVA"] * 20)
    report, csv = tmp_path / "r.html", tmp_path / "res.csv"
    A.write_outputs(r, str(report), str(csv))
    text = report.read_text(encoding="utf-8")
    assert "<svg" in text and "Edition 1 (2014)" in text and "Edition 2 (2023)" in text
    assert "NVA</b>, ASPRS Edition 2 (2023): RMSEz = <b>0.1000 m" in text
    assert "1.96 x RMSEz = <b>0.1960 m" in text
    lines = csv.read_text(encoding="utf-8").splitlines()
    assert lines[0].split(",")[5] == "dz_dtm_minus_checkpoint" and len(lines) == 21
    assert lines[1].split(",")[5] == "0.1000"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html", "res.csv"]  # no temporaries left
    with pytest.raises(OutputError, match=r"the report must end in .html or .htm"):
        A.check_accuracy_outputs([dtm], str(tmp_path / "r.pdf"))
    with pytest.raises(OutputError, match=r"must not be the input file"):
        A.check_accuracy_outputs([str(csv)], None, str(csv))
    with pytest.raises(OutputError, match=r"the residuals CSV must end in .csv or .txt"):
        A.check_accuracy_outputs([dtm], str(tmp_path / "a.html"), str(tmp_path / "a.html"))


# -- checkpoint files ------------------------------------------------------------------------

@pytest.mark.parametrize("text, ids, covers", [
    ("x,y,z\n1,2,3\n4,5,6\n", ("line 2", "line 3"), None),
    ("1 2 3\n4 5 6\n", ("line 1", "line 2"), None),
    ("# exported by a total station\n\n1\t2\t3\n4\t5\t6\n", ("line 3", "line 4"), None),
    ("Easting;Northing;Elevation;Name;Land cover\n1;2;3;A;NVA\n4,0;5;6;B;vegetated\n", ("A", "B"), ("NVA", "VVA")),
    ("CP1,1,2,3,non-vegetated\nCP2,4,5,6,VVA\n", ("CP1", "CP2"), ("NVA", "VVA")),
    ("1,2,3,nva\n4,5,6,\n", ("line 1", "line 2"), ("NVA", "")),
    ("101 1 2 3\n102 4 5 6\n", ("101", "102"), None),
    ("\ufeffPoint,Northing,Easting,Elevation,Class\nP1,2,1,3,NVA\nP2,5,4,6,NVA\n", ("P1", "P2"), ("NVA", "NVA")),
    ('"id","x","y","z"\n"a","1","2","3"\n"b","4","5","6"\n', ("a", "b"), None),
])
def test_checkpoint_files_as_survey_software_writes_them(tmp_path, text, ids, covers):
    path = tmp_path / "cp.csv"
    path.write_text(text, encoding="utf-8")
    cp = read_checkpoints(str(path))
    assert cp.x.tolist() == [1.0, 4.0] and cp.y.tolist() == [2.0, 5.0] and cp.z.tolist() == [3.0, 6.0]
    assert cp.ids == ids and cp.land_cover == covers and cp.source == str(path)


def test_decimal_commas_with_semicolons(tmp_path):
    path = tmp_path / "de.csv"
    path.write_text("Rechtswert;Hochwert;Höhe\n", encoding="utf-8")  # not our names: refused, said which
    with pytest.raises(InputError, match=r"de.csv, line 1: the header .* names no x and no y and no z column"):
        read_checkpoints(str(path))
    path.write_text("id;x;y;z\nP1;600010,25;4100050,5;81,125\n", encoding="cp1252")
    cp = read_checkpoints(str(path))
    assert (cp.x[0], cp.y[0], cp.z[0]) == (600010.25, 4100050.5, 81.125)


def test_a_user_mapping_names_other_land_covers(tmp_path):
    path = tmp_path / "cp.txt"
    path.write_text("x y z cover\n1 2 3 road\n4 5 6 Forest\n7 8 9 NVA\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"cp.txt, line 2: 'road' is not a land cover this check knows \(NVA, VVA, "
                                         r"non-vegetated, vegetated\): map it, e.g. road=NVA or road=VVA"):
        read_checkpoints(str(path))
    cp = read_checkpoints(str(path), mapping=parse_land_cover_mapping("road=NVA; forest = vva"))
    assert cp.land_cover == ("NVA", "VVA", "NVA")
    with pytest.raises(InvalidParameterError, match=r"'road' has no '='"):
        parse_land_cover_mapping("road")
    with pytest.raises(InvalidParameterError, match=r"'road=tarmac' must map a value to NVA or VVA"):
        parse_land_cover_mapping("road=tarmac")


@pytest.mark.parametrize("text, message", [
    ("x,y,z\n1,2,3\n1,2,abc\n", r"cp.csv, line 3: 'abc' is not a number \(column z\)"),
    ("x,y,z\n1,2,3\n\n# a note\n1,2\n", r"cp.csv, line 5: 2 field\(s\), expected 3"),
    ("x,y,z\n1,nan,3\n", r"cp.csv, line 2: 'nan' is not a number \(column y\)"),
    ("x,y,z\n", r"cp.csv: holds a header and no checkpoints"),
    ("\n# only a comment\n", r"cp.csv: holds no checkpoints"),
    ("1,2\n", r"cp.csv, line 1: 2 field\(s\); a checkpoint needs x, y and z"),
    ("lon,lat,h\n15,45,100\n", r"cp.csv, line 1: the header .* names no x and no y column"),
])
def test_checkpoint_file_errors_name_the_file_and_line(tmp_path, text, message):
    path = tmp_path / "cp.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=message):
        read_checkpoints(str(path))


def test_unreadable_checkpoint_files(tmp_path):
    with pytest.raises(InputError, match=r"nothing.csv: no such file"):
        read_checkpoints(str(tmp_path / "nothing.csv"))
    with pytest.raises(InputError, match=r"is a folder"):
        read_checkpoints(str(tmp_path))
    (tmp_path / "cloud.laz").write_bytes(b"LASF\0\0\0\x01\x02")
    with pytest.raises(InputError, match=r"cloud.laz: is not a text file"):
        read_checkpoints(str(tmp_path / "cloud.laz"))


# -- the command -----------------------------------------------------------------------------

def write_checkpoint_file(path, n_nva=20, n_vva=20):
    x, y = points(n_nva + n_vva, seed=9)
    dz = np.concatenate([np.tile([0.04, -0.04], n_nva // 2), np.linspace(0.01, 0.3, n_vva)])
    z = plane(x, y) - dz
    rows = ["name;easting;northing;height;cover"]
    rows += [f"CP{i + 1};{x[i]:.6f};{y[i]:.6f};{z[i]:.6f};{'paved' if i < n_nva else 'forest'}"
             for i in range(len(x))]
    rows.append(f"OUT;{X0 - 50:.3f};{TOP - 50:.3f};80.0;paved")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return dz


def test_the_command_reports_both_editions(dtm, tmp_path):
    cp = tmp_path / "cp.csv"
    dz = write_checkpoint_file(cp)
    report, csv = tmp_path / "r.html", tmp_path / "res.csv"
    out, stdout = io.StringIO(), io.StringIO()
    code = main(["accuracy", dtm, str(cp), "--land-cover-map", "paved=NVA,forest=VVA", "--report", str(report),
                 "--csv", str(csv), "--json"], out=out, stdout=stdout)
    assert code == 0, out.getvalue()
    doc = json.loads(stdout.getvalue())
    assert doc["status"] == "done" and doc["count"] == 40 and doc["skipped"] == [{"id": "OUT", "reason": "outside"}]
    assert doc["unit"] == "m" and doc["sign"].startswith("dz = DTM - checkpoint z")
    assert doc["nva"]["ed2_rmse"] == pytest.approx(0.04, abs=1e-6)
    assert doc["nva"]["ed1_95"] == pytest.approx(1.96 * 0.04, abs=1e-6)
    assert doc["vva"]["ed1_95"] == pytest.approx(np.percentile(dz[20:], 95), abs=1e-6)
    assert doc["vva"]["ed1_95_method"] == "95th percentile of |dz|"
    assert doc["all"]["std"] == pytest.approx(np.std(dz, ddof=1), abs=1e-6)
    assert doc["report"] == str(report) and report.exists() and csv.exists()
    log = out.getvalue()
    assert "40 of 41 checkpoints used (1 skipped)" in log
    assert ("NVA (20 checkpoints): RMSEz 0.0400 m (ASPRS Edition 2, 2023: NVA = RMSEz, of the DTM against the "
            "checkpoints; Edition 2's product accuracy also counts the checkpoints' own survey accuracy, which is "
            "not included here); NVA at 95 % 0.0784 m (Edition 1, 2014: 1.96 x RMSEz)") in log
    assert "WARNING: 1 of the 41 checkpoints lie outside the DTM and were skipped: OUT" in log
    # without --json nothing on stdout
    stdout = io.StringIO()
    assert main(["accuracy", dtm, str(cp), "--land-cover-map", "paved=NVA,forest=VVA"], out=io.StringIO(),
                stdout=stdout) == 0
    assert stdout.getvalue() == ""


def test_the_command_s_errors_are_one_line_with_their_kind(dtm, tmp_path):
    cp = tmp_path / "cp.csv"
    write_checkpoint_file(cp)
    out, stdout = io.StringIO(), io.StringIO()
    assert main(["accuracy", dtm, str(cp), "--json"], out=out, stdout=stdout) == 1
    doc = json.loads(stdout.getvalue())
    assert doc["kind"] == "input" and doc["error"].startswith(f"{cp}, line 2: 'paved' is not a land cover")
    assert "Traceback" not in out.getvalue()
    stdout = io.StringIO()
    assert main(["accuracy", dtm, str(cp), "--land-cover-map", "paved", "--json"], out=io.StringIO(),
                stdout=stdout) == 1
    assert json.loads(stdout.getvalue())["kind"] == "parameter"
    stdout = io.StringIO()
    assert main(["accuracy", dtm, str(cp), "--land-cover-map", "paved=NVA,forest=VVA", "--report",
                 str(tmp_path / "r.txt"), "--json"], out=io.StringIO(), stdout=stdout) == 1
    assert json.loads(stdout.getvalue())["kind"] == "output" and not (tmp_path / "r.txt").exists()
    out = io.StringIO()
    assert main(["accuracy", str(tmp_path / "none.tif"), str(cp), "--land-cover-map", "paved=NVA,forest=VVA"],
                out=out) == 1
    assert out.getvalue().strip() == f"groundsieve: {tmp_path / 'none.tif'}: no such file"


def test_json_is_in_the_command_s_help():
    from groundsieve.core.engine.cli import build_parser
    sub = [a for a in build_parser()._actions if a.choices][-1].choices["accuracy"]
    text = " ".join(sub.format_help().split())
    assert "--json write one JSON document to stdout" in text and '"status": "failed" or "interrupted"' in text


def test_an_undeclared_nodata_value_and_repeated_checkpoints_are_said(tmp_path):
    """A DTM whose nodata tag was lost (gdal_translate -a_nodata none) gave an RMSEz of 10,164 m, its -9999
    cells blended into the samples, and a CSV listing two checkpoints twice counted them twice, both without a
    word (a surveyor). Cells of -9999 or less are nodata all the same, and both are said."""
    from osgeo import gdal
    src = write_dtm(tmp_path / "dtm.tif")
    values = gdal.Open(str(src)).ReadAsArray().astype(float)
    values[40:60, 40:60] = -9999.0
    bare = tmp_path / "bare.tif"
    ds = gdal.GetDriverByName("GTiff").Create(str(bare), values.shape[1], values.shape[0], 1, gdal.GDT_Float32)
    ds.SetGeoTransform(gdal.Open(str(src)).GetGeoTransform())
    ds.GetRasterBand(1).WriteArray(values)
    ds = None
    assert gdal.Open(str(bare)).GetRasterBand(1).GetNoDataValue() is None
    x, y = points(40, seed=6)
    x, y = np.r_[x, x[:2], X0 + 50.0], np.r_[y, y[:2], TOP - 50.0]  # two repeats, one in the hole
    r = A.check_accuracy(str(bare), x, y, plane(x, y) + 0.02, ids=[f"P{i}" for i in range(len(x))])
    assert r.overall.rmse < 0.05, r.overall
    said = " ".join(r.warnings)
    # the checkpoints whose 2 x 2 window of cell centres, or own cell, holds a cell of the hole: once each
    u, v = np.floor((x - X0) / CELL - 0.5), np.floor((TOP - y) / CELL - 0.5)
    near = int(np.sum((u + 1 >= 40) & (u <= 59) & (v + 1 >= 40) & (v <= 59)))
    assert near >= 5 and "declares no nodata value" in said and f"-9999 or less next to {near} checkpoint(s)" in said
    assert "4 checkpoints share their x and y with another (P0 = P40; P1 = P41)" in said


def test_headers_with_units_and_a_pnezd_file_without_header(dtm, tmp_path):
    """'Easting (m)' and 'Elevation [m]' were refused as headers, and a PNEZD file without its header read
    its northings as x: 'none falls on the DTM: another CRS?' (a surveyor). Units in brackets are read past,
    and swapped coordinates are named as such."""
    from groundsieve.core.io.checkpoints import read_checkpoints
    x, y = points(30, seed=7)
    z = plane(x, y) + 0.03
    with_units = tmp_path / "units.csv"
    with_units.write_text("Point,Northing (m),Easting (m),Elevation [m]\n"
                          + "".join(f"P{i},{y[i]:.3f},{x[i]:.3f},{z[i]:.3f}\n" for i in range(30)))
    r = A.check_accuracy_of(dtm, read_checkpoints(str(with_units)))
    assert r.count == 30 and r.overall.rmse == pytest.approx(0.03, abs=2e-3)
    bare = tmp_path / "pnezd.csv"
    bare.write_text("".join(f"P{i},{y[i]:.3f},{x[i]:.3f},{z[i]:.3f},road\n" for i in range(30)))
    with pytest.raises(InputError, match=r"x and y look swapped \(30 of them fall on it as y, x\)"):
        A.check_accuracy_of(dtm, read_checkpoints(str(bare), mapping={"road": "NVA"}))


def test_a_mapping_written_with_a_colon_is_answered_with_what_was_meant():
    from groundsieve.core.io.checkpoints import parse_land_cover_mapping
    with pytest.raises(InvalidParameterError, match="'road:NVA' has no '=': write it as road=NVA$"):
        parse_land_cover_mapping("road:NVA")
    with pytest.raises(InvalidParameterError, match="write it as meadow=NVA or meadow=VVA"):
        parse_land_cover_mapping("meadow")


def test_the_command_puts_the_report_and_the_csv_in_place_together(dtm, tmp_path, monkeypatch):
    """A CSV that could not be written left the report behind (a code reviewer): both or neither."""
    import io

    from groundsieve.core.engine.cli import main
    points_file = tmp_path / "cp.csv"
    write_checkpoint_file(points_file)
    report, csv = tmp_path / "r.html", tmp_path / "res.csv"

    def broken(path, result):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(A, "write_residuals_csv", broken)
    out = io.StringIO()
    assert main(["accuracy", dtm, str(points_file), "--land-cover-map", "paved=NVA,forest=VVA", "--report", str(report),
                 "--csv", str(csv)], out=out) == 1
    assert "res.csv: cannot be written" in out.getvalue() and "Traceback" not in out.getvalue()
    assert sorted(os.listdir(tmp_path)) == ["cp.csv"]


def test_a_systematic_offset_is_said_and_a_p_column_names_the_points(dtm, tmp_path):
    """Checkpoints in metres against a DTM in feet gave a mean of +47.2 ft beside a deviation of 3.3 ft without
    a hint, and a PNEZD header 'P,N,E,Z,D' lost the points' names (a flood modeller)."""
    from groundsieve.core.io.checkpoints import read_checkpoints
    x, y = points(30, seed=13)
    rng = np.random.default_rng(13)
    z = plane(x, y) - 2.0 + rng.normal(0, 0.05, 30)
    path = tmp_path / "pnezd.csv"
    path.write_text("P,N,E,Z,D\n" + "".join(f"{100 + i},{y[i]:.3f},{x[i]:.3f},{z[i]:.3f},TOB\n" for i in range(30)))
    checkpoints = read_checkpoints(str(path))
    assert checkpoints.ids[:2] == ("100", "101")
    r = A.check_accuracy_of(dtm, checkpoints)
    assert any("a systematic offset" in w and "vertical datum (geoid) or unit" in w for w in r.warnings)
    fine = A.check_accuracy(dtm, x, y, plane(x, y) + rng.normal(0, 0.05, 30))
    assert not any("systematic offset" in w for w in fine.warnings)


def test_columns_the_header_words_do_not_give_away_are_named(dtm, tmp_path):
    """A survey's 'Elev_ortho' and 'Surface' columns were refused ("names no z column") with no way to name
    them (a surveyor, in QGIS's field parameters and on the command line): the columns are named now; a
    name the header lacks, or a file without a header, is refused naming the file."""
    x, y = points(30, seed=11)
    z = plane(x, y) - 0.02
    cp = tmp_path / "cp.csv"
    cp.write_text("Name;Easting;Northing;Elev_ortho;Elev_ellipsoid;Surface\n" + "".join(
        f"S{i};{x[i]:.3f};{y[i]:.3f};{z[i]:.3f};{z[i] + 45:.3f};{'asphalt' if i % 2 else 'forest'}\n"
        for i in range(30)))
    with pytest.raises(InputError, match=r"cp\.csv, line 1: the header .* names no z column"):
        read_checkpoints(str(cp))
    out, stdout = io.StringIO(), io.StringIO()
    code = main(["accuracy", dtm, str(cp), "--z-column", "elev ortho", "--land-cover-column", "Surface",
                 "--land-cover-map", "asphalt=NVA,forest=VVA", "--json"], out=out, stdout=stdout)
    assert code == 0, out.getvalue()
    doc = json.loads(stdout.getvalue())
    assert doc["count"] == 30 and doc["all"]["mean"] == pytest.approx(0.02, abs=2e-3)
    assert doc["nva"]["count"] == 15 and doc["vva"]["count"] == 15
    ellipsoid = read_checkpoints(str(cp), columns={"z": "Elev_ellipsoid", "id": "", "land_cover": ""})
    assert np.allclose(ellipsoid.z, z + 45, atol=1e-3) and ellipsoid.ids[0] == "S0" and ellipsoid.land_cover is None
    with pytest.raises(InputError, match=r"cp\.csv, line 1: the header .* has no column 'Ortho' \(given for z\)"):
        read_checkpoints(str(cp), columns={"z": "Ortho"})
    bare = tmp_path / "bare.txt"
    bare.write_text("".join(f"{x[i]:.3f} {y[i]:.3f} {z[i]:.3f}\n" for i in range(30)))
    with pytest.raises(InputError, match=r"bare\.txt: has no header line, so it has no column 'h'"):
        read_checkpoints(str(bare), columns={"z": "h"})
    with pytest.raises(InvalidParameterError, match="checkpoint columns: height is not one of"):
        read_checkpoints(str(cp), columns={"height": "Elev_ortho"})


def test_a_file_without_header_names_its_columns_as_qgis_lists_them(tmp_path):
    """QGIS lists a headerless CSV's columns as field_1, field_2, ...: naming field_4 for the heights was
    refused ('has no header line') though the dialog offered it (a power user); the column by its place is
    read now. A land-cover column found by its header word is left alone when the caller reads none."""
    bare = tmp_path / "bare.csv"
    bare.write_text("A,500010.5,5000020.5,81.25\nB,500011.5,5000021.5,82.5\n")
    cp = read_checkpoints(str(bare), columns={"z": "field_4", "id": "field_1"})
    assert cp.ids == ("A", "B") and list(cp.z) == [81.25, 82.5] and list(cp.x) == [500010.5, 500011.5]
    with pytest.raises(InputError, match="no field_9"):
        read_checkpoints(str(bare), columns={"z": "field_9"})
    covered = tmp_path / "covered.csv"
    covered.write_text("x,y,z,cover\n500010.5,5000020.5,81.25,forest\n")
    with pytest.raises(InputError, match="'forest' is not a land cover"):
        read_checkpoints(str(covered))
    assert read_checkpoints(str(covered), land_cover=False).land_cover is None


def test_an_empty_height_in_a_file_leaves_the_checkpoint_out_and_names_it(dtm, tmp_path):
    """A checkpoint file with an empty height (a mark not observed) was refused whole ("'' is not a number"),
    where a layer's NULL height leaves the checkpoint out and names it (a technical writer): the same now."""
    x, y = points(30, seed=3)
    z = plane(x, y) + 0.01
    cp = tmp_path / "cp.csv"
    cp.write_text("id,x,y,z\n" + "".join(f"P{i},{x[i]:.3f},{y[i]:.3f},{'' if i == 4 else f'{z[i]:.3f}'}\n"
                                          for i in range(30)))
    out, stdout = io.StringIO(), io.StringIO()
    assert main(["accuracy", dtm, str(cp), "--json"], out=out, stdout=stdout) == 0, out.getvalue()
    doc = json.loads(stdout.getvalue())
    assert doc["count"] == 29
    assert "WARNING: 1 checkpoint(s) with an empty height left out: P4" in out.getvalue()
    empty = tmp_path / "empty.csv"
    empty.write_text("id,x,y,z\n" + "".join(f"P{i},{x[i]:.3f},{y[i]:.3f},\n" for i in range(3)))
    with pytest.raises(InputError, match="every checkpoint's height .* is empty"):
        read_checkpoints(str(empty))


@pytest.mark.parametrize("text, kept, left", [
    ("P0,500062.3,5000020.5,\nP1,500063,5000021,81.5\n", ("P1",), ("P0",)),  # (the first line's, no header)
    ("P1;100;200;\nP2;101;201;5\n", ("P2",), ("P1",)),
])
def test_empty_heights_however_written_are_left_out(tmp_path, text, kept, left):
    """A code reviewer: an empty height on the first line of a file without header was taken for a header. (A
    line short of its height's field, "P2,101,201", stays refused: it may as well be cut short.)"""
    path = tmp_path / "cp.csv"
    path.write_text(text)
    cp = read_checkpoints(str(path))
    assert cp.ids == kept and cp.no_height == left


def test_bad_coordinates_beside_an_empty_height_are_still_refused(tmp_path):
    """'P2,abc,def,' was left out as an empty height (a code reviewer): its coordinates are refused."""
    path = tmp_path / "cp.csv"
    path.write_text("P3,1,2,3\nP2,abc,def,\n")
    with pytest.raises(InputError, match=r"line 2: 'abc' is not a number \(column x\)"):
        read_checkpoints(str(path))
