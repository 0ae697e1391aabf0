"""core/raster/crs.py: boxes in WGS 84 for GeoJSON/STAC (the .vpc's bbox and geometry)."""
import os

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


def test_degrees_without_a_crs_are_said_and_local_coordinates_are_not():
    """A UAV cloud in longitudes and latitudes with no CRS ran without a word but the DTM's size: 94 %
    of the ground lost, a 1 x 1 cell DTM (a UAV reviewer); a local site near 0 must not be warned so."""
    from groundsieve.core.raster.crs import check_lengths_unit
    said = check_lengths_unit("uav.laz", None, (9.001, 47.002, 9.004, 47.005))
    assert said.startswith("uav.laz: no CRS in the file, and its coordinates (x 9.001 to 9.004") and "degrees" in said
    assert check_lengths_unit("site.laz", None, (-20.0, -20.0, 20.0, 20.0)) == \
        "site.laz: no CRS in the file; outputs have none either."


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
    said = unit_warning("ft.laz", pyproj.CRS("EPSG:2249+8228").to_wkt())
    assert said.startswith("ft.laz: the CRS's unit is US survey foot")
    assert said.endswith("(where the parameters say m, read one US survey foot); a ground filter's defaults and a "
                         "preset's lengths, which are metres, are converted to it.")  # values set: "CELL 1 m" is 1 ft
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


def _geokey_las(path, keys, z_factor=1.0):
    """A LAS 1.2 file whose CRS is given by GeoTIFF keys only (the usual pre-1.4 delivery)."""
    import struct

    import laspy
    import numpy as np

    from groundsieve.core.synthetic import SceneSpec, make_scene
    scene = make_scene(SceneSpec(size_m=60.0, density_per_m2=2.0, seed=3))
    data = [1, 1, 0, len(keys)]
    for key, value in keys:
        data += [key, 0, 1, value]
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales, header.offsets = np.array([0.01, 0.01, 0.01]), np.array([500000.0, 5600000.0, 0.0])
    header.vlrs.append(laspy.VLR(user_id="LASF_Projection", record_id=34735, description="GeoKeyDirectoryTag",
                                 record_data=struct.pack(f"<{len(data)}H", *data)))
    las = laspy.LasData(header)
    las.x, las.y, las.z = scene.x + 500000.0, scene.y + 5600000.0, scene.z / z_factor
    las.classification = scene.classification
    las.write(str(path))
    return path


def test_the_vertical_part_of_a_crs_given_by_geotiff_keys_is_kept(tmp_path):
    """laspy reads only the horizontal CRS of GeoTIFF keys: a LAS 1.2 file of NAD83 / UTM 17N with
    NAVD88 heights in US survey feet (keys 3072, 4096 and 4099, as LAStools writes them: NAVD88's code
    5703 in metres beside the units key) ran without a word with its thresholds read in feet, and
    its DTM said metres with no vertical datum (a flood modeller)."""
    import laspy
    import pyproj

    from groundsieve.core.io.clouds import header_crs_wkt

    def crs(name, keys):
        wkt = header_crs_wkt(laspy.open(str(_geokey_las(tmp_path / name, keys))).header)
        return pyproj.CRS(wkt)

    utm = [(1024, 1), (1025, 1), (3072, 26917)]
    lastools = crs("lastools.las", utm + [(4096, 5703), (4099, 9003)])
    assert lastools.is_compound and lastools.sub_crs_list[0].to_epsg() == 26917
    assert lastools.sub_crs_list[1].datum.name == "North American Vertical Datum 1988"
    assert [a.unit_name for a in lastools.axis_info] == ["metre", "metre", "US survey foot"]
    epsg = crs("epsg.las", utm + [(4096, 6360), (4099, 9003)])  # NAVD88 height (ftUS) itself
    assert epsg.sub_crs_list[1].to_epsg() == 6360
    unit_only = crs("ft.las", utm + [(4096, 32767), (4099, 9002)])  # user-defined datum, international feet
    assert unit_only.is_compound and unit_only.axis_info[2].unit_name == "foot"
    assert crs("plain.las", utm).to_epsg() == 26917  # no vertical keys: as laspy reads it
    assert crs("odd.las", utm + [(4096, 26917)]).to_epsg() == 26917  # not a vertical CRS: ignored
    # a units key alone, in the unit of x and y, adds nothing: LAStools writes it (metres) into nearly
    # every file, and "+ unknown height (metre)" told two tiles of one survey apart and took the EPSG
    # code off their DTMs (a code reviewer)
    assert crs("units_m.las", utm + [(4099, 9001)]).to_epsg() == 26917
    # a vertical CRS named by its code is kept in any unit (a surveyor: LAStools' "+ CGVD28 height"
    # lost its datum, where the same CRS as LAS 1.4 WKT kept it)
    for name, keys in (("navd88_m.las", [(4096, 5703)]), ("both_m.las", [(4096, 5703), (4099, 9001)])):
        both = crs(name, utm + keys)
        assert both.is_compound and [c.to_epsg() for c in both.sub_crs_list] == [26917, 5703], name
    # a 3D geographic CRS with a vertical key keeps its CRS (the compound failed and the whole CRS went)
    assert crs("geo3d.las", [(1024, 2), (1025, 1), (2048, 4979), (4099, 9001)]) is not None


