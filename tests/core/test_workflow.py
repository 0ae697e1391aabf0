"""The file-to-file driver (core.engine.workflow.run_ground_filter) on a generated LAS scene:
classes written, noise and existing classes kept, last returns, DTM GeoTIFF, cancellation
and refusal to overwrite the input."""
from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass

import laspy
import numpy as np

from groundsieve.core.io.provenance import software
import pytest
from scipy.spatial import Delaunay

from groundsieve.core.errors import Cancelled, InputError, InvalidParameterError, OutputError
from groundsieve.core.grids.spec import GridSpec
from groundsieve.core.io import new_las, read_cloud, write_las
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter, select_points

X0, Y0 = 512000.0, 5403000.0
SIZE = 60.0
SLOPE_X = 0.1  # ground z = 100 + 0.1 (x - X0): exact on the 0.01 m LAS grid for x on 0.1 m


def ground_z(x):
    return 100.0 + SLOPE_X * (x - X0)


def utm32_wkt():
    import pyproj
    return pyproj.CRS.from_epsg(32632).to_wkt()


@dataclass
class Scene:
    path: str
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    cls: np.ndarray
    rn: np.ndarray
    nr: np.ndarray
    kind: np.ndarray  # "ground", "roof", "first" (non-last return at ground level), "last", "noise_low", ...

    def mask(self, *kinds):
        return np.isin(self.kind, kinds)


def build_scene(folder, name="scene.laz", seed=0) -> Scene:
    """Plane (tilted along x) + a 15 x 15 m building + multi-return pulses + class 7 noise."""
    rng = np.random.default_rng(seed)
    n = int(SIZE * SIZE * 2)
    gx = rng.integers(0, int(SIZE * 10), n) / 10.0
    gy = rng.integers(0, int(SIZE * 10), n) / 10.0
    roof = (gx > 20) & (gx < 35) & (gy > 22) & (gy < 37)
    kind = np.where(roof, "roof", "ground").astype(object)
    x, y = gx + X0, gy + Y0
    z = ground_z(x) + 10.0 * roof
    rn = np.ones(n, np.uint8)
    nr = np.ones(n, np.uint8)

    # 150 two-return pulses outside the building: the first return is at ground level (low
    # vegetation): SMRF would call it ground, last_returns_only must not.
    m = 150
    px = rng.integers(0, 180, m) / 10.0 + 40.0
    py = rng.integers(0, 500, m) / 10.0 + 5.0
    first = (px + X0, py + Y0, ground_z(px + X0) + 0.1)
    last = (px + X0 + 0.1, py + Y0, ground_z(px + X0 + 0.1))
    # 40 three-return pulses: the middle return is in a canopy, 6 m up.
    k = 40
    qx = rng.integers(0, 150, k) / 10.0 + 2.0
    qy = rng.integers(0, 150, k) / 10.0 + 2.0
    q1 = (qx + X0, qy + Y0, ground_z(qx + X0) + 0.05)
    q2 = (qx + X0 + 0.1, qy + Y0, ground_z(qx + X0 + 0.1) + 6.0)
    q3 = (qx + X0 + 0.2, qy + Y0, ground_z(qx + X0 + 0.2))
    # Noise (class 7): low points far below, high points above; one high point 15 m east of
    # the scene so the DTM grid reaches past the hull of the ground points.
    nx = np.array([5.0, 15.0, 45.0, 50.0, 55.0, 10.0, 30.0, 50.0, SIZE + 15.0])
    ny = np.array([5.0, 50.0, 10.0, 40.0, 55.0, 20.0, 10.0, 30.0, 30.0])
    nz = ground_z(nx + X0) + np.array([-30.0, -25.0, -40.0, -35.0, -28.0, 40.0, 55.0, 35.0, 30.0])

    x = np.concatenate([x, first[0], last[0], q1[0], q2[0], q3[0], nx + X0])
    y = np.concatenate([y, first[1], last[1], q1[1], q2[1], q3[1], ny + Y0])
    z = np.concatenate([z, first[2], last[2], q1[2], q2[2], q3[2], nz])
    rn = np.concatenate([rn, np.full(m, 1), np.full(m, 2), np.full(k, 1), np.full(k, 2), np.full(k, 3),
                         np.ones(nx.size)]).astype(np.uint8)
    nr = np.concatenate([nr, np.full(2 * m, 2), np.full(3 * k, 3), np.ones(nx.size)]).astype(np.uint8)
    kind = np.concatenate([kind, ["first"] * m, ["last"] * m, ["first"] * k, ["canopy"] * k, ["last"] * k,
                           ["noise_low"] * 5 + ["noise_high"] * 4]).astype(object)

    # Existing classes: roof partly 6 (building), partly 2 (a wrong ground), partly 1;
    # ground partly 2, partly 1, partly 0; canopy 5; noise 7.
    cls = np.zeros(x.size, np.uint8)
    idx = np.arange(x.size)
    cls[kind == "roof"] = np.where(idx[kind == "roof"] % 3 == 0, 6, np.where(idx[kind == "roof"] % 3 == 1, 2, 1))
    cls[kind == "ground"] = idx[kind == "ground"] % 3  # 0, 1, 2
    cls[np.isin(kind, ["first", "last"])] = 1
    cls[kind == "canopy"] = 5
    cls[np.char.startswith(kind.astype(str), "noise")] = 7

    x, y, z = (np.round(a, 2) for a in (x, y, z))
    las = new_las(x, y, z, point_format=1, crs_wkt=utm32_wkt(),
                  extra={"pulse_id": np.arange(x.size, dtype=np.uint32)},
                  classification=cls, return_number=rn, number_of_returns=nr,
                  intensity=(idx % 4000).astype(np.uint16), gps_time=idx * 1e-4 + 2.0e8)
    path = os.path.join(str(folder), name)
    write_las(las, path)
    return Scene(path, x, y, z, cls, rn, nr, kind.astype(str))


