"""numba kernels of the return-number grid filter (core.filters.echogrid). Private: call them
through :class:`~groundsieve.core.filters.echogrid.EchoGrid`, which validates and casts first."""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _kernel_index(x, y, x0, y0, size, nx):
    return int(math.floor((y - y0) / size)) * nx + int(math.floor((x - x0) / size))


@njit(cache=True, nogil=True)
def _echo_grid_stats_kernel(x, y, z, rn, nr, x0, y0, size, nx, ny, zmin, zmax, only_first, only_single):
    """Per square kernel: lowest and highest z, whether every return number is 1 (the paper's
    bypass test) and whether every point is a single return (1 of 1)."""
    zmin[:] = np.inf
    zmax[:] = -np.inf
    only_first[:] = True
    only_single[:] = True
    for k in range(x.shape[0]):
        c = _kernel_index(x[k], y[k], x0, y0, size, nx)
        if z[k] < zmin[c]:
            zmin[c] = z[k]
        if z[k] > zmax[c]:
            zmax[c] = z[k]
        if rn[k] != 1:
            only_first[c] = False
        if nr[k] > 1:
            only_single[c] = False


@njit(cache=True, nogil=True)
def _echo_grid_classify_kernel(x, y, z, x0, y0, size, nx, reference, bypass, dz, out_ground):
    """Ground where the kernel is bypassed, or z <= reference z of the kernel + dz."""
    for k in range(x.shape[0]):
        c = _kernel_index(x[k], y[k], x0, y0, size, nx)
        out_ground[k] = bypass[c] or z[k] <= reference[c] + dz


@njit(cache=True, nogil=True)
def _lower_envelope_kernel(zmin, radius, step, slope, out):
    """out[k] = min over kernels j within ``radius`` kernels of (zmin[j] + slope * distance(k, j)):
    the lowest point around each kernel, raised by the slope the terrain may climb to reach it.
    Empty kernels (inf) are ignored; a kernel with none around stays inf."""
    ny, nx = zmin.shape
    for r in range(ny):
        for c in range(nx):
            best = np.inf
            for rr in range(max(r - radius, 0), min(r + radius + 1, ny)):
                for cc in range(max(c - radius, 0), min(c + radius + 1, nx)):
                    v = zmin[rr, cc]
                    if v < np.inf:
                        v += slope * step * math.sqrt((rr - r) ** 2 + (cc - c) ** 2)
                        if v < best:
                            best = v
            out[r, c] = best
