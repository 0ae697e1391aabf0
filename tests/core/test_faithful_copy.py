"""The classified copy keeps what the input has, but the classes, where laspy's writer changed it (a
format reviewer compared every field of formats 0-10 in LAS 1.2-1.4, whole and tiled).

Waveform data packets stored inside a LAS 1.3/1.4 file (global encoding bit 1: one record after the
points, LASF_Spec 65535, from whose start every point's wave packet offset counts) are carried into
the classified copy. laspy wrote none for LAS 1.3, the header still saying they were there (a
format reviewer's 1.28 MB of samples went without a word), and in LAS 1.4 a LAZ copy kept the record
but the header pointed into the compressed points."""
from __future__ import annotations

import os
import struct

import laspy
import numpy as np

from groundsieve.core.io.provenance import package_version
import pytest
from laspy.vlrs.vlrlist import VLRList

from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
from groundsieve.core.errors import InputError, OutputError
from groundsieve.core.filters.smrf import SMRF


def write_with_packets(path, point_format, version, n=3000, other_evlr=False):
    """A cloud whose points each point at 256 bytes of samples in the record appended after them."""
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales, header.offsets = [0.01] * 3, [500000.0, 4000000.0, 0.0]
    las = laspy.LasData(header)
    rng = np.random.default_rng(1)
    las.x, las.y = 500000 + rng.uniform(0, 120, n), 4000000 + rng.uniform(0, 120, n)
    las.z = rng.uniform(0, 0.3, n) + (rng.random(n) < 0.3) * rng.uniform(2, 15, n)
    las.wavepacket_index = np.ones(n, np.uint8)
    las.wavepacket_offset = 60 + 256 * np.arange(n, dtype=np.uint64)
    las.wavepacket_size = np.full(n, 256, np.uint32)
    if other_evlr:
        las.evlrs = VLRList([laspy.VLR(user_id="test", record_id=7, description="not waveform", record_data=b"x" * 100)])
    las.write(str(path))
    data = bytearray(path.read_bytes())
    samples = rng.integers(0, 256, n * 256, dtype=np.uint8).tobytes()
    start = len(data)
    data += struct.pack("<H16sHQ32s", 0, b"LASF_Spec", 65535, len(samples), b"waveform packets") + samples
    struct.pack_into("<H", data, 6, struct.unpack_from("<H", data, 6)[0] | 0x2)  # internal packets
    struct.pack_into("<Q", data, 227, start)
    if version == "1.4":
        first, count = struct.unpack_from("<QI", data, 235)
        struct.pack_into("<QI", data, 235, first if count else start, count + 1)
    path.write_bytes(bytes(data))
    return path


def packets(path):
    """The waveform record the header points at (None when it points at none)."""
    data = path.read_bytes()
    at, = struct.unpack_from("<Q", data, 227)
    if not (struct.unpack_from("<H", data, 6)[0] & 2) or at + 60 > len(data):
        return None
    if data[at + 2:at + 18].rstrip(b"\0") != b"LASF_Spec" or struct.unpack_from("<H", data, at + 18)[0] != 65535:
        return None
    length, = struct.unpack_from("<Q", data, at + 20)
    return data[at:at + 60 + length]


@pytest.mark.parametrize("point_format, version, other_evlr", [(4, "1.3", False), (9, "1.4", False), (9, "1.4", True)])
@pytest.mark.parametrize("ext", ["las", "laz"])
@pytest.mark.parametrize("tiled", [False, True])
def test_internal_waveform_packets_are_carried_into_the_classified_copy(tmp_path, point_format, version, other_evlr,
                                                                        ext, tiled):
    src = write_with_packets(tmp_path / "wave.las", point_format, version, other_evlr=other_evlr)
    before = src.read_bytes()
    out = tmp_path / f"out.{ext}"
    options = FilterOptions(tiling=TileOptions(tile_size_m=40.0, workers=2, parallel="threads")) if tiled else FilterOptions()
    run = run_ground_filter(str(src), str(out), SMRF(), options=options)
    assert (run.cloud is None) == tiled
    assert src.read_bytes() == before
    assert packets(out) == packets(src) is not None
    a, b = laspy.read(str(src)), laspy.read(str(out))
    for dim in a.point_format.dimension_names:
        if dim != "classification":
            assert np.array_equal(a[dim], b[dim]), dim
    assert 0 < np.mean(b.classification == 2) < 1
    if other_evlr:
        assert [v.record_id for v in b.evlrs] == [7, 65535]
    # the copy is a sound input in its turn
    again = tmp_path / f"again.{ext}"
    run_ground_filter(str(out), str(again), SMRF())
    assert packets(again) == packets(src)


