"""Reading and writing point clouds (core.io): round trips, errors naming the file, output
path checks, atomic writes, and the input left untouched."""
from __future__ import annotations

import hashlib
import os
import stat

import laspy
import numpy as np
import pytest

from groundsieve.core.errors import GroundSieveError, InputError, OutputError, UnsupportedFormatError
from groundsieve.core.io import (atomic_path, check_output_path, new_las, read_cloud, write_classified,
                                 write_las)


def utm32_wkt() -> str:
    import pyproj
    return pyproj.CRS.from_epsg(32632).to_wkt()


def epsg_of(wkt):
    import pyproj
    return pyproj.CRS.from_wkt(wkt).to_epsg() if wkt else None


def sha256(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def sample_las(n=2000, point_format=1, version="1.2", seed=0, crs=True, extra=True, big_classes=False):
    """A LasData with every dimension filled with known values on the 0.01 m grid."""
    rng = np.random.default_rng(seed)
    x = np.round(rng.uniform(0, 100, n), 2) + 512000.0
    y = np.round(rng.uniform(0, 100, n), 2) + 5403000.0
    z = np.round(rng.uniform(280, 320, n), 2)
    nr = rng.integers(1, 4, n).astype(np.uint8)
    rn = np.minimum(rng.integers(1, 4, n), nr).astype(np.uint8)
    top_class = 64 if big_classes else 19
    dims = dict(classification=rng.integers(0, top_class, n).astype(np.uint8),
                intensity=rng.integers(0, 65535, n).astype(np.uint16),
                return_number=rn, number_of_returns=nr)
    if point_format in (1, 3, 4, 5, 6, 7, 8, 9, 10):
        dims["gps_time"] = np.cumsum(rng.uniform(0, 1e-3, n)) + 3.0e8
    ext = {"tree_id": rng.integers(0, 10_000, n).astype(np.int32),
           "amplitude": rng.normal(size=n).astype(np.float32)} if extra else None
    las = new_las(x, y, z, point_format=point_format, version=version, crs_wkt=utm32_wkt() if crs else None,
                  extra=ext, **dims)
    return las


def assert_same_points(a, b, *, skip=()):
    """Every dimension (standard and extra) of two LasData is equal."""
    assert a.point_format.id == b.point_format.id
    assert len(a.points) == len(b.points)
    for name in a.point_format.dimension_names:
        if name in skip:
            continue
        np.testing.assert_array_equal(np.asarray(a[name]), np.asarray(b[name]), err_msg=name)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.y, b.y)
    np.testing.assert_array_equal(a.z, b.z)


# --- round trips ----------------------------------------------------------------------------

@pytest.mark.parametrize("ext", [".las", ".laz"])
@pytest.mark.parametrize("point_format, version", [(1, "1.2"), (6, "1.4"), (0, "1.2"), (3, "1.2")])
def test_las_round_trip(tmp_path, ext, point_format, version):
    las = sample_las(point_format=point_format, version=version, big_classes=point_format >= 6)
    path = tmp_path / f"cloud{ext}"
    write_las(las, str(path))
    cloud = read_cloud(str(path))
    assert cloud.path == str(path)
    assert len(cloud) == len(las.points)
    np.testing.assert_allclose(cloud.x, las.x, atol=1e-9)
    np.testing.assert_allclose(cloud.y, las.y, atol=1e-9)
    np.testing.assert_allclose(cloud.z, las.z, atol=1e-9)
    np.testing.assert_array_equal(cloud.classification, np.asarray(las.classification))
    np.testing.assert_array_equal(cloud.return_number, np.asarray(las.return_number))
    np.testing.assert_array_equal(cloud.number_of_returns, np.asarray(las.number_of_returns))
    np.testing.assert_array_equal(cloud.intensity, np.asarray(las.intensity))
    assert cloud.has_return_info is True
    assert cloud.reference_label is None
    assert epsg_of(cloud.crs_wkt) == 32632
    np.testing.assert_array_equal(cloud.las["tree_id"], las["tree_id"])
    np.testing.assert_array_equal(cloud.las["amplitude"], las["amplitude"])
    if "gps_time" in las.point_format.dimension_names:
        np.testing.assert_array_equal(cloud.las.gps_time, las.gps_time)
    assert_same_points(cloud.las, las)
    assert cloud.las.header.version == laspy.header.Version.from_str(version)
    np.testing.assert_array_equal(cloud.xyz, np.column_stack([cloud.x, cloud.y, cloud.z]))


def test_las_without_crs(tmp_path):
    path = tmp_path / "nocrs.las"
    write_las(sample_las(crs=False, extra=False), str(path))
    assert read_cloud(str(path)).crs_wkt is None


