"""A LAS 1.4 file whose header announces more points than it holds, with extended VLRs after the
points (issue 16): only the real records are read, the log says how many were missing, the EVLRs
are kept; the same in LAZ is refused with a message."""
from __future__ import annotations

import struct

import laspy
import numpy as np
import pytest
from laspy.vlrs.vlrlist import VLRList

from groundsieve.core.engine.workflow import run_ground_filter
from groundsieve.core.progress import WARNING_PREFIX
from groundsieve.core.errors import InputError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.io import read_cloud

NUMBER_OF_POINT_RECORDS_AT = 247  # LAS 1.4 header: unsigned long long


def write_over_announced(path, n=2000, announced=2100, compress=False):
    rng = np.random.default_rng(0)
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = np.array([512000.0, 5403000.0, 0.0])
    las = laspy.LasData(header)
    las.x = 512000.0 + rng.uniform(0, 30, n)
    las.y = 5403000.0 + rng.uniform(0, 30, n)
    las.z = rng.normal(0, 0.05, n)
    las.classification = np.ones(n, dtype=np.uint8)
    las.evlrs = VLRList([laspy.VLR(user_id="groundsieve", record_id=1, description="after the points",
                                   record_data=b"\x7f" * 5000)])
    las.write(str(path), do_compress=compress)
    raw = bytearray(path.read_bytes())
    assert struct.unpack_from("<Q", raw, NUMBER_OF_POINT_RECORDS_AT)[0] == n
    struct.pack_into("<Q", raw, NUMBER_OF_POINT_RECORDS_AT, announced)
    path.write_bytes(bytes(raw))
    return las


def test_only_the_real_records_are_read_and_the_missing_ones_are_told(tmp_path):
    src = tmp_path / "over.las"
    truth = write_over_announced(src)
    cloud = read_cloud(str(src))
    assert len(cloud) == 2000
    np.testing.assert_array_equal(cloud.x, np.asarray(truth.x))   # no EVLR byte taken for a point
    assert cloud.notes == [f"{WARNING_PREFIX}{src}: the header announces 2,100 points but the file holds 2,000 point records "
                           "before its extended VLRs (at byte 60,375); read those 2,000, 100 missing "
                           "(the header's count is wrong)."]
    messages = []
    out = tmp_path / "out.las"
    run_ground_filter(str(src), str(out), SMRF(), log=messages.append)
    assert cloud.notes[0] in messages
    back = laspy.read(str(out))
    assert back.header.point_count == 2000 and len(back.evlrs) == 1
    assert (np.asarray(back.classification) == 2).mean() > 0.99


def test_the_same_in_laz_is_refused_with_a_message(tmp_path):
    src = tmp_path / "over.laz"
    write_over_announced(src, compress=True)
    with pytest.raises(InputError, match="cannot be read; the file is damaged or truncated"):
        read_cloud(str(src))


@pytest.mark.parametrize("count64", [0, 1000])
def test_a_las14_count_that_disagrees_with_a_legacy_count_matching_the_records_is_refused(tmp_path, count64):
    """LAS 1.4, point format 1: the legacy count right, the 64-bit count 0 (refused as "still being written")
    or smaller (read that many, the rest dropped with a warning, the run done: a format reviewer)."""
    import struct

    import laspy
    import numpy as np

    from groundsieve.core.engine.workflow import run_ground_filter
    from groundsieve.core.errors import InputError
    from groundsieve.core.filters.smrf import SMRF
    n = 3000
    header = laspy.LasHeader(point_format=1, version="1.4")
    header.scales, header.offsets = [0.01] * 3, [500000.0, 4000000.0, 0.0]
    las = laspy.LasData(header)
    rng = np.random.default_rng(5)
    las.x, las.y, las.z = 500000 + rng.uniform(0, 60, n), 4000000 + rng.uniform(0, 60, n), rng.uniform(0, 1, n)
    src = tmp_path / "in.las"
    las.write(str(src))
    data = bytearray(src.read_bytes())
    struct.pack_into("<I", data, 107, n)       # the legacy count, as LAStools writes it
    struct.pack_into("<Q", data, 247, count64)  # the LAS 1.4 count, wrong
    src.write_bytes(bytes(data))
    with pytest.raises(InputError, match=rf"in.las: its two point counts disagree: the LAS 1.4 count says {count64:,}, "
                                         r"the legacy count 3,000, as many as the point records the file holds"):
        run_ground_filter(str(src), str(tmp_path / "out.las"), SMRF())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.las"]