def test_a_file_without_internal_packets_is_copied_as_before(tmp_path):
    """External packets (bit 2) or none: the header is left as laspy writes it."""
    src = write_with_packets(tmp_path / "wave.las", 4, "1.3")
    data = bytearray(src.read_bytes())
    struct.pack_into("<H", data, 6, (struct.unpack_from("<H", data, 6)[0] & ~0x2) | 0x4)  # external (a .wdp file)
    src.write_bytes(bytes(data))
    run_ground_filter(str(src), str(tmp_path / "out.las"), SMRF())
    out = (tmp_path / "out.las").read_bytes()
    assert packets(tmp_path / "out.las") is None
    assert len(out) < len(data) - 256 * 3000  # the bytes after the points are not copied


def tiled_or_whole(tiled):
    return FilterOptions(tiling=TileOptions(tile_size_m=40.0, workers=2, parallel="threads")) if tiled else FilterOptions()


@pytest.mark.parametrize("tiled", [False, True])
@pytest.mark.parametrize("ext", ["las", "laz"])
def test_header_dates_legacy_counts_and_extra_bytes_descriptions_are_kept(tmp_path, tiled, ext):
    """laspy wrote 0 for LAS 1.4's legacy counts in formats 0-5 (R15 wants them when they fit: older
    readers saw no point), read a creation day 0 as the year before's last day, and wrote its own empty
    minimum and maximum into the extra-bytes descriptions beside an options byte saying they were set;
    a tiled copy moved the extra-bytes VLR last."""
    n = 3000
    header = laspy.LasHeader(point_format=3, version="1.4")
    header.scales, header.offsets = [0.01] * 3, [500000.0, 4000000.0, 0.0]
    header.add_extra_dim(laspy.ExtraBytesParams(name="treeID", type=np.int32, description="tree"))
    header.vlrs.append(laspy.VLR(user_id="MYCORP", record_id=42, description="custom", record_data=b"abc" * 8))
    las = laspy.LasData(header)
    rng = np.random.default_rng(2)
    las.x, las.y = 500000 + rng.uniform(0, 120, n), 4000000 + rng.uniform(0, 120, n)
    las.z = rng.uniform(0, 0.3, n) + (rng.random(n) < 0.3) * rng.uniform(2, 15, n)
    las.return_number = np.where(rng.random(n) < 0.7, 1, 2)
    las.number_of_returns = np.full(n, 2)
    las.treeID = rng.integers(1, 206, n)
    src = tmp_path / "in.las"
    las.write(str(src))
    data = bytearray(src.read_bytes())
    struct.pack_into("<HH", data, 90, 0, 2018)  # creation day 0 of 2018
    by_return = struct.unpack_from("<15Q", data, 255)
    struct.pack_into("<I5I", data, 107, n, *by_return[:5])  # legacy counts, as LAStools and PDAL write them
    at = struct.unpack_from("<H", data, 94)[0] + 54  # the first VLR's data: the extra-bytes description
    assert data[at - 54 + 2:at - 54 + 11] == b"LASF_Spec"
    data[at + 3] |= 0x06  # min and max set
    struct.pack_into("<q", data, at + 64, 1)
    struct.pack_into("<q", data, at + 88, 205)
    src.write_bytes(bytes(data))
    out = tmp_path / f"out.{ext}"
    run_ground_filter(str(src), str(out), SMRF(), options=tiled_or_whole(tiled))
    got = out.read_bytes()
    assert got[90:94] == data[90:94]
    # the generating software is the copy's writer (the source's "laspy ..." or a vendor's was kept)
    assert got[58:90].rstrip(b"\0") == f"GroundSieve {package_version()}".encode() and data[58:69] != b"GroundSieve"
    assert got[107:131] == data[107:131] and struct.unpack_from("<I", got, 107)[0] == n
    description = data[at:at + 192]
    assert description in got  # the same 192 bytes: name, type, options, min, max
    with laspy.open(str(out)) as reader:
        assert [type(v).__name__ for v in reader.header.vlrs][:2] == ["ExtraBytesVlr", "VLR"]
    assert np.array_equal(laspy.read(str(out)).treeID, las.treeID)


