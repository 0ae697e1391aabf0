"""CSF, the cloth simulation filter (Zhang, Qi, Wan, Wang, Xie, Wang & Yan 2016,
Remote Sensing 8(6):501), after the authors' reference implementation (jianboqi/CSF,
Apache-2.0; read, not copied; the PyPI package ``cloth-simulation-filter`` 1.1.7 is the
version measured against in ``bench/csf_compare.py``).

The cloud is turned upside down (``h = -z``) and a cloth of particles, ``cloth_resolution_m``
apart, is dropped on it from 0.05 m above its highest (inverted) point:

1. **intersection heights**: each particle gets the inverted height of "its" point, below
   which it cannot fall (see ``intersection_height`` below);
2. **iterations** (at most ``iterations``): every movable particle takes a Verlet step
   ``h += 0.99 (h - h_previous) + a`` under a constant gravity step ``a``; then the internal
   forces pull each particle towards each of its 16 neighbours (the 8 around it and the 8 at
   two particles' distance) by a fraction of their height difference that grows with
   ``rigidness`` (0.3 / 0.51 / 0.657 of it towards a pinned neighbour, 0.3 / 0.42 / 0.468 at
   each end between two movable ones: the closed form of 1, 2 or 3 relaxations); a particle
   that falls below its intersection height is put on it and pinned for good. The run stops
   early once no movable particle moved more than 5 mm in an iteration (with the default
   rotating sweep, see below: more than 40 mm over a cycle of 8 iterations);
3. **slope smoothing** (``slope_smooth``, the paper's post-processing for steep slopes):
   each group of more than 50 still-movable particles is pinned onto its intersection
   heights from its pinned edges inwards while neighbouring intersection heights differ by
   less than ``slope_smooth_height_m`` (h_cp, 0.3 m);
4. **classification**: a point is ground when its height differs from the cloth,
   interpolated bilinearly between the four particles around it, by less than
   ``class_threshold_m`` (h_cc).

Details kept from the reference implementation: the cloth extends two particles beyond the
points' bounding box on its west and south sides (and up to one on the others); the gravity
step is ``a = 0.2 * time_step**4`` per iteration (the 1.1.7 library multiplies the gravity
by ``time_step**2`` twice; some later sources of the repository do it once, which makes the
cloth 2.4 times heavier); each neighbour pair is relaxed twice per iteration, once from
each end, particle by particle in index order (Gauss-Seidel); the early stop at 5 mm.

What GroundSieve does differently, each measured on the ISPRS samples in
``bench/csf_compare.py`` and switchable back to the reference:

* ``intersection_height="nearest"`` (default): a particle's intersection height is that of
  the **nearest point in the horizontal plane**, as the paper defines it (and as the
  repository's early kd-tree code did). The 1.1.7 library instead gives each particle the
  nearest of the points that *round to it* and fills every particle without one by a
  scan line (the first particle with a point to the east, else west, south, north): where
  points are sparser than the cloth (ISPRS: 1-3.5 m spacing against 0.5 m), most particles
  take the height of a point metres to the east, the cloth is pinned too low on slopes: over
  the 8 ISPRS samples here, with the paper's parameters, the mean total error is 18.6 % the
  library's way and 7.8 % with nearest-point heights (6.1 % with the outlier step below,
  5.6 % with the rotating sweep too; published: 4.6 %). ``"cell"`` (with ``low_outlier_m=0``,
  ``sweep_order="fixed"`` and ``cloth_origin="cloud"``) reproduces the library: 99.8-100 % of points classified the
  same, on every sample.
* ``low_outlier_m`` (default 5 m; 0 = off): before the cloth is made, a point lying more
  than this below the third lowest of the lowest points of the eight 5 m cells around its
  own is a low outlier: it is not ground and the cloth does not see it. In the inverted
  cloud a low outlier is a spike that pins a tent of cloth tens of metres below the ground
  (ISPRS sample 31: 13.9 % total error with its 18 labelled low outliers, 2.0 % without).
  The reference has no outlier step.
* ``sweep_order="rotating"`` (default): the constraint pass updates the particles one
  after another, each with the new heights of those before it (Gauss-Seidel), so the cloth
  depends on the order, i.e. on how the cloud is oriented: the 8 ISPRS samples turned by 0,
  90, 180, 270 degrees give a mean total error of 6.07 / 6.59 / 7.81 / 7.41 % in the
  reference's order (samp51 alone 2.2-12.6 %). The rotating sweep runs iteration i in the
  order of the reference on the cloth turned or mirrored by the (i mod 8)-th symmetry of the
  square (:func:`sweeps`), and tests the early stop once per cycle of 8 (the cloth moved less
  than 8 x 5 mm since the previous cycle): 5.58 / 5.42 / 5.44 / 5.75 %, per-sample ranges
  4 times narrower; on 5 million generated points 1.00 % error against 1.09 %; about 1.3
  times the run time. ``"fixed"`` is the reference's order.
* ``cloth_origin="grid"`` (default): the particles sit on multiples of the cloth resolution
  (the first column at or below the lowest x, minus the two-particle border), as do the 5 m
  cells of the low-outlier step, so a tile of a survey and the whole survey share their
  particles; ``"cloud"`` starts them at the cloud's lowest corner, as the reference does. The
  cloth stays one global simulation: a tile's cloth differs from the whole cloud's near the
  tile's edges and where the tile's lowest point (where the free fall first touches) is not the
  survey's (see docs/BENCHMARKS.md, "Seams of EVC, CSF and PTD").
* Speed, not results: the free fall before the first contact is computed for one particle
  (bit-for-bit the same); pinned particles whose 16 neighbours are pinned are skipped (nothing
  can move them or be moved by them); the scan-line fill is linear in the number of particles.
  The constraint pass stays sequential (Gauss-Seidel) and single-threaded: 10 million generated
  points take about 4 s (3 s with the fixed sweep); 5 million 1.9 s against the library's 2.6 s
  on two threads (bench/csf_compare.py --part agreement).

``constraint_scheme`` chooses how neighbouring particles hold each other:

* ``"library"`` (default): the 1.1.7 library's scheme described in step 2 above, in the
  ``sweep_order`` chosen;
* ``"2016"``: the scheme of the authors' first published code (the repository's ``CSFDLL``
  folder, the code of the paper's time): ``rigidness`` passes per iteration over the list of
  neighbour pairs (the 8 around and the 8 at distance two, each pair once per pass), each
  closing 0.3 of the pair's height difference; a pair moves only when its *first* particle
  (the west, south or south-west one; the south-east end of the anti-diagonal) is movable, so
  a pinned particle pulls only the neighbours that list it second (to its west, south-west,
  south and south-east); it always runs in its own fixed order (``sweep_order`` does not
  apply). Only the constraints are that code's: its other differences (no early stop, a 4 m
  cloth buffer; its stored Particle.cpp never resets the acceleration while gravity is added
  every iteration, which taken literally makes the cloth ever heavier and gave 26 % on the
  ISPRS samples in a trial run, so it cannot be what produced the paper) are not reproduced;
  without the early stop the ISPRS figures below are the same to 0.01 point. The cloth is
  softer and the result depends on the cloud's orientation. With it the paper's ISPRS table is reproduced: with the paper's
  parameters, every one of the 8 samples here within 1.5 points of the published total error,
  mean 4.83 % against 4.64 % published (library scheme: 6.07 % in the fixed order, 5.58 %
  rotating); turned by 90, 180 or 270 degrees the same samples give 7.0-7.6 %
  (``bench/csf_compare.py --part scheme2016``). The published table is one orientation of an
  orientation-dependent filter.
"""
from __future__ import annotations

