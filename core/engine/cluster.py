"""The tiles of a survey on a Dask cluster (``TileOptions.scheduler``).

The tile engine (``tiles.py``) makes every tile a pure job (``tiles._tile_job``): same job, same
result. Here those jobs go to Dask distributed instead of a local pool:

* ``""`` (the default): not used at all; the engine runs its local processes or threads and this
  module's only import of ``distributed`` never happens (the plugin does not need it);
* ``local:N``: a ``LocalCluster`` of N worker processes, one thread each, on this machine;
* ``tcp://host:port`` (or ``tls://``, ``ws://``, ``wss://``, ``ucx://``: the schemes Dask's client
  connects with): an existing scheduler. The connection is tried in a thread the run can abandon
  (cancel, Ctrl-C) and has a time limit as a whole: distributed's own ``Client(timeout=...)`` bounds
  the TCP connection but not the handshake read that follows, so an address where another service
  listens (the dashboard's port, an SSH server) would otherwise hang for good or feed garbage to
  Dask's decoder. Such an address is refused with one line naming it.

On a cluster each job writes only its own tile's files (its classes and done marker in the
working folder) and returns its DTM block; the client applies the classes to the per-file arrays
and writes the blocks into the one GeoTIFF. A worker that dies mid-tile loses nothing shared: the
scheduler gives the tile to another worker (Dask's ``allowed-failures``), and a tile that raised an
unexpected error is retried (``retries``); the outputs are those of a run without the failure. A
deliberate error of the core (a ``GroundSieveError``: a damaged file, a bad parameter) is the same on
every try: the job returns it as a :class:`Failed` instead of raising, Dask does not retry it, and the
run stops at once with its message (which names the tile's bounds and files).

Workers must see the inputs and the working folder at the same paths as the client (a shared
file system: NFS, Lustre, GPFS, CephFS...): checked on every worker before any tile is sent, along
with the packages the core needs and the GroundSieve version.
"""
from __future__ import annotations

import asyncio
import functools
import os
import re
import socket
import threading
import time
from typing import Callable, List, Optional, Sequence, Tuple

from ..errors import Cancelled, GroundSieveError, InvalidParameterError
from ..io.provenance import PACKAGE_ROOT, package_version

PIP_HINT = 'python -m pip install "dask[distributed]"'
#: how long a scheduler address may take to answer
CONNECT_TIMEOUT_S = 10
#: the address schemes Dask's client connects with (distributed.comm's backends; not ``inproc``,
#: which reaches only a scheduler inside this same process)
SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")
#: how often a connection in progress checks the run's cancel callable
POLL_S = 0.1
NOT_DASK_HINT = "is this the dashboard's port? The scheduler's is usually 8786"
#: a tile that raised an unexpected error is tried this many times more
RETRIES = 2


class Failed:
    """A job's deliberate error, returned (not raised) so that Dask does not retry it."""

    def __init__(self, error: GroundSieveError):
        self.error = error


def no_retry(function, code: str = ""):
    """``function`` for a cluster job: its deliberate errors (a ``GroundSieveError`` raised by the core
    on purpose, i.e. not wrapping an unexpected exception) come back as :class:`Failed`. With the
    client's ``code`` (its core/ digest), a worker whose own code differs refuses the job: a worker
    that joined the cluster after the run checked its workers runs no tile with other code."""
    return _NoRetry(function, code)


def other_code(who: str, version: str, likely: str) -> str:
    """The refusal of a worker whose core/ differs from the one the run started with: ``likely`` is
    the usual cause where it is said; the groundsieve folder changed during the run is the other
    (the client's digest is taken once, when the run starts: an HPC reviewer who edited the shared
    copy mid-run was told the worker was the odd one)."""
    return (f"{who} runs GroundSieve {version} with other code than this run started with (its core/ differs: "
            f"{likely}, or the groundsieve folder changed during the run); install the same groundsieve folder "
            "on every worker (e.g. one copy on the shared file system), do not change it during a run, and run "
            "again")


class _NoRetry:
    def __init__(self, function, code: str = ""):
        self.function = function
        self.code = code

    def __call__(self, job):
        if self.code and _core_digest() != self.code:  # (this worker process's own digest, made once)
            return Failed(ClusterError(other_code(f"Dask worker {_worker_address()}", package_version(),
                                                  "a worker that joined after the workers were checked")))
        try:
            return self.function(job)
        except Cancelled:
            raise
        except GroundSieveError as err:
            cause = err.__cause__
            if cause is None or isinstance(cause, GroundSieveError):
                return Failed(err)
            raise


