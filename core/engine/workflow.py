"""The driver shared by every ground filter: from a file to a classified file and a DTM.

A filter (e.g. :class:`~groundsieve.core.filters.smrf.SMRF`) only maps the x, y, z of the
points it is given to a ground mask. This module does the rest, the same for every
filter: select the points to filter, write ASPRS classes, write the classified cloud and
the DTM, report progress, honour cancellation.

The rules on points the user (or a previous pass) has marked, applied per point here and so the
same for a whole file and for each tile of a survey:

- *withheld* (the LAS flag: "if set, this point should not be included in processing (synonymous
  with Deleted)", in the ASPRS LAS specification's words; bit 7 of the
  classification byte in point formats 0-5, a classification flag in 6-10): never given to the
  filter, never ground, never in the DTM; class and flags written back as read.
- *ignored classes* (``FilterOptions.ignore_classes``, noise 7 and 18 by default, as PDAL's
  ``ignore`` and LAStools' ``-ignore_class``): the same.
- *kept classes* (``keep_existing_classes``): every point whose class is not 0, 1 or 2 keeps it
  exactly; it is still given to the filter (it shapes the surface) but never becomes ground.
- every other point becomes 2 (ground) or 1 (unclassified); non-last returns too with
  ``last_returns_only`` (they are not filtered, so they are 1).
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from typing import Callable, List, Optional, Tuple

import numpy as np

from ..errors import GroundSieveError, InputError, InvalidParameterError
from ..grids.spec import MAX_CELL_M, GridSpec, memory_budget
from ..io import (CLASS_GROUND, CLASS_UNCLASSIFIED, NOISE_CLASSES, PointCloud, check_output_path,
                 read_cloud, write_classified)
from ..io.clouds import TEXT_EXTENSIONS, parse_classes
from ..io.outputs import LAS_EXTENSIONS, _ext, check_distinct_outputs
from ..progress import WARNING_PREFIX, Steps, warning_of
from .tiles import TileOptions

#: Classes a ground filter may rewrite when existing classes are kept: never classified,
#: unclassified, ground.
REWRITTEN_CLASSES = (0, CLASS_UNCLASSIFIED, CLASS_GROUND)


def _check_budget(value, what):
    if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0):
        raise InvalidParameterError(f"{what} must be a whole number of bytes > 0, or None (got {value!r})")


@dataclass(frozen=True)
class FilterOptions:
    """What the driver does around the filter (see the module's rules on marked points)."""
    last_returns_only: bool = False
    #: the former switch for noise: when ``ignore_classes`` is None, True ignores 7 and 18 and False
    #: ignores nothing (an explicit ``ignore_classes`` wins)
    ignore_noise: bool = True
    #: every class other than 0, 1 and 2 is left as it was (such points are never ground)
    keep_existing_classes: bool = False
    #: ASPRS codes never filtered, kept, out of the DTM: "7, 18", "7 18", "20-25", (7, 18), ...
    ignore_classes: Optional[object] = None
    #: bytes the filter's grids may take (None: a share of the memory available)
    memory_budget_bytes: Optional[int] = None
    #: survey scale: tile size, buffer, memory budget, workers, working folder (engine/tiles.py)
    tiling: TileOptions = TileOptions()

    def __post_init__(self):
        if self.ignore_classes is not None:
            object.__setattr__(self, "ignore_classes", parse_classes(self.ignore_classes, what="ignored classes"))
        _check_budget(self.memory_budget_bytes, "memory_budget_bytes")

    @property
    def ignored(self) -> tuple:
        """The ASPRS codes left out (sorted)."""
        if self.ignore_classes is not None:
            return self.ignore_classes
        return NOISE_CLASSES if self.ignore_noise else ()


@dataclass(frozen=True)
class DTMOptions:
    cell_size_m: float = 1.0
    fill_outside_hull: bool = False
    #: ground points triangulated per DTM cell at most (0 = all; see rasterize.tin_dtm)
    points_per_cell: int = 4
    #: bytes the DTM grid may take (None: a share of the memory available)
    memory_budget_bytes: Optional[int] = None
    #: classes of the input whose points enter the DTM with the ground, whatever the filter made of
    #: them: e.g. 9 (water), so that a flood model's DTM holds the water surface where the vendor
    #: classified it ("9", "9, 17", "2-5", or codes). Withheld and ignored points never enter it.
    classes: object = ()
    #: cells farther than this (m) from every DTM point stay empty, so that a data gap (a missing
    #: tile, a lake without returns) is not bridged by invented terrain; 0 = no limit
    max_distance_m: float = 0.0
    #: the cell was set by the user (typed, or another value than the default in the dialog): in the
    #: CRS's unit; otherwise a cell equal to the default is the default, 1 m, converted for a cloud in
    #: feet (defaults_in_crs_unit; a typed --dtm-cell 1 was converted: a code reviewer)
    cell_set: bool = False
    #: metres per unit of the cloud's coordinates, set by the run (defaults_in_crs_unit): the DTM's
    #: notes (the isolated pits' 0.5 m depth, the lengths they give) in the CRS's unit
    metres_per_unit: float = 1.0
    #: the DTM's extent (xmin, ymin, xmax, ymax in the cloud's CRS), widened to whole cells on the lattice of
    #: multiples of the cell: two epochs' DTMs, or a model's domain, on one grid of one size; cells without
    #: data are nodata. None: the extent of the points that may enter the DTM
    extent: Optional[Tuple[float, float, float, float]] = None

    def __post_init__(self):
        _check_budget(self.memory_budget_bytes, "memory_budget_bytes")
        object.__setattr__(self, "classes", parse_classes(self.classes, what="DTM classes"))
        if not (math.isfinite(self.max_distance_m) and self.max_distance_m >= 0):
            raise InvalidParameterError(f"DTM maximum distance must be >= 0 m, 0 = no limit "
                                        f"(got {self.max_distance_m})")
        if not (math.isfinite(self.cell_size_m) and self.cell_size_m > 0):
            raise InvalidParameterError(f"DTM cell size must be > 0 m (got {self.cell_size_m})")
        if self.cell_size_m > MAX_CELL_M:
            raise InvalidParameterError(f"DTM cell size: {self.cell_size_m:g} m is larger than any map "
                                        f"(at most {MAX_CELL_M:g} m)")
        if int(self.points_per_cell) != self.points_per_cell or self.points_per_cell < 0:
            raise InvalidParameterError(f"points_per_cell must be a whole number >= 0 (got {self.points_per_cell})")
        if self.extent is not None:
            extent = parse_extent(self.extent)
            object.__setattr__(self, "extent", extent)


def parse_extent(value) -> Optional[Tuple[float, float, float, float]]:
    """A DTM extent as (xmin, ymin, xmax, ymax): from four numbers, or the text "xmin,ymin,xmax,ymax";
    None for an empty text. Raises InvalidParameterError saying what is wrong."""
    if isinstance(value, str):
        if not value.strip():
            return None
        parts = value.replace(";", ",").split(",")
        try:
            numbers = [float(p) for p in parts]
        except ValueError:
            numbers = []
        if len(numbers) != 4:
            raise InvalidParameterError(f"DTM extent: '{value}' is not xmin,ymin,xmax,ymax (four numbers)")
        value = numbers
    try:
        xmin, ymin, xmax, ymax = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"DTM extent: {value!r} is not xmin, ymin, xmax, ymax (four numbers)") from None
    if not all(math.isfinite(v) for v in (xmin, ymin, xmax, ymax)):
        raise InvalidParameterError(f"DTM extent: ({xmin:g}, {ymin:g}, {xmax:g}, {ymax:g}) holds a value that is "
                                    "not a finite number")
    if not (xmin < xmax and ymin < ymax):
        raise InvalidParameterError(f"DTM extent: ({xmin:g}, {ymin:g}, {xmax:g}, {ymax:g}) is empty: give xmin, "
                                    "ymin, xmax, ymax with xmin < xmax and ymin < ymax")
    return xmin, ymin, xmax, ymax


#: a DTM extent more than this many times the area of the points' box is refused when its numbers in the other
#: order (QGIS's xmin,xmax,ymin,ymax against the command line's XMIN,YMIN,XMAX,YMAX) fit the points, and when it
#: is over EXTENT_AREA_M2 too; a model's domain of a few km around a small survey stays (a technical writer: 2.5 x
#: 2 km around a 60 m plot was refused at 1 km²), a wrong order in a national grid does not (a code reviewer: in
#: the British National Grid it made a valid 14 x 14 km box)
EXTENT_AREA_RATIO = 1000.0
EXTENT_AREA_M2 = 1e11


