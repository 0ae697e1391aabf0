"""``python -m groundsieve``: the ground filters without QGIS (see core/engine/cli.py)."""
import sys

from .core.engine.cli import EXIT_BUG, FINISHED, INTERRUPT_SEEN, main


def _interrupt(_signum, _frame):
    if not FINISHED[0]:  # (a run that has ended, its JSON written or being written, is left to exit as it ends)
        INTERRUPT_SEEN[0] = True  # (raised inside lazrs's or GDAL's writer it comes back as their error)
        raise KeyboardInterrupt  # SIGTERM (systemd, timeout, a batch scheduler) ends the run as Ctrl-C does


if __name__ == "__main__":
    import signal
    signal.signal(signal.SIGTERM, _interrupt)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # (left ignored where the shell ignores it)
        signal.signal(signal.SIGINT, _interrupt)
    try:
        code = main()
    except Exception:  # not a refusal: the traceback, and an exit status of its own (a job wrapper tells it apart)
        import traceback
        traceback.print_exc()
        code = EXIT_BUG
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # the interpreter's shutdown: not killed by a late SIGTERM
    if signal.getsignal(signal.SIGINT) is _interrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # nor by a late Ctrl-C (it ended as killed, exit -2)
    sys.exit(code)
