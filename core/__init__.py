"""GroundSieve core: ground filtering of point clouds and DTMs from them, free of QGIS and Qt.

Layers, each importing only from the ones below it (tests/core/test_architecture.py checks it):

    engine/     drivers: file to file (read, select, filter, classify, write, DTM), training runs
    learn/      point features, the Random Forest, its model file and report (may use filters)
    filters/    one module per ground filter, its numba kernels beside it; no filter imports another
    raster/     GeoTIFF writing (the only place GDAL is imported)
    io/ grids/  point clouds in and out, atomic outputs | grid spec, rasterize, inpaint, morphology
    validate.py progress.py metrics.py errors.py   shared checks, progress/cancel callables,
                accuracy measures, the one exception family

``synthetic.py`` makes scenes with known truth for tests, benches and the demo (it uses io).
"""


def _numba_cache_folder() -> None:
    """Give numba a cache folder where it has none: its kernels are compiled with ``cache=True`` and
    numba refuses to compile them ("cannot cache function ...: no locator available", a traceback) when
    neither the package's folders nor the user's cache folder can be written (a root-owned install run
    by a service account, cron, QGIS Server or ``docker --user`` with an unwritable HOME: a release
    engineer). Then the cache goes to ``<temp>/groundsieve-numba-<uid>``. Nothing is changed where
    numba can cache, or where NUMBA_CACHE_DIR is set to a folder it can write. One it cannot write (a
    cache compiled into a container's image or a read-only shared install: numba can only use a cache it
    may write) is treated as none: every run failed with that traceback (a research software engineer)."""
    import os
    import sys
    import tempfile

    def writable(folder: str) -> bool:
        try:
            os.makedirs(folder, exist_ok=True)
            with tempfile.TemporaryFile(dir=folder):
                return True
        except OSError:
            return False
    if not sys.platform.startswith("linux"):
        return  # (elsewhere numba's user cache is not ~/.cache/numba, and the plugin's folder is the user's)
    if os.environ.get("NUMBA_CACHE_DIR") and writable(os.environ["NUMBA_CACHE_DIR"]):
        return
    if writable(os.path.join(os.path.dirname(os.path.abspath(__file__)), "grids", "__pycache__")):
        return
    user = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "numba")
    if writable(user):
        return
    folder = os.path.join(tempfile.gettempdir(), f"groundsieve-numba-{os.getuid() if hasattr(os, 'getuid') else 'user'}")
    try:
        os.makedirs(folder, mode=0o700, exist_ok=True)
        st = os.lstat(folder)
        # numba loads its cache as code: only a folder of this user's that no one else may write
        mine = not hasattr(os, "getuid") or (st.st_uid == os.getuid() and not st.st_mode & 0o022)
        if not (mine and os.path.isdir(folder) and not os.path.islink(folder)):
            import atexit
            import shutil
            folder = tempfile.mkdtemp(prefix="groundsieve-numba-")  # this run's own (compiled again next time)
            atexit.register(shutil.rmtree, folder, True)
    except OSError:
        return  # (numba then says why it cannot cache)
    os.environ["NUMBA_CACHE_DIR"] = folder
    if "numba" in sys.modules:  # (imported before the core: numba reads it when a kernel is compiled)
        sys.modules["numba"].config.CACHE_DIR = folder


_numba_cache_folder()