@pytest.mark.parametrize("src_ext, dst_ext", [(".las", ".laz"), (".laz", ".las"), (".laz", ".laz")])
@pytest.mark.parametrize("point_format, version", [(1, "1.2"), (6, "1.4")])
def test_write_classified_keeps_everything_else(tmp_path, src_ext, dst_ext, point_format, version):
    las = sample_las(point_format=point_format, version=version, big_classes=point_format >= 6)
    src = tmp_path / f"in{src_ext}"
    dst = tmp_path / f"out{dst_ext}"
    write_las(las, str(src))
    digest = sha256(src)
    cloud = read_cloud(str(src))
    original_cls = np.asarray(cloud.las.classification).copy()
    new_cls = np.where(np.arange(len(cloud)) % 3 == 0, 2, 1).astype(np.uint8)
    write_classified(cloud, new_cls, str(dst))
    assert sha256(src) == digest, "the input file changed"
    np.testing.assert_array_equal(cloud.las.classification, original_cls)  # in-memory input as read
    np.testing.assert_array_equal(cloud.classification, original_cls)
    out = read_cloud(str(dst))
    np.testing.assert_array_equal(out.classification, new_cls)
    assert_same_points(out.las, cloud.las, skip=("classification",))
    assert epsg_of(out.crs_wkt) == 32632
    np.testing.assert_array_equal(out.las["tree_id"], las["tree_id"])
    assert out.las.header.version == cloud.las.header.version
    assert sorted(os.listdir(tmp_path)) == sorted([src.name, dst.name])  # no temporary file left


def test_write_classified_keeps_classification_flags(tmp_path):
    las = sample_las(point_format=1, extra=False)
    las.withheld = (np.arange(len(las.points)) % 2).astype(bool)
    las.synthetic = (np.arange(len(las.points)) % 5 == 0)
    src, dst = tmp_path / "in.las", tmp_path / "out.las"
    write_las(las, str(src))
    cloud = read_cloud(str(src))
    write_classified(cloud, np.full(len(cloud), 2, np.uint8), str(dst))
    out = laspy.read(str(dst))
    np.testing.assert_array_equal(out.withheld, las.withheld)
    np.testing.assert_array_equal(out.synthetic, las.synthetic)
    assert (np.asarray(out.classification) == 2).all()


def test_write_classified_refuses_classes_above_31_on_old_formats(tmp_path):
    src = tmp_path / "in.las"
    write_las(sample_las(point_format=1, extra=False), str(src))
    cloud = read_cloud(str(src))
    with pytest.raises(OutputError, match="0-31"):
        write_classified(cloud, np.full(len(cloud), 40, np.uint8), str(tmp_path / "out.las"))
    assert not (tmp_path / "out.las").exists()


def test_the_streamed_and_piecewise_copies_refuse_classes_above_31_on_old_formats(tmp_path):
    """The survey engine's two ways of writing the classified copy refuse, as write_classified
    does, classes a point format 0-5 cannot store, naming the file, and leave no output."""
    from groundsieve.core.io.lasfiles import write_classified_piece, write_classified_stream
    src = tmp_path / "in.las"
    write_las(sample_las(point_format=1, extra=False), str(src))
    n = len(read_cloud(str(src)))
    classes = np.full(n, 40, np.uint8)
    with pytest.raises(OutputError, match="out.laz: point format 1 stores classes 0-31 only"):
        write_classified_stream(str(src), str(tmp_path / "out.laz"), classes)
    records = tmp_path / "in.rec"
    with pytest.raises(OutputError, match="in.las: point format 1 stores classes 0-31 only"):
        write_classified_piece(str(src), str(records), classes, 0, n, str(tmp_path / "piece"), compress=True)
    assert sorted(os.listdir(tmp_path)) == ["in.las"]


def test_write_classified_wrong_length(tmp_path):
    src = tmp_path / "in.las"
    write_las(sample_las(n=50, extra=False), str(src))
    cloud = read_cloud(str(src))
    with pytest.raises(OutputError, match="out.las"):
        write_classified(cloud, np.ones(49, np.uint8), str(tmp_path / "out.las"))


# --- ISPRS text ---------------------------------------------------------------------------

def write_text(path, rows, fmt="%.2f\t%.2f\t%.2f\t%d"):
    np.savetxt(str(path), rows, fmt=fmt)


def test_isprs_text_reading(tmp_path):
    rows = np.array([[512743.63, 5403547.33, 308.68, 0], [512743.62, 5403547.33, 308.70, 1],
                     [512744.00, 5403548.10, 309.12, 0]])
    path = tmp_path / "samp99.txt"
    write_text(path, rows)
    cloud = read_cloud(str(path))
    assert len(cloud) == 3
    np.testing.assert_array_equal(cloud.x, rows[:, 0])
    np.testing.assert_array_equal(cloud.z, rows[:, 2])
    np.testing.assert_array_equal(cloud.reference_label, [0, 1, 0])
    assert cloud.has_return_info is False
    assert cloud.crs_wkt is None and cloud.las is None
    np.testing.assert_array_equal(cloud.return_number, 1)
    np.testing.assert_array_equal(cloud.number_of_returns, 1)
    np.testing.assert_array_equal(cloud.classification, 0)


