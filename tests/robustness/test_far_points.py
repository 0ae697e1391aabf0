"""Issue 14, items 3 and 5, and issue 10: a single point 1000 km away, and two survey areas 50 km
apart in one file, run through the survey engine, which grids only where points are (a whole-cloud
grid spanning the bounding box is refused by the memory guard with the point's place); the input
is unchanged."""
from __future__ import annotations

import numpy as np
import pytest

from groundsieve.core.engine import workflow
from groundsieve.core.filters.csf import CSF
from groundsieve.core.filters.evc import EVC
from groundsieve.core.filters.pmf import PMF
from groundsieve.core.filters.smrf import SMRF

from .folders import everything_in, sha256
from .test_silent_answers import _las


def _write(path, offsets):
    import laspy
    _las(path, 4000)
    las = laspy.read(str(path))
    x, y = np.array(las.x), np.array(las.y)
    for start, (dx, dy) in offsets:
        x[start:] += dx
        y[start:] += dy
    las.header.offsets = (float(x.min()), float(y.min()), 0.0)
    las.x, las.y = x, y
    las.write(str(path))


def _classes(path):
    import laspy
    return np.asarray(laspy.read(str(path)).classification)


@pytest.mark.parametrize("algorithm", [SMRF(), PMF(), CSF(), EVC(ground_offset_m=0.1)], ids=lambda a: a.name)
def test_a_point_1000_km_away_runs_in_tiles_where_points_are(tmp_path, algorithm):
    """A whole-cloud grid would span 1000 km (the memory guard refuses it, naming the point: see
    tests/core/test_memory_guard.py); the survey engine grids only where points are, so the run
    goes through: the stray point, alone in its tile, keeps its class and is not ground."""
    src = tmp_path / "in" / "far.las"
    src.parent.mkdir()
    _write(src, [(3999, (1_000_000.0, 1_000_000.0))])
    near = tmp_path / "in" / "near.las"
    _write(near, [])
    out = tmp_path / "out"
    out.mkdir()
    before = sha256(src)
    logged = []
    workflow.run_ground_filter(str(src), str(out / "c.las"), algorithm, log=logged.append)
    workflow.run_ground_filter(str(near), str(out / "n.las"), algorithm)
    cls, ref = _classes(out / "c.las"), _classes(out / "n.las")
    assert len(cls) == 4000 and cls[3999] != 2
    assert (cls[:3999] == ref[:3999]).mean() > 0.99
    assert any("tile" in line.lower() for line in logged)
    assert everything_in(out) == ["c.las", "n.las"] and sha256(src) == before


def test_two_areas_50_km_apart_run_in_tiles(tmp_path):
    src = tmp_path / "in" / "two.las"
    src.parent.mkdir()
    _write(src, [(2000, (50_000.0, 50_000.0))])
    out = tmp_path / "out"
    out.mkdir()
    workflow.run_ground_filter(str(src), str(out / "c.las"), SMRF())
    cls = _classes(out / "c.las")
    assert (cls[:2000] == 2).mean() > 0.3 and (cls[2000:] == 2).mean() > 0.3
    assert everything_in(out) == ["c.las"]
