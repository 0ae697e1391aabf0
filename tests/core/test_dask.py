"""The tiles of a survey on a Dask cluster (core/engine/cluster.py): a LocalCluster of 2 worker
processes, one of them killed while tiles run, gives the classes and DTM of a single-process run,
byte for byte; bad schedulers and unfit workers are refused with a clear message."""
from __future__ import annotations

import os
import re
import time

import laspy
import numpy as np
import pytest

from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
from groundsieve.core.errors import GroundSieveError, InvalidParameterError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
from groundsieve.tests.shared_data import on_ci


def _unshadow_dask():
    """A checkout in a folder named ``dask`` is a package pytest imports as ``dask`` (its parent put
    first on sys.path, the repository root having an ``__init__.py``): it then shadows the real
    dask, here and in the spawned workers. Drop that import and that path entry."""
    import sys
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    if os.path.basename(repo) != "dask":
        return
    parent = os.path.dirname(repo)
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != parent]
    for name in [n for n in sys.modules if n == "dask" or n.startswith("dask.")]:
        where = os.path.abspath(getattr(sys.modules[name], "__file__", None) or "")
        if where.startswith(repo + os.sep) and "site-packages" not in where:
            del sys.modules[name]


_unshadow_dask()
try:
    import distributed
except ImportError:  # pragma: no cover - the optional dependency
    distributed = None
    if on_ci():
        raise
needs_dask = pytest.mark.skipif(distributed is None, reason='dask[distributed] is not installed '
                                '(pip install "dask[distributed]"); it is optional')



@pytest.fixture(autouse=True)
def _real_dask_in_workers():
    _unshadow_dask()  # again: pytest puts the path back when it imports a test module


TILE = 20.0  # 8 x 8 = 64 small tiles over a 160 m scene


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    path = tmp_path_factory.mktemp("dask") / "scene.laz"
    write_scene(make_scene(SceneSpec(size_m=160.0, density_per_m2=1.0, seed=11)), path)
    return str(path)


def options(scheduler="", workers=1):
    return FilterOptions(tiling=TileOptions(tile_size_m=TILE, buffer_m=10.0, workers=workers,
                                            parallel="threads", scheduler=scheduler))


def read_tif(path):
    from osgeo import gdal
    ds = gdal.Open(str(path))
    return ds.GetGeoTransform(), ds.GetRasterBand(1).ReadAsArray()


