"""numba kernel of SMRF's last step (core.filters.smrf). Private: call it through
:class:`~groundsieve.core.filters.smrf.SMRF`, which validates and casts first."""
from __future__ import annotations

import numpy as np
from numba import njit

from ..grids._kernels import _cubic_one


@njit(cache=True, nogil=True)
def _classify_against_surface_kernel(x, y, z, surface, slope, x0, top, cell,
                                     threshold, scalar, out_ground):
    """SMRF's last step: ground where |z - surface(x, y)| <= threshold + scalar * slope(x, y),
    both grids interpolated by cubic convolution at the point."""
    wx = np.empty(4)
    wy = np.empty(4)
    for k in range(x.shape[0]):
        fc = (x[k] - x0) / cell - 0.5
        fr = (top - y[k]) / cell - 0.5
        zs = _cubic_one(surface, fc, fr, wx, wy)
        ss = _cubic_one(slope, fc, fr, wx, wy)
        out_ground[k] = abs(z[k] - zs) <= threshold + scalar * ss
