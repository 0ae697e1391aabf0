"""A scheduler address where something else than a Dask scheduler answers (the dashboard's port, an
SSH server, a Dask worker), or with a scheme Dask cannot use, ends the run with one line naming the
address, in bounded time, with nothing written; a cancel while connecting stops it at once.

Each call runs in a thread joined with a time limit, so that a hang fails the test instead of
blocking the suite (the limits are hang guards, not speed claims)."""
from __future__ import annotations

import os
import socket
import threading
import time

import pytest

from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
from groundsieve.core.errors import Cancelled, GroundSieveError, InvalidParameterError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
from groundsieve.tests.core.test_dask import _unshadow_dask, needs_dask

GUARD_S = 60  # a hang guard: the slowest of these ends after the 10 s connection limit + 2 s

@pytest.fixture(autouse=True)
def _real_dask_in_workers():
    _unshadow_dask()


class Server:
    """A local TCP server that is not Dask: it accepts, sends ``banner`` (if any), reads what comes
    and never answers, as http.server does with Dask's binary handshake (it waits for a line)."""

    def __init__(self, banner: bytes = b""):
        self.banner = banner
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.sock.settimeout(0.2)
        self.address = "tcp://127.0.0.1:%d" % self.sock.getsockname()[1]
        self.conns = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        while not self.stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except OSError:
                continue
            self.conns.append(conn)
            if self.banner:
                conn.sendall(self.banner)

    def close(self):
        self.stop.set()
        self.thread.join(5)
        for c in self.conns + [self.sock]:
            c.close()


@pytest.fixture
def silent():
    s = Server()
    yield s
    s.close()


@pytest.fixture
def ssh():
    s = Server(b"SSH-2.0-OpenSSH_9.2p1 Debian-2+deb12u3\r\n")
    yield s
    s.close()


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    path = tmp_path_factory.mktemp("dask_connect") / "scene.laz"
    write_scene(make_scene(SceneSpec(size_m=60.0, density_per_m2=1.0, seed=5)), path)
    return str(path)


def options(scheduler):
    return FilterOptions(tiling=TileOptions(tile_size_m=20.0, buffer_m=10.0, workers=1, parallel="threads",
                                            scheduler=scheduler))


def bounded(call, limit=GUARD_S):
    """``call()``'s exception (None if it returned) and its duration; fails if it is still running
    after ``limit`` seconds."""
    out = {}

    def run():
        try:
            call()
        except BaseException as err:  # noqa: B036 - reported to the test
            out["error"] = err
    t0 = time.monotonic()
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(limit)
    if thread.is_alive():
        pytest.fail(f"still connecting after {limit} s (hangs)")
    return out.get("error"), time.monotonic() - t0


def filter_to(survey, out, scheduler, **kw):
    return lambda: run_ground_filter(survey, str(out), SMRF(), options=options(scheduler), **kw)


@needs_dask
def test_a_service_that_never_answers_is_not_a_dask_scheduler(survey, tmp_path, silent):
    err, _ = bounded(filter_to(survey, tmp_path / "x.laz", silent.address))
    assert isinstance(err, GroundSieveError), repr(err)
    assert str(err) == (f"{silent.address}: not a Dask scheduler (no Dask answer within 10 s; is this the "
                        "dashboard's port? The scheduler's is usually 8786)")
    assert "\n" not in str(err)
    assert os.listdir(tmp_path) == []  # no output, no working folder


@needs_dask
def test_a_service_that_sends_a_banner_is_not_a_dask_scheduler(survey, tmp_path, ssh):
    """Its bytes read as a Dask frame's length made an exabyte MemoryError."""
    err, _ = bounded(filter_to(survey, tmp_path / "x.laz", ssh.address))
    assert isinstance(err, GroundSieveError), repr(err)
    assert str(err).startswith(ssh.address + ": not a Dask scheduler (")
    assert "EiB" not in str(err) and "\n" not in str(err)
    assert os.listdir(tmp_path) == []


def test_an_http_address_is_refused_before_connecting(survey, tmp_path):
    err, _ = bounded(filter_to(survey, tmp_path / "x.laz", "http://127.0.0.1:8786"))
    assert isinstance(err, InvalidParameterError), repr(err)
    assert str(err).startswith("Dask scheduler address 'http://127.0.0.1:8786': http:// is a web address")
    assert os.listdir(tmp_path) == []


