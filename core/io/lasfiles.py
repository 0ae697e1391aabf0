"""Survey-scale reading and writing of LAS/LAZ: headers without points, inputs given as a file, a
folder or a QGIS virtual point cloud (``.vpc``), streaming a file's points into tile parts, tile
clouds built from those parts, and a classified copy written in one streamed pass.

Nothing here holds a whole file's points: every pass goes through laspy's chunk iterator.
"""
from __future__ import annotations

import contextlib
import copy
import dataclasses
import json
import math
import os
from dataclasses import dataclass
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from ..errors import GroundSieveError, InputError, OutputError, UnsupportedFormatError, out_of_memory
from .clouds import (TEXT_ERRORS, PointCloud, check_las_layout, crs_records_conflict, finish_copy, header_crs_wkt,
                     header_records_problem, laspy_reason, other_format, point_data_end, records_held, writable_evlrs)
from ..progress import WARNING_PREFIX
from .outputs import LAS_EXTENSIONS, _ext, _reason, atomic_path, check_classes_fit

VPC_EXTENSION = ".vpc"
#: points per chunk of the streamed passes (about 100 MB of laspy records for the largest formats)
CHUNK_POINTS = 1_000_000


@dataclass(frozen=True)
class LasInfo:
    """What the header of one LAS/LAZ file says, read without its points."""
    path: str
    count: int
    mins: Tuple[float, float, float]
    maxs: Tuple[float, float, float]
    point_format: int
    version: str
    crs_wkt: Optional[str]
    copc: bool = False  #: a COPC file (the COPC info VLR): its tiles read it by bounds (io/copc.py)
    record_size: int = 0  #: bytes per point record, extra bytes included (0 = not known)
    #: points the header counts beyond return 1 (None: its counts by return are all 0, not filled in)
    later_returns: Optional[int] = None
    #: whole point records an uncompressed file holds (None: LAZ, not known without decoding)
    held: Optional[int] = None
    #: why a file with the COPC records is not read as COPC (its index is damaged): it is read as a
    #: plain LAZ, as a run of the whole file reads it ("" when it is no COPC file or a sound one)
    copc_damaged: str = ""
    #: the header's bounds were empty (every min and max one value: a writer that never filled them in)
    #: and are the points' own, read from them (a tiled run planned on them failed at its end)
    bounds_from_points: bool = False
    #: the two CRS its WKT record and its GeoTIFF keys name when they differ (clouds.crs_records_conflict)
    crs_conflict: str = ""

    @property
    def area_m2(self) -> float:
        return max(self.maxs[0] - self.mins[0], 0.0) * max(self.maxs[1] - self.mins[1], 0.0)


def scan_header(path: str) -> LasInfo:
    """The header of ``path``: point count, bounds, point format, version, CRS."""
    import laspy
    from .copc import is_copc_header
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError(f"{path}: " + ("is not a regular file (a pipe or a device?); give a point-cloud file"
                                         if os.path.exists(path) and not os.path.isdir(path) else "no such file"))
    if _ext(path) not in LAS_EXTENSIONS:
        raise UnsupportedFormatError(f"{path}: expected a .las or .laz file (got '{_ext(path) or '(none)'}')")
    check_las_layout(path)
    try:
        with laspy.open(path) as reader:
            h = reader.header
            h.point_format.dtype()  # (two extra-bytes dimensions of one name are refused here, before any work)
            held = records_held(path, h)
            if held is not None and held < int(h.point_count) and not (h.version.minor >= 4 and h.number_of_evlrs):
                raise InputError(f"{path}: the header announces {int(h.point_count):,} points but the file holds "
                                 f"{held:,} point records: the file is truncated or its header's count is wrong")
            _check_point_counts(path, h, held)
            if int(h.point_count) == 0:
                _check_not_growing(path, h, held)
            damaged = _copc_damage(path) if is_copc_header(h) else ""
            if not all(math.isfinite(float(v)) for v in (*h.mins, *h.maxs)):
                raise InputError(f"{path}: the header's bounds are not numbers ({list(h.mins)} to {list(h.maxs)}): "
                                 "the header is damaged; rewrite it with a tool that recomputes it (e.g. "
                                 "las2las, PDAL's translate)")
            mins, maxs = tuple(float(v) for v in h.mins), tuple(float(v) for v in h.maxs)
            empty_bounds = int(h.point_count) > 1 and mins[:2] == maxs[:2] and not is_copc_header(h)
            if empty_bounds:
                mins, maxs = _bounds_of_points(reader, path)
            return LasInfo(path, int(h.point_count), mins, maxs, int(h.point_format.id), str(h.version),
                           header_crs_wkt(h),
                           copc=is_copc_header(h) and not damaged, record_size=int(h.point_format.size),
                           later_returns=_later_returns(h), held=held, copc_damaged=damaged,
                           bounds_from_points=empty_bounds, crs_conflict=crs_records_conflict(h))
    except (InputError, UnsupportedFormatError):
        raise
    except Exception as err:  # laspy raises many types for damaged files
        raise InputError(header_records_problem(path, err)
                         or ("signature" in laspy_reason(err).lower() and other_format(path))
                         or f"{path}: cannot read its LAS header ({laspy_reason(err)})") from err


#: the bounds read from the points of files whose headers have none, by (path, size, modification time): a
#: run reads a header several times (a code reviewer: 2.4 s each for 10 M points, 4 times in a tiled run)
_POINT_BOUNDS: Dict[tuple, tuple] = {}


def _bounds_of_points(reader, path: str, chunk: int = 2_000_000):
    """The (x, y, z) minima and maxima of the points ``reader`` (a laspy reader at its first point) holds,
    read chunk by chunk (a header whose bounds were never filled in: a photogrammetry export's zeros),
    once per version of the file."""
    stat = os.stat(path)
    key = (os.path.realpath(path), stat.st_size, stat.st_mtime_ns)
    if key not in _POINT_BOUNDS:
        _POINT_BOUNDS[key] = _read_bounds(reader, chunk)
    return _POINT_BOUNDS[key]


def _read_bounds(reader, chunk: int):
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for points in reader.chunk_iterator(chunk):
        for axis, values in enumerate((points.x, points.y, points.z)):
            values = np.asarray(values)
            if values.size:
                lo[axis], hi[axis] = min(lo[axis], float(values.min())), max(hi[axis], float(values.max()))
    if not np.all(np.isfinite(lo)):
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    return tuple(map(float, lo)), tuple(map(float, hi))