@needs_dask
def test_a_killed_worker_changes_nothing(survey, tmp_path):
    """A worker process dies (SIGKILL) while it runs a tile in the middle of the run: Dask runs
    that tile again on a worker the nanny restarts, and the classes and the DTM are the
    single-process run's, byte for byte. (The worker kills itself in that tile's job, so the
    death falls mid-run whatever the machine's speed.)"""
    import functools

    from groundsieve.tests.core.scenes import die_once_in
    ref = run_ground_filter(survey, str(tmp_path / "ref.laz"), SMRF(), options=options(),
                            dtm_path=str(tmp_path / "ref.tif"), dtm=DTMOptions(cell_size_m=1.0))
    assert ref.tiles >= 50
    from groundsieve.core.engine import cluster as cl
    marker = str(tmp_path / "killed")
    victims = []
    real_run_jobs = cl.run_jobs

    def dying_once(scheduler, function, jobs, *args, **kw):  # on the run's own local cluster
        if "parts" in jobs[0]:  # the tiles (not the binning or writing jobs)
            victims.append(jobs[len(jobs) // 2]["key"])
            function = functools.partial(die_once_in, marker, victims[-1], function)
        return real_run_jobs(scheduler, function, jobs, *args, **kw)
    try:
        cl.run_jobs = dying_once
        logs = []
        run = run_ground_filter(survey, str(tmp_path / "dask.laz"), SMRF(), options=options("local:2"),
                                dtm_path=str(tmp_path / "dask.tif"), dtm=DTMOptions(cell_size_m=1.0),
                                log=logs.append)
    finally:
        cl.run_jobs = real_run_jobs
    assert victims and os.path.exists(marker), "no worker was killed: the test did not test a failure"
    os.remove(marker)
    assert run.tiles == ref.tiles and run.ground_count == ref.ground_count
    assert np.array_equal(laspy.read(tmp_path / "dask.laz").classification,
                          laspy.read(tmp_path / "ref.laz").classification)
    (gt_a, a), (gt_b, b) = read_tif(tmp_path / "dask.tif"), read_tif(tmp_path / "ref.tif")
    assert gt_a == gt_b and a.tobytes() == b.tobytes()
    assert any("Dask cluster" in line for line in logs)


@needs_dask
def test_an_unreachable_scheduler_is_a_clear_error_within_seconds(survey, tmp_path):
    """A closed port and an unknown host are told as such, at once; both were "did not answer
    within 10 s" after waiting those 10 s (an HPC reviewer)."""
    t0 = time.perf_counter()
    with pytest.raises(GroundSieveError, match=r"tcp://127\.0\.0\.1:9 refused the connection: nothing listens"):
        run_ground_filter(survey, str(tmp_path / "x.laz"), SMRF(), options=options("tcp://127.0.0.1:9"))
    assert time.perf_counter() - t0 < 30
    assert not (tmp_path / "x.laz").exists()
    with pytest.raises(GroundSieveError, match=r"nosuchhost\.invalid:8786: its host name is unknown"):
        run_ground_filter(survey, str(tmp_path / "x.laz"), SMRF(), options=options("tcp://nosuchhost.invalid:8786"))


@needs_dask
def test_a_worker_that_cannot_see_the_path_is_named(tmp_path):
    from groundsieve.core.engine.cluster import Cluster, ClusterError, check_workers
    with Cluster("local:1") as c:
        with pytest.raises(ClusterError, match=r"Dask worker tcp://.* cannot see /nowhere/survey\.laz"):
            check_workers(c.client, [str(tmp_path), "/nowhere/survey.laz"])
        assert check_workers(c.client, [str(tmp_path)]) == 1


def _lose_lazrs():
    import sys
    sys.modules["lazrs"] = None  # what a worker without lazrs sees: ``import lazrs`` fails


@needs_dask
def test_a_worker_without_the_core_dependencies_is_refused(tmp_path):
    from groundsieve.core.engine.cluster import Cluster, ClusterError, check_workers
    with Cluster("local:1") as c:
        c.client.run(_lose_lazrs)
        with pytest.raises(ClusterError, match=r"Dask worker tcp://.* lacks the Python package\(s\) lazrs "
                                               r"that GroundSieve needs; install them there"):
            check_workers(c.client, [str(tmp_path)])


@needs_dask
def test_a_worker_with_another_groundsieve_version_is_refused(tmp_path, monkeypatch):
    from groundsieve.core.engine import cluster as cl
    with cl.Cluster("local:1") as c:
        monkeypatch.setattr(cl, "package_version", lambda: "9.9.9")
        with pytest.raises(cl.ClusterError, match=r"Dask worker tcp://.* runs GroundSieve .*, this client 9\.9\.9"):
            cl.check_workers(c.client, [str(tmp_path)])


@needs_dask
def test_a_worker_with_the_same_version_but_other_code_is_refused(tmp_path, monkeypatch):
    """The version check read metadata.txt only: a worker with a changed or older copy of the same
    version passed and ran other code. The probe now compares a digest of core/'s sources."""
    import shutil
    from groundsieve.core.engine import cluster as cl
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    copy = tmp_path / "copy"
    shutil.copytree(os.path.join(repo, "core"), copy / "core", ignore=shutil.ignore_patterns("__pycache__"))
    digest = cl._core_digest()
    namespace = {}
    exec(compile(cl._PROBE_SOURCE, "probe", "exec"), namespace)
    assert namespace["core_digest"](str(copy)) == digest  # the same sources, the same digest
    with open(copy / "core" / "metrics.py", "a") as f:
        f.write("\n# changed\n")
    assert namespace["core_digest"](str(copy)) != digest
    with cl.Cluster("local:1") as c:
        assert cl.check_workers(c.client, [str(tmp_path)]) == 1
        monkeypatch.setattr(cl, "_core_digest", lambda: namespace["core_digest"](str(copy)))
        with pytest.raises(cl.ClusterError, match=r"Dask worker tcp://.* runs GroundSieve .* with other code"):
            cl.check_workers(c.client, [str(tmp_path)])


@needs_dask
def test_a_worker_that_joins_after_the_check_runs_no_job_with_other_code(monkeypatch):
    """Workers were checked once, at the start: one with other code that joined mid-run (dask-jobqueue
    adds workers over time) ran tiles, and a resumed run reused them (a reviewer). Each job now
    carries the client's code digest, and a worker whose own differs refuses it in words."""
    from groundsieve.core.engine import cluster as cl
    monkeypatch.setattr(cl, "check_workers", lambda *a, **k: 1)  # (as if the worker had joined after)
    monkeypatch.setattr(cl, "_core_digest", lambda: "the client's other code")
    got = []
    # (also the message when the groundsieve folder changed during the run: an HPC reviewer's was told
    # that the worker was the stale one, though the client was)
    with pytest.raises(cl.ClusterError, match=r"Dask worker tcp://.* with other code than this run started with "
                                              r"\(its core/ differs: a worker that joined after the workers were "
                                              r"checked, or the groundsieve folder changed during the run\)"):
        cl.run_jobs("local:1", len, [{"key": (0, 0)}, {"key": (0, 1)}], got.append, is_cancelled=lambda: False,
                    paths=[], writable=[], names=lambda job: str(job["key"]))
    assert got == []
    monkeypatch.undo()
    assert isinstance(cl.no_retry(len, "other code")({"key": (0, 0)}), cl.Failed)
    assert cl.no_retry(len, cl._core_digest())({"key": (0, 0)}) == 1  # the same code: the job runs


def test_scheduler_addresses_are_checked_without_dask():
    from groundsieve.core.engine.cluster import parse_scheduler
    assert parse_scheduler("") == ("", None)
    assert parse_scheduler("local:3") == ("local", 3)
    assert parse_scheduler("tcp://10.0.0.5:8786") == ("address", "tcp://10.0.0.5:8786")
    # host:port without a scheme, as Dask takes it (a reviewer's address was refused)
    assert parse_scheduler("10.0.0.5:8786") == ("address", "tcp://10.0.0.5:8786")
    assert parse_scheduler("node-7.cluster:8786") == ("address", "tcp://node-7.cluster:8786")
    for bad in ("local:0", "10.0.0.5", "local:x", "tcp://a b", "host:port", "a b:1"):
        with pytest.raises(InvalidParameterError):
            TileOptions(scheduler=bad)


@needs_dask
def test_cancel_stops_the_cluster_run_and_leaves_nothing(survey, tmp_path):
    from groundsieve.core.errors import Cancelled
    tiles_logged = []

    def log(line):
        if line.startswith("Tile "):
            tiles_logged.append(line)
    with pytest.raises(Cancelled):
        run_ground_filter(survey, str(tmp_path / "c.laz"), SMRF(), options=options("local:2"),
                          is_cancelled=lambda: len(tiles_logged) >= 3, log=log)
    assert 3 <= len(tiles_logged) < 60
    assert sorted(os.listdir(tmp_path)) == []  # no output, no working folder


@needs_dask
def test_a_deliberate_error_in_a_tile_fails_at_once_without_retry(survey, tmp_path):
    """A damaged tile part (its index file cut short: an InputError of read_part, the same on every
    try) stops the run with the error naming the tile's bounds and file; Dask runs it once (no
    retry, unlike a worker death), and no output is left."""
    from groundsieve.core.engine import cluster as cl
    from groundsieve.core.errors import InputError
    with cl.Cluster("local:1") as c:
        real_run_jobs = cl.run_jobs
        damaged = []

        def damage_one_tile_then_run(scheduler, function, jobs, *args, **kw):
            if "parts" not in jobs[0]:  # the binning and writing jobs (one per file)
                return real_run_jobs(scheduler, function, jobs, *args, **{**kw, "cluster": c})
            job = jobs[len(jobs) // 2]
            with open(job["parts"][0].index_path, "r+b") as f:
                f.truncate(8)
            damaged.append(job)
            return real_run_jobs(scheduler, function, jobs, *args, **{**kw, "cluster": c})
        try:
            cl.run_jobs = damage_one_tile_then_run
            with pytest.raises(InputError) as caught:
                run_ground_filter(survey, str(tmp_path / "x.laz"), SMRF(), options=options("local:1"),
                                  dtm_path=str(tmp_path / "x.tif"), dtm=DTMOptions(cell_size_m=1.0))
        finally:
            cl.run_jobs = real_run_jobs
        x0, y0, x1, y1 = damaged[0]["bounds"]
        assert f"tile {x0:.0f},{y0:.0f} - {x1:.0f},{y1:.0f} of scene.laz" in str(caught.value)
        assert "indices" in str(caught.value)
        prefix = f"groundsieve-tile-{damaged[0]['key'][0]}_{damaged[0]['key'][1]}-"

        def times_started(dask_scheduler):
            return sum(1 for t in dask_scheduler.transition_log
                       if str(t[0]).startswith(prefix) and t[2] == "processing")
        assert c.client.run_on_scheduler(times_started) == 1
    assert sorted(os.listdir(tmp_path)) == []


def _thread_limits():
    import numba
    return os.environ.get("RAYON_NUM_THREADS"), numba.get_num_threads()


@needs_dask
def test_local_cluster_workers_run_one_thread_each():
    """A worker of a LocalCluster is one core (threads_per_worker=1): numba's parallel kernels and
    lazrs's LAZ threads must not start one thread per core of the machine in every worker."""
    from groundsieve.core.engine.cluster import Cluster
    before = {k: os.environ.get(k) for k in ("NUMBA_NUM_THREADS", "RAYON_NUM_THREADS")}
    with Cluster("local:2") as cluster:
        limits = cluster.client.run(_thread_limits)
        # ...and this process (the client: the QGIS desktop, or this test run) keeps its own: numba
        # refuses to run once its thread count has changed under it
        assert {k: os.environ.get(k) for k in before} == before
    assert len(limits) == 2
    assert set(limits.values()) == {("1", 1)}


@needs_dask
def test_a_copc_input_on_the_cluster_gets_the_classes_its_tiles_wrote(tmp_path):
    """On a cluster the tiles write their classes as parts, which the write job of each file
    applies; a COPC input, read by bounds and so written by the streamed copy, got none of them
    (every point left at class 0) once the binned files moved to the pieces' write path."""
    from groundsieve.tests.core.test_copc import scene_las, write_copc
    copc = tmp_path / "scene.copc.laz"
    write_copc(copc, scene_las(make_scene(SceneSpec(size_m=120.0, density_per_m2=2.0, seed=5))))
    run_ground_filter(str(copc), str(tmp_path / "threads.laz"), SMRF(), options=options())
    run_ground_filter(str(copc), str(tmp_path / "dask.laz"), SMRF(), options=options("local:2"))
    want, got = (laspy.read(tmp_path / f"{n}.laz").classification for n in ("threads", "dask"))
    assert 0.3 < np.mean(want == 2) < 0.95
    assert np.array_equal(got, want)


def test_dask_failures_say_what_they_usually_mean():
    """A scheduler without GroundSieve on its path fails every job with 'Error during deserialization
    of the task graph' (a reviewer's first run of the README's example): the message says that the
    scheduler needs the package too; other failures get no invented hint."""
    from groundsieve.core.engine.cluster import _cause_hint
    hint = _cause_hint(RuntimeError("Error during deserialization of the task graph. This frequently occurs if "
                                    "the Scheduler and Client have different environments."))
    assert "start the Dask scheduler with GroundSieve importable too" in hint
    assert "run again once it is back" in _cause_hint(RuntimeError("... scheduler-connection-lost ..."))
    assert _cause_hint(ValueError("something else")) == ""


@needs_dask
def test_tiles_are_planned_for_the_clusters_workers_not_this_machine(tmp_path):
    """With a scheduler's address, the automatic tile size came from this machine's memory and cores
    (a reviewer's laptop planned for a cluster it knew nothing of: tiles too big for small workers,
    or too few for many): it now comes from the workers' memory limit per thread, and leaves a few
    tiles for each of the cluster's threads."""
    (tmp_path / "survey").mkdir()
    path = tmp_path / "survey" / "scene.laz"  # (a folder: a survey, run in tiles)
    write_scene(make_scene(SceneSpec(size_m=400.0, density_per_m2=2.0, seed=4)), path)
    from groundsieve.core.engine.tiles import plan_tile_size
    from groundsieve.core.io.lasfiles import scan_header
    here = plan_tile_size([scan_header(str(path))], TileOptions(workers=1), 20.0, 2.0)
    assert here >= 400.0  # this machine's plan: the whole scene in one tile
    alone = run_ground_filter(str(path), str(tmp_path / "alone.laz"), SMRF())
    import dask
    with dask.config.set({"distributed.nanny.environ": {"NUMBA_NUM_THREADS": "1"}}), \
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, memory_limit="2GiB",
                                     dashboard_address=None, silence_logs=50) as cluster:
        logs = []
        run = run_ground_filter(str(tmp_path / "survey"), str(tmp_path / "dask.laz"), SMRF(), log=logs.append,
                                options=FilterOptions(tiling=TileOptions(workers=1, parallel="threads",
                                                                         scheduler=cluster.scheduler_address)))
    said = [line for line in logs if line.startswith("Tiles planned for the Dask cluster's 2 thread(s), each "
                                                     "with 2.0 GB or more")]
    assert said, logs
    assert run.tiles >= 4  # 4 a thread wanted; the 50 m floor and the 400 m scene allow them
    assert run.point_count == len(alone.cloud)
    agree = (laspy.read(tmp_path / "dask.laz").classification == laspy.read(tmp_path / "alone.laz").classification)
    assert agree.mean() > 0.999


@needs_dask
def test_tiles_set_larger_than_the_workers_memory_are_warned_about(tmp_path, monkeypatch):
    """A tile size set by hand was never compared with the workers' memory: tiles too big for them got
    workers paused and restarted by Dask until the run failed (KilledWorker), with nothing said before
    the work. The set size is kept, and the run warns with a size that fits; a size that fits is not
    warned about."""
    from groundsieve.core.engine.cluster import Cluster
    (tmp_path / "survey").mkdir()
    write_scene(make_scene(SceneSpec(size_m=400.0, density_per_m2=2.0, seed=4)), tmp_path / "survey" / "scene.laz")
    # a worker with 40 MB a task, as the scheduler would tell of a small cluster (the real one has 2 GB)
    monkeypatch.setattr(Cluster, "memory_per_task", lambda self: (40 << 20, 2))
    import dask
    with dask.config.set({"distributed.nanny.environ": {"NUMBA_NUM_THREADS": "1"}}), \
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, memory_limit="2GiB",
                                     dashboard_address=None, silence_logs=50) as cluster:
        said = []

        def run(tile):
            said.clear()
            done = run_ground_filter(str(tmp_path / "survey"), str(tmp_path / f"t{tile:g}.laz"), SMRF(), log=said.append,
                                     options=FilterOptions(tiling=TileOptions(tile_size_m=tile,
                                                                              scheduler=cluster.scheduler_address)))
            assert done.tile_size_m == tile
            return [line for line in said if "more than half the memory a task has on the Dask cluster (40 MB" in line]
        warned = run(400.0)
        assert len(warned) == 1 and warned[0].startswith("Warning: tiles of 400 m and their buffer take about"), said
        fit = float(re.search(r"Use tiles of at most (\d+) m", warned[0]).group(1))
        assert 10 <= fit < 400
        assert not run(fit), said  # the size it gives is not warned about


def test_a_single_small_file_given_a_scheduler_runs_on_the_cluster(survey):
    """A LAS/LAZ that fits the client's memory ran whole in the client, beside the scheduler it was
    given (an HPC reviewer: 10 M points, 1.8 GB on the login node, the workers idle, no word). With
    a scheduler every file runs in tiles on the workers; without one it still runs whole."""
    from groundsieve.core.engine.tiles import needs_tiling
    lines = []
    assert needs_tiling(survey, TileOptions(scheduler="tcp://10.0.0.5:8786"), SMRF(), log=lines.append)
    assert lines == [f"{survey}: runs in buffered tiles on the Dask cluster (tcp://10.0.0.5:8786)."]
    assert not needs_tiling(survey, TileOptions(), SMRF())


def test_intermediate_rasters_with_a_scheduler_are_refused_for_the_right_reason(survey, tmp_path):
    """With a scheduler every file runs in tiles; EVC's grids were refused "beyond the memory budget
    ... set a larger memory budget", which could not help (a code reviewer)."""
    from groundsieve.core.errors import InvalidParameterError
    with pytest.raises(InvalidParameterError, match="a Dask scheduler is set, whose workers run it in tiles"):
        run_ground_filter(survey, str(tmp_path / "x.laz"), SMRF(), rasters={str(tmp_path / "r.tif"): lambda run: None},
                          options=FilterOptions(tiling=TileOptions(scheduler="tcp://10.0.0.5:8786")))
    assert not (tmp_path / "x.laz").exists()


@needs_dask
def test_the_algorithm_goes_to_each_worker_once_not_with_every_task(survey, tmp_path):
    """Every task carried the run's algorithm to the scheduler, which held them all until they ran: with
    a default rftrain forest (29.6 MB pickled) the run peaked at 6.7 GB for 144 tiles (bench/model_jobs.py). A task now
    carries a reference to its pickle in the working folder, which each worker loads once; the classes
    are those of a run in this process."""
    from groundsieve.tests.core.scenes import CountedSMRF
    unpickled = tmp_path / "unpickled.txt"
    ref = run_ground_filter(survey, str(tmp_path / "ref.laz"), CountedSMRF(unpickled), options=options())
    assert not unpickled.exists()  # (in this process: never pickled)
    run = run_ground_filter(survey, str(tmp_path / "dask.laz"), CountedSMRF(unpickled), options=options("local:2"))
    assert run.tiles == ref.tiles >= 50
    assert np.array_equal(laspy.read(tmp_path / "dask.laz").classification,
                          laspy.read(tmp_path / "ref.laz").classification)
    processes = unpickled.read_text().split()
    assert 1 <= len(processes) <= 2 and len(set(processes)) == len(processes)
