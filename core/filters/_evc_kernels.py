"""numba kernel of the multiscale EVC filter (core.filters.evc). Private: call it through
:class:`~groundsieve.core.filters.evc.EVC`, which validates and casts first."""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _focal_cv_kernel(values, radius, max_radius, min_cells, out_mean, out_std):
    """Mean and (population) standard deviation of the non-NaN ``values`` in the square window
    of ``radius`` cells around each non-NaN cell. Where fewer than ``min_cells`` cells of the
    window hold a value, the window grows one cell at a time up to ``max_radius``. Cells left
    with fewer than 2 values, and NaN cells, get NaN."""
    nrows, ncols = values.shape
    for r in range(nrows):
        for c in range(ncols):
            out_mean[r, c] = np.nan
            out_std[r, c] = np.nan
            if np.isnan(values[r, c]):
                continue
            rad = radius
            while True:
                count = 0
                total = 0.0
                total2 = 0.0
                for rr in range(max(r - rad, 0), min(r + rad + 1, nrows)):
                    for cc in range(max(c - rad, 0), min(c + rad + 1, ncols)):
                        v = values[rr, cc]
                        if not np.isnan(v):
                            count += 1
                            total += v
                            total2 += v * v
                if count >= min_cells or rad >= max_radius:
                    break
                rad += 1
            if count >= 2:
                mean = total / count
                var = total2 / count - mean * mean
                out_mean[r, c] = mean
                out_std[r, c] = math.sqrt(var) if var > 0.0 else 0.0


@njit(cache=True, nogil=True)
def _focal_median_kernel(values, radius, out):
    """The median of the non-NaN ``values`` in the square window of ``radius`` cells around each
    non-NaN cell (NaN elsewhere)."""
    nrows, ncols = values.shape
    window = np.empty((2 * radius + 1) ** 2, dtype=np.float64)
    for r in range(nrows):
        for c in range(ncols):
            out[r, c] = np.nan
            if np.isnan(values[r, c]):
                continue
            count = 0
            for rr in range(max(r - radius, 0), min(r + radius + 1, nrows)):
                for cc in range(max(c - radius, 0), min(c + radius + 1, ncols)):
                    v = values[rr, cc]
                    if not np.isnan(v):  # (kept in order as it fills: an insertion sort, no allocation)
                        k = count
                        while k > 0 and window[k - 1] > v:
                            window[k] = window[k - 1]
                            k -= 1
                        window[k] = v
                        count += 1
            half = count // 2
            out[r, c] = window[half] if count % 2 else 0.5 * (window[half - 1] + window[half])