def _channels(path, channel_of, x_t=None):
    """A point format 9 file with wave packets whose points are on the scanner channels ``channel_of(n)``."""
    src = write_with_packets(path, 9, "1.4", n=120_000)
    las = laspy.read(str(src))
    las.scanner_channel = channel_of(len(las.points))
    las.x_t = np.linspace(0, 1, len(las.points)) if x_t is None else x_t(len(las.points))
    las.write(str(src))
    return src


def _lazrs_mixes_channels(tmp_path) -> bool:
    probe = laspy.read(str(_channels(tmp_path / "probe.las", lambda n: np.arange(n) % 2)))
    probe.write(str(tmp_path / "probe.laz"))
    return not np.array_equal(laspy.read(str(tmp_path / "probe.laz")).wavepacket_offset, probe.wavepacket_offset)


@pytest.mark.parametrize("tiled", [False, True])
def test_a_laz_copy_whose_wave_packets_lazrs_writes_wrong_is_refused(tmp_path, tiled):
    """lazrs 0.8.2 writes the wave packet fields of point formats 9 and 10 wrong where points of several
    scanner channels carry them (the format reviewer: offsets 60 316 572 828 1084 came back as 60 316 572
    828 316). Channels mixed from the first point: refused before any work (the first chunk is tried in
    memory); mixed only after 60,000 points (a code reviewer: the first version checked the first
    50,000 and delivered the copy): refused when the copy, read back in full, differs, naming the
    output (a tiled run named its staged temporary). A .las copy is right; nothing is left behind."""
    if not _lazrs_mixes_channels(tmp_path):
        pytest.skip("this lazrs writes the wave packets of several channels right: nothing to refuse")
    options = tiled_or_whole(tiled)
    early = _channels(tmp_path / "early.las", lambda n: np.arange(n) % 2)
    said = []
    with pytest.raises(OutputError, match=r"out\.laz: the LAZ writer \(lazrs 0\.8\) writes the wave packet fields of "
                                          r".*early\.las's points wrong .*write a \.las output instead"):
        run_ground_filter(str(early), str(tmp_path / "out.laz"), SMRF(), options=options, log=said.append)
    assert not any(line.startswith(("Filtering", "Tile ")) for line in said), said  # before any work
    late = _channels(tmp_path / "late.las", lambda n: np.where(np.arange(n) < 60_000, 0, np.arange(n) % 2))
    with pytest.raises(OutputError, match=r"(?<![.\w])out\.laz: the LAZ writer \(lazrs 0\.8\) writes the wave packet "
                                          r"fields of .*late\.las's points wrong"):
        run_ground_filter(str(late), str(tmp_path / "out.laz"), SMRF(), options=options)
    assert sorted(os.listdir(tmp_path)) == ["early.las", "late.las", "probe.las", "probe.laz"]
    run_ground_filter(str(late), str(tmp_path / "out.las"), SMRF(), options=options)
    plain, got = laspy.read(str(late)), laspy.read(str(tmp_path / "out.las"))
    assert np.array_equal(got.wavepacket_offset, plain.wavepacket_offset) and np.array_equal(got.x_t, plain.x_t)