def test_a_geotiff_keys_file_in_us_survey_feet_is_warned_and_its_dtm_says_so(tmp_path):
    from osgeo import gdal

    from groundsieve.core.engine.workflow import DTMOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.progress import WARNING_PREFIX
    src = _geokey_las(tmp_path / "navd88ft.las", [(1024, 1), (1025, 1), (3072, 26917), (4096, 5703), (4099, 9003)],
                      z_factor=1200 / 3937)
    lines = []
    run_ground_filter(str(src), str(tmp_path / "o.las"), SMRF(), dtm_path=str(tmp_path / "o.tif"),
                      dtm=DTMOptions(), log=lines.append)
    assert any(line.startswith(WARNING_PREFIX) and "navd88ft.las: the heights are in US survey foot" in line
               for line in lines), lines
    dtm = gdal.Open(str(tmp_path / "o.tif"))
    assert dtm.GetRasterBand(1).GetUnitType() == "US survey foot"
    assert "North American Vertical Datum 1988" in dtm.GetProjection()


def test_a_vertical_datum_named_by_geotiff_keys_reaches_the_dtm_without_a_unit_warning(tmp_path):
    """A LAS 1.2 file of UTM 17N + NAVD88 height (keys 3072 and 4096, heights in metres, as LAStools
    writes them) made a DTM of plain UTM 17N: the delivery lost its vertical datum (a surveyor)."""
    from osgeo import gdal, osr

    from groundsieve.core.engine.workflow import DTMOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.progress import WARNING_PREFIX
    src = _geokey_las(tmp_path / "navd88m.las", [(1024, 1), (1025, 1), (3072, 26917), (4096, 5703)])
    lines = []
    run_ground_filter(str(src), str(tmp_path / "o.las"), SMRF(), dtm_path=str(tmp_path / "o.tif"),
                      dtm=DTMOptions(), log=lines.append)
    assert not [line for line in lines if line.startswith(WARNING_PREFIX)], lines
    dtm = gdal.Open(str(tmp_path / "o.tif"))
    srs = osr.SpatialReference(wkt=dtm.GetProjection())
    assert srs.IsCompound() and srs.GetAuthorityCode("PROJCS") == "26917", dtm.GetProjection()
    assert srs.GetAuthorityCode("VERT_CS") == "5703"
    assert dtm.GetRasterBand(1).GetUnitType() == "m"


