"""Per-point geometric features (core.learn.features): against a numpy oracle (cKDTree neighbours,
np.linalg.eigh) on random clouds, on shapes with known values (plane, wall, line, ball, column,
lattice), points with too few neighbours, names, validation, progress and cancellation, and
the LAS/LAZ round trip with the features as extra bytes."""
from __future__ import annotations

import hashlib
import math

import laspy
import numpy as np
import pytest
from scipy.spatial import cKDTree

from groundsieve.core.learn import _features_kernels as K
from groundsieve.core.errors import Cancelled, InputError, InvalidParameterError, OutputError
from groundsieve.core.engine.features_run import run_features, write_features
from groundsieve.core.learn.features import (COLUMN_FEATURES, EIGEN_FEATURES, FEATURES, MIN_POINTS,
                                             PAPER_FEATURES, SPHERE_FEATURES, FeatureSpec, compute_features,
                                             feature_name, parse_feature_name, radius_text)
from groundsieve.core.io import new_las, read_cloud, write_las
from groundsieve.core.progress import Steps

X0, Y0, Z0 = 512000.0, 5403000.0, 250.0  # UTM-sized coordinates, as real data


# --------------------------------------------------------------------------- the oracle

def oracle(xyz: np.ndarray, feature: str, radius: float) -> np.ndarray:
    """The feature by brute force: cKDTree neighbours, np.cov (divided by k), np.linalg.eigh."""
    out = np.full(len(xyz), np.nan)
    if feature == "height_above_min":
        tree = cKDTree(xyz[:, :2])
        for i, nb in enumerate(tree.query_ball_point(xyz[:, :2], radius)):
            out[i] = xyz[i, 2] - xyz[nb, 2].min()
        return out
    tree = cKDTree(xyz)
    for i, nb in enumerate(tree.query_ball_point(xyz, radius)):
        k = len(nb)
        if feature == "density":
            out[i] = k / (4.0 / 3.0 * math.pi * radius ** 3)
            continue
        if k < 3:
            continue
        cov = np.cov(xyz[nb].T, bias=True)
        w, v = np.linalg.eigh(cov)  # ascending
        if k == 3:
            w[0] = 0.0  # three points are coplanar (as documented: no rounding noise in the cube root)
        if feature == "eigenvalue_sum":
            out[i] = w.sum()
            continue
        w = np.clip(w, 0.0, None)
        e3, e2, e1 = w / w.sum()
        ent = -sum(e * math.log(e) for e in (e1, e2, e3) if e > 0)
        out[i] = {"linearity": (e1 - e2) / e1, "planarity": (e2 - e3) / e1, "sphericity": e3 / e1,
                  "anisotropy": (e1 - e3) / e1, "omnivariance": (e1 * e2 * e3) ** (1 / 3),
                  "eigenentropy": ent, "surface_variation": e3, "verticality": 1.0 - abs(v[2, 0])}[feature]
    return out


def assert_matches_oracle(xyz, spec, result, rtol=2e-5, atol=2e-6):
    for (feature, radius), name in zip(spec.features, spec.names):
        expected = oracle(xyz, feature, radius)
        got = result[name]
        assert got.dtype == np.float32 and got.shape == (len(xyz),)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(expected), err_msg=f"{name}: NaN pattern")
        np.testing.assert_allclose(got, expected, rtol=rtol, atol=atol, equal_nan=True, err_msg=name)


def random_cloud(n, seed, size=(6.0, 6.0, 3.0)):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 1.0, (n, 3)) * size + [X0, Y0, Z0]


ALL_AT = lambda radius: FeatureSpec(tuple((f, radius) for f in SPHERE_FEATURES))  # noqa: E731


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("radius", [0.35, 0.8])
def test_every_sphere_feature_matches_the_oracle(seed, radius):
    xyz = random_cloud(2500, seed)
    spec = ALL_AT(radius)
    assert_matches_oracle(xyz, spec, compute_features(xyz, spec))


