"""Output paths: checked before any work starts, and written atomically (under a temporary name in
the target folder, renamed over the target only when complete, deleted on any failure), so that
a failed or cancelled run leaves nothing half-written.

The temporary of an output ``NAME.EXT`` is the hidden file ``.NAME.EXT.gs<host>.<pid>-<random>.partEXT``
beside it (``<host>`` and ``<pid>``: the writing machine and process; NAME.EXT cut to 100 bytes). A run
that is killed cannot delete it; the next run writing the same output removes every such temporary of
this machine whose process is no longer running (and any of another machine or an unknown writer older
than a day)."""
from __future__ import annotations

import contextlib
import errno
import glob
import os
import re
import tempfile
import time

from ..errors import OutputError

LAS_EXTENSIONS = (".las", ".laz")


def _ext(path: str) -> str:
    return os.path.splitext(str(path))[1].lower()


#: a temporary's name holds at most this many bytes of its output's name (a 204-byte output name made
#: a temporary past the file system's 255: a reviewer's run failed after the work)
TEMP_NAME_BYTES = 100


def _short(base: str) -> str:
    """``base`` cut to at most TEMP_NAME_BYTES bytes of UTF-8 (whole characters)."""
    raw = base.encode("utf-8", "surrogateescape")
    if len(raw) <= TEMP_NAME_BYTES:
        return base
    import hashlib  # (two names sharing their first bytes must not share temporaries: a code reviewer)
    return raw[:TEMP_NAME_BYTES - 9].decode("utf-8", "ignore") + "~" + hashlib.sha1(raw).hexdigest()[:8]


def _host() -> str:
    """This machine's name as a temporary's name holds it: on a shared drive a process id means
    nothing on another machine (a reviewer's run removed a live temporary of a writer elsewhere)."""
    import socket
    return re.sub(r"[^A-Za-z0-9-]", "", socket.gethostname())[:24] or "host"


def _temp_prefix(path: str) -> str:
    """What this process's temporaries of the output ``path`` start with (the module's naming):
    ``.NAME.EXT.gs<host>.<pid>-``."""
    return f".{_short(os.path.basename(path))}.gs{_host()}.{os.getpid()}-"


def _keep_name(path: str) -> str:
    """A free name for the previous output kept while a commit puts the new one in place (the
    temporaries' naming with ``.keepEXT``), not created: os.link and os.replace make it."""
    import secrets
    folder = os.path.dirname(os.path.abspath(path)) or "."
    while True:
        name = os.path.join(folder, f"{_temp_prefix(path)}{secrets.token_hex(4)}.keep{_ext(path)}")
        if not os.path.lexists(name):
            return name


def _follow_umask(path: str, umask: int) -> None:
    """Give a temporary (mkstemp makes 0600) the mode a new file gets; best effort: a FUSE FAT drive
    has no chmod, and every output there was refused ("Function not implemented": a code reviewer)."""
    with contextlib.suppress(OSError):
        os.chmod(path, 0o666 & ~umask)


def _temp_beside(path: str):
    """A new temporary for the output ``path`` (see the module's naming): (fd, its path)."""
    return tempfile.mkstemp(prefix=_temp_prefix(path), suffix=f".part{_ext(path)}",
                            dir=os.path.dirname(os.path.abspath(path)) or ".")


def temporary_folder_beside(path: str) -> str:
    """A new hidden folder beside the output ``path`` (the module's naming, ending in ``.sink``) for a writer
    that creates the file itself under its final name there (QGIS's feature sinks: a GeoPackage's layer is
    named after its file, and a temporary name gave it an empty one), with its sidecars (a shapefile's
    .shx, .dbf, .prj); its files are moved into place when complete. :func:`remove_stale_sink_folders`
    removes one a killed run left."""
    return tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".sink", dir=os.path.dirname(os.path.abspath(path)) or ".")


