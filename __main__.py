"""``python -m groundsieve``: the ground filters without QGIS (see core/engine/cli.py)."""
import sys

from .core.engine.cli import FINISHED, main


def _interrupt(_signum, _frame):
    if not FINISHED[0]:  # (a run that has ended, its JSON written or being written, is left to exit as it ends)
        raise KeyboardInterrupt  # SIGTERM (systemd, timeout, a batch scheduler) ends the run as Ctrl-C does


if __name__ == "__main__":
    import signal
    signal.signal(signal.SIGTERM, _interrupt)
    code = main()
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # the interpreter's shutdown: not killed by a late SIGTERM
    sys.exit(code)
