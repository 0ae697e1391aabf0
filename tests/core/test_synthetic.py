"""Synthetic scenes: reproducible, at the asked density, with a consistent truth."""
import math

import numpy as np
import pytest

from groundsieve.core.errors import GroundSieveError, InvalidParameterError
from groundsieve.core.io import read_cloud
from groundsieve.core.synthetic import (CLASS_BUILDING, CLASS_GROUND, CLASS_HIGH_VEGETATION,
                                        CLASS_LOW_VEGETATION, EPSG, ORIGIN_X, ORIGIN_Y, SceneSpec,
                                        make_scene, scene_crs_wkt, write_scene)

ARRAYS = ("x", "y", "z", "classification", "return_number", "number_of_returns", "intensity", "gps_time")


@pytest.fixture(scope="module")
def scene():
    return make_scene(SceneSpec(size_m=200.0, density_per_m2=10.0, seed=7))


def _pulse_starts(scene):
    return np.flatnonzero(scene.return_number == 1)


# --------------------------------------------------------------------------- determinism, size

def test_same_seed_same_scene():
    spec = SceneSpec(size_m=80.0, seed=3)
    a, b = make_scene(spec), make_scene(spec)
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.buildings == b.buildings


def test_other_seed_other_scene():
    a, b = make_scene(SceneSpec(size_m=80.0, seed=3)), make_scene(SceneSpec(size_m=80.0, seed=4))
    assert len(a) != len(b) or not np.array_equal(a.z, b.z)


def test_layout_does_not_depend_on_density():
    sparse = make_scene(SceneSpec(size_m=150.0, density_per_m2=2.0, seed=5))
    dense = make_scene(SceneSpec(size_m=150.0, density_per_m2=8.0, seed=5))
    assert sparse.buildings == dense.buildings
    x = np.linspace(ORIGIN_X, ORIGIN_X + 150, 50)
    y = np.linspace(ORIGIN_Y, ORIGIN_Y + 150, 50)
    np.testing.assert_array_equal(sparse.ground_z(x, y), dense.ground_z(x, y))


def test_pulse_count_and_uniform_density(scene):
    starts = _pulse_starts(scene)
    assert starts.size == scene.spec.n_pulses == 400_000
    assert 1.05 < len(scene) / starts.size < 1.5          # extra returns from vegetation
    x0, y0, x1, y1 = scene.bounds
    xs, ys = scene.x[starts], scene.y[starts]
    assert xs.min() >= x0 and xs.max() <= x1 and ys.min() >= y0 and ys.max() <= y1
    # Every quarter of the square holds a quarter of the pulses.
    east, north = xs >= (x0 + x1) / 2, ys >= (y0 + y1) / 2
    for quarter in (east & north, east & ~north, ~east & north, ~east & ~north):
        assert quarter.sum() == pytest.approx(starts.size / 4, rel=0.03)


def test_realistic_coordinates(scene):
    assert scene.x.min() >= ORIGIN_X and scene.y.min() >= ORIGIN_Y
    assert 200.0 < scene.z.min() and scene.z.max() < 300.0


@pytest.mark.parametrize("n_points", [100_000, 400_000])
def test_for_points(n_points):
    spec = SceneSpec.for_points(n_points, density_per_m2=8.0, seed=2)
    assert spec.density_per_m2 == 8.0 and spec.seed == 2
    assert len(make_scene(spec)) == pytest.approx(n_points, rel=0.03)


def test_for_points_keeps_knobs():
    spec = SceneSpec.for_points(50_000, trees_per_ha=0.0, shrub_fraction=0.0)
    assert spec.trees_per_ha == 0.0 and spec.shrub_fraction == 0.0
    # Without vegetation every pulse gives exactly one point.
    assert spec.size_m == pytest.approx(math.sqrt(50_000 / 10.0), rel=0.01)


# --------------------------------------------------------------------------- truth