def test_a_laz_copy_of_one_channel_with_nan_wave_vectors_is_delivered(tmp_path):
    """One scanner channel, lazrs writes the fields right; a NaN in x_t made the check refuse it."""
    src = _channels(tmp_path / "nan.las", lambda n: np.zeros(n, int),
                    x_t=lambda n: np.where(np.arange(n) == 5, np.nan, np.linspace(0, 1, n)))
    run_ground_filter(str(src), str(tmp_path / "out.laz"), SMRF())
    got = laspy.read(str(tmp_path / "out.laz"))
    assert np.isnan(got.x_t[5]) and np.array_equal(got.wavepacket_offset, laspy.read(str(src)).wavepacket_offset)


def test_the_dimensions_a_run_adds_claim_no_minimum_or_maximum(tmp_path):
    """laspy wrote NaN or sentinels as the minimum and maximum of the extra dimensions it adds, beside an
    options byte saying they were set (a code reviewer, on groundsieve:features' output); the source's
    own descriptions are kept as they are."""
    from groundsieve.core.engine.features_run import write_features
    from groundsieve.core.io import read_cloud
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.add_extra_dim(laspy.ExtraBytesParams(name="treeID", type=np.int32))
    las = laspy.LasData(header)
    rng = np.random.default_rng(4)
    las.x, las.y, las.z = rng.uniform(0, 50, (3, 500))
    las.treeID = rng.integers(1, 9, 500)
    src = tmp_path / "in.las"
    las.write(str(src))
    data = bytearray(src.read_bytes())
    at = struct.unpack_from("<H", data, 94)[0] + 54
    data[at + 3] |= 0x06
    struct.pack_into("<q", data, at + 64, 1)
    struct.pack_into("<q", data, at + 88, 8)
    src.write_bytes(bytes(data))
    out = tmp_path / "features.las"
    write_features(read_cloud(str(src)), {"verticality": rng.random(500).astype(np.float32)}, str(out))
    with laspy.open(str(out)) as reader:
        eb = next(v for v in reader.header.vlrs if type(v).__name__ == "ExtraBytesVlr").record_data_bytes()
    assert eb[:192] == bytes(data[at:at + 192])  # the source's, as it was
    assert eb[192 + 4:192 + 4 + 11].rstrip(b"\0") == b"verticality" and not eb[192 + 3] & 0x06


def test_a_copc_headers_copy_keeps_the_other_vlrs_in_their_order():
    """plain_header set a new VLR list, which laspy writes with the extra-bytes VLR last."""
    from groundsieve.core.io.copc import plain_header
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.vlrs.append(laspy.VLR(user_id="copc", record_id=1, record_data=b"\0" * 160))
    header.vlrs.append(laspy.VLR(user_id="MYCORP", record_id=1, record_data=b"a"))
    header.add_extra_dim(laspy.ExtraBytesParams(name="e", type=np.uint8))
    header.vlrs.append(laspy.VLR(user_id="MYCORP", record_id=2, record_data=b"b"))
    before = [(str(v.user_id), v.record_id) for v in header.vlrs]
    assert before[0] == ("copc", 1)
    import io
    buffer = io.BytesIO()
    with laspy.LasWriter(buffer, header=plain_header(header), closefd=False) as writer:
        writer.write_points(laspy.ScaleAwarePointRecord.zeros(3, header=header))
    buffer.seek(0)
    with laspy.open(buffer) as reader:
        assert [(str(v.user_id), v.record_id) for v in reader.header.vlrs] == before[1:]


def _append_record(path, samples: bytes, record_id=65535) -> int:
    """Append a waveform-like EVLR to ``path``; its offset."""
    data = bytearray(path.read_bytes())
    at = len(data)
    data += struct.pack("<H16sHQ32s", 0, b"LASF_Spec", record_id, len(samples), b"packets") + samples
    path.write_bytes(bytes(data))
    return at