def test_isprs_text_crlf_spaces_and_three_columns(tmp_path):
    path = tmp_path / "pts.txt"
    path.write_bytes(b"1.0 2.0 3.0\r\n4.0   5.0 6.5\r\n")
    cloud = read_cloud(str(path))
    assert len(cloud) == 2 and cloud.reference_label is None
    np.testing.assert_array_equal(cloud.z, [3.0, 6.5])
    one = tmp_path / "one.txt"
    one.write_text("1 2 3 1\n")
    assert len(read_cloud(str(one))) == 1


def test_isprs_text_to_las_keeps_label(tmp_path):
    rows = np.array([[10.0, 20.0, 1.0, 0], [11.0, 20.5, 1.2, 1], [12.0, 21.0, 0.9, 0]])
    src = tmp_path / "s.txt"
    write_text(src, rows)
    digest = sha256(src)
    cloud = read_cloud(str(src))
    write_classified(cloud, np.array([2, 1, 2], np.uint8), str(tmp_path / "s.laz"))
    assert sha256(src) == digest
    out = read_cloud(str(tmp_path / "s.laz"))
    assert out.las.point_format.id == 0
    np.testing.assert_array_equal(out.classification, [2, 1, 2])
    np.testing.assert_array_equal(out.las["reference_label"], [0, 1, 0])
    np.testing.assert_allclose(out.x, rows[:, 0], atol=1e-9)


# --- read errors: each names the file --------------------------------------------------------

def assert_names_file(err, path):
    assert str(path) in str(err.value), f"message does not name {path}: {err.value}"
    assert isinstance(err.value, GroundSieveError)


def test_missing_file(tmp_path):
    path = tmp_path / "nothere.laz"
    with pytest.raises(InputError, match="no such file") as err:
        read_cloud(str(path))
    assert_names_file(err, path)


def test_folder(tmp_path):
    folder = tmp_path / "dir.las"
    folder.mkdir()
    with pytest.raises(InputError, match="folder") as err:
        read_cloud(str(folder))
    assert_names_file(err, folder)


def test_text_named_las(tmp_path):
    path = tmp_path / "fake.las"
    path.write_text("this is not a LAS file\n1 2 3\n")
    with pytest.raises(UnsupportedFormatError, match="not a LAS/LAZ") as err:
        read_cloud(str(path))
    assert_names_file(err, path)


@pytest.mark.parametrize("content, kind", [
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n", "but a PLY file: export LAS or LAZ"),
    (b"500000.12 5400000.50 101.25 120 130 140\n500000.20 5400000.61 101.30 121 131 141\n",
     "but text, numbers per line .*'500000.12 5400000.50 101.25 120 130 140'.* read as such when named .txt"),
    (b"ASTM-E57\x00\x00\x01\x00", "but an E57 file: export LAS or LAZ"),
    (b"X,Y,Z,R,G,B\n500000.1,5400000.2,101.3,12,13,14\n", "but text, numbers per line .*'500000.1,5400000.2,101.3"),
    (b"//X Y Z\n500000.1 5400000.2 101.3\n", "but text, numbers per line .*'500000.1 5400000.2 101.3'"),
    (b"\xef\xbb\xbf500000.1 5400000.2 101.3\n", "but text, numbers per line .*'500000.1 5400000.2 101.3'"),
], ids=["ply", "xyz", "e57", "csv-header", "cloudcompare", "bom"])
def test_another_format_named_las_is_said_what_it_is(tmp_path, content, kind):
    """A photogrammetry export renamed .las (PLY, XYZ text) was refused with laspy's "Invalid file signature
    b'ply\\n'" alone: the message says what the file is and how to convert it, whole and in a survey."""
    from groundsieve.core.io.lasfiles import scan_header
    path = tmp_path / "export.las"
    path.write_bytes(content)
    with pytest.raises(UnsupportedFormatError, match=f"export.las: not a LAS/LAZ file {kind}"):
        read_cloud(str(path))
    with pytest.raises(InputError, match=f"export.las: not a LAS/LAZ file {kind}"):
        scan_header(str(path))


