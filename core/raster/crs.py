"""Coordinates in WGS 84 (longitude, latitude), where a format asks for them (GeoJSON/STAC)."""
from __future__ import annotations

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


def horizontal_unit(crs_wkt: Optional[str]) -> Optional[str]:
    """The unit lengths are read in under ``crs_wkt``: "metres", "degrees", or GDAL's name of the
    linear unit (e.g. "US survey foot"); None when there is no CRS or it cannot be read (no GDAL)."""
    if not crs_wkt:
        return None
    try:
        from osgeo import osr
    except ImportError:  # the command line without GDAL: the CRS cannot be read
        return None
    ref = osr.SpatialReference()
    try:
        if ref.ImportFromWkt(crs_wkt) != 0:
            return None
    except RuntimeError:
        return None
    if ref.IsGeographic():
        return "degrees"
    if ref.IsProjected() and abs(ref.GetLinearUnits() - 1.0) > 1e-12:
        return ref.GetLinearUnitsName() or f"{ref.GetLinearUnits():g} m"
    return "metres"


def unit_warning(path: str, crs_wkt: Optional[str], lengths: str = "every length parameter") -> Optional[str]:
    """What to tell the user when the cloud has no CRS, or one whose unit is not the metre (the
    filters read their lengths in the CRS's unit); None for a CRS in metres."""
    if not crs_wkt:
        return f"{path}: no CRS in the file; outputs have none either."
    unit = horizontal_unit(crs_wkt)
    if unit is None or unit == "metres":
        return None
    return f"{path}: the CRS's unit is {unit}, not metres: {lengths} was read in that unit."