def test_the_waveform_record_the_header_points_at_is_the_one_carried(tmp_path):
    """Two waveform records in a LAS 1.4 file, the header pointing at the second: the copy pointed at the
    first (a QA reviewer: 4,000 bytes of the wrong samples, silently)."""
    src = write_with_packets(tmp_path / "two.las", 9, "1.4", n=500)
    second = _append_record(src, bytes(range(256)) * 160)
    data = bytearray(src.read_bytes())
    struct.pack_into("<Q", data, 227, second)
    struct.pack_into("<I", data, 243, struct.unpack_from("<I", data, 243)[0] + 1)  # one more EVLR
    src.write_bytes(bytes(data))
    for ext in ("las", "laz"):
        run_ground_filter(str(src), str(tmp_path / f"out.{ext}"), SMRF())
        assert packets(tmp_path / f"out.{ext}") == packets(src) and len(packets(src)) == 60 + 256 * 160


@pytest.mark.parametrize("pointer", ["into the points", "zero", "past the end"])
def test_a_waveform_pointer_that_leads_nowhere_finds_the_record_after_the_points(tmp_path, pointer):
    """A pointer into the point data was read as "the file holds 0 point records" and the run refused;
    a pointer of 0 or past the end dropped the samples. The record right after the points is the one."""
    src = write_with_packets(tmp_path / "p.las", 4, "1.3", n=2000)
    right = packets(src)
    data = bytearray(src.read_bytes())
    offset = struct.unpack_from("<I", data, 96)[0]
    struct.pack_into("<Q", data, 227, {"into the points": offset + 40, "zero": 0, "past the end": 10 ** 9}[pointer])
    src.write_bytes(bytes(data))
    said = []
    run_ground_filter(str(src), str(tmp_path / "out.las"), SMRF(), log=said.append)
    assert packets(tmp_path / "out.las") == right
    assert len(laspy.read(str(tmp_path / "out.las")).points) == 2000
    assert not any("point records" in line for line in said), said


@pytest.mark.parametrize("tiled", [False, True])
def test_waveform_packets_that_cannot_be_found_are_said_and_the_copy_claims_none(tmp_path, tiled):
    """A record of another id where the header points (or one longer than the file): the samples were
    dropped without a word, the copy still claiming them at its end."""
    src = write_with_packets(tmp_path / "w.las", 4, "1.3", n=2000)
    data = bytearray(src.read_bytes())
    at = struct.unpack_from("<Q", data, 227)[0]
    struct.pack_into("<H", data, at + 18, 65534)
    src.write_bytes(bytes(data))
    said = []
    run_ground_filter(str(src), str(tmp_path / "out.las"), SMRF(), options=tiled_or_whole(tiled), log=said.append)
    warned = [line for line in said if "w.las: its header says the waveform packets are in the file" in line]
    assert len(warned) == 1 and "a classified copy leaves them out" in warned[0], said
    assert not any("point records" in line for line in said), said  # (the record's bytes are no points)
    out = (tmp_path / "out.las").read_bytes()
    assert not struct.unpack_from("<H", out, 6)[0] & 2 and struct.unpack_from("<Q", out, 227)[0] == 0


@pytest.mark.parametrize("ext", ["las", "laz"])
@pytest.mark.parametrize("data_type, options, size", [(0, 4, 4), (0, 2, 2), (0, 3, 3), (4, 2, 2)],
                         ids=["undocumented 4", "undocumented 2", "undocumented 3", "int16 with a minimum only"])
def test_extra_bytes_without_a_minimum_or_maximum_run_tiled(tmp_path, ext, data_type, options, size):
    """An extra-bytes description without a minimum, a maximum or both (undocumented bytes, data type 0,
    their count in the options byte, whose bits 1 and 2 are also "minimum set" and "maximum set"; or a
    documented type with a minimum only), which LAS allows: a tiled run stopped with a traceback (laspy
    has None for them; a code reviewer found the min-only cases after the first fix)."""
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales, header.offsets = [0.01] * 3, [500000.0, 4000000.0, 0.0]
    header.add_extra_dim(laspy.ExtraBytesParams(name="foo", type=np.int16 if size == 2 else np.int32 if size == 4
                                                else "3u1"))
    las = laspy.LasData(header)
    rng = np.random.default_rng(5)
    las.x, las.y = 500000 + rng.uniform(0, 120, 4000), 4000000 + rng.uniform(0, 120, 4000)
    las.z = rng.uniform(0, 0.3, 4000)
    las.foo = rng.integers(0, 100, las.foo.shape)
    src = tmp_path / "eb.las"
    las.write(str(src))
    data = bytearray(src.read_bytes())
    at = struct.unpack_from("<H", data, 94)[0] + 54
    assert struct.unpack_from("<H", data, at - 54 + 20)[0] == 192  # one description
    data[at + 2], data[at + 3] = data_type, options
    src.write_bytes(bytes(data))
    out = tmp_path / f"out.{ext}"
    run_ground_filter(str(src), str(out), SMRF(), options=tiled_or_whole(True))
    a, b = laspy.read(str(src)), laspy.read(str(out))
    assert a.point_format.num_extra_bytes == b.point_format.num_extra_bytes == size
    for dim in a.point_format.dimension_names:
        if dim != "classification":
            assert np.array_equal(a[dim], b[dim]), dim


