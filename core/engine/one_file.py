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
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

from ..errors import InputError, InvalidParameterError, OutputError
from ..io.lasfiles import LasInfo
from ..io.outputs import LAS_EXTENSIONS, _ext
from ..raster.geotiff import RASTER_EXTENSIONS


@dataclass(frozen=True)
class Subset:
    """The part of a survey a tiled run classifies when it is not the whole: one file of it (``index``, its
    place among the files the run reads: itself and its neighbours), or the tiles making a DTM extent's cells
    (``index`` None: a DTM of an extent alone)."""
    index: Optional[int]
    tiles: Tuple[int, int, int, int]     #: the tiles' range (i0, i1, j0, j1) over the file or the extent
    clip: Optional[Tuple[float, float, float, float]]  #: the box the files' points are read in (None: whole)
    survey_box: Tuple[float, float, float, float]      #: the whole survey's box, from its headers

    @property
    def one_file(self) -> bool:
        """One file of the survey (else a DTM extent's tiles)."""
        return self.index is not None


def stem_of(path: str) -> str:
    """A survey file's name without its extension (.las, .laz, .copc.laz): what ``{name}`` stands for."""
    return re.sub(r"(\.copc)?\.la[sz]$", "", os.path.basename(os.fspath(path)), flags=re.I)


def only_index(only, inputs: Sequence[str], input_path: str) -> int:
    """The position in ``inputs`` (the survey's files, in the order of the folder's sorted names or of
    the .vpc) of the file ``only`` names: its 0-based position (a whole number, as a job array's task id
    gives it), its name (with or without its extension), or its path (of that file: a file elsewhere of
    the same name is refused)."""
    n = len(inputs)
    text = str(only).strip()
    if re.fullmatch(r"\d+", text):
        k = int(text)
        same = [m for m, p in enumerate(inputs) if stem_of(p) == text and m != k]
        if same:  # (a delivery of tiles named by number: 1.laz, 2.laz, ...; a reviewer's --only 1 ran 2.laz)
            raise InvalidParameterError(
                f"{input_path}: {text} is both a file's number and a file's name ({os.path.basename(inputs[same[0]])}, "
                f"number {same[0]}): give the name with its extension for that file, as in an array's "
                f"--only \"$SLURM_ARRAY_TASK_ID.laz\"")
        if k >= n:
            raise InvalidParameterError(
                f"{input_path}: no file {k} in the survey: it has {n:,} file(s), numbered 0 to {n - 1:,} (for a job "
                f"array: --array=0-{n - 1})")
        return k
    if os.sep in text or (os.altsep and os.altsep in text):  # a path: that file, not another of its name
        from ..io.outputs import identities
        given = identities([text])
        named = [k for k, p in enumerate(inputs) if identities([p]) & given]
        if not named:
            raise InvalidParameterError(f"{input_path}: {text} is not one of the survey's files"
                                        + ("" if os.path.exists(text) else " (no such file)")
                                        + "; give one of them, its name or its number")
    else:
        named = [k for k, p in enumerate(inputs) if os.path.basename(p) == text] \
            or [k for k, p in enumerate(inputs) if stem_of(p) == text]
    if len(named) == 1:
        return named[0]
    if len(named) > 1:
        raise InvalidParameterError(
            f"{input_path}: {len(named)} files of the survey are named {text} ({inputs[named[0]]}, "
            f"{inputs[named[1]]}); give the file's path or its number ({named[0]}, {named[1]})")
    shown = ", ".join(os.path.basename(p) for p in inputs[:3]) + (", ..." if n > 3 else "")
    raise InvalidParameterError(f"{input_path}: no file of the survey is named {text} (its {n:,} file(s): {shown}); "
                                f"give a name, a path or a number from 0 to {n - 1:,}")


#: in an output's path, replaced by the one file's name without its extension (for QGIS's destinations,
#: which are files: --OUTPUT=out/{name}.laz --DTM=dtm/{name}.tif)
NAME_FIELD = "{name}"


def check_only(tiling, input_path: str, *paths) -> None:
    """Before any run: refuse ``only`` (``tiling``'s) on an input that is not a survey, where a file that
    fits in memory ran whole, ``only`` unheard and "{name}" written as such (a code reviewer); and refuse
    ``{name}`` in an output's path of a run of every file: such a run wrote a file named "{name}.tif" (an
    HPC reviewer's job array whose task id was unset)."""
    if tiling is not None and str(getattr(tiling, "only", "")) != "":
        if not (os.path.isdir(input_path) or _ext(input_path) == ".vpc"):
            raise InvalidParameterError(f"{input_path}: one file of a survey is chosen in a survey input (a folder or "
                                        "a .vpc); this input is a single file")
        return
    for path in paths:
        if path and NAME_FIELD in os.fspath(path):
            raise InvalidParameterError(f"{os.fspath(path)}: {NAME_FIELD} stands for the name of the one file of a "
                                        "survey that a run classifies (--only, One file of the survey), and this run "
                                        "has none: give that file, or a path without " + NAME_FIELD)


