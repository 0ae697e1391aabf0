"""Raster grids: orientation and georeferencing live here and nowhere else.

Convention: row 0 is the northern row, column 0 the western column. Cell
``(row, col)`` covers ``x in [x0 + col*c, x0 + (col+1)*c)`` and
``y in (top - (row+1)*c, top - row*c]``. The GDAL geotransform is
``(x0, c, 0, top, 0, -c)``. Cell edges sit on multiples of the cell size, so grids
made with the same cell size from neighbouring tiles line up.
"""
from __future__ import annotations

import contextlib
import contextvars
import math
import os
from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

from ..errors import InvalidParameterError, MemoryBudgetError

#: Largest grid the core agrees to allocate (cells) whatever the memory: index arithmetic and
#: rasters beyond this are not meant for one piece.
MAX_CELLS = 400_000_000
#: The largest cell accepted, in metres (1000 km: a cell wider than a country is a typing error;
#: much larger ones, 1e300, overflow the grid's coordinates).
MAX_CELL_M = 1e6

#: Share of the memory available at the start of a grid that one run may use by default.
DEFAULT_MEMORY_FRACTION = 0.6

#: Peak of the harmonic fill (core/grids/inpaint.py) per empty cell of a large hole, with a margin:
#: the iterative solve that fills holes of more than 4096 cells measured 145-174 bytes a cell
#: (bench/fill_memory.py, docs/BENCHMARKS.md "Memory guard"); a 4,200 x 4,200 m SMRF grid over two
#: 200 m blocks of points peaked at 3.2 GB, 182 bytes a cell with SMRF's own grids. (The sparse LU,
#: 1.9-2.3 kB a cell, now fills only holes of at most 4096 cells, and large ones where the iteration
#: would not converge, which was never seen.) Filters that fill their grid count this for every cell
#: that no point can reach (cells - points, a lower bound of the empty cells).
FILL_BYTES_PER_EMPTY_CELL = 400

_BUDGET = contextvars.ContextVar("groundsieve_memory_budget", default=None)


def available_memory_bytes() -> int:
    """Memory this process can still take: the kernel's MemAvailable, at most what its control group's limit
    (a batch job's) has left, and below the address-space limit (``ulimit -v``, ``resource.RLIMIT_AS``) when one
    is set, what is left of it (core/machine.py)."""
    from ..machine import address_space_left, cgroup_memory_left
    avail = None
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    if avail is None:
        with contextlib.suppress(ValueError, OSError, AttributeError):
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    if avail is None:
        avail = 8 << 30  # no way to know (not Linux): assume a modest machine
    for limit in (cgroup_memory_left(), address_space_left()):
        if limit is not None:
            avail = min(avail, limit)
    return int(avail)


def memory_budget_bytes() -> int:
    """What one grid may take: the budget set with :func:`memory_budget`, otherwise
    ``DEFAULT_MEMORY_FRACTION`` of :func:`available_memory_bytes`."""
    explicit = _BUDGET.get()
    if explicit is not None:
        return int(explicit)
    return int(DEFAULT_MEMORY_FRACTION * available_memory_bytes())


@contextlib.contextmanager
def memory_budget(nbytes: Optional[int]):
    """Within the block, grids are refused above ``nbytes`` (None: the default budget)."""
    if nbytes is not None and not (isinstance(nbytes, (int, np.integer)) and nbytes > 0):
        raise InvalidParameterError(f"memory budget must be a whole number of bytes > 0 (got {nbytes!r})")
    token = _BUDGET.set(None if nbytes is None else int(nbytes))
    try:
        yield
    finally:
        _BUDGET.reset(token)


def _size(nbytes: float) -> str:
    for unit, factor in (("GB", 1 << 30), ("MB", 1 << 20), ("kB", 1 << 10)):
        if nbytes >= factor:
            return f"{nbytes / factor:.1f} {unit}"
    return f"{int(nbytes)} bytes"


def _distance(metres: float) -> str:
    return f"{metres / 1000:.1f} km" if metres >= 1000 else f"{metres:.0f} m"


