"""COPC inputs read by bounds (core/io/copc.py and its hooks in core/engine/tiles.py): a tiled run
reads each tile's points and buffer from the COPC file's octree nodes instead of binning the file,
keeps every point's index in the file's own order, and classifies exactly as the same run on the
same points in a plain LAZ.

The COPC files are written by copclib (copc-lib's Python binding), an independent writer: our reader
is not tested against our own writer. :func:`write_copc` builds the octree from a generated scene
(each level keeps one point per cell of a grid that halves with the level, the rest go deeper) and
adds the nodes in shuffled order with hierarchy sub-pages, so that the file order is neither the
scene's nor the octree's.
"""
from __future__ import annotations

import dataclasses
import json
import os
import struct

import copclib  # requirements-dev.txt: a missing install fails here, it is not skipped
import laspy
import numpy as np
import pytest

from groundsieve.core.engine import tiles as tiles_module
from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, classify_cloud, run_ground_filter
from groundsieve.core.errors import InputError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.io import new_las, read_cloud
from groundsieve.core.io import copc as copc_io
from groundsieve.core.io.lasfiles import scan_header, tile_cloud, write_vpc
from groundsieve.tests.core.scenes import flaky_smrf
from groundsieve.core.synthetic import SceneSpec, make_scene, scene_crs_wkt

TILE = 70.0
#: 560 m at 1 pulse/m²: about 380,000 points; 70 m tiles with SMRF's 38 m buffer (146 m square)
SPEC = SceneSpec(size_m=560.0, density_per_m2=1.0, seed=11)
#: the folder/.vpc test's smaller scene
SMALL = SceneSpec(size_m=240.0, density_per_m2=2.0, seed=5)


def write_copc(path, las, *, grid=64, seed=0, page_depth=2):
    """Write the points of ``las`` (a laspy LasData of point format 6, 7 or 8) as a COPC file with
    copclib: an octree whose level d keeps one point per (x, y) cell of side (cube side / 2^d) /
    ``grid`` (random pick; airborne lidar's levels of detail), the rest going deeper; nodes below ``page_depth`` in hierarchy sub-pages; nodes
    written in random order. Returns the number of nodes."""
    x, y, z = (np.asarray(a, dtype=np.float64) for a in (las.x, las.y, las.z))
    n = x.size
    lo = np.array([x.min(), y.min(), z.min()])
    hi = np.array([x.max(), y.max(), z.max()])
    center = (lo + hi) / 2
    half = float((hi - lo).max()) / 2 + 1.0
    corner = center - half
    rng = np.random.default_rng(seed)
    depth = max(1, int(np.ceil(np.log(max(n, 1) / (grid * grid)) / np.log(4))))
    level = np.full(n, depth, dtype=np.int64)
    rest = rng.permutation(n)
    p = np.column_stack([x, y, z]) - corner
    for d in range(depth):
        c = np.floor(p[rest, :2] / (2 * half / 2 ** d / grid)).astype(np.int64)
        _, first = np.unique(c[:, 0] * (1 << 31) + c[:, 1], return_index=True)
        level[rest[first]] = d
        keep = np.ones(rest.size, dtype=bool)
        keep[first] = False
        rest = rest[keep]
    k = np.minimum(np.floor(p / (2 * half / 2.0 ** level)[:, None]).astype(np.int64), (2 ** level)[:, None] - 1)
    node = ((level * (1 << 20) + k[:, 0]) * (1 << 20) + k[:, 1]) * (1 << 20) + k[:, 2]
    order = np.argsort(node, kind="stable")
    cuts = np.flatnonzero(np.diff(node[order])) + 1
    starts, stops = np.r_[0, cuts], np.r_[cuts, n]
    h = las.header
    crs = h.parse_crs()
    cfg = copclib.CopcConfigWriter(int(h.point_format.id), copclib.Vector3(*map(float, h.scales)),
                                   copclib.Vector3(*map(float, h.offsets)), crs.to_wkt() if crs else "")
    cfg.las_header.min = copclib.Vector3(*lo)
    cfg.las_header.max = copclib.Vector3(*hi)
    cfg.copc_info.center_x, cfg.copc_info.center_y, cfg.copc_info.center_z = map(float, center)
    cfg.copc_info.halfsize = half
    cfg.copc_info.spacing = 2 * half / grid
    writer = copclib.FileWriter(str(path), cfg)
    records = las.points.array
    for g in rng.permutation(len(starts)):
        idx = order[starts[g]:stops[g]]
        d, (kx, ky, kz) = int(level[idx[0]]), (int(v) for v in k[idx[0]])
        s = d - page_depth
        page = copclib.VoxelKey(page_depth, kx >> s, ky >> s, kz >> s) if page_depth and s >= 0 else \
            copclib.VoxelKey(0, 0, 0, 0)
        writer.AddNode(copclib.VoxelKey(d, kx, ky, kz),
                       copclib.VectorChar(np.ascontiguousarray(records[idx]).view(np.int8)), page)
    writer.Close()
    return len(starts)