def check_extent(options: "DTMOptions", xmin: float, ymin: float, xmax: float, ymax: float) -> None:
    """Refuse a DTM extent that misses the points' box (``xmin`` ... ``ymax``), one whose numbers in the other
    order fit them where these dwarf them, or one that dwarfs them beyond any model's domain, before any work:
    QGIS writes an extent xmin,xmax,ymin,ymax and the command line takes XMIN,YMIN,XMAX,YMAX, and one given in
    the other's order made a valid box, refused as "2 points lie 4890.7 km from the others" (a power user)."""
    if options.extent is None:
        return
    ex0, ey0, ex1, ey1 = options.extent
    points_area = max(xmax - xmin, 1.0) * max(ymax - ymin, 1.0)

    def meets(x0, y0, x1, y1):
        return x0 <= xmax and xmin <= x1 and y0 <= ymax and ymin <= y1

    def fits(x0, y0, x1, y1):
        return x0 < x1 and y0 < y1 and meets(x0, y0, x1, y1) and (x1 - x0) * (y1 - y0) <= EXTENT_AREA_RATIO * points_area

    area = (ex1 - ex0) * (ey1 - ey0)
    other = (ex0, ex1, ey0, ey1)  # (the middle two exchanged: the same four numbers read in the other order)
    if not meets(ex0, ey0, ex1, ey1):
        why = "does not meet them"
    elif area > EXTENT_AREA_RATIO * points_area and fits(*other):
        why = (f"is {area / points_area:,.0f} times their area, where its numbers in the other order, x {other[0]:,.2f} "
               f"to {other[2]:,.2f}, y {other[1]:,.2f} to {other[3]:,.2f}, fit them")
    elif area > EXTENT_AREA_RATIO * points_area and area > EXTENT_AREA_M2 / options.metres_per_unit ** 2:
        why = f"is {area / points_area:,.0f} times their area"
    else:
        return
    raise InvalidParameterError(
        f"DTM extent: x {ex0:,.2f} to {ex1:,.2f}, y {ey0:,.2f} to {ey1:,.2f} {why} (the points span x {xmin:,.2f} "
        f"to {xmax:,.2f}, y {ymin:,.2f} to {ymax:,.2f}): are its numbers in the right order (QGIS writes an extent "
        "xmin,xmax,ymin,ymax; --dtm-extent takes XMIN,YMIN,XMAX,YMAX) and in the cloud's CRS?")


def extent_grid(options: "DTMOptions", max_cells: Optional[int] = None,
                bytes_per_cell: Optional[float] = None) -> Optional[GridSpec]:
    """The DTM's grid over ``options.extent`` (cells on multiples of the cell size; None without one), its
    memory checked at ``bytes_per_cell`` (DTM_BYTES_PER_CELL by default; 0 for a tiled run's, written block
    by block)."""
    if options.extent is None:
        return None
    bytes_per_cell = DTM_BYTES_PER_CELL if bytes_per_cell is None else bytes_per_cell
    xmin, ymin, xmax, ymax = options.extent
    extra = {} if max_cells is None else dict(max_cells=max_cells)
    return GridSpec.covering(np.array([xmin, xmax]), np.array([ymin, ymax]), options.cell_size_m, what="DTM",
                             bytes_per_cell=bytes_per_cell, closed=True, **extra)


@dataclass
class FilterRun:
    cloud: PointCloud
    classification: np.ndarray
    ground: np.ndarray          #: bool per point of the cloud
    filtered: np.ndarray        #: bool per point: was given to the filter
    dtm_grid: Optional[GridSpec] = None
    dtm: Optional[np.ndarray] = None
    detail: object = None       #: what the filter's ``run`` returned (see call_filter)
    algorithm: object = None    #: the filter as it ran (its lengths in the CRS's unit: defaults_in_crs_unit)
    #: as a tiled run's ``TiledRun`` has them (run_ground_filter returns either): the input, the classified
    #: file written (none without an output), the DTM's path, and the run's warnings (its log's "Warning: "
    #: lines, without the prefix)
    inputs: List[str] = field(default_factory=list)
    outputs: List[str] = field(default_factory=list)
    dtm_path: Optional[str] = None
    warnings: List[str] = field(default_factory=list)

    @property
    def ground_count(self) -> int:
        return int(self.ground.sum())

    @property
    def point_count(self) -> int:
        return len(self.cloud)

    @property
    def crs_wkt(self) -> Optional[str]:
        """The cloud's CRS (a tiled run's ``TiledRun`` has the same field)."""
        return self.cloud.crs_wkt


def processable(cloud: PointCloud, options: FilterOptions) -> np.ndarray:
    """Boolean mask of the points that may be processed at all: not withheld, not of an ignored
    class. Only these can be filtered, become ground or enter a DTM (and span its grid)."""
    keep = ~cloud.withheld_mask
    if options.ignored:
        keep &= ~np.isin(cloud.classification, options.ignored)
    return keep


#: what a run with only last returns says of a cloud without return information (a UAV photogrammetry user:
#: the option was taken without a word)
LAST_RETURNS_WITHOUT_RETURNS = (
    f"{WARNING_PREFIX}{{what}}: 'only last returns' is set, but the cloud has no return information (every point "
    "1 of 1, or 0 of 0 as image-matching software writes it, or a text file): every point is its pulse's last, so "
    "the option leaves none out.")


def select_points(cloud: PointCloud, options: FilterOptions) -> np.ndarray:
    """Boolean mask of the points the filter sees: the processable ones (optionally only the last
    returns)."""
    keep = processable(cloud, options)
    if options.last_returns_only and cloud.has_return_info:
        rn, nr = cloud.return_number, cloud.number_of_returns
        # A return is last when its number equals the count; files that leave both 0 count as single, and a
        # return number 0 (no number: "0 of 1", a writer's) is not taken for an earlier return (a code reviewer:
        # every point was left out, "no point is left to filter")
        keep &= (rn >= nr) | (nr == 0) | (rn == 0)
    return keep


@dataclass
class Classified:
    classification: np.ndarray  #: uint8 ASPRS classes of every point
    ground: np.ndarray          #: bool per point
    filtered: np.ndarray        #: bool per point: given to the filter
    detail: object = None       #: what the filter's ``run`` returned (grids, ...), if it has one
    processable: Optional[np.ndarray] = None  #: bool per point: neither withheld nor ignored (the DTM's area)
    #: bool per point: given a class by the run (processable; with kept classes, of class 0, 1 or 2 only)
    touched: Optional[np.ndarray] = None


def _where(mask: np.ndarray, *arrays):
    """``arrays`` at the points of ``mask``: the arrays themselves when it holds every point (most
    runs; a gathered copy of millions of points costs time and fresh memory for nothing)."""
    if mask.all():
        return arrays
    return tuple(a[mask] for a in arrays)


#: the optional point field a tile gives a filter that can leave points out (core/engine/learning.ModelGround):
#: True for the points whose class is used (the tile's own, where no DTM needs the buffer's ground)
NEEDED = "_needed"


def _point_field(cloud: PointCloud, name: str) -> np.ndarray:
    """A per-point field of ``cloud``: the values an algorithm took from a tile's records
    (``cloud.attributes``) first, then the cloud's own fields."""
    if cloud.attributes is not None and name in cloud.attributes:
        return cloud.attributes[name]
    return getattr(cloud, name)


def call_filter(algorithm, cloud: PointCloud, idx: np.ndarray, steps: Steps, log):
    """Run one filter on the points ``idx`` of ``cloud``.

    The protocol every filter follows: ``run(xyz, steps=..., **fields)`` returns an object with
    a boolean ``ground`` (and whatever else the filter wants to show, e.g. grids); plain
    callables ``f(xyz, steps=...) -> ground`` work too. A filter that needs per-point
    attributes names them in ``point_fields`` (e.g. ``("return_number", "number_of_returns")``)
    and gets them as keyword arrays (``optional_point_fields``: when the cloud has them, e.g. a tile's
    ``NEEDED``); one that has something to tell the user sets
    ``wants_log = True`` and gets ``log``.
    """
    xyz = np.empty((idx.size, 3))
    every = idx.size == len(cloud)  # (most runs: no gathered copy of each coordinate first)
    for k, values in enumerate((cloud.x, cloud.y, cloud.z)):
        xyz[:, k] = values if every else values[idx]
    # The copy takes a while on millions of points (5 M points: 0.2 s of a 1.3 s SMRF stage in the
    # desktop, fresh memory): the bar moves past it.
    steps.report(0.05)
    steps = steps.sub(0.05, 1.0)
    extra = {name: np.ascontiguousarray(_point_field(cloud, name)[idx])
             for name in getattr(algorithm, "point_fields", ())}
    for name in getattr(algorithm, "optional_point_fields", ()):  # given when the cloud has them
        if cloud.attributes is not None and name in cloud.attributes:
            extra[name] = np.ascontiguousarray(cloud.attributes[name][idx])
    if getattr(algorithm, "wants_log", False):
        def named(message: str) -> None:  # a filter's warning names the file it is about (it sees arrays)
            text = warning_of(message)
            log(message if text is None or cloud.path in text else f"{WARNING_PREFIX}{cloud.path}: {text}")
        extra["log"] = named
    if hasattr(algorithm, "run"):
        detail = algorithm.run(xyz, steps=steps, **extra)
        return np.asarray(detail.ground, dtype=bool), detail
    return np.asarray(algorithm(xyz, steps=steps, **extra), dtype=bool), None