@needs_dask
def test_a_dask_worker_address_is_not_the_scheduler(tmp_path):
    from groundsieve.core.engine.cluster import Cluster, ClusterError
    with Cluster("local:1") as c:
        worker = next(iter(c.client.scheduler_info()["workers"]))
        err, _ = bounded(lambda: Cluster(worker).close())
    assert isinstance(err, ClusterError), repr(err)
    assert str(err) == (f"{worker}: not a Dask scheduler (a Dask Worker answers there; give the scheduler's "
                        "address, usually port 8786)")


@needs_dask
def test_a_cancel_while_connecting_stops_at_once(silent):
    from groundsieve.core.engine.cluster import Cluster
    t0 = time.monotonic()
    err, took = bounded(lambda: Cluster(silent.address, is_cancelled=lambda: time.monotonic() - t0 > 1.0))
    assert isinstance(err, Cancelled), repr(err)
    assert took < 5  # cancelled 1 s in; the connection would have waited 12 s


@needs_dask
def test_a_cancel_of_the_run_while_connecting_stops_it_at_once(survey, tmp_path, silent):
    """The run's own cancel (Processing's Cancel, the CLI's) reaches the connection: tiles.py
    connects with the run's cancel callable."""
    t0 = time.monotonic()
    err, took = bounded(filter_to(survey, tmp_path / "x.laz", silent.address,
                                  is_cancelled=lambda: time.monotonic() - t0 > 1.0))
    assert isinstance(err, Cancelled), repr(err)
    assert took < 5 and os.listdir(tmp_path) == []


@needs_dask
def test_a_cancel_while_connecting_stops_run_jobs(silent):
    """run_jobs without a cluster of the run's connects with the run's cancel callable."""
    from groundsieve.core.engine.cluster import run_jobs
    t0 = time.monotonic()
    err, took = bounded(lambda: run_jobs(silent.address, len, [], print, is_cancelled=lambda: time.monotonic() - t0 > 1,
                                         paths=[], writable=[], names=str))
    assert isinstance(err, Cancelled), repr(err)
    assert took < 5


def test_addresses_with_a_scheme_dask_cannot_use_are_refused_before_connecting(tmp_path):
    from groundsieve.core.engine.cluster import parse_scheduler
    for good in ("tcp://10.0.0.5:8786", "tls://host:8786", "ws://host:8786", "wss://host:8786", "ucx://h:1"):
        assert parse_scheduler(good) == ("address", good)
    assert parse_scheduler(" TCP://host:8786 ") == ("address", "tcp://host:8786")
    with pytest.raises(InvalidParameterError) as e:
        TileOptions(scheduler="http://127.0.0.1:8786")
    assert str(e.value) == ("Dask scheduler address 'http://127.0.0.1:8786': http:// is a web address (the "
                            "dashboard's), not the scheduler's; give tcp://host:port (e.g. tcp://10.0.0.5:8786), "
                            "local:N for N worker processes on this machine, or leave it empty (Dask accepts "
                            "tcp://, tls://, ws://, wss://, ucx://)")
    for bad in ("https://host:8787", "inproc://10.0.0.5:1", "ftp://host:21"):
        with pytest.raises(InvalidParameterError, match="Dask accepts tcp://, tls://"):
            parse_scheduler(bad)


def test_a_scheduler_lost_before_the_workers_check_is_a_cluster_error():
    """The scheduler gone between two stages of a run: the next stage's check of the workers raised
    distributed's own OSError (kind "other", with a traceback) where the other stages say the
    connection was lost (kind "cluster", which scripts retry). An HPC reviewer's run, killed
    scheduler; here a client whose calls fail as distributed's do then."""
    from groundsieve.core.engine.cluster import ClusterError, check_workers

    class Gone:
        class scheduler:
            address = "tcp://10.0.0.5:8786"

        def run(self, *args, **kw):
            raise OSError("Timed out trying to connect to tcp://10.0.0.5:8786 after 10 s")
    with pytest.raises(ClusterError, match=r"the connection to the Dask scheduler tcp://10\.0\.0\.5:8786 was lost"):
        check_workers(Gone(), ["/data"])