class ClusterError(GroundSieveError):
    """The Dask cluster cannot run the tiles (absent package, unreachable scheduler, unfit worker)."""


def parse_scheduler(text: str) -> Tuple[str, object]:
    """``""`` -> ("", None); ``local:N`` -> ("local", N); ``tcp://host:port`` -> ("address", text).

    Checked without Dask: an address whose scheme Dask's client cannot use (``http://``, the
    dashboard's) is refused here, before any connection."""
    text = (text or "").strip()
    if not text:
        return "", None
    m = re.fullmatch(r"local(?::(\d+))?", text)
    if m:
        from ..machine import usable_cpus
        n = int(m.group(1) or usable_cpus())
        if n < 1:
            raise InvalidParameterError(f"Dask scheduler {text!r}: local:N needs N >= 1 workers")
        return "local", n
    usage = ("give tcp://host:port (e.g. tcp://10.0.0.5:8786), local:N for N worker processes on this "
             "machine, or leave it empty")
    m = re.fullmatch(r"([A-Za-z][A-Za-z0-9+.-]*)://([^\s/]+(:\d+)?)/?", text)
    if m:
        scheme = m.group(1).lower()
        if scheme in SCHEMES:
            return "address", f"{scheme}://{m.group(2)}"
        accepted = ", ".join(f"{s}://" for s in SCHEMES)
        what = (f"{scheme}:// is a web address (the dashboard's), not the scheduler's"
                if scheme in ("http", "https") else f"Dask cannot connect to a {scheme}:// address")
        raise InvalidParameterError(f"Dask scheduler address {text!r}: {what}; {usage} "
                                    f"(Dask accepts {accepted})")
    m = re.fullmatch(r"([A-Za-z0-9.-]+|\[[0-9A-Fa-f:]+\]):(\d+)", text)
    if m:  # host:port, as Dask itself takes it: TCP
        return "address", f"tcp://{text}"
    raise InvalidParameterError(f"Dask scheduler address {text!r}: {usage}")


def import_distributed():
    try:
        import distributed
    except ImportError as err:
        raise ClusterError(f"A Dask scheduler was given but the Python package dask[distributed] is not installed "
                           f"here ({err}); install it with: {PIP_HINT} (on the client and on every worker)") from err
    return distributed


# The probe runs on every worker before any tile. It is pickled by value (defined outside any
# importable module), so that it runs even where GroundSieve itself does not import.
_PROBE_SOURCE = '''
def core_digest(root):
    """A digest of the Python sources of GroundSieve's core/ under ``root`` (same code, same digest)."""
    import hashlib, os
    h = hashlib.sha1()
    core = os.path.join(root, "core")
    for folder, dirs, files in os.walk(core):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(f for f in files if f.endswith(".py")):
            path = os.path.join(folder, name)
            h.update(os.path.relpath(path, core).replace(os.sep, "/").encode())
            with open(path, "rb") as f:
                h.update(f.read())
    return h.hexdigest()


def probe(paths, writable):
    import os, socket, sys
    out = dict(host=socket.gethostname(), python="%d.%d" % sys.version_info[:2], missing=[], version=None,
               import_error=None, unseen=[], unwritable=[])
    for name in ("numpy", "scipy", "laspy", "lazrs", "numba"):
        try:
            __import__(name)
        except Exception:
            out["missing"].append(name)
    try:
        import groundsieve.core.engine.tiles as tiles
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(tiles.__file__))))
        import re
        with open(os.path.join(root, "metadata.txt"), encoding="utf-8") as f:
            m = re.search(r"^version\\s*=\\s*(\\S+)", f.read(), re.M)
        out["version"] = m.group(1) if m else "unknown"
        out["code"] = core_digest(root)
    except Exception as err:
        out["import_error"] = "%s: %s" % (type(err).__name__, err)
    out["unseen"] = [p for p in paths if not os.path.exists(p)]
    out["unwritable"] = [p for p in writable if os.path.isdir(p) and not os.access(p, os.W_OK)]
    return out
'''


def _worker_address() -> str:
    try:
        from distributed import get_worker
        worker = get_worker()
        return f"{worker.address} (host {os.uname().nodename if hasattr(os, 'uname') else '?'})"
    except Exception:  # (not in a Dask worker)
        return "(unknown)"


