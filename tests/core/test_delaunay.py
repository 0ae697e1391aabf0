"""The numba sweep-hull Delaunay triangulation (core.grids.triangulate.delaunay) against its
definition and against scipy's qhull, and the TIN DTM made with either."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull, Delaunay, cKDTree

from groundsieve.core.errors import InvalidParameterError
from groundsieve.core.grids.rasterize import tin_dtm
from groundsieve.core.grids.spec import GridSpec
from groundsieve.core.grids.triangulate import delaunay

X0, Y0 = 512000.0, 5403000.0


def scene(kind, seed=0):
    """Point positions of a few kinds, in projected coordinates far from the origin."""
    rng = np.random.default_rng(seed)
    if kind == "random":
        x, y = rng.uniform(0, 200, 4000), rng.uniform(0, 150, 4000)
    elif kind == "grid":  # every square's four corners are cocircular
        X, Y = np.meshgrid(np.arange(50) * 0.5, np.arange(40) * 0.5)
        x, y = X.ravel(), Y.ravel()
    elif kind == "jittered_grid":  # thin_for_grid output looks like this
        X, Y = np.meshgrid(np.arange(60) * 0.25, np.arange(50) * 0.25)
        x = X.ravel() + rng.uniform(-0.05, 0.05, X.size)
        y = Y.ravel() + rng.uniform(-0.05, 0.05, X.size)
    elif kind == "clustered":
        centres = rng.uniform(0, 1000, (15, 2))
        p = centres[rng.integers(0, 15, 4000)] + rng.normal(0, 1.5, (4000, 2))
        x, y = p[:, 0], p[:, 1]
    elif kind == "circle":  # all cocircular, plus the centre
        a = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        x, y = np.r_[10 * np.cos(a), 0.0], np.r_[10 * np.sin(a), 0.0]
    else:
        raise ValueError(kind)
    xy = np.unique(np.column_stack([x + X0, y + Y0]), axis=0)  # distinct positions
    perm = rng.permutation(len(xy))
    return xy[perm, 0], xy[perm, 1]


def doubled_areas(x, y, tri):
    xa, ya = x[tri[:, 0]], y[tri[:, 0]]
    return ((x[tri[:, 1]] - xa) * (y[tri[:, 2]] - ya) - (y[tri[:, 1]] - ya) * (x[tri[:, 2]] - xa))


KINDS = ["random", "grid", "jittered_grid", "clustered", "circle"]


@pytest.mark.parametrize("kind", KINDS)
def test_triangulation_is_delaunay(kind):
    x, y = scene(kind)
    rx, ry = x - x.min(), y - y.min()
    tri = delaunay(x, y)
    assert tri.dtype == np.int64 and tri.ndim == 2 and tri.shape[1] == 3
    # Each triangle counter-clockwise and not flat.
    area2 = doubled_areas(rx, ry, tri)
    assert (area2 > 0).all()
    # Every point is a vertex, and the triangles tile the convex hull once: 2n - h - 2 of
    # them (h = points on the hull boundary, collinear ones included) and hull area.
    assert np.array_equal(np.unique(tri), np.arange(x.size))
    hull = ConvexHull(np.column_stack([rx, ry]))
    assert area2.sum() / 2 == pytest.approx(hull.volume, rel=1e-12)
    # Points on the hull boundary, vertices or not.
    eq = hull.equations
    on_hull = (np.abs(np.column_stack([rx, ry]) @ eq[:, :2].T + eq[:, 2]) < 1e-9).any(axis=1)
    assert tri.shape[0] == 2 * x.size - on_hull.sum() - 2
    assert tri.shape[0] == Delaunay(np.column_stack([rx, ry])).simplices.shape[0]
    # Each interior edge shared by exactly two triangles, in opposite directions.
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    assert np.unique(edges, axis=0).shape[0] == edges.shape[0]
    # Empty circumcircles: no point strictly inside any triangle's circumcircle.
    a, b, c = (np.column_stack([rx[tri[:, k]], ry[tri[:, k]]]) for k in range(3))
    bb, cc = b - a, c - a
    d = 2 * (bb[:, 0] * cc[:, 1] - bb[:, 1] * cc[:, 0])
    ux = (cc[:, 1] * (bb ** 2).sum(1) - bb[:, 1] * (cc ** 2).sum(1)) / d
    uy = (bb[:, 0] * (cc ** 2).sum(1) - cc[:, 0] * (bb ** 2).sum(1)) / d
    centre = a + np.column_stack([ux, uy])
    radius = np.hypot(ux, uy)
    tree = cKDTree(np.column_stack([rx, ry]))
    nearest, _ = tree.query(centre)
    assert (nearest >= radius * (1 - 1e-9) - 1e-9).all()


def test_the_check_above_catches_a_non_delaunay_triangulation():
    """The empty-circumcircle check fails on a triangulation with a bad diagonal."""
    rx = np.array([0.0, 4.0, 4.0, 0.0])
    ry = np.array([0.0, 0.0, 1.0, 1.5])
    good = delaunay(rx, ry)
    flipped = np.array([[0, 1, 3], [1, 2, 3]]) if {0, 2} <= set(good[0]) & set(good[1]) \
        else np.array([[0, 1, 2], [0, 2, 3]])
    for tri, ok in ((good, True), (flipped, False)):
        a, b, c = (np.column_stack([rx[tri[:, k]], ry[tri[:, k]]]) for k in range(3))
        bb, cc = b - a, c - a
        d = 2 * (bb[:, 0] * cc[:, 1] - bb[:, 1] * cc[:, 0])
        ux = (cc[:, 1] * (bb ** 2).sum(1) - bb[:, 1] * (cc ** 2).sum(1)) / d
        uy = (bb[:, 0] * (cc ** 2).sum(1) - cc[:, 0] * (bb ** 2).sum(1)) / d
        nearest, _ = cKDTree(np.column_stack([rx, ry])).query(a + np.column_stack([ux, uy]))
        assert (nearest >= np.hypot(ux, uy) * (1 - 1e-9) - 1e-9).all() == ok


def test_same_triangles_as_qhull_where_unique():
    x, y = scene("random", seed=3)
    ours = np.sort(np.sort(delaunay(x, y), axis=1), axis=0)
    theirs = np.sort(np.sort(delaunay(x, y, method="qhull"), axis=1), axis=0)
    ours = ours[np.lexsort(ours.T[::-1])]
    theirs = theirs[np.lexsort(theirs.T[::-1])]
    np.testing.assert_array_equal(ours, theirs)


@pytest.mark.parametrize("n", [0, 1, 2])
def test_fewer_than_three_points_no_triangle(n):
    assert delaunay(np.arange(n, dtype=float), np.zeros(n)).shape == (0, 3)


@pytest.mark.parametrize("method", ["sweep", "qhull"])
def test_collinear_points_no_triangle(method):
    t = np.arange(200.0)
    assert delaunay(X0 + 0.5 * t, Y0 - 0.25 * t, method=method).shape == (0, 3)


def test_rounded_collinear_points_give_valid_slivers():
    """Points on a line only up to rounding (0.7 m steps at 512 km) are not collinear to
    either triangulator: they get slivers of rounding width, all counter-clockwise and none
    overlapping. (The sweep skips the points its orientation test finds on the hull's line:
    they lie on the slivers' edges to rounding, so the surface does not change.)"""
    t = np.arange(200.0)
    x, y = X0 + 0.7 * t, Y0 - 0.3 * t
    for method in ("sweep", "qhull"):
        tri = delaunay(x, y, method=method)
        area2 = doubled_areas(x - x.min(), y - y.min(), tri)
        assert (area2 > 0).all() and area2.sum() / 2 < 1e-6
        edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        assert np.unique(edges, axis=0).shape[0] == edges.shape[0]


def test_nearly_collinear_points():
    """One point off a long line: a fan of flat-ish but valid triangles."""
    t = np.arange(100.0)
    x, y = np.r_[t, 50.0], np.r_[np.zeros(100), 1e-3]
    tri = delaunay(x + X0, y + Y0)
    assert tri.shape[0] == 99
    assert (doubled_areas(x, y, tri) > 0).all()


def test_unknown_method_is_refused():
    with pytest.raises(InvalidParameterError, match="triangulator"):
        delaunay(np.arange(3.0), np.arange(3.0) ** 2, method="bowyer")


def surface(x, y):
    return 250 + 3 * np.sin((x - X0) / 7) + 2 * np.cos((y - Y0) / 5) + 0.01 * (x - X0)


@pytest.mark.parametrize("ppc", [4, 0])
def test_tin_dtm_equals_qhull_one_on_random_points(ppc):
    """Unique triangulation (random points): the same raster to 1e-9 m, NaN at the same cells."""
    x, y = scene("random", seed=5)
    z = surface(x, y)
    grid = GridSpec.covering(x, y, 0.5)
    ours = tin_dtm(x, y, z, grid, points_per_cell=ppc)
    theirs = tin_dtm(x, y, z, grid, points_per_cell=ppc, triangulator="qhull")
    assert np.array_equal(np.isnan(ours), np.isnan(theirs))
    assert np.isfinite(ours).mean() > 0.9
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9, equal_nan=True)