import functools
import math
from typing import Optional
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidParameterError
from ..grids.spec import MAX_CELLS, GridSpec, check_memory
from ..progress import Steps
from ..validate import check_choice, check_number, validate_xyz

#: Constants of the reference implementation.
GRAVITY = 0.2                 #: gravity of the cloth (per unit time step squared)
CLOTH_START_M = 0.05          #: the cloth starts this far above the highest inverted point
CLOTH_BUFFER = 2              #: particles added beyond the points' bounding box
STOP_DIFF_M = 0.005           #: early stop: no movable particle moved more than this
SMOOTH_MIN_GROUP = 50         #: slope smoothing only for groups of more particles than this
#: Fraction of a height difference closed per iteration, rigidness 1, 2, 3 (the closed form of
#: 1, 2, 3 relaxations of 0.3): towards a pinned neighbour, and at each end of a movable pair.
SINGLE_MOVE = {1: 0.3, 2: 0.51, 3: 0.657}
DOUBLE_MOVE = {1: 0.3, 2: 0.42, 3: 0.468}

#: Cell of the low-outlier test (m).
LOW_OUTLIER_CELL_M = 5.0
#: "grid": particles (and the low-outlier cells) on multiples of their spacing, shared by a tile
#: and the whole survey; "cloud": from the cloud's lowest corner, as the reference does
CLOTH_ORIGINS = ("grid", "cloud")
#: Square rings of particles searched for the nearest point; particles farther than this from
#: any point take the intersection height of the nearest particle that found one.
NEAREST_MAX_RING = 8