@pytest.mark.parametrize("ext", [".laz", ".las"])
def test_truncated_file(tmp_path, ext):
    full = tmp_path / f"full{ext}"
    write_las(sample_las(n=20000, extra=False), str(full))
    data = full.read_bytes()
    cut = tmp_path / f"cut{ext}"
    cut.write_bytes(data[:len(data) // 2])
    with pytest.raises(InputError) as err:
        read_cloud(str(cut))
    assert_names_file(err, cut)
    assert "truncated" in str(err.value) or "damaged" in str(err.value)


def test_empty_las(tmp_path):
    path = tmp_path / "empty.las"
    write_las(new_las(np.array([]), np.array([]), np.array([])), str(path))
    with pytest.raises(InputError, match="no points") as err:
        read_cloud(str(path))
    assert_names_file(err, path)


def test_zero_byte_files(tmp_path):
    for name in ("zero.las", "zero.laz", "zero.txt"):
        path = tmp_path / name
        path.write_bytes(b"")
        with pytest.raises(InputError) as err:
            read_cloud(str(path))
        assert_names_file(err, path)


@pytest.mark.parametrize("name", ["cloud.xyz", "cloud.csv", "cloud", "cloud.las.bak"])
def test_unsupported_extension(tmp_path, name):
    path = tmp_path / name
    path.write_text("1 2 3\n")
    with pytest.raises(UnsupportedFormatError, match="unsupported") as err:
        read_cloud(str(path))
    assert_names_file(err, path)


def test_text_with_nan_coordinates(tmp_path):
    path = tmp_path / "nan.txt"
    path.write_text("1 2 3 0\n4 nan 6 1\n7 8 9 0\n")
    with pytest.raises(InputError, match="NaN") as err:
        read_cloud(str(path))
    assert_names_file(err, path)


def test_text_with_huge_coordinates(tmp_path):
    path = tmp_path / "huge.txt"
    path.write_text("1 2 3 0\n2.5e9 2 3 1\n")
    with pytest.raises(InputError, match="1e9") as err:
        read_cloud(str(path))
    assert_names_file(err, path)


def test_las_with_huge_coordinates(tmp_path):
    path = tmp_path / "huge.las"
    x = np.array([5.0e9, 5.0e9 + 1.0, 5.0e9 + 2.0])
    write_las(new_las(x, np.array([0.0, 1.0, 2.0]), np.zeros(3)), str(path))
    with pytest.raises(InputError, match="1e9") as err:
        read_cloud(str(path))
    assert_names_file(err, path)


@pytest.mark.parametrize("content, match", [
    ("a b c\n", r"line 1, column 1: 'a' is not a number"),
    ("1 2\n3 4\n", "expected 3 or 4 columns 'x y z \\[label\\]', found 2"),
    ("1 2 3\n4 5\n", "line 2 has 2 columns, the lines before it 3"),
    ("1 2 3 0\n4 5 6 1\n7 8 abc 0\n", r"line 3, column 3: 'abc' is not a number"),
    ("1 2 3 4 5\n", "found 5; for other text layouts convert the file to LAS/LAZ first"),
    ("# x y z label\n1 2 3 0\n4 5 6 1\n7 8 abc 0\n", r"line 4, column 3: 'abc' is not a number"),
    ("1 2 3 0 # first\n4 5 6\n", "line 2 has 3 columns, the lines before it 4"),
    (b"\xef\xbb\xbf1 2 3 0\n4 5 x 1\n", r"line 2, column 3: 'x' is not a number"),
    (b"# caf\xe9\n1 2 3 0\n1 2 z 0\n", r"line 3, column 3: 'z' is not a number"),
    (b"\xff\xfe\x00\x01 binary\n", "not text"),
    # a geomorphologist's header row and commas: the message says what to do
    ("x y z label\n1 2 3 0\n", r"'x' is not a number; a header line is not read: remove it, or start it with '#'"),
    ("1,2,3,0\n4,5,6,1\n", r"'1,2,3,0' is not a number; the values must be separated by spaces or tabs, not commas"),
    ("1 2 3 0\n4;5;6;1\n", r"line 2, column 1: '4;5;6;1' is not a number; the values must be separated by spaces")])
def test_text_not_numbers(tmp_path, content, match):
    path = tmp_path / "bad.txt"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(UnsupportedFormatError, match=match) as err:
        read_cloud(str(path))
    assert_names_file(err, path)


def test_text_with_a_bom_comments_and_latin1_is_read(tmp_path):
    path = tmp_path / "ok.txt"
    path.write_bytes(b"\xef\xbb\xbf# caf\xc3\xa9 x y z label\n1 2 3 0\n4 5 6 1 # a roof\n")
    cloud = read_cloud(str(path))
    assert cloud.z.tolist() == [3.0, 6.0] and cloud.reference_label.tolist() == [0, 1]
    path.write_bytes(b"# caf\xe9\n1 2 3 0\n")
    assert read_cloud(str(path)).x.tolist() == [1.0]
    path.write_bytes(b"\xef\xbb\xbf1 2 3 0\n4 5 6 1 # caf\xe9\n")  # a BOM and a Latin-1 comment: read as Latin-1
    assert read_cloud(str(path)).x.tolist() == [1.0, 4.0]


def test_text_is_read_in_chunks_with_progress_and_cancel(tmp_path, monkeypatch):
    """22 M lines in one loadtxt call took 8 s deaf to Cancel: the rows are parsed a chunk at a time
    from the open file (each chunk stops at its last row: none lost or read twice, comments and a BOM
    as loadtxt reads them), the bar moves with the share of the file read, and a cancel stops the read
    between chunks."""
    from groundsieve.core.errors import Cancelled
    from groundsieve.core.io import clouds
    from groundsieve.core.progress import Steps
    monkeypatch.setattr(clouds, "TEXT_CHUNK_LINES", 500)  # chunks of about 12 kB, beyond a text file's read-ahead
    rng = np.random.default_rng(3)
    rows = np.c_[rng.uniform(0, 100, (3000, 3)).round(2), rng.integers(0, 2, 3000)]
    path = tmp_path / "chunks.txt"
    write_text(path, rows)
    text = path.read_text().replace("\n", "  # a comment\n", 5).splitlines(keepends=True)
    text.insert(1200, "\n# a comment line and a blank line inside a chunk\n")
    path.write_bytes(b"\xef\xbb\xbf" + ("# x y z label\n" + "".join(text)).encode())
    shown = []
    cloud = read_cloud(str(path), Steps(shown.append))
    assert np.array_equal(np.c_[cloud.x, cloud.y, cloud.z], rows[:, :3])
    assert cloud.reference_label.tolist() == rows[:, 3].astype(int).tolist()
    assert len(shown) >= 6 and shown == sorted(shown) and 0 < shown[0] < shown[-1]
    calls = []
    with pytest.raises(Cancelled):
        read_cloud(str(path), Steps(calls.append, lambda: len(calls) >= 2))
    assert len(calls) == 2  # stopped after the second chunk, not at the end of the file
    # a later chunk with other columns is refused as a whole file's would be, naming the line
    path.write_bytes(path.read_bytes() + b"1 2 3\n")
    with pytest.raises(UnsupportedFormatError, match=r"chunks\.txt: .*line 3004 has 3 columns, the lines before it 4"):
        read_cloud(str(path))


def test_text_with_mixed_line_ends_and_one_that_changes_while_read(tmp_path, monkeypatch):
    """The chunks fill an array sized by the line ends: a file mixing newlines and carriage returns
    (500,000 lines of each kind in a QA reviewer's file) was undercounted and refused with numpy's
    "could not broadcast"; a file that grew or shrank while read was read in part without a word."""
    from groundsieve.core.io import clouds
    monkeypatch.setattr(clouds, "TEXT_CHUNK_LINES", 7)
    rows = [f"{i} {i + 1} {i % 5} {i % 2}" for i in range(40)]
    path = tmp_path / "mixed.txt"
    path.write_bytes(("\n".join(rows[:20]) + "\n" + "\r".join(rows[20:30]) + "\r"
                      + "\r\n".join(rows[30:]) + "\r\n").encode())
    cloud = read_cloud(str(path))
    assert cloud.x.tolist() == [float(i) for i in range(40)]
    real = np.loadtxt
    calls = []

    def growing(lines, *args, **kwargs):  # the file grows after the first chunk is read
        calls.append(1)
        if len(calls) == 1:
            with open(path, "a") as f:
                f.write("100 101 1 0\n")
        return real(lines, *args, **kwargs)
    monkeypatch.setattr(clouds.np, "loadtxt", growing)
    with pytest.raises(InputError, match=r"mixed\.txt: the file changed while it was read .*run again once it is complete"):
        read_cloud(str(path))


def test_empty_text(tmp_path):
    path = tmp_path / "empty.txt"
    path.write_text("")
    with pytest.raises(InputError, match="no points") as err:
        read_cloud(str(path))
    assert_names_file(err, path)


# --- output paths ---------------------------------------------------------------------------

def test_check_output_path_accepts_a_good_path(tmp_path):
    for name in ("out.las", "out.laz", "OUT.LAZ"):
        assert check_output_path(str(tmp_path / name), inputs=[str(tmp_path / "in.las")]) == str(tmp_path / name)


def test_check_output_path_refuses_the_input(tmp_path, monkeypatch):
    src = tmp_path / "in.laz"
    write_las(sample_las(n=10, extra=False), str(src))
    with pytest.raises(OutputError, match="must not be the input") as err:
        check_output_path(str(src), inputs=[str(src)])
    assert str(src) in str(err.value)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(OutputError):
        check_output_path("in.laz", inputs=[str(src)])  # relative vs absolute
    with pytest.raises(OutputError):
        check_output_path(str(tmp_path / "sub" / ".." / "in.laz"), inputs=[str(src)])


def test_check_output_path_refuses_the_input_through_a_symlink(tmp_path):
    src = tmp_path / "in.laz"
    write_las(sample_las(n=10, extra=False), str(src))
    link = tmp_path / "link.laz"
    link.symlink_to(src)
    with pytest.raises(OutputError, match="must not be the input"):
        check_output_path(str(link), inputs=[str(src)])
    with pytest.raises(OutputError, match="must not be the input"):
        check_output_path(str(src), inputs=[str(link)])
    linked_dir = tmp_path / "alias"
    linked_dir.symlink_to(tmp_path, target_is_directory=True)
    with pytest.raises(OutputError, match="must not be the input"):
        check_output_path(str(linked_dir / "in.laz"), inputs=[str(src)])


@pytest.mark.parametrize("name", ["out.txt", "out.tif", "out", "out.las.tmp"])
def test_check_output_path_refuses_wrong_extension(tmp_path, name):
    with pytest.raises(OutputError, match=r"\.las or \.laz"):
        check_output_path(str(tmp_path / name))


def test_check_output_path_refuses_missing_folder(tmp_path):
    path = tmp_path / "no" / "such" / "dir" / "out.laz"
    with pytest.raises(OutputError, match="does not exist") as err:
        check_output_path(str(path))
    assert str(path) in str(err.value)


def test_write_las_checks_the_path(tmp_path):
    with pytest.raises(OutputError):
        write_las(sample_las(n=10, extra=False), str(tmp_path / "out.txt"))
    with pytest.raises(OutputError):
        write_las(sample_las(n=10, extra=False), str(tmp_path / "missing" / "out.las"))
    assert os.listdir(tmp_path) == []


# --- atomic writes --------------------------------------------------------------------------

def test_atomic_write_success_leaves_only_the_target(tmp_path):
    path = tmp_path / "out.laz"
    write_las(sample_las(n=100, extra=False), str(path))
    assert os.listdir(tmp_path) == ["out.laz"]
    assert len(read_cloud(str(path))) == 100


def test_atomic_path_failure_leaves_nothing(tmp_path):
    path = tmp_path / "out.las"
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_path(str(path)) as tmp:
            assert os.path.dirname(tmp) == str(tmp_path) and tmp.endswith(".las")
            with open(tmp, "wb") as fh:
                fh.write(b"half a file")
            raise RuntimeError("boom")
    assert os.listdir(tmp_path) == []


def test_atomic_path_failure_keeps_the_previous_file(tmp_path):
    path = tmp_path / "out.las"
    path.write_bytes(b"previous result")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(str(path)) as tmp:
            with open(tmp, "wb") as fh:
                fh.write(b"partial")
            raise KeyboardInterrupt
    assert path.read_bytes() == b"previous result"
    assert os.listdir(tmp_path) == ["out.las"]


def test_write_las_failure_midway_leaves_nothing(tmp_path, monkeypatch):
    las = sample_las(n=100, extra=False)

    def failing_write(self, points):  # the header is written, then the disk is full
        raise OSError(28, "No space left on device")

    import laspy
    monkeypatch.setattr(laspy.LasWriter, "write_points", failing_write)
    path = tmp_path / "out.laz"
    with pytest.raises(OutputError, match="No space left") as err:
        write_las(las, str(path))
    assert str(path) in str(err.value)
    assert os.listdir(tmp_path) == []


def test_write_replaces_an_existing_output(tmp_path):
    path = tmp_path / "out.las"
    path.write_bytes(b"old")
    write_las(sample_las(n=30, extra=False), str(path))
    assert len(read_cloud(str(path))) == 30
    assert os.listdir(tmp_path) == ["out.las"]



def test_written_file_follows_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        path = tmp_path / "out.las"
        write_las(sample_las(n=10, extra=False), str(path))
    finally:
        os.umask(old)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o644


def _las_bytes(tmp_path, name, **kw):
    rng = np.random.default_rng(4)
    n = 3000
    path = tmp_path / name
    write_las(new_las(rng.uniform(0, 50, n), rng.uniform(0, 50, n), rng.uniform(0, 2, n), **kw), str(path))
    return path, bytearray(path.read_bytes())


def _refusals_in_a_child(path, timeout=60):
    """What scan_header and read_cloud say of ``path``, read in a child process: without the checks
    these files hang (eating memory) or abort the process, which would take the test run down."""
    import subprocess
    import sys
    code = ("import sys\nfrom groundsieve.core.io import read_cloud\nfrom groundsieve.core.io.lasfiles import scan_header\n"
            "from groundsieve.core.errors import InputError\n"
            "for read in (scan_header, read_cloud):\n"
            "    try:\n        read(sys.argv[1])\n    except InputError as err:\n        print(err)\n")
    done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)))
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.splitlines()