def test_a_cloud_in_us_survey_feet_runs_the_defaults_in_metres_converted(tmp_path):
    """A state-plane cloud in US survey feet ran SMRF's defaults as feet: an 18 ft window left 16,566 of
    23,305 building points ground (a surveyor: 3.95 % total error, 0.95 % converted by hand). The
    lengths left at their defaults are now converted; a value set otherwise is read in feet."""
    import numpy as np
    import pyproj
    from osgeo import gdal

    import laspy
    from groundsieve.core.engine.workflow import DTMOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.io import new_las, write_las
    from groundsieve.core.synthetic import SceneSpec, make_scene
    ft = 1200.0 / 3937.0
    scene = make_scene(SceneSpec(size_m=120.0, density_per_m2=4.0, seed=5, buildings_per_ha=8.0))
    runs = {}
    for name, crs, factor in (("m", pyproj.CRS.from_epsg(32617).to_wkt(), 1.0),
                              ("ft", pyproj.CRS.from_epsg(2264).to_wkt(), ft)):  # NAD83 / North Carolina (ftUS)
        src = tmp_path / f"{name}.las"
        write_las(new_las((scene.x - scene.x.min()) / factor + 2000000.0, (scene.y - scene.y.min()) / factor + 600000.0,
                          scene.z / factor, crs_wkt=crs, scale=0.001), str(src))
        lines = []
        run_ground_filter(str(src), str(tmp_path / f"{name}_c.las"), SMRF(), dtm_path=str(tmp_path / f"{name}.tif"),
                          dtm=DTMOptions(), log=lines.append)
        runs[name] = np.asarray(laspy.read(str(tmp_path / f"{name}_c.las")).classification) == 2
        runs[name + " log"] = lines
        runs[name + " cell"] = gdal.Open(str(tmp_path / f"{name}.tif")).GetGeoTransform()[1]
    said = [line for line in runs["ft log"] if "lengths in metres (the defaults, a preset's) are converted" in line]
    assert len(said) == 1 and "WINDOW 59.05" in said[0] and "THRESHOLD 1.64" in said[0] and "DTM cell 3 (the whole number nearest 1 m, so that the cells fall on whole ft)" in said[0]
    assert not any("are converted" in line for line in runs["m log"])
    assert runs["ft cell"] == 3.0 and runs["m cell"] == 1.0  # (whole feet: a surveyor's 3.2808 ft lattice)
    truth = scene.classification == 2
    errors = {k: np.mean(runs[k] != truth) for k in ("m", "ft")}
    assert errors["ft"] < errors["m"] + 0.003, errors  # as good as the metric run
    # a value set otherwise than the default is read in feet, as unit_warning says
    lines = []
    run_ground_filter(str(tmp_path / "ft.las"), str(tmp_path / "ft_w.las"), SMRF(window_m=18.5), log=lines.append)
    said = [line for line in lines if "are converted" in line][0]
    assert "WINDOW" not in said and "CELL 3.281" in said
    set_by_hand = np.asarray(laspy.read(str(tmp_path / "ft_w.las")).classification) == 2
    assert np.mean(set_by_hand != truth) > errors["ft"] + 0.01  # an 18.5 ft window keeps roofs


def test_a_preset_on_a_cloud_in_feet_has_every_length_converted_and_what_is_typed_is_feet(tmp_path):
    """uav-photogrammetry-smrf on a cloud in feet had its cell (equal to the default) converted and its
    window, threshold and scalar read as feet (a code reviewer: 12.4 % total error against 0.49 % in
    metres). A preset's values are metres, as the defaults are; what the user typed is in the CRS's unit."""
    import pyproj

    from groundsieve.core.engine import parameters as P
    from groundsieve.core.engine.cli import build_parser, options_from
    from groundsieve.core.engine.presets import load_preset
    from groundsieve.core.engine.workflow import defaults_in_crs_unit
    ft = 1200.0 / 3937.0
    feet = pyproj.CRS.from_epsg(2264).to_wkt()
    preset = load_preset("uav-photogrammetry-smrf.json", "smrf")
    lines = []
    converted, _dtm = defaults_in_crs_unit(preset.build(), None, feet, "ft.laz", lines.append)
    for field in ("cell_size_m", "window_m", "elevation_threshold_m", "elevation_scalar"):
        assert getattr(converted, field) == pytest.approx(getattr(preset.build(), field) / ft), field
    assert converted.slope == preset.build().slope and converted.low_outlier_slope == 1.0  # no lengths
    assert defaults_in_crs_unit(converted, None, feet, "ft.laz", lines.append)[0] == converted  # once only
    assert len(lines) == 1
    # typed on the command line: in feet, even at the default; the rest of the preset in metres
    args = build_parser().parse_args(["smrf", "--input", "ft.laz", "--output", "o.laz", "--preset",
                                      "uav-photogrammetry-smrf.json", "--cell", "1", "--window", "40"])
    algorithm, _options, _dtm = options_from(args)
    assert P.user_set(algorithm) == {"cell_size_m", "window_m"}
    got, _dtm = defaults_in_crs_unit(algorithm, None, feet, "ft.laz", lambda _l: None)
    assert (got.cell_size_m, got.window_m) == (1.0, 40.0)
    assert got.elevation_threshold_m == pytest.approx(preset.values["elevation_threshold_m"] / ft)