def classify_cloud(cloud: PointCloud, algorithm, options: FilterOptions = FilterOptions(),
                   steps: Optional[Steps] = None, log: Optional[Callable[[str], None]] = None) -> Classified:
    """Run ``algorithm`` on the selected points and give every point its ASPRS class."""
    steps = steps or Steps()
    log = log or (lambda _msg: None)
    for note in cloud.notes:
        log(note)
    may = processable(cloud, options)
    filtered = select_points(cloud, options)
    n_sel = int(filtered.sum())
    withheld = cloud.withheld_mask
    n_withheld = int(withheld.sum())
    n_ignored = int((~may & ~withheld).sum())
    if n_sel == 0:
        raise InvalidParameterError(
            f"{cloud.path}: no point is left to filter ({n_withheld:,} withheld, {n_ignored:,} of an ignored "
            f"class {_codes(options.ignored)}, {int(may.sum()):,} others"
            + (", none of them a last return)" if options.last_returns_only else ")"))
    if n_sel < len(cloud):
        log(f"{'Taking' if getattr(algorithm, 'ground_of_any_class', False) else 'Filtering'} {n_sel:,} of "
            f"{len(cloud):,} points ({n_withheld:,} withheld and {n_ignored:,} of an "
            f"ignored class {_codes(options.ignored)} left out, keeping their class"
            + (", non-last returns left out" if options.last_returns_only else "") + ").")
    if options.last_returns_only and not (cloud.has_return_info and (cloud.number_of_returns > 1).any()):
        log(LAST_RETURNS_WITHOUT_RETURNS.format(what=cloud.path))
    idx = np.flatnonzero(filtered)
    steps.report(0.01)
    with memory_budget(options.memory_budget_bytes):
        sub_ground, detail = call_filter(algorithm, cloud, idx, steps.sub(0.01, 1.0), log)
    cls = cloud.classification.copy()
    # Who gets a new class: every processable point (non-last returns too: they are not ground),
    # or with kept classes only those of class 0, 1 or 2.
    touched = may.copy()
    if options.keep_existing_classes:
        touched &= np.isin(cls, REWRITTEN_CLASSES)
    else:
        replaced = replaced_classes(cls, touched)
        note = replaced_note(replaced, algorithm)
        if note:
            log(note)
    ground = np.zeros(len(cloud), dtype=bool)
    ground[idx[sub_ground]] = True
    if not getattr(algorithm, "ground_of_any_class", False):
        ground &= touched
    if not options.keep_existing_classes:
        warning = structures_warning(structures_made_ground(cls, ground), replaced, cloud.path, algorithm)
        if warning:
            log(warning)
    note = demoted_note(*demoted_ground(cloud.classification, ground, touched), algorithm)
    if note:
        log(note)
    note = canopy_ground_note(*ground_not_last(cloud, ground), algorithm)
    if note:
        log(note)
    note = agreement_note(agreement_counts(cloud, ground, touched), algorithm, options)
    if note:
        log(note)
    cls[touched] = CLASS_UNCLASSIFIED
    cls[ground & touched] = CLASS_GROUND  # (the ground of a kept class keeps it: ground_of_any_class)
    predicted = getattr(detail, "point_classes", None)
    if predicted is not None:  # a model's classes (rfclassify in tiles): each point its predicted class
        every = np.full(len(cloud), CLASS_UNCLASSIFIED, dtype=np.uint8)
        every[idx] = predicted
        cls[touched] = every[touched]
    return Classified(cls.astype(np.uint8), ground, filtered, detail, may, touched)


def ground_classes_counts(points, counts=None, classes=()) -> str:
    """ "2 (ground): 584,948, 9 (water): 9,560" of the classes of the points ``points`` (or of {class: points}
    ``counts``), every one of ``classes`` named, 0 too: what each ground class of a DTM from classes gave (a
    flood modeller asked; a class that gave none was not said)."""
    from ..io.clouds import class_counts_text, count_classes
    if counts is None:
        counts = {**{c: 0 for c in classes}, **count_classes(points)}
    return class_counts_text(counts)


def demoted_ground(classification: np.ndarray, ground: np.ndarray, touched: np.ndarray) -> tuple:
    """(points the input had as ground (2) among those given a class, those of them not ground now)."""
    had = touched & (classification == CLASS_GROUND)
    return int(np.count_nonzero(had)), int(np.count_nonzero(had & ~ground))


def agreement_counts(cloud, ground: np.ndarray, touched: np.ndarray) -> list:
    """[tp, fn, fp, tn, by labels (1) or classes (0)]: the run's ground against the input's own, over the points
    given a class: an ISPRS text's reference labels (0 ground), or a LAS's classes (2 ground, every other class
    not: 0 too, which the ISPRS samples as LAZ give their objects; water, 9, left out, a surface every filter
    calls ground: lidR's Topography had its Type II raised by 4 points, a forester); zeros when the input holds
    no ground or nothing else."""
    if cloud.reference_label is not None:
        labelled, ref, kind = touched, np.asarray(cloud.reference_label) == 0, 1
    else:
        labelled, ref, kind = touched & (cloud.classification != 9), cloud.classification == CLASS_GROUND, 0
    tp = int(np.count_nonzero(labelled & ref & ground))
    fn = int(np.count_nonzero(labelled & ref & ~ground))
    fp = int(np.count_nonzero(labelled & ~ref & ground))
    tn = int(np.count_nonzero(labelled & ~ref & ~ground))
    return [tp, fn, fp, tn, kind] if tp + fn and fp + tn else [0, 0, 0, 0, kind]


def agreement_note(counts, algorithm=None, options=None) -> str:
    """The log's line of the run's ground against the input's labels or classes (:func:`agreement_counts`), in
    the ISPRS measures fan2023 and matrone2024 compare filters by (Sithole & Vosselman 2004): a labelled patch
    run through a filter says its errors, where a user had to script them (a photogrammetry reviewer). "" when
    the input holds no ground or nothing else, the classes are kept, or the ground is the input's own."""
    tp, fn, fp, tn, kind = (list(counts) + [0] * 5)[:5]
    if not (tp + fn and fp + tn) or getattr(algorithm, "ground_of_any_class", False) \
            or getattr(algorithm, "predicts_classes", False) or (options is not None and options.keep_existing_classes):
        return ""
    from ..metrics import GroundAccuracy
    acc = GroundAccuracy(tp, fn, fp, tn)
    what = ("the file's reference labels (0 ground, 1 object)" if kind else
            "the input's classes (2 ground, the others but water (9) not)")
    # (a vendor's classes are no truth: its unclassified (1) may hold ground it left, which made autzen's
    # Type II 75 %, most of it within 0.3 m of the vendor's own ground: a dense-UAV reviewer)
    return (f"Against {what}, over {acc.n:,} points: Type I {100 * acc.type1:.2f} % (ground called not ground), "
            f"Type II {100 * acc.type2:.2f} % (the rest called ground), total error {100 * acc.total:.2f} %, "
            f"kappa {100 * acc.kappa:.2f} % (ISPRS measures; the input unchanged"
            + ("" if kind else "; errors if the classes are a labelled truth, an agreement if a vendor's, whose "
               "unclassified (1) may hold ground it left") + ").")


#: above this share of ground points that are not their pulse's last return, the ground is said to hold canopy:
#: on real forest and terrain clouds (lidR's, the bcts tiles) SMRF, CSF, PMF and PTD gave 0-2.7 %; CSF with a
#: 0.5 m cloth and rigidness 1 under a closed canopy, whose DTM lay on the crowns, 46-55 % (a forester)
NOT_LAST_GROUND_SHARE = 0.10
#: and at least this many such points
NOT_LAST_GROUND_MIN = 500


def ground_not_last(cloud, ground: np.ndarray) -> tuple:
    """(ground points, those of them that are not their pulse's last return); (0, 0) for a cloud without
    return information."""
    if not cloud.has_return_info:
        return 0, 0
    rn, nr = cloud.return_number, cloud.number_of_returns
    # (a return number 0 is no number: "0 of 1" made every ground point a non-last return, a code reviewer)
    return int(np.count_nonzero(ground)), int(np.count_nonzero(ground & (rn < nr) & (rn > 0)))


def canopy_ground_note(ground: int, not_last: int, algorithm=None) -> str:
    """A warning when many ground points are not their pulse's last return: a pulse that went on below a
    point was not stopped by the ground there, so such ground is canopy or a roof's edge (a forester's CSF
    DTM lay 11.7 m up on the crowns, and the log warned only of 'isolated pits'). "" otherwise, and for the
    DTM from classes (its ground is the input's)."""
    if getattr(algorithm, "ground_of_any_class", False) or not getattr(algorithm, "offers_last_returns", True) \
            or not ground or not_last < NOT_LAST_GROUND_MIN or not_last < NOT_LAST_GROUND_SHARE * ground:
        return ""
    return (f"{WARNING_PREFIX}{not_last:,} of the {ground:,} ground points ({100 * not_last / ground:.0f} %) are not "
            "the last return of their pulse: the pulse went on below them, so the ground there is likely canopy "
            "(or roofs' edges), and the DTM lies on it. Check the DTM under vegetation; 'Filter only last returns' "
            "(--last-returns) keeps such points out of the ground, and another filter or setting may follow the "
            "terrain better.")


