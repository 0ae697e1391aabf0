"""Synthetic airborne LiDAR scenes with known ground truth, for tests and benchmarks.

A scene is a square of ``size_m`` at realistic UTM coordinates (EPSG:32632, south-west
corner at :data:`ORIGIN_X`, :data:`ORIGIN_Y`, terrain around :data:`BASE_Z_M`), built
from:

* terrain: a general slope of a few percent, gentle hills (a sum of long plane waves)
  and two breaklines crossing the scene: a terrace (a step of ``terrace_height_m`` over
  a 1 m wide embankment) and a trapezoidal ditch ``ditch_depth_m`` deep;
* rectangular buildings (sides 10-40 m, rotated, flat or gabled roofs, 5-15 m high),
  kept off the breaklines and away from each other;
* trees (8-25 m tall, crowns of 3-10 m radius, deciduous ellipsoids or conifer cones),
  half of them clustered in groves, and shrubs (0.3-2 m high, 0.5-2 m radius).

Laser pulses fall uniformly at random, ``density_per_m2`` per m², and echo as follows:

======================  ======================================================
pulse over              returns (ASPRS truth class)
======================  ======================================================
open ground             1 of 1 on the ground (2), ±3 cm noise
a roof                  1 of 1 on the roof (6)
just beside a wall      sometimes 1 of 1 on the wall (6): walls are sparse
a shrub                 first on the shrub (3), sometimes a last on the ground (2)
a tree crown            first in the crown (5), 0-2 intermediate (5), and in
                        about 60 % of the pulses a last on the ground (2); 1-4 in all
======================  ======================================================

Everything is drawn from one ``seed`` with independent streams for terrain, each
object kind, the pulse layout and the echoes, so a scene is reproducible and the same
seed and size give the same terrain and objects at any density. Generation is
vectorised numpy (3-4 s and 1.6 GB for 10 million points; no QGIS, no Qt).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, replace
from typing import Optional, Tuple

import numpy as np

from .errors import InvalidParameterError
from .io import CLASS_GROUND, new_las, write_las

CLASS_LOW_VEGETATION = 3
CLASS_HIGH_VEGETATION = 5
CLASS_BUILDING = 6

#: EPSG code of the scenes (WGS 84 / UTM zone 32N), their south-west corner and the
#: terrain height at their centre.
EPSG = 32632
ORIGIN_X = 500_000.0
ORIGIN_Y = 5_400_000.0
BASE_Z_M = 250.0

#: Adjusted standard GPS time (GPS seconds - 1e9) of the first pulse, and the pulse rate.
GPS_TIME_START_S = 3.0e8
PULSE_RATE_HZ = 200_000.0

#: Largest scene :func:`make_scene` agrees to generate (pulses); about 40 bytes per point.
MAX_PULSES = 200_000_000

# Breakline profiles: the terrace rises over an embankment TERRACE_WIDTH_M wide; the
# ditch has a flat bottom 2 * DITCH_HALF_BOTTOM_M wide and banks DITCH_BANK_M wide.
TERRACE_WIDTH_M = 1.0
DITCH_HALF_BOTTOM_M = 1.0
DITCH_BANK_M = 1.5
_BREAKLINE_HALF_WIDTH_M = (TERRACE_WIDTH_M / 2, DITCH_HALF_BOTTOM_M + DITCH_BANK_M)

GROUND_NOISE_M = 0.03
ROOF_NOISE_M = 0.03
WALL_BAND_M = 0.5        #: pulses this close outside a footprint may hit the wall ...
WALL_HIT_PROBABILITY = 0.3  #: ... with this probability
WALL_OFFSET_M = 0.05     #: wall points sit this far outside the footprint

# Echo statistics of a pulse in a tree crown: probability that the last return reaches the
# ground (0.4 at the trunk to 0.7 at the crown edge, 0.6 on average over the crown) and
# the distribution of the number of returns in the crown, with and without a ground return.
_TREE_GROUND_P0, _TREE_GROUND_P1 = 0.4, 0.3
_CROWN_RETURNS_IF_GROUND = np.array([0.5, 0.35, 0.15])        # 1, 2, 3 in the crown
_CROWN_RETURNS_IF_NO_GROUND = np.array([0.4, 0.35, 0.2, 0.05])  # 1, 2, 3, 4 in the crown
_SHRUB_GROUND_PROBABILITY = 0.4  #: where the shrub is >= 1 m high

_KIND_GROUND, _KIND_SHRUB, _KIND_TREE, _KIND_WALL, _KIND_ROOF = range(5)


# --------------------------------------------------------------------------- parameters

def _require(condition: bool, message: str) -> None:
    if not condition:
        raise InvalidParameterError(message)


def _check_real(name: str, value, *, low: float, high: float = math.inf,
                low_open: bool = False) -> None:
    _require(isinstance(value, numbers.Real) and not isinstance(value, bool),
             f"{name} must be a number (got {value!r})")
    ok = math.isfinite(value) and (value > low if low_open else value >= low) and value <= high
    if not ok:
        bound = f"> {low:g}" if low_open else f">= {low:g}"
        if high < math.inf:
            bound = f"in ({low:g}, {high:g}]" if low_open else f"in [{low:g}, {high:g}]"
        raise InvalidParameterError(f"{name} must be {bound} (got {value})")


@dataclass(frozen=True)
class SceneSpec:
    """What :func:`make_scene` generates. Object counts scale with the area, so a scene
    made bigger (or by :meth:`for_points`) keeps its character."""
    size_m: float = 200.0            #: side of the square scene
    density_per_m2: float = 10.0     #: laser pulses per m² (points are more: multiple returns)
    seed: int = 0
    buildings_per_ha: float = 2.0    #: wanted; fewer where they do not fit
    trees_per_ha: float = 15.0
    shrub_fraction: float = 0.05     #: shrub area / scene area (before overlaps)
    relief_m: float = 6.0            #: peak-to-trough height of the hills, at most
    slope_pct: float = 3.0           #: general slope of the terrain
    terrace_height_m: float = 1.5    #: step of the terrace breakline (0: none)
    ditch_depth_m: float = 1.2       #: depth of the ditch breakline (0: none)

    def __post_init__(self):
        _check_real("size_m", self.size_m, low=0, low_open=True)
        _check_real("density_per_m2", self.density_per_m2, low=0, low_open=True)
        _require(isinstance(self.seed, numbers.Integral) and not isinstance(self.seed, bool)
                 and self.seed >= 0, f"seed must be an integer >= 0 (got {self.seed!r})")
        _check_real("buildings_per_ha", self.buildings_per_ha, low=0)
        _check_real("trees_per_ha", self.trees_per_ha, low=0)
        _check_real("shrub_fraction", self.shrub_fraction, low=0, high=1)
        _check_real("relief_m", self.relief_m, low=0)
        _check_real("slope_pct", self.slope_pct, low=0, high=100)
        _check_real("terrace_height_m", self.terrace_height_m, low=0)
        _check_real("ditch_depth_m", self.ditch_depth_m, low=0)
        pulses = self.n_pulses
        _require(pulses >= 1, f"a scene of {self.size_m:g} m x {self.size_m:g} m at {self.density_per_m2:g} "
                 "pulses/m² has no pulse; make it bigger or denser")
        _require(pulses <= MAX_PULSES,
                 f"a scene of {self.size_m:g} m x {self.size_m:g} m at {self.density_per_m2:g} pulses/m² "
                 f"has {pulses:,} pulses (limit {MAX_PULSES:,}); make it smaller or sparser")

    @property
    def area_m2(self) -> float:
        return float(self.size_m) ** 2

    @property
    def n_pulses(self) -> int:
        return int(round(self.area_m2 * self.density_per_m2))

    @classmethod
    def for_points(cls, n_points: int, density_per_m2: float = 10.0, seed: int = 0, **knobs) -> "SceneSpec":
        """A spec whose scene holds about ``n_points`` points (within about 2 %).

        The size follows from the density and the returns per pulse, which depend on the
        vegetation cover: a first guess from the knobs is refined twice by measuring a
        sparse probe scene (same layout, at most 200 000 pulses; well under a second)."""
        _require(isinstance(n_points, numbers.Real) and not isinstance(n_points, bool)
                 and math.isfinite(n_points) and n_points >= 1,
                 f"n_points must be >= 1 (got {n_points!r})")
        spec = cls(size_m=1.0, density_per_m2=density_per_m2, seed=seed, **knobs)  # validates
        per_pulse = _expected_points_per_pulse(spec)
        for _ in range(2):
            size = math.sqrt(n_points / (density_per_m2 * per_pulse))
            probe = replace(spec, size_m=size, density_per_m2=min(density_per_m2, 200_000 / size ** 2))
            if probe.n_pulses < 1000:   # too small to measure; the guess will do
                break
            per_pulse = len(make_scene(probe)) / probe.n_pulses
        size = math.sqrt(n_points / (density_per_m2 * per_pulse))
        return replace(spec, size_m=size)


def _expected_points_per_pulse(spec: SceneSpec) -> float:
    """Mean returns per pulse, roughly: from the vegetation cover (a Boolean model, with a
    factor for the overlap of clustered crowns) and the echo statistics."""
    tree_cover = 1.0 - math.exp(-spec.trees_per_ha / 1e4 * _MEAN_CROWN_AREA_M2 * 0.75)
    shrub_cover = (1.0 - math.exp(-spec.shrub_fraction)) * (1.0 - tree_cover)
    p_ground = _TREE_GROUND_P0 + _TREE_GROUND_P1 * 2.0 / 3.0   # mean of d/R over a disk is 2/3
    k_ground = float(np.dot(np.arange(1, 4), _CROWN_RETURNS_IF_GROUND))
    k_no_ground = float(np.dot(np.arange(1, 5), _CROWN_RETURNS_IF_NO_GROUND))
    per_tree_pulse = p_ground * (k_ground + 1.0) + (1.0 - p_ground) * k_no_ground
    per_shrub_pulse = 1.0 + 0.4 * _SHRUB_GROUND_PROBABILITY   # ~40 % of shrub area is >= 1 m high
    return 1.0 + tree_cover * (per_tree_pulse - 1.0) + shrub_cover * (per_shrub_pulse - 1.0)


# --------------------------------------------------------------------------- terrain

@dataclass(frozen=True, eq=False)
class Terrain:
    """The true ground height of a scene. Call it with world ``x, y`` (arrays or scalars).

    Internally everything is in local metres from the scene's south-west corner."""
    origin_x: float
    origin_y: float
    size_m: float
    base_z_m: float
    gradient: Tuple[float, float]     #: (dz/dx, dz/dy) of the general slope
    wave_vectors: np.ndarray          #: (k, 2), rad/m, of the hills
    wave_amplitudes_m: np.ndarray     #: (k,)
    wave_phases: np.ndarray           #: (k,)
    terrace_point: Tuple[float, float]   #: local point on the terrace centre line
    terrace_normal: Tuple[float, float]  #: unit normal, pointing to the high side
    terrace_height_m: float
    ditch_point: Tuple[float, float]
    ditch_normal: Tuple[float, float]
    ditch_depth_m: float

    def __call__(self, x, y) -> np.ndarray:
        return self.local_z(np.asarray(x, dtype=np.float64) - self.origin_x,
                            np.asarray(y, dtype=np.float64) - self.origin_y)

    def local_z(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Ground height at local coordinates (metres from the south-west corner)."""
        c = self.size_m / 2
        uc, vc = u - c, v - c
        z = self.base_z_m + self.gradient[0] * uc + self.gradient[1] * vc
        for (kx, ky), amp, phase in zip(self.wave_vectors, self.wave_amplitudes_m, self.wave_phases):
            z = z + amp * np.cos(kx * uc + ky * vc + phase)
        if self.terrace_height_m > 0:
            s = self._signed_distance(u, v, self.terrace_point, self.terrace_normal)
            z = z + self.terrace_height_m * np.clip(s / TERRACE_WIDTH_M + 0.5, 0.0, 1.0)
        if self.ditch_depth_m > 0:
            s = np.abs(self._signed_distance(u, v, self.ditch_point, self.ditch_normal))
            z = z - self.ditch_depth_m * np.clip((DITCH_HALF_BOTTOM_M + DITCH_BANK_M - s) / DITCH_BANK_M,
                                                 0.0, 1.0)
        return z

    @staticmethod
    def _signed_distance(u, v, point, normal):
        return (u - point[0]) * normal[0] + (v - point[1]) * normal[1]

    def distance_to_breaklines(self, x, y) -> np.ndarray:
        """Horizontal distance (m) from world ``x, y`` to the nearest edge of the terrace
        embankment or the ditch (0 on them), e.g. to leave breaklines out of a DTM check."""
        return self.local_distance_to_breaklines(np.asarray(x, dtype=np.float64) - self.origin_x,
                                                 np.asarray(y, dtype=np.float64) - self.origin_y)

    def local_distance_to_breaklines(self, u, v) -> np.ndarray:
        """:meth:`distance_to_breaklines` at local coordinates. The lines are where they
        are even when their height is 0."""
        terrace = np.abs(self._signed_distance(u, v, self.terrace_point, self.terrace_normal))
        ditch = np.abs(self._signed_distance(u, v, self.ditch_point, self.ditch_normal))
        return np.maximum(np.minimum(terrace - _BREAKLINE_HALF_WIDTH_M[0], ditch - _BREAKLINE_HALF_WIDTH_M[1]),
                          0.0)


def _make_terrain(spec: SceneSpec, rng: np.random.Generator) -> Terrain:
    size = float(spec.size_m)
    aspect = rng.uniform(0, 2 * math.pi)
    gradient = (spec.slope_pct / 100 * math.cos(aspect), spec.slope_pct / 100 * math.sin(aspect))
    # Four long waves in random directions; amplitudes sum to relief_m / 2, so the hills
    # span at most relief_m from trough to crest.
    n_waves = 4
    wavelengths = rng.uniform(80.0, 250.0, n_waves)
    directions = rng.uniform(0, 2 * math.pi, n_waves)
    k = 2 * math.pi / wavelengths
    vectors = np.column_stack([k * np.cos(directions), k * np.sin(directions)])
    weights = rng.uniform(0.5, 1.0, n_waves)
    amplitudes = spec.relief_m / 2 * weights / weights.sum()
    phases = rng.uniform(0, 2 * math.pi, n_waves)
    # Breaklines through the central part of the scene, crossing at 40-140 degrees.
    terrace_angle = rng.uniform(0, math.pi)
    ditch_angle = terrace_angle + rng.uniform(math.radians(40), math.radians(140))
    terrace_point = tuple(size * rng.uniform(0.3, 0.7, 2))
    ditch_point = tuple(size * rng.uniform(0.3, 0.7, 2))
    return Terrain(
        origin_x=ORIGIN_X, origin_y=ORIGIN_Y, size_m=size, base_z_m=BASE_Z_M, gradient=gradient,
        wave_vectors=vectors, wave_amplitudes_m=amplitudes, wave_phases=phases,
        terrace_point=terrace_point,
        terrace_normal=(-math.sin(terrace_angle), math.cos(terrace_angle)),
        terrace_height_m=float(spec.terrace_height_m),
        ditch_point=ditch_point, ditch_normal=(-math.sin(ditch_angle), math.cos(ditch_angle)),
        ditch_depth_m=float(spec.ditch_depth_m))


# --------------------------------------------------------------------------- objects

@dataclass(frozen=True)
class Building:
    """One building: a rotated rectangle with a flat or gabled roof (world coordinates).
    The ridge of a gabled roof runs along the length."""
    x: float                 #: centre
    y: float
    length_m: float
    width_m: float
    angle_rad: float         #: direction of the length, counter-clockwise from east
    base_z: float            #: absolute height the walls stand on (>= the ground under the footprint)
    eave_m: float            #: eave height above base_z (the whole roof for a flat one)
    ridge_m: float           #: ridge height above base_z (== eave_m for a flat roof)
    roof: str                #: "flat" or "gabled"

    def _local(self, x, y):
        dx = np.asarray(x, dtype=np.float64) - self.x
        dy = np.asarray(y, dtype=np.float64) - self.y
        c, s = math.cos(self.angle_rad), math.sin(self.angle_rad)
        return dx * c + dy * s, -dx * s + dy * c

    def contains(self, x, y) -> np.ndarray:
        """True for world points strictly inside the footprint."""
        a, b = self._local(x, y)
        return (np.abs(a) < self.length_m / 2) & (np.abs(b) < self.width_m / 2)

    def roof_z(self, x, y) -> np.ndarray:
        """Absolute roof height at world points (NaN outside the footprint)."""
        _, b = self._local(x, y)
        z = self.base_z + _roof_height(np.abs(b), self.width_m / 2, self.eave_m, self.ridge_m)
        return np.where(self.contains(x, y), z, np.nan)


def _roof_height(abs_across, half_width, eave, ridge):
    """Roof height above the base at ``abs_across`` m from the centre line (flat: eave == ridge)."""
    return ridge - (ridge - eave) * np.minimum(abs_across / half_width, 1.0)


@dataclass(frozen=True, eq=False)
class _Buildings:
    """Buildings as arrays, in local coordinates."""
    u: np.ndarray
    v: np.ndarray
    length: np.ndarray
    width: np.ndarray
    angle: np.ndarray
    base_z: np.ndarray
    eave: np.ndarray
    ridge: np.ndarray

    @property
    def half_diagonal(self) -> np.ndarray:
        return 0.5 * np.hypot(self.length, self.width)

    def records(self) -> tuple:
        return tuple(Building(x=ORIGIN_X + float(self.u[i]), y=ORIGIN_Y + float(self.v[i]),
                              length_m=float(self.length[i]), width_m=float(self.width[i]),
                              angle_rad=float(self.angle[i]), base_z=float(self.base_z[i]),
                              eave_m=float(self.eave[i]), ridge_m=float(self.ridge[i]),
                              roof="flat" if self.eave[i] == self.ridge[i] else "gabled")
                     for i in range(self.u.size))


def _place_buildings(spec: SceneSpec, terrain: Terrain, rng: np.random.Generator) -> _Buildings:
    size = float(spec.size_m)
    wanted = int(round(spec.buildings_per_ha * spec.area_m2 / 1e4))
    n = 20 * wanted + 20  # candidates: rejection sampling, most are kept at sane densities
    width = rng.uniform(10.0, 25.0, n)               # the short side; SMRF's 18 m window still removes it
    length = rng.uniform(width, 40.0)
    angle = rng.uniform(0, math.pi, n)
    half_diag = 0.5 * np.hypot(length, width)
    u = rng.uniform(half_diag + 1, np.maximum(size - half_diag - 1, half_diag + 1))
    v = rng.uniform(half_diag + 1, np.maximum(size - half_diag - 1, half_diag + 1))
    fits = (half_diag + 1 < size - half_diag - 1) & (terrain.local_distance_to_breaklines(u, v) > half_diag + 3)
    keep = []
    for i in np.flatnonzero(fits):                   # a loop over candidate buildings, not points
        if len(keep) == wanted:
            break
        if keep and np.any(np.hypot(u[keep] - u[i], v[keep] - v[i]) < half_diag[keep] + half_diag[i] + 4):
            continue
        keep.append(int(i))
    keep = np.array(keep, dtype=np.int64)
    u, v, length, width, angle = u[keep], v[keep], length[keep], width[keep], angle[keep]
    # The walls stand on the highest ground under the footprint (sampled on a 7 x 7 grid),
    # so every roof point is at least the eave height above the true ground.
    f = np.linspace(-0.5, 0.5, 7)
    fa, fb = (g.ravel() for g in np.meshgrid(f, f))
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    sa, sb = fa[None, :] * length[:, None], fb[None, :] * width[:, None]
    base_z = terrain.local_z(u[:, None] + sa * c - sb * s, v[:, None] + sa * s + sb * c).max(axis=1) + 0.1
    m = keep.size
    flat = rng.random(m) < 0.5
    flat_height = rng.uniform(5.0, 15.0, m)
    eave = np.where(flat, flat_height, rng.uniform(5.0, 9.0, m))
    rise = np.minimum(width / 2 * np.tan(np.radians(rng.uniform(15.0, 35.0, m))), 15.0 - eave)
    ridge = np.where(flat, eave, eave + rise)
    return _Buildings(u, v, length, width, angle, base_z, eave, ridge)


@dataclass(frozen=True, eq=False)
class _Trees:
    u: np.ndarray
    v: np.ndarray
    height: np.ndarray       #: top of the crown above the ground
    radius: np.ndarray       #: crown radius
    crown_base: np.ndarray   #: bottom of the crown above the ground
    conifer: np.ndarray      #: bool: a cone-shaped crown, else an ellipsoid


def _tree_shapes(rng: np.random.Generator, n: int):
    height = rng.uniform(8.0, 25.0, n)
    radius = np.clip(3.0 + 7.0 * (height - 8.0) / 17.0 + rng.normal(0.0, 1.0, n), 3.0, 10.0)
    crown_base = height * rng.uniform(0.25, 0.5, n)
    conifer = rng.random(n) < 0.4
    return height, radius, crown_base, conifer


#: Mean crown area (m²) of the tree shapes above; used to predict the points per pulse.
_MEAN_CROWN_AREA_M2 = math.pi * float(np.mean(_tree_shapes(np.random.default_rng(12345), 20_000)[1] ** 2))


def _place_trees(spec: SceneSpec, terrain: Terrain, buildings: _Buildings,
                 rng: np.random.Generator) -> _Trees:
    size = float(spec.size_m)
    wanted = int(round(spec.trees_per_ha * spec.area_m2 / 1e4))
    n = 8 * wanted + 20
    # Half of the trees stand in groves around a few centres, the rest anywhere.
    groves = rng.uniform(0, size, (max(1, wanted // 12), 2))
    in_grove = rng.random(n) < 0.5
    pick = rng.integers(0, groves.shape[0], n)
    u = np.where(in_grove, groves[pick, 0] + rng.normal(0, 12.0, n), rng.uniform(0, size, n))
    v = np.where(in_grove, groves[pick, 1] + rng.normal(0, 12.0, n), rng.uniform(0, size, n))
    height, radius, crown_base, conifer = _tree_shapes(rng, n)
    ok = ((u >= 0) & (u <= size) & (v >= 0) & (v <= size)
          & _clear_of_buildings(u, v, radius + 1.5, buildings)
          & (terrain.local_distance_to_breaklines(u, v) > radius + 1))
    keep = np.flatnonzero(ok)[:wanted]
    return _Trees(u[keep], v[keep], height[keep], radius[keep], crown_base[keep], conifer[keep])


@dataclass(frozen=True, eq=False)
class _Shrubs:
    u: np.ndarray
    v: np.ndarray
    height: np.ndarray
    radius: np.ndarray


def _place_shrubs(spec: SceneSpec, terrain: Terrain, buildings: _Buildings,
                  rng: np.random.Generator) -> _Shrubs:
    size = float(spec.size_m)
    mean_area = math.pi * (2.0 ** 3 - 0.5 ** 3) / (3 * 1.5)   # E[pi r^2], r ~ U(0.5, 2)
    wanted = int(round(spec.shrub_fraction * spec.area_m2 / mean_area))
    n = 4 * wanted + 20
    u, v = rng.uniform(0, size, n), rng.uniform(0, size, n)
    height, radius = rng.uniform(0.3, 2.0, n), rng.uniform(0.5, 2.0, n)
    ok = (_clear_of_buildings(u, v, radius + WALL_BAND_M + 0.5, buildings)
          & (terrain.local_distance_to_breaklines(u, v) > radius + 0.5))
    keep = np.flatnonzero(ok)[:wanted]
    return _Shrubs(u[keep], v[keep], height[keep], radius[keep])


def _clear_of_buildings(u, v, margin, buildings: _Buildings) -> np.ndarray:
    """True for candidates farther than ``margin`` from every building's bounding circle."""
    ok = np.ones(u.shape, dtype=bool)
    for start in range(0, u.size, 4096):   # blocks bound the (candidates x buildings) matrix
        sl = slice(start, start + 4096)
        d = np.hypot(u[sl, None] - buildings.u[None, :], v[sl, None] - buildings.v[None, :])
        ok[sl] = np.all(d > buildings.half_diagonal[None, :] + np.asarray(margin)[sl, None], axis=1)
    return ok


# --------------------------------------------------------------------------- pulses

class _Pulses:
    """Uniformly random pulse positions, generated cell by cell on a square grid so that
    the pulses near an object are found without sorting or a tree."""

    def __init__(self, spec: SceneSpec, rng: np.random.Generator):
        size = float(spec.size_m)
        target_cell = max(1.0, math.sqrt(16.0 / spec.density_per_m2))   # ~16 pulses per cell
        self.m = max(1, int(math.ceil(size / target_cell)))
        self.cell = size / self.m
        n_cells = self.m * self.m
        self.counts = rng.multinomial(spec.n_pulses, np.full(n_cells, 1.0 / n_cells))
        self.starts = np.cumsum(self.counts) - self.counts
        cell_of = np.repeat(np.arange(n_cells, dtype=np.int64), self.counts)
        self.u = (cell_of % self.m + rng.random(cell_of.size)) * self.cell
        self.v = (cell_of // self.m + rng.random(cell_of.size)) * self.cell
        self.n = cell_of.size

    def pairs(self, cu: np.ndarray, cv: np.ndarray, reach: np.ndarray):
        """(object, pulse) index pairs of every pulse in the cells that the squares
        ``[c - reach, c + reach]`` of the objects touch (a superset of those within reach)."""
        m, cell = self.m, self.cell
        c0 = np.clip(np.floor((cu - reach) / cell), 0, m - 1).astype(np.int64)
        c1 = np.clip(np.floor((cu + reach) / cell), 0, m - 1).astype(np.int64)
        r0 = np.clip(np.floor((cv - reach) / cell), 0, m - 1).astype(np.int64)
        r1 = np.clip(np.floor((cv + reach) / cell), 0, m - 1).astype(np.int64)
        nx = c1 - c0 + 1
        obj, k = _expand(nx * (r1 - r0 + 1))
        cell_id = (r0[obj] + k // nx[obj]) * m + c0[obj] + k % nx[obj]
        counts = self.counts[cell_id]
        pair_cell, j = _expand(counts)
        return obj[pair_cell], self.starts[cell_id][pair_cell] + j


def _expand(counts: np.ndarray):
    """For counts ``[2, 0, 3]``: owners ``[0, 0, 2, 2, 2]`` and ranks ``[0, 1, 0, 1, 2]``."""
    counts = np.asarray(counts, dtype=np.int64)
    owner = np.repeat(np.arange(counts.size, dtype=np.int64), counts)
    rank = np.arange(owner.size, dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
    return owner, rank


def _highest(pulse: np.ndarray, height: np.ndarray) -> np.ndarray:
    """Indices of the pairs to keep: for every pulse, the pair with the highest surface."""
    order = np.lexsort((-height, pulse))
    p = pulse[order]
    first = np.ones(p.size, dtype=bool)
    first[1:] = p[1:] != p[:-1]
    return order[first]


# --------------------------------------------------------------------------- scene

@dataclass(frozen=True, eq=False)
class Scene:
    """A generated point cloud with its truth. Points of one pulse are consecutive, in
    return order, and share their ``gps_time`` (unique per pulse)."""
    x: np.ndarray                  #: float64, world (EPSG:32632)
    y: np.ndarray
    z: np.ndarray
    classification: np.ndarray     #: uint8 ASPRS truth: 2 ground, 3 low veg., 5 high veg., 6 building
    return_number: np.ndarray      #: uint8, 1-based
    number_of_returns: np.ndarray  #: uint8
    intensity: np.ndarray          #: uint16
    gps_time: np.ndarray           #: float64, adjusted standard GPS time
    spec: SceneSpec
    terrain: Terrain
    buildings: Tuple[Building, ...]

    def __post_init__(self):
        n = self.x.shape
        for name in ("y", "z", "classification", "return_number", "number_of_returns", "intensity",
                     "gps_time"):
            _require(getattr(self, name).shape == n, f"scene: {name} has shape "
                     f"{getattr(self, name).shape}, x has {n}")

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def xyz(self) -> np.ndarray:
        return np.column_stack([self.x, self.y, self.z])

    @property
    def ground(self) -> np.ndarray:
        """Truth ground mask (class 2)."""
        return self.classification == CLASS_GROUND

    @property
    def bounds(self) -> Tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the scene square."""
        s = float(self.spec.size_m)
        return (ORIGIN_X, ORIGIN_Y, ORIGIN_X + s, ORIGIN_Y + s)

    def ground_z(self, x, y) -> np.ndarray:
        """True terrain height at world ``x, y``."""
        return self.terrain(x, y)


def make_scene(spec: Optional[SceneSpec] = None) -> Scene:
    """Generate the scene described by ``spec`` (the default spec when None)."""
    spec = spec if spec is not None else SceneSpec()
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence(int(spec.seed)).spawn(6)]
    rng_terrain, rng_buildings, rng_trees, rng_shrubs, rng_pulses, rng_echoes = streams

    terrain = _make_terrain(spec, rng_terrain)
    buildings = _place_buildings(spec, terrain, rng_buildings)
    trees = _place_trees(spec, terrain, buildings, rng_trees)
    shrubs = _place_shrubs(spec, terrain, buildings, rng_shrubs)
    pulses = _Pulses(spec, rng_pulses)
    pu, pv = pulses.u, pulses.v  # wall pulses are moved onto their wall below

    # Per pulse: what it hits, how many returns, and two parameters whose meaning depends
    # on the kind (heights are above the local ground for vegetation, absolute otherwise).
    n = pulses.n
    kind = np.zeros(n, dtype=np.uint8)
    n_ret = np.ones(n, dtype=np.uint8)
    par_a = np.zeros(n, dtype=np.float64)
    par_b = np.zeros(n, dtype=np.float64)
    to_ground = np.zeros(n, dtype=bool)  # the last return of a multi-return pulse is on the ground
    rng = rng_echoes

    # Shrubs (lowest precedence: trees and buildings overwrite them). A dome whose edge is
    # still 40 % of the shrub height.
    if shrubs.u.size:
        obj, p = pulses.pairs(shrubs.u, shrubs.v, shrubs.radius)
        d2 = (pu[p] - shrubs.u[obj]) ** 2 + (pv[p] - shrubs.v[obj]) ** 2
        inside = d2 < shrubs.radius[obj] ** 2
        obj, p, d2 = obj[inside], p[inside], d2[inside]
        top = shrubs.height[obj] * (0.4 + 0.6 * np.sqrt(1.0 - d2 / shrubs.radius[obj] ** 2))
        sel = _highest(p, top)
        p, top = p[sel], top[sel]
        kind[p] = _KIND_SHRUB
        par_a[p] = np.maximum(top - rng.exponential(0.1, p.size), 0.1)
        two = (top >= 1.0) & (rng.random(p.size) < _SHRUB_GROUND_PROBABILITY)
        to_ground[p] = two
        n_ret[p] = 1 + two

    # Trees: the highest crown over a pulse takes it. par_a = first return, par_b = crown bottom.
    if trees.u.size:
        obj, p = pulses.pairs(trees.u, trees.v, trees.radius)
        d2 = (pu[p] - trees.u[obj]) ** 2 + (pv[p] - trees.v[obj]) ** 2
        inside = d2 < trees.radius[obj] ** 2
        obj, p = obj[inside], p[inside]
        rel = np.sqrt(d2[inside]) / trees.radius[obj]        # 0 at the trunk, 1 at the crown edge
        h, base = trees.height[obj], trees.crown_base[obj]
        half = np.sqrt(1.0 - rel * rel)
        mid, semi = 0.5 * (h + base), 0.5 * (h - base)
        conifer = trees.conifer[obj]
        top = np.where(conifer, h - (h - base) * rel, mid + semi * half)
        bottom = np.where(conifer, base, mid - semi * half)
        sel = _highest(p, top)
        p, top, bottom, rel = p[sel], top[sel], bottom[sel], rel[sel]
        kind[p] = _KIND_TREE
        par_a[p] = np.maximum(top - rng.exponential(0.3, p.size), bottom)   # first return, in the crown
        par_b[p] = bottom
        ground = rng.random(p.size) < _TREE_GROUND_P0 + _TREE_GROUND_P1 * rel
        in_crown = np.where(ground,
                            rng.choice(np.arange(1, 4), p.size, p=_CROWN_RETURNS_IF_GROUND),
                            rng.choice(np.arange(1, 5), p.size, p=_CROWN_RETURNS_IF_NO_GROUND))
        to_ground[p] = ground
        n_ret[p] = in_crown + ground

    # Buildings: roofs over the footprint; a few pulses just outside hit the wall.
    if buildings.u.size:
        obj, p = pulses.pairs(buildings.u, buildings.v, buildings.half_diagonal + WALL_BAND_M)
        cos, sin = np.cos(buildings.angle[obj]), np.sin(buildings.angle[obj])
        du, dv = pu[p] - buildings.u[obj], pv[p] - buildings.v[obj]
        a, b = du * cos + dv * sin, -du * sin + dv * cos        # along / across the ridge
        half_l, half_w = buildings.length[obj] / 2, buildings.width[obj] / 2
        outside = np.maximum(np.abs(a) - half_l, np.abs(b) - half_w)
        roof = outside < 0
        wall = (outside >= 0) & (outside < WALL_BAND_M) & (rng.random(p.size) < WALL_HIT_PROBABILITY)
        # Walls first, roofs second: a pulse cannot be on two buildings (they are >= 4 m apart).
        w, pw = obj[wall], p[wall]
        kind[pw] = _KIND_WALL
        n_ret[pw] = 1
        to_ground[pw] = False
        par_a[pw] = rng.random(pw.size)                       # where between foot and eave
        par_b[pw] = buildings.base_z[w] + buildings.eave[w]
        # Snap the wall hits onto the wall, just outside the footprint.
        aw = np.clip(a[wall], -half_l[wall] - WALL_OFFSET_M, half_l[wall] + WALL_OFFSET_M)
        bw = np.clip(b[wall], -half_w[wall] - WALL_OFFSET_M, half_w[wall] + WALL_OFFSET_M)
        pu, pv = pu.copy(), pv.copy()
        pu[pw] = buildings.u[w] + aw * cos[wall] - bw * sin[wall]
        pv[pw] = buildings.v[w] + aw * sin[wall] + bw * cos[wall]
        r, pr = obj[roof], p[roof]
        kind[pr] = _KIND_ROOF
        n_ret[pr] = 1
        to_ground[pr] = False
        par_a[pr] = buildings.base_z[r] + _roof_height(np.abs(b[roof]), half_w[roof],
                                                        buildings.eave[r], buildings.ridge[r])

    ground_z = terrain.local_z(pu, pv)

    # Expand pulses to returns: the points of pulse i are first[i], ..., first[i] + n_ret[i] - 1.
    n_points = int(n_ret.sum(dtype=np.int64))
    first = np.cumsum(n_ret, dtype=np.int64) - n_ret
    pulse_of = np.repeat(np.arange(n, dtype=np.int64), n_ret)
    return_number = (np.arange(n_points, dtype=np.int64) - first[pulse_of] + 1).astype(np.uint8)
    number_of_returns = n_ret[pulse_of]
    # Every point is a noisy ground return unless overwritten below; the last return of
    # a pulse through vegetation (to_ground) keeps this.
    z = ground_z[pulse_of] + rng.normal(0.0, GROUND_NOISE_M, n_points)
    classification = np.full(n_points, CLASS_GROUND, dtype=np.uint8)

    p = np.flatnonzero(kind == _KIND_SHRUB)                    # first return on the shrub
    z[first[p]] = ground_z[p] + par_a[p]
    classification[first[p]] = CLASS_LOW_VEGETATION

    tree = np.flatnonzero(kind == _KIND_TREE)
    crown_returns = n_ret[tree].astype(np.int64) - to_ground[tree]
    owner, j = _expand(crown_returns)                          # j: 0 for the first return
    p, crown_returns = tree[owner], crown_returns[owner]
    # Returns after the first fall in descending strata between the first return and the
    # crown bottom, so heights decrease with the return number.
    q = np.where(j == 0, 1.0, (crown_returns - 1 - j + rng.random(j.size)) / np.maximum(crown_returns - 1, 1))
    z[first[p] + j] = ground_z[p] + par_b[p] + (par_a[p] - par_b[p]) * q
    classification[first[p] + j] = CLASS_HIGH_VEGETATION

    p = np.flatnonzero(kind == _KIND_WALL)                     # between the foot and the eave
    z[first[p]] = ground_z[p] + 0.3 + par_a[p] * np.maximum(par_b[p] - ground_z[p] - 0.3, 0.0)
    classification[first[p]] = CLASS_BUILDING

    p = np.flatnonzero(kind == _KIND_ROOF)
    z[first[p]] = par_a[p] + rng.normal(0.0, ROOF_NOISE_M, p.size)
    classification[first[p]] = CLASS_BUILDING

    # Intensity: a level per class, lower when the pulse energy is split between returns, 20 % noise.
    level = np.array([0, 0, 1200, 800, 0, 700, 1600], dtype=np.float64)[classification]
    intensity = level / np.sqrt(number_of_returns) * (1.0 + 0.2 * rng.standard_normal(n_points))
    intensity = np.clip(np.rint(intensity), 1, 65535).astype(np.uint16)

    gps_time = GPS_TIME_START_S + pulse_of / PULSE_RATE_HZ
    return Scene(x=(pu + ORIGIN_X)[pulse_of], y=(pv + ORIGIN_Y)[pulse_of], z=z, classification=classification,
                 return_number=return_number, number_of_returns=number_of_returns,
                 intensity=intensity, gps_time=gps_time, spec=spec, terrain=terrain,
                 buildings=buildings.records())


# --------------------------------------------------------------------------- output

def photogrammetric(scene: Scene, noise_m: float = 0.03) -> Scene:
    """The surface image matching sees of ``scene``: the first return of each pulse only (no ground
    under vegetation), ``noise_m`` of Gaussian matching noise on z (seeded by the scene's seed), one
    return per point and no GPS time, the truth kept in ``classification`` (UAV photogrammetry as in
    fan2023; bench/presets.py's ``uav-photo`` scenes)."""
    top = scene.return_number == 1
    n = int(top.sum())
    z = scene.z[top] + np.random.default_rng(int(scene.spec.seed)).normal(0.0, float(noise_m), n)
    one = np.ones(n, dtype=np.uint8)
    return Scene(scene.x[top], scene.y[top], z, scene.classification[top], one, one.copy(),
                 scene.intensity[top], np.zeros(n), scene.spec, scene.terrain, scene.buildings)


def with_low_blunders(scene: Scene, clusters_per_ha: float, *, depth_m=(0.5, 4.0), per_cluster: int = 5) -> Scene:
    """``scene`` with image-matching blunders below the surface: ``clusters_per_ha`` clusters of
    ``per_cluster`` points each, 0.1 m apart around a point of the scene and ``depth_m`` (uniform)
    below it, truth class 7 (low noise), seeded by the scene's seed. Photogrammetric clouds hold such
    points (ODM, Metashape), and a handful of them made SMRF's defaults lose most of the ground of a
    dense cloud (a UAV reviewer: 370 of 800,000 points, 96 % of the ground lost)."""
    rng = np.random.default_rng(int(scene.spec.seed) + 7)
    n = len(scene)
    area_ha = float(np.ptp(scene.x)) * float(np.ptp(scene.y)) / 1e4 if n else 0.0
    count = min(int(round(clusters_per_ha * area_ha)), n)
    at = np.repeat(rng.choice(n, count, replace=False), per_cluster)
    m = at.size
    one = np.ones(m, dtype=np.uint8)
    return Scene(np.r_[scene.x, scene.x[at] + rng.normal(0.0, 0.1, m)],
                 np.r_[scene.y, scene.y[at] + rng.normal(0.0, 0.1, m)],
                 np.r_[scene.z, scene.z[at] - rng.uniform(depth_m[0], depth_m[1], m)],
                 np.r_[scene.classification, np.full(m, 7, np.uint8)],
                 np.r_[scene.return_number, one], np.r_[scene.number_of_returns, one],
                 np.r_[scene.intensity, scene.intensity[at]], np.r_[scene.gps_time, scene.gps_time[at]],
                 scene.spec, scene.terrain, scene.buildings)


def scene_crs_wkt() -> str:
    """WKT of EPSG:32632 (WGS 84 / UTM zone 32N), the coordinate system of every scene."""
    import pyproj
    return pyproj.CRS.from_epsg(EPSG).to_wkt()


def write_scene(scene: Scene, path, *, crs_wkt: Optional[str] = None) -> None:
    """Write ``scene`` as LAS 1.2 point format 1 (LAZ when ``path`` ends in .laz), with the
    truth in ``classification``. ``crs_wkt`` defaults to EPSG:32632; pass ``""`` to
    write no CRS."""
    import laspy
    if crs_wkt is None:
        crs_wkt = scene_crs_wkt()
    # 1 mm steps while the coordinates fit in the int32 records of LAS, else 1 cm.
    extent = max(float(np.ptp(scene.x)), float(np.ptp(scene.y)), float(np.ptp(scene.z))) if len(scene) else 0.0
    scale = 0.001 if extent < 2000.0 else 0.01
    las = new_las(scene.x, scene.y, scene.z, point_format=1, version="1.2", scale=scale,
                  crs_wkt=crs_wkt or None, classification=scene.classification,
                  return_number=scene.return_number, number_of_returns=scene.number_of_returns,
                  intensity=scene.intensity, gps_time=scene.gps_time)
    las.header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
    write_las(las, path)