@pytest.mark.parametrize("tiled", [False, True])
def test_an_extra_bytes_type_las_does_not_define_is_refused_in_words(tmp_path, tiled):
    """laspy says only "77"; the message said "cannot read its LAS header (77)" (a QA reviewer)."""
    from groundsieve.core.errors import InputError
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.add_extra_dim(laspy.ExtraBytesParams(name="foo", type=np.int32))
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.random.default_rng(6).uniform(0, 50, (3, 200))
    src = tmp_path / "t77.las"
    las.write(str(src))
    data = bytearray(src.read_bytes())
    data[struct.unpack_from("<H", data, 94)[0] + 54 + 2] = 77
    src.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"t77\.las: .*an extra-bytes description has the data type 77, which LAS "
                                         r"does not define"):
        run_ground_filter(str(src), str(tmp_path / "out.las"), SMRF(), options=tiled_or_whole(tiled))
    assert not (tmp_path / "out.las").exists()


@pytest.mark.parametrize("tiled", [False, True])
@pytest.mark.parametrize("ext", ["las", "laz"])
def test_header_texts_beyond_ascii_are_copied_as_they_are(tmp_path, tiled, ext):
    """Vendors write Latin-1 into the header's texts (a system identifier "Soci\xe9t\xe9", a VLR's or
    EVLR's description "donn\xe9es"): laspy's writer refused them once the whole run was done, with
    a traceback (a format reviewer). The copy keeps their bytes."""
    n = 3000
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales, header.offsets = [0.01] * 3, [500000.0, 4000000.0, 0.0]
    header.vlrs.append(laspy.VLR(user_id="MYCORP", record_id=42, description="vendor blob", record_data=b"abc" * 8))
    las = laspy.LasData(header)
    rng = np.random.default_rng(3)
    las.x, las.y = 500000 + rng.uniform(0, 120, n), 4000000 + rng.uniform(0, 120, n)
    las.z = rng.uniform(0, 0.3, n) + (rng.random(n) < 0.3) * rng.uniform(2, 15, n)
    las.evlrs = VLRList([laspy.VLR(user_id="MYCORP", record_id=7, description="vendor notes", record_data=b"x" * 100)])
    src = tmp_path / "in.las"
    las.write(str(src))
    data = bytearray(src.read_bytes())
    data[26:58] = b"Soci\xe9t\xe9 X".ljust(32, b"\0")
    vlr = struct.unpack_from("<H", data, 94)[0]
    assert data[vlr + 2:vlr + 8] == b"MYCORP"
    data[vlr + 22:vlr + 54] = b"donn\xe9es".ljust(32, b"\0")
    evlr, = struct.unpack_from("<Q", data, 235)
    assert data[evlr + 2:evlr + 8] == b"MYCORP"
    data[evlr + 28:evlr + 60] = b"\xe9tude".ljust(32, b"\0")
    src.write_bytes(bytes(data))
    out = tmp_path / f"out.{ext}"
    run = run_ground_filter(str(src), str(out), SMRF(), options=tiled_or_whole(tiled))
    assert run.ground_count > 0
    with laspy.open(str(out)) as reader:
        assert reader.header.system_identifier == b"Soci\xe9t\xe9 X"
        assert [v.description for v in reader.header.vlrs if v.user_id == "MYCORP"] == [b"donn\xe9es"]
        assert [v.description for v in reader.header.evlrs if v.user_id == "MYCORP"] == [b"\xe9tude"]
        assert reader.header.point_count == n
    assert src.read_bytes() == bytes(data)