#: what a complete LAZ without points holds after its header at most (the chunk table's offset and table)
EMPTY_LAZ_TAIL = 65536


def raised_by_the_reader(err: BaseException) -> bool:
    """Whether ``err`` came out of laspy (or lazrs, which laspy calls) reading a file, not out of
    GroundSieve's own code in the same ``try``: only the reader's errors mean a damaged file (a
    mismatched call of the binning kernel was called "damaged or truncated": a photogrammetry
    reviewer's sound file)."""
    tb = err.__traceback__
    while tb is not None:
        parts = os.path.normpath(tb.tb_frame.f_code.co_filename).split(os.sep)
        if "laspy" in parts or "lazrs" in parts:
            return True
        tb = tb.tb_next
    return type(err).__module__.split(".")[0] in ("laspy", "lazrs")


def points_error(path: str, err: BaseException) -> GroundSieveError:
    """laspy's or lazrs's error reading the points of ``path``, in words: out of memory (a tight ulimit -v: it
    was called a damaged file, a code reviewer), else a damaged or truncated file."""
    if isinstance(err, MemoryError):
        return out_of_memory(path, err)
    return InputError(f"{path}: cannot read its points ({type(err).__name__}: {err}); the file is damaged or truncated")


def _check_point_counts(path: str, header, held: Optional[int]) -> None:
    """Refuse a LAS 1.4 file of point formats 0-5 whose two point counts disagree where the legacy one is
    the number of point records the file holds: its writer left the LAS 1.4 count wrong. A count of 0
    was refused as a file still being written, a smaller one read that many points and dropped the rest
    with a warning, the run done (a format reviewer: 58 % of the points gone, exit status 0)."""
    if header.version.minor < 4 or header.point_format.id > 5 or held is None:
        return
    with open(path, "rb") as f:
        f.seek(107)
        raw = f.read(4)
    legacy = int.from_bytes(raw, "little") if len(raw) == 4 else 0
    count = int(header.point_count)
    if legacy and legacy == held and count != legacy:
        raise InputError(f"{path}: its two point counts disagree: the LAS 1.4 count says {count:,}, the legacy "
                         f"count {legacy:,}, as many as the point records the file holds; its writer left the LAS 1.4 "
                         "count wrong: repair its header (e.g. LAStools' lasinfo -repair, which counts the records) "
                         "and run again")


def _check_not_growing(path: str, header, held: Optional[int]) -> None:
    """Refuse a file whose header announces no point but which holds point data: LAS writers (laspy,
    PDAL, LAStools) set the count when they close the file, so one still being written looked empty,
    and a survey made it an empty classified copy without a word (a reviewer copying into the folder)."""
    beyond = point_data_end(path, header) - int(header.offset_to_point_data)
    if (held or 0) > 0 or (header.are_points_compressed and beyond > EMPTY_LAZ_TAIL):
        raise InputError(f"{path}: its header announces no point, but {beyond:,} bytes of point data follow it: "
                         "the file is still being written (LAS writers set the count when they close it) or its "
                         "header is damaged; use it once it is complete")


def _copc_damage(path: str) -> str:
    """Why the COPC index of ``path`` cannot be used, in words after the file's name (its hierarchy
    read and checked; cached per file), "" when it can."""
    from .copc import open_index
    try:
        open_index(path)
    except InputError as err:  # "<path>: a damaged COPC file (why); rewrite it ..."
        return str(err).removeprefix(f"{path}: ").split("; rewrite it")[0]
    return ""


def _later_returns(header) -> Optional[int]:
    """Points a header counts beyond return 1; None when its counts by return are all 0."""
    try:
        counts = [int(v) for v in header.number_of_points_by_return]
    except Exception:  # noqa: BLE001 - a header without the counts
        return None
    return sum(counts[1:]) if any(counts) else None


# -- inputs: a file, a folder, a .vpc --------------------------------------------------------------

def read_vpc(path: str) -> List[str]:
    """The data files a QGIS virtual point cloud (STAC ItemCollection, ``.vpc``) references,
    resolved against the ``.vpc``'s folder when relative."""
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: not a readable virtual point cloud ({err})") from err
    features = doc.get("features") if isinstance(doc, dict) else None
    if not isinstance(features, list) or not features:
        raise InputError(f"{path}: a virtual point cloud needs a 'features' list of STAC items; none found")
    folder = os.path.dirname(os.path.abspath(path))
    files = []
    for item in features:
        item = item if isinstance(item, dict) else {}
        assets = item.get("assets")
        data = assets.get("data") if isinstance(assets, dict) else None
        href = data.get("href") if isinstance(data, dict) else None
        if not href or not isinstance(href, str):  # (assets 5 or href 7 gave a traceback: a QA reviewer)
            raise InputError(f"{path}: item '{item.get('id', '?')}' has no assets.data.href naming a file")
        if href.startswith(("http://", "https://", "s3://", "/vsi")):
            raise InputError(f"{path}: remote data ({href}) is not supported; download the files first")
        full = href if os.path.isabs(href) else os.path.normpath(os.path.join(folder, href))
        if not os.path.isfile(full):
            raise InputError(f"{path}: references {href}, which does not exist ({full})")
        files.append(full)
    return files


def expand_inputs(path: str) -> List[str]:
    """The point-cloud files behind an input: itself, the LAS/LAZ files of a folder (sorted; hidden
    ones, named from a dot, left out: a killed run's temporary ``.NAME.laz.gs...part.laz`` beside its
    classified files broke every later run on that folder, an HPC reviewer; macOS's ``._NAME.laz``), or
    the files a ``.vpc`` references."""
    path = os.fspath(path)
    if os.path.isdir(path):
        names = os.listdir(path)
        broken = sorted(n for n in names if _ext(n) in LAS_EXTENSIONS and os.path.islink(os.path.join(path, n))
                        and not os.path.exists(os.path.join(path, n)))
        if broken:  # (a tile of the delivery missing: left out without a word, a hole in the DTM; a format reviewer)
            where = os.path.join(path, broken[0])
            raise InputError(f"{where}: a link to a file that does not exist ({os.readlink(where)})"
                             + (f", as {len(broken) - 1:,} more in the folder" if len(broken) > 1 else "")
                             + "; mend or remove the link(s)")
        files = sorted(os.path.join(path, n) for n in names
                       if _ext(n) in LAS_EXTENSIONS and not n.startswith(".") and os.path.isfile(os.path.join(path, n)))
        if not files:
            raise InputError(f"{path}: the folder holds no .las or .laz file")
        return files
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file or folder")
    if _ext(path) == VPC_EXTENSION:
        return read_vpc(path)
    return [path]