def test_all_classes_present(scene):
    assert set(np.unique(scene.classification).tolist()) == {
        CLASS_GROUND, CLASS_LOW_VEGETATION, CLASS_HIGH_VEGETATION, CLASS_BUILDING}
    assert scene.ground.dtype == bool and scene.ground.sum() == (scene.classification == 2).sum()


def test_returns_are_consistent(scene):
    rn, nr = scene.return_number, scene.number_of_returns
    assert rn.dtype == nr.dtype == np.uint8
    assert rn.min() == 1 and nr.max() == 4 and np.all(rn <= nr)
    # The returns of a pulse are consecutive, numbered 1..n, and share a unique gps_time.
    starts = _pulse_starts(scene)
    np.testing.assert_array_equal(np.diff(np.append(starts, len(scene))), nr[starts])
    owner = np.repeat(np.arange(starts.size), nr[starts])
    np.testing.assert_array_equal(rn, np.arange(len(scene)) - starts[owner] + 1)
    np.testing.assert_array_equal(nr, nr[starts][owner])
    np.testing.assert_array_equal(scene.gps_time, scene.gps_time[starts][owner])
    assert np.all(np.diff(scene.gps_time[starts]) > 0)


def test_multi_return_pulses(scene):
    rn, nr, cls, z = scene.return_number, scene.number_of_returns, scene.classification, scene.z
    starts = _pulse_starts(scene)
    last = starts + nr[starts] - 1
    multi = nr[starts] > 1
    # Only vegetation gives several returns: shrubs 1-2, trees 1-4.
    assert set(np.unique(cls[starts[multi]]).tolist()) == {CLASS_LOW_VEGETATION, CLASS_HIGH_VEGETATION}
    assert nr[starts][cls[starts] == CLASS_LOW_VEGETATION].max() == 2
    assert np.all(nr[starts][cls[starts] == CLASS_BUILDING] == 1)
    # A tree pulse: every return but the last is in the crown; the last is on the
    # ground (class 2, at the true ground) in about 60 % of the pulses.
    tree = starts[(cls[starts] == CLASS_HIGH_VEGETATION) & multi]
    tree_last = last[np.isin(starts, tree)]
    assert set(np.unique(cls[tree_last]).tolist()) == {CLASS_GROUND, CLASS_HIGH_VEGETATION}
    reached = tree_last[cls[tree_last] == CLASS_GROUND]
    assert 0.5 < reached.size / tree.size < 0.85
    gz = scene.ground_z(scene.x[reached], scene.y[reached])
    assert np.abs(z[reached] - gz).max() < 0.25
    not_last = (rn < nr) & np.isin(np.repeat(starts, nr[starts]), tree)
    assert np.all(cls[not_last] == CLASS_HIGH_VEGETATION)
    # Heights fall with the return number, and the crown is well above the ground.
    following = np.flatnonzero(not_last) + 1
    crown_next = following[cls[following] == CLASS_HIGH_VEGETATION]
    assert np.all(z[crown_next] <= z[crown_next - 1])
    veg = cls == CLASS_HIGH_VEGETATION
    assert np.all(z[veg] - scene.ground_z(scene.x[veg], scene.y[veg]) > 1.5)
    low = cls == CLASS_LOW_VEGETATION
    height = z[low] - scene.ground_z(scene.x[low], scene.y[low])
    assert height.min() > 0.05 and height.max() <= 2.0


def test_ground_points_on_true_ground(scene):
    g = scene.ground
    residual = scene.z[g] - scene.ground_z(scene.x[g], scene.y[g])
    assert 0.02 < residual.std() < 0.05
    assert abs(residual.mean()) < 0.005
    assert np.abs(residual).max() < 0.25