def test_tune_on_a_patch_in_feet_tunes_in_metres(tmp_path):
    """Tune on a patch in feet searched 3-49 ft windows and wrote a preset of feet that every other run
    reads as metres (a code reviewer). The patch is tuned in metres, and the log says so."""
    import numpy as np
    import pyproj

    from groundsieve.core.engine.tune import TuneOptions, tune
    from groundsieve.core.io import new_las, write_las
    from groundsieve.core.synthetic import SceneSpec, make_scene
    ft = 1200.0 / 3937.0
    scene = make_scene(SceneSpec(size_m=60.0, density_per_m2=3.0, seed=8, buildings_per_ha=6.0))
    src = tmp_path / "patch_ft.las"
    write_las(new_las((scene.x - scene.x.min()) / ft + 2000000.0, (scene.y - scene.y.min()) / ft + 600000.0,
                      scene.z / ft, crs_wkt=pyproj.CRS.from_epsg(2264).to_wkt(), scale=0.001,
                      classification=np.where(scene.classification == 2, 2, 1).astype(np.uint8)), str(src))
    lines = []
    result = tune(str(src), "smrf", TuneOptions(budget=4, blocks=2), log=lines.append)
    assert any("the patch is tuned in metres" in line for line in lines), lines
    assert 3.0 <= result.best_values["window_m"] <= 49.0 and result.best_values["cell_size_m"] == 1.0


@pytest.mark.parametrize("name", ["csf", "ptd", "smrf"])
def test_a_filter_in_feet_classifies_as_in_metres(tmp_path, name):
    """CSF's and PTD's built-in lengths (the cloth's gravity and start, PTD's support radius and
    thinning) stayed metres read as feet with the parameters converted: CSF 1.34 -> 1.83 %, PTD 1.09
    -> 1.23 % total error on a scene in feet (a code reviewer). The same scene in metres and in feet,
    its origin at 0 so that every grid falls on the same ground, classifies alike."""
    import laspy
    import numpy as np
    import pyproj

    from groundsieve.core.engine import parameters as P
    from groundsieve.core.engine.workflow import run_ground_filter
    from groundsieve.core.io import new_las, write_las
    from groundsieve.core.synthetic import SceneSpec, make_scene
    ft = 1200.0 / 3937.0
    scene = make_scene(SceneSpec(size_m=80.0, density_per_m2=4.0, seed=12, buildings_per_ha=6.0))
    x, y = scene.x - np.floor(scene.x.min()), scene.y - np.floor(scene.y.min())
    got = {}
    for unit, crs, factor in (("m", 32617, 1.0), ("ft", 2264, ft)):
        src = tmp_path / f"{unit}.las"
        write_las(new_las(x / factor, y / factor, scene.z / factor, crs_wkt=pyproj.CRS.from_epsg(crs).to_wkt(),
                          scale=1e-4), str(src))
        run_ground_filter(str(src), str(tmp_path / f"{unit}_c.las"), P.filter_class(name)())
        got[unit] = np.asarray(laspy.read(str(tmp_path / f"{unit}_c.las")).classification) == 2
    assert np.mean(got["m"] == got["ft"]) >= 0.999, np.mean(got["m"] == got["ft"])