def test_a_header_announcing_more_vlrs_or_evlrs_than_the_file_holds_is_refused_at_once(tmp_path):
    """A VLR count of 2e9 made laspy build VLRs until the memory ran out, deaf to Cancel; a LAS 1.4
    EVLR count of 1e9 the same (a QA reviewer's 4-byte edits). Refused before laspy reads them."""
    import struct
    path, data = _las_bytes(tmp_path, "v.las")
    struct.pack_into("<I", data, 100, 2_000_000_000)
    path.write_bytes(data)
    said = _refusals_in_a_child(path)
    assert len(said) == 2 and all("v.las: the header announces 2,000,000,000 VLRs before the points" in s
                                  for s in said), said
    path, data = _las_bytes(tmp_path, "e.las", point_format=6, version="1.4")
    struct.pack_into("<QI", data, 235, len(data), 1_000_000_000)  # EVLRs at the file's end, 1e9 of them
    path.write_bytes(data)
    said = _refusals_in_a_child(path)
    assert len(said) == 2 and all("e.las: the header announces 1,000,000,000 extended VLRs" in s for s in said), said


def test_a_laz_whose_chunk_table_announces_2_31_chunks_is_refused_not_a_crash(tmp_path):
    """lazrs allocated 34 GB for a chunk table announcing 2^31 - 1 chunks and aborted the process
    (exit 134), QGIS with it."""
    import struct
    path, data = _las_bytes(tmp_path, "c.laz")
    offset = laspy.open(str(path)).header.offset_to_point_data
    table = struct.unpack_from("<q", data, offset)[0]
    struct.pack_into("<I", data, table + 4, 0x7FFFFFFF)
    path.write_bytes(data)
    said = _refusals_in_a_child(path)
    assert len(said) == 2 and all("c.laz: the LAZ chunk table announces 2,147,483,647 chunks for 3,000 points" in s
                                  for s in said), said
    assert len(read_cloud(str(_las_bytes(tmp_path, "ok.laz")[0]))) == 3000  # an intact LAZ reads