def demoted_note(had: int, demoted: int, algorithm=None) -> str:
    """The log's line when a filter made points the input had as ground (2) non-ground: a vendor's ground
    filtered again (a flood modeller's 35 embankment points went from 2 to 1 and the DTM there 1.9 m
    lower, without a word). "" when the input had none, or for the DTM from classes (its ground is theirs)."""
    if not had or not demoted or getattr(algorithm, "ground_of_any_class", False) \
            or getattr(algorithm, "predicts_classes", False):
        return ""
    return (f"{demoted:,} of the {had:,} points the input had as ground (2) are not ground now: the filter decided "
            "again. To make a DTM from the input's ground as it is, use 'DTM from classified points' "
            "(groundsieve:dtm).")


def replaced_classes(classification: np.ndarray, touched: np.ndarray) -> dict:
    """{class: points} of the input classes other than 0, 1, 2 among the points ``touched`` (given a
    new class by the run)."""
    replaced = classification[touched & ~np.isin(classification, REWRITTEN_CLASSES)]
    codes, counts = np.unique(replaced, return_counts=True)
    return {int(c): int(n) for c, n in zip(codes, counts)}


def _keep_advice(algorithm) -> str:
    """How to keep the input's classes: for an ``algorithm`` whose run has no way to (``keeps_classes``
    False: rfclassify), the filter that has."""
    if getattr(algorithm, "keeps_classes", True):
        return "tick Keep existing classes other than 0, 1, 2 (--keep-classes)"
    return ("run the model in the learned hybrid filter (groundsieve:hybrid, MODEL) with Keep existing classes "
            "other than 0, 1, 2")


def replaced_note(counts: dict, algorithm=None) -> str:
    """The log's line on the input's classes the run replaced ("" if none): a vendor's water (9)
    silently became ground and entered a forester's DTM. None for a model of its own classes (rfclassify's
    C1-C5: the input's 3, 5 and 6 "replaced" by the model's 3, 5 and 6, a code reviewer), as its whole run."""
    if not counts or getattr(algorithm, "predicts_classes", False):
        return ""
    from ..io.clouds import class_counts_text
    parts = class_counts_text(counts)
    return (f"Classes of the input replaced by ground (2) or non-ground (1): {parts}. To keep them, "
            f"{_keep_advice(algorithm)}; to add one to the DTM, name it in the DTM classes.")


#: Classes of the input that are never terrain (building, wires and towers, bridge deck, overhead
#: structure): their points made ground by a filter are a warning, not a note.
STRUCTURE_CLASSES = (6, 13, 14, 15, 16, 17, 19)


def structures_made_ground(classification: np.ndarray, ground: np.ndarray) -> dict:
    """{class: points} of the input's :data:`STRUCTURE_CLASSES` among the points made ``ground``."""
    made = classification[ground & np.isin(classification, STRUCTURE_CLASSES)]
    codes, counts = np.unique(made, return_counts=True)
    return {int(c): int(n) for c, n in zip(codes, counts)}


def structures_warning(made_ground: dict, replaced: dict, where: str, algorithm=None) -> str:
    """The warning ("" if none) on the points of an input's structure classes that the run made
    ground: a vendor's bridge deck (17) whose points became ground put a 4 m dam across the river
    under it in a flood modeller's DTM, told only by the note on replaced classes."""
    if not made_ground or getattr(algorithm, "predicts_classes", False):
        return ""
    from ..learn.report import ASPRS_NAMES
    parts = ", ".join(f"{n:,} of {replaced.get(c, n):,} {ASPRS_NAMES.get(c, 'class ' + str(c))} ({c})"
                      for c, n in sorted(made_ground.items()))
    return (f"{WARNING_PREFIX}{where}: {parts} point(s) of the input became ground, and a DTM takes them for "
            f"terrain (a bridge deck made ground dams the river under it). To keep them as they are and out of "
            f"the DTM, {_keep_advice(algorithm)}.")


def _codes(codes) -> str:
    return "(" + (", ".join(map(str, codes)) if codes else "none") + ")"


#: Peak bytes per DTM cell: the raster, and for the fill outside the hull the distance
#: transform's indices, and the written copy (measured 30-33 bytes, bench/fill_memory.py --dtm).
DTM_BYTES_PER_CELL = 40


def dtm_points(cloud: PointCloud, ground: np.ndarray, processable_mask: np.ndarray, options: DTMOptions) -> np.ndarray:
    """The points a DTM is made from: the ground, and the processable points (neither withheld nor
    ignored) whose class in the input is one of ``options.classes``."""
    if not options.classes:
        return ground
    return ground | (np.isin(cloud.classification, options.classes) & processable_mask)


def kept_out_of_dtm(cloud: PointCloud, classification: np.ndarray, processable_mask: np.ndarray,
                    options: DTMOptions, algorithm=None) -> dict:
    """{class: points} of the processable points that kept a class of their own (kept classes:
    neither 0, 1 nor 2) and stay out of the DTM (not one of ``options.classes``). For an algorithm whose
    ground is the input's classes (``ground_of_any_class``), every class of the input left out, 0, 1 and 2
    too (the DTM from classes said nothing of the class 2 it left out when given other classes: a surveyor):
    give it ``processable_mask`` without the ground."""
    if getattr(algorithm, "ground_of_any_class", False):
        classification = cloud.classification
        out = processable_mask.copy()
    else:
        out = ~np.isin(classification, REWRITTEN_CLASSES) & processable_mask
    if options.classes:
        out &= ~np.isin(cloud.classification, options.classes)
    from ..io.clouds import count_classes
    return count_classes(classification[out])  # (np.unique sorted them: 0.9 s on 50 M points, 0.2 s so)


def kept_out_note(counts: dict, algorithm=None, dtm: Optional["DTMOptions"] = None) -> str:
    """The log's line on points kept in classes of their own and left out of the DTM ("" if none); for an
    ``algorithm`` whose ground is the input's classes (the DTM from classes), on every class left out. With
    ``dtm``: what the DTM does where they are (interpolated across them, or empty farther than its maximum
    distance), and the advice to name a class only where none is named (a flood modeller read it with 9
    named)."""
    if not counts:
        return ""
    from ..io.clouds import class_counts_text
    parts = class_counts_text(counts)
    across = ("the DTM is interpolated across them" if dtm is None or not dtm.max_distance_m else
              f"the DTM is interpolated across them up to {dtm.max_distance_m:g} from the ground, and empty farther")
    if getattr(algorithm, "ground_of_any_class", False):
        return f"DTM: {sum(counts.values()):,} points of other classes stay out of it ({parts}); {across}."
    advice = ("" if dtm is not None and dtm.classes else " To make it hold a class (e.g. 9, the water surface, for a "
              "flood model), name it in the DTM classes.")
    return (f"DTM: {sum(counts.values()):,} points kept in classes of their own are not ground and stay out of "
            f"it ({parts}); {across}.{advice}")


def check_classes_wanted(input_path: str, algorithm, options: FilterOptions) -> None:
    """Refuse, before any work, a run whose ground is the input's classes (``ground_of_any_class``) on a
    text file, which has none, or with a ground class that is also ignored (a surveyor's ``--classes 2
    --ignore-classes 2`` ran, and said the file had no point of class 2)."""
    if not getattr(algorithm, "ground_of_any_class", False):
        return
    if _ext(input_path) in TEXT_EXTENSIONS:
        raise InputError(f"{input_path}: a text file carries no classes; give a classified LAS/LAZ file")
    both = sorted(set(getattr(algorithm, "classes", ())) & set(options.ignored))
    if both:
        raise InvalidParameterError(f"the ground classes and the ignored classes both name {_codes(both)}: a class "
                                    "cannot make the DTM and be left out of it")


#: classes that are no terrain: a DTM from classes that holds them is said to (a flood modeller's 2,17 put the
#: bridge deck in the terrain without a word)
NOT_TERRAIN = {6: "building", 17: "bridge deck", 19: "overhead structure", 13: "wire guard", 14: "wire conductor",
               15: "transmission tower", 5: "high vegetation", 18: "high noise", 7: "low noise"}


def not_terrain_warning(algorithm) -> str:
    """A warning when the ground classes of a DTM from classes hold classes that are no terrain ("" if not)."""
    named = [c for c in getattr(algorithm, "classes", ()) if c in NOT_TERRAIN]
    if not getattr(algorithm, "ground_of_any_class", False) or not named:
        return ""
    return (f"{WARNING_PREFIX}the ground classes hold {', '.join(f'{c} ({NOT_TERRAIN[c]})' for c in named)}: the DTM "
            "takes their points as terrain (a bridge deck, a roof). Leave them out unless you mean it.")