@pytest.fixture
def scene(tmp_path):
    return build_scene(tmp_path)


def sha256(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def read_classes(path):
    return np.asarray(laspy.read(path).classification)


# --- classification ------------------------------------------------------------------------

def test_default_run_writes_ground_and_other(scene, tmp_path):
    out = str(tmp_path / "out.laz")
    digest = sha256(scene.path)
    run = run_ground_filter(scene.path, out, SMRF())
    assert sha256(scene.path) == digest
    cls = read_classes(out)
    np.testing.assert_array_equal(cls, run.classification)
    assert (cls[scene.mask("ground", "last")] == 2).all()
    assert (cls[scene.mask("roof", "canopy")] == 1).all()
    assert (cls[scene.mask("noise_low", "noise_high")] == 7).all()  # ignore_noise: untouched
    assert set(np.unique(cls)) <= {1, 2, 7}
    assert run.ground_count == int((cls == 2).sum())
    np.testing.assert_array_equal(run.filtered, ~scene.mask("noise_low", "noise_high"))
    assert not (run.ground & ~run.filtered).any()  # ground is a subset of the filtered points
    # Every other dimension is as in the input.
    src, dst = laspy.read(scene.path), laspy.read(out)
    for name in ("X", "Y", "Z", "intensity", "gps_time", "return_number", "number_of_returns", "pulse_id"):
        np.testing.assert_array_equal(np.asarray(dst[name]), np.asarray(src[name]), err_msg=name)
    assert read_cloud(out).crs_wkt is not None


def test_first_returns_at_ground_level_are_ground_when_all_returns_are_used(scene, tmp_path):
    run = run_ground_filter(scene.path, str(tmp_path / "out.las"), SMRF())
    assert run.ground[scene.mask("first")].all()


def test_last_returns_only(scene, tmp_path):
    out = str(tmp_path / "out.las")
    run = run_ground_filter(scene.path, out, SMRF(), options=FilterOptions(last_returns_only=True))
    cls = read_classes(out)
    non_last = scene.rn < scene.nr
    assert non_last.sum() == 150 + 80
    assert not run.ground[non_last].any()
    assert (cls[non_last] == 1).all()
    assert not run.filtered[non_last].any()
    assert (cls[scene.mask("ground", "last")] == 2).all()
    assert (cls[scene.mask("roof")] == 1).all()


def test_last_returns_only_on_a_cloud_without_returns_is_said(scene, tmp_path):
    """'Only last returns' on a photogrammetric cloud (every point 1 of 1) was taken without a word (a UAV
    photogrammetry user): it leaves no point out, and the run says so; on a multi-return cloud it says nothing."""
    cloud = read_cloud(scene.path)
    flat = tmp_path / "flat.las"
    write_las(new_las(cloud.x, cloud.y, cloud.z), str(flat))  # (return 1 of 1 everywhere)
    for path, said in ((str(flat), True), (scene.path, False)):
        lines = []
        run_ground_filter(path, str(tmp_path / "out.las"), SMRF(), options=FilterOptions(last_returns_only=True),
                          log=lines.append)
        hits = [line for line in lines if "'only last returns' is set, but the cloud has no return information" in line]
        assert len(hits) == int(said), (path, lines)


def test_keep_existing_classes(scene, tmp_path):
    out = str(tmp_path / "out.las")
    run_ground_filter(scene.path, out, SMRF(), options=FilterOptions(keep_existing_classes=True))
    cls = read_classes(out)
    roof = scene.mask("roof")
    assert (cls[roof & (scene.cls == 6)] == 6).all()      # building class kept
    assert (cls[roof & (scene.cls == 2)] == 1).all()      # former ground, now not: 1
    assert (cls[roof & (scene.cls == 1)] == 1).all()
    assert (cls[scene.mask("canopy")] == 5).all()          # vegetation kept
    assert (cls[scene.mask("ground", "last")] == 2).all()
    assert (cls[scene.mask("noise_low", "noise_high")] == 7).all()


def test_noise_is_filtered_when_not_ignored(scene, tmp_path):
    out = str(tmp_path / "out.las")
    run = run_ground_filter(scene.path, out, SMRF(), options=FilterOptions(ignore_noise=False))
    cls = read_classes(out)
    noise = scene.mask("noise_low", "noise_high")
    assert run.filtered.all()
    assert (cls[noise] == 1).all()  # low outliers and high points are not ground
    assert (cls[scene.mask("ground")] == 2).all()


def test_select_points_treats_zero_returns_as_single(scene):
    cloud = read_cloud(scene.path)
    cloud.return_number[:10] = 0
    cloud.number_of_returns[:10] = 0
    keep = select_points(cloud, FilterOptions(last_returns_only=True, ignore_noise=False))
    assert keep[:10].all()


def test_text_input_has_no_returns_and_keeps_labels(tmp_path):
    rng = np.random.default_rng(1)
    n = 3000
    x = rng.integers(0, 400, n) / 10.0 + X0
    y = rng.integers(0, 400, n) / 10.0 + Y0
    label = (rng.random(n) < 0.1).astype(int)
    z = ground_z(x) + 8.0 * label
    src = tmp_path / "samp.txt"
    np.savetxt(src, np.column_stack([x, y, z, label]), fmt="%.2f %.2f %.2f %d")
    out = str(tmp_path / "samp.las")
    run = run_ground_filter(str(src), out, SMRF(), options=FilterOptions(last_returns_only=True))
    assert run.filtered.all()
    las = laspy.read(out)
    np.testing.assert_array_equal(np.asarray(las["reference_label"]), label)
    np.testing.assert_array_equal(np.asarray(las.classification), np.where(label == 0, 2, 1))


# --- DTM ------------------------------------------------------------------------------------

LAST = FilterOptions(last_returns_only=True)


def open_raster(path):
    from osgeo import gdal
    gdal.UseExceptions()
    ds = gdal.Open(path)
    band = ds.GetRasterBand(1)
    return ds, band, band.ReadAsArray().astype(np.float64)


def expected_hull(scene, grid, ground):
    xs, ys = grid.centers()
    X, Y = np.meshgrid(xs, ys)
    tri = Delaunay(np.column_stack([scene.x[ground] - X0, scene.y[ground] - Y0]))
    return tri.find_simplex(np.column_stack([X.ravel() - X0, Y.ravel() - Y0])).reshape(X.shape) >= 0, X


@pytest.mark.parametrize("cell", [1.0, 2.0])
def test_dtm_geotiff(scene, tmp_path, cell):
    from osgeo import osr
    out, dtm = str(tmp_path / "out.laz"), str(tmp_path / "dtm.tif")
    # Last returns only: the ground points then lie exactly on the plane (the low first returns,
    # 0.05-0.1 m up, would otherwise be ground too and bend the TIN by as much).
    run = run_ground_filter(scene.path, out, SMRF(), options=LAST, dtm_path=dtm,
                            dtm=DTMOptions(cell_size_m=cell))
    ds, band, values = open_raster(dtm)
    # The DTM covers every point but the ignored noise (a noise point lies 15 m east of the rest).
    kept = ~scene.mask("noise_low", "noise_high")
    grid = GridSpec.covering(scene.x[kept], scene.y[kept], cell, closed=True)
    assert run.dtm_grid == grid
    assert (ds.RasterYSize, ds.RasterXSize) == grid.shape
    gt = ds.GetGeoTransform()
    assert gt == pytest.approx(grid.geotransform)
    assert gt[1] == cell and gt[5] == -cell and gt[2] == gt[4] == 0  # row 0 is north
    assert gt[3] >= scene.y.max() > gt[3] - cell
    assert gt[0] <= scene.x.min() < gt[0] + cell
    assert gt[0] + ds.RasterXSize * cell < scene.x.max()  # the far noise point does not stretch it
    srs = osr.SpatialReference(wkt=ds.GetProjection())
    assert srs.GetAuthorityCode(None) == "32632"
    assert band.GetNoDataValue() == -9999.0
    assert band.DataType == 6  # GDT_Float32
    assert band.GetUnitType() == "m"  # heights in the CRS's unit (UTM: metres)
    assert band.GetDescription() == "elevation"  # (QGIS's legend: "Band 1: elevation", not "Band 1 (Gray)")
    assert ds.GetMetadata("IMAGE_STRUCTURE").get("PREDICTOR") == "3"  # floating-point predictor
    # a cloud-optimised GeoTIFF as a tiled run's, naming its writer (a surveyor: the format followed
    # whether the run was tiled, and nothing said which software made the DTM)
    assert ds.GetMetadata("IMAGE_STRUCTURE").get("LAYOUT") == "COG"
    assert ds.GetMetadataItem("TIFFTAG_SOFTWARE") == software()
    # The ground lies on [Y0, Y0 + 59.9] with points on y = Y0 exactly: that southern edge adds no
    # row of nodata (a closed grid: 60 m of points give 60 m of DTM, at 1 and at 2 m)
    assert ds.RasterYSize == round(SIZE / cell)
    inside, X = expected_hull(scene, grid, run.ground)
    assert inside.any() and (cell != 1.0 or (~inside).any())
    np.testing.assert_allclose(values[inside], ground_z(X)[inside], atol=1e-3)  # the ground plane
    assert (values[~inside] == -9999.0).all()


def test_dtm_fill_outside_hull(scene, tmp_path):
    dtm = str(tmp_path / "dtm.tif")
    run = run_ground_filter(scene.path, None, SMRF(), options=LAST, dtm_path=dtm,
                            dtm=DTMOptions(cell_size_m=1.0, fill_outside_hull=True))
    _, band, values = open_raster(dtm)
    assert (values != -9999.0).all()
    inside, X = expected_hull(scene, run.dtm_grid, run.ground)
    np.testing.assert_allclose(values[inside], ground_z(X)[inside], atol=1e-3)
    lo, hi = ground_z(scene.x[run.ground]).min(), ground_z(scene.x[run.ground]).max()
    assert values.min() >= lo - 1e-3 and values.max() <= hi + 1e-3
    # No LAS output asked, none written; no temporary file left.
    assert sorted(os.listdir(tmp_path)) == ["dtm.tif", "scene.laz"]


@pytest.mark.parametrize("cell", [0.0, -1.0, math.nan, math.inf])
def test_dtm_cell_must_be_positive(cell):
    with pytest.raises(InvalidParameterError, match="DTM cell size"):
        DTMOptions(cell_size_m=cell)


def test_dtm_without_any_ground_writes_nothing(scene, tmp_path):
    out, dtm = str(tmp_path / "out.laz"), str(tmp_path / "dtm.tif")
    with pytest.raises(InvalidParameterError, match="no ground"):
        run_ground_filter(scene.path, out, lambda xyz, steps=None: np.zeros(len(xyz), bool), dtm_path=dtm)
    assert os.listdir(tmp_path) == ["scene.laz"]


# --- progress, cancellation, failures ---------------------------------------------------------

def test_progress_monotonic(scene, tmp_path):
    seen = []
    run_ground_filter(scene.path, str(tmp_path / "o.laz"), SMRF(), dtm_path=str(tmp_path / "d.tif"),
                      progress=seen.append)
    assert all(0.0 <= f <= 1.0 for f in seen)
    assert all(b >= a for a, b in zip(seen, seen[1:]))
    assert seen[-1] == 1.0


def test_cancel_from_the_start_writes_nothing(scene, tmp_path):
    with pytest.raises(Cancelled):
        run_ground_filter(scene.path, str(tmp_path / "o.laz"), SMRF(), dtm_path=str(tmp_path / "d.tif"),
                          is_cancelled=lambda: True)
    assert os.listdir(tmp_path) == ["scene.laz"]


def count_checks(scene, tmp_path):
    calls = []
    run_ground_filter(scene.path, str(tmp_path / "probe.laz"), SMRF(), dtm_path=str(tmp_path / "probe.tif"),
                      is_cancelled=lambda: calls.append(1) or False)
    for name in ("probe.laz", "probe.tif"):
        os.remove(tmp_path / name)
    return len(calls)


def test_cancel_at_every_check_before_the_outputs_writes_nothing(scene, tmp_path):
    n_checks = count_checks(scene, tmp_path)
    assert n_checks > 5
    out, dtm = tmp_path / "o.laz", tmp_path / "d.tif"
    for k in range(n_checks):
        calls = {"n": 0}

        def is_cancelled():
            calls["n"] += 1
            return calls["n"] > k

        try:
            run_ground_filter(scene.path, str(out), SMRF(), dtm_path=str(dtm), is_cancelled=is_cancelled)
        except Cancelled:
            pass
        else:
            pytest.fail(f"cancel at check {k + 1} of {n_checks} was not honoured")
        leftovers = sorted(set(os.listdir(tmp_path)) - {"scene.laz"})
        if not out.exists():
            assert leftovers == [], f"cancel at check {k + 1}: {leftovers}"
        for name in leftovers:  # see test_cancel_after_the_las_is_written_leaves_no_output
            os.remove(tmp_path / name)


def test_cancel_after_the_las_is_written_leaves_no_output(scene, tmp_path):
    out, dtm = tmp_path / "o.laz", tmp_path / "d.tif"

    def las_written():  # cancel as soon as the LAS has been written under its temporary name
        return any(".part" in name for name in os.listdir(tmp_path))

    with pytest.raises(Cancelled):
        run_ground_filter(scene.path, str(out), SMRF(), dtm_path=str(dtm), is_cancelled=las_written)
    assert sorted(os.listdir(tmp_path)) == ["scene.laz"]


def test_output_equal_to_input_is_refused_before_anything(scene, tmp_path):
    digest = sha256(scene.path)
    calls, seen = [], []

    def spy(xyz, steps=None):
        calls.append(1)
        return np.ones(len(xyz), bool)

    with pytest.raises(OutputError, match="must not be the input"):
        run_ground_filter(scene.path, scene.path, spy, dtm_path=str(tmp_path / "d.tif"), progress=seen.append)
    link = tmp_path / "link.laz"
    link.symlink_to(scene.path)
    with pytest.raises(OutputError, match="must not be the input"):
        run_ground_filter(scene.path, str(link), spy, progress=seen.append)
    # the same file by another path that realpath cannot see through (a share mounted twice, a bind
    # mount: a reviewer's input was replaced by its copy); a hard link has the same device and inode
    other = tmp_path / "other"
    other.mkdir()
    os.link(scene.path, other / "scene.laz")
    with pytest.raises(OutputError, match="must not be the input"):
        run_ground_filter(scene.path, str(other / "scene.laz"), spy, progress=seen.append)
    # an output that is an existing folder is refused before the work, not at the rename after it
    (tmp_path / "d.laz").mkdir()
    with pytest.raises(OutputError, match="d.laz: is a folder"):
        run_ground_filter(scene.path, str(tmp_path / "d.laz"), spy, progress=seen.append)
    # a read-only file there is not replaced (a rename did, and made it writable: PDAL, GDAL and cp refuse)
    (tmp_path / "ro.laz").write_bytes(b"keep")
    os.chmod(tmp_path / "ro.laz", 0o444)
    with pytest.raises(OutputError, match="ro.laz: the file there is read-only"):
        run_ground_filter(scene.path, str(tmp_path / "ro.laz"), spy, progress=seen.append)
    assert (tmp_path / "ro.laz").read_bytes() == b"keep"
    assert calls == [] and seen == []
    assert sha256(scene.path) == digest
    assert sorted(os.listdir(tmp_path)) == ["d.laz", "link.laz", "other", "ro.laz", "scene.laz"]


def test_bad_dtm_path_is_refused_before_the_las_is_written(scene, tmp_path):
    out = tmp_path / "o.laz"
    with pytest.raises(OutputError, match=r"\.tif"):
        run_ground_filter(scene.path, str(out), SMRF(), dtm_path=str(tmp_path / "dtm.las"))
    with pytest.raises(OutputError, match="does not exist"):
        run_ground_filter(scene.path, str(out), SMRF(), dtm_path=str(tmp_path / "nodir" / "dtm.tif"))
    assert not out.exists()


def test_failing_filter_writes_nothing(scene, tmp_path):
    def broken(xyz, steps=None):
        raise RuntimeError("filter crashed")

    with pytest.raises(RuntimeError, match="filter crashed"):
        run_ground_filter(scene.path, str(tmp_path / "o.laz"), broken, dtm_path=str(tmp_path / "d.tif"))
    assert os.listdir(tmp_path) == ["scene.laz"]


def test_missing_input(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        run_ground_filter(str(tmp_path / "none.laz"), str(tmp_path / "o.laz"), SMRF())
    assert os.listdir(tmp_path) == []


def test_everything_noise_is_refused(tmp_path):
    x = np.arange(10.0) + X0
    las = new_las(x, x * 0 + Y0, x * 0, classification=np.full(10, 7, np.uint8))
    src = str(tmp_path / "noise.las")
    write_las(las, src)
    with pytest.raises(InvalidParameterError, match="no point is left"):
        run_ground_filter(src, str(tmp_path / "o.las"), SMRF())
    assert os.listdir(tmp_path) == ["noise.las"]


def test_a_stray_point_that_stretches_the_dtm_is_said(tmp_path):
    """One point 2 km away made a DTM of mostly empty cells without a word (a reviewer's: 80,120 x 240
    cells, 0.3 % with a value): the run names it, how far and where, and what to do."""
    from groundsieve.core.synthetic import SceneSpec, make_scene
    s = make_scene(SceneSpec(size_m=60.0, density_per_m2=2.0, seed=6))
    x, y, z = np.append(s.x, s.x[0] + 2000.0), np.append(s.y, s.y[0]), np.append(s.z, s.z[0])
    path = str(tmp_path / "stray.laz")
    write_las(new_las(x, y, z, return_number=np.append(s.return_number, 1),
                      number_of_returns=np.append(s.number_of_returns, 1)), path)
    lines = []
    run_ground_filter(path, None, SMRF(), dtm_path=str(tmp_path / "d.tif"), dtm=DTMOptions(cell_size_m=1.0),
                      log=lines.append)
    said = [line for line in lines if line.startswith("Warning: DTM: 1 point(s) lie far from the others")]
    assert len(said) == 1 and f"x {x[-1]:,.2f}" in said[0] and "noise (7)" in said[0], lines
    write_las(new_las(s.x, s.y, s.z, return_number=s.return_number, number_of_returns=s.number_of_returns),
              str(tmp_path / "clean.laz"))
    lines = []  # without it: nothing said
    run_ground_filter(str(tmp_path / "clean.laz"), None, SMRF(), dtm_path=str(tmp_path / "f.tif"),
                      dtm=DTMOptions(cell_size_m=1.0), log=lines.append)
    assert not any("far from the others" in line for line in lines)


def test_return_number_0_is_no_number_not_an_earlier_return(scene, tmp_path):
    """A writer's "0 of 1" (return number 0: none written) made every ground point a non-last return: a false
    warning of canopy in the ground, and with 'only last returns' every point left out, "no point is left to
    filter" (a code reviewer). Such a point is neither warned about nor left out."""
    cloud = read_cloud(scene.path)
    n = len(cloud)
    src = tmp_path / "zero.las"
    write_las(new_las(cloud.x, cloud.y, cloud.z, return_number=np.zeros(n, np.uint8),
                      number_of_returns=np.ones(n, np.uint8)), str(src))
    for last in (False, True):
        lines = []
        run = run_ground_filter(str(src), str(tmp_path / "out.las"), SMRF(),
                                options=FilterOptions(last_returns_only=last), log=lines.append)
        assert run.filtered.all() and run.ground.any()
        assert not [line for line in lines if "are not the last return of their pulse" in line]
