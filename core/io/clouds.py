"""Reading and writing point clouds: LAS/LAZ (laspy + lazrs) and the ISPRS text format.

Writes are atomic (``outputs.atomic_path``): the file is written under a temporary name in the target folder
and renamed over the target only when complete, so a failed or cancelled run leaves
nothing half-written. Input files are only ever opened for reading.
"""
from __future__ import annotations

import contextlib
import copy
import functools
import math
import os
import re
import warnings
from dataclasses import dataclass, field
from typing import Optional, Tuple

import numpy as np

from ..errors import GroundSieveError, InputError, InvalidParameterError, OutputError, UnsupportedFormatError
from ..progress import WARNING_PREFIX, Steps
from ..validate import check_coordinates
from .outputs import LAS_EXTENSIONS, _ext, _reason, atomic_path, check_classes_fit, check_output_path


TEXT_EXTENSIONS = (".txt",)
READ_EXTENSIONS = LAS_EXTENSIONS + TEXT_EXTENSIONS

#: ASPRS classification codes used by the filters.
CLASS_UNCLASSIFIED = 1
CLASS_GROUND = 2
NOISE_CLASSES = (7, 18)


#: the ASPRS LAS 1.4 names of the standard classes (the log and the reports name classes by them)
ASPRS_NAMES = {0: "never classified", 1: "unclassified", 2: "ground", 3: "low vegetation",
               4: "medium vegetation", 5: "high vegetation", 6: "building", 7: "low point (noise)",
               9: "water", 10: "rail", 11: "road surface", 13: "wire guard", 14: "wire conductor",
               15: "transmission tower", 16: "wire-structure connector", 17: "bridge deck", 18: "high noise",
               19: "overhead structure"}


def count_classes(classes) -> dict:
    """{class: points} of the ASPRS codes ``classes`` (one per point), the classes present only."""
    found = np.bincount(np.asarray(classes, dtype=np.intp), minlength=256)
    return {int(c): int(found[c]) for c in np.flatnonzero(found)}


def class_counts_text(counts: dict, most: Optional[int] = None, largest_first: bool = False) -> str:
    """ "1 (unclassified): 1,234, 6 (building): 56" of {class: points}, by class (or the largest first), at
    most ``most`` of them and how many more: how every log line names classes and their points."""
    items = sorted(counts.items(), key=(lambda kv: -kv[1]) if largest_first else None)
    parts = [f"{c} ({ASPRS_NAMES.get(c, 'class ' + str(c))}): {n:,}" for c, n in items[:most]]
    if most is not None and len(items) > most:
        parts.append(f"{len(items) - most} more")
    return ", ".join(parts)


def parse_classes(text, *, what: str = "classes") -> tuple:
    """ASPRS class codes from ``"7, 18"``, ``"7 18"``, ``"2-5,9"`` or ``"[7:18]"`` (PDAL's
    ``ignore`` range form) or from a sequence of ints; an empty text or ``None`` gives ``()``.
    Codes are 0-255 (point formats 6-10; formats 0-5 store 0-31). Returns sorted unique codes."""
    if text is None:
        return ()
    if isinstance(text, (int, np.integer)) and not isinstance(text, bool):
        text = [int(text)]
    if not isinstance(text, str):
        codes = []
        for value in text:
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise InvalidParameterError(f"{what}: class codes must be whole numbers (got {value!r})")
            codes.append(int(value))
    else:
        codes = []
        body = text.strip().strip("[]")
        for part in (p for p in re.split(r"[,;\s]+", body) if p):
            m = re.fullmatch(r"(\d+)(?:\s*[-:]\s*(\d+))?", part)
            if not m:
                raise InvalidParameterError(
                    f"{what}: '{part}' is not a class code or a range such as 7 or 20-25 (got '{text}')")
            lo = int(m.group(1))
            hi = int(m.group(2)) if m.group(2) is not None else lo
            if hi < lo:
                raise InvalidParameterError(f"{what}: the range '{part}' ends before it starts")
            codes.extend(range(lo, min(hi, 255) + 1) if lo <= 255 else [lo])
    bad = [c for c in codes if not 0 <= c <= 255]
    if bad:
        raise InvalidParameterError(f"{what}: class codes are 0-255 (got {bad[0]})")
    return tuple(sorted(set(codes)))


def decimals_scale(*columns, coarsest: float = 0.01, finest: float = 1e-6) -> float:
    """The coarsest LAS scale (a power of ten, at most ``coarsest``) that stores every value of
    ``columns`` exactly as written with its decimals (0.001 for millimetre coordinates), but no
    finer than the 32-bit integers of a LAS record allow over the columns' extent."""
    exponent = round(np.log10(coarsest))
    lowest = round(np.log10(finest))
    for values in columns:
        v = np.asarray(values, dtype=np.float64)
        if v.size == 0:
            continue
        span = float(v.max() - v.min())
        # LAS stores (value - offset) / scale in an int32: keep the span below 2e9 steps.
        floor_exp = int(np.ceil(np.log10(span / 2e9))) if span > 0 else lowest
        while exponent > max(lowest, floor_exp):
            q = v / 10.0 ** exponent
            if np.all(np.abs(q - np.round(q)) <= 1e-3 + 1e-13 * np.abs(q)):
                break
            exponent -= 1
    return float(10.0 ** exponent)


@dataclass
class PointCloud:
    """The arrays of one cloud (or tile), plus what is needed to write it back."""
    path: str
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    classification: np.ndarray          #: uint8, ASPRS codes as read
    return_number: np.ndarray           #: uint8; 1 where the format has none
    number_of_returns: np.ndarray       #: uint8; 1 where the format has none
    intensity: Optional[np.ndarray] = None
    crs_wkt: Optional[str] = None
    has_return_info: bool = False       #: the file carries return numbers (LAS does, ISPRS text does not)
    las: object = field(default=None, repr=False)  #: the laspy LasData, kept to write every dimension back
    reference_label: Optional[np.ndarray] = None  #: ISPRS text: 0 = ground, 1 = object
    #: bool per point: the LAS "withheld" flag ("this point should not be included in processing",
    #: bit 7 of the classification byte in point formats 0-5, a classification flag in 6-10); None = none
    withheld: Optional[np.ndarray] = None
    scale: Optional[float] = None       #: text input: the LAS scale that keeps its decimals
    notes: list = field(default_factory=list)  #: what the reader had to say about the file (to log)
    #: per-point values an algorithm took from a tile's records beyond the fields above (name -> array; e.g. a
    #: model's colour, scan angle or GPS time, core/engine/learning.ModelGround.point_attributes); None = none
    attributes: Optional[dict] = None

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def withheld_mask(self) -> np.ndarray:
        """bool per point (all False when the file has no withheld flag set)."""
        if self.withheld is None:
            return np.zeros(len(self), dtype=bool)
        return np.asarray(self.withheld, dtype=bool)

    def subset(self, mask) -> "PointCloud":
        """The points ``mask`` (bool or indices) as a cloud of their own (every dimension, the
        LAS record too), e.g. to compute features on the points that may be processed."""
        las = self.las[np.asarray(mask)] if self.las is not None else None

        def pick(a):
            return None if a is None else np.asarray(a)[mask]
        return PointCloud(path=self.path, x=self.x[mask], y=self.y[mask], z=self.z[mask],
                          classification=self.classification[mask], return_number=self.return_number[mask],
                          number_of_returns=self.number_of_returns[mask], intensity=pick(self.intensity),
                          crs_wkt=self.crs_wkt, has_return_info=self.has_return_info, las=las,
                          reference_label=pick(self.reference_label), withheld=pick(self.withheld),
                          scale=self.scale, notes=list(self.notes),
                          attributes=None if self.attributes is None else {
                              name: np.asarray(values)[mask] for name, values in self.attributes.items()})

    @property
    def xyz(self) -> np.ndarray:
        return np.column_stack([self.x, self.y, self.z])


