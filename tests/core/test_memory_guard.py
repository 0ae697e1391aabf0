"""Grids are sized by memory, not by cell count (issue 16): the estimate in bytes is checked before
anything is allocated, against a budget (a share of the memory available, or of what is left under
an address-space limit, or an explicit one), and the refusal says where the stray points are."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from groundsieve.core.errors import MemoryBudgetError
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, classify_cloud, make_dtm
from groundsieve.core.filters.csf import CSF
from groundsieve.core.filters.echogrid import EchoGrid
from groundsieve.core.filters.evc import EVC
from groundsieve.core.filters.pmf import PMF
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.grids.spec import GridSpec, isolated_points, memory_budget, memory_budget_bytes
from groundsieve.core.io import PointCloud

import groundsieve

PLUGINS = os.path.dirname(os.path.dirname(os.path.abspath(groundsieve.__file__)))  # the folder holding the package


def cloud_with_stray(n=20_000, stray_at=(20_000.0, 50.0), seed=0):
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(0, 100, n), rng.uniform(0, 100, n)
    z = rng.normal(0, 0.05, n)
    if stray_at is not None:
        x[-1], y[-1] = stray_at
    ones = np.ones(n, dtype=np.uint8)
    return PointCloud("stray.las", x, y, z, ones.copy(), ones.copy(), ones.copy())


def test_isolated_points_finds_the_stray_point_and_nothing_in_a_clean_cloud():
    cloud = cloud_with_stray()
    far, dist, core = isolated_points(cloud.x, cloud.y)
    assert far.tolist() == [len(cloud) - 1]
    assert 19_850 < dist[0] < 19_950
    assert core[1] - core[0] < 101
    clean = cloud_with_stray(stray_at=None)
    assert isolated_points(clean.x, clean.y)[0].size == 0


@pytest.mark.parametrize("algorithm, mb", [(SMRF(), 50), (PMF(), 50), (EVC(), 50), (CSF(), 50), (EchoGrid(), 1)],
                         ids=lambda a: type(a).__name__)
def test_every_grid_filter_refuses_above_the_budget_before_allocating(algorithm, mb):
    cloud = cloud_with_stray()
    with pytest.raises(MemoryBudgetError) as err:
        classify_cloud(cloud, algorithm, FilterOptions(memory_budget_bytes=mb << 20))
    msg = str(err.value)
    assert f"more than the {mb}.0 MB this run may use" in msg
    assert "1 point lies 19.9 km from the others, at x 20000.00, y 50.00" in msg
    assert "survey-scale tiler" in msg
    # The same cloud without the stray point fits in that budget.
    classify_cloud(cloud_with_stray(stray_at=None), algorithm, FilterOptions(memory_budget_bytes=mb << 20))


def test_the_stray_point_classed_as_noise_is_ignored_and_the_run_fits():
    cloud = cloud_with_stray()
    cloud.classification[-1] = 7
    done = classify_cloud(cloud, SMRF(), FilterOptions(memory_budget_bytes=50 << 20))
    assert done.ground[:-1].mean() > 0.99 and not done.ground[-1]


def test_dtm_is_checked_in_bytes_not_cells():
    # 2e8 cells were accepted by the cell-count guard (about 8 GB for the raster alone).
    x = np.array([0.0, 20_000.0, 0.0])
    y = np.array([0.0, 0.0, 10_000.0])
    with pytest.raises(MemoryBudgetError, match=r"DTM: 20,000 x 10,000 cells of 1 m .* need about 7.5 GB"):
        make_dtm(x, y, np.zeros(3), np.ones(3, dtype=bool), DTMOptions(memory_budget_bytes=1 << 30))


def test_budget_defaults_to_a_share_of_the_memory_and_can_be_set():
    assert memory_budget_bytes() > 0
    with memory_budget(123_456_789):
        assert memory_budget_bytes() == 123_456_789
        with pytest.raises(MemoryBudgetError):
            GridSpec.covering(np.array([0.0, 1e5]), np.array([0.0, 1e3]), 1.0, bytes_per_cell=8)
    with pytest.raises(Exception, match="memory_budget_bytes"):
        FilterOptions(memory_budget_bytes=-1)


SCRIPT = textwrap.dedent("""
    import resource, sys
    sys.path.insert(0, {plugins!r})
    import numpy as np
    from groundsieve.core.engine.workflow import DTMOptions, run_ground_filter
    from groundsieve.core.errors import MemoryBudgetError
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.io import new_las, write_las
    cap = 2 << 30
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    rng = np.random.default_rng(0)
    n = 1_000_000
    x, y = rng.uniform(0, 1000, n) + 500000.0, rng.uniform(0, 1000, n) + 5400000.0
    z = rng.normal(100, 0.05, n)
    if {stray}:
        x[-1] = 521_000.0  # 20 km east of the others
    src, out, dtm = sys.argv[1], sys.argv[2], sys.argv[3]
    write_las(new_las(x, y, z, classification=np.ones(n, dtype=np.uint8)), src)
    try:
        # A 5 m DTM: 4 points a cell triangulated, 160,000 (the 1 m one spends half a minute in qhull).
        run = run_ground_filter(src, out, SMRF(), dtm_path=dtm, dtm=DTMOptions(cell_size_m=5.0), log=print)
    except MemoryBudgetError as err:
        print("REFUSED", err)
        sys.exit(3)
    print("DONE", type(run).__name__)
""")


@pytest.mark.parametrize("stray", [True, False], ids=["stray_point_20km", "clean"])
def test_one_million_points_under_a_2gb_address_space_cap(tmp_path, stray):
    src, out, dtm = tmp_path / "in.las", tmp_path / "out.las", tmp_path / "dtm.tif"
    proc = subprocess.run([sys.executable, "-c", SCRIPT.format(plugins=PLUGINS, stray=stray), str(src), str(out),
                           str(dtm)], capture_output=True, text=True, timeout=600)
    text = proc.stdout + proc.stderr
    if stray:
        # Not a kill (-9) or a crash (-11): the whole run's estimate counts SMRF's grid of 20 km (its empty
        # cells as its guard does), so the file runs in tiles, which exist only where points are, within
        # the cap (it was refused by the guard before); the log says where the stray point is.
        assert proc.returncode == 0, text
        assert "run whole it would take about" in text and "DONE TiledRun" in text, text
        assert "DTM: 1 point(s) in 1 tile(s) lie far from the others" in text, text
        assert out.exists() and dtm.exists()
    else:
        assert proc.returncode == 0, text
        assert "DONE FilterRun" in text and out.exists() and dtm.exists()


def test_a_dtm_too_large_is_refused_before_the_filter_runs(tmp_path):
    from groundsieve.core.engine.workflow import run_ground_filter
    from groundsieve.core.io import new_las, write_las
    cloud = cloud_with_stray()
    src = tmp_path / "in.las"
    write_las(new_las(cloud.x, cloud.y, cloud.z, classification=cloud.classification), str(src))
    calls = []

    def filter_that_counts(xyz, steps=None):
        calls.append(len(xyz))
        return np.ones(len(xyz), dtype=bool)
    with pytest.raises(MemoryBudgetError, match=r"^DTM: .* 1 point lies 19.9 km from the others"):
        run_ground_filter(str(src), str(tmp_path / "o.las"), filter_that_counts, dtm_path=str(tmp_path / "d.tif"),
                          dtm=DTMOptions(cell_size_m=0.5, memory_budget_bytes=50 << 20))
    assert calls == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.las"]
