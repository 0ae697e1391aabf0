"""numba kernel of SMRF's last step (core.filters.smrf). Private: call it through
:class:`~groundsieve.core.filters.smrf.SMRF`, which validates and casts first."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..grids._kernels import _keys_weights


@njit(cache=True, nogil=True)
def _classify_against_surface_kernel(x, y, z, surface, slope, x0, top, cell,
                                     threshold, scalar, out_ground):
    """SMRF's last step: ground where |z - surface(x, y)| <= threshold + scalar * slope(x, y),
    both grids interpolated by cubic convolution at the point (``_kernels._cubic_one``'s
    arithmetic, its weights and clamped indices computed once for the two grids)."""
    wx = np.empty(4)
    wy = np.empty(4)
    nrows, ncols = surface.shape
    for k in range(x.shape[0]):
        fc = (x[k] - x0) / cell - 0.5
        fr = (top - y[k]) / cell - 0.5
        c0 = int(math.floor(fc))
        r0 = int(math.floor(fr))
        _keys_weights(fc - c0, wx)
        _keys_weights(fr - r0, wy)
        zs = 0.0
        ss = 0.0
        for a in range(4):
            rr = min(max(r0 + a - 1, 0), nrows - 1)
            row_z = 0.0
            row_s = 0.0
            for b in range(4):
                cc = min(max(c0 + b - 1, 0), ncols - 1)
                row_z += wx[b] * surface[rr, cc]
                row_s += wx[b] * slope[rr, cc]
            zs += wy[a] * row_z
            ss += wy[a] * row_s
        out_ground[k] = abs(z[k] - zs) <= threshold + scalar * ss