def scene_las(scene, keep=slice(None)):
    """The scene as LAS 1.4 point format 6, each point's index in the scene in ``gps_time``."""
    ids = np.arange(len(scene.x), dtype=np.float64)[keep]
    return new_las(scene.x[keep], scene.y[keep], scene.z[keep], point_format=6, version="1.4", scale=0.001,
                   crs_wkt=scene_crs_wkt(), classification=scene.classification[keep],
                   return_number=scene.return_number[keep], number_of_returns=scene.number_of_returns[keep],
                   intensity=scene.intensity[keep], gps_time=ids)


def plain_copy(src, dst):
    """The points of ``src`` in its own order, as a plain LAZ (a fresh laspy header: no COPC VLR)."""
    a = laspy.read(src)
    las = new_las(a.x, a.y, a.z, point_format=6, version="1.4", scale=0.001, crs_wkt=scene_crs_wkt(),
                  classification=a.classification, return_number=a.return_number,
                  number_of_returns=a.number_of_returns, intensity=a.intensity, gps_time=a.gps_time)
    las.write(str(dst))
    return str(dst)


@pytest.fixture(scope="module")
def scene():
    return make_scene(SPEC)


@pytest.fixture(scope="module")
def files(scene, tmp_path_factory):
    """The scene as COPC (copclib) and the same points, in the same order, as a plain LAZ."""
    folder = tmp_path_factory.mktemp("copc")
    copc = folder / "scene.copc.laz"
    nodes = write_copc(copc, scene_las(scene))
    assert nodes > 20
    return str(copc), plain_copy(copc, folder / "plain.laz")


def tiled(tile=TILE):
    return FilterOptions(tiling=TileOptions(tile_size_m=tile, workers=2, parallel="threads"))


def test_copclib_file_is_copc_and_detected_by_its_vlr(files, tmp_path):
    copc, plain = files
    with laspy.CopcReader.open(copc) as reader:  # laspy's own COPC reader takes it
        assert len(reader.query()) == scan_header(copc).count
    assert scan_header(copc).copc and not scan_header(plain).copc
    renamed = tmp_path / "no_copc_in_the_name.laz"  # detected by the VLR, not by the name
    renamed.write_bytes(open(copc, "rb").read())
    assert scan_header(str(renamed)).copc