def test_hostile_inputs_a_qa_reviewer_found_get_messages_naming_the_file(tmp_path):
    """Each gave a traceback (kind "other") or a silent wrong answer: an infinite z in a text file
    (OverflowError in the scale), a 4th column that is no label (300, nan, 0.7 became label 0, -1
    255), a LAS 2.2 file (refused by laspy only at the write, after the whole run), header bounds
    of NaN (in the survey engine's memory estimate), a .vpc whose assets or href are not objects."""
    import json
    import struct

    from groundsieve.core.io.lasfiles import read_vpc, scan_header
    from groundsieve.core.progress import WARNING_PREFIX
    rows = "\n".join(f"{x} {y} {z} 0" for x, y, z in np.random.default_rng(2).uniform(0, 50, (30, 3)))
    (tmp_path / "inf.txt").write_text(rows + "\n1 2 inf 1\n")
    with pytest.raises(InputError, match=r"inf\.txt: 1 point\(s\) have NaN or infinite coordinates"):
        read_cloud(str(tmp_path / "inf.txt"))
    (tmp_path / "odd.txt").write_text(rows + "\n1 2 3 300\n")
    cloud = read_cloud(str(tmp_path / "odd.txt"))
    assert cloud.reference_label is None
    assert cloud.notes == [f"{WARNING_PREFIX}{tmp_path / 'odd.txt'}: the 4th column is not a label (whole numbers 0-255, "
                           "0 = ground in the ISPRS samples: point 31 has 300); it is ignored, and the cloud has no "
                           "reference labels."]
    (tmp_path / "ok.txt").write_text(rows + "\n1 2 3 1\n")
    assert read_cloud(str(tmp_path / "ok.txt")).reference_label.tolist() == [0] * 30 + [1]
    path, data = _las_bytes(tmp_path, "v22.las")
    data[24], data[25] = 2, 2  # LAS 2.2
    path.write_bytes(data)
    for read in (read_cloud, scan_header):
        with pytest.raises(UnsupportedFormatError, match=r"v22\.las: LAS version 2\.2 is not supported"):
            read(str(path))
    path, data = _las_bytes(tmp_path, "nan.las")
    struct.pack_into("<d", data, 179, float("nan"))  # max x
    path.write_bytes(data)
    with pytest.raises(InputError, match=r"nan\.las: the header's bounds are not numbers"):
        scan_header(str(path))
    for name, item in (("assets", {"assets": 5}), ("href", {"assets": {"data": {"href": 7}}})):
        vpc = tmp_path / f"{name}.vpc"
        vpc.write_text(json.dumps({"type": "FeatureCollection", "features": [item]}))
        with pytest.raises(InputError, match=rf"{name}\.vpc: item '\?' has no assets\.data\.href naming a file"):
            read_vpc(str(vpc))