def folder_note(path: str) -> str:
    """What a folder given as input holds that its run leaves out: sub-folders (not searched), hidden
    point clouds (a killed run's temporaries); "" otherwise."""
    if not os.path.isdir(path):
        return ""
    names = os.listdir(path)
    subs = sorted(n for n in names if os.path.isdir(os.path.join(path, n)) and not n.startswith("."))
    hidden = sorted(n for n in names if n.startswith(".") and _ext(n) in LAS_EXTENSIONS)
    notes = []
    if subs:
        shown = ", ".join(subs[:3]) + (", ..." if len(subs) > 3 else "")
        notes.append(f"{WARNING_PREFIX}{path}: {len(subs):,} sub-folder(s) not searched ({shown}): only the .las/.laz "
                     "files in the folder itself are the survey; give a .vpc (or one folder) to take the others too.")
    if hidden:
        notes.append(f"{WARNING_PREFIX}{path}: {len(hidden):,} hidden point cloud file(s) left out ({', '.join(hidden[:2])}"
                     f"{', ...' if len(hidden) > 2 else ''}): names from a dot are a killed run's temporaries or a "
                     "system's, not the survey's.")
    return "\n".join(notes)


def check_survey(infos: Sequence[LasInfo]) -> None:
    """Refuse inputs that cannot be one survey: different CRS, duplicates. Different point formats
    (and LAS versions) are one survey: a tile needs only what every format has (x, y, z, returns,
    classes and flags), and each file's classified copy is written from its own records, in its own
    format."""
    seen = {}
    for info in infos:
        real = os.path.realpath(info.path)
        if real in seen:
            raise InputError(f"{info.path}: given twice (also as {seen[real]})")
        seen[real] = info.path
    crss = {i.crs_wkt for i in infos}
    if len(crss) > 1:
        import collections
        by = collections.defaultdict(list)
        for i in infos:
            by["no CRS" if i.crs_wkt is None else i.crs_wkt.split('"')[1] if '"' in i.crs_wkt else "a CRS"].append(
                os.path.basename(i.path))
        listing = "; ".join(f"{k}: {', '.join(v[:3])}{' ...' if len(v) > 3 else ''}" for k, v in by.items())
        advice = ("assign the CRS to the files without one, or reproject them to one" if "no CRS" in by
                  else "reproject them to one")
        raise InputError(f"the input files have different CRS ({listing}); {advice} first")


def first_classes(path: str, count: int = 65536) -> np.ndarray:
    """The classes of the first ``count`` points of the LAS/LAZ ``path`` (one chunk read, not the file)."""
    import laspy
    with laspy.open(path) as reader:
        return np.asarray(reader.read_points(min(count, int(reader.header.point_count))).classification)


def twin_files(infos: Sequence[LasInfo]) -> List[List[str]]:
    """The groups of files of a survey with the same point count and bounds (headers): the same points
    twice, a copy or a classified copy beside its input in one folder, which a run would read twice."""
    import collections
    groups = collections.defaultdict(list)
    for info in infos:
        if info.count:
            groups[(info.count, info.mins, info.maxs)].append(info.path)
    return [paths for paths in groups.values() if len(paths) > 1]


def write_vpc(path: str, infos: Sequence[LasInfo], files: Sequence[str], *, lonlat=None) -> None:
    """Write a virtual point cloud (STAC ItemCollection as QGIS's "Build virtual point cloud"
    writes it) referencing ``files`` (relative to the .vpc when below its folder), atomically.
    GeoJSON's ``bbox`` and ``geometry`` are in WGS 84: ``lonlat(x0, y0, x1, y1, crs_wkt)`` gives a
    file's box in longitude/latitude (core/raster/crs.py lonlat_box; the io layer has no PROJ);
    the native box is in ``proj:bbox``, which QGIS reads first. Without it, or without a CRS, the
    native box stands in (QGIS's vpc provider then reads an infinite extent)."""
    folder = os.path.dirname(os.path.abspath(path))
    features = []
    for info, file in zip(infos, files):
        rel = os.path.relpath(os.path.abspath(file), folder)
        href = "./" + rel.replace(os.sep, "/") if not rel.startswith("..") else os.path.abspath(file)
        (x0, y0, z0), (x1, y1, z1) = info.mins, info.maxs
        props = {"datetime": "0001-01-01T00:00:00Z", "pc:count": info.count, "pc:type": "lidar",
                 "pc:encoding": "?", "pc:schemas": [], "proj:bbox": [x0, y0, z0, x1, y1, z1]}
        if info.crs_wkt:
            props["proj:wkt2"] = info.crs_wkt
        box = lonlat(x0, y0, x1, y1, info.crs_wkt) if lonlat is not None else None
        g0, h0, g1, h1 = box if box is not None else (x0, y0, x1, y1)
        ring = [[g0, h0, z0], [g1, h0, z0], [g1, h1, z0], [g0, h1, z0], [g0, h0, z0]]
        features.append({
            "type": "Feature", "stac_version": "1.0.0",
            "stac_extensions": ["https://stac-extensions.github.io/pointcloud/v1.0.0/schema.json",
                                "https://stac-extensions.github.io/projection/v1.1.0/schema.json"],
            "id": os.path.splitext(os.path.basename(file))[0],
            "geometry": {"type": "Polygon", "coordinates": [ring]},
            "bbox": [g0, h0, z0, g1, h1, z1], "properties": props, "links": [],
            "assets": {"data": {"href": href, "roles": ["data"]}}})
    doc = {"type": "FeatureCollection", "features": features}
    try:
        with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
            json.dump(doc, f, indent=2)
    except OSError as err:
        raise OutputError(f"{path}: cannot be written ({err})") from err


# -- tile clouds -------------------------------------------------------------------------------

def _per_point(cloud: PointCloud):
    n = len(cloud)
    for f in dataclasses.fields(PointCloud):
        value = getattr(cloud, f.name)
        if isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == n:
            yield f.name, value