def test_tin_dtm_on_a_grid_within_each_quads_height_range():
    """Gridded points: each square's diagonal may differ between the two triangulations; a
    cell centre then lies in the same square and both values are within its corners' range."""
    step = 1.0
    X, Y = np.meshgrid(X0 + np.arange(40) * step, Y0 + np.arange(30) * step)
    x, y = X.ravel(), Y.ravel()
    z = surface(x, y)
    grid = GridSpec.covering(x, y, 0.3)
    ours = tin_dtm(x, y, z, grid, points_per_cell=0)
    theirs = tin_dtm(x, y, z, grid, points_per_cell=0, triangulator="qhull")
    assert np.array_equal(np.isnan(ours), np.isnan(theirs))
    Z = z.reshape(X.shape)
    cx, cy = np.meshgrid(*grid.centers())
    inside = np.isfinite(ours)
    i = np.clip(np.floor((cy - Y0) / step).astype(int), 0, Z.shape[0] - 2)
    j = np.clip(np.floor((cx - X0) / step).astype(int), 0, Z.shape[1] - 2)
    corners = np.stack([Z[i, j], Z[i + 1, j], Z[i, j + 1], Z[i + 1, j + 1]])
    lo, hi = corners.min(0) - 1e-9, corners.max(0) + 1e-9
    for dtm in (ours, theirs):
        assert ((dtm[inside] >= lo[inside]) & (dtm[inside] <= hi[inside])).all()
    # The difference is bounded by the square's height range, and is zero on most cells.
    diff = np.abs(ours - theirs)[inside]
    assert (diff <= (hi - lo)[inside]).all()


