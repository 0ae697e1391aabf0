"""``python -m groundsieve``: the ground filters without QGIS (see core/engine/cli.py)."""
import os
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
    import threading
    if any(t.is_alive() and not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        # A thread the run could not stop (one stuck in a library's C code: OpenBLAS retrying an allocation
        # for ever) would hold the interpreter's shutdown, SIGTERM ignored, for ever (a code reviewer): the run
        # has said how it ended and removed its temporaries; leave now.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)
