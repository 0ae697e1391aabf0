"""Per-point geometric features of the local neighbourhood, for classification
(Matrone et al. 2024, Method 3: verticality 0.6 m, planarity 0.6 m, eigenentropy 0.4 m and
surface variation 0.6 m, after Weinmann et al. 2015).

Neighbourhoods
--------------
*Sphere features* use the points within the 3D distance ``radius`` of the point, **the point
itself included** (``k`` points); *column features* the points within the horizontal distance
``radius`` (a vertical cylinder of unbounded height), the point included.

Eigen features
--------------
``C`` is the covariance of the ``k`` points of the sphere (divided by ``k``, about their own
centroid), ``λ1 >= λ2 >= λ3 >= 0`` its eigenvalues and ``e_i = λ_i / (λ1 + λ2 + λ3)`` the
normalised eigenvalues, as in Weinmann et al. (2015):

=====================  =======================================  ==================
feature                value                                    range
=====================  =======================================  ==================
``linearity``          (e1 - e2) / e1                           [0, 1]
``planarity``          (e2 - e3) / e1                           [0, 1]
``sphericity``         e3 / e1                                  [0, 1]
``anisotropy``         (e1 - e3) / e1                           [0, 1]
``omnivariance``       (e1 e2 e3)^(1/3)                         [0, 1/3]
``eigenentropy``       -(e1 ln e1 + e2 ln e2 + e3 ln e3)        [0, ln 3]; 0 ln 0 = 0
``surface_variation``  e3 / (e1 + e2 + e3) = e3                 [0, 1/3]
``verticality``        1 - |n_z|, n the unit eigenvector of λ3  [0, 1]
``eigenvalue_sum``     λ1 + λ2 + λ3 (m², not normalised)        >= 0
=====================  =======================================  ==================

The ratios (linearity, planarity, sphericity, anisotropy, surface variation) and verticality are
also those of CloudCompare (CCCoreLib ``Neighbourhood::computeFeature``, covariance divided by
``k``, NaN below 3 points) and of jakteristics (covariance divided by ``k - 1``). Both of these
compute omnivariance and eigenentropy from the raw eigenvalues λ (m²) instead of ``e``: those two
features (only) differ in value from theirs; ours do not depend on the unit or on the radius.

Other features: ``density`` = k / (4/3 π r³), points per m³ in the sphere (the point
included, so never 0); ``height_above_min`` = z minus the lowest z in the vertical column
of radius ``r`` around the point (>= 0).

Points whose sphere holds fewer than :data:`MIN_POINTS` = 3 points (the point included, as
CloudCompare) get NaN for every eigen feature, and so do points whose sphere holds only
coincident points (no shape, no normal; ``eigenvalue_sum`` is then 0). For a perfectly
collinear sphere the normal (hence verticality) is one arbitrary perpendicular of the line.

Names
-----
A feature at a radius is named ``<feature>_r<radius>``, the radius in metres (the unit of the
cloud's CRS) with ``p`` as the decimal mark and no trailing zeros, e.g. ``verticality_r0p6``,
``eigenentropy_r0p4``, ``height_above_min_r2p5``, ``density_r1``. The dot is avoided because
PDAL (which QGIS uses to index LAS/LAZ) and its expressions accept only letters, digits and
underscores in dimension names; every name fits the 32 characters of a LAS extra-bytes name.
:func:`parse_feature_name` reads a name back.

Speed: one pass over the points per distinct radius (all features at that radius share the
covariance sums), in numba kernels run in parallel (see ``_features_kernels``).
"""
from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import numpy as np

from ..errors import InvalidParameterError
from ..progress import Steps
from ..validate import validate_xyz


#: Features of the eigenvalues of the covariance in a sphere.
EIGEN_FEATURES = ("linearity", "planarity", "sphericity", "omnivariance", "anisotropy", "eigenentropy",
                  "surface_variation", "verticality", "eigenvalue_sum")
#: Features of a sphere of ``radius``.
SPHERE_FEATURES = EIGEN_FEATURES + ("density",)
#: Features of a vertical column of ``radius``.
COLUMN_FEATURES = ("height_above_min",)
FEATURES = SPHERE_FEATURES + COLUMN_FEATURES

#: The features of Matrone et al. (2024) at their radii (m).
PAPER_FEATURES = (("verticality", 0.6), ("planarity", 0.6), ("eigenentropy", 0.4), ("surface_variation", 0.6))

#: Fewest points (the point included) a sphere needs for the eigen features; fewer give NaN.
MIN_POINTS = 3
#: Smallest radius accepted (m): names carry the radius to 1e-6 m, and a smaller sphere is below
#: the usual coordinate resolution of LAS files (0.01-0.001 m).
MIN_RADIUS_M = 0.001
#: Longest name of a LAS extra-bytes dimension.
MAX_NAME_LENGTH = 32

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_FEATURE_NAME_RE = re.compile(r"^(?P<feature>[a-z_]+)_r(?P<int>[0-9]+)(?:p(?P<frac>[0-9]+))?$")