INTERSECTION_HEIGHTS = ("nearest", "cell")
CONSTRAINT_SCHEMES = ("library", "2016")
SWEEP_ORDERS = ("rotating", "fixed")
RIGIDNESS_SCENES = {1: "steep slope", 2: "relief", 3: "flat"}


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise InvalidParameterError(message)


@functools.lru_cache(maxsize=None)
def sweeps():
    """The sweep orders of ``sweep_order="rotating"``: for each of the 8 symmetries g of the
    square (columns mirrored or not, then 0-3 quarter turns, as np.rot90), the neighbour list
    and the traversal flags (transpose, rev_outer, rev_inner) of _csf_cloth._time_step_kernel
    under which its sweep over the cloth is the reference's sweep over the cloth transformed by
    g. Found on small probe grids (a 5 x 4 index grid for the traversal, 5 x 5 for the
    neighbours); ``tests/core/test_csf.py`` checks the equivalence bit for bit."""
    from ._csf_cloth import NEIGHBOURS
    out = []
    W, H = 5, 4
    index = np.arange(W * H).reshape(H, W)
    probe = np.arange(25).reshape(5, 5)
    for mirror in (False, True):
        for turns in range(4):
            def g(a):
                return np.rot90(a[:, ::-1] if mirror else a, turns)
            order = g(index).ravel()
            step = int(order[1] - order[0])
            transpose = abs(step) == W
            first_row, first_col = divmod(int(order[0]), W)
            rev_outer = first_col == W - 1 if transpose else first_row == H - 1
            moved = g(probe)
            centre = int(moved[2, 2])
            neighbours = np.array([(int(moved[2 + dr, 2 + dc]) % 5 - centre % 5,
                                    int(moved[2 + dr, 2 + dc]) // 5 - centre // 5)
                                   for dc, dr in NEIGHBOURS], dtype=np.int64)
            out.append((neighbours, (transpose, rev_outer, step < 0)))
    return tuple(out)


def _transpose(a: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """The flat row-major (rows, cols) array ``a`` as a flat row-major (cols, rows) array."""
    return np.ascontiguousarray(a.reshape(rows, cols).T).ravel()


@dataclass(frozen=True)
class CSFResult:
    ground: np.ndarray          #: bool per point
    grid: GridSpec              #: cell centres on the particles (row 0 north)
    cloth: np.ndarray           #: the cloth's height (z, not inverted) at each particle
    pinned: np.ndarray          #: particles that touched the cloud or were smoothed onto it
    low_outliers: np.ndarray    #: bool per point: left out as low outliers (never ground)
    iterations: int             #: iterations run (the early stop may end them sooner)


@dataclass(frozen=True)
class CSF:
    """Parameters of CSF, with the defaults of the reference implementation (cloth
    resolution 1 m, rigidness 3, time step 0.65, class threshold 0.5 m, 500 iterations,
    slope smoothing on). Zhang et al. (2016) use 0.5 m on the ISPRS samples. The last four
    choose between the reference's behaviour, GroundSieve's changes (the defaults) and the
    authors' 2016 code (see the module docstring); ``intersection_height="cell",
    low_outlier_m=0, sweep_order="fixed", cloth_origin="cloud"`` is the reference library's
    behaviour."""
    cloth_resolution_m: float = 1.0
    rigidness: int = 3
    time_step: float = 0.65
    class_threshold_m: float = 0.5
    iterations: int = 500
    slope_smooth: bool = True
    slope_smooth_height_m: float = 0.3
    intersection_height: str = "nearest"
    low_outlier_m: float = 5.0
    constraint_scheme: str = "library"
    sweep_order: str = "rotating"
    cloth_origin: str = "grid"
    #: height (z, m) at or below which the cloth starts (None: the lowest point's, the
    #: reference); a tiled run may pass the survey's lowest z so that every tile's cloth falls
    #: from the height the whole survey's does
    cloth_start_z: Optional[float] = None
    #: metres per unit of the coordinates (1 for a CRS in metres): the filter's built-in lengths, in
    #: metres, are divided by it; a run sets it for a cloud in feet (engine/workflow.py
    #: defaults_in_crs_unit), as it converts the parameters (a code reviewer: CSF 1.34 -> 1.83 %, PTD
    #: 1.09 -> 1.23 % total error on a scene in feet with the parameters converted and these not)
    metres_per_unit: float = 1.0

    name = "csf"

    def __post_init__(self):
        for name in ("cloth_resolution_m", "rigidness", "time_step", "class_threshold_m", "iterations",
                     "slope_smooth_height_m", "low_outlier_m"):
            check_number(self, name)
        _require(math.isfinite(self.cloth_resolution_m) and self.cloth_resolution_m > 0,
                 f"cloth_resolution_m must be > 0 (got {self.cloth_resolution_m})")
        _require(self.rigidness in SINGLE_MOVE and int(self.rigidness) == self.rigidness,
                 f"rigidness must be 1 (steep slope), 2 (relief) or 3 (flat) (got {self.rigidness})")
        _require(math.isfinite(self.time_step) and self.time_step > 0,
                 f"time_step must be > 0 (got {self.time_step})")
        _require(math.isfinite(self.class_threshold_m) and self.class_threshold_m > 0,
                 f"class_threshold_m must be > 0 (got {self.class_threshold_m})")
        _require(math.isfinite(self.iterations) and int(self.iterations) == self.iterations
                 and self.iterations >= 1,
                 f"iterations must be a whole number >= 1 (got {self.iterations})")
        _require(math.isfinite(self.slope_smooth_height_m) and self.slope_smooth_height_m > 0,
                 f"slope_smooth_height_m must be > 0 (got {self.slope_smooth_height_m})")
        _require(math.isfinite(self.metres_per_unit) and self.metres_per_unit > 0,
                 f"metres_per_unit must be > 0 (got {self.metres_per_unit})")
        _require(math.isfinite(self.low_outlier_m) and self.low_outlier_m >= 0,
                 f"low_outlier_m must be >= 0 (0 = off) (got {self.low_outlier_m})")
        _require(isinstance(self.slope_smooth, (bool, np.bool_)),
                 f"slope_smooth must be True or False (got {self.slope_smooth!r})")
        check_choice(self, "intersection_height", INTERSECTION_HEIGHTS)
        check_choice(self, "sweep_order", SWEEP_ORDERS)
        check_choice(self, "constraint_scheme", CONSTRAINT_SCHEMES)
        check_choice(self, "cloth_origin", CLOTH_ORIGINS)
        if isinstance(self.cloth_start_z, str):  # the command line gives the optional height as text
            try:
                object.__setattr__(self, "cloth_start_z", float(self.cloth_start_z))
            except ValueError:
                pass  # refused just below, in the same words
        _require(self.cloth_start_z is None or (isinstance(self.cloth_start_z, (int, float, np.floating))
                                                and math.isfinite(self.cloth_start_z)),
                 f"cloth_start_z must be a height in metres or None (got {self.cloth_start_z!r})")

    @property
    def gravity_step_m(self) -> float:
        """Displacement added by gravity at each iteration (the reference's 0.2 * dt**4)."""
        return GRAVITY * self.time_step ** 4 / self.metres_per_unit

    @property
    def reach_m(self) -> float:
        """How far (m) points influence a point's class. The cloth is one elastic sheet: in
        principle every particle pulls on every other; in practice a particle's height is set
        by the points under it and by its neighbours through the springs, whose influence fades
        over a few tens of particles (more with a stiffer cloth: rigidness 3 moves a particle
        towards its neighbours in 3 sub-steps per iteration). 30 m or 10 particles per unit of
        rigidness, whichever is larger; a measured, not a proven, reach (see docs/BENCHMARKS.md)."""
        return max(30.0 / self.metres_per_unit, 10.0 * self.rigidness * self.cloth_resolution_m)

    def _origin(self, xmin: float, ymin: float, cell: float) -> tuple:
        """Where a grid of ``cell`` m starts: on the multiple of ``cell`` at or below the lowest
        point ("grid": a tile and the whole survey share their particles) or on the lowest point
        itself ("cloud", the reference)."""
        if self.cloth_origin == "cloud":
            return xmin, ymin
        return math.floor(xmin / cell) * cell, math.floor(ymin / cell) * cell

    def __call__(self, xyz: np.ndarray, steps: Steps | None = None) -> np.ndarray:
        """Boolean ground mask of the points ``xyz`` (n, 3)."""
        return self.run(xyz, steps).ground

    def run(self, xyz: np.ndarray, steps: Steps | None = None) -> CSFResult:
        from . import _csf_cloth as cloth
        from . import _csf_terrain as terrain
        steps = steps or Steps()
        xyz = validate_xyz(xyz)
        x, y, z = (np.ascontiguousarray(xyz[:, i]) for i in range(3))
        n = x.shape[0]
        res = float(self.cloth_resolution_m)

        low = np.zeros(n, dtype=np.bool_)
        if self.low_outlier_m > 0:
            cell = LOW_OUTLIER_CELL_M / self.metres_per_unit
            x0, y0 = self._origin(float(x.min()), float(y.min()), cell)
            ncols = int((float(x.max()) - x0) / cell) + 1
            nrows = int((float(y.max()) - y0) / cell) + 1
            # Two float64 grids (the lowest z per cell and its reference): refused before allocating
            # when too large (a point 1000 km away made a bare MemoryError).
            check_memory(nrows * ncols * 16.0, what="CSF low-outlier grid", shape=(nrows, ncols),
                         cell=cell, x=x, y=y)
            terrain._low_outliers_kernel(x, y, z, x0, y0, cell, ncols, nrows,
                                   float(self.low_outlier_m), low)
        use = ~low
        xu, yu, zu = (x, y, z) if not low.any() else (x[use], y[use], z[use])
        steps.report(0.02)

        # The cloth: the reference's geometry, from the bounding box of the points it sees.
        xmin, xmax = float(xu.min()), float(xu.max())
        ymin, ymax = float(yu.min()), float(yu.max())
        xmin, ymin = self._origin(xmin, ymin, res)  # the first particle column and row
        ox = xmin - CLOTH_BUFFER * res
        oy = ymin - CLOTH_BUFFER * res
        W = int(math.floor((xmax - xmin) / res)) + 2 * CLOTH_BUFFER
        H = int(math.floor((ymax - ymin) / res)) + 2 * CLOTH_BUFFER
        _require(W * H <= MAX_CELLS,
                 f"cloth_resolution_m of {res:g} m over {xmax - xmin:.1f} x {ymax - ymin:.1f} m needs "
                 f"{W} x {H} = {W * H:,} particles (limit {MAX_CELLS:,}); use a larger cloth resolution")
        # Per particle: the terrain height under it, its position, previous position, movable and
        # quiet flags, and the neighbour sums of the cloth iteration (about eight 8-byte values).
        check_memory(W * H * 64.0, what="CSF cloth", shape=(H, W), cell=res, x=xu, y=yu)
        hv = np.full(W * H, -np.inf)
        has = np.zeros(W * H, dtype=np.bool_)
        if self.intersection_height == "cell":
            terrain._cell_heights_kernel(x, y, z, use, ox, oy, res, W, H, hv, has)
            hv = terrain._scanline_fill_kernel(hv, has, W, H)
        else:
            terrain._nearest_heights_kernel(x, y, z, use, ox, oy, res, W, H, NEAREST_MAX_RING, hv, has)
            if not has.all():
                from scipy.ndimage import distance_transform_edt
                idx = distance_transform_edt(~has.reshape(H, W), return_distances=False,
                                             return_indices=True)
                hv = hv.reshape(H, W)[idx[0], idx[1]].ravel()
                del idx
        del has
        steps.report(0.1)

        # The simulation.
        lowest = float(zu.min()) if self.cloth_start_z is None else min(float(zu.min()), float(self.cloth_start_z))
        pos = np.full(W * H, -lowest + CLOTH_START_M / self.metres_per_unit)
        old = pos.copy()
        movable = np.ones(W * H, dtype=np.bool_)
        quiet = np.zeros(W * H, dtype=np.bool_)
        acceleration = -self.gravity_step_m
        single, double = SINGLE_MOVE[int(self.rigidness)], DOUBLE_MOVE[int(self.rigidness)]
        total = int(self.iterations)
        done, stopped = cloth._free_fall_kernel(pos, old, hv, acceleration, total, STOP_DIFF_M / self.metres_per_unit)
        sim = steps.sub(0.1, 0.9)
        scheme_2016 = self.constraint_scheme == "2016"
        if scheme_2016:  # that kernel runs on column-major arrays
            pos, old, movable, hv_sim = (_transpose(a, H, W) for a in (pos, old, movable, hv))
        rotating = not scheme_2016 and self.sweep_order == "rotating"
        cycle_start = pos.copy() if rotating else None
        orders = sweeps()
        first = done  # the free fall (all orders alike) is over: cycles count from here
        while done < total and not stopped:
            sim.report(done / total)  # also raises Cancelled: a long run stops within an iteration
            if scheme_2016:
                max_diff, _pinned = cloth._time_step_2016_kernel(pos, old, movable, hv_sim, W, H, acceleration,
                                                             int(self.rigidness))
            elif rotating:
                neighbours, flags = orders[(done - first) % len(orders)]
                cloth._time_step_kernel(pos, old, movable, quiet, hv, W, H, acceleration, single, double,
                                    neighbours, *flags)
            else:
                max_diff, _pinned = cloth._time_step_kernel(pos, old, movable, quiet, hv, W, H, acceleration,
                                                        single, double)
            done += 1
            if not rotating:
                stopped = max_diff != 0.0 and max_diff < STOP_DIFF_M / self.metres_per_unit
            elif (done - first) % len(orders) == 0:
                # One stop test per cycle of the 8 orders: each order has its own resting state,
                # so the step to step change never settles; the cycle to cycle one does.
                stopped = cloth._max_change(pos, cycle_start, movable) < len(orders) * STOP_DIFF_M / self.metres_per_unit
                cycle_start[:] = pos
        del cycle_start
        if scheme_2016:
            pos, movable = _transpose(pos, W, H), _transpose(movable, W, H)
            del hv_sim
        del old, quiet
        sim.report(1.0)
        if self.slope_smooth:
            cloth._slope_smooth_kernel(pos, movable, hv, W, H, float(self.slope_smooth_height_m), SMOOTH_MIN_GROUP)
        steps.report(0.92)

        ground = np.empty(n, dtype=np.bool_)
        cloth._classify_kernel(x, y, z, use, ox, oy, res, W, H, pos, float(self.class_threshold_m), ground)
        grid = GridSpec(ox - res / 2, oy + (H - 1) * res + res / 2, res, H, W)
        cloth = (-pos).reshape(H, W)[::-1].copy()
        pinned = (~movable).reshape(H, W)[::-1].copy()
        steps.report(1.0)
        return CSFResult(ground, grid, cloth, pinned, low, done)