def check_model_units(algorithm, input_path: str, crs_wkt, log) -> None:
    """For a filter that runs a model (the hybrid filter, rfclassify's on surveys): refuse a cloud
    whose CRS unit is not the one its model was trained in (learning.check_model_unit; a model
    trained in feet ran on metres without a word). The shipped models say no unit (trained on the
    ISPRS text samples, in metres): the CRS warning said before the work covers them."""
    model = getattr(algorithm, "model", None)
    if model is None or not getattr(model, "meta", {}).get("crs_unit"):
        return
    from .learning import check_model_unit
    check_model_unit(model, getattr(algorithm, "model_path", "") or "the model", input_path, crs_wkt, log)


def length_fields(algorithm) -> List[str]:
    """The fields of a table filter (core/engine/parameters.py) that are lengths or heights: the dialog's
    in m (cells, windows, thresholds, SMRF's scalar, m per unit slope) and the core's finer settings
    named ``*_m``; [] for another algorithm (the hybrid filter's model says its own unit)."""
    from . import parameters as P
    name = getattr(algorithm, "name", None)
    if name not in P.FILTERS or not isinstance(algorithm, P.filter_class(name)):
        return []
    shown = [p.field for p in P.params(name) if p.unit.startswith("m")]
    finer = [f.name for f in P.core_only_fields(name)
             if f.name.endswith("_m") and isinstance(f.default, float)]
    return shown + finer


def defaults_in_crs_unit(algorithm, dtm: Optional["DTMOptions"], crs_wkt: Optional[str], path: str, log):
    """``algorithm`` and ``dtm`` with the lengths in metres converted to the CRS's unit when x, y and z
    share one other than the metre (feet): a surveyor's state-plane cloud in US survey feet ran SMRF
    with an 18 ft window, which left 16,566 of 23,305 building points ground (3.95 % total error; 0.95 %
    converted). In metres: the filter's defaults and a preset's values (shipped presets, and tune's,
    which tunes in metres); in the CRS's unit: what the user set (parameters.user_set: a dialog value
    other than the default, an option typed on the command line; unit_warning says so). A preset whose
    cell alone was converted ran its other lengths in feet (a code reviewer: 12.4 % total error). A filter
    built by the Python API, which notes nothing, has the fields equal to their defaults converted. The
    DTM cell is converted when it is the default and not set by the user (DTMOptions.cell_set). Converting
    twice changes nothing."""
    from ..raster.crs import horizontal_unit, metres_per_unit
    factor = metres_per_unit(crs_wkt)
    if factor is None:
        return algorithm, dtm
    unit = horizontal_unit(crs_wkt)
    from . import parameters as P
    fields = length_fields(algorithm)
    changed = {}
    if not fields and getattr(algorithm, "metres_per_unit", None) == 1.0 and dataclasses.is_dataclass(algorithm):
        # (an algorithm without lengths of the table, whose built-in lengths follow the unit: the DTM from
        # classes' tile buffer)
        algorithm = dataclasses.replace(algorithm, metres_per_unit=factor)
    if fields:
        chosen = P.user_set(algorithm)
        if chosen is None:  # (built by the Python API: a field equal to its default is the default)
            defaults = {f.name: f.default for f in dataclasses.fields(algorithm) if f.name in fields}
            metres = [k for k, d in defaults.items() if getattr(algorithm, k) == d]
        else:  # the defaults and a preset's values are metres; what the user set is in the CRS's unit
            metres = [k for k in fields if k not in chosen]
        changed = {k: getattr(algorithm, k) / factor for k in metres if getattr(algorithm, k)}
        if hasattr(algorithm, "metres_per_unit") and algorithm.metres_per_unit == 1.0:
            changed["metres_per_unit"] = factor  # the filter's built-in lengths (CSF's, PTD's, SMRF's)
    if changed:
        names = {fld: key for key, fld in P.preset_names(algorithm.name).items()}
    said = [f"{names[k]} {v:.4g}" for k, v in changed.items() if k != "metres_per_unit"]
    if changed:  # (the user's fields stay noted: a second call, a tiled run after the whole run's, converts nothing)
        algorithm = P.mark_user_set(dataclasses.replace(algorithm, **changed), set(fields))
    if dtm is not None and dtm.metres_per_unit == 1.0:
        dtm = dataclasses.replace(dtm, metres_per_unit=factor)
    if dtm is not None and not dtm.cell_set and dtm.cell_size_m == DTMOptions.cell_size_m:
        dtm = dataclasses.replace(dtm, cell_size_m=dtm_cell_in_unit(factor))
        said.append(f"DTM cell {dtm.cell_size_m:.4g} (the whole number nearest 1 m, so that the cells fall on "
                    f"whole {length_label(factor)})" if dtm.cell_size_m != DTMOptions.cell_size_m / factor
                    else f"DTM cell {dtm.cell_size_m:.4g}")
    if said:
        log(f"{path}: the CRS's unit is {unit}: lengths in metres (the defaults, a preset's) are converted to it, "
            "and the run uses " + ", ".join(said) + f" ({unit}; 1 m = {1 / factor:.5g}). "
            f"Values you set are read in {unit}.")
    return algorithm, dtm


def dtm_cell_in_unit(metres_per_unit: float) -> float:
    """The default DTM cell (1 m) in a CRS's unit: the whole number of units nearest it when a unit is
    shorter than a metre (3 ft, not 3.2808: a DTM in feet whose cells fell on a lattice of 3.2808 ft
    (1999999.28 ...) snapped onto no other DTM of the county, a surveyor), else the exact conversion."""
    cell = DTMOptions.cell_size_m / metres_per_unit
    return float(round(cell)) if cell >= 1.5 else cell


def warn_about_units(path: str, infos, log) -> None:
    """Before any work: refuse a cloud in longitudes and latitudes, and say when the CRS is missing
    or not in metres (every length is read in its unit), from the files' headers ``infos``."""
    from ..raster.crs import check_lengths_unit
    infos = [i for i in infos if i.count] or list(infos)
    bounds = (min(i.mins[0] for i in infos), min(i.mins[1] for i in infos),
              max(i.maxs[0] for i in infos), max(i.maxs[1] for i in infos))
    warning = check_lengths_unit(path, infos[0].crs_wkt, bounds)
    if warning:
        log(WARNING_PREFIX + warning)
    conflicts = [i for i in infos if getattr(i, "crs_conflict", "")]
    if conflicts:
        more = f" (and {len(conflicts) - 1:,} more file(s) so)" if len(conflicts) > 1 else ""
        log(f"{WARNING_PREFIX}{conflicts[0].path}: its two CRS records disagree: {conflicts[0].crs_conflict}{more}. The "
            "WKT is taken, as LAS 1.4 and PDAL take it: check which is right, and rewrite the file with that one "
            "before you trust the DTM's place.")


def check_dtm_memory(x, y, options: DTMOptions) -> GridSpec:
    """The DTM grid over the points ``x, y`` (those that may enter it), its memory checked against
    the budget: called before the filter runs, so that a DTM too large is refused before any work."""
    if options.extent is not None and np.size(x):
        check_extent(options, float(np.min(x)), float(np.min(y)), float(np.max(x)), float(np.max(y)))
    with memory_budget(options.memory_budget_bytes):
        extent_grid(options)  # (the extent's grid, which the points' DTM is placed in, counted too)
        return GridSpec.covering(x, y, options.cell_size_m, what="DTM", bytes_per_cell=DTM_BYTES_PER_CELL,
                                 closed=True)


def _say_stray_points(x, y, grid: GridSpec, log, unit: str = "m") -> None:
    """Say when a few points far from the others stretch the DTM (one stray point 20 km away made a
    reviewer's DTM 80,120 x 240 cells, 0.3 % of them with a value)."""
    from ..grids.spec import isolated_points
    far, distance, core = isolated_points(x, y)
    if not far.size:
        return
    core_cells = (max(core[1] - core[0], grid.cell) / grid.cell + 1) * (max(core[3] - core[2], grid.cell) / grid.cell + 1)
    if grid.nrows * grid.ncols < 2 * core_cells:
        return
    k = int(np.argmax(distance))
    log(f"{WARNING_PREFIX}DTM: {far.size:,} point(s) lie far from the others (the farthest {distance[k]:,.0f} {unit} away, at x "
        f"{x[far[k]]:,.2f}, y {y[far[k]]:,.2f}): the DTM spans them, {grid.ncols:,} x {grid.nrows:,} cells, mostly "
        "empty. Class them as noise (7) to leave them out, or crop the cloud.")