def test_a_zero_scale_or_an_evlr_longer_than_the_file_is_refused(tmp_path):
    """A scale of 0 put every point on one spot and called all of them ground, without a word; an
    EVLR whose length runs past the file's end made laspy allocate it: "cannot read its LAS header
    ()" with an empty reason (a QA reviewer)."""
    import struct

    from groundsieve.core.io.lasfiles import scan_header
    path, data = _las_bytes(tmp_path, "s0.las")
    struct.pack_into("<3d", data, 131, 0.0, 0.0, 0.0)
    path.write_bytes(data)
    with pytest.raises(InputError, match=r"s0\.las: the header's scale factors \[0\.0, 0\.0, 0\.0\] are not numbers > 0"):
        read_cloud(str(path))
    path, data = _las_bytes(tmp_path, "ev.las", point_format=6, version="1.4")
    evlr = struct.pack("<H16sHQ32s", 0, b"someone", 1, 10 ** 15, b"long")
    struct.pack_into("<QI", data, 235, len(data), 1)
    path.write_bytes(bytes(data) + evlr)
    for read in (read_cloud, scan_header):
        with pytest.raises(InputError, match=r"ev\.las: its first extended VLR \(at byte [\d,]+\) announces "
                                             r"1,000,000,000,000,000 bytes"):
            read(str(path))


