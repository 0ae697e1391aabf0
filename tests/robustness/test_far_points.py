"""Issue 14, items 3 and 5: a single point 1000 km away, and two survey areas 50 km apart in one
file, are refused (a whole-cloud grid spans the bounding box) with a message saying where the
far point is and what to do, for every ground filter that grids the cloud (CSF gave a traceback);
nothing written, the input unchanged."""
from __future__ import annotations

import numpy as np
import pytest

from groundsieve.core.engine import workflow
from groundsieve.core.errors import GroundSieveError
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


@pytest.mark.parametrize("algorithm", [SMRF(), PMF(), CSF(), EVC(ground_offset_m=0.1)], ids=lambda a: a.name)
def test_a_point_1000_km_away_is_refused_with_its_place(tmp_path, algorithm):
    src = tmp_path / "in" / "far.las"
    src.parent.mkdir()
    _write(src, [(3999, (1_000_000.0, 1_000_000.0))])
    out = tmp_path / "out"
    out.mkdir()
    before = sha256(src)
    with pytest.raises(GroundSieveError) as err:
        workflow.run_ground_filter(str(src), str(out / "c.las"), algorithm)  # the filter's own grids
    message = str(err.value)
    assert "1 point lies" in message and "from the others" in message, message
    assert "remove them" in message
    assert everything_in(out) == [] and sha256(src) == before


def test_two_areas_50_km_apart_are_refused_with_what_to_do(tmp_path):
    src = tmp_path / "in" / "two.las"
    src.parent.mkdir()
    _write(src, [(2000, (50_000.0, 50_000.0))])
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(GroundSieveError) as err:
        workflow.run_ground_filter(str(src), str(out / "c.las"), SMRF())
    assert "split it into one file per area" in str(err.value), str(err.value)
    assert everything_in(out) == []