def remove_stale_sink_folders(path: str, *, max_age_s: float = 86400.0) -> list:
    """Delete the folders of :func:`temporary_folder_beside` a killed run left for the output ``path``: those of
    a process of this machine no longer running, and those of another machine older than ``max_age_s``."""
    import shutil
    pattern, named = _temporaries_named(os.fspath(path), ".sink", start="gs")
    removed = []
    for holder in glob.glob(pattern):
        try:
            stale = _left_by_the_dead(named.match(os.path.basename(holder)), os.path.getmtime(holder), max_age_s)
            if stale and os.path.isdir(holder):
                shutil.rmtree(holder)
                removed.append(holder)
        except OSError:
            continue
    return removed


def identities(paths) -> set:
    """Keys telling the files or folders ``paths`` apart by any path to them: each one's real path and,
    where it exists, its (device, inode), so that two paths share a key when they name one file or
    folder (one share mounted at two places, a bind mount, autofs's /net beside /mnt: a reviewer's
    input was replaced by its own classified copy through a second path to its folder). One stat a
    path, for a survey's thousands of files."""
    keys = set()
    for p in paths:
        p = os.fspath(p)
        keys.add(os.path.realpath(p))
        with contextlib.suppress(OSError):
            st = os.stat(p)
            keys.add((st.st_dev, st.st_ino))
    return keys


def check_output_path(path: str, *, inputs=(), extensions=LAS_EXTENSIONS, what: str = "output") -> str:
    """Refuse an output path that is an input (by any path to it), an existing folder, has the wrong
    extension or an absent folder."""
    path = os.fspath(path)
    ext = _ext(path)
    if ext not in extensions:
        raise OutputError(f"{path}: the {what} must end in {' or '.join(extensions)} (got '{ext or '(none)'}')")
    check_not_copc_name(path, what)
    real = os.path.realpath(path)
    if identities([path]) & identities([o for o in inputs if o]):
        raise OutputError(f"{path}: the {what} must not be the input file; choose another name")
    check_existing_target(path, what)
    folder = os.path.dirname(real) or "."
    if not os.path.isdir(folder):
        raise OutputError(f"{path}: the folder {folder} does not exist")
    if os.name == "nt":  # NTFS counts UTF-16 units, 255 at most (and Windows has no pathconf)
        size, most, unit = len(os.path.basename(path).encode("utf-16-le")) // 2, 255, "characters"
    else:
        size, unit = len(os.path.basename(path).encode("utf-8", "surrogateescape")), "bytes"
        try:
            most = os.pathconf(folder, "PC_NAME_MAX")
        except (OSError, ValueError, AttributeError):
            most = 255
    if size > most:
        raise OutputError(f"{path}: the file name is too long ({size} {unit}; this folder's file system takes at most "
                          f"{most}); choose a shorter name")
    check_folder_writable(path, folder)
    return path


def check_existing_target(path: str, what: str = "output") -> None:
    """Refuse an output that is an existing folder (found only when its rename failed, after the work:
    a reviewer) or an existing read-only file (a rename replaced it and made it writable; PDAL, GDAL
    and cp refuse it)."""
    if os.path.isdir(path):
        raise OutputError(f"{path}: is a folder; the {what} must be a file name")
    if os.path.isfile(path) and not os.stat(path).st_mode & 0o222:
        raise OutputError(f"{path}: the file there is read-only; make it writable or choose another name")


def check_not_copc_name(path: str, what: str = "output") -> None:
    """Refuse a classified copy named .copc.laz: it is a plain LAZ, not COPC (its chunks are not an
    octree's nodes), and QGIS and other readers open such a name as COPC, which fails."""
    if path.lower().endswith(".copc.laz"):
        raise OutputError(f"{path}: the {what} is a plain LAZ, not COPC (its chunks are not an octree's nodes), and "
                          "QGIS and other readers open a name ending in .copc.laz as COPC, which fails: name it .laz")