def test_a_header_announcing_more_points_than_a_las_holds_is_refused_before_the_run(tmp_path):
    """A LAS 1.2 whose header said 4,294,967,295 points for 3,000 records went to the tiles (its count
    over the budget) and failed in the binning with "4,294,967,295 points announced but the file ends
    at 2,147,483,647", no file named and a point index for a position (a QA reviewer). Refused when
    its header is read, naming the file, as a run of the whole file refuses it."""
    import struct

    from groundsieve.core.io.lasfiles import scan_header
    path, data = _las_bytes(tmp_path, "big.las")
    struct.pack_into("<I", data, 107, 0xFFFFFFFF)
    path.write_bytes(data)
    with pytest.raises(InputError, match=r"big\.las: the header announces 4,294,967,295 points but the file holds "
                                         r"3,000 point records: the file is truncated"):
        scan_header(str(path))


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes on this system")
def test_a_named_pipe_is_not_a_point_cloud_file(tmp_path):
    """A FIFO named like a cloud was "no such file" for a LAS name, and a text one would have waited
    for a writer for good (a QA reviewer)."""
    from groundsieve.core.io.lasfiles import scan_header
    for name in ("p.las", "p.txt"):
        os.mkfifo(tmp_path / name)
        with pytest.raises(InputError, match=rf"{name}: is not a regular file"):
            read_cloud(str(tmp_path / name))
    with pytest.raises(InputError, match=r"p\.las: is not a regular file"):
        scan_header(str(tmp_path / "p.las"))


def test_a_las_1_3_with_waveform_packets_after_its_points_holds_what_it_announces(tmp_path):
    """LAS 1.3 keeps waveform packets in the file after the points (global encoding bit 1, the start
    of their record in the header): they were counted as point records, and the file said to hold
    2,246 records more than announced, whole and now tiled (a code reviewer)."""
    import struct

    from groundsieve.core.io.lasfiles import scan_header
    rng = np.random.default_rng(0)
    n = 2000
    header = laspy.LasHeader(point_format=4, version="1.3")
    header.scales, header.offsets = [0.01] * 3, [500000, 5400000, 0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = 500000 + rng.uniform(0, 50, n), 5400000 + rng.uniform(0, 50, n), rng.uniform(0, 2, n)
    path = tmp_path / "wave13.las"
    las.write(str(path))
    data = bytearray(path.read_bytes())
    size = len(data)
    struct.pack_into("<H", data, 6, struct.unpack_from("<H", data, 6)[0] | 2)  # waveform packets internal
    struct.pack_into("<Q", data, 227, size)  # their record starts after the points
    data += struct.pack("<H16sHQ32s", 0, b"LASF_Spec", 65535, n * 64, b"waveform") + bytes(n * 64)
    path.write_bytes(data)
    assert read_cloud(str(path)).notes == []
    info = scan_header(str(path))
    assert info.count == n and info.held == n


@pytest.mark.parametrize("tiles", [0.0, 20.0], ids=["whole", "tiled"])
def test_a_las_1_0_input_is_classified_into_a_las_1_2_copy(tmp_path, tiles):
    """laspy reads LAS 1.0 but writes no 1.0: such an input failed at the write, after the whole run
    (a QA reviewer; refused up front for a while, which also refused DTM-only runs, a code reviewer).
    Its classified copy is LAS 1.2 now (the same header and point formats), points to the bit."""
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    path, data = _las_bytes(tmp_path, "v10.las")
    data[25] = 0
    path.write_bytes(data)
    assert laspy.read(str(path)).header.version.minor == 0
    out = tmp_path / "o.laz"
    run_ground_filter(str(path), str(out), SMRF(), options=FilterOptions(tiling=TileOptions(tile_size_m=tiles)))
    got, want = laspy.read(str(out)), laspy.read(str(path))
    assert str(got.header.version) == "1.2" and len(got.points) == len(want.points)
    assert np.array_equal(got.X, want.X) and np.array_equal(got.Z, want.Z) and (got.classification == 2).any()


@pytest.mark.parametrize("ext", ["las", "laz"])
def test_a_file_still_being_written_is_refused_not_read_as_empty(tmp_path, ext):
    """LAS writers set the point count when they close the file: a LAZ still being copied into a
    survey folder announced 0 points and became an empty classified copy, exit 0 (a reviewer). A
    file whose header announces no point but which holds point data is refused; a truly empty one is not."""
    import struct

    import laspy

    from groundsieve.core.io.lasfiles import scan_header
    from groundsieve.core.io.clouds import new_las, write_las
    rng = np.random.default_rng(0)
    growing = tmp_path / f"growing.{ext}"
    write_las(new_las(rng.uniform(0, 100, 50_000), rng.uniform(0, 100, 50_000), rng.uniform(0, 5, 50_000),
                      point_format=1, version="1.2"), str(growing))
    data = bytearray(growing.read_bytes())
    struct.pack_into("<I5I", data, 107, 0, 0, 0, 0, 0, 0)  # what the header says before its writer closes it
    growing.write_bytes(bytes(data))
    with pytest.raises(InputError, match=rf"growing\.{ext}: its header announces no point, but [\d,]+ bytes of point "
                                         "data follow it: the file is still being written"):
        scan_header(str(growing))
    empty = tmp_path / f"empty.{ext}"
    las = laspy.LasData(laspy.LasHeader(point_format=1, version="1.2"))
    las.write(str(empty))
    assert scan_header(str(empty)).count == 0
