"""2-D Delaunay triangulation of point positions: a numba sweep-hull kernel
(:mod:`._delaunay`) by default, scipy's qhull for comparison."""
from __future__ import annotations

import numpy as np

from ..errors import InputError, InvalidParameterError

TRIANGULATORS = ("sweep", "qhull")
#: the sweep kernel numbers half-edges (6 per point) in int32
MAX_SWEEP_POINTS = (2 ** 31 - 1) // 6 - 1


def delaunay(x, y, *, method: str = "sweep") -> np.ndarray:
    """(m, 3) int64 indices of counter-clockwise Delaunay triangles of the points ``x, y``.

    The points must be distinct (reduce duplicates first); all on a line gives (0, 3).
    Coordinates are taken relative to the lower-left corner of the data for precision.
    ``method="sweep"`` is the numba sweep-hull kernel (single-threaded, releases the GIL);
    ``method="qhull"`` is scipy's Delaunay. Where points are cocircular (e.g. a regular grid)
    the triangulation is not unique and the two may split a square differently.
    """
    if method not in TRIANGULATORS:
        raise InvalidParameterError(f"triangulator must be one of {', '.join(TRIANGULATORS)} (got {method!r})")
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.size < 3:
        return np.empty((0, 3), dtype=np.int64)
    rx = np.ascontiguousarray(x - x.min())
    ry = np.ascontiguousarray(y - y.min())
    if method == "qhull":
        from scipy.spatial import Delaunay, QhullError
        try:
            tri = Delaunay(np.column_stack([rx, ry])).simplices.astype(np.int64)
        except QhullError:
            return np.empty((0, 3), dtype=np.int64)
        # qhull does not promise an orientation: make every triangle counter-clockwise.
        a, b = rx[tri], ry[tri]
        area2 = (a[:, 1] - a[:, 0]) * (b[:, 2] - b[:, 0]) - (b[:, 1] - b[:, 0]) * (a[:, 2] - a[:, 0])
        cw = area2 < 0
        tri[cw] = tri[cw][:, [0, 2, 1]]
        return np.ascontiguousarray(tri)
    if x.size > MAX_SWEEP_POINTS:
        raise InputError(f"{x.size:,} points are too many to triangulate at once (at most "
                         f"{MAX_SWEEP_POINTS:,}): use tiles or fewer points per cell")
    from ._delaunay import delaunay_kernel
    return delaunay_kernel(rx, ry)
