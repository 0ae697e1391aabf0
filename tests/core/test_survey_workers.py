"""A survey of several files: binning into tiles and writing the classified files run one file per
job on the workers (processes or threads, engine/tiles.py ``_map_files``); the outputs are those of
the serial path (one worker), byte for byte."""
from __future__ import annotations

import hashlib
import os

import laspy
import numpy as np
import pytest

from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
from groundsieve.core.errors import InputError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
from groundsieve.tests.core.scenes import CountedSMRF, four_file_survey


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    """A 120 m scene cut into 4 files of 60 x 60 m (tiles of 30 m with a 10 m buffer cross them)."""
    return four_file_survey(str(tmp_path_factory.mktemp("survey")))


def _digest(folder):
    h = hashlib.sha256()
    for name in sorted(os.listdir(folder)):
        path = os.path.join(folder, name)
        h.update(name.encode())
        h.update(np.asarray(laspy.read(path).classification).tobytes())
    return h.hexdigest()


def _run(survey, out, workers, parallel):
    opts = FilterOptions(tiling=TileOptions(tile_size_m=30.0, buffer_m=10.0, workers=workers, parallel=parallel))
    logs = []
    run = run_ground_filter(survey, str(out / "classified.vpc"), SMRF(), options=opts,
                            dtm_path=str(out / "dtm.tif"), dtm=DTMOptions(cell_size_m=1.0), log=logs.append)
    from osgeo import gdal
    ds = gdal.Open(str(out / "dtm.tif"))
    return run, _digest(out / "classified"), ds.GetRasterBand(1).ReadAsArray().tobytes(), logs


@pytest.mark.parametrize("parallel", ["processes", "threads"])
def test_binning_and_writing_on_workers_give_the_serial_outputs(survey, tmp_path, parallel):
    (tmp_path / "serial").mkdir()
    (tmp_path / "par").mkdir()
    ref, ref_cls, ref_dtm, _ = _run(survey, tmp_path / "serial", 1, parallel)
    run, cls, dtm, logs = _run(survey, tmp_path / "par", 2, parallel)
    assert ref.tiles == run.tiles >= 16 and ref.ground_count == run.ground_count > 0
    assert cls == ref_cls and dtm == ref_dtm
    assert any(line.startswith("Wrote 4 classified file(s)") for line in logs)
    # every input point is classified once, in its own file, with the input's other fields kept
    for name in "abcd":
        a, b = laspy.read(os.path.join(survey, f"{name}.laz")), laspy.read(tmp_path / "par" / "classified" / f"{name}.laz")
        assert len(a.points) == len(b.points) and np.array_equal(a.x, b.x) and np.array_equal(a.gps_time, b.gps_time)


