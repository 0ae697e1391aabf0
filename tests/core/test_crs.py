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


def test_a_local_survey_labelled_geographic_is_warned_not_refused_and_degrees_are():
    """A terrestrial scan in local metres (0 to 50) exported with WGS 84 as its CRS is not a cloud in
    degrees (a reviewer's case was refused and told to reproject); a survey spanning a fraction of a
    degree is refused before any work."""
    import pyproj
    from groundsieve.core.errors import InputError
    from groundsieve.core.raster.crs import check_lengths_unit
    wgs84 = pyproj.CRS.from_epsg(4326).to_wkt()
    said = check_lengths_unit("scan.laz", wgs84, (0.0, 0.0, 50.0, 50.0))
    assert said.startswith("scan.laz: the file's CRS is geographic (degrees), but its coordinates (x 0 to 50")
    with pytest.raises(InputError, match="uav.laz: its coordinates are longitudes and latitudes"):
        check_lengths_unit("uav.laz", wgs84, (9.001, 47.002, 9.004, 47.005))
    assert check_lengths_unit("utm.laz", pyproj.CRS.from_epsg(32632).to_wkt(), (10.0, 20.0, 60.0, 70.0)) is None


def test_a_local_crs_in_feet_is_said_to_be_in_feet():
    """A LOCAL_CS in feet was taken for metres, without a warning."""
    from groundsieve.core.raster.crs import horizontal_unit
    local_ft = 'LOCAL_CS["site grid",LOCAL_DATUM["site",0],UNIT["foot",0.3048],AXIS["X",EAST],AXIS["Y",NORTH]]'
    local_m = 'LOCAL_CS["site grid",LOCAL_DATUM["site",0],UNIT["metre",1],AXIS["X",EAST],AXIS["Y",NORTH]]'
    assert horizontal_unit(local_ft) == "foot"
    assert horizontal_unit(local_m) == "metres"
