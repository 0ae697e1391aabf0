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


def test_heights_in_feet_under_a_compound_crs_in_metres_are_warned_and_the_dtm_says_feet(tmp_path):
    """A compound CRS with x, y in metres and heights in US survey feet (EPSG:2949+6360) ran without
    a word: the height thresholds were read in feet, 8,000 of 26,600 ground points were lost, and the
    DTM's band said metres (a geomorphologist). The run now warns, and the band's unit is the heights'."""
    import numpy as np
    import pyproj
    from osgeo import gdal

    from groundsieve.core.engine.workflow import DTMOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.progress import WARNING_PREFIX
    from groundsieve.core.raster.crs import elevation_unit, unit_warning, vertical_unit
    from groundsieve.core.synthetic import SceneSpec, make_scene
    feet = pyproj.CRS("EPSG:2949+6360").to_wkt()
    metres = pyproj.CRS("EPSG:32632+5703").to_wkt()
    assert vertical_unit(feet) == "US survey foot" and vertical_unit(metres) == "metres"
    assert vertical_unit(pyproj.CRS.from_epsg(32632).to_wkt()) is None
    assert unit_warning("a.laz", metres) is None
    # US survey feet across and international feet up (2 ppm apart): the same unit for the thresholds
    assert unit_warning("ft.laz", pyproj.CRS("EPSG:2249+8228").to_wkt()).startswith("ft.laz: the CRS's unit is US survey foot")
    said = unit_warning("a.laz", feet)
    assert said.startswith("a.laz: the heights are in US survey foot (the CRS's vertical part), x and y in metres")
    assert elevation_unit(feet) == "US survey foot" and elevation_unit(metres) == "m"
    from groundsieve.core.io import new_las, write_las
    scene = make_scene(SceneSpec(size_m=60.0, density_per_m2=2.0, seed=3))
    src = tmp_path / "ft.laz"  # LAS 1.4 with a WKT CRS: a compound CRS has no GeoTIFF keys of its own
    write_las(new_las(scene.x, scene.y, scene.z, point_format=6, version="1.4", crs_wkt=feet,
                      classification=scene.classification), src)
    lines = []
    run_ground_filter(str(src), str(tmp_path / "o.laz"), SMRF(), dtm_path=str(tmp_path / "o.tif"), dtm=DTMOptions(),
                      log=lines.append)
    assert any(line.startswith(WARNING_PREFIX) and "the heights are in US survey foot" in line for line in lines), lines
    assert gdal.Open(str(tmp_path / "o.tif")).GetRasterBand(1).GetUnitType() == "US survey foot"