def test_node_indices_are_the_file_order(files):
    """Every node's points get the index a streamed read of the file gives them: the chunks in
    file-offset order (they were written shuffled, so key order or hierarchy order would fail)."""
    copc, _ = files
    index = copc_io.open_index(copc)
    assert np.all(np.diff(index.nodes["offset"].astype(np.int64)) > 0)
    points, file_index = copc_io._read_nodes(index, np.arange(index.nodes.size))
    streamed = np.asarray(laspy.read(copc).gps_time)
    assert np.array_equal(np.sort(file_index), np.arange(streamed.size))
    assert np.array_equal(np.asarray(points.gps_time), streamed[file_index])
    # a few nodes alone: their indices, not a running count
    some = np.array([1, 7, index.nodes.size // 2, index.nodes.size - 1])
    points, file_index = copc_io._read_nodes(index, some)
    assert np.array_equal(np.asarray(points.gps_time), streamed[file_index])


def test_tile_cloud_has_every_field_read_cloud_gives(files):
    copc, _ = files
    info = scan_header(copc)
    size = 1.0e5  # one tile holding the whole file
    key = (int(np.floor(info.mins[0] / size)), int(np.floor(info.mins[1] / size)))
    cloud, idx, decompressed = copc_io.read_tile(copc_io.CopcSource(0, copc, key, size, 0.0))
    assert decompressed == info.count and np.array_equal(idx, np.arange(info.count))
    whole = read_cloud(copc)
    for name in whole.__dataclass_fields__:
        mine, theirs = getattr(cloud, name), getattr(whole, name)
        if name == "las":
            assert mine is None
        elif isinstance(theirs, np.ndarray):
            assert isinstance(mine, np.ndarray) and mine.dtype == theirs.dtype and np.array_equal(mine, theirs), name
        else:
            assert mine == theirs, name


@pytest.fixture(scope="module")
def runs(files, tmp_path_factory):
    """The same tiled SMRF run with a 1 m DTM on the COPC file and on the plain LAZ; which files
    the binning pass was given. Without the node cache, so that each tile decompresses every node
    it reads (the cache is tested on its own, and by the folder and resume tests)."""
    copc, plain = files
    folder = tmp_path_factory.mktemp("runs")
    binned = []
    real = tiles_module.bin_file

    def spy(path, *args, **kwargs):
        binned.append(path)
        return real(path, *args, **kwargs)
    tiles_module.bin_file = spy
    cache, copc_io._CACHE = copc_io._CACHE, copc_io._NodeCache(0)
    try:
        out = {}
        for name, src in (("copc", copc), ("plain", plain)):
            run = run_ground_filter(src, str(folder / f"{name}.laz"), SMRF(), options=tiled(),
                                    dtm_path=str(folder / f"{name}.tif"), dtm=DTMOptions(cell_size_m=1.0))
            out[name] = run
    finally:
        tiles_module.bin_file = real
        copc_io._CACHE = cache
    return out, binned, folder


def test_copc_input_is_not_binned(runs, files):
    out, binned, folder = runs
    copc, plain = files
    assert out["copc"].copc_inputs == [copc] and out["plain"].copc_inputs == []
    assert copc not in binned and plain in binned  # the spy sees the plain run's binning
    assert out["copc"].tiles == out["plain"].tiles >= 25


def test_each_tile_decompresses_a_bounded_share_of_the_file(runs):
    out, _, _ = runs
    run = out["copc"]
    count = run.point_count
    reads = [t["copc_read"] for t in run.tile_log]
    assert len(reads) == run.tiles and min(reads) > 0
    # a 146 m buffered tile of a 560 m scene is 7 % of its area; the nodes it meets are wider,
    # and the upper nodes are read by every tile
    print(f"decompressed per tile: max {max(reads) / count:.1%}, mean {np.mean(reads) / count:.1%} of the "
          f"file; in all {sum(reads) / count:.2f} times the file")
    # measured: max 18.6 %, mean 12.5 % (10.1 times the file in all, over 81 tiles, without the
    # node cache: the price of small tiles, whose buffered box meets 3 or 4 of the 70 m leaf
    # nodes each way, and of the upper nodes every tile reads)
    assert max(reads) < 0.25 * count and np.mean(reads) < 0.15 * count
    assert all(t["read"] <= t["copc_read"] for t in run.tile_log)


def test_node_cache_spares_decompressing_a_node_twice(files):
    copc, _ = files
    info = scan_header(copc)
    cache, copc_io._CACHE = copc_io._CACHE, copc_io._NodeCache(64 << 20)
    try:
        key = (int(np.floor(info.mins[0] / TILE)) + 2, int(np.floor(info.mins[1] / TILE)) + 2)
        first = copc_io.read_tile(copc_io.CopcSource(0, copc, key, TILE, 38.0))
        again = copc_io.read_tile(copc_io.CopcSource(0, copc, key, TILE, 38.0))
        assert first[2] > 0 and again[2] == 0
        assert np.array_equal(first[1], again[1]) and np.array_equal(first[0].z, again[0].z)
        assert np.array_equal(first[0].intensity, again[0].intensity)
        beside = copc_io.read_tile(copc_io.CopcSource(0, copc, (key[0], key[1] + 1), TILE, 38.0))
        copc_io._CACHE = copc_io._NodeCache(0)
        alone = copc_io.read_tile(copc_io.CopcSource(0, copc, (key[0], key[1] + 1), TILE, 38.0))
        assert 0 < beside[2] < 0.7 * alone[2]  # the upper nodes and the shared strip were held
        assert np.array_equal(beside[1], alone[1]) and np.array_equal(beside[0].x, alone[0].x)
    finally:
        copc_io._CACHE = cache


def test_copc_run_classifies_exactly_as_the_plain_laz_run(runs, files):
    out, _, folder = runs
    copc, plain = files
    a, b = laspy.read(folder / "copc.laz"), laspy.read(folder / "plain.laz")
    assert np.array_equal(a.gps_time, laspy.read(copc).gps_time)  # every point, in the COPC's order
    assert np.array_equal(a.gps_time, b.gps_time)
    assert np.array_equal(a.classification, b.classification)
    assert out["copc"].ground_count == out["plain"].ground_count > 0
    whole = classify_cloud(read_cloud(copc), SMRF()).classification
    assert np.mean(np.asarray(a.classification) == whole) >= 0.999


def test_copc_run_dtm_equals_the_plain_laz_run_dtm(runs):
    from osgeo import gdal
    _, _, folder = runs
    one, two = gdal.Open(str(folder / "copc.tif")), gdal.Open(str(folder / "plain.tif"))
    assert one.GetGeoTransform() == two.GetGeoTransform()
    a, b = one.ReadAsArray(), two.ReadAsArray()
    assert a.shape == b.shape and np.array_equal(a, b)
    assert np.count_nonzero(a != -9999) > 0.9 * a.size


def test_output_of_a_copc_input_is_a_plain_laz_with_every_point(runs, files):
    """The classified copy's LAZ chunks are not the octree's nodes: it carries no COPC record
    (laspy's CopcReader refuses it), and keeps every point, dimension, VLR and the CRS (which
    copclib writes as an EVLR)."""
    _, _, folder = runs
    copc, _ = files
    out = str(folder / "copc.laz")
    assert not scan_header(out).copc
    with pytest.raises(Exception, match="COPC"):
        laspy.CopcReader.open(out)
    with laspy.open(out) as reader:
        assert not any(str(v.user_id).rstrip("\0") == "copc" for v in reader.header.vlrs)
        assert not any(str(v.user_id).rstrip("\0") == "copc" for v in reader.header.evlrs or [])
    assert scan_header(out).crs_wkt == scan_header(copc).crs_wkt is not None
    a, b = laspy.read(copc), laspy.read(out)
    for dim in a.point_format.dimension_names:
        if dim != "classification":
            assert np.array_equal(a[dim], b[dim]), dim


def _damage(src, dst, how):
    data = bytearray(open(src, "rb").read())
    if how == "truncated":
        data = data[:len(data) * 2 // 3]
    else:  # one hierarchy entry's point count wrong
        with laspy.CopcReader.open(src) as reader:
            at = reader.copc_info.hierarchy_root_offset
        data[at + 28:at + 32] = np.int32(12345).tobytes()
    open(dst, "wb").write(bytes(data))
    return str(dst)


def test_a_truncated_copc_is_refused_naming_the_file(files, tmp_path):
    bad = _damage(files[0], tmp_path / "bad.copc.laz", "truncated")
    with pytest.raises(InputError, match=r"bad\.copc\.laz: .*the file is truncated or its header is damaged"):
        run_ground_filter(bad, str(tmp_path / "out.laz"), SMRF(), options=tiled())
    assert not (tmp_path / "out.laz").exists()


def test_a_copc_with_a_damaged_index_is_read_as_a_plain_laz_with_a_warning(files, runs, tmp_path):
    """A wrong count in its hierarchy: a run of the whole file reads the LAZ chunks and never looks at
    the index; a tiled run refused the file. It now bins it as the plain LAZ it also is, saying so, and
    gives the plain file's classes."""
    bad = _damage(files[0], tmp_path / "bad.copc.laz", "counts")
    info = scan_header(bad)
    assert not info.copc and "hierarchy holds" in info.copc_damaged
    assert scan_header(files[0]).copc and not scan_header(files[0]).copc_damaged
    said = []
    run_ground_filter(bad, str(tmp_path / "out.laz"), SMRF(), options=tiled(), log=said.append)
    warned = [m for m in said if "bad.copc.laz: a damaged COPC file (its hierarchy holds" in m]
    assert len(warned) == 1 and "read as a plain LAZ file's" in warned[0], said
    _, _, folder = runs
    got, plain = laspy.read(tmp_path / "out.laz"), laspy.read(folder / "plain.laz")
    assert np.array_equal(got.gps_time, plain.gps_time)
    assert np.array_equal(got.classification, plain.classification)


@pytest.mark.parametrize("halfsize", [float("nan"), -300.0, 1e-3])
def test_a_copc_whose_octree_cube_misses_its_points_is_read_as_a_plain_laz(files, runs, tmp_path, halfsize):
    """A NaN, negative or tiny half side in the COPC info VLR put every node nowhere: a tiled run read
    none of their points and said "the file's header and its points disagree" (a QA reviewer), where a
    run of the whole file reads them all. The cube is checked: such a file is binned as the plain LAZ it
    is, with a warning naming the cube."""
    data = bytearray(open(files[0], "rb").read())
    info_at = struct.unpack_from("<H", data, 94)[0] + 54  # the first VLR's data: the COPC info
    struct.pack_into("<d", data, info_at + 24, halfsize)
    bad = tmp_path / "cube.copc.laz"
    bad.write_bytes(bytes(data))
    assert "does not hold the points' bounds" in scan_header(str(bad)).copc_damaged
    said = []
    run_ground_filter(str(bad), str(tmp_path / "out.laz"), SMRF(), options=tiled(), log=said.append)
    assert any("cube.copc.laz: a damaged COPC file (its octree's cube" in m for m in said), said
    _, _, folder = runs
    got, plain = laspy.read(tmp_path / "out.laz"), laspy.read(folder / "plain.laz")
    assert np.array_equal(got.gps_time, plain.gps_time) and np.array_equal(got.classification, plain.classification)


def test_copc_and_plain_laz_in_one_folder_and_vpc(tmp_path):
    """West half a plain LAZ, east half a COPC: the same classes as both halves as plain LAZ (same
    point order), through a folder and through a .vpc."""
    scene = make_scene(SMALL)
    at_x = float(np.floor(np.median(scene.x))) + 0.5  # inside a tile
    west, east = scene.x < at_x, scene.x >= at_x
    (tmp_path / "mixed").mkdir()
    (tmp_path / "plain").mkdir()
    scene_las(scene, west).write(str(tmp_path / "mixed" / "a_west.laz"))
    write_copc(tmp_path / "mixed" / "b_east.copc.laz", scene_las(scene, east), seed=3)
    scene_las(scene, west).write(str(tmp_path / "plain" / "a_west.laz"))
    plain_copy(tmp_path / "mixed" / "b_east.copc.laz", tmp_path / "plain" / "b_east.copc.laz")
    mixed = [str(tmp_path / "mixed" / n) for n in ("a_west.laz", "b_east.copc.laz")]
    vpc = tmp_path / "mixed.vpc"
    write_vpc(str(vpc), [scan_header(p) for p in mixed], mixed)
    ref = run_ground_filter(str(tmp_path / "plain"), str(tmp_path / "ref.vpc"), SMRF(), options=tiled())
    assert ref.copc_inputs == []
    # the COPC input's copy is a plain LAZ, named .laz (readers open a .copc.laz as COPC)
    want = {n: laspy.read(tmp_path / "ref" / n).classification for n in ("a_west.laz", "b_east.laz")}
    for source, out in ((str(tmp_path / "mixed"), tmp_path / "m1.vpc"), (str(vpc), tmp_path / "m2.vpc")):
        run = run_ground_filter(source, str(out), SMRF(), options=tiled())
        assert run.copc_inputs == [mixed[1]]
        for name, classes in want.items():
            got = laspy.read(os.path.join(os.path.splitext(str(out))[0], name))
            assert np.array_equal(got.classification, classes), name
        features = json.load(open(out))["features"]
        assert [f["properties"]["pc:count"] for f in features] == [int(west.sum()), int(east.sum())]
        assert [os.path.basename(f["assets"]["data"]["href"]) for f in features] == ["a_west.laz", "b_east.laz"]
    whole = classify_cloud(tile_cloud([read_cloud(p) for p in mixed]), SMRF()).classification
    assert np.mean(np.concatenate(list(want.values())) == whole) >= 0.999


def test_one_file_of_a_survey_of_copc_and_plain_laz_is_classified_as_the_whole_survey(tmp_path):
    """A job of an array (``only``) whose file is a COPC file, or a plain LAZ beside one: the COPC file
    is read by bounds as the tiles' own points or as their buffer, and each file's classes are those of
    the run of the whole survey."""
    scene = make_scene(SMALL)
    at_x = float(np.floor(np.median(scene.x))) + 0.5
    west, east = scene.x < at_x, scene.x >= at_x
    (tmp_path / "mixed").mkdir()
    scene_las(scene, west).write(str(tmp_path / "mixed" / "a_west.laz"))
    write_copc(tmp_path / "mixed" / "b_east.copc.laz", scene_las(scene, east), seed=3)
    run_ground_filter(str(tmp_path / "mixed"), str(tmp_path / "whole.vpc"), SMRF(), options=tiled(),
                      dtm_path=str(tmp_path / "whole.tif"), dtm=DTMOptions(cell_size_m=1.0))
    from osgeo import gdal
    whole = gdal.Open(str(tmp_path / "whole.tif"))
    wg, wv = whole.GetGeoTransform(), whole.ReadAsArray()
    for only, name in ((0, "a_west"), ("b_east.copc.laz", "b_east")):
        options = FilterOptions(tiling=dataclasses.replace(tiled().tiling, only=only))
        run = run_ground_filter(str(tmp_path / "mixed"), str(tmp_path / "jobs"), SMRF(), options=options,
                                dtm_path=str(tmp_path / "dtm"), dtm=DTMOptions(cell_size_m=1.0))
        assert run.outputs == [str(tmp_path / "jobs" / f"{name}.laz")]
        assert np.array_equal(laspy.read(run.outputs[0]).classification,
                              laspy.read(tmp_path / "whole" / f"{name}.laz").classification)
        ds = gdal.Open(run.dtm_path)
        g, v = ds.GetGeoTransform(), ds.ReadAsArray()
        col, row = round((g[0] - wg[0]) / wg[1]), round((g[3] - wg[3]) / wg[5])
        assert np.array_equal(v, wv[row:row + v.shape[0], col:col + v.shape[1]])


def test_an_output_named_copc_laz_is_refused(files, tmp_path):
    """The copy of a COPC input is a plain LAZ; named .copc.laz, QGIS's COPC provider (and other readers)
    would open it as COPC and fail (a format reviewer)."""
    from groundsieve.core.errors import OutputError
    with pytest.raises(OutputError, match=r"out\.copc\.laz: the output is a plain LAZ, not COPC .*name it \.laz"):
        run_ground_filter(files[0], str(tmp_path / "out.copc.laz"), SMRF())
    assert os.listdir(tmp_path) == []


def test_an_interrupted_copc_run_resumes(tmp_path):
    """The COPC tiles are planned again from the hierarchy on resuming: the tiles done are skipped,
    the others run, and the output is the uninterrupted run's."""
    Flaky = flaky_smrf(budget=3)
    copc = tmp_path / "small.copc.laz"
    write_copc(copc, scene_las(make_scene(SMALL)))
    work = tmp_path / "work"
    work.mkdir()
    options = FilterOptions(tiling=TileOptions(tile_size_m=TILE, workers=1, work_dir=str(work)))
    out = tmp_path / "out.laz"
    with pytest.raises(Exception, match="killed"):
        run_ground_filter(str(copc), str(out), Flaky(), options=options)
    assert not out.exists()
    Flaky.failing, Flaky.calls = False, 0
    messages = []
    run = run_ground_filter(str(copc), str(out), Flaky(), options=options, log=messages.append)
    assert Flaky.calls == run.tiles - 3 and any("3 of" in m and "skipping" in m for m in messages)
    clean = tmp_path / "clean.laz"
    run_ground_filter(str(copc), str(clean), SMRF(), options=tiled())
    assert np.array_equal(laspy.read(out).classification, laspy.read(clean).classification)


def test_a_copc_run_as_one_cloud_writes_a_plain_laz(tmp_path):
    """A COPC small enough for one cloud (no tiling) goes through read_cloud and write_classified:
    its copy is written (laspy writes no COPC record) as a plain LAZ with every point."""
    copc = tmp_path / "small.copc.laz"
    write_copc(copc, scene_las(make_scene(SMALL)))
    out = tmp_path / "out.laz"
    run = run_ground_filter(str(copc), str(out), SMRF())
    assert run.cloud is not None  # the whole-cloud run, not tiles
    assert not scan_header(str(out)).copc and scan_header(str(out)).crs_wkt == scan_header(str(copc)).crs_wkt
    a, b = laspy.read(copc), laspy.read(out)
    assert np.array_equal(a.gps_time, b.gps_time) and np.array_equal(a.X, b.X)
    assert np.array_equal(b.classification, classify_cloud(read_cloud(str(copc)), SMRF()).classification)


def test_tile_points_are_those_binning_gives_even_on_the_edges(tmp_path):
    """Points on a 1 m lattice, so that many lie exactly on tile edges (70 m) and buffer edges
    (38 m beyond them): every tile read by bounds holds the same points, own and buffer, as the
    tile parts ``bin_file`` writes for the same points in a plain LAZ, in the same (file) order."""
    from groundsieve.core.io.lasfiles import TileGrid, bin_file, read_part
    g = np.arange(0.0, 301.0)
    x, y = (a.ravel() + off for a, off in zip(np.meshgrid(g, g), (500_010.0, 5_400_020.0)))
    rng = np.random.default_rng(2)
    las = new_las(x, y, rng.uniform(100, 110, x.size), point_format=6, version="1.4", scale=0.001,
                  crs_wkt=scene_crs_wkt(), gps_time=np.arange(x.size, dtype=np.float64))
    copc = tmp_path / "lattice.copc.laz"
    write_copc(copc, las, seed=4)
    plain = plain_copy(copc, tmp_path / "lattice.laz")
    grid = TileGrid(TILE, 38.0)
    (tmp_path / "parts").mkdir()
    parts = bin_file(plain, 0, grid, str(tmp_path / "parts"))
    assert len(parts) >= 25
    for key, part in parts.items():
        part_cloud, want = read_part(part)
        cloud, got, _ = copc_io.read_tile(copc_io.CopcSource(0, str(copc), key, grid.size, grid.buffer))
        assert np.all(np.diff(np.where(got >= 0, got, -1 - got)) > 0)  # in file order
        assert np.array_equal(got, want), key  # same points, same own/buffer marks, same order
        assert np.array_equal(cloud.x, part_cloud.x) and np.array_equal(cloud.y, part_cloud.y)


def test_copc_files_cut_on_the_tile_edges_give_each_tile_its_buffer(scene, tmp_path):
    """A delivery of COPC files in tiles on the files' edges (500 m files, 500 m tiles): a tile took no
    point of its neighbours' files for its buffer ('+0 buffer'), and its seams were wrong by up to 0.34 m
    (1.23 m with SMRF), where the same files as plain LAZ gave the whole run's DTM (an HPC reviewer). Each
    tile now reads its buffer from every file it reaches: the COPC run classifies and interpolates as the
    plain one."""
    x = np.asarray(scene.x)
    cut = (np.floor(np.median(x) / TILE)) * TILE  # a file edge on a tile edge
    for kind in ("copc", "plain"):
        (tmp_path / kind).mkdir()
    for name, keep in (("west", x < cut), ("east", x >= cut)):
        copc = tmp_path / "copc" / f"{name}.copc.laz"
        write_copc(copc, scene_las(scene, keep))
        plain_copy(copc, tmp_path / "plain" / f"{name}.laz")
    logs, out = {}, {}
    for kind in ("copc", "plain"):
        (tmp_path / f"out_{kind}").mkdir()
        logs[kind] = []
        out[kind] = run_ground_filter(str(tmp_path / kind), str(tmp_path / f"out_{kind}" / "c.vpc"), SMRF(),
                                      options=tiled(), dtm_path=str(tmp_path / f"{kind}.tif"),
                                      dtm=DTMOptions(cell_size_m=1.0), log=logs[kind].append)
    assert not any("+0 buffer" in line for line in logs["copc"] if line.startswith("Tile ")), logs["copc"][:12]
    for name in ("west", "east"):
        a = laspy.read(tmp_path / "out_copc" / "c" / f"{name}.laz")  # (a classified copy is no COPC)
        b = laspy.read(tmp_path / "out_plain" / "c" / f"{name}.laz")
        order_a, order_b = np.argsort(a.gps_time), np.argsort(b.gps_time)
        assert np.array_equal(np.asarray(a.classification)[order_a], np.asarray(b.classification)[order_b]), name
    from osgeo import gdal
    one, two = gdal.Open(str(tmp_path / "copc.tif")).ReadAsArray(), gdal.Open(str(tmp_path / "plain.tif")).ReadAsArray()
    assert one.shape == two.shape and np.array_equal(one, two)