def test_a_damaged_file_fails_the_parallel_binning_with_its_name(survey, tmp_path):
    import shutil
    folder = tmp_path / "in"
    shutil.copytree(survey, folder)
    with open(folder / "c.laz", "r+b") as f:
        f.seek(os.path.getsize(folder / "c.laz") // 2)
        f.truncate()
    opts = FilterOptions(tiling=TileOptions(tile_size_m=30.0, buffer_m=10.0, workers=2, parallel="processes"))
    with pytest.raises(InputError, match=r"c\.laz: cannot read its points .*damaged or truncated"):
        run_ground_filter(str(folder), str(tmp_path / "out.vpc"), SMRF(), options=opts)
    assert not (tmp_path / "out.vpc").exists()


def test_a_truncated_single_file_is_named_before_the_tiles_are_planned(survey, tmp_path):
    """The planner reads a sample chunk for the density first: a LAZ cut short (its chunk table
    gone) was a raw lazrs traceback there, not a message naming the file."""
    import shutil
    cut = tmp_path / "cut.laz"
    shutil.copy(os.path.join(survey, "a.laz"), cut)
    with open(cut, "r+b") as f:
        f.truncate(os.path.getsize(cut) // 2)
    opts = FilterOptions(tiling=TileOptions(tile_size_m=30.0, buffer_m=10.0, workers=1))
    with pytest.raises(InputError, match=r"cut\.laz: cannot read its points .*damaged or truncated"):
        run_ground_filter(str(cut), str(tmp_path / "out.laz"), SMRF(), options=opts)
    assert sorted(os.listdir(tmp_path)) == ["cut.laz"]


def _jobs_given(monkeypatch, job_function) -> list:
    """The jobs the engine's ``_map_files`` is given for ``job_function`` from now on (it still runs
    them)."""
    from groundsieve.core.engine import tiles
    seen = []
    real_map = tiles._map_files

    def spy(function, jobs, *args, **kw):
        if function is job_function:
            seen.extend(jobs)
        return real_map(function, jobs, *args, **kw)
    monkeypatch.setattr(tiles, "_map_files", spy)
    return seen


def test_one_big_file_is_binned_in_pieces_on_the_workers_with_the_serial_outputs(survey, tmp_path, monkeypatch):
    """A single input binned in 2 pieces of consecutive points (one per worker process; the second
    piece starts by seeking in the LAZ) gives the serial run's classes and DTM."""
    from groundsieve.core.engine import tiles
    whole = os.path.join(os.path.dirname(survey), "whole.laz")

    def run(out, workers):
        out.mkdir()
        opts = FilterOptions(tiling=TileOptions(tile_size_m=30.0, buffer_m=10.0, workers=workers,
                                                parallel="processes"))
        done = run_ground_filter(whole, str(out / "c.laz"), SMRF(), options=opts,
                                 dtm_path=str(out / "dtm.tif"), dtm=DTMOptions(cell_size_m=1.0))
        from osgeo import gdal
        ds = gdal.Open(str(out / "dtm.tif"))  # kept: its band dies with it
        return (done.ground_count, np.asarray(laspy.read(out / "c.laz").classification).tobytes(),
                ds.GetRasterBand(1).ReadAsArray().tobytes())
    ref = run(tmp_path / "serial", 1)
    monkeypatch.setattr(tiles, "BIN_PIECE_POINTS", 5000)
    bin_jobs = _jobs_given(monkeypatch, tiles._bin_job)
    got = run(tmp_path / "pieces", 2)
    assert [j.get("piece") for j in bin_jobs] == [0, 1] and bin_jobs[1]["first"] > 0
    assert got == ref


def _thread_limits(_job=None):
    import numba
    return os.environ.get("RAYON_NUM_THREADS"), numba.get_num_threads()


def test_worker_processes_share_the_cores():
    """Each of N spawned worker processes gets cores // N threads for numba and lazrs."""
    from groundsieve.core.engine.tiles import _worker_pool
    share = max(1, (os.cpu_count() or 1) // 2)
    with _worker_pool(2, True) as pool:
        limits = [f.result() for f in [pool.submit(_thread_limits) for _ in range(4)]]
    assert set(limits) == {(str(share), share)}


def _rss_after_freeing(_job=None):
    """RSS (kB) with a 200 MB array, then after freeing it."""
    def rss():
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))
    a = np.ones(25_000_000)
    held = rss()
    del a
    return held, rss()


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads the RSS from /proc (Linux)")
def test_worker_processes_keep_the_memory_a_tile_frees_for_the_next():
    """In the engine's worker processes, a large array freed stays in the process for the next
    tile's (glibc's malloc neither unmaps it nor trims the heap: ``keep_freed_memory``); a process
    of its own without that setting gives it back at once (the comparison shows the test can
    fail)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from groundsieve.core.engine.tiles import _worker_pool
    with _worker_pool(1, True) as pool:
        held, after = pool.submit(_rss_after_freeing).result()
    assert after > held - 50_000  # (kB) the 200 MB are still the process's
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as plain:
        held, after = plain.submit(_rss_after_freeing).result()
    assert after < held - 150_000


def test_auto_runs_small_surveys_in_threads_and_big_ones_in_processes():
    """Spawning worker processes only pays on big runs (docs/BENCHMARKS.md): "auto" picks threads
    below PROCESS_MIN_POINTS, processes from there (here, in a Python interpreter that can spawn)."""
    from groundsieve.core.engine import tiles
    assert tiles._auto_parallel(tiles.PROCESS_MIN_POINTS - 1) == "threads"
    assert tiles._auto_parallel(tiles.PROCESS_MIN_POINTS) == "processes"


@pytest.mark.parametrize("evlr", [False, True], ids=["las12", "las14-evlr"])
@pytest.mark.parametrize("ext", [".laz", ".las"])
def test_the_classified_copy_in_pieces_is_the_streamed_copy_byte_for_byte(tmp_path, ext, evlr):
    """The write phase: the binning keeps the records in file order (two binning pieces here), the
    copy is written in 3 pieces on LAZ chunk boundaries (in reverse order) and put together: the
    bytes of one streamed laspy pass over the input (header, VLRs, chunks and chunk table, and the
    EVLRs of a LAS 1.4 input: the pieces' copy dropped them)."""
    from groundsieve.core.io.lasfiles import (TileGrid, assemble_classified, bin_file, laz_chunk_points, piece_cuts,
                                              write_classified_piece, write_classified_stream)
    src = str(tmp_path / "s.laz")
    write_scene(make_scene(SceneSpec(size_m=260.0, density_per_m2=2.0, seed=3)), src)
    if evlr:  # LAS 1.4 point format 6 with an EVLR of its own
        from laspy.vlrs.vlrlist import VLRList
        las = laspy.convert(laspy.read(src), point_format_id=6, file_version="1.4")
        las.evlrs = VLRList([laspy.VLR("groundsieve", 42, "a test EVLR", b"kept" * 100)])
        las.write(src)
    with laspy.open(src) as r:
        n, pf = int(r.header.point_count), r.header.point_format
    assert n > 3 * laz_chunk_points(pf) > 0
    classes = np.random.default_rng(0).integers(0, 32, n).astype(np.uint8)
    write_classified_stream(src, str(tmp_path / f"ref{ext}"), classes)
    records = str(tmp_path / "s.rec")
    bin_file(src, 0, TileGrid(100.0, 10.0), str(tmp_path), records=records, first=0, stop=n // 3, piece=0)
    bin_file(src, 0, TileGrid(100.0, 10.0), str(tmp_path), records=records, first=n // 3, stop=n, piece=1)
    cuts = piece_cuts(n, 3, laz_chunk_points(pf))
    assert len(cuts) == 4 and all(c % laz_chunk_points(pf) == 0 for c in cuts[:-1])
    pieces = [write_classified_piece(src, records, classes[a:b], a, b, str(tmp_path / f"p{i}"), compress=ext == ".laz")
              for i, (a, b) in enumerate(zip(cuts[:-1], cuts[1:]))]
    assemble_classified(src, str(tmp_path / f"got{ext}"), pieces[::-1])
    assert (tmp_path / f"got{ext}").read_bytes() == (tmp_path / f"ref{ext}").read_bytes()
    got = laspy.read(tmp_path / f"got{ext}")
    assert np.array_equal(got.classification, classes)
    if evlr:
        assert [(v.user_id, v.record_id, v.record_data) for v in got.evlrs] == [("groundsieve", 42, b"kept" * 100)]


def test_one_big_file_is_written_in_pieces_on_the_workers_with_the_serial_outputs(tmp_path, monkeypatch):
    """A single input of more than two LAZ chunks, in worker processes: its classified copy is
    compressed in 2 pieces (one per worker, cut on a LAZ chunk boundary) and put together; the
    same bytes as the serial run's one piece."""
    from groundsieve.core.engine import tiles
    src = tmp_path / "big.laz"
    write_scene(make_scene(SceneSpec(size_m=240.0, density_per_m2=2.0, seed=7)), src)

    def run(out, workers):
        out.mkdir()
        opts = FilterOptions(tiling=TileOptions(tile_size_m=60.0, buffer_m=10.0, workers=workers,
                                                parallel="processes"))
        run_ground_filter(str(src), str(out / "c.laz"), SMRF(), options=opts)
        return (out / "c.laz").read_bytes()
    ref = run(tmp_path / "serial", 1)
    monkeypatch.setattr(tiles, "WRITE_PIECE_POINTS", 5000)
    write_jobs = _jobs_given(monkeypatch, tiles._write_piece_job)
    got = run(tmp_path / "pieces", 2)
    assert [(j["first"], j["stop"] > j["first"]) for j in write_jobs][0] == (0, True) and len(write_jobs) == 2
    assert write_jobs[1]["first"] % 50_000 == 0 and write_jobs[1]["first"] > 0
    assert got == ref


def _nap_or_fail(seconds):
    """A job for the worker pool: sleeps, or fails at once when ``seconds`` is negative."""
    import time
    if seconds < 0:
        raise InputError("a tile that fails")
    time.sleep(seconds)
    return seconds


def test_a_failed_run_does_not_wait_for_the_tiles_its_workers_are_running():
    """A tile's error (a reviewer's: out of memory under ``ulimit -v``) reached the user only once
    the other worker had finished its own tile, minutes later: the run now stops its worker
    processes (``stop_workers``) and says why at once. Here the other job would sleep 10 minutes;
    without stopping the workers the pool's shutdown waits for it (the join below times out)."""
    import threading
    from groundsieve.core.engine.tiles import _record_as_completed, _worker_pool, stop_workers
    pool = _worker_pool(2, True)
    with pytest.raises(InputError, match="a tile that fails"):
        _record_as_completed(pool, _nap_or_fail, [600, -1], lambda result: None)
    stop_workers(pool)
    ended = threading.Thread(target=pool.shutdown, kwargs=dict(wait=True, cancel_futures=True), daemon=True)
    ended.start()
    ended.join(60)
    assert not ended.is_alive(), "the pool waited for the sleeping job"


def test_a_worker_process_that_dies_fails_the_run_in_words():
    """A worker process killed by the system (the OOM killer; ``ulimit -v`` in a reviewer's run)
    ended the run with concurrent.futures' BrokenProcessPool traceback: now one error that says
    what stage it was and what to change."""
    from groundsieve.core.engine.tiles import _record_as_completed, _worker_pool
    from groundsieve.core.errors import GroundSieveError
    with _worker_pool(1, True) as pool:
        with pytest.raises(GroundSieveError, match=r"worker process ended abruptly during the tiles of a\.laz "
                                                   r".*smaller memory budget or fewer workers"):
            _record_as_completed(pool, os._exit, [3], lambda result: None, stage="tiles of a.laz")


def test_the_client_sees_a_cancel_while_its_workers_run():
    """With worker processes the tiles do not see the cancel themselves: the client looked at it
    only when a tile finished (a cancelled CLI run went on for a whole tile). It now looks every
    CHECK_EVERY_S while the jobs run: the cancel is raised with the job still running."""
    import threading
    from concurrent.futures import ThreadPoolExecutor
    from groundsieve.core.engine.tiles import _record_as_completed
    from groundsieve.core.errors import Cancelled
    release, finished, calls = threading.Event(), [], []

    def job(_):
        release.wait(60)
        finished.append(True)

    def check():
        calls.append(1)
        if len(calls) >= 3:
            raise Cancelled("cancelled")
    with ThreadPoolExecutor(1) as pool:
        try:
            with pytest.raises(Cancelled):
                _record_as_completed(pool, job, [0], lambda result: None, check)
            assert not finished, "the cancel came only after the job"
        finally:
            release.set()


_SCRIPT = '''import sys
from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
from groundsieve.core.errors import GroundSieveError
from groundsieve.core.filters.smrf import SMRF
{body}
'''
_RUN = ('run_ground_filter(sys.argv[1], sys.argv[2], SMRF(), options=FilterOptions(tiling=TileOptions('
        'tile_size_m=30.0, workers=2, parallel="processes")))')


@pytest.mark.parametrize("catches", [True, False])
def test_a_script_without_a_main_guard_is_told_so_not_blamed_on_memory(survey, tmp_path, catches):
    """Spawned workers import the script that started the run: without `if __name__ == "__main__":` its
    run started again in every worker, and the run ended "a worker process ended abruptly ... lack of
    memory" (a research software engineer). The workers' imports are refused in words naming the script;
    a script that catches the refusal runs to its end, one that does not names itself in the run's error."""
    import subprocess
    import sys
    body = (f"try:\n    {_RUN}\n    print('done')\nexcept GroundSieveError as err:\n    print('refused:', err)\n"
            if catches else f"{_RUN}\nprint('done')\n")
    script = tmp_path / "noguard.py"
    script.write_text(_SCRIPT.format(body=body))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    out = subprocess.run([sys.executable, str(script), survey, str(tmp_path / "out.vpc")], capture_output=True,
                         text=True, env=env, timeout=300, cwd=tmp_path)
    said = out.stdout + out.stderr
    assert f"{script}: a GroundSieve worker process is importing this script" in said, said[-3000:]
    assert 'put the script\'s work under `if __name__ == "__main__":`' in said
    if catches:
        assert out.returncode == 0 and out.stdout.strip().splitlines()[-1] == "done", said[-3000:]
    else:
        assert out.returncode != 0
        assert f"the script that started the run, {script}, is imported again by every worker process" in said


def test_a_broken_link_in_a_survey_folder_is_refused_and_sub_folders_are_said(survey, tmp_path):
    """A delivery folder's tile that is a broken link was left out without a word (a hole in the DTM), and
    a sub-folder's files too (a format reviewer)."""
    folder = tmp_path / "links"
    folder.mkdir()
    for name in ("a.laz", "b.laz"):
        os.symlink(os.path.join(survey, name), folder / name)
    os.symlink(str(tmp_path / "nowhere.laz"), folder / "c.laz")
    with pytest.raises(InputError, match=r"links/c.laz: a link to a file that does not exist \(.*nowhere.laz\); mend"):
        run_ground_filter(str(folder), str(tmp_path / "o.vpc"), SMRF())
    os.remove(folder / "c.laz")
    (folder / "block2").mkdir()
    os.symlink(os.path.join(survey, "c.laz"), folder / "block2" / "c.laz")
    lines = []
    run = run_ground_filter(str(folder), str(tmp_path / "o.vpc"), SMRF(), log=lines.append)
    assert len(run.inputs) == 2
    assert any("links: 1 sub-folder(s) not searched (block2)" in w for w in run.warnings), run.warnings


def test_a_pool_whose_worker_dies_while_a_large_job_is_sent_fails_and_does_not_hang(tmp_path):
    """A tiled rfclassify in worker processes hung for good when its workers died (a script without a main
    guard; the system's memory killer does the same): each tile's job carries the model (the hybrid's 210 kB, a
    C2 forest's 2 MB), more than a pipe holds, and Python 3.11's breaking executor waited for the thread that was
    sending it to a reader that was gone (CPython gh-107219). The engine's pool now fails as broken, at once."""
    import subprocess
    import sys
    code = ("import os\n"
            "from concurrent.futures.process import BrokenProcessPool\n"
            "from groundsieve.core.engine.tiles import _worker_pool\n"
            "if __name__ == '__main__':\n"
            "    pool = _worker_pool(1, True)\n"
            "    pool.submit(len, b'').result()\n"  # (the worker is up)
            "    dies = pool.submit(os._exit, 1)\n"
            "    try:\n"  # (the worker may be gone before the last is submitted: then submit says so)
            "        big = [pool.submit(len, b'x' * 4_000_000) for _ in range(4)]\n"
            "    except BrokenProcessPool:\n"
            "        pass\n"
            "    try:\n"
            "        dies.result()\n"
            "    except BrokenProcessPool:\n"
            "        print('broken')\n"
            "    pool.shutdown(wait=True)\n"
            "    print('shut down')\n")
    script = tmp_path / "dies.py"
    script.write_text(code)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    try:
        out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=60,
                             cwd=tmp_path)
    except subprocess.TimeoutExpired:
        pytest.fail("the pool hung after its worker died")
    assert out.stdout.split() == ["broken", "shut", "down"], out.stdout + out.stderr[-2000:]


def test_worker_processes_receive_the_algorithm_once_each_not_with_every_tile(survey, tmp_path):
    """The run's algorithm (a model's forest: 29.6 MB pickled for a default rftrain model) is sent to
    each worker process once (core/engine/sent_once.py), where every tile job carried it and was
    unpickled with it; the classes and DTM are those of a run in this process."""
    unpickled = tmp_path / "unpickled.txt"
    outputs = {}
    for workers in (1, 2):
        out = tmp_path / f"w{workers}"
        out.mkdir()
        opts = FilterOptions(tiling=TileOptions(tile_size_m=30.0, buffer_m=10.0, workers=workers,
                                                parallel="processes"))
        run = run_ground_filter(survey, str(out / "classified.vpc"), CountedSMRF(unpickled), options=opts,
                                dtm_path=str(out / "dtm.tif"), dtm=DTMOptions(cell_size_m=1.0))
        from osgeo import gdal
        ds = gdal.Open(str(out / "dtm.tif"))  # (held: a band outliving its dataset crashes GDAL)
        outputs[workers] = (run.tiles, _digest(out / "classified"), ds.GetRasterBand(1).ReadAsArray().tobytes())
    assert outputs[1] == outputs[2] and outputs[2][0] >= 16
    processes = unpickled.read_text().split()
    assert 1 <= len(processes) <= 2 and len(set(processes)) == len(processes)