def check_folder_writable(path: str, folder: str) -> None:
    """Refuse ``path`` when its folder cannot take a new file (read-only folder or file system, no
    permission), found by creating and deleting a probe named as a temporary (so that a run killed
    in between leaves a file the next run removes): permissions alone do not tell (an
    administrator ignores them; a read-only mount does not show in them)."""
    try:
        fd, probe = _temp_beside(os.path.join(folder, os.path.basename(path)))
    except OSError as err:
        raise OutputError(f"{path}: the folder {folder} cannot be written to ({_reason(err)}); "
                          "choose a folder where you may create files") from err
    os.close(fd)
    with contextlib.suppress(OSError):
        os.remove(probe)


def _reason(err: OSError) -> str:
    """An OSError in the user's words: its message without the path (the caller names the file)."""
    return err.strerror or str(err)


def check_classes_fit(path: str, point_format_id: int, classification) -> None:
    """Refuse classes the output's point format cannot store (formats 0-5 keep 5 bits: 0-31)."""
    if point_format_id < 6 and len(classification) and int(classification.max()) > 31:
        raise OutputError(f"{path}: point format {point_format_id} stores classes 0-31 only")


def check_distinct_outputs(outputs) -> None:
    """Refuse two outputs on one file (the last write would win): ``outputs`` is
    ``{label: path}`` or ``[(label, path), ...]``, labels as the dialog names the outputs."""
    seen = {}
    items = outputs.items() if isinstance(outputs, dict) else outputs
    for label, path in items:
        if not path:
            continue
        real = os.path.realpath(os.fspath(path))
        if real in seen:
            raise OutputError(f"{path}: chosen for two outputs ({seen[real]} and {label}); "
                              "give each output a file of its own")
        seen[real] = label