def tile_cloud(parts: Sequence[PointCloud], *, path: Optional[str] = None) -> PointCloud:
    """One ``PointCloud`` of the points of ``parts`` (in their order), carrying every per-point
    field a ``PointCloud`` has (whatever ``read_cloud`` fills in, present and future) and the
    other fields of the first part; ``las`` is dropped (a tile is never written back as such).
    This is the one place tile clouds are made."""
    if not parts:
        raise InputError("a tile needs at least one part")
    first = parts[0]
    values = {}
    for f in dataclasses.fields(PointCloud):
        values[f.name] = getattr(first, f.name)
    names = {name: array for p in parts for name, array in _per_point(p)}
    for name, example in names.items():
        # A part without the field (None, e.g. no withheld flag set in that file) gets zeros.
        arrays = [getattr(p, name) if getattr(p, name) is not None else
                  np.zeros((len(p),) + example.shape[1:], dtype=example.dtype) for p in parts]
        values[name] = np.concatenate(arrays) if len(arrays) > 1 else arrays[0]
    if any(p.attributes is not None for p in parts):  # (an algorithm's values of each part: every part has them)
        keys = set(parts[0].attributes or ())
        if any(set(p.attributes or ()) != keys for p in parts):
            raise InputError(f"{path or first.path}: the tile's parts carry different point attributes")
        values["attributes"] = {k: np.concatenate([p.attributes[k] for p in parts]) for k in sorted(keys)}
    values["las"] = None
    if path is not None:
        values["path"] = path
    return PointCloud(**values)


def subset_cloud(cloud: PointCloud, idx) -> PointCloud:
    """The points ``idx`` (indices or boolean mask) of ``cloud``, every per-point field kept."""
    values = {f.name: getattr(cloud, f.name) for f in dataclasses.fields(PointCloud)}
    for name, array in _per_point(cloud):
        values[name] = array[idx]
    if cloud.attributes is not None:
        values["attributes"] = {name: array[idx] for name, array in cloud.attributes.items()}
    values["las"] = None
    return PointCloud(**values)


# -- streaming a file into tile parts ------------------------------------------------------------

@dataclass(frozen=True)
class TileGrid:
    """Square tiles of ``size`` m on multiples of ``size`` (tile (i, j) covers
    ``[i*size, (i+1)*size) x [j*size, (j+1)*size)``), each read with ``buffer`` m around it.

    ``edge``: the survey's far edges, its headers' (xmax, ymax) (:meth:`for_survey`). Where one lies on a
    tile line, the points on it belong to the tile below it, which the edge closes, not to a tile of
    their own beyond the survey: a delivery of files on multiples of the tile size, points on both edges,
    made a row and a column of tiles of a few points each, every one filtering its whole buffer (9 files
    of 100 m made 15 tiles, 6 of them of 1-6 points reading about 150,000 buffer points each: a UAV
    reviewer). Points beyond the headers keep their own tiles."""
    size: float
    buffer: float
    edge: Tuple[float, float] = (math.inf, math.inf)

    @classmethod
    def for_survey(cls, size: float, buffer: float, box) -> "TileGrid":
        """The grid of a survey whose headers span ``box`` (xmin, ymin, xmax, ymax)."""
        return cls(float(size), float(buffer), (float(box[2]), float(box[3])))

    def edge_keys(self) -> Tuple[int, int]:
        """The tile index, along x and y, that the far edge closes (its points go to the one below):
        the edge's where it lies on a tile line (within floating-point noise), else none
        (:data:`NO_EDGE_KEY`)."""
        def key(v):
            if not math.isfinite(v):
                return NO_EDGE_KEY
            k = round(v / self.size)
            return int(k) if abs(v / self.size - k) <= 1e-9 * max(1.0, abs(k)) else NO_EDGE_KEY
        return key(self.edge[0]), key(self.edge[1])

    def key_of(self, x: np.ndarray, y: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        kx = np.floor(np.asarray(x) / self.size).astype(np.int64)
        ky = np.floor(np.asarray(y) / self.size).astype(np.int64)
        ex, ey = self.edge_keys()
        if ex != NO_EDGE_KEY:
            kx = np.where((kx == ex) & (np.asarray(x) <= self.edge[0]), kx - 1, kx)
        if ey != NO_EDGE_KEY:
            ky = np.where((ky == ey) & (np.asarray(y) <= self.edge[1]), ky - 1, ky)
        return kx, ky

    def bounds(self, key) -> Tuple[float, float, float, float]:
        i, j = key
        return (i * self.size, j * self.size, (i + 1) * self.size, (j + 1) * self.size)


#: :meth:`TileGrid.edge_keys` of an edge on no tile line
NO_EDGE_KEY = -(1 << 62)


@dataclass
class TilePart:
    """The points of one input file that one tile (with its buffer) needs: their indices in the
    input (``>= 0``: the tile's own point; ``-1 - index``: a buffer point; int32 when the file has
    fewer than 2**31 points, int64 otherwise), in file order, in ``index_path``. Their records are
    read from the input's records as the binning kept them in file order (``records_path``, raw
    records of ``record_size`` bytes): a tile part copies no record, so the working folder holds
    each record once (the classified copy is written from the same file)."""
    file_index: int
    records_path: str
    index_path: str
    own_count: int = 0      #: points of the tile itself (the rest is buffer)
    count: int = 0          #: points of the tile and its buffer
    span: int = 0           #: records a tile reads to gather them (per chunk, first to last point)
    copy_path: str = ""     #: where the points lie scattered in the file: their records, copied
    point_format: int = 0   #: the input's point format (how the record bytes read)
    record_size: int = 0    #: bytes per record in ``records_path``
    scales: tuple = (1.0, 1.0, 1.0)
    offsets: tuple = (0.0, 0.0, 0.0)
    index_dtype: str = "<i8"


def _chunks(reader, first: int, stop: Optional[int], chunk_points: int, path: str = "the file"):
    """The reader's points ``first`` to ``stop`` (None: the end), ``chunk_points`` at a time."""
    if first == 0 and stop is None:
        yield from reader.chunk_iterator(chunk_points)
        return
    stop = int(reader.header.point_count) if stop is None else stop
    if first:
        reader.seek(first)  # LAZ: from the chunk table, decoding only the chunk it lands in
    pos = first
    while pos < stop:
        chunk = reader.read_points(min(chunk_points, stop - pos))
        if len(chunk) == 0:
            raise InputError(f"{path}: the header announces {reader.header.point_count:,} points but the file ends "
                             f"before point {pos + 1:,}: the file is truncated or its header's count is wrong")
        pos += len(chunk)
        yield chunk


def index_dtype(count: int) -> np.dtype:
    """The dtype of a tile part's indices into a file of ``count`` points."""
    return np.dtype("<i4") if count < (1 << 31) - 1 else np.dtype("<i8")


def file_positions(index: np.ndarray) -> np.ndarray:
    """The points' places in the file (int64) of a tile part's indices (``-1 - index`` for a buffer
    point)."""
    return np.where(index >= 0, index, -1 - index).astype(np.int64)


def _read_records(fd: int, buffer: np.ndarray, first: int, stop: int, size: int, path: str) -> np.ndarray:
    """Records ``first`` to ``stop`` of the records file ``path`` (open as ``fd``), read at once into
    ``buffer``: rows of ``size`` bytes."""
    rows = buffer[:(stop - first) * size]
    if os.preadv(fd, [memoryview(rows)], first * size) != rows.size:
        raise InputError(f"{path}: ends before record {stop - 1:,}; the working folder was changed during the run")
    return rows.reshape(-1, size)


def merge_bounds(a: Optional[list], b: list) -> list:
    """The [xmin, ymin, xmax, ymax] holding both ``a`` (None or empty: nothing yet) and ``b``."""
    if not a:
        return list(b)
    return [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])]