def make_dtm(x, y, z, ground: np.ndarray, options: DTMOptions, why_none: str = "", path: str = "",
             steps: Optional[Steps] = None, log: Optional[Callable[[str], None]] = None):
    """DTM grid covering the points ``x, y`` (give only those that may enter a DTM: neither
    withheld nor ignored), interpolated from the ground points among them. The grid's memory is
    checked against the budget before it is allocated. ``why_none``: the filter's explanation when
    it found no ground point (quoted in the refusal); ``path``: the input, named in it."""
    from ..grids.rasterize import tin_dtm
    with memory_budget(options.memory_budget_bytes):
        grid = GridSpec.covering(x, y, options.cell_size_m, what="DTM", bytes_per_cell=DTM_BYTES_PER_CELL,
                                 closed=True)
    unit = length_label(options.metres_per_unit)  # (a cloud in feet: its lengths in feet)
    if log is not None:
        _say_stray_points(x, y, grid, log, unit)
        if grid.ncols * grid.nrows < 16:  # (a corridor, 400 x 2 cells, is a DTM of its own)
            log(f"{WARNING_PREFIX}DTM: a cell of {options.cell_size_m:g} makes {grid.ncols:,} x {grid.nrows:,} cells over "
                f"points spanning {float(np.ptp(x)):,.1f} x {float(np.ptp(y)):,.1f}: a DTM of a few cells. The cell "
                "size is in the CRS's unit (metres for most); choose one near the ground points' spacing.")
    if not ground.any():
        raise InvalidParameterError((f"{path}: " if path else "")
                                    + "the filter found no ground point: no DTM can be made"
                                    + (f". Why: {why_none}" if why_none else ""))
    # threads=None: the whole cloud's DTM in strips on numba's threads (a tile's, in the tiled
    # engine, runs on one core: its workers run the tiles in parallel)
    dtm = tin_dtm(x[ground], y[ground], z[ground], grid, fill_outside=options.fill_outside_hull,
                  points_per_cell=options.points_per_cell, threads=None, steps=steps, log=log,
                  max_distance=options.max_distance_m, unit=unit)
    if log is not None and not options.fill_outside_hull:
        note = dtm_spacing_note(int(ground.sum()), int(np.count_nonzero(np.isfinite(dtm))), grid.cell, unit)
        if note:
            log(note)
        if not options.max_distance_m:
            note = gaps_note(*data_gaps(x, y, dtm, grid), unit)
            if note:
                log(note)
    if log is not None:
        note = floating_note(*points_below(x, y, z, dtm, grid, options.metres_per_unit), options.metres_per_unit, unit)
        if note:
            log(note)
        from ..grids.rasterize import PIT_DEPTH, isolated_pits_and_spikes
        pits, spikes = isolated_pits_and_spikes(dtm, depth=PIT_DEPTH / options.metres_per_unit,
                                                check=steps.check if steps is not None else None)
        for note in (pits_note(*pits, grid, options.metres_per_unit),
                     pits_note(*spikes, grid, options.metres_per_unit, spikes=True)):
            if note:
                log(note)
    wanted = extent_grid(options)
    if wanted is not None:
        grid, dtm = wanted, place_in(dtm, grid, wanted)
        if log is not None:
            say_extent(wanted, int(np.count_nonzero(np.isfinite(dtm))), unit, log)
    return grid, dtm


def place_in(values: np.ndarray, grid: GridSpec, wanted: GridSpec) -> np.ndarray:
    """``values`` (on ``grid``) on the grid ``wanted`` (the same lattice): its cells that ``grid`` covers, the
    others NaN. The DTM is made over its points and placed in the extent: beyond the points it is nodata,
    filled or not, as a tiled run's, which has no block there (a code reviewer: a fill reached over the whole
    extent whole and not tiled)."""
    col0, row0 = grid.offset_of(wanted)
    out = np.full(wanted.shape, np.nan, dtype=values.dtype)
    r0, r1 = max(row0, 0), min(row0 + wanted.nrows, grid.nrows)
    c0, c1 = max(col0, 0), min(col0 + wanted.ncols, grid.ncols)
    if r0 < r1 and c0 < c1:
        out[r0 - row0:r1 - row0, c0 - col0:c1 - col0] = values[r0:r1, c0:c1]
    return out


def say_extent(grid: GridSpec, valued: Optional[int], unit: str, log, what: str = "the extent given") -> None:
    """The log's line on a DTM made for the extent given (``valued``: its cells with a value, None when not
    counted), a warning when none has one; ``what`` the grid is (one file's cells of it)."""
    x1, y0 = grid.x0 + grid.ncols * grid.cell, grid.top - grid.nrows * grid.cell
    line = (f"DTM: {what}, x {grid.x0:,.2f} to {x1:,.2f}, y {y0:,.2f} to {grid.top:,.2f} ({unit}, on "
            f"multiples of the cell): {grid.ncols:,} x {grid.nrows:,} cells"
            + (f", {valued:,} of them with a value." if valued is not None else "."))
    log(line if valued != 0 else f"{WARNING_PREFIX}{line} The extent holds no ground: is it in the cloud's CRS?")


def length_label(metres_per_unit: float) -> str:
    """How the log names lengths in the cloud's unit: "m", "ft" (international or US survey), else
    the unit's size in metres."""
    if abs(metres_per_unit - 1.0) < 1e-12:
        return "m"
    if abs(metres_per_unit - 0.3048) < 1e-5:
        return "ft"
    return f"units of {metres_per_unit:g} m"


#: a DTM with more than this share of the points that may enter it lying more than FLOATING_DEPTH_M below it floats
#: on vegetation: CSF's defaults on a generated steep forest had 36 % of the last returns more than 1 m below a DTM
#: about 4 m too high, with a clean log (a forester); SMRF, PTD, PMF and the hybrid there, and every filter on
#: lidR's and lasR's real plots, 0.0-0.25 % (CSF 3.3 % on a flatter generated forest)
FLOATING_SHARE = 0.02
#: and at least this many such points
FLOATING_MIN = 500
FLOATING_DEPTH_M = 1.0


def points_below(x, y, z, dtm: np.ndarray, grid, metres_per_unit: float = 1.0, row0: int = 0, col0: int = 0) -> list:
    """[points more than FLOATING_DEPTH_M below the DTM at their cell, points over a DTM cell with a value] of the
    points ``x, y, z``; ``dtm`` a block of the grid ``grid`` starting at (``row0``, ``col0``)."""
    if not len(x):
        return [0, 0]
    r, c = grid.row_of(np.asarray(y)) - row0, grid.col_of(np.asarray(x)) - col0
    inside = (r >= 0) & (r < dtm.shape[0]) & (c >= 0) & (c < dtm.shape[1])
    level = np.full(len(x), np.nan)
    level[inside] = dtm[r[inside], c[inside]]
    valued = np.isfinite(level)
    deep = valued & (np.asarray(z) < level - FLOATING_DEPTH_M / metres_per_unit)
    return [int(np.count_nonzero(deep)), int(np.count_nonzero(valued))]


def floating_note(below: int, total: int, metres_per_unit: float = 1.0, unit: str = "m") -> str:
    """A warning when many points lie well below the DTM (:func:`points_below`): the DTM floats on vegetation
    or on roofs there, where the filter missed the ground (steep slopes under canopy). "" otherwise."""
    if below < FLOATING_MIN or below < FLOATING_SHARE * total:
        return ""
    return (f"{WARNING_PREFIX}DTM: {below:,} of the {total:,} points over it ({100 * below / total:.1f} %) lie more than "
            f"{FLOATING_DEPTH_M / metres_per_unit:g} {unit} below it: the DTM floats above the ground there (a filter "
            "that missed the ground, on steep slopes under canopy most often; low noise is left out when classed 7). "
            "Look at the DTM with the points, and try another filter or setting (SMRF, PTD and the hybrid followed "
            "steep forest where CSF's defaults floated 4 m up).")


def pits_note(count: int, depth: float, row: int, col: int, grid, metres_per_unit: float = 1.0,
              spikes: bool = False) -> str:
    """What to say of a DTM's isolated pits (:func:`~groundsieve.core.grids.rasterize.isolated_pits`: the
    deepest at ``row``, ``col`` of ``grid``), "" without one. An archaeologist's hillshade showed 1-2 m pits that looked like post-holes: low
    points (multipath or noise echoes) that SMRF's low-outlier test lets through when less than 5 cells
    deep, made ground, with nothing in the log. A narrow, deep ditch sampled by few points is beaded
    into such pits too (a code reviewer: 1 m wide and 2 m deep, 0.5 m between points), so the note says
    both and asks for a look before any change. A warning (``--json``'s ``warnings``, QGIS's log in
    orange): a batch QA pipeline reads those only (a surveyor), and the pits were all a UAV reviewer's
    log said of blunders that had taken 96 % of the ground. ``spikes``: the same of the isolated spikes
    (the pits of the negated DTM)."""
    from ..grids.rasterize import PIT_DEPTH
    if not count:
        return ""
    x, y = grid.x0 + (col + 0.5) * grid.cell, grid.top - (row + 0.5) * grid.cell
    unit = length_label(metres_per_unit)  # (a cloud in feet: 0.5 m is 1.64 ft, and said so)
    if spikes:  # (``isolated_pits`` of the negated DTM: a surveyor's class 2 held points 20 m up, not a word)
        return (f"{WARNING_PREFIX}DTM: {count:,} isolated spike(s), cells more than {PIT_DEPTH / metres_per_unit:.3g} "
                f"{unit} above every other cell within 2 cells, the highest {depth:.2f} {unit} at x {x:,.2f}, y {y:,.2f}. "
                "Objects or high points made ground make them (a pole, a bird, a wire, a boulder's top, a point "
                "misclassified as ground): look at them before mapping them, and class such points as objects or "
                "noise (18) beforehand.")
    return (f"{WARNING_PREFIX}DTM: {count:,} isolated pit(s), cells more than {PIT_DEPTH / metres_per_unit:.3g} {unit} "
            f"below every other cell within 2 cells, the deepest {depth:.2f} {unit} at x {x:,.2f}, y {y:,.2f}. Low points made ground (multipath "
            "or noise echoes, image-matching blunders) make them, and so does a narrow, deep ditch sampled by few "
            "points: look at them before mapping them. Where they are low points, class those as noise (7) "
            "beforehand, or with SMRF lower the Low-outlier slope (1 catches points 1 m deep); in a cloud of surface "
            "points (photogrammetry) also set the Low-outlier share to 1 (the preset uav-photogrammetry-smrf.json "
            "sets both): there a few blunders can take the ground around them too.")


