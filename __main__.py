"""``python -m groundsieve``: the ground filters without QGIS (see core/engine/cli.py)."""
import sys

from .core.engine.cli import main


def _interrupt(_signum, _frame):
    raise KeyboardInterrupt  # SIGTERM (systemd, timeout, a batch scheduler) ends the run as Ctrl-C does


if __name__ == "__main__":
    import signal
    signal.signal(signal.SIGTERM, _interrupt)
    sys.exit(main())
