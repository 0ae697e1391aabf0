"""Survey scale: a cloud too big for memory, or many files, in buffered tiles.

The engine owns the tiles, the filter owns a tile (lidR's LAScatalog, lasR's ``exec(chunk=,
buffer=)``):

1. **plan** from the headers (bounds, point counts) and one sample chunk (the density where the
   points are): square tiles on multiples of the tile size, each read with a buffer of the
   filter's own reach (``algorithm.reach_m``, overridable); the tile size follows the memory
   budget, or the user's;
2. **bin**: one streamed pass over each file (laspy chunks) writes, into a working folder, the
   points each tile needs (its own and its buffer's) as uncompressed LAS parts with their indices
   in the input, and the file's records once more in file order (``.rec``, for step 4); tiles exist
   only where points are (a stray point far away makes a tiny tile);
3. **filter** each tile: its parts become one ``PointCloud`` (``io.lasfiles.tile_cloud``, every
   field ``read_cloud`` gives), the unchanged filter runs through ``workflow.classify_cloud``,
   and only the tile's own points keep their class, written into a per-file ``uint8`` memmap;
   with a DTM, the tile's cells are interpolated from the ground of the tile and its buffer and
   written as one block of one GeoTIFF;
4. **write** each input's classified copy from its kept records with the new classes, without
   decoding the input again: in pieces compressed on the workers (a big single file: one per
   worker, on LAZ chunk boundaries), then put together (atomic; the bytes of one streamed laspy
   copy); for several inputs a ``.vpc`` referencing the classified files. The tile parts are
   removed before (every tile is done by then).

Tiles run concurrently: in worker processes under ``qgis_process`` and plain Python for runs of
:data:`PROCESS_MIN_POINTS` points or more, in threads below that and inside the QGIS desktop (whose executable is QGIS itself: it cannot spawn Python workers; the numba
kernels release the GIL). Each tile is a pure function of its job (``_tile_job``), writing its
classes into per-file memmaps and returning its DTM block; the working folder is removed at the end.
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
import numbers
import os
import re
import shutil
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..errors import Cancelled, GroundSieveError, InputError, InvalidParameterError, OutputError
from ..io.clouds import extra_records_warning
from ..io.lasfiles import (CHUNK_POINTS, VPC_EXTENSION, LasInfo, TileGrid, assemble_classified, bin_file,
                           check_survey, expand_inputs, folder_note, iter_chunks, merge_bounds, piece_cuts, read_part,
                           scan_header, tile_cloud, write_classified_piece, write_classified_stream, write_vpc)
from ..io.outputs import LAS_EXTENSIONS, StagedOutputs, _ext, _reason, check_output_path
from ..progress import WARNING_PREFIX, Steps

#: Memory a point costs in a whole-cloud run with a DTM (measured: 321 bytes/point at 50 M points
#: through qgis_process; docs/BENCHMARKS.md), used to size tiles.
BYTES_PER_POINT = 330
#: What one LAS/LAZ file run whole costs, to decide whether it fits the memory budget
#: (:func:`whole_run_bytes`; fitted on every filter with a 1 m DTM at 10 M dense and 20 M airborne
#: points, docs/BENCHMARKS.md): each point (its record, kept for the output, plus this much), each
#: ground point the DTM triangulates, each cell of the finest grid, and for a filter that fills its
#: grid's empty cells what its guard counts for them (grids.spec.FILL_BYTES_PER_EMPTY_CELL). The
#: process itself (Python and its imports, about 0.25 GB) is not counted, as for tiles.
WHOLE_BYTES_PER_POINT = 128
WHOLE_BYTES_PER_TIN_POINT = 150
WHOLE_BYTES_PER_CELL = 60
#: what an empty cell of a filling filter's grid costs where the holes are many and small (measured
#: by a reviewer: 710-850 B uncounted per such cell at 2.4-1.2 points a cell; the sparse LU solves
#: holes of at most 4096 cells at 1.9-2.3 kB a cell, grids/spec.py)
SMALL_HOLE_BYTES = 1000
#: A header whose bounding box is larger than this (100 km²; a 1 m grid of 10^8 cells) is tiled
#: whatever its point count.
SPARSE_AREA_M2 = 1e8


#: a single input file is binned in pieces of at least this many points, one per worker
BIN_PIECE_POINTS = 4 * CHUNK_POINTS

#: the layout of the working folder (tile parts, records, done marks): a run resumes only from
#: a folder of the same layout (3: parts are int32 indices into the records kept in file order)
WORK_FORMAT = 3

#: a tile holding fewer points than this, buffer included, is not filtered (isolated points)
MIN_TILE_POINTS = 50

#: below this many points in a run, "auto" runs the workers as threads even where worker processes
#: could be spawned: starting them (the core's imports and numba caches, per process) cost more than
#: they gave back (1 M points in 8 files, 2 workers: threads 1.8-2.0 s, processes 3.5 s; 10 M points
#: in 20 files: about equal, 16.0-18.6 s against 17.9-18.7 s; docs/BENCHMARKS.md)
PROCESS_MIN_POINTS = 10_000_000

def default_memory_budget_mb(workers: int = 1) -> float:
    """A quarter of the memory this job has (the machine's RAM, at most its control group's limit), at most
    2 GB: room for QGIS and for the other programs; below an address-space limit (``ulimit -v``),
    DEFAULT_MEMORY_FRACTION (60 %) of what was left of it when the run first asked beyond what ``workers``
    threads take outside the budget (machine.address_space_reserve: OpenBLAS's buffers, stacks). Measured
    with bench/ulimit.py, in BENCHMARKS ("A batch job's address-space limit")."""
    from ..grids.spec import DEFAULT_MEMORY_FRACTION
    from ..machine import address_space_left, address_space_reserve, machine_memory_bytes
    budget = min(machine_memory_bytes() // 4, 2 << 30)
    left = address_space_left(first=True)
    if left is not None:  # (and what ``workers`` threads take beyond it: machine.address_space_reserve)
        budget = min(budget, int(DEFAULT_MEMORY_FRACTION * (left - address_space_reserve(workers))))
    return float(max(budget // (1 << 20), 1))


#: below this much address space left under ulimit -v, "every core" is one worker: each more takes OpenBLAS's
#: 128 MB buffer and its stacks, and the tiles had less (lasR's bcts_2, 824 k points, ran out under 1000000
#: with two workers where one ran)
TIGHT_ADDRESS_SPACE = 2 << 30


@dataclass(frozen=True)
class TileOptions:
    """How a run is cut into tiles (all optional: the defaults decide from the input)."""
    #: tile side (m); 0 = from the memory budget. Setting it tiles even a cloud that fits.
    tile_size_m: float = 0.0
    #: buffer around each tile (m); None = the filter's reach (``reach_m``)
    buffer_m: Optional[float] = None
    #: memory the tiles of all workers together may use (MB); 0 = a quarter of the job's memory (the RAM, at
    #: most its control group's limit), at most 2 GB, and below ``ulimit -v`` (core/machine.py)
    memory_budget_mb: float = 0.0
    #: tiles run at the same time; 0 = every core this process may use (its CPU set and quota)
    workers: int = 0
    #: where the temporary tiles go (removed at the end); None = beside the output
    work_dir: Optional[str] = None
    #: "auto" (worker processes under qgis_process and Python from PROCESS_MIN_POINTS points on,
    #: threads below that and in the QGIS desktop),
    #: "threads" or "processes"
    parallel: str = "auto"
    #: Dask scheduler: "" = this machine (the above), "local:N" = a LocalCluster of N worker
    #: processes, "tcp://host:port" = a running scheduler (engine/cluster.py). Not part of the
    #: working folder's name (repr=False): a run may resume on another cluster.
    scheduler: str = field(default="", repr=False)
    #: one file of a survey input (a folder or a .vpc): its 0-based place in the survey (a job array's
    #: task id), its name or its path; "" = every file. Only that file's points are classified and
    #: written, on the tiles of the whole survey, buffered by its neighbours' points (engine/one_file.py)
    only: object = ""

    def __post_init__(self):
        from .cluster import parse_scheduler
        parse_scheduler(self.scheduler)
        for name in ("tile_size_m", "memory_budget_mb"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise InvalidParameterError(f"{name} must be a number >= 0 (0 = automatic; got {value!r})")
        if self.buffer_m is not None and not (math.isfinite(self.buffer_m) and self.buffer_m >= 0):
            raise InvalidParameterError(f"buffer_m must be >= 0 m (got {self.buffer_m})")
        if self.parallel not in ("auto", "threads", "processes"):
            raise InvalidParameterError(f"parallel must be auto, threads or processes (got {self.parallel!r})")
        if int(self.workers) != self.workers or self.workers < 0:
            raise InvalidParameterError(f"workers must be a whole number >= 0 (0 = every core; got {self.workers})")
        if not isinstance(self.only, (str, numbers.Integral, os.PathLike)) or isinstance(self.only, bool) \
                or (isinstance(self.only, numbers.Integral) and self.only < 0):
            raise InvalidParameterError(f"only must be one file of the survey: its place from 0, its name or its path "
                                        f"(got {self.only!r})")

    @property
    def budget_bytes(self) -> int:
        mb = self.memory_budget_mb or default_memory_budget_mb(self.worker_count)
        return int(mb * (1 << 20))

    @property
    def worker_count(self) -> int:
        from ..machine import address_space_left, usable_cpus
        if self.workers:
            return int(self.workers)
        left = address_space_left(first=True)
        if left is not None and left < TIGHT_ADDRESS_SPACE:
            return 1  # (under a tight ulimit -v each worker's BLAS buffer and stacks cost more than it gives)
        return usable_cpus()


def filter_reach_m(algorithm) -> float:
    """The buffer a filter needs around a tile: its ``reach_m`` (a property or a method)."""
    reach = getattr(algorithm, "reach_m", None)
    if callable(reach):
        reach = reach()
    if reach is None:
        raise InvalidParameterError(f"{type(algorithm).__name__} does not state its reach (reach_m); "
                                    "give the tile buffer explicitly")
    return float(reach)


def is_survey_input(path: str) -> bool:
    return os.path.isdir(path) or _ext(path) == VPC_EXTENSION


def finest_grid_m(algorithm) -> float:
    """The finest grid a filter makes over the whole cloud (m): its cell, cloth or small scale; 1 m
    for a filter with none of these (its DTM-like surfaces are on 1 m cells or coarser)."""
    cells = [float(getattr(algorithm, name)) for name in ("cell_size_m", "cloth_resolution_m", "small_scale_m")
             if isinstance(getattr(algorithm, name, None), (int, float)) and getattr(algorithm, name) > 0]
    return min(cells, default=1.0)


def whole_run_bytes(info: LasInfo, algorithm=None, dtm=None) -> int:
    """The memory a run of one whole file takes, estimated from its header: see WHOLE_BYTES_PER_POINT,
    plus the algorithm's own ``extra_bytes_per_point`` if it states one. Without ``algorithm`` (a
    model's classification, whose features are not all known here), or for an algorithm whose
    extra is None (not measured), BYTES_PER_POINT a point, the first tile engine's figure."""
    extra = getattr(algorithm, "extra_bytes_per_point", 0) if algorithm is not None else None
    if extra is None:
        return int(info.count * BYTES_PER_POINT)
    from ..grids.spec import FILL_BYTES_PER_EMPTY_CELL
    record = (info.record_size or 34) + extra
    # (an algorithm that makes no grid over the cloud says so: rfclassify's models of point attributes)
    cells = info.area_m2 / finest_grid_m(algorithm) ** 2 if getattr(algorithm, "makes_grids", True) else 0.0
    # a filter that fills the empty cells of its grid (SMRF, PMF, the hybrid's surfaces): its points
    # leave about cells x exp(-points / cells) of them empty where spread evenly; many small holes
    # (more than 0.8 points a cell) go to the sparse LU solver (SMALL_HOLE_BYTES), fewer points make
    # large holes, the iterative fill, which the grid's own guard prices (FILL_BYTES_PER_EMPTY_CELL);
    # so that a cloud whose grid it would refuse is tiled instead
    empty_bytes = 0.0
    cell = getattr(algorithm, "cell_size_m", None)
    if isinstance(cell, (int, float)) and cell > 0 and getattr(algorithm, "makes_grids", True):
        grid_cells = info.area_m2 / cell ** 2
        spread = grid_cells * math.exp(-info.count / max(grid_cells, 1.0))
        if info.count > 0.8 * grid_cells:
            empty_bytes = spread * SMALL_HOLE_BYTES
        else:
            empty_bytes = max(grid_cells - info.count, spread) * FILL_BYTES_PER_EMPTY_CELL
    tin = 0.0
    if dtm is not None:
        dtm_cells = info.area_m2 / dtm.cell_size_m ** 2
        cells = max(cells, dtm_cells)
        tin = min(float(info.count), dtm.points_per_cell * dtm_cells) if dtm.points_per_cell else float(info.count)
    return int(info.count * (WHOLE_BYTES_PER_POINT + record)
               + tin * WHOLE_BYTES_PER_TIN_POINT + cells * WHOLE_BYTES_PER_CELL + empty_bytes)


def needs_tiling(input_path: str, tiling: TileOptions, algorithm=None, dtm=None,
                 log: Optional[Callable[[str], None]] = None) -> bool:
    """A folder, a .vpc, a set tile size, or a LAS/LAZ whose run would exceed the memory budget
    (:func:`whole_run_bytes` of ``algorithm`` with ``dtm``, a ``workflow.DTMOptions`` or None for no
    DTM); ``log`` is told why a single file is tiled."""
    if is_survey_input(input_path):
        return True
    if _ext(input_path) not in LAS_EXTENSIONS or not os.path.isfile(input_path):
        from ..io.clouds import TEXT_EXTENSIONS
        if tiling.tile_size_m > 0 and log and os.path.isfile(input_path) and _ext(input_path) in TEXT_EXTENSIONS:
            log(f"{WARNING_PREFIX}{input_path}: a tile size is set, but only LAS/LAZ files, folders and .vpc run in "
                "tiles: this text file runs whole.")
        return False
    if tiling.tile_size_m > 0:
        return True
    if tiling.scheduler:
        # On a cluster the workers do the work: a file run whole would be read, filtered and written
        # in this process, beside the scheduler it was told to use (an HPC reviewer's 10 M points
        # took 1.8 GB on the login node, the workers idle, without a word).
        if log:
            log(f"{input_path}: runs in buffered tiles on the Dask cluster ({tiling.scheduler}).")
        return True
    info = scan_header(input_path)
    # A bounding box no 1 m grid could cover (two areas far apart, a stray point): tiles exist only
    # where points are.
    if info.area_m2 > SPARSE_AREA_M2:
        if log:
            log(f"{input_path}: its points span {info.area_m2 / 1e6:,.0f} km²: run in buffered tiles, which "
                "exist only where there are points.")
        return True
    need = whole_run_bytes(info, algorithm, dtm)
    if need > tiling.budget_bytes:
        if log:
            dx, dy = info.maxs[0] - info.mins[0], info.maxs[1] - info.mins[1]
            log(f"{input_path}: run whole it would take about {need / 2**20:,.0f} MB, more than the memory budget "
                f"({tiling.budget_bytes / 2**20:,.0f} MB), for {info.count:,} points over its header's "
                f"{dx:,.0f} x {dy:,.0f} extent (which a few points far from the others may enlarge: a DTM's run names "
                "them): run in buffered tiles, which exist only where there are points.")
        return True
    return False


def occupied_cells(x, y, cell_m: float = 10.0) -> np.ndarray:
    """The keys of the cells of ``cell_m`` that hold at least one of the points ``x, y``."""
    x, y = np.asarray(x), np.asarray(y)
    return np.unique(np.floor(x / cell_m).astype(np.int64) * (1 << 32) + np.floor(y / cell_m).astype(np.int64))


def points_density(x, y, cell_m: float = 10.0) -> float:
    """Points per square unit where the points are: the points over the area of the cells of ``cell_m`` they
    occupy (a gap or a stray point does not thin it); 0 for no point."""
    return len(x) / (occupied_cells(x, y, cell_m).size * cell_m * cell_m) if len(x) else 0.0


def sample_density(path: str, chunk_points: int = CHUNK_POINTS, cell_m: float = 10.0) -> float:
    """Points per m² where the points are: the first chunk over the 10 m cells it occupies (a stray
    point far away does not dilute it, as the header's bounding box would). A file in no spatial
    order (its first chunk and a chunk from its middle spread over the same cells) has its first
    chunk thinly over the whole area: then the file's points over the cells the two chunks occupy
    (without this, a shuffled file's tiles were planned about its count / a chunk times too large)."""
    info = scan_header(path)
    if info.copc:  # its first chunk is its root node: sparse points over the whole file
        from ..io.copc import sample_density as copc_density
        return copc_density(path)

    def cells(chunk):
        return occupied_cells(chunk.x, chunk.y, cell_m)
    for chunk in iter_chunks(path, chunk_points):
        if len(chunk) == 0:
            break
        first = cells(chunk)
        density = len(chunk) / (first.size * cell_m * cell_m)
        if info.count < 3 * chunk_points:
            return density
        middle = cells(next(iter_chunks(path, chunk_points, first=info.count // 2)))
        shared = np.intersect1d(first, middle, assume_unique=True).size
        if shared > 0.5 * min(first.size, middle.size):
            return max(density, info.count / (np.union1d(first, middle).size * cell_m * cell_m))
        return density
    return 1.0


def plan_tile_size(infos: Sequence[LasInfo], tiling: TileOptions, buffer_m: float, density: float,
                   multiple_of: float = 1.0) -> float:
    """The tile side: the user's, or the largest square whose points and buffer fit one worker's
    share of the budget (less the decompressed-node cache a worker keeps for COPC inputs); a
    multiple of ``multiple_of`` (e.g. the DTM cell) and of 10 m."""
    if tiling.tile_size_m > 0:
        size = float(tiling.tile_size_m)
    else:
        per_worker = tiling.budget_bytes / tiling.worker_count
        if any(info.copc for info in infos):
            from ..io.copc import NODE_CACHE_BYTES
            per_worker = max(per_worker - NODE_CACHE_BYTES, per_worker / 2)
        points = per_worker / BYTES_PER_POINT
        side = math.sqrt(points / max(density, 1e-6))  # tile plus buffer
        size = max(side - 2 * buffer_m, buffer_m, 50.0)
        size = max(10.0, math.floor(size / 10.0) * 10.0)
    if multiple_of > 0:
        size = math.ceil(size / multiple_of - 1e-9) * multiple_of
    return size


@dataclass
class TiledRun:
    """What a tiled run reports (the cloud itself is never whole in memory)."""
    inputs: List[str]
    outputs: List[str]
    point_count: int
    ground_count: int
    crs_wkt: Optional[str]
    tile_size_m: float
    buffer_m: float
    tiles: int
    dtm_path: Optional[str] = None
    cloud: None = None  #: no cloud in memory (FilterRun has one)
    tile_log: List[dict] = field(default_factory=list)
    #: the COPC inputs, read by bounds by each tile instead of binned (io/copc.py)
    copc_inputs: List[str] = field(default_factory=list)
    #: the filter as it ran (its lengths in the CRS's unit: workflow.defaults_in_crs_unit)
    algorithm: object = None
    #: the run's warnings (its log's "Warning: " lines, without the prefix; set by run_ground_filter)
    warnings: List[str] = field(default_factory=list)
    #: {class: points} the filter gave the tiles' own points (a model's classes; not those kept as read)
    class_counts: Dict[int, int] = field(default_factory=dict)


def output_files(inputs: Sequence[str], output_path: Optional[str]) -> List[Optional[str]]:
    """Where each input's classified copy goes: the output itself for one input; for several, a
    folder beside the ``.vpc`` named after it, one file per input with the input's name."""
    if not output_path:
        return [None] * len(inputs)
    if len(inputs) == 1 and _ext(output_path) != VPC_EXTENSION:
        return [output_path]
    if _ext(output_path) != VPC_EXTENSION:
        raise OutputError(f"{output_path}: several input files give several classified files; the output must "
                          "name a .vpc (e.g. out/classified.vpc), beside which a folder of the same name holds them")
    folder = os.path.splitext(os.path.abspath(output_path))[0]
    # a COPC input's copy is a plain LAZ: not named .copc.laz, which readers open as COPC
    names = [re.sub(r"\.copc\.laz$", ".laz", os.path.basename(p), flags=re.I) for p in inputs]
    if len(set(names)) != len(names):
        twice = next(n for n in names if names.count(n) > 1)
        same = [p for p, n in zip(inputs, names) if n == twice]
        if len({os.path.basename(p) for p in same}) > 1:  # x.copc.laz beside x.laz
            raise InputError(f"{same[0]} and {same[1]} would both have the classified copy {twice} (a COPC "
                             "input's copy is a plain LAZ, named .laz); rename one of them")
        raise InputError(f"two input files have the same name ({' and '.join(same[:2])}); the classified files "
                         "would overwrite each other")
    return [os.path.join(folder, n) for n in names]


def check_tiled_outputs(inputs: Sequence[str], output_path: Optional[str], dtm_path: Optional[str],
                        point_formats: Optional[Sequence[int]] = None, log=None) -> List:
    """The classified files of ``inputs`` (:func:`output_files`), their paths and the DTM's checked;
    ``point_formats`` (the inputs', from their headers) spare the wave-packet trial (0.9 ms a file) to
    all but formats 9 and 10. ``log`` is told of point clouds in a .vpc's folder of classified files
    that this run does not write (:func:`_say_other_files`)."""
    from ..io.outputs import check_existing_target, check_not_copc_name, identities
    outs = output_files(inputs, output_path)
    # by any path to them (a share mounted twice: a reviewer's inputs were replaced by their copies)
    input_files = identities(inputs)
    if output_path and _ext(output_path) == VPC_EXTENSION:
        check_output_path(output_path, extensions=(VPC_EXTENSION,), what="virtual point cloud output")
        folder = os.path.dirname(os.path.realpath(outs[0]))
        if identities([folder]) & identities({os.path.dirname(os.path.abspath(p)) for p in inputs}):
            raise OutputError(f"{output_path}: the classified files would go into {folder}, which holds input "
                              "files; choose another output name or folder")
        if log is not None:
            _say_other_files(output_path, folder, outs, log)
    from ..io.clouds import check_laz_wave_packets
    for k, (path, out) in enumerate(zip(inputs, outs)):
        if out and identities([out]) & input_files:
            raise OutputError(f"{out}: the output must not be an input file; choose another name")
        if out:
            check_existing_target(out, "classified file")
        if out and _ext(out) not in LAS_EXTENSIONS:
            raise OutputError(f"{out}: the output must end in .las or .laz")
        if out:
            check_not_copc_name(out)
            if point_formats is None or point_formats[k] in (9, 10):
                check_laz_wave_packets(path, out)
    if dtm_path:
        from ..raster.geotiff import check_raster_path
        check_raster_path(dtm_path, inputs=list(inputs) + [output_path])
    return outs


def _say_other_files(output_path: str, folder: str, outs: Sequence[str], log) -> None:
    """Warn when the .vpc's folder of classified files holds point clouds this run does not write: a
    survey run again after some inputs were dropped or renamed left their earlier classified copies
    beside the new ones (a release engineer), and a user who loads the folder rather than the .vpc gets
    both. They are left as they are (they may be someone's), and the .vpc names only this run's."""
    if not os.path.isdir(folder):
        return
    mine = {os.path.normcase(os.path.basename(o)) for o in outs if o}
    others = sorted(n for n in os.listdir(folder) if _ext(n) in LAS_EXTENSIONS and not n.startswith(".")
                    and os.path.normcase(n) not in mine)
    if others:
        log(f"{WARNING_PREFIX}{folder}: {len(others):,} point cloud file(s) there are not written by this run "
            f"({', '.join(others[:3])}{', ...' if len(others) > 3 else ''}): an earlier run's classified copies of "
            f"inputs this run does not have? They are left as they are; {os.path.basename(output_path)} names "
            "only this run's files. Delete them, or write into an empty folder, to keep only this run's.")


def _check_disk(work_dir: str, infos: Sequence[LasInfo], buffer_m: float, size: float,
                shares: Optional[Sequence[float]] = None) -> None:
    """Refuse before work when the working folder's disk cannot hold the temporary tiles: each
    input's records in file order (the tiles read their points from them, and the classified copy
    is written from them), the tile parts' indices (the buffer's points in several) and the
    classes; the classified copy's pieces (at most the records' size) come after the parts are
    removed. ``shares``: each file's share of its points binned (1 by default; less for a file cut to a box)."""
    overlap = ((size + 2 * buffer_m) / size) ** 2
    shares = [1.0] * len(infos) if shares is None else shares
    need = sum(i.count * share * ((i.record_size or 40) * 2 + 8 * overlap + 1) for i, share in zip(infos, shares))
    free = shutil.disk_usage(work_dir).free
    if free < need:
        raise OutputError(f"{work_dir}: the working folder's disk has {free / 1e9:.1f} GB free, the temporary "
                          f"tiles need about {need / 1e9:.1f} GB; set the working folder to a bigger disk")


#: The most cells a survey's DTM may have: it is written block by block (``BlockGeoTIFF``, sparse), so
#: memory does not bound it; 2e10 cells are 80 GB of float32, a 0.5 m DTM of 5,000 km².
MAX_SURVEY_DTM_CELLS = 20_000_000_000


#: fewer points a m² over the files' header bounds than this: some far point stretches them (a survey holds
#: 1-1000 a m²)
SPARSE_SURVEY_PER_M2 = 0.01


def survey_box(infos: Sequence[LasInfo]) -> tuple:
    """(xmin, ymin, xmax, ymax) over the headers of the files holding points."""
    counted = [i for i in infos if i.count]
    return (min(i.mins[0] for i in counted), min(i.mins[1] for i in counted),
            max(i.maxs[0] for i in counted), max(i.maxs[1] for i in counted))


def survey_dtm_grid(infos: Sequence[LasInfo], cell: float, extent=None):
    """The survey DTM's grid over every file's header bounds (and the DTM's ``extent``, xmin, ymin, xmax,
    ymax, if given), refused (naming the cell size) when it would have more than
    :data:`MAX_SURVEY_DTM_CELLS` cells: the headers alone tell, before any work."""
    from ..grids.spec import GridSpec
    xs = np.array([v for i in infos if i.count for v in (i.mins[0], i.maxs[0])] + ([extent[0], extent[2]] if extent else []))
    ys = np.array([v for i in infos if i.count for v in (i.mins[1], i.maxs[1])] + ([extent[1], extent[3]] if extent else []))
    try:
        return GridSpec.covering(xs, ys, cell, what="DTM", bytes_per_cell=0.0, max_cells=MAX_SURVEY_DTM_CELLS,
                                 closed=True)
    except InvalidParameterError as err:  # (the headers count every point: a code reviewer's (0, 0, 0) noise point)
        area = max(float(np.ptp(xs)), cell) * max(float(np.ptp(ys)), cell)
        if sum(i.count for i in infos) / area >= SPARSE_SURVEY_PER_M2:  # (points over all of it: the cell, not a point)
            raise
        raise InvalidParameterError(f"{err}. The files' headers span x {xs.min():,.2f}-{xs.max():,.2f}, y "
                                    f"{ys.min():,.2f}-{ys.max():,.2f}, every point counted, withheld and noise "
                                    "too: a point far from the others (e.g. at 0, 0) widens them; remove it from "
                                    "the file (e.g. PDAL's filters.range, LAStools' las2las -drop_class 7)") from None


def fit_dtm_blocks(size: float, buffer_m: float, cell: float, tiling: "TileOptions",
                   log: Callable[[str], None] = lambda _m: None) -> float:
    """Each tile interpolates its DTM block (its cells and its buffer's) in memory, the workers at
    the same time: a planned tile size is made smaller until their blocks fit the memory budget
    (``grids.spec.memory_budget_bytes``); a tile size the user set, or a DTM cell so small that no
    tile of 10 m fits, is refused before any work, naming the cell size."""
    from ..errors import MemoryBudgetError
    from ..grids.spec import _size, memory_budget_bytes
    from .workflow import DTM_BYTES_PER_CELL
    budget, workers = memory_budget_bytes(), tiling.worker_count
    pad = math.ceil(buffer_m / cell - 1e-9) + 1

    def side(s):
        return math.ceil(s / cell - 1e-9) + 2 * pad
    per_cell = DTM_BYTES_PER_CELL * workers
    if side(size) ** 2 * per_cell <= budget:
        return size
    fits = (math.floor(math.sqrt(budget / per_cell)) - 2 * pad) * cell  # the largest tile whose block fits
    smaller = math.floor(math.floor(fits / 10.0) * 10.0 / cell + 1e-9) * cell
    if tiling.tile_size_m <= 0 and smaller >= 10.0:
        log(f"Tiles of {smaller:g} m instead of {size:g} m: each tile's DTM block of {cell:g} m cells must fit "
            f"the memory ({workers} worker(s) at a time).")
        return smaller
    n = side(size)
    raise MemoryBudgetError(
        f"DTM: a cell size of {cell:g} m makes each tile's DTM block {n:,} x {n:,} cells ({size:g} m tiles and "
        f"a {buffer_m:g} m buffer); {workers} worker(s) at a time need about {_size(n * n * per_cell)} at peak, more "
        f"than the {_size(budget)} this run may use; use a larger DTM cell size"
        + ([" or fewer workers", ", a smaller tile size or fewer workers"] if workers > 1
           else ["", " or a smaller tile size"])[tiling.tile_size_m > 0])


def run_tiled(input_path: str, output_path: Optional[str], algorithm, *, options, dtm_path: Optional[str] = None,
              dtm=None, steps: Optional[Steps] = None, log: Optional[Callable[[str], None]] = None) -> TiledRun:
    """Classify ``input_path`` (a LAS/LAZ, a folder or a .vpc) tile by tile; see the module's docstring.
    ``options`` is a ``workflow.FilterOptions`` (its ``tiling`` field a :class:`TileOptions`), ``dtm``
    a ``workflow.DTMOptions``."""
    refuse_in_a_workers_import()
    from . import workflow
    steps = steps or Steps()
    log = log or (lambda _msg: None)
    tiling: TileOptions = getattr(options, "tiling", None) or TileOptions()
    from ..machine import warm_blas
    warm_blas(tiling.worker_count)  # (under ulimit -v: OpenBLAS's buffers for the tile threads, taken first)
    inputs = expand_inputs(input_path)
    only = None  # one file of the survey, buffered by its neighbours (engine/one_file.py)
    if str(tiling.only) != "":
        from .one_file import check_only, only_index
        check_only(tiling, input_path)
        only = only_index(tiling.only, inputs, input_path)
    for note in folder_note(input_path).splitlines():
        log(note)
    infos = [scan_header(p) for p in inputs]
    check_survey(infos)
    if not any(i.count for i in infos):
        raise InputError(f"{input_path}: the input holds no points")
    empty = [os.path.basename(i.path) for i in infos if not i.count]
    if empty and only is None:  # (a survey's empty file was taken without a word: an HPC reviewer)
        log(f"{len(empty):,} of the {len(infos):,} input files hold no points ({', '.join(empty[:3])}"
            f"{', ...' if len(empty) > 3 else ''}): they add nothing (the classified copy of one is empty too).")
    from ..io.lasfiles import twin_files
    for twins in twin_files(infos):  # (read twice, their points count twice)
        if only is not None and inputs[only] not in twins:
            continue  # (one job of an array tells of its own file)
        log(f"{WARNING_PREFIX}{', '.join(os.path.basename(p) for p in twins[:4])}{' ...' if len(twins) > 4 else ''}: "
            "the same point count and bounds in their headers: the same points twice (a copy, or a classified copy "
            "beside its input)? Every file is read, so such points count twice; leave the copies out of the input.")
    for info in (infos if only is None else [infos[only]]):  # as a run of the whole file says (a tiled one
        # dropped 8,554 points without a word)
        if info.held is not None and info.held > info.count:
            log(extra_records_warning(info.path, info.count, info.held))
        if info.version >= "1.3":  # (as the whole run's reading says)
            from ..io.clouds import waveform_note
            note = waveform_note(info.path)
            if note:
                log(note)
        if info.bounds_from_points:  # (planned on its header's zeros, the run failed after every tile)
            log(f"{WARNING_PREFIX}{info.path}: its header's bounds are empty (every minimum and maximum the same "
                "value): the tiles are planned on its points' bounds, read from them. Other programs may not read "
                "it right; rewrite it with a tool that recomputes the header (e.g. las2las, PDAL's translate).")
        if info.copc_damaged:  # read as the whole run reads it (it was refused here)
            log(f"{WARNING_PREFIX}{info.path}: {info.copc_damaged}: its points are read as a plain LAZ file's, "
                "binned instead of read by bounds")
    if getattr(algorithm, "ground_of_any_class", False):
        _say_if_unclassified(infos if only is None else [infos[only]], algorithm, log)
    workflow.warn_about_units(input_path, infos, log)
    algorithm, dtm = workflow.defaults_in_crs_unit(algorithm, dtm, infos[0].crs_wkt, input_path, log)
    workflow.check_model_units(algorithm, input_path, infos[0].crs_wkt, log)
    # what a filter decides from the whole cloud (e.g. the echo grid: whether it has echoes), decided
    # once from the headers, so that no tile decides it from what it alone holds
    for_survey = getattr(algorithm, "for_survey", None)
    if for_survey is not None:
        algorithm = for_survey(infos, log)
    if only is None:
        outs = check_tiled_outputs(inputs, output_path, dtm_path, [i.point_format for i in infos], log)
    else:  # one file's copy, into a folder every job of an array shares, or a .las/.laz
        from .one_file import (check_names_apart, check_not_beside_inputs, fixed_names_warning, make_output_folders,
                               only_outputs)
        warning = fixed_names_warning(inputs[only], output_path, dtm_path)
        if warning:
            log(warning)
        check_names_apart(inputs, only, output_path, dtm_path)
        output_path, dtm_path = only_outputs(inputs[only], output_path, dtm_path)
        check_not_beside_inputs(output_path, inputs)
        empty = not infos[only].count  # (its DTM's folder is not made: it has none)
        make_output_folders([output_path, None if empty else dtm_path])
        mine = check_tiled_outputs([inputs[only]], output_path, None if empty else dtm_path,
                                   [infos[only].point_format], log)
        outs = [mine[0] if m == only else None for m in range(len(inputs))]
        if empty:  # (as a run of the whole survey writes it: an empty copy, a note)
            return _empty_file_run(inputs[only], outs[only], dtm_path, infos[only], log)
    # the DTM's grid from the headers: a DTM cell far too small for the survey is refused now
    if dtm_path and dtm.extent is not None:
        workflow.check_extent(dtm, *survey_box(infos))
        # (its cells counted now: a large extent was refused only after every tile, by the whole run's memory
        # rule, a code reviewer; a tiled DTM is written block by block)
        workflow.extent_grid(dtm, max_cells=MAX_SURVEY_DTM_CELLS, bytes_per_cell=0.0)
    dtm_grid = survey_dtm_grid(infos, dtm.cell_size_m, dtm.extent) if dtm_path else None
    if dtm_grid is not None and only is not None:  # the survey DTM's cells over the file's header bounds
        from .one_file import header_box
        dtm_grid = grid_window(dtm_grid, header_box(infos[only]))
        if dtm_grid is not None and dtm.extent is not None:
            dtm_grid = grid_window(dtm_grid, dtm.extent)
        if dtm_grid is None:
            if not output_path:
                raise InputError(f"{inputs[only]}: the file lies outside the DTM's extent: no DTM for it, and no "
                                 "classified copy asked for")
            log(f"{WARNING_PREFIX}{inputs[only]}: the file lies outside the DTM's extent: no DTM is written for it.")
            dtm_path = None
    elif dtm_grid is not None and dtm.extent is not None and not output_path:
        # a DTM of an area alone (no classified copy): only the tiles making its cells are filtered, and
        # only the files within their reach are read (_plan_and_run); the grid is the extent's cells
        dtm_grid = grid_window(dtm_grid, dtm.extent) or dtm_grid
    # The reach rounded up to whole metres: the buffer's edges then sit on whole metres, where the
    # filters' grids (edges on multiples of their cell) put theirs without floating-point doubt.
    reach = filter_reach_m(algorithm)
    buffer_m = math.ceil(reach) if tiling.buffer_m is None else float(tiling.buffer_m)
    if buffer_m < reach:
        log(f"{WARNING_PREFIX}the tile buffer ({buffer_m:g} m) is less than the filter's reach ({reach:g} m): points "
            "near the tile edges may be classified otherwise than in a run of the whole cloud, and the DTM may show "
            "the tile lines; leave the buffer at -1 (the filter's reach) unless you mean it.")
    density = _survey_density(infos, log)
    cluster = None
    from .cluster import parse_scheduler
    if parse_scheduler(tiling.scheduler)[0] == "address":
        # tiles sized for the cluster's workers, not for this machine, or a size set checked against
        # them: connected now (the run keeps the connection for the binning, the tiles and the writing)
        from .cluster import Cluster
        cluster = Cluster(tiling.scheduler, log, steps.is_cancelled)
    try:
        return _plan_and_run(inputs, infos, outs, output_path, algorithm, options, dtm_path, dtm, dtm_grid, buffer_m,
                             density, tiling, steps, log, workflow, cluster, only)
    except BaseException:
        if cluster is not None:
            cluster.close()
        raise


def _survey_density(infos, log) -> float:
    """The points per m² the tiles are planned for: the first file's with points (sample_density), or where
    it cannot be read the next one's: one damaged file failed every job of an array that sampled it, the
    jobs whose tiles never read it too (an HPC reviewer). The damaged file fails the runs that read it."""
    first = None
    for info in (i for i in infos if i.count):
        try:
            return sample_density(info.path)
        except (Cancelled, MemoryError):
            raise
        except Exception as err:  # noqa: BLE001 - a damaged file (laspy, lazrs, or said already): the next one
            first = first or err
            said = str(err) if isinstance(err, GroundSieveError) else f"{info.path}: {type(err).__name__}: {err}"
            log(f"{WARNING_PREFIX}{said}; the tiles are planned from the next file's points.")
    if first is None:
        return 1.0
    raise first


def _empty_file_run(path, out, dtm_path, info, log) -> "TiledRun":
    """The run of one empty file of a survey: its copy (empty, as a run of the whole survey writes it), no
    DTM; a job of an array for a delivery's empty tile (all water, beyond the flight) ends done."""
    from ..io.lasfiles import write_classified_stream
    log(f"{path}: the file holds no points: its classified copy is empty" + (", and no DTM is made for it."
                                                                              if dtm_path else "."))
    if out:
        write_classified_stream(path, out, np.zeros(0, dtype=np.uint8))
    return TiledRun([path], [out] if out else [], 0, 0, info.crs_wkt, 0.0, 0.0, 0, None)


def _say_tiles_beyond_workers(size: float, buffer_m: float, density: float, per_task: int, tiling: TileOptions,
                              log) -> None:
    """Warn when the tiles set by the user (their size, or a memory budget) take more memory than a
    Dask task has on the cluster: Dask pauses a worker at 80 % of its limit and restarts it at 95 %,
    and the run then fails after its retries ("KilledWorker") instead of saying so before the work."""
    per_tile = (size + 2 * buffer_m) ** 2 * density * BYTES_PER_POINT
    if per_tile <= CLUSTER_TASK_SHARE * per_task:
        return
    fit = math.sqrt(CLUSTER_TASK_SHARE * per_task / BYTES_PER_POINT / max(density, 1e-6)) - 2 * buffer_m
    what = f"tiles of {size:g} m" + (" (from the memory budget set)" if not tiling.tile_size_m else "")
    log(f"{WARNING_PREFIX}{what} and their buffer take about {per_tile / 2**20:,.0f} MB each, more than half the "
        f"memory a task has on the Dask cluster ({per_task / 2**20:,.0f} MB: the smallest worker's memory limit over its "
        "threads); Dask pauses a worker at 80 % of its limit and restarts it at 95 %. "
        + (f"Use tiles of at most {max(math.floor(fit / 10) * 10, 10):g} m, or " if fit >= 10 else "Use ")
        + "a tile size of 0 and no memory budget, to have the tiles planned for the cluster.")


def _tiles_across(size: float, buffer_m: float, box) -> Tuple[int, int]:
    """(columns, rows) of the tiles of ``size`` that the survey's box ``box`` (xmin, ymin, xmax, ymax) spans, its
    far edge closing its last tiles (``TileGrid.for_survey``)."""
    kx, ky = TileGrid.for_survey(size, buffer_m, box).key_of(np.array([box[0], box[2]]), np.array([box[1], box[3]]))
    return int(kx[1] - kx[0] + 1), int(ky[1] - ky[0] + 1)


def _tile_and_buffer_points(reach: float, w: float, h: float, density: float, total: int) -> float:
    """The points a tile with its buffer (a square of side ``reach``) holds at most in a survey of ``w`` x ``h``
    and ``total`` points at ``density``: its square cut to the survey's box, and never more than the survey
    (a dense survey of 8.6 M points was said to need 6,338 MB a tile: a photogrammetry reviewer)."""
    return min(min(reach, w) * min(reach, h) * density, float(total))


def survey_as_one_tile(infos: Sequence[LasInfo], size: float, buffer_m: float, tiling: TileOptions, algorithm=None,
                       dtm=None, log: Callable[[str], None] = lambda _m: None) -> Optional[float]:
    """A tile size that makes the survey one tile, or None: where the survey fits the memory budget whole
    (:func:`whole_run_bytes` of its files as one, as a single file that fits runs whole) and its tiles of
    ``size`` would each read about as many points again as their own times more than the workers run at
    once (their buffers reach across most of the survey), tiling only repeats work. A dense UAV survey of
    4 M points in 4 files took 2.8 times its whole file's time in 4 tiles of 90 m, each reading its 90 m
    buffer, that is the whole survey (a photogrammetry reviewer: 8.6 M points in 9 files, 2.4 times). The
    size is the smallest multiple of 10 m (and of the DTM cell) from the survey's side up to 4 times it
    whose tile on the grid holds the whole survey (the survey's far edge closes it) and whose DTM block fits."""
    box = survey_box(infos)
    x0, y0, x1, y1 = box
    w, h = x1 - x0, y1 - y0
    reach = size + 2 * buffer_m
    tiles = math.prod(_tiles_across(size, buffer_m, box))
    # the points the tiles read with their buffers against the survey's (an upper bound: each tile's buffered
    # square cut to the survey's box), against the tiles the budget lets run at once (not the workers asked
    # for: 4 workers on a 2 GB budget run 1 such tile at a time, and 4 tiles each reading the whole survey
    # took 2.2 times one tile's time, a dense-UAV reviewer)
    total = sum(i.count for i in infos)
    repeated = tiles * min(reach, w) * min(reach, h) / max(w * h, 1.0)
    per_tile = _tile_and_buffer_points(reach, w, h, total / max(w * h, 1.0), total) * BYTES_PER_POINT
    at_once = max(1, min(tiling.worker_count, int(tiling.budget_bytes // max(per_tile, 1.0))))
    if tiles < 2 or repeated <= at_once:
        return None
    merged = dataclasses.replace(infos[0], count=total, mins=(x0, y0, infos[0].mins[2]), maxs=(x1, y1, infos[0].maxs[2]),
                                 record_size=max(i.record_size for i in infos))
    need = whole_run_bytes(merged, algorithm, dtm)
    # (within the budget; or a budget the planned tiles exceed as well: one just below the whole run's 696 MB
    # made 4 tiles each holding the whole survey, about 874 MB each, a dense-UAV reviewer)
    if need > max(tiling.budget_bytes, per_tile):
        return None
    cell = dtm.cell_size_m if dtm is not None else 1.0
    side = max(w, h, 10.0)
    one = math.ceil(side / 10.0) * 10.0
    while one <= 4 * side:
        s = math.ceil(one / cell - 1e-9) * cell
        if _tiles_across(s, buffer_m, box) == (1, 1):
            if dtm is not None:
                try:
                    if fit_dtm_blocks(s, buffer_m, cell, dataclasses.replace(tiling, workers=1)) != s:
                        return None
                except GroundSieveError:
                    return None
            log(f"The survey runs as one tile of {s:g} m: run whole it takes about {need / 2**20:,.0f} MB"
                + (f", within the memory budget ({tiling.budget_bytes / 2**20:,.0f} MB)" if need <= tiling.budget_bytes
                   else f", less than each of its planned tiles ({per_tile / 2**20:,.0f} MB)")
                + f", and its tiles of {size:g} m would each read their {buffer_m:g} m buffer: {tiles} tiles reading "
                f"about {repeated:.1f} times the survey's points, more than the {at_once} tile(s) the budget runs at "
                "once gain.")
            return s
        one += 10.0
    return None


def _plan_and_run(inputs, infos, outs, output_path, algorithm, options, dtm_path, dtm, dtm_grid, buffer_m, density,
                  tiling, steps, log, workflow, cluster, only=None):
    """run_tiled's run once its inputs are checked: the tiles planned, the working folder held; ``only``:
    the place of the one file to run (engine/one_file.py), None for every file."""
    total = sum(i.count for i in infos) if only is None else infos[only].count
    per_task, threads = cluster.memory_per_task() if cluster is not None else (None, 0)
    chosen = bool(tiling.tile_size_m or tiling.memory_budget_mb)  # the user's tiles, not the cluster's plan
    if per_task and not chosen:
        # a tile within its share of the smallest task's memory, and at least TILES_PER_THREAD tiles
        # for each of the cluster's threads where the survey is big enough
        tile_bytes = min(CLUSTER_TASK_SHARE * per_task, total * BYTES_PER_POINT / (TILES_PER_THREAD * max(threads, 1)))
        tiling = dataclasses.replace(tiling, memory_budget_mb=tile_bytes * tiling.worker_count / (1 << 20))
        log(f"Tiles planned for the Dask cluster's {threads} thread(s), each with {per_task / 2**30:.1f} GB or more "
            f"(its worker's memory limit over its threads): at most {tile_bytes / 2**20:,.0f} MB a tile.")
    size = plan_tile_size(infos, tiling, buffer_m, density, multiple_of=dtm.cell_size_m if dtm_path else 1.0)
    one_tile = None
    if not tiling.tile_size_m and cluster is None and only is None:
        one_tile = survey_as_one_tile(infos, size, buffer_m, tiling, algorithm, dtm if dtm_path else None, log)
        size = one_tile or size
    if tiling.tile_size_m and abs(size - tiling.tile_size_m) > 1e-9:  # (it had been changed without a word)
        log(f"Tiles of {size:g} instead of the {tiling.tile_size_m:g} set: a multiple of the DTM cell "
            f"({dtm.cell_size_m:g}), so that each tile makes whole cells.")
    if only is not None and not tiling.tile_size_m:  # (tiles across a file's edges: its job filters more)
        from .one_file import fit_to_files
        fitted = fit_to_files(size, infos, multiple_of=dtm.cell_size_m if dtm_path else 1.0)
        if fitted != size:
            log(f"Tiles of {fitted:g} instead of {size:g}: fitted to the survey's files, as every job of the array "
                "fits them.")
            size = fitted
    if dtm_path and not one_tile:  # (one tile's block was fitted for the one tile at a time it is)
        size = fit_dtm_blocks(size, buffer_m, dtm.cell_size_m, tiling, log)
    if per_task and chosen:
        _say_tiles_beyond_workers(size, buffer_m, density, per_task, tiling, log)
    if not tiling.tile_size_m and not one_tile:  # the planned tiles cannot be smaller than 50 m: say when the
        # budget asked for less
        bx0, by0, bx1, by1 = survey_box(infos)
        per_tile = _tile_and_buffer_points(size + 2 * buffer_m, max(bx1 - bx0, 1.0), max(by1 - by0, 1.0), density,
                                           sum(i.count for i in infos)) * BYTES_PER_POINT
        fit = max(1, int(tiling.budget_bytes // max(per_tile, 1.0)))
        if cluster is None and fit < tiling.worker_count:
            # the budget wins over the workers: fewer tiles at a time rather than more memory than allowed
            log(f"{tiling.worker_count} tiles at the same time would take about "
                f"{per_tile * tiling.worker_count / 2**20:,.0f} MB, more than the memory budget "
                f"({tiling.budget_bytes / 2**20:,.0f} MB): {fit} at a time instead.")
            tiling = dataclasses.replace(tiling, workers=fit)
        need = per_tile * tiling.worker_count
        if need > 1.05 * tiling.budget_bytes:
            log(f"The memory budget ({tiling.budget_bytes / 2**20:,.0f} MB) is below what the smallest tiles "
                f"need: tiles of {size:g} m and their buffer take about {need / 2**20:,.0f} MB on "
                f"{tiling.worker_count} worker(s), which the run may use.")
    headers = survey_box(infos)  # (before the files are cut to those a subset of the tiles reads)
    grid = TileGrid.for_survey(size, buffer_m, headers)  # (the survey's far edge closes its last tiles)
    note = getattr(algorithm, "tiled_note", "")
    if note:
        log(note)
    from ..raster.crs import metres_per_unit
    from .workflow import length_label
    unit = length_label(metres_per_unit(infos[0].crs_wkt) or 1.0)  # (a survey in feet: feet)
    one = None  # one_file.Subset: one file's run, or a DTM extent's alone (None: the whole survey)
    if only is not None:
        from .one_file import Subset, header_box, neighbours, reach_box, tile_range
        tiles_of = tile_range(header_box(infos[only]), size)
        box = reach_box(tiles_of, size, buffer_m)
        keep = neighbours(infos, only, box)
        name, files = os.path.basename(inputs[only]), len(inputs)
        inputs, infos, outs = [inputs[m] for m in keep], [infos[m] for m in keep], [outs[m] for m in keep]
        one = Subset(index=keep.index(only), tiles=tiles_of, clip=box, survey_box=headers)
        log(f"{name}, file {only} of the survey's {files:,} (numbered from 0), is the one classified: its tiles read "
            f"their buffers from {len(keep) - 1:,} neighbouring file(s); every file run so on the same tiles gets the "
            "classes and DTM of a run of the whole survey.")
    elif dtm_path and dtm.extent is not None and not output_path:  # a DTM of an area alone: its tiles only
        from .one_file import Subset, neighbours, reach_box, tile_range
        g = dtm_grid
        # (the cells' edges: a tile beginning where they end makes none of them, and a domain on round numbers
        # had read a row and a column of files more: a flood modeller)
        tiles_of = tile_range((g.x0, g.top - g.nrows * g.cell, g.x0 + g.ncols * g.cell, g.top), size, closed=True)
        box = reach_box(tiles_of, size, buffer_m)
        keep = [m for m in neighbours(infos, -1, box) if infos[m].count]
        files = len(inputs)
        if keep:
            # the files within reach, cut to it; where that is every file (a single big file, a small
            # delivery), every file is binned whole, in pieces, and only the extent's tiles are filtered
            every = len(keep) == sum(1 for i in infos if i.count)
            inputs, infos, outs = [inputs[m] for m in keep], [infos[m] for m in keep], [outs[m] for m in keep]
            one = Subset(index=None, tiles=tiles_of, clip=None if every else box, survey_box=headers)
            total = sum(i.count for i in infos)
            log("A DTM of its extent alone: only the tiles making its cells are "
                + ("read" if getattr(algorithm, "ground_of_any_class", False) else "filtered")
                + (f", reading {len(keep):,} of the {files:,} file(s), those within their reach." if not every else
                   f", in the {files:,} file(s), all within their reach."))
    log(f"{len(inputs)} file(s), {total:,} points; tiles of {size:g} {unit} with a buffer of {buffer_m:g} {unit} "
        f"({'set' if tiling.buffer_m is not None else getattr(algorithm, 'reach_words', 'the filter reach')}); "
        f"{tiling.worker_count} worker(s)."
        + ("" if tiling.tile_size_m or cluster is not None else
           " (The tile size is planned from the memory budget shared by the workers"
           + (" and fitted to the survey's files: a run of the whole survey with this tile size set gives the same "
              f"classes and DTM; set it, {size:g}, in every job for the same tiles on any machine.)" if one is not None
              and one.one_file else
              f": set it, {size:g}, for the same tiles and so the same classes and DTM with other workers or on "
              "another machine.)")))
    steps.check()
    parent = tiling.work_dir or os.path.dirname(os.path.abspath(output_path or dtm_path or inputs[0]))
    if os.path.exists(parent) and not os.path.isdir(parent):
        raise OutputError(f"{parent}: the working folder is a file, not a folder")
    if not os.path.isdir(parent):
        raise OutputError(f"{parent}: the working folder does not exist")
    # The working folder is named after everything the tiles' results depend on: a run killed or
    # crashed midway finds it again and skips the tiles already done.
    work = os.path.join(parent, WORK_PREFIX + _fingerprint(infos, grid, algorithm, options,
                                                                     dtm if dtm_path else None,
                                                                     None if one is None else
                                                                     "the DTM's extent" if not one.one_file
                                                                     else os.path.realpath(inputs[one.index])))
    if os.path.isdir(work):
        lock = _lock_working_folder(work)  # another run still using it is refused, its folder left alone
        log(f"Resuming the interrupted run in {work}.")
    else:
        # Made before the free space is read: a read-only folder is refused for what it is (a
        # read-only file system reports no space), and a folder the disk check refuses is removed.
        try:
            os.makedirs(work)
        except OSError as err:
            raise OutputError(f"{parent}: the working folder cannot be written to ({_reason(err)}); "
                              "choose a folder where you may create files") from err
        lock = _lock_working_folder(work)
        try:
            from .one_file import clip_shares
            shares = [1.0] * len(infos) if one is None or one.clip is None else \
                clip_shares(infos, one.index, one.clip)
            binned = [k for k, i in enumerate(infos) if not i.copc]  # (COPC files are not binned)
            _check_disk(parent, [infos[k] for k in binned], buffer_m, size, [shares[k] for k in binned])
        except OutputError:
            lock.close()
            _remove_tree(work)
            raise
    # (the jobs of an array share a working folder; where its locks do not reach across nodes, their live
    # folders would look stale, and the warning invites deleting them: a code reviewer)
    stale = _stale_working_folders(parent, work) if one is None or not one.one_file else []
    if stale:
        log(f"{WARNING_PREFIX}{len(stale)} working folder(s) of earlier runs that were killed hold "
            f"{_gb(sum(b for _p, b in stale))} "
            f"in {parent} ({', '.join(os.path.basename(p) for p, _b in stale[:3])}{', ...' if len(stale) > 3 else ''}); "
            "only a run of the same inputs and parameters resumes from one: delete those you will not run again.")
    try:
        return _run_locked(work, inputs, infos, outs, output_path, grid, algorithm, options, dtm_path, dtm, tiling,
                           steps, log, workflow, total, dtm_grid, cluster, one)
    finally:
        lock.close()


WORK_PREFIX = ".groundsieve-tiles-"


def _gb(nbytes: int) -> str:
    return f"{nbytes / 1e9:.1f} GB" if nbytes >= 1e8 else f"{nbytes / 1e6:.1f} MB"


def _stale_working_folders(parent: str, current: str) -> List[tuple]:
    """The working folders in ``parent`` other than ``current`` that no live run holds (a run killed
    with kill -9, by the system or a power cut leaves its folder, named after its inputs and
    parameters, for a run of the same to resume from), with their sizes in bytes, largest first.
    A folder whose lock cannot be tested (no flock) is not listed."""
    try:
        import fcntl
        names = os.listdir(parent)
    except (ImportError, OSError):
        return []
    stale = []
    for name in names:
        path = os.path.join(parent, name)
        if not name.startswith(WORK_PREFIX) or os.path.abspath(path) == os.path.abspath(current) \
                or not os.path.isdir(path):
            continue
        try:
            # read-only (nothing created) and shared: a live run holds its folder exclusively; a run
            # taking a folder at this instant retries (_lock_working_folder)
            with open(os.path.join(path, ".lock"), "r") as f:
                fcntl.flock(f, fcntl.LOCK_SH | fcntl.LOCK_NB)  # released when closed
        except OSError:  # held by a live run (BlockingIOError), no lock file (being made), not ours
            continue
        size = 0
        for root, _dirs, files in os.walk(path):
            for file in files:
                with contextlib.suppress(OSError):
                    size += os.path.getsize(os.path.join(root, file))
        stale.append((path, size))
    return sorted(stale, key=lambda item: -item[1])


#: tries of a working folder's lock, 0.05 s apart, before another run is said to be using it
LOCK_ATTEMPTS = 10


class _NoLock:
    def close(self):
        pass


def _lock_working_folder(work: str):
    """Hold the working folder for this run (an exclusive lock on ``work/.lock``; closing the returned
    object releases it). Two runs of the same inputs and parameters share one folder name: a second
    run started while the first is alive would resume from tiles the first then deletes. Where the
    file system has no locks (some network file systems, Windows) nothing is held."""
    try:
        import fcntl
    except ImportError:
        return _NoLock()
    path = os.path.join(work, ".lock")
    try:
        f = open(path, "a+")
    except OSError:
        return _NoLock()
    try:
        for attempt in range(LOCK_ATTEMPTS):  # (another run's look at stale folders holds it an instant)
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if attempt == LOCK_ATTEMPTS - 1:
                    raise
                time.sleep(0.05)
    except BlockingIOError:
        f.seek(0)
        holder = f.read().strip() or "another process"
        f.close()
        raise OutputError(f"{work}: another run of the same inputs and parameters ({holder}) is using this "
                          "working folder; wait for it to end, or give this run another working folder")
    except OSError:
        f.close()
        return _NoLock()
    f.seek(0)
    f.truncate()
    f.write(f"process {os.getpid()} on {os.uname().nodename if hasattr(os, 'uname') else 'this machine'}")
    f.flush()
    return f


def _run_locked(work, inputs, infos, outs, output_path, grid, algorithm, options, dtm_path, dtm, tiling, steps,
                log, workflow, total, dtm_grid, cluster=None, one=None):
    """run_tiled's run once the working folder is held (on ``cluster`` when connected already: the
    run closes it)."""
    pool = None
    rasters = []  # the DTM writer, released at once if the run fails
    try:
        if tiling.scheduler and cluster is None:  # one connection (one LocalCluster) for the whole run
            from .cluster import Cluster
            cluster = Cluster(tiling.scheduler, log, steps.is_cancelled)
        elif tiling.worker_count > 1 and (tiling.parallel if tiling.parallel != "auto"
                                          else _auto_parallel(total)) == "processes":
            # one pool of worker processes for the binning, the tiles and the writing (each
            # process started once: its imports and numba caches loaded once)
            pool = _worker_pool(tiling.worker_count, True)
        run = _run(work, inputs, infos, outs, output_path, grid, algorithm, options, dtm_path, dtm, tiling,
                   steps, log, workflow, cluster=cluster, rasters=rasters, pool=pool, dtm_grid=dtm_grid, one=one)
    except BaseException:
        if pool is not None:  # its workers' tiles are not waited for: the run says why at once
            stop_workers(pool)
            pool.shutdown(wait=True, cancel_futures=True)
            pool = None
        for writer in rasters:  # closed at once, not by the garbage collector (GDAL may crash then)
            try:
                writer.close()
            except Exception:  # noqa: BLE001 - e.g. a full disk: the run's own error is the one to tell
                pass  # (GDAL's "TIFFAppendToStrip: Write error" replaced "No space left on device": a reviewer)
        if cluster is not None:  # first: a LocalCluster's workers still running a tile stop writing
            cluster.close()
            cluster = None
        # Kept for a restart when the user chose the working folder and the binning is done (a restart
        # deletes a partial binning anyway); removed otherwise.
        if not tiling.work_dir:
            _remove_tree(work)
            log("The tiles done so far are deleted with the run's temporary working folder; name a working "
                "folder to keep them for the next run to resume from.")
        elif not os.path.exists(os.path.join(work, "binned.json")):
            _remove_tree(work)
            log(f"Nothing a run could resume from was done; the working folder {work} is removed.")
        else:
            log(f"The tiles done so far are kept in {work}: run again to resume, or delete it.")
        raise
    finally:
        if cluster is not None:
            cluster.close()
        if pool is not None:
            pool.shutdown(wait=True)
    _remove_tree(work)
    return run


def _remove_tree(path: str, patience_s: float = 3.0) -> None:
    """Remove the working folder, again while a worker (of a remote cluster, whose tasks a cancel
    does not stop) is still writing a tile's last files into it; a worker that writes after the
    folder is gone fails on the missing folder, which nothing recreates."""
    deadline = time.monotonic() + patience_s
    while True:
        shutil.rmtree(path, ignore_errors=True)
        if not os.path.exists(path) or time.monotonic() > deadline:
            return
        time.sleep(0.1)


def _full_disk(err: OSError, work: str, where: str = "", then: str = "") -> Optional[OutputError]:
    """The output error for a full disk (or quota) in the working folder ``work``, or None for another
    OSError: a full disk is the working folder's, not a bug."""
    import errno
    if err.errno not in (errno.ENOSPC, errno.EDQUOT):
        return None
    return OutputError(f"{where}the disk of the working folder {work} is full ({err.strerror}); free space or set "
                       f"another working folder{then}")


def _reserve(paths, work: str) -> None:
    """Give the (sparse) class files their disk blocks now: the tiles write them through memory maps,
    and a disk that filled up mid-run then killed the process with SIGBUS, no message (an HPC
    reviewer's full working folder). Where the system cannot reserve, nothing is done."""
    if not hasattr(os, "posix_fallocate"):
        return
    for path in paths:
        try:
            with open(path, "r+b") as f:
                os.posix_fallocate(f.fileno(), 0, os.fstat(f.fileno()).st_size)
        except OSError as err:
            full = _full_disk(err, work)
            if full is not None:
                raise full from err
            return  # (a file system without fallocate: EOPNOTSUPP, EINVAL)


def _fingerprint(infos, grid, algorithm, options, dtm, only: Optional[str] = None) -> str:
    """What a working folder's results depend on: the inputs, the tiles and their buffer, the filter,
    the options but how the tiles are run (workers, threads or processes, the memory budget and the
    scheduler change where and when a tile runs, not its result: a reviewer's run killed on 2
    workers did not resume on 1), the DTM, and the code: a run resumed with another core/ (same
    version) mixed tiles of both versions, its classes and DTM those of neither. ``only``: the real path
    of the one file of the survey the run classifies (the jobs of an array, each its file, in one folder
    at once), or "the DTM's extent" for a run of a DTM's extent alone (its tiles' parts are cut to it)."""
    import dataclasses
    import hashlib
    import json as _json
    from .cluster import _core_digest
    files = [(os.path.realpath(i.path), os.path.getsize(i.path), os.stat(i.path).st_mtime_ns) for i in infos]
    results = dataclasses.replace(options, memory_budget_bytes=None, tiling=None) \
        if dataclasses.is_dataclass(options) and hasattr(options, "tiling") else options
    dtm_results = dataclasses.replace(dtm, memory_budget_bytes=None) \
        if dataclasses.is_dataclass(dtm) and hasattr(dtm, "memory_budget_bytes") else dtm
    text = _json.dumps([files, grid.size, grid.buffer, list(grid.edge), repr(algorithm), repr(results), repr(dtm_results), WORK_FORMAT,
                        _core_digest()] + ([only] if only else []), default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def _save_json(path, doc) -> None:
    import json as _json
    tmp = path + ".part"
    with open(tmp, "w") as f:
        _json.dump(doc, f)
    os.replace(tmp, path)


def _run(work, inputs, infos, outs, output_path, grid, algorithm, options, dtm_path, dtm, tiling, steps, log,
         workflow, cluster=None, rasters=None, pool=None, dtm_grid=None, one=None) -> TiledRun:
    """The run (steps 1-4 of the module's docstring) in its held working folder. ``one``: the run of one
    file of the survey (engine/one_file.py): ``index``, its place in ``infos`` (the others are its
    neighbours, binned in ``clip`` only, of which nothing is written), and ``tiles``, the tiles its header
    bounds touch; or, with ``index`` None, the run of a DTM's extent alone: ``tiles`` those its cells lie
    in, every file binned in ``clip`` only and no classified copy written."""
    t_start = time.perf_counter()
    import json as _json
    from ..io.lasfiles import TilePart
    # 1. bin every file into tile parts (once: a resumed run finds them listed in binned.json)
    tiles: Dict[tuple, list] = {}
    binned = os.path.join(work, "binned.json")
    done_dir = os.path.join(work, "done")
    if os.path.exists(binned):
        with open(binned) as f:
            for entry in _json.load(f):
                tiles[tuple(entry["key"])] = [TilePart(**part) for part in entry["parts"]]
    else:
        for name in os.listdir(work):  # a run killed while binning left partial parts
            if name != ".lock":  # (this run's hold on the folder)
                os.remove(os.path.join(work, name))
        total = sum(i.count for i in infos)
        done_points = 0
        bin_steps = steps.sub(0.0, 0.3)
        binned_parts = {}

        file_bounds: Dict[int, list] = {}

        def record_bin(result):
            nonlocal done_points
            binned_parts[(result["file_index"], result["first"])] = result["parts"]
            if result.get("bounds"):
                k = result["file_index"]
                file_bounds[k] = merge_bounds(file_bounds.get(k), result["bounds"])
            done_points += result["points"]
            bin_steps.report(done_points / total)
        # one job per input file, on the workers (each file's parts have their own names); a big file
        # in pieces of consecutive points, one per worker (LAZ seeks through its chunk table)
        bin_jobs = []
        for k, info in enumerate(infos):
            if not info.count or info.copc:  # a COPC file is read by bounds by its tiles
                continue
            # (a file cut to a box is binned whole: its points are numbered among those in the box)
            alone = (len(infos) == 1 and (one is None or one.clip is None)) or (one is not None and k == one.index)
            pieces = min(tiling.worker_count, info.count // BIN_PIECE_POINTS) if alone else 1
            records = _records_path(work, k)
            if pieces <= 1:
                bin_jobs.append(dict(key=("bin", k), path=info.path, file_index=k, grid=grid, work=work,
                                     records=records, clip=None if alone or one is None else one.clip))
                continue
            cuts = [info.count * p // pieces for p in range(pieces + 1)]
            bin_jobs += [dict(key=("bin", k, p), path=info.path, file_index=k, grid=grid, work=work, first=cuts[p],
                              stop=cuts[p + 1], piece=p, records=records) for p in range(pieces)]
        _map_files(_bin_job, bin_jobs, record_bin, tiling, steps, log, stage="binning", points=total,
                   paths=[info.path for info in infos] + [work], writable=[work], cluster=cluster, pool=pool)
        _say_beyond_header(infos, file_bounds, log)
        for k in sorted(binned_parts):  # in file (and piece) order, whatever order the jobs finished in
            for key, part in binned_parts[k].items():
                tiles.setdefault(key, []).append(part)
        # (a neighbour of the one file run keeps no class: a stand-in of one)
        classes = [np.lib.format.open_memmap(os.path.join(work, f"f{k:05d}.cls.npy"), mode="w+", dtype=np.uint8,
                                             shape=(max(info.count if one is None or one.index in (None, k)
                                                        else 0, 1),))
                   for k, info in enumerate(infos)]
        for c in classes:
            c.flush()
        del classes
        _reserve([os.path.join(work, f"f{k:05d}.cls.npy") for k in range(len(infos))], work)
        os.makedirs(done_dir)
        _save_json(binned, [dict(key=list(k), parts=[dataclasses.asdict(p) for p in v]) for k, v in tiles.items()])
    # a tile with buffer points only (its own area empty: a lake, a gap in the data) is no tile,
    # unless it is in the DTM: its cells are then interpolated from the ground around it, as a run
    # of the whole cloud does (it filters the buffer's points for their ground, and classifies none)
    keys = sorted(k for k, parts in tiles.items()
                  if sum(p.own_count for p in parts)
                  or (dtm_grid is not None and _block_cells(dtm_grid, grid.bounds(k)) is not None))
    from ..io.copc import plan_tiles
    copc_tiles = plan_tiles(infos, grid)  # the tiles COPC inputs may have points in
    keys = sorted(set(keys) | set(copc_tiles))
    if one is not None:
        keys = _one_files_tiles(keys, tiles, copc_tiles, one, grid, dtm_grid, infos, log)
    if copc_tiles:  # ... and those whose buffer reaches into them
        from ..io.copc import add_buffer_sources
        add_buffer_sources(copc_tiles, infos, keys, grid)
    n_copc = sum(1 for i in infos if i.copc)
    log(f"Binned into {len(keys)} tile(s) in {time.perf_counter() - t_start:.1f} s." if not n_copc else
        f"Planned {len(keys)} tile(s) in {time.perf_counter() - t_start:.1f} s ({n_copc} COPC file(s) read by "
        "bounds by each tile, not binned).")
    assigned = [0] * len(infos)
    crs_wkt = infos[0].crs_wkt
    # the points the run classifies, and what its messages name: one file's, or the survey's
    mine = infos if one is None or not one.one_file else [infos[one.index]]
    total_points = sum(i.count for i in mine)  # (a DTM's extent alone: those in its tiles, counted below)
    where = mine[0].path if len(mine) == 1 else f"{len(inputs)} input files" if one is None else \
        f"the {len(inputs)} input files within the DTM extent's reach"
    # 2. the DTM's block writer, on the grid run_tiled made from the headers
    dtm_writer = None
    if dtm_path:
        from ..raster.geotiff import BlockGeoTIFF
        from .workflow import length_label
        unit = length_label(dtm.metres_per_unit)  # (the notes' and the log's lengths, in the cloud's unit)
        heights = [abs(v) for i in infos if i.count for v in (i.mins[2], i.maxs[2])]
        dtm_writer = BlockGeoTIFF(os.path.join(work, "dtm.tif"), dtm_grid, crs_wkt=crs_wkt,
                                  largest_abs=max(heights, default=0.0))
        if rasters is not None:
            rasters.append(dtm_writer)
        if dtm.max_distance_m > grid.buffer:
            log(f"DTM: the maximum distance ({dtm.max_distance_m:g} m) is larger than the tiles' buffer "
                f"({grid.buffer:g} m), how far a tile sees beyond its edges: in gaps wider than the buffer the "
                "DTM may differ from tile to tile. Keep the distance at most the buffer, or set a larger tile "
                "buffer.")
    tile_log = []
    ground_total = dtm_points = 0  # the tiles' own ground points; those that entered the DTM
    classes_made: Dict[int, int] = {}  # {class: the tiles' own points given it by the filter}
    # the box of the points that may enter the DTM (neither withheld nor ignored), from the tiles: the
    # DTM is cut to it, as a whole run's grid spans those points only (None in a result: not known)
    area_box: Optional[list] = [math.inf, math.inf, -math.inf, -math.inf]
    data_gaps: list = []  # the gaps in the data the DTM spans (workflow.data_gaps), from the tiles
    hull_points: Optional[list] = []  # the first and last valued cells of the tiles' DTM rows (_block_hull)
    gap_sizes: list = []  # the smallest gap each tile names
    kept_out: Dict[int, int] = {}  # points kept in classes of their own, left out of the DTM
    replaced: Dict[int, int] = {}  # points of the input's other classes given 1 or 2
    demoted = [0, 0]  # points the input had as ground (2), and of them not ground now
    agreement = [0, 0, 0, 0, 0]  # the run's ground against the input's classes (workflow.agreement_counts)
    below = [0, 0]  # the tiles' points well below their DTM blocks, and over them (workflow.floating_note)
    not_last = [0, 0]  # ground points, and of them not their pulse's last return
    ground_by_class: Dict[int, int] = {}  # the DTM from classes: the tiles' own ground, by class
    structures: Dict[int, int] = {}  # those of its structure classes made ground
    filter_steps = steps.sub(0.3, 0.85)
    t_tiles = time.perf_counter()
    class_paths = [os.path.join(work, f"f{k:05d}.cls.npy") for k in range(len(infos))]
    class_parts: List[list] = [[] for _ in infos]  # on a cluster: each tile's classes, per file
    # the jobs open the memmaps themselves (in threads or in worker processes)
    workers = max(1, min(tiling.worker_count, len(keys)))
    mode = tiling.parallel if tiling.parallel != "auto" else _auto_parallel(sum(i.count for i in infos))
    use_processes = workers > 1 and mode == "processes"
    done_before = [_load_done(done_dir, key) for key in keys]
    failed = threading.Event()  # a tile failed: the tiles running in other threads stop at their next check

    def tile_cancelled() -> bool:
        return failed.is_set() or steps.is_cancelled()
    if any(d is not None for d in done_before):
        log(f"{sum(d is not None for d in done_before)} of {len(keys)} tile(s) were done before; skipping them.")
    sent = algorithm
    if use_processes or tiling.scheduler:  # (sent to each worker once, not with every job: sent_once.py)
        from .sent_once import SentOnce
        sent = SentOnce(algorithm, os.path.join(work, "algorithm.pickle"))
    jobs = [dict(key=key, parts=tiles.get(key, []), copc=copc_tiles.get(key, []), bounds=grid.bounds(key),
                 buffer=grid.buffer, done_dir=done_dir,
                 names=sorted({os.path.basename(inputs[p.file_index])
                               for p in tiles.get(key, []) + copc_tiles.get(key, [])}),
                 paths={p.file_index: inputs[p.file_index] for p in tiles.get(key, []) + copc_tiles.get(key, [])},
                 class_paths=class_paths, algorithm=sent, options=options, dtm=dtm if dtm_path else None,
                 dtm_grid=dtm_writer.grid if dtm_writer is not None else None,
                 is_cancelled=None if use_processes or tiling.scheduler else tile_cancelled,
                 own_classes=bool(tiling.scheduler), only=None if one is None else one.index)
            for key, before in zip(keys, done_before) if before is None]
    if not tiling.scheduler:  # (a cluster run says where its tiles go)
        log(f"{len(keys)} tile(s) on {workers} worker(s) ({'processes' if use_processes else 'threads'}).")

    def record(result, resumed=False):
        nonlocal ground_total, dtm_points, area_box, hull_points
        if result is None:
            return
        steps.check()
        for k, part in (result.get("class_parts") or {}).items():  # a cluster tile: its write job applies it
            class_parts[int(k)].append(part)
        for k, count in result["assigned"].items():
            assigned[int(k)] += count
        if result["block"] is not None:
            dtm_writer.write_block(*result["block"])
        for code, count in result.get("kept_out", ()):
            kept_out[int(code)] = kept_out.get(int(code), 0) + int(count)
        for code, count in result.get("ground_classes", ()):
            ground_by_class[int(code)] = ground_by_class.get(int(code), 0) + int(count)
        for k, count in enumerate(result.get("demoted", (0, 0))):
            demoted[k] += int(count)
        for k, count in enumerate(result.get("agreement", (0, 0, 0, 0))[:4]):
            agreement[k] += int(count)
        for k, count in enumerate(result.get("below", (0, 0))):
            below[k] += int(count)
        for k, count in enumerate(result.get("not_last", (0, 0))):
            not_last[k] += int(count)
        for code, count in result.get("replaced", ()):
            replaced[int(code)] = replaced.get(int(code), 0) + int(count)
        for code, count in result.get("structures", ()):
            structures[int(code)] = structures.get(int(code), 0) + int(count)
        for code, count in result.get("classes", ()):
            classes_made[int(code)] = classes_made.get(int(code), 0) + int(count)
        ground_total += result["ground"]
        dtm_points += result["dtm_points"]
        if "hull" not in result:  # (a tile done by an earlier version, resumed)
            hull_points = None
        elif hull_points is not None:
            hull_points.extend(result["hull"])
        if result.get("gaps"):
            gap_sizes.append(result["gaps"][0])
            data_gaps.extend(tuple(g) for g in result["gaps"][1:])
        if "area_bounds" not in result:  # (a tile done by an earlier version, resumed)
            area_box = None
        elif result["area_bounds"] is not None and area_box is not None:
            b = result["area_bounds"]
            area_box = [min(area_box[0], b[0]), min(area_box[1], b[1]), max(area_box[2], b[2]), max(area_box[3], b[3])]
        tile_log.append(dict(key=tuple(result["key"]), points=result["own"], read=result["read"],
                             ground=result["ground"], copc_read=result.get("copc_read", 0)))
        done_frac = len(tile_log) / len(keys)
        filter_steps.report(done_frac)
        if resumed:  # a tile of the interrupted run: counted, not told again (the log said how many)
            return
        pace["done"] += 1
        pace["last"] = time.perf_counter()
        # the time left at the pace of this run's tiles (a resumed run's earlier tiles took none of it)
        left = time_left(pace["last"] - pace["start"], pace["done"], workers, len(keys) - len(tile_log))
        x0, y0 = grid.bounds(tuple(result["key"]))[:2]
        log(f"Tile {len(tile_log)}/{len(keys)} at {x0:.0f}, {y0:.0f}: {result['own']:,} points "
            f"(+{result['read'] - result['own']:,} buffer), {result['ground']:,} ground; "
            f"about {left:.0f} s left.")

    # Between two finished tiles the bar moves on at the pace of those finished so far in this run
    # (never past the next one): with few large tiles on worker processes it stood still for minutes.
    pace = {"done": 0, "last": None, "start": time.perf_counter()}

    def tick():
        steps.check()
        if pace["done"]:
            per_tile = (pace["last"] - pace["start"]) / pace["done"]
            ahead = min(0.9, (time.perf_counter() - pace["last"]) / max(per_tile, 1e-6))
            filter_steps.report(min(1.0, (len(tile_log) + ahead) / len(keys)))

    for before in done_before:
        if before is not None:
            record(before, resumed=True)
    pace.update(done=0, start=time.perf_counter())  # (the pace of this run's tiles only)
    if tiling.scheduler:
        from .cluster import run_jobs
        run_jobs(tiling.scheduler, _tile_job, jobs, record, is_cancelled=steps.is_cancelled,
                 paths=[info.path for info in infos] + [work], log=log,
                 # the output folders too: the workers write the classified files there at the end
                 writable=[done_dir] + sorted({_existing_folder(o) for o in outs if o}),
                 names=lambda job: job_name(job["bounds"], job["names"]),
                 **({"cluster": cluster} if cluster is not None else {}))
    elif workers == 1:
        for job in jobs:
            steps.check()
            record(_tile_job(job))
    else:
        with _pool(workers, use_processes, pool) as tile_pool:
            try:
                _record_as_completed(tile_pool, _tile_job, jobs, record, tick,
                                     stage=f"tiles of {_few({n for job in jobs for n in job['names']})}")
            except BaseException:
                failed.set()  # (worker processes are stopped by the run: stop_workers)
                raise
    for k, info in enumerate(infos):
        if one is not None and k != one.index:
            continue  # (a neighbour lends its points to the tiles' buffers; none of them is classified)
        if assigned[k] != info.count:
            raise InputError(f"{info.path}: {assigned[k]:,} of {info.count:,} points were classified; "
                             "the file's header and its points disagree")
    if one is not None and not one.one_file:
        total_points = sum(assigned)
    if one is not None and area_box is not None:
        # (the box of the points that may enter the DTM, over the whole survey: the tiles this run filtered
        # know theirs only; beyond them the headers tell: a DTM extent past the survey's edge lost 615 cells
        # the whole run has, a code reviewer)
        sb = one.survey_box
        area_box = [min(area_box[0], sb[0]), min(area_box[1], sb[1]), max(area_box[2], sb[2]), max(area_box[3], sb[3])]
    resumed = sum(d is not None for d in done_before)  # (said apart: "Filtered 144" had counted 54 done before)
    log(f"{getattr(algorithm, 'tiles_done_words', 'Filtered')} {len(keys) - resumed} tile(s) in "
        f"{time.perf_counter() - t_tiles:.1f} s" + (f", and {resumed} done before." if resumed else "."))
    if getattr(algorithm, "ground_of_any_class", False):
        from .workflow import ground_classes_counts
        chosen = {c: ground_by_class.get(c, 0) for c in getattr(algorithm, "classes", ())}
        log(f"Ground: {ground_total:,} of {total_points:,} points, of the ground classes "
            f"({ground_classes_counts(None, chosen)}).")
    dtm_out = None
    if dtm_writer is not None:
        wanted = workflow.extent_grid(dtm, max_cells=MAX_SURVEY_DTM_CELLS, bytes_per_cell=0.0)
        if wanted is not None and one is not None:  # (the extent's cells over the one file, run_tiled made them)
            wanted = dtm_writer.grid
        dtm_out = _dtm_extent(dtm_writer.grid, area_box, log) if wanted is None else wanted
        if wanted is not None:  # (an extent without ground is warned about, as a whole run's)
            points = _dtm_extent(dtm_writer.grid, area_box, lambda _m: None)
            if points is not dtm_writer.grid:  # beyond the points' box nodata, as the whole run's DTM placed in it
                dtm_writer.blank_outside(points)
            workflow.say_extent(dtm_out, None if dtm_writer.has_values_in(dtm_out) else 0, unit, log,
                                "the extent given" if one is None or not one.one_file else
                                f"the extent given over {os.path.basename(inputs[one.index])}'s cells")
    if dtm_out is not None and not n_copc and one is None:  # (one file's neighbours hold a few tiles' points)
        _say_stray_tiles(tiles, grid, dtm_out, log)
    # (as a whole run refuses it, not an empty DTM written; an extent's or a file's DTM in a gap of the data,
    # made from the ground around it, has cells though no point of its own: a flood modeller's domain)
    if dtm_writer is not None and not dtm_points and not (one is not None and dtm_writer.valued_cells):
        why = getattr(algorithm, "no_ground_in_survey", "")
        if why:  # (the DTM from classes filters nothing: its input lacks the classes; an HPC reviewer)
            raise InputError(f"{where}: no DTM can be made: {why}")
        raise InvalidParameterError(f"{where}: the filter found no ground point in any tile: no DTM can be made")
    # every tile is done (and marked so for a resumed run): its parts make room for the write's pieces
    for parts in tiles.values():
        for part in parts:
            for name in (part.index_path, part.copy_path):
                if name and os.path.exists(name):
                    os.remove(name)
    # 3. write the outputs: every classified file, the .vpc and the DTM under temporary names, put in
    # place together once all are complete (StagedOutputs): a run that fails or is stopped here leaves
    # none of them, and the previous run's set of the same names untouched
    # (with a DTM to write after them, the classified files do not take the bar to 100 %: the DTM's
    # cloud-optimised copy takes a while at fine cells, and 100 % means every output is in place)
    write_steps = steps.sub(0.85, 0.95 if dtm_writer is not None else 0.99)
    t_write = time.perf_counter()
    written = []
    with _output_folders(outs), StagedOutputs() as staging:
        staged = [staging.stage(out) if out else None for out in outs]
        _write_classified(infos, outs, staged, work, class_paths, class_parts, tiling, steps, log, write_steps,
                          written, cluster, pool)
        if written:  # (a run for its DTM alone writes none)
            log(f"Wrote {len(written)} classified file(s) in {time.perf_counter() - t_write:.1f} s.")
        if output_path and _ext(output_path) == VPC_EXTENSION:
            from ..raster.crs import lonlat_box
            write_vpc(staging.stage(output_path), [scan_header(o) for o in staged], outs, lonlat=lonlat_box)
        from .workflow import agreement_note, canopy_ground_note, demoted_note, replaced_note, structures_warning
        for note in (demoted_note(*demoted, algorithm), canopy_ground_note(*not_last, algorithm),
                     agreement_note(agreement, algorithm, options)):
            if note:
                log(note)
        note = replaced_note(replaced, algorithm)
        if note:
            log(note)
        warning = structures_warning(structures, replaced, where, algorithm)
        if warning:
            log(warning)
        if dtm_writer is not None:
            from .workflow import kept_out_note
            note = kept_out_note(kept_out, algorithm, dtm)
            if note:
                log(note)
            _say_enclosed_nodata(dtm_writer, dtm, grid.buffer, log, hull_points, unit)
            from ..grids.rasterize import PIT_DEPTH
            from .workflow import dtm_spacing_note, floating_note, gaps_note, pits_note
            # (the smallest gap named: the largest of the tiles', whose point spacings differ a little)
            note = gaps_note(data_gaps, max(gap_sizes), unit) if data_gaps else ""
            if note:
                log(note)
            mpu = dtm.metres_per_unit
            note = floating_note(*below, mpu, unit)
            if note:
                log(note)
            pits, spikes = dtm_writer.isolated_pits_and_spikes(check=steps.check, depth=PIT_DEPTH / mpu)
            for note in ("" if dtm.fill_outside_hull else
                         dtm_spacing_note(dtm_points, dtm_writer.valued_cells, dtm_writer.grid.cell, unit),
                         pits_note(*pits, dtm_writer.grid, mpu), pits_note(*spikes, dtm_writer.grid, mpu, spikes=True)):
                if note:
                    log(note)
            dtm_writer.finish(staging.stage(dtm_path), atomic=False, name=dtm_path, grid=dtm_out)
        steps.check()
        staging.commit()
    if dtm_writer is not None:
        g = dtm_out
        log(f"Wrote the DTM {dtm_path} ({g.ncols:,} x {g.nrows:,} cells of {g.cell:g} {unit}).")
    steps.report(1.0)
    log(f"Done in {time.perf_counter() - t_start:.1f} s.")
    return TiledRun(inputs if one is None or not one.one_file else [inputs[one.index]], [o for o in outs if o],
                    total_points,
                    ground_total, crs_wkt,
                    grid.size, grid.buffer, len(tile_log), dtm_path, tile_log=tile_log,
                    copc_inputs=[i.path for i in infos if i.copc], algorithm=algorithm,
                    class_counts=dict(sorted(classes_made.items())))


def _one_files_tiles(keys, tiles, copc_tiles, one, grid, dtm_grid, infos, log) -> list:
    """The tiles the run of one file filters (engine/one_file.py): those holding its points, and with a
    DTM those making its cells (``dtm_grid``, the survey DTM's cells over its header bounds), whose
    values then come from the same points as in the run of the whole survey. A tile of its points beyond
    its header's bounds lies beyond the area its neighbours lent points for: said."""
    k = one.index
    i0, i1, j0, j1 = one.tiles
    chosen, beyond = [], 0
    for key in keys:
        holds = any(p.file_index == k and p.own_count for p in tiles.get(key, ())) \
            or any(src.file_index == k for src in copc_tiles.get(key, ()))
        inside = i0 <= key[0] <= i1 and j0 <= key[1] <= j1
        if holds or (inside and dtm_grid is not None and _block_cells(dtm_grid, grid.bounds(key)) is not None):
            chosen.append(key)
            beyond += holds and not inside
    if beyond:
        log(f"{WARNING_PREFIX}{infos[k].path}: {beyond:,} tile(s) of its points lie beyond its header's bounds, so "
            "beyond the area its neighbours' points were read for: near them, its classes may differ from a run "
            "of the whole survey. Rewrite the file with a tool that recomputes its header.")
    return chosen


@contextlib.contextmanager
def _output_folders(outs):
    """Make the folders of the classified files; those made here are removed again (when empty) if
    the run fails (a reviewer's failed .vpc run left its empty folder of classified files)."""
    made = []
    for folder in sorted({os.path.dirname(os.path.abspath(out)) for out in outs if out}):
        if not os.path.isdir(folder):
            os.makedirs(folder)
            made.append(folder)
    try:
        yield
    except BaseException:
        for folder in reversed(made):
            try:
                os.rmdir(folder)
            except OSError:
                pass
        raise


def _block_hull(block, grid) -> list:
    """A tile's share of the survey's ground hull, few numbers to return: the centres of the first and last
    cell with a value of each row of its DTM block, [[x, y], ...] (their hull is the hull of the block's
    values; the hull of the tile's ground points cost 0.1-0.5 s a tile, as much as 12 % of a run)."""
    if block is None:
        return []
    row0, col0, values = block
    valued = ~np.isnan(values)
    rows = np.flatnonzero(valued.any(axis=1))
    if rows.size == 0:
        return []
    first = valued[rows].argmax(axis=1)
    last = values.shape[1] - 1 - valued[rows][:, ::-1].argmax(axis=1)
    y = grid.top - (row0 + rows + 0.5) * grid.cell
    xs = [grid.x0 + (col0 + first + 0.5) * grid.cell, grid.x0 + (col0 + last + 0.5) * grid.cell]
    return np.column_stack([np.concatenate(xs), np.concatenate([y, y])]).tolist()


def _survey_hull(points) -> Optional[np.ndarray]:
    """The convex hull (its vertices in order) of the tiles' hull points; None when it has no area."""
    if points is None or len(points) < 3:
        return None
    from scipy.spatial import ConvexHull, QhullError
    xy = np.asarray(points, dtype=np.float64)
    try:
        return xy[ConvexHull(xy).vertices]
    except QhullError:
        return None


#: files whose first points the DTM from classes samples before its tiles, and points of each
UNCLASSIFIED_SAMPLE_FILES, UNCLASSIFIED_SAMPLE_POINTS = 16, 65536


def _say_if_unclassified(infos, algorithm, log) -> None:
    """Before the tiles of a DTM from classes: warn when the first points of the survey's first files hold
    none of the ground classes, as an unclassified survey's do. A survey without them was refused only after
    every tile had been read (the headers do not count classes); a sample cannot refuse it (a file sorted in
    space may begin under a roof), so the warning says when to stop the run."""
    from ..io.lasfiles import first_classes
    from ..io.clouds import class_counts_text, count_classes
    sampled = [i for i in infos if i.count and not i.copc][:UNCLASSIFIED_SAMPLE_FILES]
    if not sampled:
        return
    try:
        classes = np.concatenate([first_classes(i.path, UNCLASSIFIED_SAMPLE_POINTS) for i in sampled])
    except Exception:  # noqa: BLE001 - a damaged file: the tiles' reading names it in words (lazrs raised here)
        return
    if classes.size == 0 or np.isin(classes, list(algorithm.classes)).any():
        return
    codes = ", ".join(str(c) for c in algorithm.classes)
    log(f"{WARNING_PREFIX}the first {classes.size:,} points of {len(sampled):,} of the input files hold no point of "
        f"class {codes} ({class_counts_text(count_classes(classes))}): an unclassified survey? The run refuses it "
        "only after its last tile: if so, stop it and classify the ground first with a ground filter, or name the "
        "classes that hold it.")


def _say_enclosed_nodata(writer, dtm, buffer_m: float, log, hull_points=None, unit: str = "m") -> None:
    """Say when the tiled DTM left cells empty that a run of the whole cloud fills: a tile sees ground
    only as far as its buffer, so in a gap (a lake, a missing flight line) wider than that its block has
    no value there, where one triangulation of the whole cloud spans the gap (a flood modeller's 120 m
    lake: 32 empty cells and a 0.97 m step at a tile edge, not a word in the log). Cells with values
    around them in their row and their column are warned about, with the advice of a wider buffer. The
    whole run fills the convex hull of the ground, bays open to the data's edge too (a coastline, a river
    running off the survey: a flood modeller's 40,002 such cells went unsaid): with the tiles' hulls
    (``hull_points``) those are said too, as a note, since the whole run's triangles across them are no
    measured terrain either (a code reviewer's bay, which a warning told to fill with a buffer as wide).
    With a maximum distance or a fill the empty cells are the rule's."""
    if dtm.max_distance_m > 0 or dtm.fill_outside_hull:
        return
    hull = _survey_hull(hull_points)
    empty, inside = writer.empty_cells(hull)
    if empty:
        log(f"{WARNING_PREFIX}DTM: {empty:,} cell(s) with values around them in their row and their column stayed "
            f"nodata: a gap in the data there (a lake, a missing strip) is wider than the tiles' buffer ({buffer_m:g} "
            f"{unit}), which a tile cannot see across, while a run of the whole cloud interpolates across it (near "
            "such gaps the tiled DTM may also step at tile edges). A tile buffer of at least the gap's width gives "
            "the whole run's DTM; to leave such gaps empty on purpose (water without returns), set a DTM maximum "
            "distance (tiled or whole, without this warning).")
    open_cells = inside - empty
    if open_cells > 0:
        log(f"DTM: {open_cells:,} cell(s) inside the outline of the ground (its convex hull) stayed nodata in bays or "
            f"channels of the data open to its edge (a coastline, a river without returns) wider than the tiles' "
            f"buffer ({buffer_m:g} {unit}): a run of the whole cloud draws triangles across them, which are not "
            "measured terrain either. A tile buffer as wide gives the whole run's DTM; to compare two runs (epochs), "
            "run both in tiles of the same size.")


def _existing_folder(path: str) -> str:
    """The folder of ``path``, or its nearest ancestor that exists (a survey's output folder is
    made at the write)."""
    folder = os.path.dirname(os.path.abspath(path))
    while not os.path.isdir(folder) and os.path.dirname(folder) != folder:
        folder = os.path.dirname(folder)
    return folder


def _write_classified(infos, outs, staged, work, class_paths, class_parts, tiling, steps, log, write_steps,
                      written, cluster, pool) -> None:
    """Each input's classified copy, written to its staged name ``staged[k]`` (``outs[k]`` is the
    name it will have)."""
    # Each input's records were kept in file order by the binning: the classified copy is written
    # from them without decoding the input again, in pieces of consecutive points (a big single
    # file: one per worker, each on LAZ chunk boundaries) compressed on the workers, then put
    # together (header, the pieces' chunks, one chunk table) by one job per file.
    pieces_of = _write_pieces(infos, outs, tiling)
    write_jobs = [dict(key=("write", k, p), path=info.path, records=_records_path(work, k), out=outs[k],
                       piece_path=os.path.join(work, f"f{k:05d}w{p:04d}.piece"), first=a, stop=b,
                       class_path=class_paths[k], class_parts=sorted(class_parts[k]), count=info.count)
                  for k, info in enumerate(infos) if outs[k] for p, (a, b) in enumerate(pieces_of[k])]
    pieces: Dict[int, list] = {}
    total_jobs = len(write_jobs) + sum(1 for o in outs if o)

    def record_piece(result):
        pieces.setdefault(result["file_index"], []).append(result)
        write_steps.report(sum(map(len, pieces.values())) / total_jobs)

    _map_files(_write_piece_job, write_jobs, record_piece, tiling, steps, log, stage="writing",
               points=sum(i.count for i in infos),
               paths=[info.path for info in infos] + [work], writable=[work], cluster=cluster, pool=pool)

    def record_write(result):
        written.append(result)
        write_steps.report((len(write_jobs) + len(written)) / total_jobs)
    assemble_jobs = [dict(key=("assemble", k), path=info.path, out=staged[k], name=outs[k], pieces=pieces.get(k, []),
                          class_path=class_paths[k], class_parts=sorted(class_parts[k]), count=info.count)
                     for k, info in enumerate(infos) if outs[k]]
    _map_files(_assemble_job, assemble_jobs, record_write, tiling, steps, log, stage="writing",
               points=sum(i.count for i in infos),
               paths=[info.path for info in infos] + [work],
               writable=sorted({os.path.dirname(os.path.abspath(o)) for o in outs if o} | {work}), cluster=cluster,
               pool=pool)


def _bin_job(job) -> dict:
    """Bin one input file into its tile parts (a pure function of its job: same parts, same names)."""
    first, stop = job.get("first", 0), job.get("stop")
    bounds: list = []
    parts = bin_file(job["path"], job["file_index"], job["grid"], job["work"], check=job.get("check"),
                     first=first, stop=stop, piece=job.get("piece"), records=job.get("records"), bounds=bounds,
                     clip=job.get("clip"))
    points = (stop if stop is not None else scan_header(job["path"]).count) - first
    return dict(file_index=job["file_index"], first=first, parts=parts, points=points, bounds=bounds)


def _say_beyond_header(infos, bounds: dict, log) -> None:
    """Warn about files whose points lie beyond their header's bounds, which the survey's DTM grid is
    made from: a file whose header said x ended 20 m short of its points lost that strip of the DTM
    without a word (a QA reviewer). ``bounds``: {file index: the points' stored [xmin, ymin, xmax,
    ymax]}."""
    import laspy
    for k, (x0, y0, x1, y1) in sorted(bounds.items()):
        info = infos[k]
        with laspy.open(info.path) as reader:
            scales, offsets = reader.header.scales, reader.header.offsets
        lo = (x0 * scales[0] + offsets[0], y0 * scales[1] + offsets[1])
        hi = (x1 * scales[0] + offsets[0], y1 * scales[1] + offsets[1])
        slack = (scales[0], scales[1])
        if any(lo[i] < info.mins[i] - slack[i] or hi[i] > info.maxs[i] + slack[i] for i in (0, 1)):
            log(f"{WARNING_PREFIX}{info.path}: its points reach x {lo[0]:,.2f} to {hi[0]:,.2f}, y {lo[1]:,.2f} to "
                f"{hi[1]:,.2f}, beyond its header's bounds (x {info.mins[0]:,.2f} to {info.maxs[0]:,.2f}, y "
                f"{info.mins[1]:,.2f} to {info.maxs[1]:,.2f}): the points are classified, but the DTM, made for the "
                "headers' bounds, leaves out those beyond them. Rewrite the file with a tool that recomputes its "
                "header (e.g. PDAL's translate, LAStools' lasinfo -repair_bb).")


def _records_path(work: str, file_index: int) -> str:
    """The input's records in file order, uncompressed, as the binning decoded them."""
    return os.path.join(work, f"f{file_index:05d}.rec")


#: a single input's classified copy is written in pieces of at least this many points, one per worker
WRITE_PIECE_POINTS = BIN_PIECE_POINTS


def _write_pieces(infos, outs, tiling) -> List[list]:
    """Each input's pieces of the classified copy, as (first, stop): one piece per file, or for a
    single big file one per worker (worker processes or a cluster: in threads, lazrs holds the GIL),
    cut on LAZ chunk boundaries."""
    from ..io.lasfiles import laz_chunk_points
    mode = tiling.parallel if tiling.parallel != "auto" else _auto_parallel(sum(i.count for i in infos))
    split = sum(1 for o in outs if o) == 1 and (mode == "processes" or bool(tiling.scheduler))
    result = []
    for info, out in zip(infos, outs):
        if not out or not info.count or info.copc:  # a COPC input has no kept records: it is streamed
            result.append([])
            continue
        pieces = min(tiling.worker_count, info.count // WRITE_PIECE_POINTS) if split else 1
        if pieces > 1:
            import laspy
            with laspy.open(info.path) as reader:
                cuts = piece_cuts(info.count, pieces, laz_chunk_points(reader.header.point_format))
        else:
            cuts = [0, info.count]
        result.append(list(zip(cuts[:-1], cuts[1:])))
    return result


def _file_classes(job, first: int, stop: int) -> np.ndarray:
    """Points ``first`` to ``stop`` of one input's classes, as its tiles wrote them: in the per-file
    memmap, or on a cluster in one part per tile that held points of the file, applied here on the
    worker (so that the client never handles points); a resumed run may have tiles of both kinds."""
    classes = np.array(np.load(job["class_path"], mmap_mode="r")[first:stop])
    for part in job.get("class_parts") or ():
        with np.load(part) as saved:
            index = saved["index"]
            sel = (index >= first) & (index < stop)
            classes[index[sel] - first] = saved["cls"][sel]
    return classes


def _write_piece_job(job) -> dict:
    """Points ``first`` to ``stop`` of one input's classified copy (a pure function of its job): the
    records the binning kept, with the classes the tiles wrote (:func:`_file_classes`), compressed
    into a piece file of the working folder."""
    first, stop = job["first"], job["stop"]
    classes = _file_classes(job, first, stop)
    piece = write_classified_piece(job["path"], job["records"], classes, first, stop, job["piece_path"],
                                   compress=_ext(job["out"]) == ".laz", check=job.get("check"))
    piece["file_index"] = int(job["key"][1])
    return piece


def _assemble_job(job) -> dict:
    """One input's classified copy (atomic) from its pieces; an input without kept records (a COPC
    input, or one without points) is streamed with the classes its tiles wrote."""
    if not job["pieces"]:
        write_classified_stream(job["path"], job["out"], _file_classes(job, 0, job["count"]),
                                check=job.get("check"), name=job.get("name"), atomic=False)  # (staged already)
    else:
        assemble_classified(job["path"], job["out"], job["pieces"], name=job.get("name"), atomic=False)
        for piece in job["pieces"]:
            os.remove(piece["path"])
    return dict(out=job["out"])


def worker_thread_environ(threads: int) -> Dict[str, str]:
    """The environment that holds a worker process to ``threads`` threads of its own: numba's
    parallel kernels (NUMBA_NUM_THREADS) and lazrs's LAZ (de)compression (RAYON_NUM_THREADS; laspy
    uses lazrs's parallel backend when it can). Without it every worker would start one thread per
    core of the machine, and N workers on N cores would run N x N threads."""
    return {"NUMBA_NUM_THREADS": str(max(1, threads)), "RAYON_NUM_THREADS": str(max(1, threads))}


def keep_freed_memory() -> bool:
    """Have glibc's malloc keep the memory a worker process frees for its next tiles instead of
    giving it back to the system: no allocation by ``mmap`` (each large array would be unmapped when
    freed) and no trimming of the heap. A tile allocates and frees the same large arrays as the one
    before, and memory handed back is zeroed and faulted in again page by page for the next: on
    this machine (a VM that hands freed pages back to its host) that is 2 s a GB the first time
    against 0.1 s reused. Measured on 20 M points (one process, 7 tiles): the tiles' system time
    1.77 -> 0.64 s, their time 9.9 -> 8.9 s, the peak RSS the same (0.80 / 0.84 GB);
    docs/BENCHMARKS.md. Only in the worker processes the engine starts (never in QGIS itself);
    False where the C library is not glibc."""
    from ..machine import mallopt as glibc_mallopt
    mallopt = glibc_mallopt()
    if mallopt is None:
        return False
    M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4  # (malloc.h)
    return bool(mallopt(M_MMAP_MAX, 0)) and bool(mallopt(M_TRIM_THRESHOLD, 2 ** 31 - 1))


def _init_worker(environ: Dict[str, str], parent: int = 0) -> None:
    os.environ.update(environ)  # before the job imports numba or starts lazrs's thread pool
    keep_freed_memory()
    from ..machine import fit_address_space, warm_blas
    fit_address_space()
    warm_blas(1)  # (a worker process runs one tile at a time: one BLAS buffer, taken before its tiles)
    import signal
    # Ctrl-C in a terminal reaches every process of the group: the run that started this worker
    # decides (it stops its workers, see stop_workers), not a KeyboardInterrupt traceback per worker
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent:
        _exit_with_parent(parent)


#: the share of a Dask task's memory (a worker's memory limit over its threads) a tile is planned to
#: use: Dask starts spilling at 60 % of a worker's limit and pauses it at 80 %, and a worker process
#: holds its imports (numba, scipy, laspy: about 0.4 GB) besides
CLUSTER_TASK_SHARE = 0.5
#: tiles planned for each thread of a Dask cluster, at least (where the tiles stay above 50 m): a
#: survey is spread over every worker, and a slow tile does not hold the run's end alone
TILES_PER_THREAD = 4


#: how often a worker process looks whether the run that started it is still there (s)
PARENT_POLL_S = 0.5


def _exit_with_parent(parent: int) -> None:
    """End this worker process when the process that started it ends: a run killed (kill -9, or a
    SIGTERM from systemd, timeout or a batch scheduler, which Python does not turn into cleanup) would
    otherwise leave its workers waiting for jobs for ever, holding their memory and the run's output
    pipe. POSIX: the parent's end re-parents this process (os.getppid() changes)."""
    if os.name != "posix":
        return

    def watch():
        while os.getppid() == parent:
            time.sleep(PARENT_POLL_S)
        os._exit(1)
    threading.Thread(target=watch, name="groundsieve-parent-watch", daemon=True).start()


def started_by_a_script() -> Optional[str]:
    """The Python script (a file) this process was started with, if any: spawned worker processes import it
    again (not the command line's ``python -m groundsieve``, nor QGIS)."""
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    spec = getattr(main, "__spec__", None)
    if not path or (spec is not None and (spec.name or "").split(".")[0] == "groundsieve"):
        return None
    return path


def refuse_in_a_workers_import() -> None:
    """Refuse a run started while a worker process imports the script that started the engine: spawned
    workers import the parent's ``__main__`` again, and a script without ``if __name__ == "__main__":`` ran
    its runs again in every worker (each refused by the working folder's lock, or, for small files, run
    and written again), while the run itself ended with "a worker ended abruptly ... lack of memory" (a
    research software engineer)."""
    import multiprocessing.process
    if getattr(multiprocessing.process.current_process(), "_inheriting", False):
        raise GroundSieveError(
            f"{getattr(sys.modules.get('__mp_main__'), '__file__', None) or 'the script'}: a GroundSieve worker "
            "process is importing this script, "
            "which starts a run at import: put the script's work under `if __name__ == \"__main__\":` (worker "
            "processes import the script that started the run; docs/API.md)")


def _worker_pool(workers: int, use_processes: bool):
    """The pool the tiles and the per-file jobs run on: spawned worker processes (with this QGIS's
    Python when it is not sys.executable), each with its share of the cores, or threads."""
    if not use_processes:
        return ThreadPoolExecutor(max_workers=workers)
    import multiprocessing
    ctx = multiprocessing.get_context("spawn")
    exe = _python_executable()
    if exe:
        ctx.set_executable(exe)
    from ..machine import usable_cpus
    share = max(1, usable_cpus() // workers)
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                               initargs=(worker_thread_environ(share), os.getpid()))
    # A pool whose workers died (killed for memory, or refusing a script without a main guard) hung the run for
    # good when a job larger than a pipe's 64 kB (one with a model: the hybrid's 210 kB, a C2 forest's 2 MB) was
    # being sent: Python 3.11's executor, breaking, joins the queue's feeder thread, which waits for a reader that
    # is gone (CPython gh-107219). The run, not the feeder, is then what ends.
    queue = getattr(pool, "_call_queue", None)
    if queue is not None and hasattr(queue, "cancel_join_thread"):
        queue.cancel_join_thread()
    return pool


def stop_workers(pool) -> None:
    """End a process pool's worker processes now, with the tiles they are running: a run that fails
    (a tile's error) or is stopped (cancel, Ctrl-C, SIGTERM) does not wait for tiles whose results
    it will not use before it says why and cleans up (a worker's files are written atomically, so
    a killed tile leaves nothing a resumed run would take for done). The pool is broken after this;
    the run shuts it down. Threads cannot be stopped from outside: a thread pool is left alone."""
    processes = getattr(pool, "_processes", None)  # (ProcessPoolExecutor's; no public way before 3.14)
    for process in list((processes or {}).values()):
        try:
            process.terminate()
        except (OSError, AttributeError, ValueError):
            continue


def _pool(workers: int, use_processes: bool, shared=None):
    """The run's shared pool of worker processes (kept open), or a pool of its own."""
    if use_processes and shared is not None:
        import contextlib
        return contextlib.nullcontext(shared)
    return _worker_pool(workers, use_processes)


def _map_files(function, jobs, record, tiling, steps, log, *, stage, paths, writable, points, cluster=None,
               pool=None) -> None:
    """Run one job per input file (binning, writing) on the run's workers: the Dask cluster, worker
    processes or threads as for the tiles (of a run of ``points`` points), ``record``-ing each result
    in the client as it comes; ``stage`` ("binning", "writing") names it when a worker process dies."""
    if not jobs:
        return
    workers = max(1, min(tiling.worker_count, len(jobs)))
    mode = tiling.parallel if tiling.parallel != "auto" else _auto_parallel(points)
    if tiling.scheduler:
        from .cluster import run_jobs
        run_jobs(tiling.scheduler, function, jobs, record, is_cancelled=steps.is_cancelled, paths=paths,
                 writable=writable, log=log, names=lambda job: os.path.basename(job["path"]),
                 **({"cluster": cluster} if cluster is not None else {}))
        return
    if workers == 1 or mode != "processes":
        jobs = [dict(job, check=steps.check) for job in jobs]  # cancellation inside the file's pass
    if workers == 1:
        for job in jobs:
            steps.check()
            record(function(job))
        return
    with _pool(workers, mode == "processes", pool) as file_pool:
        _record_as_completed(file_pool, function, jobs, record, steps.check,
                             stage=f"{stage} of {_few({os.path.basename(j['path']) for j in jobs})}")


def _few(names) -> str:
    """A few file names for a message, or how many there are."""
    names = sorted(names)
    return ", ".join(names) if len(names) <= 3 else f"{len(names)} files"


#: how often the client looks at the cancel callable while its workers run (s)
CHECK_EVERY_S = 0.2


def _record_as_completed(pool, function, jobs, record, check=None, stage="jobs") -> None:
    """Run ``function`` on each job in ``pool`` and ``record`` each result as it comes, then let it
    go: a list of done futures would keep every result (a tile's DTM block) alive in the client
    until the last one. ``check`` is called every :data:`CHECK_EVERY_S` while the workers run (a
    worker process does not see the cancel; its run stops it). On an error or a cancel the jobs not
    started are cancelled. A worker process that dies (killed by the system for lack of memory,
    a crash in native code) fails the run with the ``stage`` it was in and the likely cause, not a
    traceback (every job of the pool fails then, so the one that ran in it is not known)."""
    from concurrent.futures.process import BrokenProcessPool
    pending = {pool.submit(function, job) for job in jobs}
    del jobs
    try:
        while pending:
            if check is not None:
                check()
            done, _ = futures_wait(pending, timeout=CHECK_EVERY_S, return_when=FIRST_COMPLETED)
            while done:  # (popped: a future in ``done`` would keep its result)
                fut = done.pop()
                pending.discard(fut)
                if check is not None:
                    check()
                try:
                    result = fut.result()
                except BrokenProcessPool as err:
                    script = started_by_a_script()
                    raise GroundSieveError(
                        f"a worker process ended abruptly during the {stage} ("
                        + (f"the script that started the run, {script}, is imported again by every worker process: "
                           "its work must be under `if __name__ == \"__main__\":` (docs/API.md); if it is, "
                           if script else "")
                        + "most often the system stops one for lack of memory: see its log, e.g. dmesg); use a "
                        "smaller memory budget or fewer workers") from err
                del fut
                record(result)
                del result
            del done
    except BaseException:
        for fut in pending:
            fut.cancel()
        raise


def _tile_job(job) -> Optional[dict]:
    """Filter one tile (a pure function of its job, so that it runs in a thread or a worker
    process): read its parts, classify tile + buffer with the unchanged filter, write the own
    points' classes into the per-file memmaps, and interpolate the tile's DTM block."""
    from . import workflow
    where = job_name(job["bounds"], job["names"])
    options = job["options"]
    try:
        from ..io.copc import tile_sources
        from .sent_once import resolve
        algorithm = resolve(job["algorithm"])  # (in a worker, loaded once: a model's forest)
        clouds, indices, files = [], [], []
        # An algorithm that takes more of the points than a tile cloud's fields (a model's colour, scan angle,
        # GPS time) is given each part's records, as the file's own header reads them, and keeps its values.
        attributes = getattr(algorithm, "point_attributes", None)
        reader = read_part if attributes is None else _part_reader(job["paths"])
        sources, copc_read = tile_sources(job["parts"], job.get("copc", ()), reader,  # in file order
                                          records=attributes is not None)
        if not sources:  # a COPC tile whose area holds no point
            return None
        for file_index, c, idx in sources:
            if attributes is not None:
                c.attributes, c.las = attributes(c, job["paths"][file_index]), None
            clouds.append(c)
            indices.append(idx)
            files.append(np.full(idx.size, file_index, dtype=np.int32))
        index = np.concatenate(indices)
        file_of = np.concatenate(files)
        in_tile = index >= 0  # the points in the tile (the rest is its buffer)
        # those it classifies: of every file, or of the one file run (its neighbours' lend their points)
        own = in_tile if job.get("only") is None else in_tile & (file_of == job["only"])
        if not own.any() and job["dtm"] is None:  # (with a DTM: the tile's block, from its buffer)
            return None
        cloud = tile_cloud(clouds, path=where)
        del clouds
        if workflow.NEEDED in getattr(algorithm, "optional_point_fields", ()) and job["dtm"] is None:
            # (a model's prediction, most of its time, left out for the buffer, whose classes no DTM uses)
            cloud.attributes = {**(cloud.attributes or {}), workflow.NEEDED: own.copy()}
        replaced, structures, demoted, ground_classes, not_last, made = {}, {}, (0, 0), [], (0, 0), []
        agreement = [0, 0, 0, 0, 0]
        if len(cloud) < getattr(algorithm, "min_tile_points", MIN_TILE_POINTS):
            # Isolated points (a stray point far from the survey): too few for any filter's grid;
            # they keep their classes and are not ground.
            cls, ground = cloud.classification, np.zeros(len(cloud), dtype=bool)
        elif workflow.select_points(cloud, options).any():
            done = workflow.classify_cloud(cloud, algorithm, options, Steps(is_cancelled=job["is_cancelled"]))
            cls, ground = done.classification, done.ground
            if getattr(algorithm, "ground_of_any_class", False):
                from ..io.clouds import count_classes
                ground_classes = sorted(count_classes(cloud.classification[ground & own]).items())
            demoted = workflow.demoted_ground(cloud.classification, ground, own & done.touched)
            agreement = workflow.agreement_counts(cloud, ground, own & done.touched)
            codes, counts = np.unique(cls[own & done.touched], return_counts=True)
            made = [[int(c), int(n)] for c, n in zip(codes, counts)]
            not_last = workflow.ground_not_last(cloud, ground & own)
            if not options.keep_existing_classes:  # said once for the run (the tile's log goes nowhere)
                replaced = workflow.replaced_classes(cloud.classification, own & done.processable)
                structures = workflow.structures_made_ground(cloud.classification, own & ground)
        else:  # nothing to filter here (all noise): the points keep their classes
            cls, ground = cloud.classification, np.zeros(len(cloud), dtype=bool)
        assigned, class_parts = {}, None
        if job.get("own_classes"):  # on a cluster: this tile's own files, one per input file
            class_parts = {}
            for k in np.unique(file_of[own]):
                sel = own & (file_of == k)
                class_parts[int(k)] = _done_name(job["done_dir"], job["key"]) + f".f{int(k):05d}.cls.npz"
                _save_classes(class_parts[int(k)], index[sel], cls[sel])
                assigned[int(k)] = int(sel.sum())
        for k in ([] if class_parts is not None else np.unique(file_of[own])):
            sel = own & (file_of == k)
            classes = np.load(job["class_paths"][k], mmap_mode="r+")
            classes[index[sel]] = cls[sel]
            # Unmapped without flush(): msync would wait for the disk (busy writing the binned parts
            # back) for pages that every process on this machine sees in the page cache anyway
            # (the write phase reads them there; a killed worker's writes stay too).
            del classes
            assigned[int(k)] = int(sel.sum())
        block, kept_out, dtm_own, area_bounds, gaps, hull = None, {}, 0, None, [], []
        below = [0, 0]
        if job["dtm"] is not None:
            area = workflow.processable(cloud, options)
            mine = area & in_tile  # (the DTM's extent: the points that may enter it, as a whole run's grid)
            if mine.any():
                xs, ys = cloud.x[mine], cloud.y[mine]
                area_bounds = [float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max())]
            in_dtm = workflow.dtm_points(cloud, ground, area, job["dtm"])
            # (of every file in the tile: the DTM of one file whose own points hold no ground, a roof or a lake,
            # is made from its neighbours' ground there, as the run of the whole survey makes it)
            dtm_own = int(np.count_nonzero(in_dtm & in_tile))
            gaps = []  # [the smallest gap named, then each gap (area, x, y)]
            block = _dtm_block(cloud, in_dtm, job["dtm"], job["dtm_grid"], job["bounds"], job["buffer"], area, gaps)
            if block is not None and mine.any():  # (the points of the tile against its block: workflow.floating_note)
                below = workflow.points_below(cloud.x[mine], cloud.y[mine], cloud.z[mine], block[2], job["dtm_grid"],
                                              job["dtm"].metres_per_unit, block[0], block[1])
            hull = _block_hull(block, job["dtm_grid"])  # (the whole run fills the ground's hull)
            if options.keep_existing_classes:
                kept_out = workflow.kept_out_of_dtm(cloud, cls, area & own & ~in_dtm, job["dtm"], algorithm)
        result = dict(key=list(job["key"]), own=int(own.sum()), read=len(cloud), ground=int(ground[own].sum()),
                      dtm_points=dtm_own, assigned=assigned, block=block, class_parts=class_parts, copc_read=copc_read,
                      kept_out=sorted(kept_out.items()), replaced=sorted(replaced.items()),
                      structures=sorted(structures.items()), area_bounds=area_bounds, gaps=gaps, hull=hull,
                      demoted=list(demoted), agreement=list(agreement), below=list(below), ground_classes=ground_classes,
                      not_last=list(not_last),
                      classes=made)
        _save_done(job["done_dir"], result)
        return result
    except Cancelled:
        raise
    except GroundSieveError as err:
        raise type(err)(f"{where}: {err}") from err
    except OSError as err:
        full = _full_disk(err, os.path.dirname(job["done_dir"]), f"{where}: ", ", then run again")
        if full is not None:
            raise full from err
        raise GroundSieveError(f"{where} failed: {type(err).__name__}: {err}") from err
    except MemoryError as err:  # (under ulimit -v 1000000 a tile ran out: say what to change)
        from ..errors import out_of_memory
        raise out_of_memory(where, err) from err
    except Exception as err:  # an unexpected failure still names the tile
        raise GroundSieveError(f"{where} failed: {type(err).__name__}: {err}") from err


def _part_reader(paths: Dict[int, str]):
    """``read_part`` with the records of each part, read by its input's header (opened once a tile)."""
    import laspy
    headers = {}

    def read(part):
        if part.file_index not in headers:
            with laspy.open(paths[part.file_index]) as reader:
                headers[part.file_index] = reader.header
        return read_part(part, headers[part.file_index])
    return read


def time_left(elapsed: float, done: int, workers: int, remaining: int) -> float:
    """Seconds left for ``remaining`` tiles when ``done`` took ``elapsed`` on ``workers``: at the pace so far,
    where until as many tiles as workers are done the others ran beside them (the first tile's estimate had
    been about 3 times what 2 workers then took: a UAV reviewer)."""
    return elapsed / max(done, workers, 1) * remaining


def _dtm_extent(full, box, log):
    """The survey DTM's grid: ``full`` (the headers' bounds) cut to ``box``, the bounds of the points that
    may enter it (neither withheld nor ignored), on the same lattice, as a whole run spans those points
    only. A stray noise point, ignored, stretched a tiled DTM 2,300 x 300 cells where the whole run's was
    300 x 300 (a surveyor). ``full`` when the box is not known (a resumed run's older tiles)."""
    if box is None or not math.isfinite(box[0]):
        return full
    cut = grid_window(full, box)
    if cut is full or cut is None:  # (None: no point's box beyond the grid; kept whole, as before)
        return full
    log(f"DTM: cut to the {cut.ncols:,} x {cut.nrows:,} cells of the points it may hold (the files' bounds make "
        f"{full.ncols:,} x {full.nrows:,}: withheld or ignored points lie beyond them, or a header's bounds are "
        "wider than its points).")
    return cut


def grid_window(full, box):
    """The cells of the grid ``full`` that the box (xmin, ymin, xmax, ymax) covers, on its lattice (a
    closed covering: a box on cell edges adds no cell), as a window of it; ``full`` itself when that is
    all of it, None when the box misses it."""
    from ..grids.spec import GridSpec
    cut = GridSpec.covering(np.array([box[0], box[2]]), np.array([box[1], box[3]]), full.cell, what="DTM",
                            bytes_per_cell=0.0, max_cells=MAX_SURVEY_DTM_CELLS, closed=True)
    col0, row0 = full.offset_of(cut)
    # (points beyond the headers' bounds: the cut ends where it would, inside the full grid; a code reviewer)
    col1, row1 = min(col0 + cut.ncols, full.ncols), min(row0 + cut.nrows, full.nrows)
    col0, row0 = max(0, col0), max(0, row0)
    ncols, nrows = col1 - col0, row1 - row0
    if ncols <= 0 or nrows <= 0:
        return None
    if (col0, row0, ncols, nrows) == (0, 0, full.ncols, full.nrows):
        return full
    return full.window(col0, row0, ncols, nrows)


def _say_stray_tiles(tiles, grid, dtm_grid, log) -> None:
    """Say when a survey's DTM (``dtm_grid``, cut to its points) is mostly empty because a few points
    lie far from the others (tiles of fewer than MIN_TILE_POINTS points, which are not filtered): the
    tiled counterpart of workflow._say_stray_points (a stray point 1,000 km away made a 1,000,040 x 40
    cell DTM without a word)."""
    counts = {k: sum(p.own_count for p in parts) for k, parts in tiles.items()}
    kept = [grid.bounds(k) for k, n in counts.items() if n >= MIN_TILE_POINTS]
    if not kept:
        return
    x0, y0 = min(b[0] for b in kept), min(b[1] for b in kept)
    x1, y1 = max(b[2] for b in kept), max(b[3] for b in kept)

    dx0, dy1 = dtm_grid.x0, dtm_grid.top
    dx1, dy0 = dx0 + dtm_grid.ncols * dtm_grid.cell, dy1 - dtm_grid.nrows * dtm_grid.cell

    def outside(k):  # a tile beyond the box of the filtered tiles, not touching it: the DTM is stretched
        # to reach it (a few points beside the box are not far: an HPC reviewer's 9 points on the survey's
        # edge, which made a tile of their own before that edge closed its tiles, were called so), unless
        # its points are all ignored or withheld (the DTM, cut to the others, does not reach it)
        bx0, by0, bx1, by1 = grid.bounds(k)
        reached = bx0 <= dx1 and bx1 >= dx0 and by0 <= dy1 and by1 >= dy0
        return reached and (bx1 < x0 or bx0 > x1 or by1 < y0 or by0 > y1)
    few = sorted((k for k, n in counts.items() if 0 < n < MIN_TILE_POINTS and outside(k)), key=lambda k: counts[k])
    if not few:
        return
    bx0, by0, _bx1, _by1 = grid.bounds(few[0])
    log(f"{WARNING_PREFIX}DTM: {sum(counts[k] for k in few):,} point(s) in {len(few):,} tile(s) lie far from the others "
        f"(e.g. {counts[few[0]]:,} in the tile at x {bx0:,.0f}, y {by0:,.0f}): the DTM spans them, {dtm_grid.ncols:,} x "
        f"{dtm_grid.nrows:,} cells, mostly empty. Class them as noise (7) to leave them out, or crop the cloud.")


def _tile_cells(full, bounds):
    """(row0, row1, col0, col1): a tile of ``bounds``'s cells on the lattice of the DTM grid ``full``
    (cell edges on multiples of the cell; tile edges on multiples of the cell too), whether or not the
    grid holds them all."""
    c = full.cell
    x0, y0, x1, y1 = bounds
    return (int(round((full.top - y1) / c)), int(round((full.top - y0) / c)),
            int(round((x0 - full.x0) / c)), int(round((x1 - full.x0) / c)))


def _block_cells(full, bounds):
    """(row0, row1, col0, col1): the cells of the DTM grid ``full`` a tile of ``bounds`` makes
    (:func:`_tile_cells` within the grid); None when it makes none."""
    row0, row1, col0, col1 = _tile_cells(full, bounds)
    row0, row1, col0, col1 = max(0, row0), min(full.nrows, row1), max(0, col0), min(full.ncols, col1)
    if col1 <= col0 or row1 <= row0:
        return None
    return row0, row1, col0, col1


def job_name(bounds, names) -> str:
    x0, y0, x1, y1 = bounds
    return f"tile {x0:.0f},{y0:.0f} - {x1:.0f},{y1:.0f} of {', '.join(names)}"


def _save_classes(path, index, cls) -> None:
    """A tile's own points' classes in one input file (index in the file, class), written
    atomically: a worker killed mid-write leaves no file, and a retried tile writes the same bytes."""
    tmp = f"{path}.{os.getpid()}.part"
    with open(tmp, "wb") as f:
        np.savez(f, index=index.astype(np.int64), cls=cls.astype(np.uint8))
    os.replace(tmp, path)


def _done_name(done_dir, key) -> str:
    return os.path.join(done_dir, f"{key[0]}_{key[1]}")


def _save_done(done_dir, result) -> None:
    """Mark a tile done (its classes are in the memmaps already): its counts, and its DTM block."""
    base = _done_name(done_dir, result["key"])
    doc = {k: v for k, v in result.items() if k != "block"}
    if result["block"] is not None:
        row0, col0, values = result["block"]
        np.save(base + ".npy", values)
        doc["block"] = [int(row0), int(col0)]
    _save_json(base + ".json", doc)


def _load_done(done_dir, key) -> Optional[dict]:
    import json as _json
    base = _done_name(done_dir, key)
    if not os.path.exists(base + ".json"):
        return None
    with open(base + ".json") as f:
        doc = _json.load(f)
    if doc.get("block") is not None:
        doc["block"] = (*doc["block"], np.load(base + ".npy"))
    else:
        doc["block"] = None
    return doc


def _auto_parallel(points: int) -> str:
    """Worker processes where this process is a Python interpreter or qgis_process and the run holds
    at least :data:`PROCESS_MIN_POINTS` points; threads for smaller runs, and inside the QGIS
    desktop, whose executable is QGIS itself (it cannot spawn Python workers)."""
    if points < PROCESS_MIN_POINTS:
        return "threads"
    try:
        exe = os.path.basename(os.path.realpath("/proc/self/exe")).lower()
    except OSError:
        exe = os.path.basename(sys.executable or "").lower()
    if exe.startswith("python") or exe.startswith("qgis_process"):
        return "processes" if _python_executable() else "threads"
    return "threads"


def _python_executable() -> Optional[str]:
    """A Python interpreter for worker processes: this one, or (embedded in qgis_process) the
    interpreter of the same installation."""
    # Embedded (qgis_process), sys.executable is whatever "python3" PATH finds first (e.g. a pyenv
    # shim of another installation); the standard library this process really runs (os.__file__,
    # <prefix>/lib/pythonX.Y/os.py) names the right one.
    prefix = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(os.__file__))))
    exe = sys.executable or ""
    if os.path.isfile(exe) and os.path.basename(exe).lower().startswith("python") and (
            sys.prefix != sys.base_prefix or os.path.realpath(exe).startswith(prefix + os.sep)):
        return exe  # a venv's interpreter, or one of this installation
    v = sys.version_info
    for name in (f"python{v.major}.{v.minor}", f"python{v.major}"):
        cand = os.path.join(prefix, "bin", name)
        if os.path.isfile(cand):
            return cand
    return None


def _dtm_block(cloud, ground, dtm, full, bounds, buffer_m, area=None, gaps=None):
    """Interpolate the DTM cells whose centres lie in the tile from the ground of the tile and its
    buffer, on a grid aligned with the whole DTM's (so the thinning picks the same points). ``gaps``, a
    list, gets the gaps in the data (workflow.data_gaps, of the points ``area``: neither withheld nor
    ignored) that the block's surface spans and whose centre lies in the tile (each gap said once)."""
    from ..grids.rasterize import tin_dtm
    from ..grids.spec import GridSpec
    c = full.cell
    cells = _block_cells(full, bounds)
    if cells is None or not ground.any():
        return None
    row0, row1, col0, col1 = cells
    # the tile's whole block on the grid's lattice, where the grid holds part of it only (a survey's edge,
    # one file's cells, an extent's): its surface is then the same whatever grid it is written into (cut to
    # one file's cells, the block lost ground points beyond them, and the DTM beside a lake differed from
    # the whole survey's by up to 19 mm: an HPC reviewer)
    trow0, trow1, tcol0, tcol1 = _tile_cells(full, bounds)
    # one cell more than the buffer: a point on the buffer's outer edge still falls in the grid (the
    # thinning's one-pass kernel needs every point inside; same points kept, same surface)
    pad = int(math.ceil(buffer_m / c)) + 1
    ext = GridSpec(full.x0 + (tcol0 - pad) * c, full.top - (trow0 - pad) * c, c,
                   trow1 - trow0 + 2 * pad, tcol1 - tcol0 + 2 * pad)
    g = ground
    values = tin_dtm(cloud.x[g], cloud.y[g], cloud.z[g], ext, fill_outside=dtm.fill_outside_hull,
                     points_per_cell=dtm.points_per_cell, max_distance=dtm.max_distance_m)
    if gaps is not None and area is not None and not dtm.fill_outside_hull and not dtm.max_distance_m:
        from .workflow import data_gaps
        found, smallest = data_gaps(cloud.x[area], cloud.y[area], values, ext)
        x0, y0, x1, y1 = bounds
        gaps.extend([smallest] + [list(gap) for gap in found if x0 <= gap[1] < x1 and y0 <= gap[2] < y1])
    r, k = pad + row0 - trow0, pad + col0 - tcol0
    return row0, col0, np.ascontiguousarray(values[r:r + row1 - row0, k:k + col1 - col0])
