"""One file of a survey, buffered by its neighbours: the job of a job array (SLURM ``--array``, PBS ``-J``).

A survey of many files is often run as many batch jobs, one per file, where the scheduler gives each job
its own node. Run whole, each file's tiles would miss the points of the files beside it, and the
classes and the DTM would show seams along the files' edges. Here a run of the survey with
``TileOptions.only`` set classifies the points of that one file only, on the same tiles as a run of
the whole survey (tiles on multiples of the tile size), each read with its buffer from the
neighbouring files: every file's classes are then those of the run of the whole survey on the same
tiles, and its DTM is that DTM's cells over the file's header bounds.

The engine (``tiles.py``) plans, bins and runs; this module says which file, which tiles, which
neighbours and where the outputs go.
"""
from __future__ import annotations

import math
import os
import re
from typing import List, Optional, Sequence, Tuple

from ..errors import InvalidParameterError, OutputError
from ..io.lasfiles import LasInfo
from ..io.outputs import LAS_EXTENSIONS, _ext

#: what the messages call the setting (the command line's option; the API's field is ``only``)
OPTION = "--only"


def only_index(only, inputs: Sequence[str], input_path: str) -> int:
    """The position in ``inputs`` (the survey's files, in the order of the folder's sorted names or of
    the .vpc) of the file ``only`` names: its 0-based position (a whole number, as a job array's task id
    gives it), its name, or its path."""
    n = len(inputs)
    text = str(only).strip()
    if re.fullmatch(r"\d+", text):
        k = int(text)
        if k >= n:
            raise InvalidParameterError(
                f"{input_path}: {OPTION} {k}: the survey has {n:,} file(s), numbered 0 to {n - 1:,} (for a job "
                f"array: --array=0-{n - 1})")
        return k
    real = os.path.realpath(text) if os.path.exists(text) else None
    named = [k for k, p in enumerate(inputs)
             if (real is not None and os.path.realpath(p) == real) or os.path.basename(p) == os.path.basename(text)]
    if real is not None:  # a path given: that file, not another of the same name
        named = [k for k in named if os.path.realpath(inputs[k]) == real] or named
    if len(named) == 1:
        return named[0]
    if len(named) > 1:
        raise InvalidParameterError(
            f"{input_path}: {OPTION} {text}: {len(named)} of its files have that name ({inputs[named[0]]}, "
            f"{inputs[named[1]]}); give the file's path or its number ({named[0]}, {named[1]})")
    shown = ", ".join(os.path.basename(p) for p in inputs[:3]) + (", ..." if n > 3 else "")
    raise InvalidParameterError(f"{input_path}: {OPTION} {text}: no file of the survey has that name (its {n:,} "
                                f"file(s): {shown}); give a name, a path or a number from 0 to {n - 1:,}")


def only_outputs(target: str, output_path: Optional[str], dtm_path: Optional[str]) -> Tuple[Optional[str], Optional[str]]:
    """Where one file's outputs go: ``output_path`` a .las/.laz (its classified copy) or a folder
    (made if missing; the copy there under the file's name, a COPC file's as .laz), ``dtm_path`` a .tif
    or a folder (the DTM there as the file's name .tif). A folder is what every job of an array is
    given, each writing its own file into it."""
    name = re.sub(r"\.copc\.laz$", ".laz", os.path.basename(target), flags=re.I)
    out = dtm = None
    if output_path:
        if _ext(output_path) == ".vpc":
            raise OutputError(f"{output_path}: with {OPTION}, a run writes one file's classified copy: give a folder "
                              "(each job of an array writes its file there) or a .las/.laz file, not a .vpc. The "
                              "folder of classified files is itself a survey input.")
        out = output_path if _ext(output_path) in LAS_EXTENSIONS else os.path.join(output_path, name)
    if dtm_path:
        dtm = dtm_path if _ext(dtm_path) in (".tif", ".tiff") else \
            os.path.join(dtm_path, os.path.splitext(name)[0] + ".tif")
    return out, dtm


def make_output_folders(paths: Sequence[Optional[str]]) -> None:
    """The folders of one file's outputs, made if missing (by any of the array's jobs: another may make
    one at the same time); they are not removed when the run fails, as other jobs write into them."""
    for path in paths:
        if not path:
            continue
        folder = os.path.dirname(os.path.abspath(path))
        if os.path.exists(folder) and not os.path.isdir(folder):
            raise OutputError(f"{folder}: a file, not a folder: the outputs of {OPTION} go into a folder")
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as err:
            raise OutputError(f"{folder}: the output folder cannot be made ({err.strerror or err})") from err


def tile_range(info: LasInfo, size: float) -> Tuple[int, int, int, int]:
    """(i0, i1, j0, j1): the tiles of ``size`` (on multiples of it) the file's header bounds touch."""
    return (math.floor(info.mins[0] / size), math.floor(info.maxs[0] / size),
            math.floor(info.mins[1] / size), math.floor(info.maxs[1] / size))


def reach_box(tiles: Tuple[int, int, int, int], size: float, buffer: float) -> Tuple[float, float, float, float]:
    """The area those tiles read, their buffer included, and a metre more (points on its edge are in)."""
    i0, i1, j0, j1 = tiles
    pad = buffer + 1.0
    return (i0 * size - pad, j0 * size - pad, (i1 + 1) * size + pad, (j1 + 1) * size + pad)


def neighbours(infos: Sequence[LasInfo], k: int, box) -> List[int]:
    """The files (positions in ``infos``, in survey order, ``k`` among them) whose header bounds meet
    ``box``: those the tiles of file ``k`` read their buffers from."""
    x0, y0, x1, y1 = box
    return [m for m, info in enumerate(infos)
            if m == k or (info.count and info.mins[0] <= x1 and info.maxs[0] >= x0
                          and info.mins[1] <= y1 and info.maxs[1] >= y0)]