@pytest.mark.parametrize("seed", [0, 3])
def test_height_above_column_minimum_matches_the_oracle(seed):
    xyz = random_cloud(3000, seed, size=(20.0, 20.0, 8.0))
    spec = FeatureSpec((("height_above_min", 1.7), ("height_above_min", 0.3)))
    assert_matches_oracle(xyz, spec, compute_features(xyz, spec))


def test_clustered_cloud_with_several_radii_matches_the_oracle():
    """Clusters of very different densities (some spheres sparse, some dense), the paper's set
    plus extra features at other radii in one call."""
    rng = np.random.default_rng(5)
    centres = rng.uniform(0, 15, (12, 3)) * [1, 1, 0.3]
    parts = [c + rng.normal(size=(int(rng.integers(20, 400)), 3)) * rng.uniform(0.05, 0.6) for c in centres]
    xyz = np.vstack(parts + [rng.uniform(0, 15, (300, 3))]) + [X0, Y0, Z0]
    spec = FeatureSpec(PAPER_FEATURES + (("linearity", 0.5), ("density", 0.25), ("height_above_min", 2.5),
                                         ("sphericity", 1.1)))
    assert_matches_oracle(xyz, spec, compute_features(xyz, spec))


def test_far_apart_parts_use_the_sparse_column_index():
    """Two patches 80 km apart: the grid of 0.3 m columns is too large to be dense, so the
    columns are found by binary search; the values are the same."""
    a = random_cloud(800, 7, size=(4.0, 4.0, 2.0))
    b = random_cloud(800, 8, size=(4.0, 4.0, 2.0)) + [80_000.0, 50_000.0, 30.0]
    xyz = np.vstack([a, b])
    spec = FeatureSpec((("planarity", 0.3), ("verticality", 0.3), ("density", 0.3), ("height_above_min", 0.6)))
    assert_matches_oracle(xyz, spec, compute_features(xyz, spec))


def test_values_follow_their_points_whatever_the_input_order():
    xyz = random_cloud(1500, 9)
    perm = np.random.default_rng(10).permutation(len(xyz))
    spec = FeatureSpec(PAPER_FEATURES + (("height_above_min", 1.0),))
    base, shuffled = compute_features(xyz, spec), compute_features(xyz[perm], spec)
    for name in spec.names:
        np.testing.assert_allclose(shuffled[name], base[name][perm], rtol=1e-5, atol=1e-6, equal_nan=True)


def test_kernel_rows_follow_the_feature_list():
    assert SPHERE_FEATURES[K.LINEARITY] == "linearity"
    assert SPHERE_FEATURES[K.VERTICALITY] == "verticality"
    assert SPHERE_FEATURES[K.EIGENVALUE_SUM] == "eigenvalue_sum"
    assert SPHERE_FEATURES[K.DENSITY] == "density"
    assert len(SPHERE_FEATURES) == K.N_SPHERE and MIN_POINTS == K.MIN_POINTS
    assert set(FEATURES) == set(EIGEN_FEATURES) | {"density"} | set(COLUMN_FEATURES)


# --------------------------------------------------------------------------- known shapes

