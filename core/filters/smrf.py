"""SMRF, the simple morphological filter (Pingel, Clarke & McBride 2013).

Faithful to the paper and to the author's own code:

1. minimum surface ``Zmin`` on a grid of ``cell_size_m``; empty cells filled by
   harmonic ("springs") inpainting;
2. low outliers: the progressive filter run once (radius 1 cell) on ``-Zmin`` with a
   slope of ``low_outlier_slope`` (5 = 500 %); such cells are objects (Pingel's rule, kept
   without ``low_outlier_fill``). With ``low_outlier_fill`` (ours, the default) they are removed
   from ``Zmin`` and refilled before step 3 where they are few (``low_outlier_max_share`` of
   the occupied cells within 10 m); where they are many they are the ground seen through gaps
   in a canopy: they stay in ``Zmin``, and are objects only if still more than
   ``low_outlier_slope`` cells below the terrain around them (themselves and the cells the
   openings leave as ground) opened with a disk of 3 cells. Not told apart: a dense, flat sheet
   of low noise in open ground (a mirror image under water or glass) looks like a forest floor;
   classify it as noise (7, ignored by default) first;
3. progressive morphological opening with disks whose radius grows by one cell from
   1 to ``window_m / cell_size_m``, each step opening the previous result; a cell
   whose height drops by more than ``slope * radius * cell_size_m`` is an object;
4. the provisional surface: ``Zmin`` with empty, low-outlier and object cells removed
   and refilled by inpainting;
5. every point is ground when ``|z - Zpro(x, y)| <= elevation_threshold_m +
   elevation_scalar * S(x, y)``, ``S`` the gradient magnitude (rise/run) of ``Zpro``;
   both grids are interpolated at the point by cubic convolution (MATLAB's
   ``interp2(..., 'cubic')`` in the original; Pingel's Python uses a cubic spline).

PDAL's ``filters.smrf`` differs (diamond-shaped windows, nearest-cell lookup, a
kd-tree fill) and measures worse on ISPRS; it is not followed here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np

from ..errors import InvalidParameterError
from ..grids.inpaint import inpaint_harmonic
from ..grids.morphology import opening, progressive_filter
from ..grids.rasterize import cell_min
from ..grids.spec import FILL_BYTES_PER_EMPTY_CELL, GridSpec
from ..progress import Steps
from ..validate import _require, check_number, validate_xyz


#: points classified against the final surface per kernel call (progress and cancel between)
POINTS_PER_SLICE = 500_000
#: at most this much memory for the progressive opening's drops kept over a search (one grid per radius)
KEEP_OPENINGS_BYTES = 256 * 2 ** 20


@dataclass(frozen=True)
class SMRFResult:
    ground: np.ndarray          #: bool per point
    grid: GridSpec
    provisional_surface: np.ndarray  #: Zpro (row 0 north)
    object_cells: np.ndarray    #: empty, low-outlier or object cells


@dataclass(frozen=True)
class SMRFMinimum:
    """SMRF's steps 1-2 on one cloud (read-only arrays): they depend only on the points, the cell
    and the low-outlier settings (``key``, :attr:`SMRF.minimum_key`), so runs that differ in slope,
    window or thresholds share them (tuning, the hybrid features)."""
    grid: GridSpec
    raw: np.ndarray             #: lowest z per cell, NaN where empty
    zmin: np.ndarray            #: filled, low outliers removed and refilled (with ``low_outlier_fill``)
    empty: np.ndarray           #: cells no point falls in
    low: np.ndarray             #: low-outlier cells
    key: tuple
    #: kept drops of the progressive opening (see :meth:`drops`); None = not kept
    openings: Optional[list] = field(default=None, compare=False, repr=False)
    #: the low-outlier cells removed and refilled (with ``low_outlier_fill``, where few: low_outlier_share)
    refilled: Optional[np.ndarray] = None

    def drops(self, radius: int, steps: Steps | None = None) -> Optional[List[np.ndarray]]:
        """The progressive opening's drops ``last - opening(last, r)`` for r = 1..``radius`` (cells),
        ``last`` starting at ``zmin``: they depend on neither the slope nor the window, which only
        compare them with ``slope * r * cell`` and choose where to stop. Made once and kept (a
        search over slope and window then opens the surface once per radius, not once per run).
        None when they are not kept or would take more than :data:`KEEP_OPENINGS_BYTES`."""
        state = self.openings
        if state is None or radius * self.zmin.nbytes > KEEP_OPENINGS_BYTES:
            return None
        if not state:
            state.extend([self.zmin, []])
        last, drops = state
        while len(drops) < radius:
            opened = opening(last, len(drops) + 1)
            drop = last - opened
            drop.flags.writeable = False
            drops.append(drop)
            last = state[0] = opened
            if steps is not None:
                steps.report(len(drops) / radius)  # progress, and a cancel check between openings
        return drops[:radius]


@dataclass(frozen=True)
class SMRF:
    """Parameters of SMRF, with Pingel's single-set defaults (slope 0.15, window 18 m,
    threshold 0.5 m, scalar 1.25, cell 1 m)."""
    cell_size_m: float = 1.0
    slope: float = 0.15
    window_m: float = 18.0
    elevation_threshold_m: float = 0.5
    elevation_scalar: float = 1.25
    low_outlier_slope: float = 5.0
    low_outlier_fill: bool = True
    #: refill a low-outlier cell only where low-outlier cells are at most this share of the cells
    #: holding points within LOW_OUTLIER_SHARE_RADIUS_M around it; more are not outliers but the
    #: ground seen through gaps in a canopy (1 = refill every one, as before 2026-11-25)
    low_outlier_max_share: float = 0.05
    #: metres per unit of the coordinates (1 for a CRS in metres): the filter's built-in lengths, in
    #: metres, are divided by it; a run sets it for a cloud in feet (engine/workflow.py
    #: defaults_in_crs_unit), as it converts the parameters (a code reviewer: CSF 1.34 -> 1.83 %, PTD
    #: 1.09 -> 1.23 % total error on a scene in feet with the parameters converted and these not)
    metres_per_unit: float = 1.0

    name = "smrf"

    def __post_init__(self):
        for name in ("cell_size_m", "slope", "window_m", "elevation_threshold_m", "elevation_scalar",
                     "low_outlier_slope"):
            check_number(self, name)
        _require(math.isfinite(self.cell_size_m) and self.cell_size_m > 0,
                 f"cell_size_m must be > 0 (got {self.cell_size_m})")
        _require(math.isfinite(self.slope) and self.slope >= 0,
                 f"slope (rise/run) must be >= 0 (got {self.slope})")
        _require(math.isfinite(self.window_m) and self.window_m >= self.cell_size_m,
                 f"window_m must be at least the cell size {self.cell_size_m} m (got {self.window_m})")
        _require(math.isfinite(self.elevation_threshold_m) and self.elevation_threshold_m >= 0,
                 f"elevation_threshold_m must be >= 0 (got {self.elevation_threshold_m})")
        _require(math.isfinite(self.elevation_scalar) and self.elevation_scalar >= 0,
                 f"elevation_scalar must be >= 0 (got {self.elevation_scalar})")
        _require(math.isfinite(self.low_outlier_slope) and self.low_outlier_slope > 0,
                 f"low_outlier_slope must be > 0 (got {self.low_outlier_slope})")
        _require(math.isfinite(self.metres_per_unit) and self.metres_per_unit > 0,
                 f"metres_per_unit must be > 0 (got {self.metres_per_unit})")
        _require(math.isfinite(self.low_outlier_max_share) and 0 <= self.low_outlier_max_share <= 1,
                 f"low_outlier_max_share must be between 0 and 1 (got {self.low_outlier_max_share})")

    @property
    def radii(self) -> range:
        """Window radii in cells: 1, 2, ..., window_m / cell_size_m."""
        return range(1, max(1, int(round(self.window_m / self.cell_size_m))) + 1)

    @property
    def reach_m(self) -> float:
        """How far (m) points influence a point's class: the largest opening (erosion then
        dilation by a disk of ``window_m``) reads cells up to two window radii away, plus a cell
        for the cubic interpolation of the surface and its slope. The harmonic inpainting of
        object cells reaches further in principle, but inside a building's footprint, whose
        radius the window is. A tiled run reads this much around each tile."""
        return 2.0 * self.window_m + 2.0 * self.cell_size_m

    def __call__(self, xyz: np.ndarray, steps: Steps | None = None) -> np.ndarray:
        """Boolean ground mask of the points ``xyz`` (n, 3)."""
        return self.run(xyz, steps).ground

    @property
    def minimum_key(self) -> tuple:
        """What :meth:`minimum_surface` depends on besides the points: a minimum surface made by an
        SMRF with the same key serves this one (tuning and the hybrid features reuse it)."""
        return (float(self.cell_size_m), float(self.low_outlier_slope), bool(self.low_outlier_fill),
                float(self.low_outlier_max_share))

    def minimum_surface(self, xyz: np.ndarray, steps: Steps | None = None,
                        keep_openings: bool = False) -> SMRFMinimum:
        """Steps 1 and 2: the filled minimum surface with the low outliers found (and, with
        ``low_outlier_fill``, removed and refilled). Independent of slope, window and thresholds.
        ``keep_openings``: keep the progressive opening's drops as runs make them
        (:meth:`SMRFMinimum.drops`; one grid per radius) for the next :meth:`surface` calls."""
        xyz = validate_xyz(xyz)
        return self._minimum(*(np.ascontiguousarray(xyz[:, i]) for i in range(3)), steps, keep_openings)

    def _minimum(self, x, y, z, steps: Steps | None, keep_openings: bool) -> SMRFMinimum:
        """:meth:`minimum_surface` of validated contiguous coordinates."""
        steps = steps or Steps()
        # Peak per cell: about ten float64 grids at once (minimum surface, its fill, the openings,
        # the gradient); every cell no point reaches costs the harmonic fill on top.
        grid = GridSpec.covering(x, y, self.cell_size_m, what="SMRF grid", bytes_per_cell=96,
                                 bytes_per_empty_cell=FILL_BYTES_PER_EMPTY_CELL)
        steps.report(0.1)
        raw = cell_min(x, y, z, grid, steps.sub(0.1, 0.3))
        empty = np.isnan(raw)
        zmin = inpaint_harmonic(raw)
        steps.report(0.6)
        low = progressive_filter(-zmin, [1], self.cell_size_m, self.low_outlier_slope)
        steps.report(0.7)
        refilled = np.zeros_like(low)
        if self.low_outlier_fill and low.any():
            refilled = low & (low_outlier_share(low, ~empty, self.cell_size_m * self.metres_per_unit)
                              <= self.low_outlier_max_share)
            if refilled.any():
                zmin[refilled] = np.nan
                zmin = inpaint_harmonic(zmin)
        steps.report(1.0)
        for a in (raw, zmin, empty, low, refilled):
            a.flags.writeable = False  # shared between runs: nobody may change it
        return SMRFMinimum(grid, raw, zmin, empty, low, self.minimum_key, [] if keep_openings else None,
                           refilled)

    def surface(self, xyz: np.ndarray, steps: Steps | None = None,
                minimum: SMRFMinimum | None = None) -> Tuple[GridSpec, np.ndarray, np.ndarray]:
        """Steps 1-4 without the point test: (grid, provisional surface Zpro, object cells).
        ``minimum``: this cloud's :meth:`minimum_surface` made earlier with the same
        :attr:`minimum_key` (it is not changed)."""
        steps = steps or Steps()
        if minimum is None:
            minimum = self.minimum_surface(xyz, steps.sub(0.0, 0.2))
        return self._surface(minimum, steps)

    def _surface(self, minimum: SMRFMinimum, steps: Steps) -> Tuple[GridSpec, np.ndarray, np.ndarray]:
        if minimum.key != self.minimum_key:
            raise InvalidParameterError(f"this minimum surface was made for cell, low-outlier slope and refill "
                                        f"{minimum.key}, not {self.minimum_key}")
        steps.report(0.2)
        # Once a disk spans the grid's diagonal the opened surface is the grid's minimum everywhere,
        # and the openings after it drop nothing: the radii stop there, with the same objects (a
        # window of 1e9 m built a list of 1e9 radii and exhausted the memory; 1e4 m took 146 s).
        radii = self.radii[:max(1, math.ceil(math.hypot(*minimum.zmin.shape)))]
        drops = minimum.drops(len(radii), steps.sub(0.2, 0.8))
        if drops is None:
            objects = progressive_filter(minimum.zmin, radii, self.cell_size_m, self.slope,
                                         steps=steps.sub(0.2, 0.8))
        else:  # progressive_filter's test on the kept drops, the same comparisons
            objects = np.zeros(minimum.zmin.shape, dtype=bool)
            for radius, drop in zip(radii, drops):
                objects |= drop > self.slope * radius * self.cell_size_m
        steps.report(0.8)
        objects |= minimum.empty | self._low_objects(minimum, objects, steps)
        steps.report(0.9)  # (a cancel is honoured between the judging of kept cells and the last fill)
        if objects.all():
            # Nothing survived as ground: fall back to the minimum surface itself.
            zpro = minimum.raw.copy()
        else:
            zpro = minimum.zmin.copy()
            zpro[objects] = np.nan
        zpro = inpaint_harmonic(zpro)
        steps.report(1.0)
        return minimum.grid, zpro, objects

    def _low_objects(self, minimum: SMRFMinimum, opened: np.ndarray, steps: Steps | None = None) -> np.ndarray:
        """The low-outlier cells that are objects. Without the refill, every one (Pingel's rule). With
        it, those refilled, and of those kept (too many around to be outliers: the ground seen through
        gaps in a canopy, see low_outlier_share) the ones still low outliers against the terrain
        around them, the kept cells and the cells the openings (``opened``: their object cells) left
        as ground: a true low outlier among them stays an object, and the ground under a closed canopy
        is not (were it an object, the surface there would be a fill from the canopy's edge, which a
        tile cannot see whole)."""
        low = minimum.low
        if not (self.low_outlier_fill and low.any()):
            return low
        refilled = minimum.refilled
        kept = low & ~refilled
        if not kept.any():
            return refilled
        terrain = -inpaint_harmonic(np.where((kept | ~opened) & ~minimum.empty & ~refilled, minimum.raw, np.nan))
        if steps is not None:
            steps.report(0.85)
        # against a disk of LOW_OUTLIER_TERRAIN_CELLS: a cluster of low points smaller than it (multipath
        # under a canopy) is still caught, where the 3 x 3 test sees the cluster's own cells around
        still = terrain - opening(terrain, LOW_OUTLIER_TERRAIN_CELLS) > self.low_outlier_slope * self.cell_size_m
        return refilled | (still & kept)

    def run(self, xyz: np.ndarray, steps: Steps | None = None,
            minimum: SMRFMinimum | None = None) -> SMRFResult:
        steps = steps or Steps()
        # Progress shares from the stages' times (5 M points, warm: the copy of the coordinates and
        # the minimum surface 21 %, the openings and the surface 49 %, the last step 29 %).
        xyz = validate_xyz(xyz)
        x, y, z = (np.ascontiguousarray(xyz[:, i]) for i in range(3))
        steps.report(0.05)
        if minimum is None:
            minimum = self._minimum(x, y, z, steps.sub(0.05, 0.22), False)
        grid, zpro, objects = self._surface(minimum, steps.sub(0.22, 0.72))
        steps.report(0.72)
        ground = ground_against_surface(x, y, z, zpro, surface_slope(zpro, self.cell_size_m), grid,
                                        self.elevation_threshold_m, self.elevation_scalar, steps.sub(0.72, 1.0))
        steps.report(1.0)
        return SMRFResult(ground, grid, zpro, objects)


#: the neighbourhood (m) over which low_outlier_share counts the low-outlier cells: a few crowns
LOW_OUTLIER_SHARE_RADIUS_M = 10.0
#: the disk (cells) a kept low-outlier cell is judged against the terrain around it with (SMRF._low_objects)
LOW_OUTLIER_TERRAIN_CELLS = 3


def low_outlier_share(low: np.ndarray, occupied: np.ndarray, cell_m: float) -> np.ndarray:
    """Per cell, the low-outlier cells over the cells holding points in the square of
    LOW_OUTLIER_SHARE_RADIUS_M around it (1 where none holds points). True low outliers (a
    multipath return, a point below a bridge) are a few isolated cells; under a closed canopy the
    cells whose lowest point is ground are most of the occupied ones among cells of crowns, and
    Pingel's test flags 10-16 % of them (lidR's Megaplot, MixedConifer; 0.1-2.8 % on the ISPRS
    samples; docs/BENCHMARKS.md)."""
    from scipy.ndimage import uniform_filter
    size = 2 * max(1, int(round(LOW_OUTLIER_SHARE_RADIUS_M / cell_m))) + 1
    flagged = uniform_filter(low.astype(np.float64), size, mode="constant")
    held = uniform_filter(occupied.astype(np.float64), size, mode="constant")
    return np.where(held > 1e-9, flagged / np.maximum(held, 1e-9), 1.0)


def surface_slope(surface: np.ndarray, cell_m: float) -> np.ndarray:
    """The slope (rise/run) of a surface grid, as SMRF's last step reads it."""
    gy, gx = np.gradient(surface, cell_m) if min(surface.shape) > 1 else (
        np.zeros_like(surface), np.zeros_like(surface))
    return np.sqrt(gx * gx + gy * gy)


def ground_against_surface(x, y, z, surface: np.ndarray, slope_grid: np.ndarray, grid: GridSpec,
                           threshold_m: float, scalar: float, steps: Steps | None = None) -> np.ndarray:
    """SMRF's last step: a point is ground when it lies within ``threshold_m + scalar x slope`` of
    the surface (interpolated at the point). Used by SMRF itself and by tuning, which re-scores
    thresholds on one run's surface. Point by point and independent: in slices, with progress and
    a cancel check between them."""
    from ._smrf_kernels import _classify_against_surface_kernel
    steps = steps or Steps()
    x, y, z = (np.ascontiguousarray(a, dtype=np.float64) for a in (x, y, z))
    ground = np.empty(x.shape[0], dtype=np.bool_)
    n = x.shape[0]
    for i in range(0, n, POINTS_PER_SLICE):
        j = min(i + POINTS_PER_SLICE, n)
        _classify_against_surface_kernel(x[i:j], y[i:j], z[i:j], surface, slope_grid, grid.x0, grid.top, grid.cell,
                                         float(threshold_m), float(scalar), ground[i:j])
        steps.report(j / n)
    return ground
