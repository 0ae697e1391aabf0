"""Output paths: checked before any work starts, and written atomically (under a temporary name in
the target folder, renamed over the target only when complete, deleted on any failure), so that
a failed or cancelled run leaves nothing half-written."""
from __future__ import annotations

import contextlib
import os
import tempfile

from ..errors import OutputError

LAS_EXTENSIONS = (".las", ".laz")


def _ext(path: str) -> str:
    return os.path.splitext(str(path))[1].lower()


def check_output_path(path: str, *, inputs=(), extensions=LAS_EXTENSIONS, what: str = "output") -> str:
    """Refuse an output path that equals an input, has the wrong extension or an absent folder."""
    path = os.fspath(path)
    ext = _ext(path)
    if ext not in extensions:
        raise OutputError(f"{path}: the {what} must end in {' or '.join(extensions)} (got '{ext or '(none)'}')")
    real = os.path.realpath(path)
    for other in inputs:
        if other and os.path.realpath(os.fspath(other)) == real:
            raise OutputError(f"{path}: the {what} must not be the input file; choose another name")
    folder = os.path.dirname(real) or "."
    if not os.path.isdir(folder):
        raise OutputError(f"{path}: the folder {folder} does not exist")
    return path


@contextlib.contextmanager
def atomic_path(path: str):
    """Yield a temporary path beside ``path`` (same extension); rename it to ``path`` on success,
    delete it on any failure."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    base = os.path.basename(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{base}.", suffix=f".part{_ext(path)}", dir=folder)
    os.close(fd)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; the output follows the umask like any file
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise
