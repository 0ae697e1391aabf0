"""What every ground filter promises the driver, checked once for all of them: progress stays
within the range it is given, grows and ends at its top; a cancellation request stops the run
through ``run`` and through ``__call__``; concurrent runs in threads agree with single runs; bad
arrays (empty, wrong shape, NaN or infinite coordinates) raise InputError; and the terrain
filters (SMRF, PMF, CSF, PTD and the learned hybrid) call every point ground on degenerate but
valid input (one point, identical points, one height, points on a line or a grid). Filter-specific progress counts,
mid-run cancellation and inputs are tested in each filter's own module."""
import numpy as np
import pytest

from groundsieve.core.filters.csf import CSF
from groundsieve.core.filters.echogrid import EchoGrid
from groundsieve.core.errors import Cancelled, InputError
from groundsieve.core.filters.evc import EVC
from groundsieve.core.filters.pmf import PMF
from groundsieve.core.progress import Steps
from groundsieve.core.filters.ptd import PTD
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.learn.hybrid import Hybrid

FILTERS = [SMRF(), PMF(), CSF(), PTD(), EchoGrid(), EVC(), Hybrid(), Hybrid(shipped_model="accurate")]


def plane(size=20.0, density=4.0, seed=0):
    """A gently tilted, slightly noisy plane at UTM-sized coordinates."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, size, (int(size * size * density), 2))
    z = 100.0 + 0.02 * xy[:, 0] + rng.normal(0.0, 0.02, len(xy))
    return np.column_stack([xy + [512000.0, 5403000.0], z])


@pytest.mark.parametrize("algorithm", FILTERS, ids=lambda f: f.name)
def test_progress_within_a_sub_range(algorithm):
    seen = []
    algorithm.run(plane(), Steps(progress=seen.append).sub(0.2, 0.6))
    assert seen, "no progress reported"
    assert min(seen) >= 0.2 - 1e-12 and max(seen) <= 0.6 + 1e-12
    assert seen[-1] == pytest.approx(0.6)
    assert all(b >= a for a, b in zip(seen, seen[1:])), seen


@pytest.mark.parametrize("algorithm", FILTERS, ids=lambda f: f.name)
def test_cancelled_from_the_start(algorithm):
    xyz = plane()
    with pytest.raises(Cancelled):
        algorithm.run(xyz, Steps(is_cancelled=lambda: True))
    with pytest.raises(Cancelled):
        algorithm(xyz, steps=Steps(is_cancelled=lambda: True))


def test_concurrent_runs_in_threads_give_the_same_results():
    """QGIS runs each Processing algorithm in a task thread, so two filters can run at once in
    one process (numba's parallel kernels included): 8 threads, 2 per filter of four kinds with
    parallel kernels, each run 3 times, give the results of the runs one at a time."""
    import threading

    from groundsieve.core.synthetic import SceneSpec, make_scene
    scene = make_scene(SceneSpec.for_points(60_000, density_per_m2=5, seed=2))
    xyz = np.column_stack([scene.x, scene.y, scene.z])
    kinds = [SMRF(), PMF(), PTD(), CSF()]
    expected = [f(xyz) for f in kinds]
    problems = []

    def work(i):
        try:
            for _ in range(3):
                if not np.array_equal(kinds[i % 4](xyz), expected[i % 4]):
                    problems.append(f"{kinds[i % 4].name}: another result in thread {i}")
        except Exception as exc:  # pragma: no cover - reported below
            problems.append(f"{kinds[i % 4].name} in thread {i}: {exc!r}")

    threads = [threading.Thread(target=work, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert not any(t.is_alive() for t in threads), "a thread did not finish"
    assert not problems, problems
    assert all(e.any() and not e.all() for e in expected)  # real classifications, not trivial ones


# --- degenerate and bad inputs, the same answer from every filter -------------------------------

X0, Y0 = 512000.0, 5403000.0
#: The filters of a terrain surface: on degenerate but finite input every point is ground.
TERRAIN_FILTERS = [SMRF(), PMF(), CSF(), PTD(), Hybrid(), Hybrid(shipped_model="accurate")]


def _bad_arrays():
    finite = plane(size=10.0)
    cases = {"empty": np.empty((0, 3)), "empty1d": np.empty((0,)), "2cols": np.zeros((5, 2)),
             "4cols": np.zeros((3, 4)), "1d": np.zeros(3)}
    for column in range(3):
        for name, value in (("nan", np.nan), ("inf", np.inf), ("-inf", -np.inf)):
            xyz = finite.copy()
            xyz[3, column] = value
            cases[f"{name}-in-{'xyz'[column]}"] = xyz
    return cases


BAD_ARRAYS = _bad_arrays()


@pytest.mark.parametrize("case", list(BAD_ARRAYS))
@pytest.mark.parametrize("algorithm", FILTERS, ids=lambda f: f.name)
def test_bad_arrays_raise_input_error(algorithm, case):
    with pytest.raises(InputError) as info:
        algorithm(BAD_ARRAYS[case])
    if "-in-" in case:
        assert "NaN or infinite" in str(info.value)


@pytest.mark.parametrize("algorithm", TERRAIN_FILTERS, ids=lambda f: f.name)
def test_one_point_is_ground(algorithm):
    g = algorithm(np.array([[X0, Y0, 250.0]]))
    assert g.shape == (1,) and g.dtype == bool and g[0]


@pytest.mark.parametrize("algorithm", TERRAIN_FILTERS, ids=lambda f: f.name)
def test_identical_points_are_ground(algorithm):
    assert algorithm(np.tile([[X0, Y0, 3.0]], (1000, 1))).all()


@pytest.mark.parametrize("algorithm", TERRAIN_FILTERS, ids=lambda f: f.name)
def test_points_at_one_height_are_ground(algorithm):
    rng = np.random.default_rng(11)
    xyz = np.column_stack([rng.uniform(0, 30, 500) + X0, rng.uniform(0, 30, 500) + Y0, np.full(500, 7.0)])
    assert algorithm(xyz).all()


def _layouts():
    t = np.arange(40, dtype=np.float64)
    gx, gy = np.meshgrid(np.arange(20.0), np.arange(20.0))
    return {"row": np.column_stack([t + X0, np.full(40, Y0), np.zeros(40)]),
            "column": np.column_stack([np.full(40, X0), t + Y0, np.zeros(40)]),
            "diagonal": np.column_stack([t + X0, t + Y0, np.zeros(40)]),
            "two": np.array([[X0, Y0, 1.0], [X0 + 25.0, Y0 + 3.0, 1.5]]),
            "grid": np.column_stack([gx.ravel() + X0, gy.ravel() + Y0, np.full(gx.size, 2.0)])}


LAYOUTS = _layouts()


@pytest.mark.parametrize("layout", list(LAYOUTS))
@pytest.mark.parametrize("algorithm", TERRAIN_FILTERS, ids=lambda f: f.name)
def test_degenerate_layouts_are_ground(algorithm, layout):
    """Points on a line, a diagonal, a regular grid, or just two far apart: no crash, all ground."""
    xyz = LAYOUTS[layout]
    g = algorithm(xyz)
    assert g.shape == (len(xyz),) and g.all()