def _probe_namespace() -> dict:
    """The probe's functions (``probe``, ``core_digest``), made from its source as the workers get it."""
    namespace = {"__name__": "groundsieve_cluster_probe"}
    exec(compile(_PROBE_SOURCE, "<groundsieve worker probe>", "exec"), namespace)
    return namespace


@functools.lru_cache(maxsize=1)
def _core_digest() -> str:
    """This process's core/ digest, by the probe's own function (once: a run asks for it at each
    stage, a worker at each job)."""
    return _probe_namespace()["core_digest"](PACKAGE_ROOT)


def _probe_function():
    return _probe_namespace()["probe"]


def check_workers(client, paths: Sequence[str], writable: Sequence[str] = ()) -> int:
    """Refuse, naming the worker, one that lacks the core's packages, runs another GroundSieve, or
    cannot see a path (input or working folder). Returns the number of workers."""
    import sys
    try:
        reports = client.run(_probe_function(), list(paths), list(writable))
    except (OSError, TimeoutError) as err:  # the scheduler gone between two stages (an HPC reviewer: kind "other")
        raise _scheduler_lost(client, err) from err
    if not reports:
        raise ClusterError(f"The Dask scheduler {client.scheduler.address} has no worker; start some "
                           "(dask worker <scheduler address>) and run again")
    mine = package_version()
    code = _core_digest()
    here = "%d.%d" % sys.version_info[:2]
    for worker, r in sorted(reports.items()):
        who = f"Dask worker {worker} (host {r['host']})"
        if r["missing"]:
            raise ClusterError(f"{who} lacks the Python package(s) {', '.join(r['missing'])} that GroundSieve "
                               "needs; install them there (pip install -r requirements.txt)")
        if r["import_error"]:
            raise ClusterError(f"{who} cannot import GroundSieve ({r['import_error']}); install the same "
                               "groundsieve folder there (e.g. on the shared file system, on its PYTHONPATH)")
        if r["version"] != mine:
            raise ClusterError(f"{who} runs GroundSieve {r['version']}, this client {mine}; every worker must "
                               "run the same version")
        if r.get("code") and r["code"] != code:
            raise ClusterError(other_code(who, mine, "a changed or older copy of the same version on that worker"))
        if r["python"] != here:
            raise ClusterError(f"{who} runs Python {r['python']}, this client {here}; use the same Python "
                               "on the client and the workers")
        if r["unseen"]:
            raise ClusterError(f"{who} cannot see {r['unseen'][0]}: the workers read the inputs and the "
                               "working folder at the same paths as this client; put them on a file system "
                               "every worker mounts at the same place (and set the working folder there)")
        if r["unwritable"]:
            raise ClusterError(f"{who} cannot write into {r['unwritable'][0]} (the working folder); the "
                               "workers write their tiles' results there")
    return len(reports)


