"""Grey-scale morphology with disk windows (exact), on float grids without NaN."""
from __future__ import annotations

import numpy as np

from ..errors import InvalidParameterError


def _check(grid: np.ndarray, radius: int) -> np.ndarray:
    grid = np.ascontiguousarray(grid, dtype=np.float64)
    if grid.ndim != 2:
        raise InvalidParameterError(f"grid must be 2-D (got {grid.ndim}-D)")
    if not isinstance(radius, (int, np.integer)) and not (
            isinstance(radius, float) and radius.is_integer()) or radius < 0:
        raise InvalidParameterError(f"radius must be a whole number of cells >= 0 (got {radius})")
    return grid


def disk(radius: int) -> np.ndarray:
    """The footprint used here: cells with dx² + dy² <= radius² (as scikit-image's ``disk``)."""
    r = int(radius)
    dy, dx = np.mgrid[-r:r + 1, -r:r + 1]
    return (dx * dx + dy * dy) <= r * r


def erode(grid: np.ndarray, radius: int) -> np.ndarray:
    """Minimum over the disk of ``radius`` cells around each cell (cells outside the grid ignored)."""
    from ._kernels import _disk_extreme_kernel
    grid = _check(grid, radius)
    out = np.empty_like(grid)
    _disk_extreme_kernel(grid, int(radius), False, out)
    return out


def dilate(grid: np.ndarray, radius: int) -> np.ndarray:
    """Maximum over the disk of ``radius`` cells around each cell (cells outside the grid ignored)."""
    from ._kernels import _disk_extreme_kernel
    grid = _check(grid, radius)
    out = np.empty_like(grid)
    _disk_extreme_kernel(grid, int(radius), True, out)
    return out


def opening(grid: np.ndarray, radius: int) -> np.ndarray:
    """Grey opening (erosion then dilation) with a disk of ``radius`` cells."""
    return dilate(erode(grid, radius), radius)


def progressive_filter(surface: np.ndarray, radii, cell_size_m: float, slope: float,
                       steps=None) -> np.ndarray:
    """Pingel et al. (2013) progressive filter: open the surface with disks of growing
    radius, each opening applied to the previous opened surface; a cell whose
    height drops by more than ``slope * radius * cell_size_m`` in one step is an
    object cell. Returns the boolean grid of object cells."""
    last = np.ascontiguousarray(surface, dtype=np.float64)
    is_object = np.zeros(last.shape, dtype=bool)
    radii = [int(r) for r in radii]
    for i, radius in enumerate(radii):
        opened = opening(last, radius)
        is_object |= (last - opened) > slope * radius * cell_size_m
        last = opened
        if steps is not None:
            steps.report((i + 1) / len(radii))
    return is_object