def _two_extra_dims(path, second_name: bytes):
    """A LAS 1.2 file with extra-bytes dimensions 'ampA' and 'ampB', the second renamed to ``second_name``."""
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales, header.offsets = [0.01] * 3, [500000.0, 4000000.0, 0.0]
    for name in ("ampA", "ampB"):
        header.add_extra_dim(laspy.ExtraBytesParams(name=name, type=np.uint16))
    las = laspy.LasData(header)
    rng = np.random.default_rng(4)
    las.x, las.y, las.z = 500000 + rng.uniform(0, 50, 500), 4000000 + rng.uniform(0, 50, 500), rng.uniform(0, 1, 500)
    las.write(str(path))
    data = bytearray(path.read_bytes())
    at = data.index(b"ampB\0")
    data[at:at + 32] = second_name.ljust(32, b"\0")
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("tiled", [False, True])
@pytest.mark.parametrize("name, words", [
    (b"ampA", "name the dimension 'ampA' twice, or name one its point format already has"),
    (b"gps_time", "name the dimension 'gps_time' twice"),
    (b"\xc9cho", "the name of one of its extra-bytes dimensions is not UTF-8 text (byte 0xc9"),
])
def test_extra_bytes_names_laspy_cannot_take_are_refused_for_what_they_are(tmp_path, tiled, name, words):
    """Two extra-bytes dimensions of one name were "damaged or truncated"; a Latin-1 name was laspy's
    "'utf-8' codec can't decode" (a format reviewer). Refused in words, naming the file, before any work."""
    src = _two_extra_dims(tmp_path / "in.las", name)
    with pytest.raises(InputError) as err:
        run_ground_filter(str(src), str(tmp_path / "out.las"), SMRF(), options=tiled_or_whole(tiled))
    assert str(err.value).startswith(f"{src}: ") and words in str(err.value)
    assert "damaged" not in str(err.value) and "codec" not in str(err.value)
    assert os.listdir(tmp_path) == ["in.las"]


@pytest.mark.parametrize("tiled", [False, True])
def test_waveforms_in_an_external_file_are_said(tmp_path, tiled):
    """Global encoding bit 2: the packets are in NAME.wdp beside the file (Riegl, LAStools). The copy kept
    the wave packet fields pointing into a file it does not have, without a word (a format reviewer)."""
    header = laspy.LasHeader(point_format=4, version="1.3")
    header.scales, header.offsets = [0.01] * 3, [500000.0, 4000000.0, 0.0]
    las = laspy.LasData(header)
    rng = np.random.default_rng(6)
    n = 2000
    las.x, las.y, las.z = 500000 + rng.uniform(0, 60, n), 4000000 + rng.uniform(0, 60, n), rng.uniform(0, 1, n)
    las.wavepacket_index = np.ones(n, np.uint8)
    las.wavepacket_offset = 60 + 256 * np.arange(n, dtype=np.uint64)
    las.wavepacket_size = np.full(n, 256, np.uint32)
    src = tmp_path / "in.las"
    las.write(str(src))
    data = bytearray(src.read_bytes())
    struct.pack_into("<H", data, 6, (struct.unpack_from("<H", data, 6)[0] & ~2) | 4)  # external packets
    src.write_bytes(bytes(data))
    (tmp_path / "in.wdp").write_bytes(b"\0" * 60 + rng.integers(0, 256, n * 256, dtype=np.uint8).tobytes())
    run = run_ground_filter(str(src), str(tmp_path / "out.las"), SMRF(), options=tiled_or_whole(tiled))
    assert any(w.startswith(f"{src}: its waveform packets are in an external file (in.wdp beside it): the classified "
                            "copy keeps the points' wave packet fields") for w in run.warnings), run.warnings
