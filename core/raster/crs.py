"""Coordinates in WGS 84 (longitude, latitude), where a format asks for them (GeoJSON/STAC)."""
from __future__ import annotations

import functools
from typing import Optional, Tuple


def lonlat_box(x0: float, y0: float, x1: float, y1: float, crs_wkt: Optional[str]) -> Optional[Tuple[float, ...]]:
    """The box (lon0, lat0, lon1, lat1) in WGS 84 covering the box (x0, y0, x1, y1) in ``crs_wkt``
    (its corners and edge midpoints transformed); None without a CRS or where PROJ cannot do it."""
    if not crs_wkt:
        return None
    from osgeo import osr
    source, target = osr.SpatialReference(), osr.SpatialReference()
    try:
        if source.ImportFromWkt(crs_wkt) != 0:
            return None
        target.ImportFromEPSG(4326)
        for ref in (source, target):
            ref.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)  # x = longitude, as GeoJSON
        transform = osr.CoordinateTransformation(source, target)
        xm, ym = (x0 + x1) / 2, (y0 + y1) / 2
        points = [(x, y) for x in (x0, xm, x1) for y in (y0, ym, y1)]
        lonlat = [transform.TransformPoint(float(x), float(y))[:2] for x, y in points]
    except RuntimeError:
        return None
    lons, lats = [p[0] for p in lonlat], [p[1] for p in lonlat]
    return min(lons), min(lats), max(lons), max(lats)


def _spatial_reference(crs_wkt: Optional[str]):
    """``crs_wkt`` as GDAL's ``osr.SpatialReference``; None when there is no CRS, no GDAL (the
    command line can run without it) or a WKT GDAL cannot read."""
    if not crs_wkt:
        return None
    try:
        from osgeo import osr
    except ImportError:
        return None
    ref = osr.SpatialReference()
    try:
        if ref.ImportFromWkt(crs_wkt) != 0:
            return None
    except RuntimeError:
        return None
    return ref


def horizontal_unit(crs_wkt: Optional[str]) -> Optional[str]:
    """The unit lengths are read in under ``crs_wkt``: "metres", "degrees", or GDAL's name of the
    linear unit (e.g. "US survey foot"); None when there is no CRS or it cannot be read (no GDAL)."""
    ref = _spatial_reference(crs_wkt)
    if ref is None:
        return None
    if ref.IsGeographic():
        return "degrees"
    if (ref.IsProjected() or ref.IsLocal()) and abs(ref.GetLinearUnits() - 1.0) > 1e-12:
        return ref.GetLinearUnitsName() or f"{ref.GetLinearUnits():g} m"  # (a local CRS in feet too)
    return "metres"


def vertical_unit(crs_wkt: Optional[str]) -> Optional[str]:
    """The unit of the heights under a compound CRS (its vertical part): "metres" or GDAL's name
    (e.g. "US survey foot"); None without a vertical part (heights then in the horizontal unit)."""
    ref = _spatial_reference(crs_wkt)
    factor = _vertical_factor(ref)
    if factor is None:
        return None
    if abs(factor - 1.0) <= 1e-12:
        return "metres"
    return ref.GetAttrValue("VERT_CS|UNIT") or f"{factor:g} m"


def _vertical_factor(ref) -> Optional[float]:
    """Metres per unit of a compound CRS's vertical part; None without one."""
    if ref is None or not ref.IsCompound():
        return None
    return ref.GetTargetLinearUnits("VERT_CS") or None


def heights_differ(crs_wkt: Optional[str]) -> bool:
    """Whether the heights of a compound CRS are in another unit than x and y (by size: US survey
    and international feet, 2 ppm apart, are the same unit for a filter's thresholds)."""
    ref = _spatial_reference(crs_wkt)
    vertical = _vertical_factor(ref)
    if vertical is None or ref.IsGeographic():
        return False
    return abs(vertical / ref.GetLinearUnits() - 1.0) > 1e-5


