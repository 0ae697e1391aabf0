"""Progress and cancellation as plain callables.

The core never sees a QGIS feedback object: it receives ``progress(fraction)``
with ``fraction`` in [0, 1] and ``is_cancelled() -> bool``. :class:`Steps` maps
the sub-steps of one job onto one progress range and checks cancellation
between them.
"""
from __future__ import annotations

from typing import Callable, Optional

from .errors import Cancelled

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]

#: how the core's log marks a warning (a CRS not in metres, a stale working folder, ...): the command
#: line lists them in its JSON, the Processing dialog shows them as warnings
WARNING_PREFIX = "Warning: "


def warning_of(line: str) -> Optional[str]:
    """The text of a log line that is a warning (without :data:`WARNING_PREFIX`), else None."""
    return line[len(WARNING_PREFIX):] if line.startswith(WARNING_PREFIX) else None


def collecting_warnings(log):
    """(the warnings, a log that keeps them, as :func:`warning_of` gives them, and passes every line on to
    ``log``): the run's result and the command line's JSON carry them."""
    said = []
    out = log or (lambda _msg: None)

    def collect(msg: str) -> None:
        text = warning_of(msg)
        if text is not None:
            said.append(text)
        out(msg)
    return said, collect


def _noop_progress(_fraction: float) -> None:
    return None


def _never() -> bool:
    return False


class Steps:
    """Report progress for a job within ``[start, stop]`` of the caller's range."""

    def __init__(self, progress: Optional[ProgressFn] = None,
                 is_cancelled: Optional[CancelFn] = None,
                 start: float = 0.0, stop: float = 1.0, _shown: Optional[list] = None):
        self._progress = progress or _noop_progress
        self._is_cancelled = is_cancelled or _never
        self.start = start
        self.stop = stop
        #: the highest value reported so far, shared with the children: the bar never goes back
        self._shown = _shown if _shown is not None else [0.0]

    def report(self, fraction: float) -> None:
        """Report ``fraction`` (0..1) of this job done; raise Cancelled if asked to stop. The value
        passed on never falls below one reported before by this reporter or its relatives (a
        child that restarts from its own 0 holds the bar where it is)."""
        self.check()
        fraction = min(max(fraction, 0.0), 1.0)
        value = max(self.start + (self.stop - self.start) * fraction, self._shown[0])
        self._shown[0] = value
        self._progress(value)

    def check(self) -> None:
        if self._is_cancelled():
            raise Cancelled("cancelled by the user")

    def sub(self, start: float, stop: float) -> "Steps":
        """A child reporter covering ``[start, stop]`` (fractions of this job)."""
        span = self.stop - self.start
        return Steps(self._progress, self._is_cancelled,
                     self.start + span * start, self.start + span * stop, self._shown)

    @property
    def is_cancelled(self) -> CancelFn:
        return self._is_cancelled


def _estimated_share(t: float) -> float:
    """The share of a kernel's work shown after ``t`` times its expected duration: 56 % at the
    expected time, 75 % at twice, 89 % at four times, 96 % at eight, never 100 %. The tail is
    long (a power of the time, not an exponential), so that on a machine several times slower
    than expected the bar still moves: an exponential stood still for seconds in whole percent."""
    return 1.0 - 1.0 / (1.0 + 0.5 * max(t, 0.0)) ** 2


def run_cancellable(fn, *args, steps: Optional[Steps] = None, expected_s: float = 0.0, poll_s: float = 0.05):
    """``fn(*args)`` (a numba kernel that releases the GIL) in a worker thread, while this thread
    checks cancellation every ``poll_s`` seconds: a cancel raises :class:`Cancelled` at once,
    without waiting for the kernel (which finishes in the background, its result dropped).
    With ``expected_s`` > 0 the progress moves with the time elapsed (an estimate: a kernel cannot
    tell how far it is), approaching 98 % of ``steps``, and goes to 100 % when it returns."""
    import math
    import threading
    import time
    steps = steps or Steps()
    steps.check()
    box = {}

    def work():
        try:
            box["value"] = fn(*args)
        except BaseException as err:  # handed to the caller
            box["error"] = err

    worker = threading.Thread(target=work, name="groundsieve-kernel", daemon=True)
    start = time.perf_counter()
    worker.start()
    while True:
        worker.join(poll_s)
        if not worker.is_alive():
            break
        if expected_s > 0:
            steps.report(0.98 * _estimated_share((time.perf_counter() - start) / expected_s))
        else:
            steps.check()
    if "error" in box:
        raise box["error"]
    steps.report(1.0)
    return box["value"]


#: Seconds a block of :func:`run_in_row_blocks` aims at: a cancel is seen within about this.
ROW_BLOCK_S = 0.1


def run_in_row_blocks(call, n: int, steps: Steps, *, align: int = 2048, first: int = 1 << 16) -> None:
    """``call(lo, hi)`` on consecutive blocks of the rows ``0:n`` (at least one call, ``0:0`` when
    ``n`` is 0), reporting progress and honouring cancellation between blocks. The first block has
    ``first`` rows; each next one as many as the rows per second so far do in :data:`ROW_BLOCK_S`
    (so a cancel is seen within about that on any machine and for any kernel), a multiple of
    ``align`` and of at least ``align`` per thread (each block keeps the threads busy). The rows
    must be independent of each other: the blocks then change nothing in the results."""
    import time
    import numba
    floor = align * max(1, int(numba.get_num_threads()))
    lo, rows, done_s = 0, max(first, floor), 0.0
    while True:
        hi = min(n, lo + rows)
        start = time.perf_counter()
        call(lo, hi)
        done_s += time.perf_counter() - start
        steps.report(hi / n if n else 1.0)
        if hi >= n:
            return
        lo = hi
        rows = max(floor, int(ROW_BLOCK_S * lo / max(done_s, 1e-9)) // align * align)