def test_a_typed_dtm_cell_is_in_feet_and_the_default_is_converted(tmp_path):
    """--dtm-cell 1 on a cloud in feet made 3.28 ft cells where --dtm-cell 2 made 2 ft (a code reviewer). The
    default 1 m is 3 ft, whole feet (its 3.2808 ft cells fell on a lattice no other DTM in feet shares)."""
    import pyproj

    from groundsieve.core.engine.cli import build_parser, options_from
    from groundsieve.core.engine.workflow import defaults_in_crs_unit
    feet = pyproj.CRS.from_epsg(2264).to_wkt()
    for argv, cell in (([], 3.0), (["--dtm-cell", "1"], 1.0), (["--dtm-cell", "2"], 2.0)):
        args = build_parser().parse_args(["smrf", "--input", "ft.laz", "--output", "o.laz", *argv])
        _algorithm, _options, dtm = options_from(args)
        _same, converted = defaults_in_crs_unit(None, dtm, feet, "ft.laz", lambda _l: None)
        assert converted.cell_size_m == cell, argv


@pytest.mark.parametrize("tiled", [False, True])
def test_the_dtm_notes_of_a_cloud_in_feet_are_in_feet(tmp_path, tiled):
    """In a run in feet the isolated pits were cells 0.5 ft below the others (15 cm, not 0.5 m) and the
    notes said "m" for feet (a code reviewer)."""
    import numpy as np
    import pyproj

    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.io import new_las, write_las
    from groundsieve.core.synthetic import SceneSpec, make_scene
    ft = 1200.0 / 3937.0
    scene = make_scene(SceneSpec(size_m=120.0, density_per_m2=3.0, seed=4, buildings_per_ha=0.0, trees_per_ha=0.0))
    rng = np.random.default_rng(3)
    z = scene.z.copy()
    deep = rng.choice(len(z), 8, replace=False)
    z[deep] -= 2.5  # low points 2.5 m deep: pits
    shallow = rng.choice(np.setdiff1d(np.arange(len(z)), deep), 8, replace=False)
    z[shallow] -= 0.3  # 0.3 m: no pit (it was one in feet: 0.98 ft > 0.5)
    src = tmp_path / "ft.las"
    write_las(new_las((scene.x - scene.x.min()) / ft + 2000000.0, (scene.y - scene.y.min()) / ft + 600000.0, z / ft,
                      crs_wkt=pyproj.CRS.from_epsg(2264).to_wkt(), scale=0.001), str(src))
    lines = []
    options = FilterOptions(tiling=TileOptions(tile_size_m=200.0, workers=1, parallel="threads")) if tiled else FilterOptions()
    run_ground_filter(str(src), None, SMRF(), dtm_path=str(tmp_path / "d.tif"), dtm=DTMOptions(), options=options,
                      log=lines.append)
    pits = [line for line in lines if "isolated pit(s)" in line]
    assert len(pits) == 1 and "cells more than 1.64 ft below" in pits[0], pits
    count = int(pits[0].split("DTM: ")[1].split(" isolated")[0])
    assert 1 <= count <= 8, pits  # the deep ones only