def _process_alive(pid: int) -> bool:
    if os.name == "nt":  # os.kill(pid, 0) sends Ctrl-C there (signal 0 is CTRL_C_EVENT: a code reviewer)
        return _windows_process_alive(pid)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists (another user's) or cannot tell: keep its file
    return True


def _windows_process_alive(pid: int) -> bool:
    """Whether process ``pid`` runs, asked of Windows (OpenProcess, GetExitCodeProcess); True when it
    cannot tell (its file is then kept)."""
    import ctypes
    from ctypes import wintypes
    kernel32 = ctypes.WinDLL("kernel32", use_last_error=True)  # type: ignore[attr-defined]
    kernel32.OpenProcess.argtypes = (wintypes.DWORD, wintypes.BOOL, wintypes.DWORD)
    kernel32.OpenProcess.restype = wintypes.HANDLE
    kernel32.GetExitCodeProcess.argtypes = (wintypes.HANDLE, ctypes.POINTER(wintypes.DWORD))
    kernel32.CloseHandle.argtypes = (wintypes.HANDLE,)
    handle = kernel32.OpenProcess(0x1000, False, pid)  # PROCESS_QUERY_LIMITED_INFORMATION
    if not handle:
        return ctypes.get_last_error() == 5  # access denied: another user's, running
    try:
        code = wintypes.DWORD()
        if not kernel32.GetExitCodeProcess(handle, ctypes.byref(code)):
            return True
        return code.value == 259  # STILL_ACTIVE
    finally:
        kernel32.CloseHandle(handle)


def _temporaries_named(path: str, ending: str, start: str = ""):
    """The glob (of ``.NAME.<start>*<ending>``) and the pattern of the temporaries of the output ``path`` ending
    in ``ending`` (the module's naming, ``.NAME.gs…<ending>``): ".NAME.gs<host>.<pid>-...", this machine's
    writers by their process, another machine's by age only; ".NAME.gs<pid>-..." (before the host was named)
    as this machine's."""
    folder = os.path.dirname(os.path.abspath(path))
    base = _short(os.path.basename(path))
    return (os.path.join(glob.escape(folder), glob.escape(f".{base}.{start}") + "*" + glob.escape(ending)),
            re.compile(re.escape(f".{base}.gs") + r"(?:([A-Za-z0-9-]*)\.)?(\d+)-[^/]*" + re.escape(ending) + "$"))


def _left_by_the_dead(match, since: float, max_age_s: float) -> bool:
    """Whether a temporary whose name gave ``match`` (:func:`_temporaries_named`; None: not named so) was left
    by a writer gone: a process of this machine no longer running, else one unknown whose temporary dates
    from ``since`` (a time stamp) more than ``max_age_s`` ago."""
    if match and match.group(1) in (None, _host()):
        return int(match.group(2)) != os.getpid() and not _process_alive(int(match.group(2)))
    return time.time() - since > max_age_s


def remove_stale_temporaries(path: str, *, max_age_s: float = 86400.0) -> list:
    """Delete the temporaries a killed run left for the output ``path`` (see the module's naming):
    those of a process no longer running, and those of an unknown writer older than ``max_age_s``.
    Returns the paths removed."""
    path = os.fspath(path)
    ext = _ext(path)
    (pattern, own), (keep, kept) = _temporaries_named(path, f".part{ext}"), _temporaries_named(path, f".keep{ext}")
    removed = []
    # (GDAL's COG writer keeps the overviews in "<its output>.ovr.tmp" until it ends: a DTM killed
    # while being written left one beside its temporary)
    for tmp in glob.glob(pattern) + glob.glob(pattern + ".ovr.tmp") + glob.glob(keep):
        previous = tmp.endswith(f".keep{ext}")
        name = os.path.basename(tmp[:-len(".ovr.tmp")] if tmp.endswith(".ovr.tmp") else tmp)
        m = (kept if previous else own).match(name)
        try:
            # (a kept file has its output's old mtime; its ctime is when it was kept)
            stale = _left_by_the_dead(m, os.stat(tmp).st_ctime if previous else os.path.getmtime(tmp), max_age_s)
            if stale and os.path.isfile(tmp):
                if previous and not os.path.lexists(path):
                    os.replace(tmp, path)  # a commit killed while the output was moved aside: put it back
                else:
                    os.remove(tmp)
                removed.append(tmp)
        except OSError:
            continue
    return removed


def _undo(pending, done) -> list:
    """Put back what a failed or interrupted commit had changed: the output whose rename was under way
    (``pending``: temporary, output, kept previous file) and those renamed (``done``: output, kept file),
    in reverse. A second interrupt meanwhile (Ctrl-C twice, a scheduler's repeated SIGTERM) is let wait
    until it is done: a half-undone commit left a mixed set (a code reviewer). Returns the files that
    could not be put back."""
    steps = []
    if pending is not None:
        tmp, put, backup = pending
        if not os.path.lexists(tmp):  # renamed already: undone as the others
            done = list(done) + [(put, backup)]
        elif backup is not None:
            steps.append(("settle", put, backup))
    steps += [("restore", put, backup) for put, backup in reversed(done)]
    unrestored, interrupted = [], None
    while steps:
        kind, put, backup = steps[0]
        try:
            if kind == "settle":  # its rename never happened: the output is the previous one, or moved aside
                if os.path.lexists(put):
                    with contextlib.suppress(OSError):
                        os.remove(backup)
                else:
                    os.replace(backup, put)
            elif backup is not None:
                if os.path.lexists(backup) or not os.path.lexists(put):  # (done already, if interrupted after)
                    os.replace(backup, put)
            else:
                with contextlib.suppress(FileNotFoundError):
                    os.remove(put)
        except OSError:
            unrestored.append(backup or put)
        except BaseException as err:  # noqa: BLE001 - the step is done again (each is idempotent)
            interrupted = interrupted or err
            continue
        steps.pop(0)
    if interrupted is not None and not isinstance(interrupted, KeyboardInterrupt):
        raise interrupted
    return unrestored


class StagedOutputs:
    """Several outputs put in place together: each is written under the temporary name
    :func:`atomic_path` would give it (``.NAME.EXT.gs<host>.<pid>-<random>.partEXT``, beside it), and
    :meth:`commit` renames them all once every one is complete; :meth:`discard` (or leaving the
    ``with`` block on an error) deletes them. A survey's classified files, its .vpc and its DTM
    therefore appear together or not at all, and a failed run leaves the previous set untouched.
    A killed run's temporaries are removed by the next run writing the same outputs."""

    def __init__(self):
        self._pairs = []

    def stage(self, path: str) -> str:
        """The temporary name ``path`` is written under (created empty, so that it is reserved)."""
        path = os.fspath(path)
        remove_stale_temporaries(path)
        try:
            fd, tmp = _temp_beside(path)
        except OSError as err:
            raise OutputError(f"{path}: cannot be written ({_reason(err)})") from err
        os.close(fd)
        self._pairs.append((tmp, path))
        return tmp

    def commit(self) -> None:
        """Rename every staged file to its output name, in the order staged, all or none: each output
        already there is kept first (a hard link beside it, so that its name is never missing; moved
        aside where the file system has no links) and put back, and the outputs renamed so far
        removed, if any rename fails or the run is interrupted meanwhile (a reviewer's immutable
        classified file, as one open in another program on Windows: the new DTM was in place beside
        the old cloud). A kept file a killed commit left is put back by the next run when its output
        is missing (remove_stale_temporaries)."""
        umask = os.umask(0)
        os.umask(umask)
        done = []  # (output, its previous file kept, or None)
        pending = None  # (temporary, output, its previous file kept) while its rename is under way
        path = ""
        try:
            for tmp, path in self._pairs:
                _follow_umask(tmp, umask)
                if os.path.isdir(path):  # (refused before the work; a folder made there meanwhile stays)
                    raise IsADirectoryError(errno.EISDIR, "Is a directory", path)
                pending = (tmp, path, None)
                if os.path.lexists(path):
                    backup = _keep_name(path)  # (named, not created: nothing to remove if interrupted here)
                    pending = (tmp, path, backup)
                    try:
                        os.link(path, backup, follow_symlinks=False)
                    except (OSError, NotImplementedError):  # (no hard links here: FAT, some shares)
                        os.replace(path, backup)
                os.replace(tmp, path)
                done.append(pending[1:])
                pending = None
        except BaseException as err:
            unrestored = _undo(pending, done)
            self.discard()
            if not isinstance(err, OSError):
                raise
            said = ("no output of the run was put in place, and those there before are as they were" if not unrestored
                    else "and putting back what was there failed too: the previous files are " + ", ".join(unrestored))
            raise OutputError(f"{path}: cannot be written ({_reason(err)}); {said}") from err
        self._pairs = []
        interrupted = None
        for _path, backup in done:  # (every one, an interrupt meanwhile or not: a kept copy is the old output)
            if backup is not None:
                try:
                    os.remove(backup)
                except OSError:
                    pass
                except BaseException as err:  # noqa: BLE001 - finish the loop, then stop as asked
                    interrupted = interrupted or err
                    with contextlib.suppress(OSError):
                        os.remove(backup)
        if interrupted is not None:
            raise interrupted

    def discard(self) -> None:
        for tmp, _path in self._pairs:
            with contextlib.suppress(OSError):
                os.remove(tmp)
        self._pairs = []

    def __enter__(self):
        return self

    def __exit__(self, kind, _value, _tb):
        if kind is not None:
            self.discard()


@contextlib.contextmanager
def atomic_path(path: str):
    """Yield a temporary path beside ``path`` (same extension); rename it to ``path`` on success,
    delete it on any failure. Stale temporaries of ``path`` left by killed runs are removed first."""
    path = os.fspath(path)
    remove_stale_temporaries(path)
    try:
        fd, tmp = _temp_beside(path)
    except OSError as err:
        raise OutputError(f"{path}: cannot be written ({_reason(err)})") from err
    os.close(fd)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        _follow_umask(tmp, umask)  # mkstemp makes 0600; the output follows the umask like any file
        os.replace(tmp, path)
    except OSError as err:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        # A full disk or a folder made read-only meanwhile: the user's words, not a traceback.
        raise OutputError(f"{path}: cannot be written ({_reason(err)})") from err
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise
