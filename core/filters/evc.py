"""The multiscale elevation-variation-coefficient (EVC) filter of Fan et al. (2023).

1. Virtual grids of mean elevation at a small scale (``small_scale_m``, 0.2 m) and a large
   scale (``large_scale_m``, 2.0 m; 3.2 m was the paper's other optimum).
2. The elevation difference between the two on the small grid (the "output standard"): each
   small cell against the large cell holding its centre.
3. In a square window of ``radius`` cells (1 = 3 x 3) around each small cell,
   EVC = standard deviation / mean of that difference.
4. Table 2 of the paper: ground where 0 < EVC <= ``threshold`` (1.5); vegetation area where
   EVC <= 0; vegetation boundary where EVC > threshold. Points take their small cell's class.
   ``auto_threshold`` picks the threshold by natural breaks (Jenks, two classes of the
   positive EVC values), as the paper did; the values above their ``breaks_percentile`` (95)
   are left out first, where the ratio explodes near a zero mean difference (ours: the paper
   says natural breaks only; ``breaks_percentile=100`` keeps every value).

Sign of the difference. The paper says the values "in vegetation areas were mostly negative"
and so were their EVCs, and Table 2 calls EVC <= 0 vegetation. Vegetation raises a small cell
above the smoother large-scale surface, so that sign is ``large - small``, the default here
(``difference="large_minus_small"``). ``"small_minus_large"`` is available; with it the same
Table 2 calls the canopy ground (measured in docs/BENCHMARKS.md).

Empty small cells (the normal case below ~25 points/m² at 0.2 m) hold no difference and are
left out of every window: the statistics use the non-empty cells only, and where a window holds
fewer than ``min_cells`` non-empty cells it grows one cell at a time up to ``max_radius``. A
cell still left with fewer than two values gets no EVC and its points are called vegetation
boundary (not ground). Large cells are never empty where a small cell has points, except at
the rim when the scales are not multiples; those take the nearest large cell's mean.

Cells sit on multiples of their size (``cell_origin="grid"``, the default) and each point's cell
is found from its own coordinate, so a tile of a survey and the whole survey share their cells
and a tiled run classifies as the whole cloud; ``"cloud"`` starts them at the cloud's lowest
corner, the paper's virtual grid (measured in docs/BENCHMARKS.md).

``point_tolerance_m`` (default 0 = the paper) is our second, an option too: in the paper every point takes
its small cell's class, so a point floating metres above the ground (an image-matching blunder) or a cluster
below it is ground wherever its cell stays ground, and makes a spike or a pit in the DTM (a photogrammetry
reviewer: 82 of 248 floating points ground with the shipped preset). With a tolerance, a point of a ground
cell is ground only within that height of the median of the ground cells' mean elevations in the window of
``radius`` cells around its cell (itself included: robust to a few cells the blunders raise or sink). On
generated photogrammetric scenes with blunders, 0.3 m left 0-4 of about 100 noise points ground where the
paper's rule left 22-36, and lowered the total error a little (bench/evc_noise.py, docs/BENCHMARKS.md); the
``uav-photogrammetry-evc`` preset sets it.

``ground_offset_m`` (default 0 = the paper) is our first departure, offered as an option: the
coefficient of variation is unstable where the mean difference is near zero, which is the case
on open ground far from vegetation (the difference is then only noise, of random sign, and
about half of such ground falls into "vegetation area"). Adding a small offset (the ground's
roughness, e.g. 0.1 m) to the mean difference before the ratio keeps open ground in [0, t]:
with an offset, a cell is ground when the shifted mean is positive and EVC <= t (so a perfectly
smooth surface, EVC = 0, is ground; under the paper's rule 0/0 is no EVC at all).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..errors import InvalidParameterError
from ..grids.spec import MAX_CELLS, GridSpec, check_memory
from ..progress import Steps
from ..validate import check_choice, check_number, validate_xyz

DIFFERENCES = ("large_minus_small", "small_minus_large")
#: "grid": cells on multiples of their size (a tile and the whole survey share them);
#: "cloud": cells from the cloud's lowest corner (the paper's virtual grid)
CELL_ORIGINS = ("grid", "cloud")
#: class codes of the class raster
EMPTY, GROUND, VEGETATION_AREA, VEGETATION_BOUNDARY = 0, 1, 2, 3


#: the classes of the class raster (Fan et al. 2023, Table 2): value, legend label, colour
EVC_CLASSES = ((GROUND, "Ground", "#b07d3c"),
               (VEGETATION_AREA, "Vegetation area", "#1a7f2e"),
               (VEGETATION_BOUNDARY, "Vegetation boundary", "#9bd35a"))

#: the EVC workflow's rasters (groundsieve:evcrasters, and the command line's evc): name -> (label,
#: f(EVCResult) -> (values, grid[, write_geotiff's options]))
EVC_RASTERS = {
    "small_mean": ("Small-scale mean elevation", lambda d: (d.small_mean, d.small_grid)),
    "large_mean": ("Large-scale mean elevation", lambda d: (d.large_mean, d.large_grid)),
    "difference": ("Elevation difference", lambda d: (d.difference, d.small_grid)),
    "evc": ("Elevation variation coefficient (EVC)", lambda d: (d.evc, d.small_grid)),
    # the class raster as bytes, empty cells (0) as no data, its classes coloured (a palette) and named (the
    # band's description and metadata) in the file
    "classes": ("EVC classes (1 ground, 2 vegetation area, 3 vegetation boundary)",
                lambda d: (d.classes, d.small_grid, {"dtype": "uint8", "nodata": 0, "categories": EVC_CLASSES})),
}


@dataclass(frozen=True)
class EVCResult:
    ground: np.ndarray              #: bool per point
    small_grid: GridSpec
    large_grid: GridSpec
    small_mean: np.ndarray          #: mean z per small cell (NaN = empty)
    large_mean: np.ndarray          #: mean z per large cell (NaN = empty)
    difference: np.ndarray          #: on the small grid (NaN = empty)
    evc: np.ndarray                 #: on the small grid (NaN = empty or undefined)
    classes: np.ndarray             #: uint8 on the small grid: 0 empty, 1 ground, 2 veg. area, 3 veg. boundary
    threshold: float                #: the threshold used (given, or found by natural breaks)
    #: when no point is ground: why, and what to change (the DTM's refusal quotes it)
    no_ground_reason: str = ""


@dataclass(frozen=True)
class EVC:
    small_scale_m: float = 0.2
    large_scale_m: float = 2.0
    radius: int = 1
    threshold: float = 1.5
    auto_threshold: bool = False
    difference: str = "large_minus_small"
    min_cells: int = 3
    max_radius: int = 5
    ground_offset_m: float = 0.0
    #: a ground cell's point is ground only within this height (m) of its window's ground cells' median
    #: elevation (0 = the paper: every point takes its cell's class)
    point_tolerance_m: float = 0.0
    cell_origin: str = "grid"
    #: natural breaks (auto_threshold) leave out the EVC values above this percentile (100 = none)
    breaks_percentile: float = 95.0

    name = "evc"

    def __post_init__(self):
        for name in ("small_scale_m", "large_scale_m", "threshold", "ground_offset_m", "point_tolerance_m"):
            check_number(self, name)
        for name in ("radius", "min_cells", "max_radius"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise InvalidParameterError(f"{name} must be a whole number (got {value!r})")
        if not (math.isfinite(self.small_scale_m) and self.small_scale_m > 0):
            raise InvalidParameterError(f"small_scale_m must be > 0 (got {self.small_scale_m})")
        if not (math.isfinite(self.large_scale_m) and self.large_scale_m > self.small_scale_m):
            raise InvalidParameterError(
                f"large_scale_m must be larger than small_scale_m {self.small_scale_m} m (got {self.large_scale_m})")
        if self.radius < 1:
            raise InvalidParameterError(f"radius must be at least 1 cell (got {self.radius})")
        if self.max_radius < self.radius:
            raise InvalidParameterError(f"max_radius must be >= radius {self.radius} (got {self.max_radius})")
        if self.min_cells < 2:
            raise InvalidParameterError(f"min_cells must be at least 2 (got {self.min_cells})")
        if not (math.isfinite(self.threshold) and self.threshold > 0):
            raise InvalidParameterError(f"threshold must be > 0 (got {self.threshold})")
        if not (math.isfinite(self.ground_offset_m) and self.ground_offset_m >= 0):
            raise InvalidParameterError(f"ground_offset_m must be >= 0 (got {self.ground_offset_m})")
        if not (math.isfinite(self.point_tolerance_m) and self.point_tolerance_m >= 0):
            raise InvalidParameterError(f"point_tolerance_m must be >= 0 (got {self.point_tolerance_m})")
        check_choice(self, "difference", DIFFERENCES)
        check_choice(self, "cell_origin", CELL_ORIGINS)
        check_number(self, "breaks_percentile")
        if not (math.isfinite(self.breaks_percentile) and 0 < self.breaks_percentile <= 100):
            raise InvalidParameterError(f"breaks_percentile must be in (0, 100] (got {self.breaks_percentile})")

    @property
    def reach_m(self) -> float:
        """How far (m) points influence a point's class: the large-scale cell holding its small
        cell (and the nearest filled large cell when that one is empty), and the focal window of
        up to ``max_radius`` small cells on the difference grid. Not the natural-breaks
        threshold (``auto_threshold``), which looks at the whole cloud: a tiled run picks one
        per tile."""
        return 3.0 * self.large_scale_m + (self.max_radius + 1) * self.small_scale_m

    #: the engine passes ``log`` to :meth:`run` (it says the threshold natural breaks chose)
    wants_log = True

    @property
    def tiled_note(self) -> str:
        """What a tiled run should say of this filter's settings ("" = nothing)."""
        if not self.auto_threshold:
            return ""
        return ("EVC: natural breaks picks its threshold in each tile, from that tile's cells, so tiles may "
                "differ from one another and from a run of the whole cloud; for a survey, set the threshold "
                "(e.g. the one natural breaks chose on a typical part, which a run on it logs) instead.")

    def __call__(self, xyz, steps=None, **_fields) -> np.ndarray:
        return self.run(xyz, steps).ground

    def run(self, xyz, steps: Optional[Steps] = None, log=None, **_fields) -> EVCResult:
        from scipy.ndimage import distance_transform_edt

        from ._evc_kernels import _focal_cv_kernel, _focal_median_kernel
        steps = steps or Steps()
        xyz = validate_xyz(xyz)
        x, y, z = (np.ascontiguousarray(xyz[:, i]) for i in range(3))
        span = max(float(x.max() - x.min()), float(y.max() - y.min()))
        if self.large_scale_m > span:
            raise InvalidParameterError(
                f"large_scale_m {self.large_scale_m:g} m is larger than the cloud itself "
                f"({span:.2f} m across): the large-scale grid would be a single cell")
        # Per small cell: the mean surface and its count, the difference, its windowed mean and
        # standard deviation, the EVC and the classes (about eight 8-byte grids).
        small, cell_s, (gx0_s, gy1_s) = _cells(x, y, self.small_scale_m, self.cell_origin,
                                               "EVC small-scale grid", 64)
        large, cell_l, (gx0_l, gy1_l) = _cells(x, y, self.large_scale_m, self.cell_origin,
                                               "EVC large-scale grid", 16)
        small_mean = _mean_by_cell(cell_s, z, small.shape)
        large_mean = _mean_by_cell(cell_l, z, large.shape)
        del cell_l
        steps.report(0.3)
        filled = large_mean
        if np.isnan(large_mean).any():
            idx = distance_transform_edt(np.isnan(large_mean), return_distances=False, return_indices=True)
            filled = large_mean[tuple(idx)]
        # The large cell holding each small cell's centre, counted in whole cells from the origin:
        # the same integers in a tile and in the whole cloud.
        ratio = self.small_scale_m / self.large_scale_m
        small_gx = gx0_s + np.arange(small.ncols)
        small_gy = gy1_s - np.arange(small.nrows)          # row 0 = the northern row
        cols = np.clip(np.floor((small_gx + 0.5) * ratio).astype(np.int64) - gx0_l, 0, large.ncols - 1)
        rows = np.clip(gy1_l - (np.ceil((small_gy + 0.5) * ratio).astype(np.int64) - 1), 0, large.nrows - 1)
        large_on_small = filled[rows[:, None], cols[None, :]]
        if self.difference == "large_minus_small":
            difference = large_on_small - small_mean
        else:
            difference = small_mean - large_on_small
        del large_on_small
        steps.report(0.5)
        mean = np.empty_like(difference)
        std = np.empty_like(difference)
        _focal_cv_kernel(difference, int(self.radius), int(self.max_radius), int(self.min_cells), mean, std)
        with np.errstate(divide="ignore", invalid="ignore"):
            evc = std / (mean + self.ground_offset_m)
        steps.report(0.8)
        threshold = natural_break(evc, upper_percentile=self.breaks_percentile) if self.auto_threshold \
            else float(self.threshold)
        if self.auto_threshold and log is not None:
            log(f"EVC: natural breaks chose the threshold {threshold:.4g}.")
        classes = np.full(evc.shape, VEGETATION_BOUNDARY, dtype=np.uint8)  # also: no EVC
        if self.ground_offset_m > 0:
            shifted = mean + self.ground_offset_m
            classes[shifted <= 0] = VEGETATION_AREA
            classes[(shifted > 0) & (evc <= threshold)] = GROUND
        else:  # the paper's Table 2
            classes[evc <= 0] = VEGETATION_AREA
            classes[(evc > 0) & (evc <= threshold)] = GROUND
        classes[np.isnan(small_mean)] = EMPTY
        cls_at_point = classes.ravel()[cell_s]
        ground = cls_at_point == GROUND
        if self.point_tolerance_m > 0 and ground.any():
            level = np.empty_like(small_mean)
            _focal_median_kernel(np.where(classes == GROUND, small_mean, np.nan), int(self.radius), level)
            ground &= np.abs(z - level.ravel()[cell_s]) <= self.point_tolerance_m
        steps.report(1.0)
        return EVCResult(ground, small, large, small_mean, large_mean, difference, evc, classes, threshold,
                         "" if ground.any() else self._why_no_ground(small_mean, mean, std, threshold))

    def _why_no_ground(self, small_mean, mean, std, threshold) -> str:
        """Why the filter called no cell ground, in words that say what to change."""
        occupied = ~np.isnan(small_mean)
        flat = occupied & (mean == 0) & (std == 0)
        if self.ground_offset_m == 0 and flat.sum() >= 0.5 * max(1, int(occupied.sum())):
            return (f"the surface is perfectly flat ({flat.sum() / max(1, occupied.sum()):.0%} of the "
                    f"{self.small_scale_m:g} m cells lie exactly on the {self.large_scale_m:g} m surface): there "
                    "the paper's EVC, standard deviation / mean of the difference, is 0 / 0, undefined, and "
                    "Table 2 calls no such cell ground. Set the ground offset (the ground's roughness, e.g. 0.1 m; "
                    "'Ground offset added to the mean difference (m)' in QGIS), which makes a smooth surface ground")
        return (f"no cell has an EVC in (0, {threshold:g}] (the threshold): raise the threshold, or set the ground "
                "offset (e.g. 0.1 m), or check the scales against the point spacing")


def _cells(x, y, cell, origin, what, bytes_per_cell):
    """The grid of ``cell`` m covering the points and each point's cell in it (row-major index).

    Each point's cell is ``floor((x - o) / cell)`` counted from the origin ``o`` (0 for "grid",
    the cloud's lowest corner for "cloud"): with the "grid" origin the same float expression on
    the same coordinate, so a tile and the whole survey put every point, also one lying exactly
    on a cell edge, in the same cell. (``floor((x - x0) / cell)`` with ``x0`` a multiple of 0.2 m
    that binary cannot hold exactly puts a point on an edge on either side depending on ``x0``;
    with coordinates in 1 cm steps that is one point in ten.) As in ``GridSpec``, a cell holds its
    western and its northern edge; rows count from the north."""
    ox, oy = (0.0, 0.0) if origin == "grid" else (float(x.min()), float(y.min()))
    gx = np.floor((x - ox) / cell).astype(np.int64)
    gy = np.ceil((y - oy) / cell).astype(np.int64) - 1    # rows hold their northern edge
    gx0, gx1, gy0, gy1 = int(gx.min()), int(gx.max()), int(gy.min()), int(gy.max())
    nrows, ncols = gy1 - gy0 + 1, gx1 - gx0 + 1
    check_memory(nrows * ncols * float(bytes_per_cell), what=what, shape=(nrows, ncols), cell=cell, x=x, y=y)
    if nrows * ncols > MAX_CELLS:
        raise InvalidParameterError(f"{what}: a cell size of {cell:g} m needs {ncols} x {nrows} = "
                                    f"{nrows * ncols:,} cells (limit {MAX_CELLS:,}); use a larger cell size")
    grid = GridSpec(ox + gx0 * cell, oy + (gy1 + 1) * cell, float(cell), nrows, ncols)
    gx -= gx0
    np.subtract(gy1, gy, out=gy)
    gy *= ncols
    gy += gx
    return grid, gy, (gx0, gy1)


def _mean_by_cell(flat, z, shape):
    """Mean z per cell (NaN where empty) from each point's row-major cell index."""
    count = np.bincount(flat, minlength=shape[0] * shape[1])
    total = np.bincount(flat, weights=z, minlength=shape[0] * shape[1])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1), np.nan).reshape(shape)


def natural_break(evc: np.ndarray, max_values: int = 200_000, upper_percentile: float = 95.0) -> float:
    """Two-class natural break (Jenks; for two classes the exact optimum of the within-class
    sum of squares) of the positive finite EVC values: the largest value of the lower class.
    The ratio explodes where the mean difference nears zero, so values above the
    ``upper_percentile`` are left out first (they would otherwise be a class of their own)."""
    values = evc[np.isfinite(evc) & (evc > 0)]
    if values.size:
        values = values[values <= np.percentile(values, upper_percentile)]
    if values.size < 2:
        raise InvalidParameterError("too few positive EVC values to find a natural break; set a threshold")
    if values.size > max_values:  # an even subsample of the sorted values keeps the break
        values = np.sort(values)[np.linspace(0, values.size - 1, max_values).astype(np.int64)]
    else:
        values = np.sort(values)
    n = values.size
    csum = np.cumsum(values)
    csum2 = np.cumsum(values * values)
    k = np.arange(1, n)  # lower class = values[:k]
    left = csum2[k - 1] - csum[k - 1] ** 2 / k
    right = (csum2[-1] - csum2[k - 1]) - (csum[-1] - csum[k - 1]) ** 2 / (n - k)
    best = int(np.argmin(left + right))
    return float(values[best])
