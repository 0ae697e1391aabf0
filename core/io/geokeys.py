"""A LAS file's CRS from its GeoTIFF keys, read by GDAL (libgeotiff) where laspy's reader misreads them.

laspy builds a CRS from the keys' EPSG codes only. A projection without an EPSG code is written as
user-defined keys (ProjectedCSTypeGeoKey 32767 with the projection's parameters, as LAStools' ``-tm``,
TerraScan and older Riegl exports do), or as an "ESRI PE String" in a citation key (ArcGIS); an EPSG code
may come with a ProjLinearUnitsGeoKey of another unit. laspy read the first as its bare geographic datum
(NAD83 in degrees: the DTM labelled EPSG:4269, the lengths left in feet unconverted, the file blamed for a
"likely wrong" CRS), the second as no CRS, the third in metres (a format reviewer). PDAL reads all three
with libgeotiff; so does this module, through GDAL: the keys are put into a one-pixel GeoTIFF in memory,
whose CRS GDAL reads.
"""
from __future__ import annotations

import struct
import uuid
from typing import Optional

#: GeoTIFF keys (GeoTIFF 1.1): the model type, the projected CRS, its linear unit, and the citations
GT_MODEL_TYPE, PROJECTED_CRS, PROJ_LINEAR_UNITS = 1024, 3072, 3076
GT_CITATION, GEOG_CITATION, PCS_CITATION = 1026, 2049, 3073
MODEL_PROJECTED, USER_DEFINED = 1, 32767
ESRI_PE = "ESRI PE String = "
#: metres of the EPSG length units a ProjLinearUnitsGeoKey names
_UNIT_METRES = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0}

_SHORT, _ASCII, _LONG, _DOUBLE = 3, 2, 4, 12


def _tiff(directory: bytes, doubles: bytes, text: bytes) -> bytes:
    """A little-endian TIFF of one 8-bit pixel carrying the three GeoTIFF tags as given."""
    plain = [(256, _SHORT, 1, 1), (257, _SHORT, 1, 1), (258, _SHORT, 1, 8), (259, _SHORT, 1, 1),
             (262, _SHORT, 1, 1), (273, _LONG, 1, 0), (277, _SHORT, 1, 1), (278, _SHORT, 1, 1),
             (279, _LONG, 1, 1)]
    blobs = [(34735, _SHORT, len(directory) // 2, directory)]
    if doubles:
        blobs.append((34736, _DOUBLE, len(doubles) // 8, doubles))
    if text:
        blobs.append((34737, _ASCII, len(text), text))
    count = len(plain) + len(blobs)
    data_at = 8 + 2 + 12 * count + 4
    entries, data = [list(e) for e in plain], bytearray()
    for tag, kind, n, blob in blobs:
        if len(blob) <= 4:
            entries.append([tag, kind, n, blob.ljust(4, b"\0")])
        else:
            data += b"\0" * ((data_at + len(data)) % 2)
            entries.append([tag, kind, n, data_at + len(data)])
            data += blob
    pixel = data_at + len(data)
    data += b"\0"
    out = bytearray(b"II*\0" + struct.pack("<I", 8) + struct.pack("<H", count))
    for tag, kind, n, value in sorted(entries, key=lambda e: e[0]):
        if tag == 273:
            value = pixel
        if isinstance(value, bytes):
            out += struct.pack("<HHI", tag, kind, n) + value
        elif kind == _SHORT:
            out += struct.pack("<HHIHH", tag, kind, n, value, 0)
        else:
            out += struct.pack("<HHII", tag, kind, n, value)
    return bytes(out + struct.pack("<I", 0) + data)


def gdal_crs_wkt(directory: bytes, doubles: bytes = b"", text: bytes = b"") -> Optional[str]:
    """The CRS of the GeoTIFF keys ``directory`` (GeoKeyDirectoryTag's shorts, as LAS's record 34735
    holds them), with their doubles and ASCII parameters, as GDAL reads them: WKT 2, the EPSG CRS where
    PROJ finds one the same; None without GDAL or a CRS GDAL can read."""
    if len(directory) < 8:
        return None
    try:
        from osgeo import gdal, osr
    except ImportError:
        return None
    name = f"/vsimem/groundsieve-geokeys-{uuid.uuid4().hex}.tif"
    gdal.PushErrorHandler("CPLQuietErrorHandler")  # (GDAL's words for keys it cannot read stay off the console)
    try:
        gdal.FileFromMemBuffer(name, _tiff(directory, doubles, text))
        dataset = gdal.Open(name)
        ref = dataset.GetSpatialRef() if dataset is not None else None
        dataset = None
        title = (ref.GetName() or "") if ref is not None else ""
        if title.startswith(ESRI_PE):  # (GDAL keeps ArcGIS's citation as the CRS's name: the PE string itself)
            esri = osr.SpatialReference()
            try:
                if esri.SetFromUserInput(title[len(ESRI_PE):]) == 0 and (esri.IsProjected() or esri.IsGeographic()):
                    ref = esri
            except RuntimeError:  # (a PE string GDAL cannot read, where exceptions are on: the keys' CRS as GDAL has it)
                pass
        # keys that name no horizontal CRS (units alone, as LAStools writes into nearly every file) are no CRS:
        # GDAL made them an "unnamed" engineering CRS (a code reviewer)
        if ref is None or not (ref.IsProjected() or ref.IsGeographic()):
            return None
        ref = _epsg_match(ref, osr) or ref
        return ref.ExportToWkt(["FORMAT=WKT2_2019"])
    except RuntimeError:  # (where exceptions are on: keys GDAL cannot read are read as laspy reads them)
        return None
    finally:
        gdal.Unlink(name)
        gdal.PopErrorHandler()


def _epsg_match(ref, osr):
    """The EPSG CRS PROJ finds to be ``ref`` (confidence 100: the same definition, e.g. an ESRI PE string's
    "WGS_1984_UTM_Zone_32N" is EPSG:32632), else None."""
    try:
        matches = ref.FindMatches() or []
    except RuntimeError:
        return None
    for match, confidence in matches:
        if confidence >= 100 and match.GetAuthorityName(None) == "EPSG":
            epsg = osr.SpatialReference()
            if epsg.ImportFromEPSG(int(match.GetAuthorityCode(None))) == 0:
                return epsg
    return None


def laspy_misreads(keys: dict, crs) -> bool:
    """Whether laspy's CRS ``crs`` (a pyproj CRS, or None) of the GeoTIFF keys ``keys`` ({key id: value}
    of the directory's short values) leaves out what the keys say: a projection without EPSG code (or a
    citation GDAL reads), a projected model read as geographic or not at all, a ProjLinearUnitsGeoKey of
    another unit than the CRS's."""
    if not keys:
        return False
    if crs is None or keys.get(PROJECTED_CRS) == USER_DEFINED:
        return True
    if keys.get(GT_MODEL_TYPE) == MODEL_PROJECTED and not crs.is_projected:
        return True
    unit = _UNIT_METRES.get(keys.get(PROJ_LINEAR_UNITS))
    if unit is not None and crs.is_projected and crs.axis_info:
        factor = crs.axis_info[0].unit_conversion_factor
        return bool(factor) and abs(factor / unit - 1) > 1e-6
    return False