def test_tin_dtm_unknown_triangulator_is_refused():
    x, y = scene("random")
    grid = GridSpec.covering(x, y, 1.0)
    with pytest.raises(InvalidParameterError, match="triangulator"):
        tin_dtm(x, y, surface(x, y), grid, triangulator="delaunator")


@pytest.mark.parametrize("kind", ["random", "ties", "skewed", "outlier"])
def test_bucket_sort_orders_like_a_stable_sort(kind):
    from groundsieve.core.grids._delaunay import _sort_by_distance
    rng = np.random.default_rng(7)
    d = {"random": rng.uniform(0, 50, 5000),
         "ties": rng.integers(0, 30, 5000).astype(float),   # many equal keys, and zeros
         "skewed": rng.exponential(1.0, 5000) ** 4,            # most in the first buckets
         "outlier": np.r_[rng.uniform(0, 1, 4999), 1e9]}[kind]  # all but one in bucket 0
    np.testing.assert_array_equal(_sort_by_distance(d), np.argsort(d, kind="stable"))


@pytest.mark.parametrize("kind", KINDS)
def test_flip_stack_grows_instead_of_dropping_edges(kind):
    """The flip stack used to be capped at 1024 edges, dropping the rest silently. It now starts at
    ``stack_size`` and doubles: started at 1 (so every chain of two pending flips overflows it, the
    path the old cap took), the triangles are exactly those of the default and still Delaunay."""
    from groundsieve.core.grids._delaunay import delaunay_kernel
    x, y = scene(kind, seed=5)
    rx, ry = np.ascontiguousarray(x - x.min()), np.ascontiguousarray(y - y.min())
    default = delaunay_kernel(rx, ry)
    for size in (1, 2, 3):
        np.testing.assert_array_equal(delaunay_kernel(rx, ry, size), default)
    # and empty circumcircles (checked on the random scene, where the triangulation is unique)
    if kind == "random":
        theirs = np.sort(np.sort(delaunay(x, y, method="qhull"), axis=1), axis=0)
        ours = np.sort(np.sort(delaunay_kernel(rx, ry, 1), axis=1), axis=0)
        np.testing.assert_array_equal(ours[np.lexsort(ours.T[::-1])], theirs[np.lexsort(theirs.T[::-1])])