def _keyed_las(path, keys, doubles=(), text=b"", feet=False):
    """A LAS 1.2 file whose CRS is GeoTIFF keys ``[(key, location, count, value)]`` with their doubles and
    ASCII parameters; coordinates in US survey feet with ``feet``."""
    import struct

    import laspy
    import numpy as np

    from groundsieve.core.synthetic import SceneSpec, make_scene
    scene = make_scene(SceneSpec(size_m=60.0, density_per_m2=2.0, seed=3))
    f = 1200 / 3937 if feet else 1.0
    data = [1, 1, 0, len(keys)]
    for key in keys:
        data += list(key)
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales, header.offsets = np.array([0.01, 0.01, 0.01]), np.array([500000.0 // f, 5600000.0 // f, 0.0])
    header.vlrs.append(laspy.VLR(user_id="LASF_Projection", record_id=34735, description="GeoKeyDirectoryTag",
                                 record_data=struct.pack(f"<{len(data)}H", *data)))
    if doubles:
        header.vlrs.append(laspy.VLR(user_id="LASF_Projection", record_id=34736, description="GeoDoubleParamsTag",
                                     record_data=struct.pack(f"<{len(doubles)}d", *doubles)))
    if text:
        header.vlrs.append(laspy.VLR(user_id="LASF_Projection", record_id=34737, description="GeoAsciiParamsTag",
                                     record_data=text))
    las = laspy.LasData(header)
    las.x, las.y, las.z = (scene.x + 500000.0) / f, (scene.y + 5600000.0) / f, scene.z / f
    las.classification = scene.classification
    las.write(str(path))
    return path


#: a transverse Mercator in US survey feet without EPSG code, as LAStools' -tm writes it: user-defined keys
USER_DEFINED_TM = [(1024, 0, 1, 1), (2048, 0, 1, 4269), (3072, 0, 1, 32767), (3074, 0, 1, 32767),
                   (3075, 0, 1, 1), (3076, 0, 1, 9003), (3080, 34736, 1, 0), (3081, 34736, 1, 1),
                   (3082, 34736, 1, 3), (3083, 34736, 1, 4), (3092, 34736, 1, 2)]
ESRI_UTM32N = (b'ESRI PE String = PROJCS["WGS_1984_UTM_Zone_32N",GEOGCS["GCS_WGS_1984",DATUM["D_WGS_1984",'
               b'SPHEROID["WGS_1984",6378137.0,298.257223563]],PRIMEM["Greenwich",0.0],UNIT["Degree",'
               b'0.0174532925199433]],PROJECTION["Transverse_Mercator"],PARAMETER["False_Easting",500000.0],'
               b'PARAMETER["False_Northing",0.0],PARAMETER["Central_Meridian",9.0],PARAMETER["Scale_Factor",0.9996],'
               b'PARAMETER["Latitude_Of_Origin",0.0],UNIT["Meter",1.0]]|\0')


def test_a_crs_of_geotiff_keys_without_epsg_code_is_read_as_pdal_reads_it(tmp_path):
    """laspy builds a CRS from the keys' EPSG codes only: user-defined keys (LAStools' -tm, TerraScan) were
    read as their bare datum, NAD83 in degrees (the DTM labelled EPSG:4269, the lengths in feet unconverted,
    "the CRS is likely wrong"); ArcGIS's PE string as no CRS; an EPSG code with a unit key of another unit
    in metres (a format reviewer). GDAL (libgeotiff, as PDAL) reads the keys (core/io/geokeys.py)."""
    import laspy
    import pyproj

    from groundsieve.core.io.clouds import header_crs_wkt

    def crs(name, *args, **kw):
        wkt = header_crs_wkt(laspy.open(str(_keyed_las(tmp_path / name, *args, **kw))).header)
        return pyproj.CRS(wkt) if wkt else None

    tm = crs("tm.las", USER_DEFINED_TM, doubles=(-81.0, 0.0, 0.9996, 1640416.667, 0.0), feet=True)
    assert tm.is_projected and tm.axis_info[0].unit_name == "US survey foot"
    assert tm.coordinate_operation.method_name == "Transverse Mercator" and tm.datum.name.startswith("North American Datum 1983")
    esri = crs("esri.las", [(1024, 0, 1, 1), (1026, 34737, len(ESRI_UTM32N) - 1, 0), (3072, 0, 1, 32767)], text=ESRI_UTM32N)
    assert esri.to_epsg() == 32632 and esri.name == "WGS 84 / UTM zone 32N"
    override = crs("override.las", [(1024, 0, 1, 1), (3072, 0, 1, 32632), (3076, 0, 1, 9003)], feet=True)
    assert override.is_projected and override.axis_info[0].unit_name == "US survey foot" and override.to_epsg() is None
    # what laspy reads right stays laspy's: an EPSG code, in its own unit or with a units key of the same
    assert crs("utm.las", [(1024, 0, 1, 1), (3072, 0, 1, 32632), (3076, 0, 1, 9001)]).to_epsg() == 32632
    assert crs("none.las", []) is None


def test_a_cloud_whose_user_defined_keys_are_in_feet_runs_in_feet_and_its_dtm_says_so(tmp_path):
    from osgeo import osr

    from groundsieve.core.engine.workflow import DTMOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.progress import WARNING_PREFIX
    src = _keyed_las(tmp_path / "tm.las", USER_DEFINED_TM, doubles=(-81.0, 0.0, 0.9996, 1640416.667, 0.0), feet=True)
    lines = []
    run_ground_filter(str(src), str(tmp_path / "o.las"), SMRF(), dtm_path=str(tmp_path / "o.tif"),
                      dtm=DTMOptions(), log=lines.append)
    assert any("the CRS's unit is US survey foot: lengths in metres (the defaults, a preset's) are converted" in line
               for line in lines), lines
    assert not any(line.startswith(WARNING_PREFIX) and "geographic" in line for line in lines), lines
    from osgeo import gdal
    ref = osr.SpatialReference(gdal.Open(str(tmp_path / "o.tif")).GetProjection())
    assert ref.IsProjected() and ref.GetLinearUnitsName() == "US survey foot"
    assert ref.GetProjParm("central_meridian") == -81.0


@pytest.mark.parametrize("tiled", [False, True])
def test_heights_in_feet_of_an_unknown_datum_leave_no_aux_xml_and_the_dtm_keeps_their_unit(tmp_path, tiled):
    """UTM in metres with heights in US survey feet by the units key alone: GeoTIFF keys cannot name the
    vertical CRS "unknown height (US survey foot)", and GDAL wrote the band's unit into a hidden
    .NAME...part.tif.aux.xml beside the temporary file, one more each run, the DTM without its unit (a
    format reviewer)."""
    from osgeo import gdal

    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    folder = tmp_path / "in"
    folder.mkdir()
    src = _geokey_las(folder / "ft.las", [(1024, 1), (1025, 1), (3072, 32632), (4099, 9003)], z_factor=1200 / 3937)
    out = tmp_path / "out"
    out.mkdir()
    options = FilterOptions(tiling=TileOptions(tile_size_m=30.0, workers=1)) if tiled else FilterOptions()
    for _ in range(2):
        run_ground_filter(str(src), str(out / "o.las"), SMRF(), dtm_path=str(out / "o.tif"), dtm=DTMOptions(),
                          options=options)
    assert sorted(os.listdir(out)) == ["o.las", "o.tif"]
    dtm = gdal.Open(str(out / "o.tif"))
    assert dtm.GetRasterBand(1).GetUnitType() == "US survey foot" and "32632" in dtm.GetProjection()


@pytest.mark.parametrize("tiled", [False, True])
def test_a_wkt_record_and_geotiff_keys_that_disagree_are_warned_about(tmp_path, tiled):
    """A stale GeoTIFF key directory beside a WKT record (UTM 32N against 33N) ran without a word, the DTM
    placed by the WKT (a format reviewer). The WKT is still taken; the run says the two disagree."""
    import laspy
    import pyproj

    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    options = FilterOptions(tiling=TileOptions(tile_size_m=30.0, workers=1)) if tiled else FilterOptions()
    said = {}
    for name, epsg in (("stale", 32633), ("same", 32632)):
        src = _geokey_las(tmp_path / f"{name}.las", [(1024, 1), (1025, 1), (3072, 32632)])
        las = laspy.read(str(src))
        las.header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(pyproj.CRS.from_epsg(epsg).to_wkt()))
        las.write(str(src))
        run = run_ground_filter(str(src), str(tmp_path / f"{name}_out.las"), SMRF(), options=options)
        said[name] = [w for w in run.warnings if "CRS records disagree" in w]
        assert pyproj.CRS.from_wkt(run.crs_wkt).to_epsg() == epsg
    assert said["same"] == []
    assert said["stale"] == [f"{tmp_path / 'stale.las'}: its two CRS records disagree: the WKT record says WGS 84 / "
                             "UTM zone 33N, the GeoTIFF keys WGS 84 / UTM zone 32N. The WKT is taken, as LAS 1.4 and "
                             "PDAL take it: check which is right, and rewrite the file with that one before you trust "
                             "the DTM's place."]


def test_a_dtm_keeps_the_vertical_crs_gdal_can_write_and_its_unit_always(tmp_path):
    """GDAL decides what GeoTIFF keys hold (core/raster/crs.py geotiff_crs tries it): a vertical CRS they
    cannot hold (NAVD88 height (ftUS) without an ID) left a .aux.xml beside the temporary file and a DTM
    without its unit; one they can (EGM96 height in feet, NAVD88 under another name) was dropped by a rule
    on EPSG codes (a code reviewer)."""
    import numpy as np
    import pyproj
    from osgeo import gdal
    from pyproj.crs import CompoundCRS, VerticalCRS
    from pyproj.crs.coordinate_system import VerticalCS

    from groundsieve.core.grids.spec import GridSpec
    from groundsieve.core.raster.geotiff import write_geotiff

    def compound(name, datum, axis):
        return CompoundCRS(f"UTM + {name}", [pyproj.CRS.from_epsg(26917), VerticalCRS(
            name, datum=datum, vertical_cs=VerticalCS(axis=axis))]).to_wkt()
    cases = {"navd88_ftus_noid": (compound("NAVD88 height (ftUS)", "North American Vertical Datum 1988",
                                           "GRAVITY_HEIGHT_US_FT"), "US survey foot", None),
             "egm96_ft": (compound("EGM96 height (ft)", "EGM96 geoid", "GRAVITY_HEIGHT_FT"), "ft", "EGM96 geoid"),
             "navd88_renamed": (compound("NAVD88 (Geoid18)", "North American Vertical Datum 1988", "GRAVITY_HEIGHT"),
                                "m", "North American Vertical Datum 1988")}
    grid = GridSpec(500000.0, 4000010.0, 1.0, 10, 10)
    gdal.SetConfigOption("GTIFF_REPORT_COMPD_CS", "YES")
    try:
        for name, (wkt, unit, datum) in cases.items():
            path = tmp_path / f"{name}.tif"
            write_geotiff(str(path), np.ones((10, 10), "float32"), grid, crs_wkt=wkt, elevation=True)
            ds = gdal.Open(str(path))
            crs = pyproj.CRS.from_wkt(ds.GetProjection())
            assert ds.GetRasterBand(1).GetUnitType() == unit, name
            assert (crs.sub_crs_list[1].datum.name if crs.is_compound else None) == datum, name
            ds = None
    finally:
        gdal.SetConfigOption("GTIFF_REPORT_COMPD_CS", None)
    assert sorted(os.listdir(tmp_path)) == sorted(f"{n}.tif" for n in cases)


def test_geotiff_keys_that_name_no_horizontal_crs_are_still_no_crs(tmp_path):
    """Units alone (LAStools writes them into nearly every file): GDAL made them an "unnamed" engineering CRS,
    which hid the "no CRS" warning, took feet for metres and, beside a WKT record, was a false "the two CRS
    records disagree" (a code reviewer). A bad ESRI PE string with GDAL's exceptions on refused the file."""
    import subprocess
    import sys

    import laspy
    import pyproj

    from groundsieve.core.io.clouds import crs_records_conflict, header_crs_wkt
    units = [(1024, 0, 1, 1), (1025, 0, 1, 1), (3076, 0, 1, 9002), (4099, 0, 1, 9002)]
    src = _keyed_las(tmp_path / "units.las", units)
    assert header_crs_wkt(laspy.open(str(src)).header) is None
    las = laspy.read(str(src))
    las.header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(pyproj.CRS.from_epsg(32632).to_wkt()))
    las.write(str(tmp_path / "both.las"))
    header = laspy.open(str(tmp_path / "both.las")).header
    assert pyproj.CRS.from_wkt(header_crs_wkt(header)).to_epsg() == 32632 and crs_records_conflict(header) == ""
    bad = _keyed_las(tmp_path / "bad.las", [(1024, 0, 1, 1), (1026, 34737, 26, 0), (3072, 0, 1, 32767)],
                     text=b"ESRI PE String = garbage|\0")
    code = ("from osgeo import gdal, osr\ngdal.UseExceptions(); osr.UseExceptions()\nimport laspy\n"
            "from groundsieve.core.io.lasfiles import scan_header\n"
            f"print(scan_header({str(bad)!r}).crs_wkt)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "None", out.stderr[-2000:]
