"""Issue 14, item 4, in the core: answers that were silent or unclear now say what happened and
what to change (a LAS header announcing fewer points than the file holds; EVC on a perfectly
flat cloud asked for a DTM)."""
from __future__ import annotations

import struct

import laspy
import numpy as np
import pytest

from groundsieve.core.engine import workflow
from groundsieve.core.errors import InvalidParameterError
from groundsieve.core.filters.evc import EVC
from groundsieve.core.io import read_cloud

from .folders import everything_in, sha256


def _las(path, n, *, version="1.2", z=None):
    rng = np.random.default_rng(5)
    las = laspy.create(point_format=1 if version == "1.2" else 6, file_version=version)
    las.header.scales = (0.01, 0.01, 0.01)
    las.header.offsets = (500000.0, 4000000.0, 0.0)
    las.x = 500000.0 + rng.uniform(0, 30, n)
    las.y = 4000000.0 + rng.uniform(0, 30, n)
    las.z = rng.uniform(0, 2, n) if z is None else np.full(n, z)
    las.write(str(path))


@pytest.mark.parametrize("version", ["1.2", "1.4"])
def test_a_header_announcing_fewer_points_than_held_is_said(tmp_path, version):
    path = tmp_path / "short-header.las"
    _las(path, 1000, version=version)
    with open(path, "r+b") as handle:  # the legacy count (offset 107), and LAS 1.4's 64-bit one (247)
        handle.seek(107)
        handle.write(struct.pack("<I", 0 if version == "1.4" else 990))
        if version == "1.4":
            handle.seek(247)
            handle.write(struct.pack("<Q", 990))
    before = sha256(path)
    cloud = read_cloud(str(path))
    assert len(cloud) == 990
    assert [n for n in cloud.notes if "announces 990 points but the file holds 1,000 point records" in n
            and "10 ignored" in n and n.startswith(f"Warning: {path}")], cloud.notes
    log = []
    workflow.run_ground_filter(str(path), str(tmp_path / "out.las"), EVC(ground_offset_m=0.1), log=log.append)
    assert any("10 ignored" in m for m in log)
    assert sha256(path) == before


def test_an_honest_header_says_nothing(tmp_path):
    path = tmp_path / "ok.las"
    _las(path, 500)
    assert read_cloud(str(path)).notes == []


def test_evc_on_a_perfectly_flat_cloud_explains_why_no_dtm(tmp_path):
    src = tmp_path / "flat.las"
    _las(src, 20_000, z=12.0)
    out = tmp_path / "out"
    out.mkdir()
    before = sha256(src)
    with pytest.raises(InvalidParameterError) as err:
        workflow.run_ground_filter(str(src), str(out / "c.las"), EVC(), dtm_path=str(out / "dtm.tif"))
    message = str(err.value)
    assert message.startswith(f"{src}: the filter found no ground point: no DTM can be made. Why: the surface is "
                              "perfectly flat"), message
    assert "0 / 0" in message
    assert "Ground offset added to the mean difference (m)" in message
    assert everything_in(out) == [] and sha256(src) == before
    # and what it says to change works
    workflow.run_ground_filter(str(src), str(out / "c.las"), EVC(ground_offset_m=0.1), dtm_path=str(out / "dtm.tif"))
    assert everything_in(out) == ["c.las", "dtm.tif"]