def radius_text(radius: float) -> str:
    """The radius as it appears in feature names: 0.6 -> ``0p6``, 2.5 -> ``2p5``, 1.0 -> ``1``."""
    text = f"{float(radius):.6f}".rstrip("0").rstrip(".")
    return text.replace(".", "p")


def feature_name(feature: str, radius: float) -> str:
    """``<feature>_r<radius>``, e.g. ``feature_name("planarity", 0.6) == "planarity_r0p6"``."""
    return f"{feature}_r{radius_text(radius)}"


def canonical_name(name: str) -> str:
    """``name`` as :func:`feature_name` writes it when it names a feature of a radius (``planarity_r2p0`` ->
    ``planarity_r2``), else as it is."""
    try:
        return feature_name(*parse_feature_name(name))
    except InvalidParameterError:
        return name


def parse_feature_name(name: str) -> Tuple[str, float]:
    """(feature, radius) of a name made by :func:`feature_name`; InvalidParameterError otherwise."""
    match = _FEATURE_NAME_RE.match(str(name))
    if not match or match.group("feature") not in FEATURES:
        raise InvalidParameterError(
            f"'{name}' is not a feature name: expected <feature>_r<radius> (e.g. planarity_r0p6) with "
            f"<feature> one of {', '.join(FEATURES)}")
    radius = float(match.group("int") + "." + (match.group("frac") or "0"))
    return match.group("feature"), radius


@dataclass(frozen=True)
class FeatureSpec:
    """Which features, each at which radius (m): ``features`` is a tuple of
    ``(feature, radius)`` pairs (a mapping ``{feature: radius}`` is accepted too); the same
    feature may come at several radii. Defaults: the paper's four features and radii."""
    features: Tuple[Tuple[str, float], ...] = PAPER_FEATURES

    def __post_init__(self):
        items = self.features
        if isinstance(items, Mapping):
            items = tuple(items.items())
        if isinstance(items, (str, bytes)) or not hasattr(items, "__iter__"):
            raise InvalidParameterError(f"features must be (feature, radius) pairs (got {items!r})")
        pairs = []
        for item in items:
            if isinstance(item, (str, bytes)) or not hasattr(item, "__len__") or len(item) != 2:
                raise InvalidParameterError(
                    f"features must be (feature, radius) pairs (got {item!r}); e.g. ('planarity', 0.6)")
            feature, radius = item
            if feature not in FEATURES:
                raise InvalidParameterError(f"unknown feature {feature!r}; expected one of {', '.join(FEATURES)}")
            if isinstance(radius, bool) or not isinstance(radius, (int, float, np.integer, np.floating)):
                raise InvalidParameterError(f"{feature} radius must be a number in m (got {radius!r})")
            radius = float(radius)
            if not (math.isfinite(radius) and radius >= MIN_RADIUS_M):
                raise InvalidParameterError(f"{feature} radius must be at least {MIN_RADIUS_M} m (got {radius:g})")
            pairs.append((feature, radius))
        if not pairs:
            raise InvalidParameterError("no feature asked: give at least one (feature, radius)")
        seen = {}
        for feature, radius in pairs:
            name = feature_name(feature, radius)
            if len(name) > MAX_NAME_LENGTH:
                raise InvalidParameterError(f"{feature} radius {radius:g} m makes the name {name} longer than "
                                            f"the {MAX_NAME_LENGTH} characters of a LAS dimension")
            if name in seen:
                raise InvalidParameterError(
                    f"{name} asked twice ({feature} at {seen[name]:g} m and {radius:g} m); radii must differ "
                    "by at least 1e-6 m")
            seen[name] = radius
        object.__setattr__(self, "features", tuple(pairs))

    @classmethod
    def from_names(cls, names) -> "FeatureSpec":
        """The spec computing the features named ``names`` (e.g. a trained model's list)."""
        if isinstance(names, str):
            names = [n for n in (s.strip() for s in names.split(",")) if n]
        return cls(tuple(parse_feature_name(n) for n in names))

    @property
    def names(self) -> Tuple[str, ...]:
        """The output names, in the order of ``features``."""
        return tuple(feature_name(f, r) for f, r in self.features)

    def sphere_passes(self) -> Dict[float, list]:
        """{radius: [(feature, name), ...]} of the sphere features: one pass each."""
        passes: Dict[float, list] = {}
        for feature, radius in self.features:
            if feature in SPHERE_FEATURES:
                passes.setdefault(radius, []).append((feature, feature_name(feature, radius)))
        return passes

    def column_passes(self) -> Dict[float, list]:
        passes: Dict[float, list] = {}
        for feature, radius in self.features:
            if feature in COLUMN_FEATURES:
                passes.setdefault(radius, []).append((feature, feature_name(feature, radius)))
        return passes


# --------------------------------------------------------------------------- computation