def bin_file(path: str, file_index: int, grid: TileGrid, work_dir: str, *, chunk_points: int = CHUNK_POINTS,
             check=None, first: int = 0, stop: Optional[int] = None, piece: Optional[int] = None,
             records: Optional[str] = None, bounds: Optional[list] = None,
             clip: Optional[Sequence[float]] = None) -> Dict[tuple, TilePart]:
    """Stream ``path`` once (laspy chunks) and write, for every tile its points or buffer touch,
    the part of the file that tile needs into ``work_dir``. Tiles exist only where points are.
    ``first``/``stop`` bin only those points of the file (one ``piece`` of it, named in the parts'
    file names): pieces binned in parallel, their parts taken in file order, give the whole file's.
    ``records``: the file (created if missing; ``fNNNNN.rec`` in ``work_dir`` when None) into which
    the decoded records are written, at their place in file order: the tiles read their points
    from it (:func:`read_part`), and the classified copy is written from it without decoding the
    input again (:func:`write_classified_piece`).

    A point goes to its own tile (``TileGrid.key_of``) and to every tile whose buffer holds it
    (:func:`_in_buffer`), in one numba pass a chunk (``_binning_kernels``); each part lists its
    points in file order. ``bounds``: a list given the points' [xmin, ymin, xmax, ymax] (as stored,
    scaled integers), to compare with the header's.

    ``clip`` (xmin, ymin, xmax, ymax): only the points in that box are binned, numbered (and kept in
    ``records``) 0, 1, ... in file order among them, not by their place in the file: a neighbouring
    file that lends a few tiles their buffers (engine/one_file.py), of which nothing is written."""
    import laspy

    from ._binning_kernels import bin_chunk_kernel
    parts: Dict[tuple, TilePart] = {}
    index_files = {}
    if records is None:
        records = os.path.join(work_dir, f"f{file_index:05d}.rec")
    m = int(math.ceil(grid.buffer / grid.size)) if grid.buffer > 0 else 0
    edge_x, edge_y = grid.edge_keys()
    stem = f"f{file_index:05d}" + (f"p{piece:04d}" if piece is not None else "")
    fd = os.open(records, os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        with laspy.open(path) as reader:
            h = reader.header
            idx_dtype = index_dtype(int(h.point_count))
            scales, offsets = tuple(float(v) for v in h.scales), tuple(float(v) for v in h.offsets)
            start = first
            for chunk in _chunks(reader, first, stop, chunk_points, path):
                if check is not None:
                    check()
                recs = np.ascontiguousarray(chunk.array)
                if clip is not None:
                    x = recs["X"] * scales[0] + offsets[0]
                    y = recs["Y"] * scales[1] + offsets[1]
                    recs = recs[(x >= clip[0]) & (x <= clip[2]) & (y >= clip[1]) & (y <= clip[3])]
                    if not len(recs):
                        continue
                n = len(recs)
                raw = recs.view(np.uint8).reshape(n, recs.dtype.itemsize)
                flat = memoryview(raw).cast("B")
                done = 0
                while done < len(flat):  # (pwrite may write less than asked)
                    done += os.pwrite(fd, flat[done:], start * recs.dtype.itemsize + done)
                if bounds is not None and n:
                    bounds[:] = merge_bounds(bounds, [int(recs["X"].min()), int(recs["Y"].min()),
                                                      int(recs["X"].max()), int(recs["Y"].max())])
                kx0, ky0, nky, cuts, out_idx, own_count = bin_chunk_kernel(
                    recs["X"], recs["Y"], scales[0], offsets[0], scales[1], offsets[1], float(grid.size),
                    float(grid.buffer), m, start, edge_x, edge_y, grid.edge[0], grid.edge[1])
                out_idx = out_idx.astype(idx_dtype, copy=False)
                for b in np.flatnonzero(np.diff(cuts)):
                    lo, hi = int(cuts[b]), int(cuts[b + 1])
                    tkey = (int(kx0 + b // nky), int(ky0 + b % nky))
                    if tkey not in index_files:
                        name = os.path.join(work_dir, f"{stem}_{tkey[0]}_{tkey[1]}.idx")
                        parts[tkey] = TilePart(file_index, records, name, point_format=int(h.point_format.id),
                                               record_size=int(recs.dtype.itemsize),
                                               scales=scales, offsets=offsets, index_dtype=idx_dtype.str)
                        index_files[tkey] = open(name, "wb")
                    index_files[tkey].write(memoryview(out_idx[lo:hi]).cast("B"))
                    parts[tkey].own_count += int(own_count[b])
                    parts[tkey].count += hi - lo
                    a, z = file_positions(out_idx[[lo, hi - 1]])
                    parts[tkey].span += int(z - a) + 1
                start += n
            for f in index_files.values():
                f.close()
            scattered = [p for p in parts.values()
                         if p.span > SCATTER_FACTOR * p.count and p.span > SCATTER_FACTOR * chunk_points]
            if scattered:
                _copy_scattered(records, scattered, first, start, check)
    except OSError as err:
        raise OutputError(f"{work_dir}: cannot write the temporary tiles of {path} ({err}); "
                          "point the working folder at a disk with more room") from err
    except GroundSieveError:
        raise
    except Exception as err:  # laspy / lazrs on a damaged or truncated file
        if not (raised_by_the_reader(err) or isinstance(err, MemoryError)):  # (a fault of our own, not the file's)
            raise
        raise points_error(path, err) from err
    finally:
        for f in index_files.values():
            f.close()
        os.close(fd)
    return parts


#: a part whose points a tile would gather from more than this many times as many records (and
#: more than this many chunks' worth): a file in no spatial order. Its records are copied once at
#: the end of the binning instead of read by every tile from all over the file.
SCATTER_FACTOR = 4


def _copy_scattered(records: str, parts: Sequence[TilePart], first: int, stop: int, check=None) -> None:
    """Copy the records of ``parts`` (of the records ``first`` to ``stop``, in file order) into a file
    beside each part's index (``copy_path``), in one pass over those records, window by window; each
    part's indices are read as the pass goes (memory: a window, and a batch of indices a part)."""
    size = parts[0].record_size
    per = max(1, READ_WINDOW_BYTES // size)
    batch = 1 << 20
    state = []
    try:
        for p in parts:
            p.copy_path = p.index_path[:-len(".idx")] + ".rec"
            state.append([open(p.index_path, "rb"), np.empty(0, dtype=np.int64), open(p.copy_path, "wb"), p])
        fd = os.open(records, os.O_RDONLY)
        try:
            buffer = np.empty(min(per, max(stop - first, 1)) * size, dtype=np.uint8)
            for w0 in range(first, stop, per):
                if check is not None:
                    check()
                w1 = min(w0 + per, stop)
                rows = _read_records(fd, buffer, w0, w1, size, records)
                for entry in state:
                    index_file, pending, out, p = entry
                    while not pending.size or pending[-1] < w1:
                        more = np.fromfile(index_file, dtype=np.dtype(p.index_dtype), count=batch)
                        if not more.size:
                            break
                        pending = np.concatenate([pending, file_positions(more)])
                    cut = int(np.searchsorted(pending, w1))
                    if cut:
                        out.write(memoryview(np.ascontiguousarray(rows[pending[:cut] - w0])).cast("B"))
                    entry[1] = pending[cut:]
        finally:
            os.close(fd)
    finally:
        for index_file, _pending, out, _p in state:
            index_file.close()
            out.close()


def _in_buffer(f: np.ndarray, d, grid: TileGrid) -> np.ndarray:
    """Whether points at ``f`` (their position inside their own tile, [0, size), along x or y) lie
    within the buffer of the tile ``d`` tiles away along that axis (all of them for d = 0); ``d``
    one step for all points, or one per point (each point then tested as for its own step)."""
    if np.ndim(d):
        out = np.empty(f.shape[0], dtype=bool)
        for step in np.unique(d):
            at = d == step
            out[at] = _in_buffer(f[at], int(step), grid)
        return out
    if d < 0:
        return f + (-d - 1) * grid.size < grid.buffer
    if d > 0:
        return (grid.size - f) + (d - 1) * grid.size <= grid.buffer
    return np.ones(f.shape[0], dtype=bool)


#: a tile reads its records from the records file in windows of at most this many bytes of
#: consecutive records (its points are in file order), each read at once into one buffer
READ_WINDOW_BYTES = 64 << 20


def read_part(part: TilePart, header=None) -> Tuple[PointCloud, np.ndarray]:
    """The cloud of one tile part (the fields a tile cloud has: x, y, z, classification, returns,
    intensity, withheld; decoded as laspy decodes them) and its index array; with ``header`` (the
    input's laspy header), the cloud's ``las`` holds the part's records too, every dimension, for
    an algorithm that takes more of them (:func:`records_las`). The records are
    gathered from the records file window by window (:data:`READ_WINDOW_BYTES`): fast where a
    tile's points lie in runs in file order (the order of acquisition, or any spatial sort); those
    of a part scattered over a file in no such order were copied at the binning
    (:data:`SCATTER_FACTOR`) and are read from their copy."""
    index = np.fromfile(part.index_path, dtype=np.dtype(part.index_dtype))
    at = file_positions(index)
    size = part.record_size
    held = os.path.getsize(part.records_path) // size if os.path.exists(part.records_path) else 0
    if index.shape[0] != part.count or (at.size and (at[-1] >= held or np.any(np.diff(at) <= 0))):
        raise InputError(f"{part.index_path}: {index.shape[0]:,} indices, not the {part.count:,} points binned into "
                         f"{part.records_path} ({held:,} records); the working folder was changed during the run")
    if part.copy_path:  # a part scattered over the file: its records copied at the binning
        rec = np.fromfile(part.copy_path, dtype=np.uint8)
        if rec.size != at.size * size:
            raise InputError(f"{part.copy_path}: {rec.size // size:,} records, not the {at.size:,} points of "
                             f"{part.index_path}; the working folder was changed during the run")
        return _part_cloud(part, rec.reshape(-1, size), header), index
    rec = np.empty((at.size, size), dtype=np.uint8)
    per_window = max(1, READ_WINDOW_BYTES // size)
    buffer = np.empty(min(per_window, int(at[-1] - at[0]) + 1 if at.size else 0) * size, dtype=np.uint8)
    fd = os.open(part.records_path, os.O_RDONLY)
    try:
        lo = 0
        while lo < at.size:  # a window of consecutive records read at once, the part's taken from it
            first = int(at[lo])
            hi = int(np.searchsorted(at, first + per_window, side="left"))
            rows = _read_records(fd, buffer, first, int(at[hi - 1]) + 1, size, part.records_path)
            rec[lo:hi] = rows[at[lo:hi] - first]
            lo = hi
    finally:
        os.close(fd)
    return _part_cloud(part, rec, header), index


def records_las(header, rec: np.ndarray, path: str):
    """A laspy ``LasData`` of raw point records ``rec`` (rows of ``header``'s point format size, as the
    binning kept them; not copied), whose dimensions read as those of the file ``path`` read whole."""
    import laspy
    pf = header.point_format
    if rec.ndim != 2 or rec.shape[1] != pf.size:
        raise InputError(f"{path}: its records are {rec.shape[-1]} bytes, its header's point format {pf.id} "
                         f"{pf.size}: the file changed during the run")
    array = np.ascontiguousarray(rec).reshape(-1).view(pf.dtype())
    return laspy.LasData(header=header, points=laspy.PackedPointRecord(array, pf))


def _part_cloud(part: TilePart, rec: np.ndarray, header=None) -> PointCloud:
    """The tile cloud of a part's records (rows of ``record_size`` bytes); with ``header``, its
    ``las`` holds them (:func:`records_las`)."""
    n, size = rec.shape

    def field(offset, dtype):
        return np.ndarray((n,), dtype=np.dtype(dtype), buffer=rec, offset=offset, strides=(size,))
    xyz = [field(4 * k, "<i4") * scale + offset for k, (scale, offset) in enumerate(zip(part.scales, part.offsets))]
    bits = field(14, "u1")
    if part.point_format >= 6:  # returns 4 + 4 bits; flags byte (withheld: bit 2), then the class byte
        return_number, number_of_returns = bits & 0x0F, bits >> 4
        withheld = (field(15, "u1") & 0x04).astype(bool)
        classification = field(16, "u1").copy()
    else:  # returns 3 + 3 bits; class in bits 0-4 of one byte with its flags (withheld: bit 7)
        return_number, number_of_returns = bits & 0x07, (bits >> 3) & 0x07
        cls = field(15, "u1")
        withheld = (cls & 0x80).astype(bool)
        classification = cls & 0x1F
    return PointCloud(path=part.index_path, x=xyz[0], y=xyz[1], z=xyz[2], classification=classification,
                      return_number=return_number, number_of_returns=number_of_returns,
                      intensity=field(12, "<u2").copy(), has_return_info=True,
                      withheld=withheld if withheld.any() else None,
                      las=None if header is None else records_las(header, rec, part.records_path))


# -- the classified copy --------------------------------------------------------------------------

def write_classified_stream(src: str, dst: str, classification: np.ndarray, *,
                            chunk_points: int = CHUNK_POINTS, check=None, name: Optional[str] = None,
                            atomic: bool = True) -> None:
    """Copy ``src`` to ``dst`` (LAZ when it ends in .laz) with ``classification`` (one uint8 per
    point, in file order; a memmap is fine) in one streamed pass, every other dimension, the VLRs
    and the CRS kept. Atomic: ``dst`` appears only when complete (``atomic=False``: ``dst`` is already the
    caller's staged temporary; a second one inside it outlived a killed run: a code reviewer). ``name``:
    the path its messages give."""
    import laspy
    from .copc import plain_evlrs, plain_header
    classification = np.asarray(classification)
    try:
        with laspy.open(src) as reader:
            n_total = int(reader.header.point_count)
            if classification.shape[0] != n_total:  # (a file still being written when the run read it)
                raise InputError(f"{src}: it changed during the run (its header announced "
                                 f"{classification.shape[0]:,} points when it was read, {n_total:,} now): run "
                                 "again once it is complete")
            check_classes_fit(dst, reader.header.point_format.id, classification)
            with atomic_path(dst) if atomic else contextlib.nullcontext(dst) as tmp:
                # Not COPC any more (the LAZ chunks are not the octree's nodes): no COPC records.
                with laspy.open(tmp, mode="w", header=plain_header(reader.header),
                                do_compress=_ext(dst) == ".laz", encoding_errors=TEXT_ERRORS) as writer:
                    start = 0
                    for chunk in reader.chunk_iterator(chunk_points):
                        if check is not None:
                            check()
                        n = len(chunk)
                        chunk.classification = classification[start:start + n]
                        writer.write_points(chunk)
                        start += n
                    if reader.header.version.minor >= 4 and plain_evlrs(reader.header):
                        writer.write_evlrs(writable_evlrs(plain_evlrs(reader.header)))
                finish_copy(tmp, src, name or dst)
    except OSError as err:
        raise OutputError(f"{name or dst}: cannot be written ({_reason(err)})") from err
    except GroundSieveError:
        raise
    except Exception as err:  # laspy / lazrs on a damaged or truncated input
        if not (raised_by_the_reader(err) or isinstance(err, MemoryError)):  # (a fault of our own, not the file's)
            raise
        raise points_error(src, err) from err


# -- the classified copy in pieces, from the records the binning kept -------------------------------

def laz_chunk_points(point_format) -> int:
    """Points per LAZ chunk of the classified copy (lazrs's fixed chunk size, 50,000): a piece of a
    LAZ copy starts on a multiple of it, so that the pieces' chunks are the whole file's."""
    import lazrs
    return int(lazrs.LazVlr.new_for_compression(point_format.id, point_format.num_extra_bytes).chunk_size())


def piece_cuts(count: int, pieces: int, multiple: int) -> List[int]:
    """Boundaries of at most ``pieces`` pieces of ``count`` points, each a multiple of ``multiple``
    (but the last), none empty."""
    pieces = max(1, min(pieces, -(-count // multiple)))
    cuts = [min(count, (count * p // pieces) // multiple * multiple) for p in range(pieces)] + [count]
    return sorted(set(cuts))


def write_classified_piece(src: str, records: str, classification: np.ndarray, first: int, stop: int,
                           piece_path: str, *, compress: bool, chunk_points: int = CHUNK_POINTS, check=None) -> dict:
    """Points ``first`` to ``stop`` of the classified copy of ``src``: their records, read from
    ``records`` (the input's records in file order, :func:`bin_file`), get ``classification`` (the
    piece's classes) and go, LAZ-compressed (``first`` on a LAZ chunk boundary) or raw, into
    ``piece_path``, without decoding ``src`` again (only its header is read). Returns what
    :func:`assemble_classified` needs: the header statistics of these points, grown as laspy's
    writer grows them, and the LAZ chunk table."""
    import laspy
    import lazrs
    try:
        with laspy.open(src) as reader:
            header = copy.deepcopy(reader.header)
        pf = header.point_format
        check_classes_fit(src, pf.id, classification)
        header.partial_reset()  # as laspy's writer does: the statistics come from the points written
        dtype = pf.dtype()
        vlr = lazrs.LazVlr.new_for_compression(pf.id, pf.num_extra_bytes) if compress else None
        with open(records, "rb") as f_in, open(piece_path, "wb") as f_out:
            compressor = lazrs.ParLasZipCompressor(f_out, vlr) if compress else None
            pos = first
            while pos < stop:
                if check is not None:
                    check()
                n = min(chunk_points, stop - pos)
                f_in.seek(pos * dtype.itemsize)
                array = np.fromfile(f_in, dtype=dtype, count=n)
                if array.shape[0] != n:
                    raise InputError(f"{records}: holds {pos + array.shape[0]:,} records, {stop:,} expected; "
                                     "the working folder was changed during the run")
                points = laspy.PackedPointRecord(array, pf)
                points.classification = classification[pos - first:pos - first + n]
                header.grow(points)
                if compressor is not None:
                    compressor.compress_many(np.frombuffer(points.array, np.uint8))
                else:
                    f_out.write(points.array.tobytes())
                pos += n
            if compressor is not None:
                compressor.done()
        table = None
        if compress:
            with open(piece_path, "rb") as f:
                table = [(int(c), int(b)) for c, b in lazrs.read_chunk_table(f, vlr)]
    except OSError as err:
        raise OutputError(f"{piece_path}: cannot be written ({err})") from err
    return dict(path=piece_path, first=first, table=table, stats=_header_stats(header))


def _header_stats(h) -> dict:
    # (a description without a minimum or without a maximum, e.g. undocumented bytes: None for it)
    eb = [tuple(None if value is None else value.tolist() for value in (s._raw_min(), s._raw_max()))
          for v in h.vlrs.get("ExtraBytesVlr")[:1] for s in v.extra_bytes_structs]
    return dict(mins=[float(v) for v in h.mins], maxs=[float(v) for v in h.maxs], count=int(h.point_count),
                min_gps=float(h.min_gps_time), max_gps=float(h.max_gps_time),
                by_return=[int(v) for v in h.number_of_points_by_return], eb=eb)


def _merge_stats(h, stats: Sequence[dict]) -> None:
    """Set the header's statistics to those of all pieces together (minima, maxima and sums:
    what laspy's writer would have grown from all their points)."""
    h.mins = np.min([s["mins"] for s in stats], axis=0)
    h.maxs = np.max([s["maxs"] for s in stats], axis=0)
    h.min_gps_time = min(s["min_gps"] for s in stats)
    h.max_gps_time = max(s["max_gps"] for s in stats)
    h.point_count = sum(s["count"] for s in stats)
    h.number_of_points_by_return = np.sum([s["by_return"] for s in stats], axis=0, dtype=np.uint64)
    for v in h.vlrs.get("ExtraBytesVlr")[:1]:
        for i, struct in enumerate(v.extra_bytes_structs):
            lo, hi = struct._raw_min(), struct._raw_max()
            if lo is not None:
                lo[:] = np.min([s["eb"][i][0] for s in stats], axis=0).astype(lo.dtype)
            if hi is not None:
                hi[:] = np.max([s["eb"][i][1] for s in stats], axis=0).astype(hi.dtype)


def _copy_bytes(src, dst, n: int, block: int = 16 << 20) -> None:
    while n > 0:
        data = src.read(min(block, n))
        if not data:
            raise OutputError(f"{getattr(src, 'name', '?')}: ends {n:,} bytes early; the working folder was changed")
        dst.write(data)
        n -= len(data)


def _pieces_backend(pieces):
    """A laspy LAZ backend whose writer takes the pieces' compressed chunks as they are (no point
    goes through it): the 8-byte offset of the chunk table, the chunks, the whole chunk table."""
    import struct

    import lazrs
    from laspy._compression.lazrsbackend import LazrsPointWriter
    from laspy._pointwriter import IPointWriter
    from laspy.vlrs.known import LasZipVlr

    class Writer(LazrsPointWriter):
        def write_initial_header_and_vlrs(self, header, encoding_errors):
            header.vlrs.append(LasZipVlr(self.vlr.record_data()))
            IPointWriter.write_initial_header_and_vlrs(self, header, encoding_errors)

        def write_points(self, points):
            raise NotImplementedError("the pieces are compressed already")

        def done(self):
            dest = self.dest
            start = dest.tell()
            dest.write(struct.pack("<q", -1))
            table = []
            for piece in pieces:
                with open(piece["path"], "rb") as f:
                    f.seek(8)
                    _copy_bytes(f, dest, sum(b for _c, b in piece["table"]))
                table += piece["table"]
            at = dest.tell()
            dest.flush()
            lazrs.write_chunk_table(dest, table, self.vlr)
            dest.flush()
            end = dest.tell()
            dest.seek(start)
            dest.write(struct.pack("<q", at))
            dest.seek(end)

    class Backend:
        def is_available(self):
            return True

        def create_writer(self, dest, header):
            return Writer(dest, header.point_format, parallel=False)
    return Backend()


def assemble_classified(src: str, dst: str, pieces: Sequence[dict], name: Optional[str] = None,
                        atomic: bool = True) -> None:
    """Write ``dst`` (LAZ when it ends in .laz; atomic) from the pieces of
    :func:`write_classified_piece` (in file order, together every point of ``src``): ``src``'s
    header and VLRs as laspy's writer writes them for a streamed copy, the pieces' records or LAZ
    chunks, one chunk table. The same bytes as :func:`write_classified_stream`."""
    import laspy
    from .copc import plain_evlrs, plain_header
    compress = _ext(dst) == ".laz"
    pieces = sorted(pieces, key=lambda p: p["first"])
    try:
        with laspy.open(src) as reader:
            header = plain_header(reader.header)  # as write_classified_stream: no COPC records
            evlrs = plain_evlrs(reader.header) if reader.header.version.minor >= 4 else []
        with atomic_path(dst) if atomic else contextlib.nullcontext(dst) as tmp:
            with open(tmp, "wb") as f:
                writer = laspy.LasWriter(f, header=header, do_compress=compress, closefd=False,
                                         laz_backend=_pieces_backend(pieces) if compress else None,
                                         encoding_errors=TEXT_ERRORS)
                _merge_stats(writer.header, [p["stats"] for p in pieces])
                if not compress:
                    for piece in pieces:
                        with open(piece["path"], "rb") as g:
                            _copy_bytes(g, f, os.path.getsize(piece["path"]))
                if evlrs:  # after the points (the LAZ backend's done() writes the chunks first)
                    writer.write_evlrs(writable_evlrs(evlrs))
                writer.close()
            finish_copy(tmp, src, name or dst)
    except OSError as err:
        raise OutputError(f"{name or dst}: cannot be written ({_reason(err)})") from err


def iter_chunks(path: str, chunk_points: int = CHUNK_POINTS, first: int = 0) -> Iterable:
    """laspy point records of ``path`` from point ``first`` on, ``chunk_points`` at a time; a damaged
    or truncated file is an :class:`InputError` naming it (laspy and lazrs raise many types)."""
    import laspy
    try:
        with laspy.open(path) as reader:
            yield from _chunks(reader, first, None, chunk_points, path)
    except GroundSieveError:
        raise
    except Exception as err:
        if not (raised_by_the_reader(err) or isinstance(err, MemoryError)):  # (a fault of our own, not the file's)
            raise
        raise points_error(path, err) from err
