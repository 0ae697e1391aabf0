"""Raster grids: orientation and georeferencing live here and nowhere else.

Convention: row 0 is the northern row, column 0 the western column. Cell
``(row, col)`` covers ``x in [x0 + col*c, x0 + (col+1)*c)`` and
``y in (top - (row+1)*c, top - row*c]``. The GDAL geotransform is
``(x0, c, 0, top, 0, -c)``. Cell edges sit on multiples of the cell size, so grids
made with the same cell size from neighbouring tiles line up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidParameterError

#: Largest grid the core agrees to allocate (cells); a guard against a cell size
#: that is far too small for the extent of the cloud.
MAX_CELLS = 400_000_000


@dataclass(frozen=True)
class GridSpec:
    x0: float
    top: float
    cell: float
    nrows: int
    ncols: int

    @classmethod
    def covering(cls, x: np.ndarray, y: np.ndarray, cell: float, *, what: str = "grid") -> "GridSpec":
        """The smallest grid with edges on multiples of ``cell`` that holds every point."""
        if not (cell > 0 and math.isfinite(cell)):
            raise InvalidParameterError(f"{what}: cell size must be a finite number > 0 (got {cell})")
        xmin, xmax = float(np.min(x)), float(np.max(x))
        ymin, ymax = float(np.min(y)), float(np.max(y))
        x0 = math.floor(xmin / cell) * cell
        top = math.ceil(ymax / cell) * cell
        if top < ymax:  # floating-point rounding of the product
            top += cell
        ncols = int(math.floor((xmax - x0) / cell)) + 1
        nrows = int(math.floor((top - ymin) / cell)) + 1
        # Rounding at exact edges can leave the last point one cell out: grow by one if so.
        if x0 + ncols * cell <= xmax:
            ncols += 1
        if top - nrows * cell >= ymin:
            nrows += 1
        cells = nrows * ncols
        if cells > MAX_CELLS:
            raise InvalidParameterError(
                f"{what}: a cell size of {cell:g} m over an extent of {xmax - xmin:.1f} x {ymax - ymin:.1f} m "
                f"needs {nrows} x {ncols} = {cells:,} cells (limit {MAX_CELLS:,}); use a larger cell size")
        return cls(float(x0), float(top), float(cell), nrows, ncols)

    @property
    def shape(self) -> tuple:
        return (self.nrows, self.ncols)

    @property
    def geotransform(self) -> tuple:
        return (self.x0, self.cell, 0.0, self.top, 0.0, -self.cell)

    def col_of(self, x: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((x - self.x0) / self.cell).astype(np.int64), 0, self.ncols - 1)

    def row_of(self, y: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((self.top - y) / self.cell).astype(np.int64), 0, self.nrows - 1)

    def centers(self) -> tuple:
        """x of every column centre and y of every row centre (1-D arrays)."""
        xs = self.x0 + (np.arange(self.ncols) + 0.5) * self.cell
        ys = self.top - (np.arange(self.nrows) + 0.5) * self.cell
        return xs, ys