def metres_per_unit(crs_wkt: Optional[str]) -> Optional[float]:
    """Metres per unit of a projected or local CRS whose x, y and heights share one linear unit other
    than the metre (0.3048 for feet, 0.3048006 for US survey feet); None otherwise (metres, no CRS,
    degrees, heights in another unit than x and y: those are said by :func:`unit_warning`)."""
    ref = _spatial_reference(crs_wkt)
    if ref is None or ref.IsGeographic() or not (ref.IsProjected() or ref.IsLocal()) or heights_differ(crs_wkt):
        return None
    factor = ref.GetLinearUnits()
    return factor if factor > 0 and abs(factor - 1.0) > 1e-12 else None


def elevation_unit(crs_wkt: Optional[str]) -> str:
    """A raster band's unit type for elevations: the vertical part's unit under a compound CRS, else
    the CRS's linear unit (the unit every length of a run is read in): "m", "ft" or "US survey foot";
    "" when there is no CRS or it is not linear."""
    ref = _spatial_reference(crs_wkt)
    if ref is None or not ref.IsProjected():
        return ""
    factor = _vertical_factor(ref) or ref.GetLinearUnits()
    for unit, metres in (("m", 1.0), ("ft", 0.3048), ("US survey foot", 1200.0 / 3937.0)):
        if abs(factor - metres) < 1e-9:
            return unit
    return ""


def geotiff_crs(crs_wkt: Optional[str]) -> Optional[str]:
    """The CRS a GeoTIFF is given: ``crs_wkt``, but for a compound CRS whose vertical part GeoTIFF keys cannot
    hold (GDAL's own test: :func:`_keys_hold`), its horizontal part. GDAL dropped such a vertical CRS (an
    unknown datum in US survey feet, as a LAS 1.2 file's units key gives heights in feet; a WKT's NAVD88
    height (ftUS) without an ID) and put the band's unit and description into a .aux.xml beside the
    temporary file, which never reached the DTM: one more hidden file a run, a DTM without its unit (a
    format reviewer, then a code reviewer). The unit stays the band's unit type; the vertical CRSs GDAL
    writes (EGM96 height in feet, NAVD88 (Geoid18): a code reviewer) are kept."""
    if not crs_wkt:
        return crs_wkt
    import pyproj
    try:
        crs = pyproj.CRS.from_wkt(crs_wkt)
    except pyproj.exceptions.CRSError:
        return crs_wkt
    if not crs.is_compound or len(crs.sub_crs_list) != 2 or _keys_hold(crs_wkt, elevation_unit(crs_wkt)):
        return crs_wkt
    return crs.sub_crs_list[0].to_wkt()


@functools.lru_cache(maxsize=32)
def _keys_hold(crs_wkt: str, unit: str) -> bool:
    """Whether GDAL writes ``crs_wkt`` into a GeoTIFF's keys whole, with a band of heights in ``unit``: a
    one-pixel GeoTIFF in memory so made is written; GDAL puts what its keys cannot hold into a .aux.xml."""
    import uuid
    from osgeo import gdal
    name = f"/vsimem/groundsieve-crs-{uuid.uuid4().hex}.tif"
    gdal.PushErrorHandler("CPLQuietErrorHandler")
    try:
        mem = gdal.GetDriverByName("MEM").Create("", 1, 1, 1, gdal.GDT_Float32)  # (copied, as the DTMs are)
        mem.SetProjection(crs_wkt)
        mem.SetGeoTransform([0.0, 1.0, 0.0, 1.0, 0.0, -1.0])
        mem.GetRasterBand(1).SetUnitType(unit or "m")
        gdal.Translate(name, mem, format="GTiff")
        mem = None
        return gdal.VSIStatL(name + ".aux.xml") is None
    except RuntimeError:
        return False
    finally:
        for path in (name, name + ".aux.xml"):
            if gdal.VSIStatL(path) is not None:
                gdal.Unlink(path)
        gdal.PopErrorHandler()


#: what a ground filter's run does with lengths in metres in a CRS of another unit (unit_warning's last words)
CONVERTED = "a ground filter's defaults and a preset's lengths, which are metres, are converted to it."