class Cluster:
    """A client on the scheduler (and the LocalCluster it started, if any); a context manager."""

    def __init__(self, scheduler: str, log: Callable[[str], None] = lambda _m: None,
                 is_cancelled: Optional[Callable[[], bool]] = None):
        kind, value = parse_scheduler(scheduler)
        if not kind:
            raise InvalidParameterError("no Dask scheduler given")
        distributed = import_distributed()
        self.local = None
        import logging
        # While the run holds its client, Dask's client logger is quiet: a lost scheduler makes it log
        # tens of lines of tracebacks (as it tries to reconnect) that the run says in one line itself.
        self._quiet = logging.getLogger("distributed.client")
        self._level = self._quiet.level
        self._quiet.setLevel(logging.CRITICAL)
        try:
            if kind == "local":
                import dask

                from .tiles import worker_thread_environ
                _set_spawn_executable()
                # One thread per worker, as Dask itself does for OpenMP/MKL (its nanny sets
                # OMP_NUM_THREADS=1): numba's and lazrs's thread pools too. Set in each worker process
                # as it starts ("environ"), before it imports numba or starts a LAZ thread pool; not by
                # "pre-spawn-environ", which the nanny writes into this (the client's) process for good.
                environ = dict(dask.config.get("distributed.nanny.environ", {}) or {}, **worker_thread_environ(1))
                # Logs at CRITICAL only: a worker's failure reaches the client through its task (the
                # error, or KilledWorker); what else the workers log at ERROR is the heartbeat of a
                # worker outliving its scheduler at close, a traceback that means nothing to the user.
                with dask.config.set({"distributed.nanny.environ": environ}):
                    self.local = distributed.LocalCluster(n_workers=value, threads_per_worker=1, processes=True,
                                                          dashboard_address=None, silence_logs=50)
                self.client = distributed.Client(self.local, timeout=f"{CONNECT_TIMEOUT_S}s")
                log(f"Started a local Dask cluster of {value} worker process(es).")
            else:
                self.client = _connect(distributed, value, is_cancelled or (lambda: False))
                log(f"Connected to the Dask scheduler {value}.")
        except (OSError, TimeoutError) as err:
            self.close()
            raise _unreachable(scheduler, err) from err
        except BaseException:
            self.close()
            raise

    def memory_per_task(self) -> Tuple[Optional[int], int]:
        """The memory a task may have on the cluster (bytes: the smallest worker memory limit over its
        threads, a worker running that many tasks at once; None when no worker states a limit, or
        none is connected yet) and the cluster's number of threads."""
        try:
            try:  # every worker: some distributed versions (2025.4 to mid-2026) list 5 by default
                info = self.client.scheduler_info(n_workers=-1)
            except TypeError:  # (older ones take no argument and list them all)
                info = self.client.scheduler_info()
            workers = list(info.get("workers", {}).values())
        except Exception:  # (a reply without workers: planned as without a cluster)
            return None, 0
        threads = sum(max(1, int(w.get("nthreads") or 1)) for w in workers)
        shares = [int(w.get("memory_limit") or 0) // max(1, int(w.get("nthreads") or 1)) for w in workers]
        shares = [share for share in shares if share > 0]
        return (min(shares) if shares else None), threads

    def close(self):
        """Close the client (and the LocalCluster); again is a no-op."""
        client, local = getattr(self, "client", None), getattr(self, "local", None)
        self.client = self.local = None
        try:
            if client is not None:
                client.close()
            if local is not None:
                local.close()
        finally:
            if getattr(self, "_quiet", None) is not None:
                self._quiet.setLevel(self._level)
                self._quiet = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _unreachable(address: str, err: BaseException) -> ClusterError:
    """The error of a scheduler that cannot be reached: what the cause chain says when it is a
    refused connection or an unknown host (both were told as "did not answer within 10 s", after
    waiting those 10 s: an HPC reviewer), else the time limit."""
    seen, cause = set(), err
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if isinstance(cause, ConnectionRefusedError):
            return ClusterError(f"The Dask scheduler {address} refused the connection: nothing listens on that port "
                                "(is `dask scheduler` running there, on this port?)")
        if isinstance(cause, socket.gaierror):
            return ClusterError(f"The Dask scheduler {address}: its host name is unknown ({cause}); check the address")
        cause = cause.__cause__ or cause.__context__
    return ClusterError(f"The Dask scheduler {address} did not answer within {CONNECT_TIMEOUT_S} s "
                        f"({type(err).__name__}: {err}); check the address and that `dask scheduler` "
                        "runs there and its port is open")


def _not_dask(address: str, why: str) -> ClusterError:
    return ClusterError(f"{address}: not a Dask scheduler ({why}; {NOT_DASK_HINT})")


def _connect(distributed, address: str, is_cancelled: Callable[[], bool]):
    """A ``distributed.Client`` on the scheduler at ``address``, or a one-line :class:`ClusterError`.

    First a probe under our own time limit: distributed's connection and handshake, then the
    ``identity`` call, which a scheduler answers with its type. ``Client(timeout=...)`` alone bounds
    the TCP connection only: a service that accepts and never answers (http.server, the dashboard)
    left it waiting for the handshake for good, and one that sends a banner (SSH) had its bytes
    decoded as a frame length (a MemoryError of exabytes). Then the client itself. Both run in a
    daemon thread that this one polls every ``POLL_S``: a cancel or Ctrl-C abandons it at once (the
    probe is cancelled; a client that connects after that is closed by its thread)."""
    state = {"loop": None, "task": None, "abandoned": False, "client": None, "error": None, "stage": "probe"}
    lock = threading.Lock()
    done = threading.Event()

    def attempt():
        try:
            _refused_or_unknown(distributed, address)
            loop = asyncio.new_event_loop()
            try:
                with lock:
                    if state["abandoned"]:
                        return
                    task = loop.create_task(asyncio.wait_for(_probe(distributed, address),
                                                             CONNECT_TIMEOUT_S + 2))
                    state["loop"], state["task"] = loop, task
                loop.run_until_complete(task)
            finally:
                with lock:
                    state["loop"] = None
                _close_loop(loop)
            with lock:
                if state["abandoned"]:
                    return
                state["stage"] = "client"
            client = distributed.Client(address, timeout=f"{CONNECT_TIMEOUT_S}s")
            with lock:
                abandoned = state["abandoned"]
                if not abandoned:
                    state["client"] = client
            if abandoned:
                client.close()
        except BaseException as err:  # reported by the polling thread (or dropped if abandoned)
            state["error"] = err
        finally:
            done.set()

    def abandon():
        with lock:
            state["abandoned"] = True
            loop, task = state["loop"], state["task"]
            if loop is not None:
                try:
                    loop.call_soon_threadsafe(task.cancel)
                except RuntimeError:  # the loop closed meanwhile
                    pass

    thread = threading.Thread(target=attempt, name=f"groundsieve-dask-connect {address}", daemon=True)
    # a whole-attempt limit besides the probe's own: the client's handshake after a probe that
    # succeeded, bounded by the client's timeout but for its handshake read
    start = time.monotonic()
    deadline = start + 3 * CONNECT_TIMEOUT_S + 5
    thread.start()
    try:
        while not done.wait(POLL_S):
            if is_cancelled():
                raise Cancelled("cancelled by the user")
            if time.monotonic() > deadline:
                if state["stage"] == "client":  # a scheduler answered the probe; its client stalls
                    raise ClusterError(f"{address}: the Dask scheduler answered but its client could not "
                                       f"connect within {deadline - start:.0f} s; check the scheduler's log")
                raise _not_dask(address, f"no Dask answer within {CONNECT_TIMEOUT_S} s")
    except BaseException:
        abandon()
        raise
    err = state["error"]
    if err is None:
        return state["client"]
    if isinstance(err, GroundSieveError):
        raise err
    if state["stage"] == "client":  # the probe's handshake went well: a Dask scheduler answers
        if isinstance(err, (OSError, TimeoutError)):
            raise _unreachable(address, err) from err
        raise ClusterError(f"{address}: the Dask scheduler answered but its client could not connect "
                           f"({type(err).__name__}: {err})") from err
    if isinstance(err, (asyncio.TimeoutError, TimeoutError)):
        raise _not_dask(address, f"no Dask answer within {CONNECT_TIMEOUT_S} s") from err
    comm_closed = getattr(getattr(distributed, "comm", None), "CommClosedError", ())
    if type(err) is OSError or isinstance(err, _AT_ONCE):  # distributed's connect: no TCP connection within
        # the time limit; or what _refused_or_unknown found at once
        raise _unreachable(address, err) from err
    if isinstance(err, comm_closed):
        if "ssl" in str(err).lower() or "tls" in str(err).lower():
            raise ClusterError(f"{address}: cannot connect to the Dask scheduler ({err})") from err
        raise _not_dask(address, "it closed the connection without a Dask answer") from err
    # MemoryError, ValueError, msgpack's errors...: Dask's decoder fed with another protocol's bytes
    raise _not_dask(address, "what answers there does not speak Dask's protocol") from err


_AT_ONCE = (ConnectionRefusedError, socket.gaierror)


def _refused_or_unknown(distributed, address: str) -> None:
    """Raise at once (ConnectionRefusedError, socket.gaierror) for a TCP address whose host is unknown
    or whose port refuses the connection: distributed's connect retries both until its 10 s limit,
    then says it timed out (an HPC reviewer). A connection that is neither made nor refused within a
    second is left to the probe."""
    try:
        scheme, location = distributed.comm.parse_address(address)
        host, port = distributed.comm.parse_host_port(location)
    except Exception:  # (an address form this does not know: the probe says what is wrong)
        return
    if scheme not in ("tcp", "tls") or not host or not port:
        return
    socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    try:
        with socket.create_connection((host, port), timeout=1.0):
            pass
    except ConnectionRefusedError:
        raise
    except OSError:  # a time-out, no route...: the probe's own limit decides
        return


async def _probe(distributed, address: str) -> None:
    """Dask's connection handshake with ``address`` and its ``identity``: a Dask scheduler's, or a
    :class:`ClusterError` naming what answered."""
    from distributed.comm import connect
    comm = await connect(address, timeout=CONNECT_TIMEOUT_S, **_connection_args(distributed, address))
    try:
        await comm.write({"op": "identity", "reply": True})
        reply = await comm.read()
    finally:
        comm.abort()
    kind = reply.get("type") if isinstance(reply, dict) else None
    if kind != "Scheduler":
        what = f"a Dask {kind} answers there" if isinstance(kind, str) else "its answer is not a scheduler's"
        raise ClusterError(f"{address}: not a Dask scheduler ({what}; give the scheduler's address, "
                           "usually port 8786)")


def _connection_args(distributed, address: str) -> dict:
    """The client's connection arguments (TLS certificates from Dask's configuration), as the
    ``Client`` computes them."""
    try:
        from distributed.client import _maybe_call_security_loader
        security = _maybe_call_security_loader(address)
    except ImportError:
        security = None
    return (security or distributed.Security()).get_connection_args("client")


def _close_loop(loop) -> None:
    try:
        pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
        for t in pending:
            t.cancel()
        if pending:
            loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
    finally:
        loop.close()


def _set_spawn_executable():
    """Embedded in qgis_process, the worker processes must be spawned with this installation's
    Python, not qgis_process (tiles._python_executable)."""
    import multiprocessing
    import sys
    from .tiles import _python_executable
    exe = _python_executable()
    if exe and os.path.realpath(exe) != os.path.realpath(sys.executable or ""):
        multiprocessing.set_executable(exe)


def _scheduler_lost(client, err: BaseException) -> ClusterError:
    return ClusterError(f"the connection to the Dask scheduler {client.scheduler.address} was lost "
                        f"({type(err).__name__}); the tiles done so far are kept in the working folder: run again "
                        "once the scheduler is back to resume")


def _cause_hint(err: BaseException) -> str:
    """What a Dask failure usually means, when its words say (appended to the message)."""
    text = str(err)
    if "deserialization of the task graph" in text or "No module named 'groundsieve'" in text:
        return (". The scheduler (not only the workers) unpickles the jobs: start the Dask scheduler with "
                "GroundSieve importable too, e.g. with the same PYTHONPATH as the workers")
    if "scheduler-connection-lost" in text:
        return ". The connection to the scheduler was lost: run again once it is back to resume"
    return ""


def run_jobs(scheduler: str, function, jobs: List[dict], record: Callable[[object], None], *,
             is_cancelled: Callable[[], bool], paths: Sequence[str], writable: Sequence[str],
             names: Callable[[dict], str], log: Callable[[str], None] = lambda _m: None,
             cluster: Optional[Cluster] = None) -> None:
    """Run ``function(job)`` for every job on the cluster and ``record`` each result as it comes
    (in completion order). Cancellation cancels the futures not yet done."""
    own = cluster is None
    cluster = cluster or Cluster(scheduler, log, is_cancelled)
    try:
        distributed = import_distributed()
        client = cluster.client
        n = check_workers(client, paths, writable)
        log(f"{len(jobs)} job(s) on the Dask cluster's {n} worker(s) ({client.scheduler.address}).")
        code = _core_digest()  # (a worker joining later checks it before each job)
        futures = {}
        for job in jobs:
            fut = client.submit(no_retry(function, code), job, retries=RETRIES, pure=False,
                                key=f"groundsieve-tile-{job['key'][0]}_{job['key'][1]}-{os.urandom(4).hex()}")
            futures[fut] = job
        pending = set(futures)
        try:
            while pending:
                if is_cancelled():
                    raise Cancelled("cancelled by the user")
                try:
                    done = distributed.wait(pending, timeout=0.5, return_when="FIRST_COMPLETED").done
                except (TimeoutError, distributed.TimeoutError):
                    continue
                except Exception as err:  # the scheduler gone: its futures are cancelled
                    raise _scheduler_lost(client, err) from err
                for fut in done:
                    pending.discard(fut)
                    job = futures.pop(fut)  # let the result go once recorded (Dask frees it on the worker)
                    try:
                        result = fut.result()
                    except GroundSieveError:
                        raise
                    except distributed.KilledWorker as err:
                        raise ClusterError(f"{names(job)}: the Dask workers running it died "
                                           f"repeatedly ({err}); too little memory per worker?") from err
                    except (distributed.comm.CommClosedError, OSError) as err:
                        raise _scheduler_lost(client, err) from err
                    except Exception as err:
                        raise ClusterError(f"{names(job)} failed on the Dask cluster: "
                                           f"{type(err).__name__}: {err}{_cause_hint(err)}") from err
                    del fut
                    if isinstance(result, Failed):
                        raise result.error
                    record(result)
                    del result
        except BaseException:
            client.cancel(list(pending))
            raise
    finally:
        if own:
            cluster.close()
