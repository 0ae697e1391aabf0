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


def _noop_progress(_fraction: float) -> None:
    return None


def _never() -> bool:
    return False


class Steps:
    """Report progress for a job within ``[start, stop]`` of the caller's range."""

    def __init__(self, progress: Optional[ProgressFn] = None,
                 is_cancelled: Optional[CancelFn] = None,
                 start: float = 0.0, stop: float = 1.0):
        self._progress = progress or _noop_progress
        self._is_cancelled = is_cancelled or _never
        self.start = start
        self.stop = stop

    def report(self, fraction: float) -> None:
        """Report ``fraction`` (0..1) of this job done; raise Cancelled if asked to stop."""
        self.check()
        fraction = min(max(fraction, 0.0), 1.0)
        self._progress(self.start + (self.stop - self.start) * fraction)

    def check(self) -> None:
        if self._is_cancelled():
            raise Cancelled("cancelled by the user")

    def sub(self, start: float, stop: float) -> "Steps":
        """A child reporter covering ``[start, stop]`` (fractions of this job)."""
        span = self.stop - self.start
        return Steps(self._progress, self._is_cancelled,
                     self.start + span * start, self.start + span * stop)

    @property
    def is_cancelled(self) -> CancelFn:
        return self._is_cancelled