def unit_warning(path: str, crs_wkt: Optional[str], lengths: str = "every length parameter",
                 bounds: Optional[Tuple[float, float, float, float]] = None, converted: str = CONVERTED) -> Optional[str]:
    """What to tell the user when the cloud has no CRS, or one whose unit is not the metre (the
    filters read their lengths in the CRS's unit); None for a CRS in metres. With the points'
    ``bounds`` (x0, y0, x1, y1), a geographic CRS whose coordinates cannot be degrees is said to be
    wrong instead."""
    if not crs_wkt:
        if bounds is not None and in_degree_range(bounds) and max(bounds[2] - bounds[0], bounds[3] - bounds[1]) < 1.0:
            return (f"{path}: no CRS in the file, and its coordinates (x {bounds[0]:g} to {bounds[2]:g}, y {bounds[1]:g} "
                    f"to {bounds[3]:g}) span less than 1 unit: they look like longitudes and latitudes in degrees, "
                    "in which every length parameter (m) would be read (1 m of cell: 1 degree, 111 km). If so, "
                    "reproject the cloud to a projected CRS in metres (its UTM zone) first; outputs have no CRS.")
        return f"{path}: no CRS in the file; outputs have none either."
    unit = horizontal_unit(crs_wkt)
    if heights_differ(crs_wkt):
        return (f"{path}: the heights are in {vertical_unit(crs_wkt)} (the CRS's vertical part), x and y in {unit}: the "
                "filters' height thresholds and the DTM are read in the heights' unit, their cells and windows "
                "in x and y's. Convert the heights to the horizontal unit first (e.g. PDAL's "
                "filters.reprojection to a compound CRS in metres, or LAStools' las2las).")
    if unit is None or unit == "metres":
        return None
    if unit == "degrees" and bounds is not None and not in_degree_range(bounds):
        return (f"{path}: the file's CRS is geographic (degrees), but its coordinates (x {bounds[0]:,.0f} to "
                f"{bounds[2]:,.0f}, y {bounds[1]:,.0f} to {bounds[3]:,.0f}) cannot be one survey's longitudes and "
                "latitudes: the CRS is likely wrong, and the lengths were read in the coordinates' own unit. "
                "Assign the right CRS to the file (outputs keep the wrong one).")
    return (f"{path}: the CRS's unit is {unit}, not metres: {lengths} was read in that unit (where the parameters "
            f"say m, read one {unit}); {converted.format(unit=unit)}")


#: the widest span (degrees) a cloud in longitudes and latitudes is taken to have: a local survey in
#: metres labelled with a geographic CRS (a terrestrial scan from 0 to 50 m exported as WGS 84) spans more
DEGREE_SPAN_MAX = 5.0


def in_degree_range(bounds: Tuple[float, float, float, float]) -> bool:
    """Whether (x0, y0, x1, y1) can be longitudes and latitudes of one survey."""
    x0, y0, x1, y1 = bounds
    return (-360.0 <= x0 <= x1 <= 360.0 and -90.0 <= y0 <= y1 <= 90.0
            and x1 - x0 <= DEGREE_SPAN_MAX and y1 - y0 <= DEGREE_SPAN_MAX)


def check_lengths_unit(path: str, crs_wkt: Optional[str], bounds: Tuple[float, float, float, float],
                       lengths: str = "every length parameter (cells, windows, thresholds)") -> Optional[str]:
    """Before any work: refuse a cloud in longitudes and latitudes (a geographic CRS, coordinates in
    degrees): the filters' lengths are metres (1 m of cell would be 1 degree, 111 km); else what
    :func:`unit_warning` says (None for metres). Raises the core's ``InputError``."""
    if horizontal_unit(crs_wkt) == "degrees" and in_degree_range(bounds):
        from ..errors import InputError
        raise InputError(f"{path}: its coordinates are longitudes and latitudes in degrees (a geographic CRS), and "
                         f"{lengths} are lengths in metres: reproject the cloud to a projected CRS in metres (its "
                         "UTM zone, e.g. with PDAL's filters.reprojection or LAStools' las2las) first")
    return unit_warning(path, crs_wkt, lengths, bounds)