#: share of a LAS/LAZ read's progress given to decoding its points; the rest to making the cloud's
#: arrays of them (coordinates, returns, classes: 0.3 s of 1.4 s for 5 M points in the desktop)
READ_SHARE = 0.8

#: points read or written per chunk of a LAS/LAZ file: progress is reported and cancellation
#: checked between chunks (about 0.1 s of LAZ decompression each on this machine)
CHUNK_POINTS = 500_000

#: How laspy's writer treats header texts beyond ASCII (system identifier, generating software, VLR and
#: EVLR descriptions). Vendors write Latin-1 there ("Soci\xe9t\xe9"); laspy keeps such a text as the
#: bytes it read and, told "replace", writes them back unchanged (strict, its default, it refused them
#: once the whole run was done: a format reviewer). Our own texts are ASCII.
TEXT_ERRORS = "replace"


def writable_evlrs(evlrs):
    """``evlrs`` (a laspy ``VLRList``) to give ``LasWriter.write_evlrs``, which takes no text errors
    of its own: its descriptions are written as :data:`TEXT_ERRORS` says."""
    from laspy.vlrs.vlrlist import VLRList

    class _Records(VLRList):
        def write_to(self, stream, as_extended=False, encoding_errors="strict"):
            return super().write_to(stream, as_extended=as_extended, encoding_errors=TEXT_ERRORS)

    return _Records(evlrs)


