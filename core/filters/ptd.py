"""PTD, progressive TIN densification (Axelsson 2000, "DEM generation from laser scanner data
using adaptive TIN models", IAPRS 33(B4/1):110-117).

1. Seeds: the lowest point of each cell of a grid of ``seed_cell_m`` (about the size of the
   largest building, so that every cell holds some ground). Low outliers: a lowest point that
   lies far below most of the area around it (fewer than ``low_outlier_support``, 40 %, of the
   non-empty cells of a fine grid within 10 point spacings, at least 5 m, have their lowest
   point within the iteration distance and angle above it) is not ground, and the cell's next
   lowest point is tried. This also rejects groups of low points (multipath echoes along a
   wall, ISPRS samp41). Under a closed canopy most fine cells' lowest points are crowns, and the
   ground seen through them has little support: ``low_outlier_retry`` tries the seed cells none of
   whose 32 lowest points has support again with half the share, down to 1/16 of it, where at
   least half of the cells around (3 x 3) failed too (without it, where no cell kept a seed, the
   lowest point of all, an outlier, became the one seed and the TIN stayed below the ground: a
   generated UAV forest lost 73 % of its ground, 0.95 % with it; lidR's Megaplot 8.1 -> 6.0 % Type
   I; the ISPRS samples unchanged; a cell that failed among cells with seeds holds a large group of
   low points, and is not retried). A share of 0.2 takes Megaplot to 0.03 % but accepts a group of
   25 multipath points 25 m down along 12 m (docs/BENCHMARKS.md).
2. The initial TIN: the Delaunay triangulation of the seeds, closed by a ring of virtual
   vertices half a seed cell outside the data. Their heights extrapolate the TIN (a plane
   fitted to the real vertices among their neighbours and neighbours' neighbours) and are
   updated every round, so the TIN does not bend towards an arbitrary height at the border.
3. Densification in rounds. A point is tested against the facet holding it (in plan): above
   the facet it passes when its distance to the facet's plane is at most ``max_distance_m``
   and the angles between that plane and the lines from the point to the three vertices are
   at most ``max_angle_deg`` (Axelsson's two criteria); below the facet only the distance
   counts (the TIN is built up from the lowest points, so there it is too high). A facet
   steeper than ``max_terrain_angle_deg`` accepts nothing (TerraScan's "terrain angle": a
   facet stood up along a wall is no terrain). In each round every triangle adds at most one
   point, the passing point nearest its plane; rounds go on until no point is added.
4. Optional: ``mirror`` (Axelsson's mirror points: a point failing the test is tested again as
   its image through the nearest vertex, which lets the TIN climb steep slopes; off by default,
   see below); ``min_edge_m``, a triangle whose edges are all shorter is not densified further
   (its passing points are ground but not added: Axelsson's edge-length limit, TerraScan's
   "stop triangulation when edges are shorter than"); ``max_edge_m``, a triangle with a longer
   edge accepts no point (the TIN does not bridge large gaps).
5. The points left out of the densification are judged against the final TIN: ground when
   they pass the same test or lie within ``offset_m`` of the facet (above or below), as
   LAStools' lasground (``-offset``) and lasR's ``pdt`` (``offset``) do. The offset takes the
   points that the angle criterion rejects only because they lie very close (in plan) to a
   vertex, where the angle measures the noise of two points and not a slope.

Thinning: in a cloud denser than 2 points/m², only the lowest point of each 1 m square takes
part in the densification (a TIN denser than that adds nothing to ground detection, and it
keeps the rounds cheap); the other points are judged as in 5. lasR's PTD thins the same way
(0.25 m squares) but leaves the thinned points out of the ground altogether.

Axelsson derives the iteration thresholds from histograms of the data; here they are
parameters, as in TerraScan (which implements his filter), LP360, LAStools and lasR. Defaults
(lasR's values read in its source, src/LASRstages/ptd.cpp and pdt.cpp; GeoCue's support notes
on TerraScan and LP360 ground parameters):

* ``max_distance_m`` 1.4 m: inside GeoCue's "typical 0.5-1.5 m"; lasR uses 1 m;
* ``max_angle_deg`` 30°: lasR's ``ptd`` default (15° in its older ``pdt``). The 4-10° GeoCue
  advises for TerraScan and LP360 leave 10-30 % of the ground out on the ISPRS samples with
  this implementation (mean total error 18.8 % with a 60 m seed cell and 6°);
* ``seed_cell_m`` 30 m: the largest buildings of ordinary residential scenes ("max building
  size" for TerraScan; lasR's ``res`` is 50 m). On the ISPRS samples 30 m did better than 50 or
  60 m (the steep samp11 gains most); raise it where buildings are larger, or their roofs
  become seeds;
* ``max_terrain_angle_deg`` 75°: lasR's ``pdt`` (GeoCue: the steepest terrain slope plus
  10-15°, 88° where there are near-vertical features);
* ``offset_m`` 0.2 m: lasR's ``pdt`` uses 0.05 m on modern data; 0.2 m suits the noise of the
  older, sparser ISPRS data (without it the mean total error there is 6.2 % instead of 5.2 %);
* ``mirror`` off: on the ISPRS samples it let the TIN climb onto large objects joined to
  sloping ground (mean total error 9.9 % instead of 5.2 %).

Seed cells sit on multiples of ``seed_cell_m`` (``seed_origin="grid"``, the default), so a tile
of a survey and the whole survey pick the same seeds away from the tile's border; with it the
low-outlier test's fine grid is the seed cell halved a whole number of times and its radius a
whole number of metres (both are derived from the density, which differs a little per tile);
``"cloud"`` starts them at the cloud's lowest corner (the paper's grid). What still differs in a
tile: the ring of virtual vertices at its border, and the order in which a round's accepted
points are inserted (the order of the triangle list, which is numbered differently in a tile; a
point whose triangle an earlier insertion changed is tested again), so a few points anywhere
(0.04 % on a generated scene, docs/BENCHMARKS.md, "Seams of EVC, CSF and PTD").

The angle, distance, seed cell and offset were chosen among literature values with the 8 ISPRS
samples at hand (docs/BENCHMARKS.md), so the ISPRS figures of these defaults are optimistic.

Implementation (numba, core/filters/_ptd_tin.py and _ptd_kernels.py): one incremental Delaunay triangulation with an
adjacency structure, never rebuilt. Every triangle keeps the list of candidate points inside
it; a split or flip shares the points of the old triangles among the new ones, so no point is
ever searched for. Only the triangles changed in the last round are tested again (in parallel),
and the chosen points are inserted one by one with Lawson flips. The rounds work on a copy of the
candidates and seeds only (in a dense cloud the thinned points are most of the points, and the
lists are then walked in a memory an order of magnitude smaller), in the points' order, so the
TIN and the order of every list are those the whole array would give.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

import numpy as np

from ..errors import InvalidParameterError
from ..progress import Steps, run_cancellable
from ..validate import check_choice, check_number, validate_xyz

#: Largest seed cell accepted (m): far larger than any building; the seed cells sit on multiples of
#: the cell, so a cell of 1e9 m put the grid's corner at the origin and its thinning grid ran out of
#: memory (a QA reviewer).
MAX_SEED_CELL_M = 1000.0
#: Largest seed grid accepted (cells): a guard against a seed cell far too small.
MAX_SEED_CELLS = 50_000_000
#: Points per cell (on average) of the fine grid that orders the points in memory and holds
#: the lowest point of each cell for the low-outlier test.
_POINTS_PER_FINE_CELL = 4.0
#: Low-outlier test: radius in mean point spacings (at least _SUPPORT_MIN_RADIUS_M), lowest points
#: tried per seed cell at most (the share of cells around that must support a point is
#: ``PTD.low_outlier_support``).
_SUPPORT_SPACINGS = 10.0
_SUPPORT_MIN_RADIUS_M = 5.0
_MAX_SEED_TRIES = 32
#: The low-outlier retry halves the share down to this fraction of it (PTD.low_outlier_retry).
_SUPPORT_SHARE_FLOOR = 1 / 16
#: Thinning: in clouds denser than _THIN_MIN_DENSITY points/m², only the lowest point of each
#: _THIN_M square takes part in the densification (see the module's docstring).
_THIN_M = 1.0
_THIN_MIN_DENSITY = 2.0
#: "grid": seed cells on multiples of ``seed_cell_m`` (a tile and the whole survey share them);
#: "cloud": from the cloud's lowest corner, as the paper's grid
SEED_ORIGINS = ("grid", "cloud")
#: Rounds at most (a guard; densification stops long before).
_MAX_ROUNDS = 1_000_000
#: Virtual vertices move when their extrapolated height changes by more than this (m).
_VIRTUAL_TOLERANCE_M = 1e-3


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise InvalidParameterError(message)


@dataclass(frozen=True)
class PTDResult:
    ground: np.ndarray          #: bool per point
    seed: np.ndarray            #: bool per point: a seed of the initial TIN
    tin_vertex: np.ndarray      #: bool per point: a vertex of the final TIN (seeds included)
    low_outlier: np.ndarray     #: bool per point: a cell's lowest point rejected as a low outlier
    rounds: int                 #: densification rounds (the last one adds nothing)
    added: Tuple[int, ...]      #: ground points added in each round (not counting the seeds)


@dataclass(frozen=True)
class PTD:
    """Parameters of progressive TIN densification (see the module's docstring for the
    defaults' sources). Lengths in metres, angles in degrees; 0 turns an edge limit or the
    offset off."""
    seed_cell_m: float = 30.0
    max_angle_deg: float = 30.0
    max_distance_m: float = 1.4
    max_terrain_angle_deg: float = 75.0
    min_edge_m: float = 0.0
    max_edge_m: float = 0.0
    offset_m: float = 0.2
    mirror: bool = False
    low_outlier_check: bool = True
    low_outlier_support: float = 0.4
    low_outlier_retry: bool = True
    seed_origin: str = "grid"
    #: metres per unit of the coordinates (1 for a CRS in metres): the filter's built-in lengths, in
    #: metres, are divided by it; a run sets it for a cloud in feet (engine/workflow.py
    #: defaults_in_crs_unit), as it converts the parameters (a code reviewer: CSF 1.34 -> 1.83 %, PTD
    #: 1.09 -> 1.23 % total error on a scene in feet with the parameters converted and these not)
    metres_per_unit: float = 1.0

    name = "ptd"

    def __post_init__(self):
        for name in ("seed_cell_m", "max_angle_deg", "max_distance_m", "max_terrain_angle_deg",
                     "min_edge_m", "max_edge_m", "offset_m", "low_outlier_support"):
            check_number(self, name)
        _require(math.isfinite(self.metres_per_unit) and self.metres_per_unit > 0,
                 f"metres_per_unit must be > 0 (got {self.metres_per_unit})")
        _require(math.isfinite(self.seed_cell_m) and self.seed_cell_m > 0,
                 f"seed_cell_m must be > 0 (got {self.seed_cell_m})")
        _require(self.seed_cell_m * self.metres_per_unit <= MAX_SEED_CELL_M,  # (in metres: a preset's 400 m in feet)
                 f"seed_cell_m must be at most {MAX_SEED_CELL_M:g} m, the size of the largest buildings "
                 f"(got {self.seed_cell_m * self.metres_per_unit:g} m)")
        _require(math.isfinite(self.max_angle_deg) and 0 < self.max_angle_deg < 90,
                 f"max_angle_deg must be in (0, 90) degrees (got {self.max_angle_deg})")
        _require(math.isfinite(self.max_distance_m) and self.max_distance_m > 0,
                 f"max_distance_m must be > 0 (got {self.max_distance_m})")
        _require(math.isfinite(self.max_terrain_angle_deg) and 0 < self.max_terrain_angle_deg <= 90,
                 f"max_terrain_angle_deg must be in (0, 90] degrees (90 = no limit; "
                 f"got {self.max_terrain_angle_deg})")
        _require(math.isfinite(self.min_edge_m) and self.min_edge_m >= 0,
                 f"min_edge_m must be >= 0 (0 = off; got {self.min_edge_m})")
        _require(math.isfinite(self.max_edge_m) and self.max_edge_m >= 0,
                 f"max_edge_m must be >= 0 (0 = off; got {self.max_edge_m})")
        _require(self.max_edge_m == 0 or self.max_edge_m > self.min_edge_m,
                 f"max_edge_m ({self.max_edge_m}) must be larger than min_edge_m ({self.min_edge_m})")
        _require(math.isfinite(self.offset_m) and self.offset_m >= 0,
                 f"offset_m must be >= 0 (0 = off; got {self.offset_m})")
        _require(math.isfinite(self.low_outlier_support) and 0 < self.low_outlier_support <= 1,
                 f"low_outlier_support must be in (0, 1] (a share of the cells around; got {self.low_outlier_support})")
        for name in ("mirror", "low_outlier_check", "low_outlier_retry"):
            value = getattr(self, name)
            _require(isinstance(value, (bool, np.bool_)), f"{name} must be True or False (got {value!r})")
        check_choice(self, "seed_origin", SEED_ORIGINS)

    @property
    def reach_m(self) -> float:
        """How far (m) points influence a point's class: the seeds are the lowest points of
        ``seed_cell_m`` cells, and a point is tested against the TIN triangle above it, whose
        corners are seeds or accepted points up to about a seed cell away (or ``max_edge_m``);
        two seed cells (or the edge limit, when larger) cover the triangle and the seed cells
        that make it."""
        return max(2.0 * self.seed_cell_m, self.max_edge_m)

    def __call__(self, xyz: np.ndarray, steps: Steps | None = None) -> np.ndarray:
        """Boolean ground mask of the points ``xyz`` (n, 3)."""
        return self.run(xyz, steps).ground

    def run(self, xyz: np.ndarray, steps: Steps | None = None) -> PTDResult:
        from . import _ptd_kernels as K
        from . import _ptd_tin as T
        steps = steps or Steps()
        xyz = validate_xyz(xyz)
        steps.report(0.0)
        n = xyz.shape[0]
        if n > 2 ** 30:
            raise InvalidParameterError(f"PTD handles at most {2 ** 30:,} points at once (got {n:,}); "
                                        "process the cloud in tiles")
        x0, y0 = float(xyz[:, 0].min()), float(xyz[:, 1].min())
        seed_cell = float(self.seed_cell_m)
        if self.seed_origin == "grid":
            # Seed cells (and the 1 m thinning squares, when the seed cell is a whole number of
            # metres) on multiples of the seed cell: a tile and the whole survey share them.
            x0, y0 = math.floor(x0 / seed_cell) * seed_cell, math.floor(y0 / seed_cell) * seed_cell
        xr, yr = float(xyz[:, 0].max()) - x0, float(xyz[:, 1].max()) - y0
        scols, srows = int(xr // seed_cell) + 1, int(yr // seed_cell) + 1
        if scols * srows > MAX_SEED_CELLS:
            raise InvalidParameterError(
                f"seed_cell_m = {seed_cell:g} m over {xr:.1f} x {yr:.1f} m needs {scols * srows:,} seed cells "
                f"(limit {MAX_SEED_CELLS:,}); use a larger seed cell")

        # 1. The points sorted along a fine grid (near in space = near in memory), in coordinates
        # relative to the data's corner, with room for the virtual vertices at the end.
        area = max((float(xyz[:, 0].max()) - float(xyz[:, 0].min()))
                   * (float(xyz[:, 1].max()) - float(xyz[:, 1].min())), 1e-6)  # the data's, for its density
        cell = max(math.sqrt(_POINTS_PER_FINE_CELL * area / n), max(xr, yr) / n, 1e-3)
        if self.seed_origin == "grid":
            # The seed cell halved a whole number of times (the nearest such size): the fine grid of
            # the low-outlier test then also sits on the seed cells' multiples, and a tile whose
            # density is near the survey's gets the same fine cells.
            cell = seed_cell / 2 ** max(0, round(math.log2(seed_cell / cell)))
        ncols, nrows = int(xr // cell) + 1, int(yr // cell) + 1
        block = 32
        nkeys = ((nrows + block - 1) // block) * ((ncols + block - 1) // block) * block * block
        perm = np.empty(n, dtype=np.int32)
        cell_start = np.empty(nkeys + 1, dtype=np.int64)
        steps.check()
        run_cancellable(K.spatial_sort_kernel, xyz[:, 0], xyz[:, 1], x0, y0, cell, ncols, nrows, block, perm,
                        cell_start, steps=steps.sub(0.0, 0.02))
        ring = _ring(xr, yr, seed_cell)
        nv = n + 4 + ring.shape[0]
        points = np.empty((nv, 3))
        vx, vy, vz = points[:, 0], points[:, 1], points[:, 2]
        K.gather_kernel(xyz, perm, x0, y0, points)
        steps.report(0.03)

        # 2. Seeds, low outliers.
        status = np.zeros(n, dtype=np.uint8)
        seed_of_cell = np.empty(scols * srows, dtype=np.int64)
        spacing = math.sqrt(area / n)
        radius = max(_SUPPORT_SPACINGS * spacing, _SUPPORT_MIN_RADIUS_M / self.metres_per_unit)
        if self.seed_origin == "grid":  # whole metres: the same in a tile of about the same density
            radius = float(math.ceil(radius))
        tan_angle = math.tan(math.radians(self.max_angle_deg))
        zmin_fine = np.empty(nkeys)
        K.cell_min_kernel(vz, cell_start, zmin_fine)
        thin = _THIN_M / self.metres_per_unit
        if n / area > _THIN_MIN_DENSITY * self.metres_per_unit ** 2:  # then the thinning grid has fewer than n / 2 squares
            K.thin_kernel(vx, vy, vz, n, thin, int(xr // thin) + 1, int(yr // thin) + 1, status)
        del cell_start
        # ``low_outlier_retry``: where most seed cells around one failed (none of their lowest points
        # had support), they are tried again with half the share, down to _SUPPORT_SHARE_FLOOR of it.
        # Under a closed canopy with little understory the lowest points of nearly every fine cell are
        # crowns: every candidate of such cells was rejected, and where no cell kept a seed the one
        # seed left (the lowest point of all: a low outlier) kept the whole TIN below the ground (a
        # forester's generated forest lost all its ground). A cell that failed among cells that found
        # their seed is not retried: there it is a large group of low points (60 multipath echoes fill
        # a cell's 32 tries, and a retry made them seeds: a code reviewer). The cell's lowest points
        # are tried first at each share, so the ground has the lowest share at which it has support.
        share = float(self.low_outlier_support)
        thinned = status.copy()
        active = np.ones(scols * srows, dtype=bool)
        first = True
        while True:
            K.seeds_kernel(vx, vy, vz, n, seed_cell, scols, srows, zmin_fine, cell, ncols, nrows, block,
                           radius if self.low_outlier_check else -1.0, float(self.max_distance_m), tan_angle,
                           share, _MAX_SEED_TRIES, status, seed_of_cell, active)
            if not (self.low_outlier_check and self.low_outlier_retry) \
                    or share / 2 < float(self.low_outlier_support) * _SUPPORT_SHARE_FLOOR:
                break
            tried = status == K.EXCLUDED  # the points rejected in this pass's active cells
            if not tried.any():
                break
            if first:  # each point's seed cell, as the kernel computes it
                k = (np.minimum((vy[:n] / seed_cell).astype(np.int64), srows - 1) * scols
                     + np.minimum((vx[:n] / seed_cell).astype(np.int64), scols - 1))
            failed = np.zeros(scols * srows, dtype=bool)
            failed[k[tried]] = True
            failed &= seed_of_cell < 0  # cells whose candidates were all rejected
            if first:
                occupied = np.bincount(k, minlength=scols * srows).reshape(srows, scols) > 0
                failed &= _mostly_failed(failed.reshape(srows, scols), occupied).ravel()
                first = False
            active = failed & active
            if not active.any():
                break
            again = active[k]
            status[again] = thinned[again]
            share /= 2
        del zmin_fine, thinned
        low_outlier = status == K.EXCLUDED
        has_seed = seed_of_cell >= 0
        seeds = seed_of_cell[has_seed]  # (thinned points can be seeds: all points were looked at)
        if seeds.size == 0:  # every lowest point was rejected (cannot happen with real data)
            status[low_outlier] = K.CANDIDATE
            low_outlier[:] = False
            seeds = np.array([int(np.argmin(vz[:n]))])
            has_seed[:] = False
        steps.report(0.06)

        # 3. The points that take part in the densification (the candidates and the seeds) in rows of
        # their own, in the same order, then the virtual vertices: in a dense cloud the thinned points
        # are most of the points, and the TIN's rounds then walk a much smaller memory. A point's x, y,
        # z side by side, read in one go; the next point of its triangle's list in a small array of its
        # own (walking a list then waits on that array only, not on the coordinates).
        member = status == K.CANDIDATE
        member[seeds] = True
        index = np.flatnonzero(member).astype(np.int32)  # the point of each member
        del member
        nm = index.size
        mv = nm + 4 + ring.shape[0]
        rows = np.empty((mv, 3))
        mx, my, mz = rows[:, 0], rows[:, 1], rows[:, 2]
        nxt = np.empty(nm, dtype=np.int32)
        mx[:nm], my[:nm], mz[:nm] = vx[index], vy[index], vz[index]
        mstatus = status[index]
        mseeds = np.searchsorted(index, seeds).astype(np.int32)

        # 4. The initial TIN: the box's corners, the ring, the seeds.
        zgrid = np.full(scols * srows, float(vz[seeds[0]]))
        zgrid[has_seed] = vz[seed_of_cell[has_seed]]
        zgrid = _fill_nearest(np.where(has_seed, zgrid, np.nan).reshape(srows, scols)) if has_seed.any() \
            else zgrid.reshape(srows, scols)
        m = seed_cell
        extra = np.vstack([[[-m, -m], [xr + m, -m], [xr + m, yr + m], [-m, yr + m]], ring])
        mx[nm:], my[nm:] = extra[:, 0], extra[:, 1]
        c = np.clip((extra[:, 0] // seed_cell).astype(np.int64), 0, scols - 1)
        r = np.clip((extra[:, 1] // seed_cell).astype(np.int64), 0, srows - 1)
        mz[nm:] = zgrid[r, c]
        capacity = 2 * mv + 16
        tv = np.empty((capacity, 3), dtype=np.int32)
        tn = np.empty((capacity, 3), dtype=np.int32)
        tstamp = np.empty(capacity, dtype=np.int32)
        head = np.empty(capacity, dtype=np.int32)
        dirty = np.empty(capacity, dtype=np.int32)
        state = np.zeros(3, dtype=np.int64)  # triangles, dirty-list length, dirty-list mark
        T.init_box_kernel(tv, tn, tstamp, head, state, nm, nm + 1, nm + 2, nm + 3)
        order = np.concatenate([np.arange(nm + 4, mv), mseeds]).astype(np.int32)
        inserted = np.zeros(order.size, dtype=np.bool_)
        T.insert_vertices_kernel(tv, tn, tstamp, dirty, state, mx, my, head, nxt, mstatus, order, inserted)
        mstatus[mseeds] = np.where(inserted[ring.shape[0]:], K.GROUND_VERTEX, K.GROUND_OTHER)
        ntri = int(state[0])
        T.fill_buckets_kernel(tv, tn, ntri, mx, my, nm, mstatus, head, nxt)
        # Every triangle is dirty for the first round.
        mark = 0
        dirty[:ntri] = np.arange(ntri, dtype=np.int32)
        tstamp[:ntri] = mark
        ndirty = ntri
        new_dirty = np.empty(capacity, dtype=np.int32)
        best = np.empty(capacity, dtype=np.int32)
        hints = np.zeros(mv - nm, dtype=np.int64)
        zlo, zhi = float(vz[:n].min()), float(vz[:n].max())
        state[1], state[2] = ndirty, mark
        for _ in range(2):  # the virtual vertices extrapolate the seeds' TIN
            K.update_virtual_kernel(tv, tn, tstamp, dirty, state, mx, my, mz, nm, mv, hints, zlo, zhi,
                                    _VIRTUAL_TOLERANCE_M / self.metres_per_unit)
        ndirty = int(state[1])
        steps.report(0.08)

        # 5. Densification rounds.
        tan2 = tan_angle ** 2
        max_dist = float(self.max_distance_m)
        max_slope2 = math.tan(math.radians(self.max_terrain_angle_deg)) ** 2 \
            if self.max_terrain_angle_deg < 90 else np.inf
        min_edge2 = float(self.min_edge_m) ** 2
        max_edge2 = float(self.max_edge_m) ** 2 if self.max_edge_m > 0 else np.inf
        mirror = bool(self.mirror)
        added = []
        candidates = max(int((mstatus == K.CANDIDATE).sum()), 1)
        found = 0
        for rnd in range(_MAX_ROUNDS):
            if rnd:
                state[1], state[2] = ndirty, mark
                K.update_virtual_kernel(tv, tn, tstamp, dirty, state, mx, my, mz, nm, mv, hints, zlo, zhi,
                                        _VIRTUAL_TOLERANCE_M / self.metres_per_unit)
                ndirty = int(state[1])
            got = K.test_kernel(tv, tn, mx, my, mz, head, nxt, mstatus, dirty, ndirty, best,
                                tan2, max_dist, max_slope2, min_edge2, max_edge2, mirror)
            mark += 1
            state[1], state[2] = 0, mark
            got += K.insert_kernel(tv, tn, tstamp, mx, my, mz, head, nxt, mstatus, dirty, ndirty, best, new_dirty,
                                   state, tan2, max_dist, max_slope2, min_edge2, max_edge2, mirror)
            dirty, new_dirty, ndirty = new_dirty, dirty, int(state[1])
            added.append(int(got))
            found += int(got)
            # Progress: the share of candidates found so far or the rounds done, whichever is more.
            steps.report(0.08 + 0.87 * min(0.99, max(found / candidates, 1.0 - 0.95 ** (rnd + 1))))
            if got == 0:
                break
        del dirty, new_dirty, best

        # 6. Points near the final TIN, thinned points (the TIN's vertices back to the points' numbers).
        ntri = int(state[0])
        # The two last kernels (about 0.7 s each on 10 M points) in a worker thread: a cancel is seen at once.
        if self.offset_m > 0:
            run_cancellable(K.offset_kernel, tv, ntri, mx, my, mz, head, nxt, mstatus, float(self.offset_m),
                            max_slope2, max_edge2, steps=steps.sub(0.95, 0.97))
        status[index] = mstatus
        vx[n:], vy[n:], vz[n:] = mx[nm:], my[nm:], mz[nm:]
        tv = np.concatenate([index, np.arange(n, nv, dtype=np.int32)])[tv[:ntri]]
        del rows, head, mstatus
        run_cancellable(K.last_pass_kernel, tv, tn, ntri, vx, vy, vz, n, status, tan2, max_dist, max_slope2,
                        max_edge2, float(self.offset_m), mirror, steps=steps.sub(0.97, 0.99))
        ground = np.empty(n, dtype=bool)
        ground[perm] = (status == K.GROUND_VERTEX) | (status == K.GROUND_OTHER)
        seed = np.zeros(n, dtype=bool)
        seed[perm[seeds]] = True
        vertex = np.empty(n, dtype=bool)
        vertex[perm] = status == K.GROUND_VERTEX
        outlier = np.empty(n, dtype=bool)
        outlier[perm] = low_outlier
        steps.report(1.0)
        return PTDResult(ground, seed, vertex, outlier, len(added), tuple(added))


def _mostly_failed(failed: np.ndarray, occupied: np.ndarray) -> np.ndarray:
    """Per seed cell: at least half of the cells holding points in its 3 x 3 neighbourhood (itself
    included) failed to find a supported seed."""
    from scipy.ndimage import uniform_filter
    f = uniform_filter(failed.astype(np.float64), size=3, mode="constant")
    o = uniform_filter(occupied.astype(np.float64), size=3, mode="constant")
    return f >= 0.5 * o - 1e-9


def _ring(xr: float, yr: float, seed_cell: float) -> np.ndarray:
    """Virtual vertices half a seed cell outside the data's box, at most a seed cell apart."""
    h = seed_cell / 2
    nx = max(1, int(math.ceil((xr + 2 * h) / seed_cell)))
    ny = max(1, int(math.ceil((yr + 2 * h) / seed_cell)))
    xs = np.linspace(-h, xr + h, nx + 1)
    ys = np.linspace(-h, yr + h, ny + 1)
    bottom = np.column_stack([xs, np.full(xs.size, -h)])
    top = np.column_stack([xs, np.full(xs.size, yr + h)])
    left = np.column_stack([np.full(ys.size - 2, -h), ys[1:-1]])
    right = np.column_stack([np.full(ys.size - 2, xr + h), ys[1:-1]])
    return np.vstack([bottom, top, left, right])


def _fill_nearest(grid: np.ndarray) -> np.ndarray:
    """NaN cells take the value of the nearest finite cell."""
    missing = np.isnan(grid)
    if not missing.any() or missing.all():
        return grid
    from scipy.ndimage import distance_transform_edt
    idx = distance_transform_edt(missing, return_distances=False, return_indices=True)
    return grid[tuple(idx)]


def triangulate(x, y) -> np.ndarray:
    """Delaunay triangles (k, 3) of the points (x, y) made by PTD's TIN kernels, as indices into
    x, y, counter-clockwise; the triangles that use the enclosing box's corners are left out,
    and a point at the position of an earlier one is not a vertex. For tests and inspection."""
    from . import _ptd_tin as T
    x = np.ascontiguousarray(x, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    n = x.size
    if n == 0 or y.size != n:
        raise InvalidParameterError("triangulate: x and y must be non-empty and of the same size")
    x0, y0 = float(x.min()), float(y.min())
    span = max(float(x.max()) - x0, float(y.max()) - y0, 1.0)
    m = 10.0 * span
    vx = np.concatenate([x - x0, [-m, span + m, span + m, -m]])
    vy = np.concatenate([y - y0, [-m, -m, span + m, span + m]])
    capacity = 2 * (n + 4) + 16
    tv = np.empty((capacity, 3), dtype=np.int32)
    tn = np.empty((capacity, 3), dtype=np.int32)
    tstamp = np.empty(capacity, dtype=np.int32)
    head = np.empty(capacity, dtype=np.int32)
    dirty = np.empty(capacity, dtype=np.int32)
    state = np.zeros(3, dtype=np.int64)
    status = np.zeros(n, dtype=np.uint8)
    nxt = np.empty(n, dtype=np.int32)
    T.init_box_kernel(tv, tn, tstamp, head, state, n, n + 1, n + 2, n + 3)
    inserted = np.zeros(n, dtype=np.bool_)
    T.insert_vertices_kernel(tv, tn, tstamp, dirty, state, vx, vy, head, nxt, status,
                             np.arange(n, dtype=np.int32), inserted)
    tris = tv[:state[0]]
    return tris[(tris < n).all(axis=1)].astype(np.int64)
