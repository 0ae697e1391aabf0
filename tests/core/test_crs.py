"""core/raster/crs.py: boxes in WGS 84 for GeoJSON/STAC (the .vpc's bbox and geometry)."""
import pytest

from groundsieve.core.raster.crs import lonlat_box


def test_a_utm_box_in_longitude_latitude():
    from osgeo import osr
    ref = osr.SpatialReference()
    ref.ImportFromEPSG(32632)  # UTM 32N: the central meridian 9 E at x = 500000
    box = lonlat_box(500000.0, 5400000.0, 501000.0, 5401000.0, ref.ExportToWkt())
    lon0, lat0, lon1, lat1 = box
    assert lon0 == pytest.approx(9.0, abs=1e-6) and 9.0 < lon1 < 9.02
    assert 48.7 < lat0 < lat1 < 48.8 and lat1 - lat0 == pytest.approx(0.009, abs=5e-4)


def test_no_crs_or_a_broken_one_gives_none():
    assert lonlat_box(0, 0, 1, 1, None) is None
    assert lonlat_box(0, 0, 1, 1, "") is None
    assert lonlat_box(0, 0, 1, 1, "not a crs") is None