def grid_plane(size=6.0, step=0.05, jitter=0.002, seed=0):
    """A horizontal square of points on a jittered grid; and a mask of the points at least
    1 m from its edge."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.arange(0.0, size, step), np.arange(0.0, size, step))
    u, v = u.ravel() + rng.uniform(-jitter, jitter, u.size), v.ravel() + rng.uniform(-jitter, jitter, u.size)
    inner = (u > 1) & (u < size - 1) & (v > 1) & (v < size - 1)
    return u, v, inner


def test_horizontal_plane_is_planar_and_not_vertical():
    u, v, inner = grid_plane()
    xyz = np.column_stack([u + X0, v + Y0, np.full(u.size, Z0)])
    spec = FeatureSpec((("planarity", 0.55), ("verticality", 0.55), ("linearity", 0.55), ("sphericity", 0.55),
                        ("surface_variation", 0.55), ("eigenentropy", 0.55)))
    f = compute_features(xyz, spec)
    assert f["planarity_r0p55"][inner].min() > 0.95
    assert f["verticality_r0p55"].max() < 1e-6
    assert f["linearity_r0p55"][inner].max() < 0.05
    assert f["sphericity_r0p55"].max() < 1e-6 and f["surface_variation_r0p55"].max() < 1e-6
    # two equal eigenvalues, one zero: entropy ln 2
    np.testing.assert_allclose(f["eigenentropy_r0p55"][inner], math.log(2), atol=0.01)


@pytest.mark.parametrize("slope", [0.1, 0.3, 1.0])
def test_tilted_plane_verticality_is_one_minus_cos_of_the_slope(slope):
    u, v, inner = grid_plane(seed=1)
    xyz = np.column_stack([u + X0, v + Y0, Z0 + slope * u])
    f = compute_features(xyz, FeatureSpec((("verticality", 0.55), ("planarity", 0.55))))
    expected = 1.0 - 1.0 / math.sqrt(1.0 + slope * slope)
    np.testing.assert_allclose(f["verticality_r0p55"], expected, atol=1e-5)
    assert f["planarity_r0p55"][inner].min() > 0.9


def test_vertical_wall_has_verticality_one():
    u, v, inner = grid_plane(seed=2)
    xyz = np.column_stack([np.full(u.size, X0), u + Y0, v + Z0])  # the plane x = X0
    f = compute_features(xyz, FeatureSpec((("verticality", 0.55), ("planarity", 0.55))))
    assert f["verticality_r0p55"].min() > 1 - 1e-6
    assert f["planarity_r0p55"][inner].min() > 0.95


def test_oblique_wall_with_noise_is_nearly_vertical():
    rng = np.random.default_rng(3)
    s, h = rng.uniform(0, 10, 6000), rng.uniform(0, 6, 6000)
    direction = np.array([0.6, 0.8])
    xyz = np.column_stack([X0 + s * direction[0], Y0 + s * direction[1], Z0 + h])
    xyz[:, :2] += rng.normal(0, 0.01, (6000, 1)) * [0.8, -0.6]  # noise across the wall
    f = compute_features(xyz, FeatureSpec((("verticality", 0.6),)))
    assert np.median(f["verticality_r0p6"]) > 0.99 and f["verticality_r0p6"].min() > 0.9


def test_line_has_linearity_one():
    t = np.sort(np.random.default_rng(4).uniform(0, 20, 2000))
    direction = np.array([0.48, 0.6, 0.64])
    xyz = np.array([X0, Y0, Z0]) + t[:, None] * direction
    xyz += np.random.default_rng(5).normal(0, 0.002, xyz.shape)
    f = compute_features(xyz, FeatureSpec((("linearity", 0.5), ("planarity", 0.5), ("anisotropy", 0.5))))
    assert f["linearity_r0p5"].min() > 0.98
    assert f["planarity_r0p5"].max() < 0.02
    assert f["anisotropy_r0p5"].min() > 0.99


def test_isotropic_ball_is_spherical():
    rng = np.random.default_rng(6)
    xyz = rng.uniform(-2, 2, (40000, 3)) + [X0, Y0, Z0]  # 625 points per m³
    inner = np.abs(xyz - [X0, Y0, Z0]).max(axis=1) < 1.0
    spec = FeatureSpec((("sphericity", 0.7), ("omnivariance", 0.7), ("eigenentropy", 0.7), ("linearity", 0.7),
                        ("planarity", 0.7), ("surface_variation", 0.7)))
    f = compute_features(xyz, spec)
    assert np.median(f["sphericity_r0p7"][inner]) > 0.8
    assert f["sphericity_r0p7"][inner].min() > 0.6
    assert np.median(f["omnivariance_r0p7"][inner]) > 0.32  # 1/3 for a perfect ball
    assert np.median(f["eigenentropy_r0p7"][inner]) > 0.99 * math.log(3)
    assert np.median(f["surface_variation_r0p7"][inner]) > 0.3
    assert np.median(f["linearity_r0p7"][inner]) < 0.15 and np.median(f["planarity_r0p7"][inner]) < 0.15


def test_eigenvalue_sum_is_the_variance_in_metres():
    """Points on a circle of radius a around the centre point: total variance about the centroid."""
    a, n = 0.4, 36
    ang = np.arange(n) * 2 * math.pi / n
    ring = np.column_stack([a * np.cos(ang), a * np.sin(ang), np.zeros(n)])
    xyz = np.vstack([[0.0, 0.0, 0.0], ring]) + [X0, Y0, Z0]
    f = compute_features(xyz, FeatureSpec((("eigenvalue_sum", 0.5),)))
    # n ring points at distance a and the centre: mean 0, sum of squares n a², divided by n + 1
    assert f["eigenvalue_sum_r0p5"][0] == pytest.approx(n * a * a / (n + 1), rel=1e-6)


def test_height_above_the_column_minimum_on_a_constructed_cloud():
    """A flat ground at Z0 on a 0.5 m grid, a pole of points above (3, 3), a pit 2 m deep at
    (7, 7): with a column radius of 1 m, every point is z - Z0 except within 1 m of the pit."""
    g = np.arange(0.0, 10.01, 0.5)
    gx, gy = np.meshgrid(g, g)
    ground = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    pole = np.column_stack([np.full(10, 3.1), np.full(10, 3.1), np.arange(1.0, 11.0)])
    pit = np.array([[7.1, 7.1, -2.0]])
    rel = np.vstack([ground, pole, pit])
    xyz = rel + [X0, Y0, Z0]
    height = compute_features(xyz, FeatureSpec((("height_above_min", 1.0),)))["height_above_min_r1"]
    near_pit = np.hypot(rel[:, 0] - 7.1, rel[:, 1] - 7.1) <= 1.0
    expected = np.where(near_pit, rel[:, 2] + 2.0, rel[:, 2])
    np.testing.assert_allclose(height, expected, atol=1e-5)
    assert height[len(ground) + 9] == pytest.approx(10.0)  # top of the pole
    assert height[-1] == 0.0 and (height >= 0).all()


def test_density_on_a_lattice():
    """A cubic lattice of 0.1 m: inside, the sphere of 0.25 m holds the lattice points with
    i² + j² + k² <= 6.25 (no point lies on the sphere itself)."""
    g = np.arange(0.0, 2.0, 0.1)
    xyz = np.stack(np.meshgrid(g, g, g), axis=-1).reshape(-1, 3) + [X0, Y0, Z0]
    inner = (np.abs(xyz - [X0 + 0.95, Y0 + 0.95, Z0 + 0.95]) < 0.6).all(axis=1)
    r = np.arange(-3, 4)
    count = int(((r[:, None, None] ** 2 + r[None, :, None] ** 2 + r[None, None, :] ** 2) <= 6.25).sum())
    density = compute_features(xyz, FeatureSpec((("density", 0.25),)))["density_r0p25"]
    np.testing.assert_allclose(density[inner], count / (4 / 3 * math.pi * 0.25 ** 3), rtol=1e-6)
    assert (density[~inner] <= density[inner].max()).all()


# --------------------------------------------------------------------------- too few neighbours

def test_points_with_fewer_than_three_points_in_their_sphere_get_nan():
    # an isolated point, a pair, a triangle, and a square with its centre
    rel = np.array([[0, 0, 0],
                    [10, 0, 0], [10.3, 0, 0],
                    [20, 0, 0], [20.3, 0, 0], [20, 0.3, 0],
                    [30, 0, 0], [30.3, 0, 0], [30, 0.3, 0], [30.3, 0.3, 0.1], [30.15, 0.15, 0.05]], float)
    xyz = rel + [X0, Y0, Z0]
    spec = FeatureSpec(tuple((f, 0.5) for f in SPHERE_FEATURES))
    f = compute_features(xyz, spec)
    for feature in EIGEN_FEATURES:
        values = f[feature_name(feature, 0.5)]
        assert np.isnan(values[:3]).all(), feature
        assert np.isfinite(values[3:]).all(), feature
    sphere = 4 / 3 * math.pi * 0.5 ** 3
    np.testing.assert_allclose(f["density_r0p5"][:6], np.array([1, 2, 2, 3, 3, 3]) / sphere, rtol=1e-6)
    # three points span a plane: no third dimension
    assert f["surface_variation_r0p5"][3] == pytest.approx(0.0, abs=1e-6)
    assert f["verticality_r0p5"][3] == pytest.approx(0.0, abs=1e-6)
    assert_matches_oracle(xyz, spec, f)


def test_coincident_points_have_no_shape():
    xyz = np.vstack([np.tile([X0, Y0, Z0], (5, 1)), [[X0 + 5, Y0, Z0]]])
    f = compute_features(xyz, FeatureSpec((("planarity", 0.6), ("verticality", 0.6), ("eigenvalue_sum", 0.6),
                                           ("density", 0.6))))
    assert np.isnan(f["planarity_r0p6"]).all() and np.isnan(f["verticality_r0p6"]).all()
    assert (f["eigenvalue_sum_r0p6"][:5] == 0).all() and np.isnan(f["eigenvalue_sum_r0p6"][5])
    assert f["density_r0p6"][0] == pytest.approx(5 / (4 / 3 * math.pi * 0.216))


def test_a_single_point():
    f = compute_features(np.array([[X0, Y0, Z0]]), FeatureSpec((("planarity", 0.6), ("height_above_min", 2.0))))
    assert np.isnan(f["planarity_r0p6"][0]) and f["height_above_min_r2"][0] == 0.0


def test_bad_coordinates_are_refused():
    with pytest.raises(InputError, match="NaN"):
        compute_features(np.array([[0.0, 0.0, np.nan], [1.0, 1.0, 1.0]]))
    with pytest.raises(InputError, match="no points"):
        compute_features(np.empty((0, 3)))


# --------------------------------------------------------------------------- names and validation

def test_default_spec_is_the_papers():
    spec = FeatureSpec()
    assert spec.features == (("verticality", 0.6), ("planarity", 0.6), ("eigenentropy", 0.4),
                             ("surface_variation", 0.6))
    assert spec.names == ("verticality_r0p6", "planarity_r0p6", "eigenentropy_r0p4", "surface_variation_r0p6")
    assert list(spec.sphere_passes()) == [0.6, 0.4]  # one pass per distinct radius


@pytest.mark.parametrize("radius,text", [(0.6, "0p6"), (2.5, "2p5"), (1.0, "1"), (1, "1"), (0.125, "0p125"),
                                         (10.0, "10"), (0.001, "0p001"), (0.1 + 0.2, "0p3")])
def test_radius_text(radius, text):
    assert radius_text(radius) == text


def test_names_round_trip_and_fit_in_las():
    for feature in FEATURES:
        for radius in (0.001, 0.4, 2.5, 123.456789):
            name = feature_name(feature, radius)
            assert len(name) <= 32 and name.replace("_", "").isalnum()
            back_feature, back_radius = parse_feature_name(name)
            assert back_feature == feature and back_radius == pytest.approx(radius, abs=1e-6)
    spec = FeatureSpec.from_names("verticality_r0p6, height_above_min_r2p5,density_r1")
    assert spec.features == (("verticality", 0.6), ("height_above_min", 2.5), ("density", 1.0))
    assert FeatureSpec.from_names(FeatureSpec().names) == FeatureSpec()


@pytest.mark.parametrize("name", ["verticality_r0.6", "verticality", "roughness_r0p6", "planarity_rp6",
                                  "Planarity_r0p6", ""])
def test_parse_refuses_other_names(name):
    with pytest.raises(InvalidParameterError, match="feature name"):
        parse_feature_name(name)


@pytest.mark.parametrize("radius", [0, 0.0, -0.6, float("nan"), float("inf"), 0.0001])
def test_bad_radius_is_refused_naming_the_feature(radius):
    with pytest.raises(InvalidParameterError, match="planarity radius"):
        FeatureSpec((("verticality", 0.6), ("planarity", radius)))


@pytest.mark.parametrize("radius", [None, "0.6", True])
def test_radius_must_be_a_number(radius):
    with pytest.raises(InvalidParameterError, match="eigenentropy radius must be a number"):
        FeatureSpec((("eigenentropy", radius),))


def test_unknown_feature_is_refused():
    with pytest.raises(InvalidParameterError, match="unknown feature 'roughness'.*planarity"):
        FeatureSpec((("roughness", 0.6),))


@pytest.mark.parametrize("features,match", [
    ((), "no feature"),
    ((("surface_variation", 1234567.123457),), "surface_variation radius .* longer than the 32 characters"),
    ("planarity", "pairs"),
    (("planarity", 0.6), "pairs"),
    ((("planarity", 0.6, 1),), "pairs"),
    ((("planarity", 0.6), ("planarity", 0.6)), "planarity_r0p6 asked twice"),
    ((("planarity", 0.6), ("planarity", 0.6000000001)), "asked twice"),
])
def test_malformed_specs_are_refused(features, match):
    with pytest.raises(InvalidParameterError, match=match):
        FeatureSpec(features)


def test_spec_accepts_a_mapping_and_is_frozen():
    spec = FeatureSpec({"planarity": 0.6, "height_above_min": 2})
    assert spec.features == (("planarity", 0.6), ("height_above_min", 2.0))
    assert hash(spec) == hash(FeatureSpec((("planarity", 0.6), ("height_above_min", 2.0))))
    with pytest.raises(Exception):
        spec.features = ()


def test_compute_features_wants_a_spec():
    with pytest.raises(InvalidParameterError, match="FeatureSpec"):
        compute_features(random_cloud(10, 0), {"planarity": 0.6})


# --------------------------------------------------------------------------- progress, cancellation

def test_progress_rises_to_one_and_cancellation_stops():
    xyz = random_cloud(3000, 11)
    seen = []
    compute_features(xyz, FeatureSpec(PAPER_FEATURES + (("height_above_min", 2.5),)), steps=Steps(seen.append))
    assert seen == sorted(seen) and seen[-1] == 1.0 and len(seen) >= 4
    calls = []

    def cancel_after_two():
        calls.append(1)
        return len(calls) > 2

    with pytest.raises(Cancelled):
        compute_features(xyz, steps=Steps(None, cancel_after_two))


# --------------------------------------------------------------------------- files

def utm32_wkt() -> str:
    import pyproj
    return pyproj.CRS.from_epsg(32632).to_wkt()


def sample_las(n=3000, point_format=1, version="1.2", seed=0):
    """A LasData with standard dimensions and two extra-bytes dimensions filled."""
    rng = np.random.default_rng(seed)
    x = np.round(rng.uniform(0, 20, n), 2) + X0
    y = np.round(rng.uniform(0, 20, n), 2) + Y0
    z = np.round(rng.uniform(0, 4, n), 2) + Z0
    nr = rng.integers(1, 4, n).astype(np.uint8)
    rn = np.minimum(rng.integers(1, 4, n), nr).astype(np.uint8)
    dims = dict(classification=rng.integers(0, 19, n).astype(np.uint8),
                intensity=rng.integers(0, 65535, n).astype(np.uint16), return_number=rn, number_of_returns=nr)
    if point_format != 0:
        dims["gps_time"] = np.cumsum(rng.uniform(0, 1e-3, n)) + 3.0e8
    extra = {"tree_id": rng.integers(0, 10_000, n).astype(np.int32),
             "amplitude": rng.normal(size=n).astype(np.float32)}
    return new_las(x, y, z, point_format=point_format, version=version, crs_wkt=utm32_wkt(), extra=extra, **dims)


def sha256(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


@pytest.mark.parametrize("src_ext,dst_ext,point_format,version",
                         [(".laz", ".laz", 1, "1.2"), (".las", ".laz", 6, "1.4"), (".laz", ".las", 3, "1.2")])
def test_las_round_trip_keeps_the_input_and_adds_the_features(tmp_path, src_ext, dst_ext, point_format, version):
    src, dst = tmp_path / f"in{src_ext}", tmp_path / f"out{dst_ext}"
    write_las(sample_las(point_format=point_format, version=version), str(src))
    before = sha256(src)
    cloud = read_cloud(str(src))
    spec = FeatureSpec(PAPER_FEATURES + (("height_above_min", 2.5), ("density", 0.6)))
    features = compute_features(cloud.xyz, spec)
    write_features(cloud, features, str(dst))
    assert sha256(src) == before
    assert "verticality_r0p6" not in set(cloud.las.point_format.dimension_names)  # the cloud in memory is as read
    a, b = laspy.read(str(src)), laspy.read(str(dst))
    assert b.point_format.id == point_format and len(b.points) == len(a.points)
    for name in a.point_format.dimension_names:
        np.testing.assert_array_equal(np.asarray(a[name]), np.asarray(b[name]), err_msg=name)
    added = [d for d in b.point_format.dimension_names if d not in set(a.point_format.dimension_names)]
    assert added == list(spec.names)
    for name in spec.names:
        assert np.asarray(b[name]).dtype == np.float32
        np.testing.assert_array_equal(np.asarray(b[name]), features[name])
    descriptions = {d.name: d.description for d in b.point_format.extra_dimensions}
    assert descriptions["eigenentropy_r0p4"] == "eigenentropy sphere r=0.4"
    assert descriptions["height_above_min_r2p5"] == "height_above_min column r=2.5"
    assert b.header.parse_crs().to_epsg() == 32632


def test_isprs_text_input_becomes_las_with_label_and_features(tmp_path):
    rng = np.random.default_rng(12)
    data = np.column_stack([rng.uniform(0, 10, 400) + X0, rng.uniform(0, 10, 400) + Y0,
                            rng.uniform(0, 2, 400) + Z0, rng.integers(0, 2, 400)])
    src = tmp_path / "sample.txt"
    np.savetxt(src, data, fmt="%.2f %.2f %.2f %d")
    run = run_features(str(src), str(tmp_path / "out.las"), FeatureSpec((("planarity", 1.0),)))
    out = laspy.read(str(tmp_path / "out.las"))
    np.testing.assert_array_equal(np.asarray(out["reference_label"]), data[:, 3])
    np.testing.assert_array_equal(np.asarray(out["planarity_r1"]), run.features["planarity_r1"])
    np.testing.assert_allclose(np.asarray(out.x), data[:, 0], atol=0.006)


def test_run_features_end_to_end(tmp_path):
    src, dst = tmp_path / "in.laz", tmp_path / "out.laz"
    write_las(sample_las(), str(src))
    seen, messages = [], []
    run = run_features(str(src), str(dst), progress=seen.append, log=messages.append)
    assert run.names == FeatureSpec().names
    assert seen[-1] == 1.0 and seen == sorted(seen)
    assert any("Read 3,000 points" in m for m in messages)
    assert any("within 0.4 m: no value (NaN) for eigenentropy_r0p4" in m for m in messages)
    assert set(run.names) <= set(laspy.read(str(dst)).point_format.dimension_names)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "temporary files left behind"


def test_existing_dimension_of_the_same_name_is_refused(tmp_path):
    src, first, second = tmp_path / "in.laz", tmp_path / "first.laz", tmp_path / "second.laz"
    write_las(sample_las(n=500), str(src))
    run_features(str(src), str(first))
    seen = []
    with pytest.raises(OutputError, match="already has a dimension named 'verticality_r0p6'"):
        run_features(str(first), str(second), progress=seen.append)
    assert not second.exists()
    assert max(seen, default=0.0) < 0.05, "the clash is found before the features are computed"
    cloud = read_cloud(str(src))
    with pytest.raises(OutputError, match="already has a dimension named 'Amplitude'|'amplitude'"):
        write_features(cloud, {"AMPLITUDE": np.zeros(len(cloud))}, str(second))
    with pytest.raises(OutputError, match="'intensity'"):
        write_features(cloud, {"Intensity": np.zeros(len(cloud))}, str(second))


@pytest.mark.parametrize("name", ["verticality_r0.6", "a" * 33, "1abc", "has space", ""])
def test_names_that_cannot_be_las_dimensions_are_refused(tmp_path, name):
    src = tmp_path / "in.las"
    write_las(sample_las(n=100), str(src))
    cloud = read_cloud(str(src))
    with pytest.raises(OutputError, match="cannot name a LAS extra dimension"):
        write_features(cloud, {name: np.zeros(len(cloud))}, str(tmp_path / "out.las"))


def test_feature_arrays_must_fit_the_cloud(tmp_path):
    src = tmp_path / "in.las"
    write_las(sample_las(n=100), str(src))
    cloud = read_cloud(str(src))
    with pytest.raises(OutputError, match="99"):
        write_features(cloud, {"planarity_r0p6": np.zeros(99)}, str(tmp_path / "out.las"))
    with pytest.raises(OutputError, match="differ only by case"):
        write_features(cloud, {"abc": np.zeros(100), "ABC": np.zeros(100)}, str(tmp_path / "out.las"))


def test_output_must_not_be_the_input(tmp_path):
    src = tmp_path / "in.laz"
    write_las(sample_las(n=100), str(src))
    with pytest.raises(OutputError, match="must not be the input"):
        run_features(str(src), str(src))
    with pytest.raises(OutputError, match=r"\.las or \.laz"):
        run_features(str(src), str(tmp_path / "out.txt"))


def test_withheld_and_ignored_points_stay_out_of_the_neighbourhoods(tmp_path):
    """As in rfclassify: withheld points and points of an ignored class (7, 18 by default) are in no
    neighbourhood and get NaN; every other point's features are those of the cloud without them."""
    las = sample_las(n=2000, seed=5)
    classes = np.asarray(las.classification).copy()
    classes[np.isin(classes, (7, 18))] = 1  # no other noise than the points below
    classes[:150] = 7                      # noise, ignored by default
    las.classification = classes
    withheld = np.zeros(len(classes), dtype=bool)
    withheld[150:300] = True
    las.withheld = withheld
    src, dst = tmp_path / "in.laz", tmp_path / "out.laz"
    write_las(las, str(src))
    spec = FeatureSpec(PAPER_FEATURES + (("height_above_min", 2.5),))
    messages = []
    run = run_features(str(src), str(dst), spec, log=messages.append)
    cloud = read_cloud(str(src))
    keep = np.ones(len(classes), dtype=bool)
    keep[:300] = False
    alone = compute_features(cloud.xyz[keep], spec)
    written = laspy.read(str(dst))
    for name in spec.names:
        values = np.asarray(written[name])
        assert np.isnan(values[:300]).all(), name
        np.testing.assert_array_equal(values[keep], alone[name], err_msg=name)
        np.testing.assert_array_equal(run.features[name], values)
    # The noise points, when not ignored, change their neighbours' features (the test can fail).
    everything = run_features(str(src), str(tmp_path / "all.laz"), spec, ignore_classes="").features
    assert np.isnan(everything[spec.names[0]][150:300]).all()
    assert not np.array_equal(everything["height_above_min_r2p5"][keep], alone["height_above_min_r2p5"])
    assert any("150 withheld point(s) and 150 of an ignored class (7, 18)" in m for m in messages)


def test_features_of_a_cloud_entirely_withheld_are_refused(tmp_path):
    las = sample_las(n=200, seed=6)
    las.withheld = np.ones(200, dtype=bool)
    src = tmp_path / "in.laz"
    write_las(las, str(src))
    with pytest.raises(InputError, match="every point is withheld or of an ignored class"):
        run_features(str(src), str(tmp_path / "out.laz"))
    assert not (tmp_path / "out.laz").exists()