def dtm_spacing_note(points: int, valued_cells: int, cell: float, unit: str = "m") -> str:
    """What to say when the DTM's cells are much finer than its ground points are apart (on average
    over the cells with a value: more than 2 cells apart), "" otherwise. An archaeologist's 0.5 m DTMs
    of 1 point/m² data were mosaics of the TIN's triangles in the hillshade, without a word."""
    if points <= 0 or valued_cells <= 0:
        return ""
    spacing = cell * math.sqrt(valued_cells / points)
    if spacing < 2 * cell:
        return ""
    return (f"DTM: {points:,} ground points for {valued_cells:,} cells of {cell:g} {unit} with a value: about one point "
            f"every {spacing:.1f} {unit}, so most cells are interpolated between points, and a hillshade shows the "
            f"triangles between them rather than finer terrain. A cell of about {spacing:.1f} {unit} shows what the "
            "data hold.")


#: a gap is blocks of this many times the points' mean spacing on a side with no point in them (the
#: chance that such a block is empty where the points are spread at random: e^-25)
GAP_BLOCK_SPACINGS = 5
#: ... and the blocks a gap holds at least, to be named
GAP_MIN_BLOCKS = 4
#: points binned at a time (the memory of data_gaps stays a few dozen MB)
GAP_CHUNK = 2_000_000


