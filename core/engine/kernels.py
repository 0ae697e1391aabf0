"""The numba kernels cached on disk (``@njit(cache=True)``): which modules hold them, how many of
them numba's cache holds, and what to say when a run is about to compile them (the first run of an
algorithm after an install or upgrade waits 20-60 s with its progress bar still). Imports nothing
but the standard library until asked (the plugin's dialog reads COMPILING without numpy)."""
from __future__ import annotations

import functools
import importlib
import os
import re
from typing import List, Optional, Sequence, Tuple

COMPILING = ("First run of this algorithm since the plugin was installed or upgraded: compiling its numerical "
             "kernels (about 20-60 s, once; the progress bar waits meanwhile).")

_CORE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: a kernel decorated to be cached on disk
_CACHED = re.compile(r"^\s*@(?:numba\.)?njit\([^)]*cache\s*=\s*True", re.M)
_PACKAGE = __package__.rsplit(".", 1)[0]  # "groundsieve.core"

#: the kernel modules of each filter beyond those named after it (core/filters/_<name>_*.py): the
#: learned hybrid computes SMRF's and PTD's surfaces and the point features; the DTM from classes only the DTM's
#: (rftrain and rfclassify apart: a classification with a DTM compiles the DTM's kernels a training does not)
_ALSO = {"hybrid": ("filters._smrf", "filters._ptd", "learn."), "rftrain": ("learn.",),
         "rfclassify": ("learn.",), "features": ("learn.",),
         "evcrasters": ("filters._evc",), "dtm": ("grids.",)}


def kernel_modules() -> List[str]:
    """The dotted names of the core's modules whose numba kernels are cached on disk, found by their
    source (no import)."""
    return list(_kernel_modules())


@functools.lru_cache(maxsize=1)
def _kernel_modules() -> Tuple[str, ...]:
    """:func:`kernel_modules`, found once a process: a run's check (about_to_compile) asks twice, and
    each walk reads every source file of the core."""
    names = []
    for folder, dirs, files in os.walk(_CORE):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(f for f in files if f.endswith(".py")):
            path = os.path.join(folder, name)
            with open(path, encoding="utf-8") as f:
                if not _CACHED.search(f.read()):  # (a docstring naming cache=True is no kernel: a code reviewer)
                    continue
            names.append(_PACKAGE + "." + os.path.relpath(path, _CORE)[:-3].replace(os.sep, "."))
    return tuple(names)


def modules_for(name: str) -> Optional[List[str]]:
    """The kernel modules an algorithm's own work compiles (a filter's ``_<name>_*`` modules, and
    those ``_ALSO`` names); None (all of them) for an algorithm without its own."""
    prefixes = (f"filters._{name}",) + _ALSO.get(name, ())
    found = [m for m in kernel_modules() if any(m[len(_PACKAGE) + 1:].startswith(p) for p in prefixes)]
    return found or None


def shared_modules() -> List[str]:
    """The kernel modules every ground filter's run compiles (the grids': surfaces, morphology, the DTM)."""
    return [m for m in kernel_modules() if m.startswith(_PACKAGE + ".grids.")]


def about_to_compile(name: Optional[str]) -> bool:
    """Whether a run of algorithm ``name`` (None: any) is about to compile kernels. Not when a run of it
    finished with these kernels' sources (:func:`remember_run`) and their cache is still there; else when
    fewer than half of its own kernels (:func:`modules_for`), or of the shared ones
    (:func:`shared_modules`), are cached. (The count alone said it at every run of a fresh install: a
    run compiles the shared kernels of its own path only, 13 of 39 for SMRF with a DTM; a new user.)"""
    if name:
        stamp = _read_stamp()
        if stamp is not None and stamp.get("sources") == _sources_stamp() and name in stamp.get("ran", ()):
            state = kernel_cache_state(modules_for(name) or shared_modules())
            if state is not None and state[0] > 0:  # (a cache cleared since is said again)
                return False
    own = modules_for(name) if name else None
    return any(compiling_note(kernel_cache_state(group)) for group in ((own, shared_modules()) if own else (None,)))


#: the file beside numba's cache of the core's first kernel module that names the algorithms whose run
#: finished with the kernels' present sources
STAMP_NAME = "groundsieve-runs.json"


