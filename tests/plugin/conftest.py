"""Fixtures of the plugin tests: QGIS with Processing (pytest-qgis) and GroundSieve's provider."""
import numpy as np
import pytest


@pytest.fixture(scope="session")
def groundsieve_provider(qgis_app, qgis_processing):
    from qgis.core import QgsApplication

    from groundsieve.provider.provider import GroundSieveProvider
    registry = QgsApplication.processingRegistry()
    provider = registry.providerById("groundsieve")
    if provider is None:
        provider = GroundSieveProvider()  # keep a Python reference, or the algorithms vanish
        assert registry.addProvider(provider)
    yield provider


@pytest.fixture(scope="session")
def scene_laz(tmp_path_factory):
    """A generated scene with known truth, written as LAZ with a CRS."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, scene_crs_wkt, write_scene
    scene = make_scene(SceneSpec(size_m=120.0, density_per_m2=6.0, seed=7))
    path = tmp_path_factory.mktemp("scene") / "scene.laz"
    write_scene(scene, str(path), crs_wkt=scene_crs_wkt())
    return path, scene


def classes_of(path):
    import laspy
    return np.asarray(laspy.read(str(path)).classification)