def test_buildings(scene):
    assert len(scene.buildings) == 8       # 2 per hectare on 4 ha
    cls, x, y, z = scene.classification, scene.x, scene.y, scene.z
    on_roof = np.zeros(len(scene), dtype=bool)
    for b in scene.buildings:
        assert 10.0 <= b.width_m <= b.length_m <= 40.0
        assert 5.0 <= b.eave_m <= b.ridge_m <= 15.0
        assert b.roof in ("flat", "gabled") and (b.roof == "flat") == (b.eave_m == b.ridge_m)
        inside = b.contains(x, y)
        assert np.all(cls[inside] == CLASS_BUILDING)       # a roof hides the ground
        assert np.abs(z[inside] - b.roof_z(x[inside], y[inside])).max() < 0.25
        on_roof |= inside
        # The roof stands at least 5 m above the true ground everywhere under it.
        a, c = np.meshgrid(np.linspace(-0.49, 0.49, 40), np.linspace(-0.49, 0.49, 40))
        cos, sin = math.cos(b.angle_rad), math.sin(b.angle_rad)
        gx = b.x + a.ravel() * b.length_m * cos - c.ravel() * b.width_m * sin
        gy = b.y + a.ravel() * b.length_m * sin + c.ravel() * b.width_m * cos
        assert np.all(b.roof_z(gx, gy) - scene.ground_z(gx, gy) >= 5.0)
    roof = on_roof & (cls == CLASS_BUILDING)
    assert np.all(z[roof] - scene.ground_z(x[roof], y[roof]) >= 4.9)
    # The other building points are sparse wall hits between the foot and the eave.
    wall = ~on_roof & (cls == CLASS_BUILDING)
    assert 0 < wall.sum() < 0.08 * roof.sum()
    assert np.all(z[wall] - scene.ground_z(x[wall], y[wall]) > 0.2)


def _largest_jump_over_2m(scene, **spec_changes):
    x0, y0, x1, y1 = scene.bounds
    xs, ys = np.arange(x0, x1, 0.5), np.arange(y0, y1, 0.5)
    gx, gy = np.meshgrid(xs, ys)
    dem = scene.ground_z(gx, gy)
    return max(np.abs(dem[:, 4:] - dem[:, :-4]).max(), np.abs(dem[4:, :] - dem[:-4, :]).max())


def test_breaklines(scene):
    assert _largest_jump_over_2m(scene) >= 1.0
    # Along them the terrain is sharp; without them (and elsewhere) it is smooth.
    smooth = make_scene(SceneSpec(size_m=200.0, density_per_m2=0.1, seed=7, terrace_height_m=0.0,
                                  ditch_depth_m=0.0))
    assert _largest_jump_over_2m(smooth) < 0.6
    # Away from the breaklines the scene is the smooth terrain, raised by the terrace
    # height on the terrace's high side.
    x0, y0, x1, y1 = scene.bounds
    gx, gy = np.meshgrid(np.arange(x0, x1, 0.5), np.arange(y0, y1, 0.5))
    distance = scene.terrain.distance_to_breaklines(gx, gy)
    assert distance.min() == 0.0
    far = distance > 1.0
    step = (scene.ground_z(gx, gy) - smooth.ground_z(gx, gy))[far]
    low, high = np.isclose(step, 0.0, atol=1e-9), np.isclose(step, 1.5, atol=1e-9)
    assert np.all(low | high) and low.any() and high.any()


# --------------------------------------------------------------------------- files

@pytest.mark.parametrize("ext", ["laz", "las"])
def test_write_read_round_trip(scene, tmp_path, ext):
    path = tmp_path / f"scene.{ext}"
    write_scene(scene, str(path))
    cloud = read_cloud(str(path))
    assert len(cloud) == len(scene) and cloud.has_return_info
    for name in ("x", "y", "z"):
        np.testing.assert_allclose(getattr(cloud, name), getattr(scene, name), rtol=0, atol=0.0006)
    for name in ("classification", "return_number", "number_of_returns", "intensity"):
        np.testing.assert_array_equal(getattr(cloud, name), getattr(scene, name), err_msg=name)
    np.testing.assert_array_equal(np.asarray(cloud.las.gps_time), scene.gps_time)
    assert cloud.las.point_format.id == 1
    assert cloud.crs_wkt is not None and '"EPSG",32632' in cloud.crs_wkt.replace(" ", "")
    assert not list(tmp_path.glob(".*part*"))            # the atomic write left nothing behind