def remember_run(name: Optional[str]) -> None:
    """After a run of algorithm ``name`` finished: its kernels are compiled for these sources, so the
    next run says nothing of compiling (:func:`about_to_compile`). Silent where the cache cannot be
    written (numba then compiles in memory each time anyway). Two runs finishing at once may keep one
    of the two names: the other's next run then says the note once more."""
    path = _stamp_path()
    if not name or path is None:
        return
    import json
    stamp = _read_stamp() or {}
    sources = _sources_stamp()
    ran = set(stamp.get("ran", ())) if stamp.get("sources") == sources else set()
    if name in ran:
        return
    ran.add(name)
    import threading  # (two runs of one QGIS process finish in threads of their own: a code reviewer)
    part = f"{path}.{os.getpid()}-{threading.get_ident()}.part"
    try:
        with open(part, "w", encoding="utf-8") as f:
            json.dump({"sources": sources, "ran": sorted(ran)}, f)
        os.replace(part, path)
    except OSError:
        try:
            os.remove(part)
        except OSError:
            pass


def _read_stamp() -> Optional[dict]:
    import json
    path = _stamp_path()
    try:
        with open(path, encoding="utf-8") as f:
            stamp = json.load(f)
        return stamp if isinstance(stamp, dict) else None
    except (OSError, TypeError, ValueError):
        return None


def _stamp_path() -> Optional[str]:
    """:data:`STAMP_NAME` in the folder where numba caches the core's first kernel module (beside the
    source, NUMBA_CACHE_DIR's, or the user's cache), so that it goes where that cache goes."""
    try:
        from numba.core.dispatcher import Dispatcher
        for name in kernel_modules():
            module = importlib.import_module(name)
            for obj in vars(module).values():
                if isinstance(obj, Dispatcher):
                    index = getattr(getattr(getattr(obj, "_cache", None), "_cache_file", None), "_index_path", None)
                    if index:
                        return os.path.join(os.path.dirname(index), STAMP_NAME)
    except Exception:  # noqa: BLE001 - another numba's internals: no stamp
        return None
    return None


def _sources_stamp() -> str:
    """The kernel modules' sources as the stamp knows them: their names, sizes and times (an upgrade
    changes them)."""
    import hashlib
    digest = hashlib.sha1()
    for name in kernel_modules():
        path = os.path.join(_CORE, *name[len(_PACKAGE) + 1:].split(".")) + ".py"
        try:
            st = os.stat(path)
            digest.update(f"{name}:{st.st_size}:{st.st_mtime_ns};".encode())
        except OSError:
            digest.update(f"{name}:-;".encode())
    return digest.hexdigest()


def kernel_cache_state(modules: Optional[Sequence[str]] = None) -> Optional[Tuple[int, int]]:
    """(cached, total): of the numba kernels of ``modules`` (default: :func:`kernel_modules`) cached on
    disk, how many have their index file in numba's cache (where numba itself looks: beside the
    source in __pycache__, NUMBA_CACHE_DIR when set, the user's cache when the plugin's folder is
    read-only). Importing the modules compiles nothing. None when it cannot be told."""
    try:
        from numba.core.dispatcher import Dispatcher
        cached = total = 0
        for name in kernel_modules() if modules is None else modules:
            module = importlib.import_module(name)
            for obj in vars(module).values():
                if not isinstance(obj, Dispatcher) or getattr(obj.py_func, "__module__", None) != module.__name__:
                    continue
                index = getattr(getattr(getattr(obj, "_cache", None), "_cache_file", None), "_index_path", None)
                if index is None:  # not cached on disk
                    continue
                total += 1
                cached += os.path.isfile(index)
        return cached, total
    except Exception:  # noqa: BLE001 - another numba's internals, a broken module: say nothing
        return None


def compiling_note(state: Optional[Tuple[int, int]]) -> bool:
    """Whether a run whose kernels' cache ``state`` is (cached, total) is about to compile them: fewer
    than half cached (some kernels of a module compile only on paths a run never takes, so "all"
    would be said again every session)."""
    return state is not None and state[1] > 0 and 2 * state[0] < state[1]