def data_gaps(x, y, dtm: np.ndarray, grid: GridSpec) -> tuple:
    """The gaps in the data the DTM has values over: blocks of GAP_BLOCK_SPACINGS point spacings with no
    point at all (``x, y``: every point that may enter a DTM), GAP_MIN_BLOCKS or more together, whose cells
    the triangulation filled (water without returns, a missing strip, a shadow of image matching). Returns
    ([(area, x, y) of each gap's blocks and their centre], the smallest area named)."""
    valued = np.isfinite(dtm)
    if x.size == 0 or not valued.any():
        return [], 0.0
    cell = grid.cell
    spacing = cell * math.sqrt(np.count_nonzero(valued) / x.size)
    k = max(1, int(math.ceil(GAP_BLOCK_SPACINGS * spacing / cell)))  # the block's side in cells
    side = k * cell
    rows, cols = -(-grid.nrows // k), -(-grid.ncols // k)
    if rows * cols < GAP_MIN_BLOCKS:
        return [], GAP_MIN_BLOCKS * side * side
    points = np.zeros(rows * cols, dtype=np.int64)
    x, y = np.asarray(x), np.asarray(y)
    for start in range(0, x.size, GAP_CHUNK):  # (in chunks: 50 M points took 1.2 GB more at once; a code reviewer)
        col = ((x[start:start + GAP_CHUNK] - grid.x0) / cell).astype(np.int64)
        col //= k
        np.clip(col, 0, cols - 1, out=col)
        row = ((grid.top - y[start:start + GAP_CHUNK]) / cell).astype(np.int64)
        row //= k
        np.clip(row, 0, rows - 1, out=row)
        row *= cols
        row += col
        points += np.bincount(row, minlength=rows * cols)
    points = points.reshape(rows, cols)
    padded = np.zeros((rows * k, cols * k), dtype=bool)
    padded[:grid.nrows, :grid.ncols] = valued
    filled = padded.reshape(rows, k, cols, k).mean(axis=(1, 3)) > 0.5
    from scipy import ndimage
    labels, found = ndimage.label((points == 0) & filled)
    if not found:
        return [], GAP_MIN_BLOCKS * side * side
    sizes = np.bincount(labels.ravel())[1:]
    big = np.flatnonzero(sizes >= GAP_MIN_BLOCKS)
    centres = ndimage.center_of_mass(np.ones_like(labels), labels, big + 1) if big.size else []
    gaps = [(float(sizes[b] * side * side), grid.x0 + (c + 0.5) * side, grid.top - (r + 0.5) * side)
            for b, (r, c) in zip(big, centres)]
    return gaps, GAP_MIN_BLOCKS * side * side


def gaps_note(gaps, smallest: float, unit: str = "m") -> str:
    """The log's line on the gaps :func:`data_gaps` found ("" when none). A tiled run leaves gaps wider than
    its buffer empty and warns; a whole run interpolated across them without a word (a UAV photogrammetry
    practitioner). A warning: the DTM's values there are not measured, and a QA pipeline reads the
    warnings (``--json``) alone (an HPC reviewer)."""
    if not gaps:
        return ""
    area, cx, cy = max(gaps)
    return (f"{WARNING_PREFIX}DTM: the data have {len(gaps):,} gap(s) of {smallest:,.0f} {unit}² or more without any point (the largest "
            f"about {area:,.0f} {unit}² around x {cx:,.0f}, y {cy:,.0f}), which the triangulation interpolates across: "
            "the DTM's values there are not measured (water without returns, a missing strip, a shadow of the image "
            "matching). To leave such gaps empty, set 'DTM: leave cells farther than this from any ground point "
            "empty' below the gaps' half-width but above half the widest building, if any (the cells under a roof are that "
            "far from the ground).")


def check_outputs(input_path: str, output_path: Optional[str], raster_paths=()) -> None:
    """Refuse bad output paths before any work: wrong extension, missing folder, the input itself,
    two outputs on one file (``raster_paths`` may be paths or ``(label, path)`` pairs)."""
    from ..raster.geotiff import check_raster_path
    labelled = [item if isinstance(item, tuple) else (f"raster {i + 1}" if i else "DTM", item)
                for i, item in enumerate(raster_paths)]
    check_distinct_outputs([("classified point cloud", output_path), *labelled])
    if output_path:
        check_output_path(output_path, inputs=[input_path])
        from ..io.clouds import check_laz_wave_packets
        check_laz_wave_packets(input_path, output_path)
    for _label, path in labelled:
        if path:
            check_raster_path(path, inputs=[input_path, output_path])


def write_outputs(cloud: PointCloud, classification: np.ndarray, output_path: Optional[str],
                  rasters=(), steps: Optional[Steps] = None, log: Optional[Callable[[str], None]] = None,
                  cloud_share: float = 0.9) -> None:
    """Write the classified cloud and the rasters ``[(path, values, grid), ...]`` (GeoTIFF, the
    cloud's CRS). Every output goes to a temporary file first; all are renamed into place only
    once all are complete and no cancellation came, so a failed or cancelled run leaves none.
    ``cloud_share``: the part of ``steps`` the cloud takes when there are rasters too; ``steps``
    reaches 1.0 only once every output is in place."""
    from ..raster.geotiff import write_geotiff
    steps = steps or Steps()
    log = log or (lambda _msg: None)
    share = cloud_share if (output_path and rasters) else (1.0 if output_path else 0.0)
    from ..io.outputs import StagedOutputs
    with StagedOutputs() as staging:
        if output_path:
            log(f"Writing {len(cloud):,} classified points to {output_path} ...")
            write_classified(cloud, classification, staging.stage(output_path), atomic=False,
                             steps=steps.sub(0.0, share * 0.99), name=output_path)
        for i, (path, values, grid, *how) in enumerate(rasters):  # how: write_geotiff's options, if any
            log(f"Writing {path} ...")
            write_geotiff(staging.stage(path), values, grid, crs_wkt=cloud.crs_wkt, atomic=False, name=path,
                          **(how[0] if how else {}))
            steps.report(share + (1 - share) * 0.99 * (i + 1) / len(rasters))
        steps.check()
        staging.commit()  # all or none (a failed rename puts back what was there)
    steps.report(1.0)


#: Seconds per point of each stage of a whole-cloud run, measured on this 2-core machine on a
#: 5.1 M point LAZ (scripts/desktop_profile.py); only their ratios matter: they share the
#: progress bar out so that it moves at a steady pace. Filters not listed take FILTER_S_DEFAULT.
READ_S = {".laz": 4.9e-7, ".las": 1.0e-7}
WRITE_S = {".laz": 2.8e-7, ".las": 6.0e-8}
FILTER_S = {"SMRF": 5.5e-7, "CSF": 1.2e-6, "PMF": 5.5e-7}
FILTER_S_DEFAULT = 1.0e-6
DTM_S = 4.5e-7           #: per point of the cloud (two thirds ground, thinned to 4 per cell of 1 m; strips)


def stage_weights(input_path: str, output_path: Optional[str], algorithm, dtm: bool, n_rasters: int):
    """Fractions of the progress bar for reading, filtering, the DTM and writing (sum 1)."""
    import os
    ext_in = os.path.splitext(input_path)[1].lower()
    ext_out = os.path.splitext(output_path or "")[1].lower()
    read = READ_S.get(ext_in, 3e-7)
    filt = FILTER_S.get(type(algorithm).__name__, FILTER_S_DEFAULT)
    make = DTM_S if dtm else 0.0
    write = (WRITE_S.get(ext_out, 1e-7) if output_path else 0.0) + 2e-9 * (n_rasters + bool(dtm))
    total = read + filt + make + write
    return read / total, filt / total, make / total, write / total


def run_ground_filter(input_path: str, output_path: Optional[str], algorithm, *,
                      options: FilterOptions = FilterOptions(),
                      dtm_path: Optional[str] = None, dtm: DTMOptions = DTMOptions(),
                      rasters: Optional[dict] = None,
                      progress: Optional[Callable[[float], None]] = None,
                      is_cancelled: Optional[Callable[[], bool]] = None,
                      log: Optional[Callable[[str], None]] = None) -> FilterRun:
    """Read ``input_path``, classify ground with ``algorithm``, write ``output_path`` (LAS/LAZ)
    and optionally ``dtm_path`` (GeoTIFF). ``rasters`` maps more GeoTIFF paths to functions
    ``f(run) -> (values, grid)`` (e.g. the intermediate grids a filter keeps in ``run.detail``).
    All outputs are written to temporary files and renamed together at the end: a failed or
    cancelled run leaves none of them. The input file is never modified."""
    from .tiles import refuse_in_a_workers_import
    refuse_in_a_workers_import()
    input_path, output_path, dtm_path = _path(input_path, "input"), _path(output_path, "output"), _path(dtm_path, "DTM")
    options = FilterOptions() if options is None else options
    dtm = DTMOptions() if dtm is None else dtm
    from .one_file import check_only
    check_only(options.tiling, input_path, output_path, dtm_path, *(rasters or {}))
    algorithm = _filter_of(algorithm)
    steps = Steps(progress, is_cancelled)
    from ..progress import collecting_warnings
    said, log = collecting_warnings(log)
    run = _run_ground_filter(input_path, output_path, algorithm, options, dtm_path, dtm, rasters, steps, log)
    run.warnings = said
    return run


def _path(path, what: str) -> Optional[str]:
    """``path`` as text (a ``pathlib.Path`` or any path-like; None stays None)."""
    if path is None:
        return None
    try:
        return os.fspath(path)
    except TypeError:
        raise InvalidParameterError(f"the {what} must be a path (got {type(path).__name__} {path!r})") from None


def _filter_of(algorithm):
    """``algorithm``, or the filter a name gives with its defaults ("smrf", as tune and presets take it)."""
    if isinstance(algorithm, str):
        from . import parameters as P
        return P.filter_class(algorithm)()
    if isinstance(algorithm, type) and callable(getattr(algorithm, "run", None)):
        return algorithm()  # (a filter's class, SMRF for SMRF(): its defaults; a TypeError after the read before)
    if not callable(getattr(algorithm, "run", None)) and not callable(algorithm):
        raise InvalidParameterError(f"the filter must be a filter object (e.g. SMRF()) or a filter's name "
                                    f"(got {type(algorithm).__name__})")
    return algorithm


def _run_ground_filter(input_path, output_path, algorithm, options, dtm_path, dtm, rasters, steps, log):
    from ..machine import check_address_space, fit_address_space
    fit_address_space()  # (under ulimit -v: before the run starts its threads)
    check_address_space(options.tiling.worker_count if options.tiling is not None else 1)
    rasters = {path: fn for path, fn in (rasters or {}).items() if path}
    check_classes_wanted(input_path, algorithm, options)
    warning = not_terrain_warning(algorithm)
    if warning:
        log(warning)
    describe = getattr(algorithm, "describe", None)
    if callable(describe):  # a filter whose parameters are not a table's (the hybrid: its model)
        log(describe())
    from .tiles import needs_tiling, run_tiled
    header = None
    if _ext(input_path) in LAS_EXTENSIONS and os.path.isfile(input_path):
        from ..io.lasfiles import scan_header
        try:
            header = scan_header(input_path)
        except GroundSieveError:
            header = None  # said below, after the outputs are checked, as before
        else:
            algorithm, dtm = defaults_in_crs_unit(algorithm, dtm, header.crs_wkt, input_path, log)
    if needs_tiling(input_path, options.tiling, algorithm, dtm if dtm_path else None, log):
        # A folder, a .vpc, a set tile size or a cloud beyond the memory budget: buffered tiles.
        if rasters:
            from .tiles import is_survey_input
            tiling = options.tiling
            why = ("it is a survey (a folder or a .vpc), run in tiles" if is_survey_input(input_path) else
                   "a tile size is set" if tiling is not None and tiling.tile_size_m else
                   "a Dask scheduler is set, whose workers run it in tiles" if tiling is not None and tiling.scheduler
                   else "it is beyond the memory budget, so it would be run in tiles")
            raise InvalidParameterError(
                f"{input_path}: the filter's intermediate grids are made for one cloud in memory, and {why}; "
                "leave those outputs empty, or (for one file) set a larger memory budget (e.g. 8000 MB), "
                "no tile size and no scheduler")
        return run_tiled(input_path, output_path, algorithm, options=options, dtm_path=dtm_path, dtm=dtm,
                         steps=steps, log=log)
    if not os.path.exists(input_path):  # before the outputs: a mistyped input explains the rest
        raise InputError(f"{input_path}: no such file or folder")
    from ..machine import warm_blas
    warm_blas(1)  # (under ulimit -v: OpenBLAS's buffer for this thread's fills, taken before the cloud is read)
    check_outputs(input_path, output_path, [dtm_path, *rasters])
    if _ext(input_path) in LAS_EXTENSIONS:
        from ..io.lasfiles import scan_header
        header = header or scan_header(input_path)
        warn_about_units(input_path, [header], log)
        check_model_units(algorithm, input_path, header.crs_wkt, log)
    elif _ext(input_path) in TEXT_EXTENSIONS and (output_path or dtm_path or rasters):
        log(f"{WARNING_PREFIX}{input_path}: a text file carries no CRS; the outputs have none either (assign one in "
            "QGIS: the layer's Properties > Source, or Assign projection for a raster).")
    steps.check()
    w_read, w_filter, w_dtm, _w_write = stage_weights(input_path, output_path, algorithm, bool(dtm_path),
                                                      len(rasters))
    at_filter, at_dtm = w_read, w_read + w_filter
    at_write = at_dtm + w_dtm
    log(f"Reading {input_path} ...")
    cloud = read_cloud(input_path, steps.sub(0.0, w_read * 0.97))
    log(f"Read {len(cloud):,} points from {input_path}.")
    area = processable(cloud, options)
    if dtm_path and area.any():  # a DTM too large for the memory is refused before the filter's work
        check_dtm_memory(*_where(area, cloud.x, cloud.y), dtm)
    steps.report(at_filter)
    log(getattr(algorithm, "stage_line", "") or f"Filtering ({type(algorithm).__name__}) ...")
    done = classify_cloud(cloud, algorithm, options, steps.sub(at_filter, at_dtm), log)
    cls, ground = done.classification, done.ground
    log(f"Ground: {int(ground.sum()):,} of {int(done.filtered.sum()):,} "
        + (f"points, of the ground classes ({ground_classes_counts(cloud.classification[ground], classes=algorithm.classes)})."
           if getattr(algorithm, "ground_of_any_class", False) else "filtered points."))
    run = FilterRun(cloud, cls, ground, done.filtered, detail=done.detail, algorithm=algorithm)
    if dtm_path:
        # The DTM spans only the points that may enter it: not withheld, not ignored (noise may lie far away).
        area = done.processable
        note = kept_out_note(kept_out_of_dtm(cloud, cls, area & ~ground, dtm, algorithm), algorithm, dtm) if options.keep_existing_classes else ""
        if note:
            log(note)
        run.dtm_grid, run.dtm = make_dtm(*_where(area, cloud.x, cloud.y, cloud.z, dtm_points(cloud, ground, area, dtm)),
                                         dtm, getattr(done.detail, "no_ground_reason", ""), input_path,
                                         steps.sub(at_dtm, at_write), log)
    steps.report(at_write)
    extra = [(path, *make(run)) for path, make in rasters.items()]
    if dtm_path:
        extra.insert(0, (dtm_path, run.dtm, run.dtm_grid, {"elevation": True}))
    write_outputs(cloud, cls, output_path, extra, steps.sub(at_write, 1.0), log)
    steps.report(1.0)
    run.inputs, run.outputs, run.dtm_path = [input_path], [output_path] if output_path else [], dtm_path
    return run