def isolated_points(x: np.ndarray, y: np.ndarray, *, max_share: float = 0.001):
    """The few points far outside the extent of the others, found cheaply: the box of the
    0.1-99.9 % quantiles of x and y (on a sample of at most 200,000 points), widened by half its
    size; points outside it are isolated when they are at most ``max_share`` of the cloud.
    Returns ``(indices, their distances to the quantile box in m, that box (xmin, xmax, ymin, ymax))``;
    no indices when there are none."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    n = x.size
    none = (np.empty(0, dtype=np.int64), np.empty(0), None)
    if n < 10:
        return none
    sample = np.random.default_rng(0).choice(n, 200_000, replace=False) if n > 200_000 else slice(None)
    qx = np.quantile(x[sample], [0.001, 0.999])
    qy = np.quantile(y[sample], [0.001, 0.999])
    margin = 0.5 * max(qx[1] - qx[0], qy[1] - qy[0], 1.0)
    core = (float(qx[0]), float(qx[1]), float(qy[0]), float(qy[1]))
    box = (qx[0] - margin, qx[1] + margin, qy[0] - margin, qy[1] + margin)
    dx = np.maximum(np.maximum(box[0] - x, x - box[1]), 0.0)
    dy = np.maximum(np.maximum(box[2] - y, y - box[3]), 0.0)
    far = np.flatnonzero((dx > 0) | (dy > 0))
    if far.size == 0 or far.size > max(1, max_share * n):
        return none
    fx, fy = x[far], y[far]
    cx = np.maximum(np.maximum(core[0] - fx, fx - core[1]), 0.0)
    cy = np.maximum(np.maximum(core[2] - fy, fy - core[3]), 0.0)
    return far, np.hypot(cx, cy), core


def check_memory(nbytes: float, *, what: str, shape: tuple, cell: float, x=None, y=None,
                 budget: Optional[int] = None) -> None:
    """Refuse, before allocating, a grid of ``shape`` cells whose estimated peak is ``nbytes``
    when that is above the budget (:func:`memory_budget_bytes`). The message gives the estimate,
    the extent and, when a few points lie far from the others (``x``, ``y``), where they are."""
    budget = memory_budget_bytes() if budget is None else int(budget)
    if nbytes <= budget:
        return
    nrows, ncols = (int(v) for v in shape)
    message = (f"{what}: {ncols:,} x {nrows:,} cells of {cell:g} m (an extent of "
               f"{ncols * cell:,.1f} x {nrows * cell:,.1f} m) need about {_size(nbytes)} at peak, more than the "
               f"{_size(budget)} this run may use")
    if _BUDGET.get() is None:
        message += f" ({DEFAULT_MEMORY_FRACTION:.0%} of the memory available)"
    far = ()
    if x is not None and y is not None:
        far, dist, core = isolated_points(x, y)
        if far.size:
            worst = int(np.argmax(dist))
            i = int(far[worst])
            some = "1 point lies" if far.size == 1 else f"{far.size:,} points lie up to"
            message += (f". Likely cause: {some} {_distance(float(dist[worst]))} from the others, at "
                        f"x {float(x[i]):.2f}, y {float(y[i]):.2f} (the others span about "
                        f"{core[1] - core[0]:,.0f} x {core[3] - core[2]:,.0f} m)")
    if x is not None and not len(far):
        # no stray point: the points themselves span the grid, so the cell size is what costs
        fits = float(f"{cell * math.sqrt(nbytes / max(budget, 1)) * 1.01:.2g}")
        message += (f". The points themselves span this extent: use a larger cell size ({fits:g} m or more fits), "
                    "set a larger memory budget, or run in tiles (a tile size), which grid one tile at a time.")
    else:
        message += (". Class such points as noise (7, which is ignored by default) or remove them; if the file "
                    "holds separate survey areas, split it into one file per area; or use a larger cell size, or "
                    "set a larger memory budget. A grid over the whole extent is what costs: the survey-scale "
                    "tiler, which grids only where points are, will avoid it once the run goes through it.")
    raise MemoryBudgetError(message)


def _lattice_index(value: float, rounding) -> int:
    """``rounding(value)`` (math.floor or math.ceil), or the nearest integer when ``value`` is one
    but for floating-point noise (a coordinate on a cell edge divided by the cell size)."""
    nearest = round(value)
    if abs(value - nearest) <= max(1e-9, 1e-12 * abs(value)):
        return int(nearest)
    return int(rounding(value))


def _lattice_value(k: int, cell: float) -> float:
    """``k * cell`` as the decimal it stands for when ``cell`` is a short decimal: 1666679 * 0.3 is
    500003.69999999995 in floating point, which a DTM's geotransform showed (a geomorphologist: two
    epochs' origins then shared fewer exact cell centres); rounded to the cell's decimals it is 500003.7."""
    value = k * cell
    text = repr(float(cell))
    if "e" in text or "E" in text:
        return value
    decimals = len(text.split(".")[1].rstrip("0")) if "." in text else 0
    return round(value, decimals) if decimals <= 9 else value


@dataclass(frozen=True)
class GridSpec:
    x0: float
    top: float
    cell: float
    nrows: int
    ncols: int

    @classmethod
    def covering(cls, x: np.ndarray, y: np.ndarray, cell: float, *, what: str = "grid",
                 bytes_per_cell: float = 8.0, bytes_per_empty_cell: float = 0.0,
                 max_cells: int = MAX_CELLS, closed: bool = False) -> "GridSpec":
        """The smallest grid with edges on multiples of ``cell`` that holds every point.

        ``closed``: a point on the grid's eastern or southern edge (x = x0 + ncols * cell, y = top -
        nrows * cell) counts as in it, though it lies on the next cell's edge, so that points in
        [500000, 501000] give 1000 columns of 1 m, not 1001 (a DTM of a vendor's 1 km tile, whose
        points include its edges); :meth:`col_of` and :meth:`row_of` put such points in the last
        column and row. The filters' grids are not closed: their kernels want every point inside.

        Refused before anything is allocated when its estimated peak memory,
        ``cells * bytes_per_cell + max(0, cells - points) * bytes_per_empty_cell`` (what the
        caller's grids cost per cell, and per cell no point reaches, e.g. for filling holes),
        is above the budget (:func:`check_memory`), or when it has more than ``max_cells``."""
        if not (cell > 0 and math.isfinite(cell)):
            raise InvalidParameterError(f"{what}: cell size must be a finite number > 0 (got {cell})")
        if cell > MAX_CELL_M:
            raise InvalidParameterError(f"{what}: a cell size of {cell:g} m is larger than any map "
                                        f"(at most {MAX_CELL_M:g} m); give the cell size in metres")
        xmin, xmax = float(np.min(x)), float(np.max(x))
        ymin, ymax = float(np.min(y)), float(np.max(y))
        x0 = math.floor(xmin / cell) * cell
        top = math.ceil(ymax / cell) * cell
        if top < ymax:  # floating-point rounding of the product
            top += cell
        if closed:
            # Cell edges by their index on the lattice of multiples of ``cell``: an edge a point lies on
            # (within floating-point noise: 500000.3 / 0.1 is 5000002.9999999995) is that point's edge,
            # so that it adds no column or row on any side.
            k0, k1 = _lattice_index(xmin / cell, math.floor), _lattice_index(xmax / cell, math.ceil)
            t0, t1 = _lattice_index(ymin / cell, math.floor), _lattice_index(ymax / cell, math.ceil)
            x0, top = _lattice_value(k0, cell), _lattice_value(t1, cell)
            ncols, nrows = max(1, k1 - k0), max(1, t1 - t0)
        else:
            ncols = int(math.floor((xmax - x0) / cell)) + 1
            nrows = int(math.floor((top - ymin) / cell)) + 1
            # Rounding at exact edges can leave the last point one cell out: grow by one if so.
            if x0 + ncols * cell <= xmax:
                ncols += 1
            if top - nrows * cell >= ymin:
                nrows += 1
        cells = nrows * ncols
        estimate = cells * float(bytes_per_cell) + max(0, cells - int(np.size(x))) * float(bytes_per_empty_cell)
        check_memory(estimate, what=what, shape=(nrows, ncols), cell=cell, x=x, y=y)
        if cells > max_cells:
            raise InvalidParameterError(
                f"{what}: a cell size of {cell:g} m over an extent of {xmax - xmin:,.1f} x {ymax - ymin:,.1f} m "
                f"needs {ncols:,} x {nrows:,} = {cells:,} cells (limit {max_cells:,}); use a larger cell size")
        return cls(float(x0), float(top), float(cell), nrows, ncols)

    @property
    def shape(self) -> tuple:
        return (self.nrows, self.ncols)

    @property
    def geotransform(self) -> tuple:
        return (self.x0, self.cell, 0.0, self.top, 0.0, -self.cell)

    def offset_of(self, other: "GridSpec") -> Tuple[int, int]:
        """(column, row) of the north-west cell of ``other``, a grid on this one's lattice, in this grid (may
        lie outside it)."""
        return int(round((other.x0 - self.x0) / self.cell)), int(round((self.top - other.top) / self.cell))

    def window(self, col0: int, row0: int, ncols: int, nrows: int) -> "GridSpec":
        """The ``ncols`` x ``nrows`` cells of this grid from column ``col0``, row ``row0``; an origin on the
        lattice of multiples of the cell stays the decimal it stands for (as :meth:`covering` makes it), so
        that a tiled run's DTM cut from its survey grid has a whole run's geotransform."""
        x0, top = self.x0 + col0 * self.cell, self.top - row0 * self.cell
        kx, ky = round(x0 / self.cell), round(top / self.cell)
        if abs(x0 / self.cell - kx) < 1e-6 and abs(top / self.cell - ky) < 1e-6:
            x0, top = _lattice_value(kx, self.cell), _lattice_value(ky, self.cell)
        return GridSpec(x0, top, self.cell, nrows, ncols)

    def padded(self, cells: int) -> "GridSpec":
        """This grid with ``cells`` more cells on every side (the same cell edges)."""
        return GridSpec(self.x0 - cells * self.cell, self.top + cells * self.cell, self.cell,
                        self.nrows + 2 * cells, self.ncols + 2 * cells)

    def col_of(self, x: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((x - self.x0) / self.cell).astype(np.int64), 0, self.ncols - 1)

    def row_of(self, y: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((self.top - y) / self.cell).astype(np.int64), 0, self.nrows - 1)

    def centers(self) -> tuple:
        """x of every column centre and y of every row centre (1-D arrays)."""
        xs = self.x0 + (np.arange(self.ncols) + 0.5) * self.cell
        ys = self.top - (np.arange(self.nrows) + 0.5) * self.cell
        return xs, ys