def _columns(xr: np.ndarray, yr: np.ndarray, z: np.ndarray, cell: float):
    """Sort the points by (column of ``cell``, z). ``xr``, ``yr`` are >= 0 (relative to the
    minimum). Returns order, sorted x, y, z, the start of each occupied column's run (plus n),
    the sorted keys of the occupied columns, a dense key -> column lookup when the grid is small
    (else an empty array) and the grid's numbers of columns and rows ``nx``, ``ny``."""
    ix = np.floor(xr / cell).astype(np.int64)
    iy = np.floor(yr / cell).astype(np.int64)
    nx, ny = int(ix.max()) + 1, int(iy.max()) + 1
    if nx * ny >= 2 ** 62:
        raise InvalidParameterError(
            f"a radius of {cell:g} m is too small for a cloud {xr.max():.3g} x {yr.max():.3g} m wide")
    key = ix * ny + iy
    del ix, iy
    order = np.lexsort((z, key))
    skey = key[order]
    del key
    breaks = np.flatnonzero(skey[1:] != skey[:-1]) + 1
    starts = np.concatenate([[0], breaks, [skey.shape[0]]]).astype(np.int64)
    ukeys = np.ascontiguousarray(skey[starts[:-1]])
    if nx * ny <= max(4 * xr.shape[0], 1 << 20):
        lookup = np.full(nx * ny, -1, dtype=np.int64)  # dense: one lookup per neighbour column
        lookup[ukeys] = np.arange(ukeys.shape[0], dtype=np.int64)
    else:
        lookup = np.empty(0, dtype=np.int64)  # sparse: binary search in ukeys
    return (order.astype(np.int64), np.ascontiguousarray(xr[order]), np.ascontiguousarray(yr[order]),
            np.ascontiguousarray(z[order]), starts, ukeys, lookup, nx, ny)


def _threads() -> int:
    import numba
    return int(numba.get_num_threads())


def _run_in_chunks(kernel, args: tuple, out: np.ndarray, n_columns: int, steps: Steps) -> None:
    """Call ``kernel(*args, c0, c1, ntasks, out)`` on slices ``c0:c1`` of the columns,
    reporting progress and honouring cancellation between slices."""
    ntasks = 8 * _threads()
    nchunks = max(1, min(n_columns // 4096, 32))
    bounds = np.linspace(0, n_columns, nchunks + 1).astype(np.int64)
    for i in range(nchunks):
        kernel(*args, int(bounds[i]), int(bounds[i + 1]), ntasks, out)
        steps.report((i + 1) / nchunks)


#: Cells per radius in the neighbour search (1: 3 x 3 columns of the radius; 2: 5 x 5 of half).
_SPHERE_SPLIT = 1
_COLUMN_SPLIT = 2


def compute_features(xyz: np.ndarray, spec: FeatureSpec = FeatureSpec(), *,
                     steps: Optional[Steps] = None) -> Dict[str, np.ndarray]:
    """The features of ``spec`` for every point of ``xyz`` (n, 3): ``{name: float32 (n,)}``
    in the order of ``spec.names`` (see the module's documentation for the definitions)."""
    from . import _features_kernels as K
    if not isinstance(spec, FeatureSpec):
        raise InvalidParameterError(f"spec must be a FeatureSpec (got {type(spec).__name__})")
    steps = steps or Steps()
    xyz = validate_xyz(xyz)
    n = xyz.shape[0]
    xr = xyz[:, 0] - xyz[:, 0].min()
    yr = xyz[:, 1] - xyz[:, 1].min()
    z = np.ascontiguousarray(xyz[:, 2])
    del xyz
    sphere, column = spec.sphere_passes(), spec.column_passes()
    npasses = len(sphere) + len(column)
    results: Dict[str, np.ndarray] = {}
    done = 0
    for radius, wanted in sphere.items():
        sub = steps.sub(done / npasses, (done + 1) / npasses)
        cell = radius / _SPHERE_SPLIT
        order, xs, ys, zs, starts, ukeys, lookup, nx, ny = _columns(xr, yr, z, cell)
        sub.report(0.1)
        rows = np.full(K.N_SPHERE, -1, dtype=np.int64)
        for i, (feature, _name) in enumerate(wanted):
            rows[SPHERE_FEATURES.index(feature)] = i
        out = np.empty((len(wanted), n), dtype=np.float32)
        _run_in_chunks(K._sphere_features_kernel,
                       (xs, ys, zs, order, starts, ukeys, lookup, nx, ny, cell, _SPHERE_SPLIT, radius, rows),
                       out, ukeys.shape[0], sub.sub(0.1, 1.0))
        for i, (_feature, name) in enumerate(wanted):
            results[name] = out[i]
        done += 1
    for radius, wanted in column.items():
        sub = steps.sub(done / npasses, (done + 1) / npasses)
        cell = radius / _COLUMN_SPLIT
        order, xs, ys, zs, starts, ukeys, lookup, nx, ny = _columns(xr, yr, z, cell)
        sub.report(0.1)
        height = np.empty(n, dtype=np.float32)
        _run_in_chunks(K._column_min_kernel,
                       (xs, ys, zs, order, starts, ukeys, lookup, nx, ny, cell, _COLUMN_SPLIT, radius),
                       height, ukeys.shape[0], sub.sub(0.1, 1.0))
        for _feature, name in wanted:
            results[name] = height
        done += 1
    steps.report(1.0)
    return {name: results[name] for name in spec.names}