def test_write_without_crs(tmp_path):
    small = make_scene(SceneSpec(size_m=30.0, seed=1))
    write_scene(small, str(tmp_path / "no_crs.laz"), crs_wkt="")
    assert read_cloud(str(tmp_path / "no_crs.laz")).crs_wkt is None


def test_scene_crs_wkt():
    wkt = scene_crs_wkt()
    assert wkt.startswith("PROJCRS[") and "UTM zone 32N" in wkt and f'ID["EPSG",{EPSG}]]' in wkt


# --------------------------------------------------------------------------- validation

@pytest.mark.parametrize("changes, message", [
    (dict(size_m=-1), "size_m must be > 0 (got -1)"),
    (dict(size_m=0.0), "size_m must be > 0 (got 0.0)"),
    (dict(size_m=float("nan")), "size_m must be > 0 (got nan)"),
    (dict(size_m="big"), "size_m must be a number (got 'big')"),
    (dict(density_per_m2=0), "density_per_m2 must be > 0 (got 0)"),
    (dict(seed=-1), "seed must be an integer >= 0 (got -1)"),
    (dict(seed=1.5), "seed must be an integer >= 0 (got 1.5)"),
    (dict(buildings_per_ha=-2), "buildings_per_ha must be >= 0 (got -2)"),
    (dict(trees_per_ha=float("inf")), "trees_per_ha must be >= 0 (got inf)"),
    (dict(shrub_fraction=1.5), "shrub_fraction must be in [0, 1] (got 1.5)"),
    (dict(relief_m=-0.1), "relief_m must be >= 0 (got -0.1)"),
    (dict(slope_pct=150), "slope_pct must be in [0, 100] (got 150)"),
    (dict(terrace_height_m=-1), "terrace_height_m must be >= 0 (got -1)"),
    (dict(ditch_depth_m=True), "ditch_depth_m must be a number (got True)"),
    (dict(size_m=1e5), "limit 200,000,000"),
])
def test_invalid_spec(changes, message):
    with pytest.raises(InvalidParameterError) as info:
        SceneSpec(**changes)
    assert message in str(info.value)
    assert isinstance(info.value, GroundSieveError)


@pytest.mark.parametrize("n_points", [0, -5, float("nan")])
def test_for_points_invalid(n_points):
    with pytest.raises(InvalidParameterError, match="n_points must be >= 1"):
        SceneSpec.for_points(n_points)


def test_for_points_validates_knobs():
    with pytest.raises(InvalidParameterError, match="density_per_m2 must be > 0"):
        SceneSpec.for_points(1000, density_per_m2=-3)


def test_a_photogrammetric_scene_is_the_surface_seen_from_above():
    """photogrammetric(): the first return of each pulse (no ground under vegetation), one return a
    point, 3 cm of matching noise, the truth kept; the same scene twice gives the same points."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, photogrammetric
    scene = make_scene(SceneSpec(size_m=40.0, density_per_m2=20.0, seed=9, shrub_fraction=0.3))
    photo = photogrammetric(scene)
    first = scene.return_number == 1
    assert len(photo) == int(first.sum()) < len(scene)
    assert (photo.return_number == 1).all() and (photo.number_of_returns == 1).all() and not photo.gps_time.any()
    np.testing.assert_array_equal(photo.x, scene.x[first])
    np.testing.assert_array_equal(photo.classification, scene.classification[first])
    noise = photo.z - scene.z[first]
    assert 0.025 < noise.std() < 0.035 and abs(noise.mean()) < 0.005
    np.testing.assert_array_equal(photogrammetric(scene).z, photo.z)
    # under a tree crown the first return is the crown: fewer ground points than the LiDAR scene keeps
    assert photo.ground.mean() < scene.ground[scene.return_number == scene.number_of_returns].mean()