def only_outputs(target: str, output_path: Optional[str], dtm_path: Optional[str]) -> Tuple[Optional[str], Optional[str]]:
    """Where one file's outputs go: ``output_path`` a .las/.laz (its classified copy) or a folder
    (made if missing; the copy there under the file's name, a COPC file's as .laz), ``dtm_path`` a .tif
    or a folder (the DTM there as the file's name .tif); in either, ``{name}`` is the file's name without
    its extension. A folder, or a path with ``{name}``, is what every job of an array is given, each
    writing its own file."""
    stem = stem_of(target)
    out = dtm = None
    if output_path:
        output_path = os.fspath(output_path).replace(NAME_FIELD, stem)
        if _ext(output_path) == ".vpc":
            raise OutputError(f"{output_path}: a run of one file of the survey writes that file's classified copy: "
                              "give a folder (each job of an array writes its file there), a path with {name} (the "
                              "file's name), or a .las/.laz, not a .vpc. The folder of classified files is itself a "
                              "survey input.")
        ext = _ext(target) if _ext(target) in LAS_EXTENSIONS else ".laz"
        out = output_path if _ext(output_path) in LAS_EXTENSIONS else os.path.join(output_path, stem + ext)
    if dtm_path:
        dtm_path = os.fspath(dtm_path).replace(NAME_FIELD, stem)
        dtm = dtm_path if _ext(dtm_path) in RASTER_EXTENSIONS else os.path.join(dtm_path, stem + ".tif")
    return out, dtm


def _fixed(path: Optional[str], extensions) -> bool:
    """Whether an output's path is one file, the same for every file of the survey: a file's path
    (``extensions``) without ``{name}``, not a folder."""
    return bool(path) and NAME_FIELD not in os.fspath(path) and _ext(path) in extensions


def fixed_names_warning(target: str, output_path: Optional[str], dtm_path: Optional[str]) -> str:
    """A warning when an output of one file's run is a file path that does not name the file (no folder,
    no ``{name}``, another name): the jobs of an array all given that path overwrite each other's outputs,
    the last one's left. "" otherwise."""
    from ..progress import WARNING_PREFIX
    stem = stem_of(target)

    def names_it(path):  # the file's name, then the end or a separator: t1.laz, t1_ground.laz; not data.laz for a
        base = os.path.splitext(os.path.basename(path))[0]
        return base.startswith(stem) and (len(base) == len(stem) or not base[len(stem)].isalnum())
    fixed = [os.fspath(p) for p, exts in ((output_path, LAS_EXTENSIONS), (dtm_path, RASTER_EXTENSIONS))
             if _fixed(p, exts) and not names_it(os.fspath(p))]
    if not fixed:
        return ""
    return (f"{WARNING_PREFIX}{' and '.join(fixed)}: not named after {os.path.basename(target)}: the jobs of an array "
            "given the same path overwrite each other's output, the last one's kept. Give a folder, or {name} in "
            "the path, for each job's own file.")


def check_names_apart(inputs: Sequence[str], k: int, output_path: Optional[str], dtm_path: Optional[str]) -> None:
    """Refuse outputs of file ``k`` that another file of the survey would have too, as a run of the whole
    survey refuses them: two files of one name (a .vpc gathering several delivery folders), a.las beside
    a.laz, b.copc.laz beside b.laz. Each job of an array would write the same file, the last one's kept,
    without a word. A fixed path (neither a folder nor ``{name}``) is every file's: it is warned about
    (:func:`fixed_names_warning`), not refused."""
    mine = only_outputs(inputs[k], output_path, dtm_path)
    fixed = (_fixed(output_path, LAS_EXTENSIONS), _fixed(dtm_path, RASTER_EXTENSIONS))
    for m, other in enumerate(inputs):
        if m == k:
            continue
        theirs = only_outputs(other, output_path, dtm_path)
        for what, a, b, same in zip(("classified copy", "DTM"), mine, theirs, fixed):
            if a and not same and os.path.normcase(a) == os.path.normcase(b):
                raise InputError(f"{inputs[k]} and {other} would both have the {what} {a}: each one's job would "
                                 "overwrite the other's; rename one of them")


def check_not_beside_inputs(output_path: Optional[str], inputs: Sequence[str]) -> None:
    """Refuse a classified copy going into a folder that holds the survey's files: the next job of the
    array lists the folder (or a .vpc's neighbours are there) and would take the copy for one of the
    survey's files, its points twice."""
    if not output_path:
        return
    from ..io.outputs import identities
    folder = os.path.dirname(os.path.abspath(output_path))
    if os.path.isdir(folder) and identities([folder]) & identities({os.path.dirname(os.path.abspath(p)) for p in inputs}):
        raise OutputError(f"{output_path}: the classified copy would go into {folder}, which holds the survey's files: "
                          "the array's other jobs would take it for one of them; choose another folder")


