"""The driver shared by every ground filter: from a file to a classified file and a DTM.

A filter (e.g. :class:`~groundsieve.core.filters.smrf.SMRF`) only maps the x, y, z of the
points it is given to a ground mask. This module does the rest, the same for every
filter: select the points to filter (drop noise, optionally keep only last returns),
write ASPRS classes (2 ground, 1 other, or keep the other existing classes), write
the classified cloud and the DTM, report progress, honour cancellation.
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from ..errors import InvalidParameterError
from ..grids.spec import GridSpec
from ..io import (CLASS_GROUND, CLASS_UNCLASSIFIED, NOISE_CLASSES, PointCloud, atomic_path, check_output_path,
                 read_cloud, write_classified)
from ..progress import Steps
from .tiles import TileOptions


@dataclass(frozen=True)
class FilterOptions:
    """What the driver does around the filter."""
    last_returns_only: bool = False
    ignore_noise: bool = True
    keep_existing_classes: bool = False
    #: survey scale: tile size, buffer, memory budget, workers, working folder (engine/tiles.py)
    tiling: TileOptions = TileOptions()


@dataclass(frozen=True)
class DTMOptions:
    cell_size_m: float = 1.0
    fill_outside_hull: bool = False
    #: ground points triangulated per DTM cell at most (0 = all; see rasterize.tin_dtm)
    points_per_cell: int = 4

    def __post_init__(self):
        if not (math.isfinite(self.cell_size_m) and self.cell_size_m > 0):
            raise InvalidParameterError(f"DTM cell size must be > 0 m (got {self.cell_size_m})")
        if int(self.points_per_cell) != self.points_per_cell or self.points_per_cell < 0:
            raise InvalidParameterError(f"points_per_cell must be a whole number >= 0 (got {self.points_per_cell})")


@dataclass
class FilterRun:
    cloud: PointCloud
    classification: np.ndarray
    ground: np.ndarray          #: bool per point of the cloud
    filtered: np.ndarray        #: bool per point: was given to the filter
    dtm_grid: Optional[GridSpec] = None
    dtm: Optional[np.ndarray] = None
    detail: object = None       #: what the filter's ``run`` returned (see call_filter)

    @property
    def ground_count(self) -> int:
        return int(self.ground.sum())


def select_points(cloud: PointCloud, options: FilterOptions) -> np.ndarray:
    """Boolean mask of the points the filter sees."""
    keep = np.ones(len(cloud), dtype=bool)
    if options.ignore_noise:
        keep &= ~np.isin(cloud.classification, NOISE_CLASSES)
    if options.last_returns_only and cloud.has_return_info:
        rn, nr = cloud.return_number, cloud.number_of_returns
        # A return is last when its number equals the count; files that leave both 0 count as single.
        keep &= (rn >= nr) | (nr == 0)
    return keep


@dataclass
class Classified:
    classification: np.ndarray  #: uint8 ASPRS classes of every point
    ground: np.ndarray          #: bool per point
    filtered: np.ndarray        #: bool per point: given to the filter
    detail: object = None       #: what the filter's ``run`` returned (grids, ...), if it has one


def call_filter(algorithm, cloud: PointCloud, idx: np.ndarray, steps: Steps, log):
    """Run one filter on the points ``idx`` of ``cloud``.

    The protocol every filter follows: ``run(xyz, steps=..., **fields)`` returns an object with
    a boolean ``ground`` (and whatever else the filter wants to show, e.g. grids); plain
    callables ``f(xyz, steps=...) -> ground`` work too. A filter that needs per-point
    attributes names them in ``point_fields`` (e.g. ``("return_number", "number_of_returns")``)
    and gets them as keyword arrays; one that has something to tell the user sets
    ``wants_log = True`` and gets ``log``.
    """
    xyz = np.column_stack([cloud.x[idx], cloud.y[idx], cloud.z[idx]])
    extra = {name: np.ascontiguousarray(getattr(cloud, name)[idx])
             for name in getattr(algorithm, "point_fields", ())}
    if getattr(algorithm, "wants_log", False):
        extra["log"] = log
    if hasattr(algorithm, "run"):
        detail = algorithm.run(xyz, steps=steps, **extra)
        return np.asarray(detail.ground, dtype=bool), detail
    return np.asarray(algorithm(xyz, steps=steps, **extra), dtype=bool), None


def classify_cloud(cloud: PointCloud, algorithm, options: FilterOptions = FilterOptions(),
                   steps: Optional[Steps] = None, log: Optional[Callable[[str], None]] = None) -> Classified:
    """Run ``algorithm`` on the selected points and give every point its ASPRS class."""
    steps = steps or Steps()
    log = log or (lambda _msg: None)
    filtered = select_points(cloud, options)
    n_sel = int(filtered.sum())
    if n_sel == 0:
        raise InvalidParameterError(f"{cloud.path}: no point is left to filter "
                                    "(all are noise, or none is a last return)")
    if n_sel < len(cloud):
        log(f"Filtering {n_sel:,} of {len(cloud):,} points (noise or non-last returns left out).")
    idx = np.flatnonzero(filtered)
    sub_ground, detail = call_filter(algorithm, cloud, idx, steps, log)
    ground = np.zeros(len(cloud), dtype=bool)
    ground[idx[sub_ground]] = True
    # Every point but ignored noise gets a new class: non-last returns are not ground either.
    cls = cloud.classification.copy()
    touched = ~np.isin(cls, NOISE_CLASSES) if options.ignore_noise else np.ones(len(cloud), dtype=bool)
    if options.keep_existing_classes:
        touched &= cls == CLASS_GROUND  # only a former ground class is taken away
    cls[touched] = CLASS_UNCLASSIFIED
    cls[ground] = CLASS_GROUND
    return Classified(cls.astype(np.uint8), ground, filtered, detail)


def make_dtm(x, y, z, ground: np.ndarray, options: DTMOptions):
    """DTM grid covering all the points, interpolated from the ground points."""
    from ..grids.rasterize import tin_dtm
    grid = GridSpec.covering(x, y, options.cell_size_m, what="DTM")
    if not ground.any():
        raise InvalidParameterError("the filter found no ground point: no DTM can be made")
    dtm = tin_dtm(x[ground], y[ground], z[ground], grid, fill_outside=options.fill_outside_hull,
                  points_per_cell=options.points_per_cell)
    return grid, dtm


def check_outputs(input_path: str, output_path: Optional[str], raster_paths=()) -> None:
    """Refuse bad output paths before any work: wrong extension, missing folder, the input itself."""
    from ..raster.geotiff import check_raster_path
    if output_path:
        check_output_path(output_path, inputs=[input_path])
    for path in raster_paths:
        if path:
            check_raster_path(path, inputs=[input_path, output_path])


def write_outputs(cloud: PointCloud, classification: np.ndarray, output_path: Optional[str],
                  rasters=(), steps: Optional[Steps] = None) -> None:
    """Write the classified cloud and the rasters ``[(path, values, grid), ...]`` (GeoTIFF, the
    cloud's CRS). Every output goes to a temporary file first; all are renamed into place only
    once all are complete and no cancellation came, so a failed or cancelled run leaves none."""
    from ..raster.geotiff import write_geotiff
    steps = steps or Steps()
    with contextlib.ExitStack() as stack:
        if output_path:
            write_classified(cloud, classification, stack.enter_context(atomic_path(output_path)), atomic=False)
            steps.report(0.95)
        for path, values, grid in rasters:
            write_geotiff(stack.enter_context(atomic_path(path)), values, grid, crs_wkt=cloud.crs_wkt,
                          atomic=False)
        steps.check()


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
    steps = Steps(progress, is_cancelled)
    log = log or (lambda _msg: None)
    rasters = {path: fn for path, fn in (rasters or {}).items() if path}
    from .tiles import needs_tiling, run_tiled
    if needs_tiling(input_path, options.tiling):
        # A folder, a .vpc, a set tile size or a cloud beyond the memory budget: buffered tiles.
        if rasters:
            raise InvalidParameterError("the filter's intermediate grids are written for a single cloud that fits "
                                        "in memory only, not in a tiled run; leave those outputs empty")
        return run_tiled(input_path, output_path, algorithm, options=options, dtm_path=dtm_path, dtm=dtm,
                         steps=steps, log=log)
    check_outputs(input_path, output_path, [dtm_path, *rasters])
    steps.check()
    cloud = read_cloud(input_path)
    log(f"Read {len(cloud):,} points from {input_path}.")
    steps.report(0.1)
    done = classify_cloud(cloud, algorithm, options, steps.sub(0.1, 0.75), log)
    cls, ground = done.classification, done.ground
    log(f"Ground: {int(ground.sum()):,} of {int(done.filtered.sum()):,} filtered points.")
    run = FilterRun(cloud, cls, ground, done.filtered, detail=done.detail)
    if dtm_path:
        # The DTM covers every point but ignored noise (which may lie far away).
        area = ~np.isin(cloud.classification, NOISE_CLASSES) if options.ignore_noise else slice(None)
        run.dtm_grid, run.dtm = make_dtm(cloud.x[area], cloud.y[area], cloud.z[area], ground[area], dtm)
        steps.report(0.85)
    extra = [(path, *make(run)) for path, make in rasters.items()]
    if dtm_path:
        extra.insert(0, (dtm_path, run.dtm, run.dtm_grid))
    write_outputs(cloud, cls, output_path, extra, steps)
    steps.report(1.0)
    return run