def header_crs_wkt(header) -> Optional[str]:
    """The CRS of a laspy header as WKT (from its WKT or GeoTIFF records), or None when it has none
    or none that can be parsed (a file without a usable CRS is still read). A CRS given by GeoTIFF
    keys keeps its vertical part (:func:`_with_geokey_heights`), which laspy's parser drops."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            crs = header.parse_crs()
        except Exception:
            crs = None
        crs = _crs_of_geokeys(_records(header), crs)
        if crs is None:
            return None
        try:
            return _with_geokey_heights(crs, header).to_wkt()
        except Exception:  # (the horizontal CRS is kept when no compound can be made of the keys)
            return crs.to_wkt()


def _records(header) -> list:
    """The header's VLRs and EVLRs (laspy's records), in that order."""
    return list(header.vlrs) + list(header.evlrs or [])


def crs_records_conflict(header) -> str:
    """The two CRS a header names when its WKT record and its GeoTIFF keys name different horizontal CRS
    ("WGS 84 / UTM zone 33N" and "WGS 84 / UTM zone 32N": the WKT is taken, as laspy, PDAL and LAS 1.4 have
    it); "" otherwise. A file with a stale record beside a new one ran without a word, its DTM placed by
    the WKT (a format reviewer)."""
    from laspy.vlrs.known import GeoKeyDirectoryVlr, WktCoordinateSystemVlr
    records = _records(header)
    wkt = [r for r in records if isinstance(r, WktCoordinateSystemVlr) and r.string]
    keys = [r for r in records if isinstance(r, GeoKeyDirectoryVlr)]
    if not wkt or not keys:
        return ""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            import pyproj
            by_wkt = pyproj.CRS.from_wkt(wkt[0].string)
            by_keys = _crs_of_geokeys([r for r in records if not isinstance(r, WktCoordinateSystemVlr)],
                                      keys[0].parse_crs())
        except Exception:  # (a record that cannot be read is said elsewhere, or not at all, as before)
            return ""
    if by_keys is None:
        return ""

    def horizontal(crs):
        return crs.sub_crs_list[0] if crs.is_compound else crs
    a, b = horizontal(by_wkt), horizontal(by_keys)
    if a.equals(b, ignore_axis_order=True) or (a.to_epsg() is not None and a.to_epsg() == b.to_epsg()):
        return ""
    return f"the WKT record says {a.name}, the GeoTIFF keys {b.name}"


def _geokeys(records) -> dict:
    """{key id: value} of the GeoTIFF keys whose value is in the directory itself."""
    from laspy.vlrs.known import GeoKeyDirectoryVlr
    keys = {}
    for record in records:
        if isinstance(record, GeoKeyDirectoryVlr):
            keys.update({int(k.id): int(k.value_offset) for k in record.geo_keys if int(k.tiff_tag_location) == 0})
    return keys


def _crs_of_geokeys(records, crs):
    """``crs`` (laspy's CRS of the header ``records``, or None), or the CRS GDAL reads from their GeoTIFF keys
    where laspy's leaves out what they say (core/io/geokeys.py: a projection without EPSG code, an ESRI
    PE string, a unit key); a WKT record is taken as laspy has it."""
    from laspy.vlrs.known import WktCoordinateSystemVlr
    from .geokeys import gdal_crs_wkt, laspy_misreads
    if any(isinstance(r, WktCoordinateSystemVlr) and r.string for r in records):
        return crs
    if not laspy_misreads(_geokeys(records), crs):
        return crs
    raw = {}
    for record in records:
        if getattr(record, "user_id", "") == "LASF_Projection" and record.record_id in (34735, 34736, 34737):
            raw.setdefault(record.record_id, record.record_data_bytes())
    wkt = gdal_crs_wkt(raw.get(34735, b""), raw.get(34736, b""), raw.get(34737, b""))
    if wkt is None:
        return crs
    import pyproj
    return pyproj.CRS.from_wkt(wkt)


#: GeoTIFF's VerticalCSTypeGeoKey and VerticalUnitsGeoKey, and the EPSG length units the second may
#: name, with pyproj's axis of a height in that unit.
_VERTICAL_CS_KEY, _VERTICAL_UNITS_KEY = 4096, 4099
_HEIGHT_AXES = {9001: ("GRAVITY_HEIGHT", "metre"), 9002: ("GRAVITY_HEIGHT_FT", "foot"),
                9003: ("GRAVITY_HEIGHT_US_FT", "US survey foot")}


@functools.lru_cache(maxsize=16)
def _epsg_height(datum: str, unit: str):
    """The EPSG vertical CRS of heights (up) on the vertical datum named ``datum`` in ``unit``, e.g.
    NAVD88 height (ftUS), EPSG:6360; None when EPSG has none. A GeoTIFF DTM keeps a vertical CRS by
    its code: GDAL wrote a custom one in US survey feet as metres. (About 0.2 s, once.)"""
    import pyproj
    from pyproj.database import query_crs_info
    for info in query_crs_info(auth_name="EPSG", pj_types=["VERTICAL_CRS"]):
        candidate = pyproj.CRS.from_epsg(info.code)
        axes = candidate.axis_info
        if candidate.datum is not None and candidate.datum.name == datum and len(axes) == 1 \
                and axes[0].direction == "up" and axes[0].unit_name == unit and not info.deprecated:
            return candidate
    return None


def _with_geokey_heights(crs, header):
    """``crs`` with the vertical part that the header's GeoTIFF keys give, when its CRS comes from
    those keys: laspy reads only their horizontal CRS, so a LAS 1.2 delivery "NAD83 / UTM 17N +
    NAVD88 height in US survey feet" (keys 3072, 4096 and 4099, as LAStools writes them) lost its
    heights' datum and unit, its heights in feet were taken for metres without a word, and its DTM
    said metres (a flood modeller). The units key wins over the vertical CRS's own unit (LAStools
    writes NAVD88's code 5703, in metres, beside US survey feet); without a known vertical CRS the
    heights get a vertical CRS of unknown datum in that unit. A vertical CRS the keys name by its EPSG
    code is kept whatever its unit (a surveyor: "NAD83 / BC Albers + CGVD28 height" from LAStools lost
    its datum in the DTM, where the same CRS as LAS 1.4 WKT kept it). A units key alone adds a vertical
    CRS only for heights in another unit than x and y: LAStools writes it (metres) into nearly every
    file, and a compound CRS of "unknown height (metre)" told two tiles of one survey apart and took
    the EPSG code off their DTMs (a code reviewer). A WKT CRS, and a 3D one, are kept as they are."""
    from laspy.vlrs.known import WktCoordinateSystemVlr
    records = _records(header)
    if any(isinstance(r, WktCoordinateSystemVlr) and r.string for r in records) or crs.is_compound \
            or crs.is_vertical or len(crs.axis_info) != 2:
        return crs
    keys = _geokeys(records)
    code, unit = keys.get(_VERTICAL_CS_KEY), keys.get(_VERTICAL_UNITS_KEY)
    if code is None and unit is None:
        return crs
    import pyproj
    from pyproj.crs import CompoundCRS, VerticalCRS
    from pyproj.crs.coordinate_system import VerticalCS
    vertical, by_code = None, False
    if code is not None and 0 < code < 32767:
        try:
            vertical = pyproj.CRS.from_epsg(code)
        except pyproj.exceptions.CRSError:
            vertical = None
        if vertical is not None and not vertical.is_vertical:
            vertical = None
        by_code = vertical is not None
    if unit in _HEIGHT_AXES:
        axis, name = _HEIGHT_AXES[unit]
        has = vertical.axis_info[0].unit_name if vertical is not None and vertical.axis_info else None
        if vertical is None:
            vertical = VerticalCRS(name=f"unknown height ({name})", vertical_cs=VerticalCS(axis),
                                   datum={"type": "VerticalReferenceFrame", "name": "unknown"})
        elif has != name:
            vertical = _epsg_height(vertical.datum.name, name) or VerticalCRS(
                name=f"{vertical.name} ({name})", datum=vertical.datum, vertical_cs=VerticalCS(axis))
    if vertical is None or not vertical.axis_info or not crs.axis_info:
        return crs
    # metres per unit, as PROJ knows them (US survey and international feet, 2 ppm apart, are one unit
    # for the thresholds, as raster/crs.py's heights_differ has it)
    up, across = vertical.axis_info[0].unit_conversion_factor, crs.axis_info[0].unit_conversion_factor
    if not by_code and up and across and abs(up / across - 1) <= 1e-5:
        return crs  # an unknown datum in the unit of x and y: nothing a run reads differently
    return CompoundCRS(name=f"{crs.name} + {vertical.name}", components=[crs, vertical])


def read_cloud(path: str, steps: Optional[Steps] = None) -> PointCloud:
    """Read a LAS/LAZ file or an ISPRS ``x y z [label]`` text file. A LAS/LAZ file is read in
    chunks of :data:`CHUNK_POINTS`, reporting progress to ``steps`` and checking cancellation
    between them."""
    steps = steps or Steps()
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file")
    if os.path.isdir(path):
        raise InputError(f"{path}: is a folder, not a point-cloud file")
    if not os.path.isfile(path):  # a FIFO or a device: reading it could wait for good
        raise InputError(f"{path}: is not a regular file (a pipe or a device?); give a point-cloud file")
    ext = _ext(path)
    if ext in LAS_EXTENSIONS:
        cloud = _read_las(path, steps)
    elif ext in TEXT_EXTENSIONS:
        cloud = _read_isprs_text(path, steps)
    else:
        raise UnsupportedFormatError(
            f"{path}: unsupported file type '{ext or '(none)'}'; expected .las, .laz or ISPRS .txt")
    if len(cloud) == 0:
        raise InputError(f"{path}: the file holds no points")
    check_coordinates(cloud.x, cloud.y, cloud.z, what=path)
    return cloud


#: Bytes of a LAS VLR header and of an EVLR header (their smallest possible size on disk).
_VLR_BYTES, _EVLR_BYTES = 54, 60
#: Bytes of a LAS 1.4 header, the largest.
_HEADER_BYTES_14 = 375


def _laszip_compressor(f, header: bytes) -> Optional[int]:
    """The compressor of the LASzip VLR among the VLRs after ``header`` (0 none, 1 pointwise, 2
    pointwise and chunked, 3 layered and chunked: LAS 1.4 formats 6-10); None without one."""
    import struct
    for at, user, record, _length in _vlrs(f, header):
        if user == b"laszip encoded" and record == 22204:
            f.seek(at)
            data = f.read(2)
            return struct.unpack("<H", data)[0] if len(data) == 2 else None
    return None


#: The waveform data packets' record (LAS 1.3 and 1.4): an EVLR of LASF_Spec, record 65535.
_WAVEFORM_USER, _WAVEFORM_RECORD = b"LASF_Spec", 65535


def _is_waveform_record(evlr_header: bytes) -> bool:
    import struct
    return (len(evlr_header) >= _EVLR_BYTES and evlr_header[2:18].rstrip(b"\0") == _WAVEFORM_USER
            and struct.unpack_from("<H", evlr_header, 18)[0] == _WAVEFORM_RECORD)


def finish_copy(dst: str, src: Optional[str] = None, name: Optional[str] = None) -> None:
    """Mend ``dst``, a LAS/LAZ file just written by laspy (before it is put in place), where laspy's
    writer changes or drops what a copy of ``src`` (the LAS/LAZ it was read from, if any) should keep
    (a format reviewer compared every field):

    - the waveform data packets ``src`` holds inside the file (:func:`carry_waveform_packets`);
    - the generating software: GroundSieve and its version (laspy kept ``src``'s: a classified copy
      claimed the vendor's pipeline had written it, a surveyor);
    - the header's creation day and year, as ``src`` has them (laspy read day 0 as the last day of the
      year before and wrote an unset date as today's);
    - a LAS 1.4 file of point formats 0-5: the legacy point counts, which LAS 1.4 R15 wants filled in
      when they fit (laspy wrote 0: older readers saw no point);
    - the extra-bytes descriptions as ``src`` has them for the dimensions the copy keeps; for the
      others (added by the run) the options byte no longer claims a minimum and maximum (laspy wrote
      sentinels or NaN beside an options byte saying they were set).

    Then a LAZ copy of point format 9 or 10 is read back and its wave packet fields compared with
    ``src``'s, chunk by chunk: lazrs 0.8.2 writes them wrong where points of several scanner channels
    carry wave packets, and such a copy is refused (:class:`OutputError`, naming ``name``: the copy's
    final path) rather than delivered (:func:`check_laz_wave_packets` tries the first chunk before
    the work)."""
    import struct
    name = name or dst
    with open(dst, "r+b") as g, (open(src, "rb") if src else contextlib.nullcontext()) as f:
        b = bytearray(g.read(_HEADER_BYTES_14))
        if len(b) < 227 or b[:4] != b"LASF":
            return
        a = bytearray(f.read(_HEADER_BYTES_14)) if f is not None else b""
        if len(a) < 227 or a[:4] != b"LASF":
            f = None
        from .provenance import software
        g.seek(58)
        g.write(software().encode("ascii").ljust(32, b"\0"))  # generating software: the copy's writer
        if f is not None:
            g.seek(90)
            g.write(a[90:94])  # creation day of year, year
        if b[25] >= 4 and len(b) >= 375 and b[104] & 0x3F < 6:
            count, = struct.unpack_from("<Q", b, 247)
            by_return = struct.unpack_from("<15Q", b, 255)
            if count < 2 ** 32 and all(v < 2 ** 32 for v in by_return[:5]):
                g.seek(107)
                g.write(struct.pack("<I5I", count, *by_return[:5]))
        _match_extra_bytes(f, g, a, b)
    if f is None:
        return
    carry_waveform_packets(src, dst)
    if name.lower().endswith(".laz") and b[104] & 0x3F in (9, 10):
        _check_wave_packets(src, dst, name)


def _vlrs(f, header: bytes):
    """(offset of the record's data, user id, record id, length) of each VLR after ``header``, as many as
    the bytes between the header and the points can hold at most (check_las_layout refuses a count
    beyond that) and as far as the file holds them."""
    import struct
    at, offset = struct.unpack_from("<HI", header, 94)
    count, = struct.unpack_from("<I", header, 100)
    out = []
    for _ in range(min(count, max(offset - at, 0) // _VLR_BYTES)):
        f.seek(at)
        h = f.read(_VLR_BYTES)
        if len(h) < _VLR_BYTES:
            break
        length, = struct.unpack_from("<H", h, 20)
        out.append((at + _VLR_BYTES, h[2:18].rstrip(b"\0"), struct.unpack_from("<H", h, 18)[0], length))
        at += _VLR_BYTES + length
    return out


#: Bytes of one extra-bytes description; its options byte's bits for "minimum set" and "maximum set".
_EXTRA_BYTES_STRUCT, _MIN_MAX_BITS = 192, 0x06


def _match_extra_bytes(f, g, a: bytes, b: bytes) -> None:
    """The copy's extra-bytes descriptions as the source's (``f``, None without one), for each the copy
    keeps (the same name and type in the same place: a copy may add dimensions after them); the others
    claim no minimum and maximum."""
    theirs = [v for v in _vlrs(g, b) if v[1] == b"LASF_Spec" and v[2] == 4]
    if len(theirs) != 1:
        return
    ours = [v for v in _vlrs(f, a) if v[1] == b"LASF_Spec" and v[2] == 4] if f is not None else []
    source = b""
    if len(ours) == 1:
        f.seek(ours[0][0])
        source = f.read(ours[0][3])
    g.seek(theirs[0][0])
    copy = bytearray(g.read(theirs[0][3]))
    n = _EXTRA_BYTES_STRUCT
    kept = 0
    for k in range(min(len(source), len(copy)) // n):
        s, c = source[n * k:n * (k + 1)], copy[n * k:n * (k + 1)]
        if s[2] != c[2] or s[4:36] != c[4:36]:  # data type, name
            break
        copy[n * k:n * (k + 1)] = s
        kept += 1
    for k in range(kept, len(copy) // n):
        copy[n * k + 3] &= ~_MIN_MAX_BITS & 0xFF
    g.seek(theirs[0][0])
    g.write(copy)


#: The wave packet fields of point formats 4, 5, 9 and 10 (in the floats, NaN equals NaN).
_WAVE_FIELDS = ("wavepacket_index", "wavepacket_offset", "wavepacket_size", "return_point_wave_location",
                "x_t", "y_t", "z_t")


def _same_wave_packets(a, b) -> bool:
    return all(np.array_equal(np.asarray(a[n]), np.asarray(b[n]), equal_nan=np.asarray(a[n]).dtype.kind == "f")
               for n in _WAVE_FIELDS)


def _lazrs_wave_packets_error(name: str, src: str) -> OutputError:
    return OutputError(f"{name}: the LAZ writer (lazrs 0.8) writes the wave packet fields of {src}'s points wrong "
                       "(point format 9 or 10 with several scanner channels): write a .las output instead")


def _check_wave_packets(src: str, dst: str, name: str) -> None:
    import laspy
    with laspy.open(src) as r, laspy.open(dst) as w:
        for a, b in zip(r.chunk_iterator(CHUNK_POINTS), w.chunk_iterator(CHUNK_POINTS)):
            if not _same_wave_packets(a, b):
                raise _lazrs_wave_packets_error(name, src)


def check_laz_wave_packets(src: str, out: Optional[str]) -> None:
    """Before any work: refuse a LAZ copy of a point format 9 or 10 file whose first chunk's wave
    packet fields lazrs writes wrong (tried in memory), so that a run does not end with the refusal
    of :func:`finish_copy` after all its work; the copy written is still checked in full."""
    if not out or _ext(out) != ".laz" or _ext(src) not in LAS_EXTENSIONS:
        return
    import io
    import laspy
    try:
        with laspy.open(src) as reader:
            if reader.header.point_format.id not in (9, 10):
                return
            points = reader.read_points(50_000)
            header = copy.deepcopy(reader.header)
        buffer = io.BytesIO()
        with laspy.LasWriter(buffer, header=header, do_compress=True, closefd=False,
                             encoding_errors=TEXT_ERRORS) as writer:
            writer.write_points(points)
        buffer.seek(0)
        with laspy.open(buffer) as back:
            same = _same_wave_packets(points, back.read_points(len(points)))
    except Exception:  # noqa: BLE001 - a file laspy cannot read is refused by the run in its own words
        return
    if not same:
        raise _lazrs_wave_packets_error(out, src)


def _evlr_at(f, at: int, size: int) -> Tuple[int, bool]:
    """The EVLR at byte ``at`` of a file of ``size`` bytes: (its length with its header, whether it is
    the waveform packets' record), or (0, False) when its header does not lie in the file."""
    import struct
    if not 0 < at <= size - _EVLR_BYTES:
        return 0, False
    f.seek(at)
    evlr = f.read(_EVLR_BYTES)
    return _EVLR_BYTES + struct.unpack_from("<Q", evlr, 20)[0], _is_waveform_record(evlr)


def _evlr_places(f, head: bytes, size: int) -> list:
    """(offset, total length, waveform record?) of each EVLR a LAS 1.4 header lists, as far as they
    lie in the file."""
    import struct
    if head[25] < 4 or len(head) < 247:
        return []
    at, count = struct.unpack_from("<QI", head, 235)
    out = []
    for _ in range(min(count, 100_000)):
        total, wave = _evlr_at(f, at, size)
        if not total:
            break
        out.append((at, total, wave))
        at += total
    return out


def internal_waveform(path: str) -> Tuple[Optional[int], int, str]:
    """Where the waveform data packets of a LAS 1.3/1.4 file that says it holds them (global encoding
    bit 1) are: (offset of their record, its length with its header, ""), found where the header points
    or, when that leads to no such record, right after the point records of an uncompressed file;
    (None, 0, why) when the file says so but holds none that fits; (None, 0, "") when it does not say so."""
    import struct
    with open(path, "rb") as f:
        head = f.read(_HEADER_BYTES_14)
        if len(head) < 235 or head[:4] != b"LASF" or head[25] < 3 or not struct.unpack_from("<H", head, 6)[0] & 2:
            return None, 0, ""
        size = os.fstat(f.fileno()).st_size

        def record_at(at: int) -> int:
            total, wave = _evlr_at(f, at, size)
            return total if wave and at + total <= size else 0

        pointer, = struct.unpack_from("<Q", head, 227)
        total = record_at(pointer)
        if total:
            return pointer, total, ""
        offset, = struct.unpack_from("<I", head, 96)
        record, = struct.unpack_from("<H", head, 105)
        count, = struct.unpack_from("<I", head, 107)
        if head[25] >= 4 and len(head) >= 255:
            count = struct.unpack_from("<Q", head, 247)[0] or count
        after = offset + count * record
        total = 0 if head[104] & 0x80 else record_at(after)  # (a LAZ's points end where only lazrs knows)
        if total:
            return after, total, ""
    return None, 0, (f"its header says the waveform packets are in the file, at byte {pointer:,}, but no waveform "
                     "record (LASF_Spec 65535) that fits in the file is there")


def waveform_note(path: str) -> str:
    """A warning when a LAS file says it holds its waveform packets but they cannot be found: its
    classified copy says it holds none (the points' wave packet fields are kept as they are)."""
    _at, _total, why = internal_waveform(path)
    if why:
        return (f"{WARNING_PREFIX}{path}: {why}; a classified copy leaves them out and says in its header that it "
                "holds none")
    return external_waveform_note(path)


def external_waveform_note(path: str) -> str:
    """A warning when a LAS 1.3/1.4 file keeps its waveform packets in an external file (global encoding bit
    2: NAME.wdp beside it, as Riegl and LAStools deliver them): its classified copy keeps the points' wave
    packet fields, which point into a file the copy does not have (it went without a word: a format
    reviewer)."""
    import struct
    with open(path, "rb") as f:
        head = f.read(8)
    if len(head) < 8 or head[:4] != b"LASF" or not struct.unpack_from("<H", head, 6)[0] & 4:
        return ""
    wdp = os.path.splitext(path)[0] + ".wdp"
    there = os.path.exists(wdp) or os.path.exists(os.path.splitext(path)[0] + ".WDP")
    return (f"{WARNING_PREFIX}{path}: its waveform packets are in an external file ({os.path.basename(wdp)} beside "
            f"it{'' if there else ', not found'}): the classified copy keeps the points' wave packet fields, which "
            "point into that file, but not the file; copy it beside the classified copy under the copy's name "
            "(NAME.wdp) to keep the waveforms with it.")


def carry_waveform_packets(src: str, dst: str) -> None:
    """Give ``dst``, a copy of ``src`` just written by laspy (before it is put in place), the waveform
    data packets ``src`` holds inside the file (LAS 1.3/1.4, global encoding bit 1: one record after
    the points, from whose start every point's wave packet offset counts; :func:`internal_waveform`).
    laspy writes none for LAS 1.3, the header still saying they are there (a reviewer's 1.28 MB of
    samples went without a word); in LAS 1.4 it keeps the records among the EVLRs but not the
    header's pointer to the one in use, which a LAZ copy moves. The record is found among the copy's
    EVLRs (the same one: the same place among the waveform records) or appended as it is, and the
    header points at it; a file that says it holds them but does not gets a copy that says it holds
    none (bit 1 and the pointer cleared), rather than a pointer to nothing."""
    import shutil
    import struct
    at, total, why = internal_waveform(src)
    if at is None and not why:
        return
    with open(src, "rb") as f, open(dst, "r+b") as g:
        out = g.read(_HEADER_BYTES_14)
        if at is None:
            encoding, = struct.unpack_from("<H", out, 6)
            g.seek(6)
            g.write(struct.pack("<H", encoding & ~2))
            g.seek(227)
            g.write(struct.pack("<Q", 0))
            return
        head = f.read(_HEADER_BYTES_14)
        theirs = [p for p, _t, wave in _evlr_places(f, head, os.fstat(f.fileno()).st_size) if wave]
        ours = [p for p, _t, wave in _evlr_places(g, out, os.fstat(g.fileno()).st_size) if wave]
        if at in theirs and len(ours) == len(theirs):  # LAS 1.4: laspy kept them among the EVLRs
            g.seek(227)
            g.write(struct.pack("<Q", ours[theirs.index(at)]))
            return
        end = g.seek(0, os.SEEK_END)
        f.seek(at)
        shutil.copyfileobj(_Limited(f, total), g, 1 << 20)
        g.seek(227)
        g.write(struct.pack("<Q", end))
        if out[25] >= 4:
            first, count = struct.unpack_from("<QI", out, 235)
            g.seek(235)
            g.write(struct.pack("<QI", first if count else end, count + 1))


class _Limited:
    """The next ``n`` bytes of a file, for shutil.copyfileobj."""

    def __init__(self, f, n: int):
        self.f, self.left = f, n

    def read(self, size: int = -1) -> bytes:
        size = self.left if size is None or size < 0 else min(size, self.left)
        data = self.f.read(size) if size else b""
        self.left -= len(data)
        return data


def check_las_layout(path: str) -> None:
    """Refuse a LAS/LAZ file whose header announces more records than the file can hold, before
    laspy or lazrs reads it: a VLR count of 2e9 made laspy build VLRs until the memory ran out
    (deaf to Cancel), and a LAZ chunk table announcing 2^31 chunks made lazrs allocate 34 GB and
    abort the process, QGIS with it (a QA reviewer's 4-byte edits). Each VLR takes at least 54
    bytes, each EVLR 60, and each LAZ chunk at least one point record stored raw (LASzip writes a
    chunk's first point uncompressed). A file this cannot parse is left to laspy's own errors."""
    import struct
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as f:
            head = f.read(375)
            if len(head) < 227 or head[:4] != b"LASF":
                return
            major, minor = struct.unpack_from("<BB", head, 24)
            if major != 1 or minor > 4:
                raise UnsupportedFormatError(f"{path}: LAS version {major}.{minor} is not supported (1.0 to 1.4 are); "
                                             "convert it first, e.g. las2las -set_version 1.2 or PDAL's translate")
            header_size, offset, vlrs = struct.unpack_from("<HII", head, 94)
            point_format, record = struct.unpack_from("<BH", head, 104)
            count, = struct.unpack_from("<I", head, 107)
            scales = struct.unpack_from("<3d", head, 131)
            if not all(math.isfinite(v) and v > 0 for v in scales):  # (0 put every point on one spot, all ground)
                raise InputError(f"{path}: the header's scale factors {list(scales)} are not numbers > 0: the header is "
                                 "damaged")
            if vlrs * _VLR_BYTES > max(offset - header_size, 0) or offset > size:
                raise InputError(f"{path}: the header announces {vlrs:,} VLRs before the points, which start at "
                                 f"byte {offset:,} of {size:,}: the "
                                 + ("file is truncated or its header is damaged" if offset > size else "header is damaged"))
            if minor >= 4 and len(head) >= 255:
                evlr_at, evlrs, count64 = struct.unpack_from("<QIQ", head, 235)
                count = count64 or count
                if evlrs and evlr_at + evlrs * _EVLR_BYTES > size:
                    raise InputError(f"{path}: the header announces {evlrs:,} extended VLRs from byte {evlr_at:,}, "
                                     f"more than the file's {size:,} bytes hold: the file is truncated or its "
                                     "header is damaged")
                if evlrs:  # the first one's length (laspy allocates it: a bogus one was a MemoryError)
                    f.seek(evlr_at + 20)
                    length, = struct.unpack("<Q", f.read(8))
                    if evlr_at + _EVLR_BYTES + length > size:
                        raise InputError(f"{path}: its first extended VLR (at byte {evlr_at:,}) announces {length:,} "
                                         f"bytes, more than the file's {size:,} hold: the file is damaged")
            if not point_format & 0x80 or record <= 0 or offset + 8 > size:
                return
            if _laszip_compressor(f, head) not in (2, 3):  # only chunked LASzip has the table
                return
            f.seek(offset)
            table_at, = struct.unpack("<q", f.read(8))
            if table_at == -1 and size >= 8:  # written at the end by a streaming writer
                f.seek(size - 8)
                table_at, = struct.unpack("<q", f.read(8))
            if not 0 < table_at <= size - 8:
                return  # (lazrs says what is wrong with the table's place)
            f.seek(table_at)
            _version, chunks = struct.unpack("<II", f.read(8))
    except (OSError, struct.error):
        return
    if chunks * record > size or (count and chunks > count):
        raise InputError(f"{path}: the LAZ chunk table announces {chunks:,} chunks for {count:,} points in "
                         f"{size:,} bytes: the file is damaged (its chunk table or its end was overwritten)")


def extra_records_warning(path: str, announced: int, held: int) -> str:
    """The warning on a LAS file holding more point records than its header announces (only the
    announced are read), whole or tiled."""
    return (f"{WARNING_PREFIX}{path}: the header announces {announced:,} points but the file holds {held:,} point "
            f"records; read the {announced:,} announced, {held - announced:,} ignored (the header's count is wrong, "
            "or something else follows the points; rewrite the file with a tool that fixes its header to use them "
            "all).")


def _records_before_evlrs(header) -> Optional[int]:
    """How many point records fit between the point data's start and the first EVLR of an
    uncompressed LAS 1.4 file (None when there is no such bound)."""
    if header.are_points_compressed or header.version.minor < 4 or not header.number_of_evlrs:
        return None
    start = int(header.start_of_first_evlr or 0)
    if start <= int(header.offset_to_point_data):
        return None
    return (start - int(header.offset_to_point_data)) // int(header.point_format.size)


def point_data_end(path: str, header) -> int:
    """Where a LAS/LAZ file's point data end at most: its first EVLR (LAS 1.4), else the file's end."""
    end = os.path.getsize(path)
    if header.version.minor >= 4 and header.number_of_evlrs and int(header.start_of_first_evlr or 0) > 0:
        end = min(end, int(header.start_of_first_evlr))
    return end


def records_held(path: str, header) -> Optional[int]:
    """How many whole point records an uncompressed LAS file holds between the point data's start
    and its end (the first EVLR, or the end of the file); None for LAZ (no cheap bound)."""
    if header.are_points_compressed:
        return None
    end = point_data_end(path, header)
    # LAS 1.3+ with the waveform packets in the file: they follow the points (a code reviewer's file was
    # said to hold 2,246 records more than announced); where the header points, or right after the points
    # when it points nowhere (a pointer into the points read as "0 point records": a QA reviewer)
    try:
        internal = header.version.minor >= 3 and header.global_encoding.waveform_data_packets_internal
    except AttributeError:
        internal = False
    if internal:
        packets, _total, _why = internal_waveform(path)
        pointer = int(header.start_of_waveform_data_packet_record or 0)
        if packets is None and pointer >= int(header.offset_to_point_data) + int(header.point_count) * int(
                header.point_format.size):  # a damaged record past the points: still where they end
            packets = pointer
        if packets is not None and packets > int(header.offset_to_point_data):
            end = min(end, packets)
    return max(0, end - int(header.offset_to_point_data)) // int(header.point_format.size)


def _read_points(reader, count: int, steps: Steps):
    """``count`` point records from ``reader`` in chunks (fewer when the file ends first)."""
    from laspy import ScaleAwarePointRecord
    points = ScaleAwarePointRecord.zeros(count, header=reader.header)
    done = 0
    while done < count:
        chunk = reader.read_points(min(CHUNK_POINTS, count - done))
        if len(chunk) == 0:
            break
        points.array[done:done + len(chunk)] = chunk.array
        done += len(chunk)
        steps.report(done / count)
    return points if done == count else points[:done]


def laspy_reason(err: BaseException) -> str:
    """laspy's error in words: its message, or what its bare ones mean ("77" for an extra-bytes type)."""
    if type(err).__name__ == "UnknownExtraType":
        return (f"an extra-bytes description has the data type {err}, which LAS does not define: 0 is undocumented "
                "bytes, 1-10 numbers")
    return str(err) or type(err).__name__


def other_format(path: str) -> Optional[str]:
    """What a file given as LAS/LAZ whose signature is not "LASF" is, from its first bytes, and what to do,
    in words; None when it is none of these (a damaged LAS then). A PLY or XYZ export renamed .las was
    refused with laspy's "Invalid file signature b'ply\\n'" alone (a photogrammetry reviewer)."""
    try:
        with open(path, "rb") as f:
            head = f.read(512)
    except OSError:
        return None
    convert = "export LAS or LAZ from the software that made it, or convert it (e.g. PDAL's translate, CloudCompare)"
    for magic, kind in ((b"ply", "a PLY file"), (b"ASTM-E57", "an E57 file"), (b"# .PCD", "a PCD file"),
                        (b"VERSION .", "a PCD file"), (b"PK\x03\x04", "a zip archive"), (b"\x89HDF", "an HDF5 file")):
        if head.startswith(magic):
            return f"{path}: not a LAS/LAZ file but {kind}: {convert}"
    try:
        text = head.decode("utf-8-sig")  # (a byte-order mark first: Windows' exports)
    except UnicodeDecodeError:
        return None
    # the first line of numbers among the first lines: after a header line ("X,Y,Z", CloudCompare's "//X Y Z")
    for line in [line.strip() for line in text.splitlines()[:6] if line.strip()]:
        fields = re.split(r"[\s,;]+", line)
        if len(fields) >= 3 and all(re.fullmatch(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", v) for v in fields[:3]):
            return (f"{path}: not a LAS/LAZ file but text, numbers per line (XYZ or CSV: a line is '{line[:60]}'): "
                    f"{convert}; a text file of x y z [label] per line is read as such when named .txt")
    return None


def header_records_problem(path: str, err: BaseException) -> Optional[str]:
    """What laspy refuses in ``path``'s header records that is not damage, in words (None for any other
    error): two extra-bytes dimensions of one name (or one named as a dimension of the point format), or
    a text of the records that is not UTF-8 (a vendor's Latin-1 dimension name). Both were called
    "damaged or truncated", or given in laspy's bare words (a format reviewer)."""
    found = re.search(r"field '([^']*)' occurs more than once", str(err))
    if found:
        return (f"{path}: its extra-bytes descriptions name the dimension '{found.group(1)}' twice, or name one "
                "its point format already has, so its points cannot be told apart: rename one (e.g. with PDAL's "
                "translate or LAStools' las2las) and run again")
    if isinstance(err, UnicodeDecodeError):
        import traceback
        frames = traceback.extract_tb(err.__traceback__)
        what = ("the name of one of its extra-bytes dimensions" if frames and frames[-1].name == "format_name" else
                "a text of its header's records (an extra-bytes dimension's description, or its CRS's text)")
        byte = err.object[err.start:err.start + 1].hex() if isinstance(err.object, bytes) else "?"
        return (f"{path}: {what} is not UTF-8 text (byte 0x{byte}, Latin-1?), which the LAS reader cannot read: "
                "rewrite that text in ASCII (e.g. with PDAL's translate or LAStools' las2las) and run again")
    return None


def _read_las(path: str, steps: Steps) -> PointCloud:
    import laspy
    check_las_layout(path)
    notes = [note for note in (waveform_note(path),) if note]
    try:
        las = None
        with laspy.open(path) as reader:
            header = reader.header
            room = _records_before_evlrs(header)
            if room is not None and int(header.point_count) > room:
                # Reading the announced count would take the EVLRs' bytes for points.
                announced = int(header.point_count)
                evlr_at = int(header.start_of_first_evlr)
                las = laspy.LasData(header=header, points=_read_points(reader, room, steps.sub(0.0, READ_SHARE)))
                las.evlrs = reader.evlrs
                las.update_header()
                notes.append(f"{WARNING_PREFIX}{path}: the header announces {announced:,} points but the file holds "
                             f"{room:,} point records before its extended VLRs (at byte "
                             f"{evlr_at:,}); read those {room:,}, "
                             f"{announced - room:,} missing (the header's count is wrong).")
            held = records_held(path, header)
            if las is None and held is not None and held > int(header.point_count):
                notes.append(extra_records_warning(path, int(header.point_count), held))
            if las is None:
                las = laspy.LasData(header=header, points=_read_points(reader, int(header.point_count), steps.sub(0.0, READ_SHARE)))
    except GroundSieveError:
        raise  # cancelled
    except MemoryError as err:
        from ..errors import out_of_memory
        raise out_of_memory(path, err) from err
    except Exception as err:  # laspy raises many types for damaged files
        msg = laspy_reason(err)
        problem = header_records_problem(path, err)
        if problem:
            raise InputError(problem) from err
        if "signature" in msg.lower():
            raise UnsupportedFormatError(other_format(path) or f"{path}: not a LAS/LAZ file ({msg})") from err
        raise InputError(f"{path}: cannot be read; the file is damaged or truncated ({msg})") from err
    n = int(len(las.points))
    if n != int(las.header.point_count):
        raise InputError(f"{path}: header announces {las.header.point_count} points but {n} could be read; "
                         "the file is truncated")
    crs_wkt = header_crs_wkt(las.header)
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (las.x, las.y, las.z))
    steps.report(READ_SHARE + 0.5 * (1.0 - READ_SHARE))
    rn = np.asarray(las.return_number, dtype=np.uint8)
    nr = np.asarray(las.number_of_returns, dtype=np.uint8)
    withheld = np.asarray(las.withheld).astype(bool)
    cloud = PointCloud(
        path=path, withheld=withheld if withheld.any() else None, notes=notes, x=x, y=y, z=z,
        classification=np.asarray(las.classification, dtype=np.uint8),
        return_number=rn, number_of_returns=nr,
        intensity=np.asarray(las.intensity), crs_wkt=crs_wkt, has_return_info=True, las=las)
    steps.report(1.0)
    return cloud


def _text_problem(path: str) -> str:
    """Where a text file stops being rows of 3 or 4 numbers, in words: the first line (counted from
    1) with a word that is not a number or with another count of columns than the first row.
    Read as numpy's loadtxt reads it: comments from '#' on, bytes as Latin-1, a UTF-8 BOM ignored."""
    try:
        with open(path, encoding="latin-1") as f:
            columns = None
            for number, line in enumerate(f, 1):
                if number == 1 and line.startswith("\xef\xbb\xbf"):
                    line = line[3:]
                if "\x00" in line:
                    return "it is not text (a binary file?)"
                words = line.split("#", 1)[0].split()
                if not words:
                    continue
                for column, word in enumerate(words, 1):
                    try:
                        float(word)
                    except ValueError:
                        hint = ""
                        if any(sep in word for sep in ",;"):
                            hint = ("; the values must be separated by spaces or tabs, not commas or semicolons "
                                    "(or convert the file to LAS/LAZ)")
                        elif number == 1:
                            hint = "; a header line is not read: remove it, or start it with '#'"
                        return f"line {number}, column {column}: {word[:40]!r} is not a number{hint}"
                if columns is None:
                    columns = len(words)
                elif len(words) != columns:
                    return f"line {number} has {len(words)} columns, the lines before it {columns}"
    except OSError as err:
        return f"it cannot be read ({err.strerror or err})"
    return ""


#: Rows of a text cloud parsed at a time (about 0.1 s each): a cancel is seen between them.
TEXT_CHUNK_LINES = CHUNK_POINTS


def _text_rows(path: str, encoding: str, steps: Steps) -> np.ndarray:
    """The numbers of a text cloud as numpy's loadtxt reads them, parsed :data:`TEXT_CHUNK_LINES` rows
    at a time from the open file (given a file object, loadtxt's reader pulls its lines one at a time,
    so each call stops at its last row), reporting the share of the file read to ``steps`` and checking
    cancellation between chunks (22 M lines in one loadtxt call took 8 s deaf to Cancel). The chunks
    fill one array of as many rows as the file has lines, so the peak memory stays about one loadtxt
    call's. A ValueError when the rows are not numbers (loadtxt's row numbers counted from the file's
    start) or their columns differ between chunks, as loadtxt raises within one; an InputError when
    the file changes while it is read."""
    before_read = os.stat(path)
    size = max(before_read.st_size, 1)
    out, filled = None, 0
    with open(path, encoding=encoding) as f:
        first = True
        while True:
            steps.check()
            try:
                rows = np.loadtxt(_no_bom(f) if first else f, dtype=np.float64, ndmin=2, max_rows=TEXT_CHUNK_LINES)
            except UnicodeDecodeError:
                raise  # (the caller reads the file again as Latin-1)
            except ValueError as err:  # "... at row 12, column 3": the row counted in this chunk
                raise ValueError(re.sub(r"\brow (\d+)", lambda m: f"row {int(m.group(1)) + filled}", str(err))) from err
            first = False
            if not rows.size:
                break
            done = f.buffer.tell()  # (with what the text layer has read ahead: a few kB)
            if out is None:  # as many rows as the file has lines at most (a guess from the first chunk's bytes
                # per row could be 5 times too many, or too few, where line lengths change: a code reviewer)
                out = np.empty((max(len(rows), _line_ends(path, steps) + 1), rows.shape[1]))
            elif rows.shape[1] != out.shape[1]:
                raise ValueError("the number of columns changed")
            if filled + len(rows) > len(out):
                grown = np.empty((max(filled + len(rows), len(out) + len(out) // 2), out.shape[1]))
                grown[:filled] = out[:filled]
                out = grown
            out[filled:filled + len(rows)] = rows
            filled += len(rows)
            steps.report(READ_SHARE * min(done / size, 1.0))
            if len(rows) < TEXT_CHUNK_LINES:
                break
    after_read = os.stat(path)
    if (after_read.st_size, after_read.st_mtime_ns) != (before_read.st_size, before_read.st_mtime_ns):
        raise InputError(f"{path}: the file changed while it was read ({before_read.st_size:,} bytes, then "
                         f"{after_read.st_size:,}): run again once it is complete")
    if out is None:
        return np.empty((0, 0))
    return out[:filled]


def _line_ends(path: str, steps: Steps, block: int = 1 << 24) -> int:
    """The line ends of the file as Python's text mode counts them: newlines, carriage returns and
    their pairs (a file may mix them: 500,000 lines ending in a newline, then carriage returns only)."""
    ends, last = 0, b""
    with open(path, "rb") as f:
        while True:
            steps.check()
            data = f.read(block)
            if not data:
                return ends
            ends += data.count(b"\n") + data.count(b"\r") - data.count(b"\r\n")
            if last == b"\r" and data[:1] == b"\n":  # a pair split between two blocks
                ends -= 1
            last = data[-1:]


def _no_bom(f):
    """The lines of ``f``, a UTF-8 BOM read as Latin-1 dropped from the first (a file with a BOM and a
    Latin-1 comment: 'ï»¿161.45' was not a number)."""
    for line in f:  # (not "yield from f": closing this generator would close the file)
        yield line[3:] if line.startswith("\xef\xbb\xbf") else line
        break
    for line in f:
        yield line


def _read_isprs_text(path: str, steps: Optional[Steps] = None) -> PointCloud:
    what = "not an ISPRS text file of 'x y z [label]' numbers"
    steps = steps or Steps()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "empty input file" is reported below
            try:
                data = _text_rows(path, "utf-8-sig", steps)
            except UnicodeDecodeError:  # not UTF-8 (e.g. a Latin-1 comment): bytes as Latin-1
                data = _text_rows(path, "latin-1", steps)
    except GroundSieveError:  # a cancel (a ValueError too)
        raise
    except ValueError as err:
        raise UnsupportedFormatError(f"{path}: {what}: {_text_problem(path) or err}") from err
    if data.size == 0:
        raise InputError(f"{path}: the file holds no points")
    if not 3 <= data.shape[1] <= 4:
        raise UnsupportedFormatError(
            f"{path}: {what}: expected 3 or 4 columns 'x y z [label]', found {data.shape[1]}"
            + ("" if data.shape[1] < 3 else "; for other text layouts convert the file to LAS/LAZ first"))
    n = data.shape[0]
    # before the scale (an infinite z gave decimals_scale's OverflowError with a traceback)
    check_coordinates(data[:, 0], data[:, 1], data[:, 2], what=path)
    label, notes = None, []
    if data.shape[1] >= 4:
        labels = data[:, 3]
        odd = ~(np.isfinite(labels) & (labels == np.round(labels)) & (labels >= 0) & (labels <= 255))
        if odd.any():  # (256, nan and 0.7 became label 0, ground truth for tune; -1 became 255)
            k = int(np.argmax(odd))
            notes.append(f"{WARNING_PREFIX}{path}: the 4th column is not a label (whole numbers 0-255, 0 = ground "
                         f"in the ISPRS samples: point {k + 1:,} has {labels[k]:g}); it is ignored, and the "
                         "cloud has no reference labels.")
        else:
            label = labels.astype(np.uint8)
    ones = np.ones(n, dtype=np.uint8)
    return PointCloud(path=path, x=data[:, 0].copy(), y=data[:, 1].copy(), z=data[:, 2].copy(),
                      classification=np.zeros(n, dtype=np.uint8), return_number=ones,
                      number_of_returns=ones.copy(), crs_wkt=None, has_return_info=False,
                      reference_label=label, scale=decimals_scale(data[:, 0], data[:, 1], data[:, 2]),
                      notes=notes)


def new_las(x, y, z, *, point_format: int = 1, version: str = "1.2", scale: float = 0.01,
            crs_wkt: Optional[str] = None, extra: Optional[dict] = None, **dims):
    """A laspy ``LasData`` holding the given coordinates and dimensions (``classification=...``,
    ``return_number=...``, ...), with ``extra`` arrays stored as extra bytes."""
    import laspy
    header = laspy.LasHeader(point_format=point_format, version=version)
    x, y, z = (np.asarray(a, dtype=np.float64) for a in (x, y, z))
    header.scales = np.array([scale, scale, scale])
    header.offsets = np.array([np.floor(x.min()) if x.size else 0.0,
                               np.floor(y.min()) if y.size else 0.0,
                               np.floor(z.min()) if z.size else 0.0])
    for name, values in (extra or {}).items():
        header.add_extra_dim(laspy.ExtraBytesParams(name=name, type=np.asarray(values).dtype))
    if crs_wkt:
        import pyproj
        header.add_crs(pyproj.CRS.from_wkt(crs_wkt))
    las = laspy.LasData(header)
    las.x, las.y, las.z = x, y, z
    for name, values in dims.items():
        if values is not None:
            setattr(las, name, values)
    for name, values in (extra or {}).items():
        las[name] = values
    return las


def write_las(las, path: str, *, atomic: bool = True, steps: Optional[Steps] = None,
              source: Optional[str] = None, name: Optional[str] = None) -> None:
    """Write a laspy ``LasData`` (LAZ when the name ends in .laz), atomically unless the caller
    already writes to a temporary path of its own (``atomic=False``). The points go out in chunks
    of :data:`CHUNK_POINTS` when ``steps`` is given, reporting progress to it and checking
    cancellation between them (a cancelled write leaves no file when atomic); in one call of
    ``LasData.write`` otherwise (the same bytes). ``source``: the file ``las`` was read from, whose
    header fields, extra-bytes descriptions and waveform packets the copy then keeps (:func:`finish_copy`);
    ``name``: the path the messages give, when ``path`` is the caller's temporary."""
    if atomic:  # (a caller's temporary is its own: checking it made a probe longer than the file system takes)
        path = check_output_path(path)
    try:
        if atomic:
            with atomic_path(path) as tmp:
                _write_chunks(las, tmp, _ext(path) == ".laz", steps)
                finish_copy(tmp, source, path)
        else:
            _write_chunks(las, path, _ext(path) == ".laz", steps)
            finish_copy(path, source, name)
    except OSError as err:
        # the output's name and the reason in words (the temporary's name and "[Errno 28]" were said)
        raise OutputError(f"{name or path}: cannot be written ({_reason(err)})") from err


def _write_chunks(las, path: str, compress: bool, steps: Optional[Steps]) -> None:
    """What ``LasData.write`` does, chunk by chunk."""
    import laspy
    n = len(las.points)
    with open(path, "wb+") as out, laspy.LasWriter(out, las.header, do_compress=compress, closefd=False,
                                                   encoding_errors=TEXT_ERRORS) as writer:
        for start in range(0, n, CHUNK_POINTS):
            writer.write_points(las.points[start:start + CHUNK_POINTS])
            if steps is not None:
                steps.report(min(start + CHUNK_POINTS, n) / n)
        if las.header.version.minor >= 4 and las.evlrs is not None:
            writer.write_evlrs(writable_evlrs(las.evlrs))


def write_classified(cloud: PointCloud, classification: np.ndarray, path: str, *, atomic: bool = True,
                     steps: Optional[Steps] = None, name: Optional[str] = None) -> None:
    """Write ``cloud`` with a new classification, keeping every other dimension, the
    extra bytes, the VLRs and the CRS of a LAS/LAZ input. An ISPRS text input becomes
    LAS 1.2 point format 0 with its label column kept as the extra dimension
    ``reference_label`` (0 = ground, 1 = object)."""
    classification = np.asarray(classification, dtype=np.uint8)
    if classification.shape != (len(cloud),):
        raise OutputError(f"{path}: classification has {classification.shape} values for {len(cloud)} points")
    if cloud.las is not None:
        las = cloud.las
        from .copc import is_copc_header, plain_header
        if is_copc_header(las.header) or las.header.version.minor == 0:  # laspy writes neither COPC (nor
            # would the copy be one: its chunks) nor LAS 1.0
            import laspy
            las = laspy.LasData(header=plain_header(las.header), points=las.points)
        check_classes_fit(path, las.point_format.id, classification)
        original = np.array(las.classification)
        las.classification = classification
        try:
            write_las(las, path, atomic=atomic, steps=steps, source=cloud.path, name=name)
        finally:
            las.classification = original  # the in-memory input stays as read
    else:
        extra = {"reference_label": cloud.reference_label} if cloud.reference_label is not None else None
        las = new_las(cloud.x, cloud.y, cloud.z, point_format=0, crs_wkt=cloud.crs_wkt, extra=extra,
                      scale=cloud.scale or 0.01, classification=classification)
        write_las(las, path, atomic=atomic, steps=steps)