def make_output_folders(paths: Sequence[Optional[str]]) -> None:
    """The folders of one file's outputs, made if missing (by any of the array's jobs: another may make
    one at the same time); they are not removed when the run fails, as other jobs write into them."""
    for path in paths:
        if not path:
            continue
        folder = os.path.dirname(os.path.abspath(path))
        if os.path.exists(folder) and not os.path.isdir(folder):
            raise OutputError(f"{folder}: a file, not a folder: the outputs of one file of the survey go into a folder")
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as err:
            raise OutputError(f"{folder}: the output folder cannot be made ({err.strerror or err})") from err


def fit_to_files(size: float, infos: Sequence[LasInfo], multiple_of: float = 1.0) -> float:
    """The planned tile ``size`` of a run of one file fitted to the survey's files: at most their usual
    side S (the median of their longer sides, in whole 10 m: a delivery's partial files on its edges
    and along a corridor are slivers of the grid, one side whole), else the largest S / n not below half of
    ``size``, so that on a delivery on multiples of S (1 km files on whole kilometres) a file is whole
    tiles and its job filters its own area and the buffers only; tiles straddling its edges make it
    filter its neighbours' points too (bench/one_file.py). From every file's header, so that each job of
    the array plans the same tiles; a multiple of 10 m and of ``multiple_of`` (the DTM cell)."""
    sides = sorted(max(i.maxs[0] - i.mins[0], i.maxs[1] - i.mins[1]) for i in infos if i.count)
    side = max(10.0, round(sides[len(sides) // 2] / 10.0) * 10.0)  # (a 1 km file's points span 999.99 m)

    def fits(s):
        return abs(s / 10.0 - round(s / 10.0)) < 1e-9 and (multiple_of <= 0 or
                                                            abs(s / multiple_of - round(s / multiple_of)) < 1e-9)
    parts = [side] if size >= side else [side / n for n in range(2, int(side // 10) + 1) if side / n >= size / 2]
    for part in parts:
        if part <= size and fits(part):
            return part
    if size <= side:
        return size
    # (a cell that does not divide the side: the largest multiple of it within the side, never wider)
    return max(math.floor(side / multiple_of + 1e-9), 1) * multiple_of if multiple_of > 0 else side


def tile_range(box, size: float, closed: bool = False) -> Tuple[int, int, int, int]:
    """(i0, i1, j0, j1): the tiles of ``size`` (on multiples of it) a box (xmin, ymin, xmax, ymax; a file's
    header bounds, whose points on its east or north edge are in the next tile) touches; ``closed``: cells
    ending at xmax, ymax (an extent's), which the tile beginning there does not hold."""
    def last(v):
        return math.ceil(v / size) - 1 if closed else math.floor(v / size)
    i0, j0 = math.floor(box[0] / size), math.floor(box[1] / size)
    return i0, max(i0, last(box[2])), j0, max(j0, last(box[3]))


def header_box(info: LasInfo) -> Tuple[float, float, float, float]:
    return info.mins[0], info.mins[1], info.maxs[0], info.maxs[1]


def clip_shares(infos: Sequence[LasInfo], keep_whole: Optional[int], box) -> List[float]:
    """Each file's share of its points that the binning keeps: 1 for ``keep_whole`` (the one file), else
    its header area within ``box`` (the points spread evenly): the working folder's disk is priced on them
    (a job of an array had been priced its 8 neighbours whole)."""
    shares = []
    for k, info in enumerate(infos):
        x0, y0, x1, y1 = header_box(info)
        if k == keep_whole:
            shares.append(1.0)
            continue
        w, h = max(x1 - x0, 1e-9), max(y1 - y0, 1e-9)
        inside = max(0.0, min(x1, box[2]) - max(x0, box[0])) * max(0.0, min(y1, box[3]) - max(y0, box[1]))
        shares.append(min(1.0, inside / (w * h)) if x1 > x0 and y1 > y0 else 1.0)
    return shares


def reach_box(tiles: Tuple[int, int, int, int], size: float, buffer: float) -> Tuple[float, float, float, float]:
    """The area those tiles read, their buffer included, and a metre more (points on its edge are in)."""
    i0, i1, j0, j1 = tiles
    pad = buffer + 1.0
    return (i0 * size - pad, j0 * size - pad, (i1 + 1) * size + pad, (j1 + 1) * size + pad)


def neighbours(infos: Sequence[LasInfo], k: int, box) -> List[int]:
    """The files (positions in ``infos``, in survey order, ``k`` among them) whose header bounds meet
    ``box``: those the tiles of file ``k`` read their buffers from (``k`` -1: those the tiles of an area
    read)."""
    x0, y0, x1, y1 = box
    return [m for m, info in enumerate(infos)
            if m == k or (info.count and info.mins[0] <= x1 and info.maxs[0] >= x0
                          and info.mins[1] <= y1 and info.maxs[1] >= y0)]
