"""Survey-scale reading and writing of LAS/LAZ: headers without points, inputs given as a file, a
folder or a QGIS virtual point cloud (``.vpc``), streaming a file's points into tile parts, tile
clouds built from those parts, and a classified copy written in one streamed pass.

Nothing here holds a whole file's points: every pass goes through laspy's chunk iterator.
"""
from __future__ import annotations

import copy
import dataclasses
import json
import math
import os
from dataclasses import dataclass
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from ..errors import GroundSieveError, InputError, OutputError, UnsupportedFormatError
from .clouds import PointCloud, header_crs_wkt, read_cloud
from .outputs import LAS_EXTENSIONS, _ext, atomic_path

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

    @property
    def area_m2(self) -> float:
        return max(self.maxs[0] - self.mins[0], 0.0) * max(self.maxs[1] - self.mins[1], 0.0)


def scan_header(path: str) -> LasInfo:
    """The header of ``path``: point count, bounds, point format, version, CRS."""
    import laspy
    from .copc import is_copc_header
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such file")
    if _ext(path) not in LAS_EXTENSIONS:
        raise UnsupportedFormatError(f"{path}: expected a .las or .laz file (got '{_ext(path) or '(none)'}')")
    try:
        with laspy.open(path) as reader:
            h = reader.header
            return LasInfo(path, int(h.point_count), tuple(float(v) for v in h.mins),
                           tuple(float(v) for v in h.maxs), int(h.point_format.id), str(h.version),
                           header_crs_wkt(h),
                           copc=is_copc_header(h))
    except (InputError, UnsupportedFormatError):
        raise
    except Exception as err:  # laspy raises many types for damaged files
        raise InputError(f"{path}: cannot read its LAS header ({err})") from err


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
        href = ((item or {}).get("assets") or {}).get("data", {}).get("href")
        if not href:
            raise InputError(f"{path}: item '{(item or {}).get('id', '?')}' has no assets.data.href")
        if href.startswith(("http://", "https://", "s3://", "/vsi")):
            raise InputError(f"{path}: remote data ({href}) is not supported; download the files first")
        full = href if os.path.isabs(href) else os.path.normpath(os.path.join(folder, href))
        if not os.path.isfile(full):
            raise InputError(f"{path}: references {href}, which does not exist ({full})")
        files.append(full)
    return files


def expand_inputs(path: str) -> List[str]:
    """The point-cloud files behind an input: itself, the LAS/LAZ files of a folder (sorted), or
    the files a ``.vpc`` references."""
    path = os.fspath(path)
    if os.path.isdir(path):
        files = sorted(os.path.join(path, n) for n in os.listdir(path)
                       if _ext(n) in LAS_EXTENSIONS and os.path.isfile(os.path.join(path, n)))
        if not files:
            raise InputError(f"{path}: the folder holds no .las or .laz file")
        return files
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file or folder")
    if _ext(path) == VPC_EXTENSION:
        return read_vpc(path)
    return [path]


def check_survey(infos: Sequence[LasInfo]) -> None:
    """Refuse inputs that cannot be one survey: different CRS or point formats, duplicates."""
    seen = {}
    for info in infos:
        real = os.path.realpath(info.path)
        if real in seen:
            raise InputError(f"{info.path}: given twice (also as {seen[real]})")
        seen[real] = info.path
    formats = {i.point_format for i in infos}
    if len(formats) > 1:
        listing = ", ".join(f"{os.path.basename(i.path)}: {i.point_format}" for i in infos)
        raise InputError(f"the input files have different point formats ({listing}); convert them to one first")
    crss = {i.crs_wkt for i in infos}
    if len(crss) > 1:
        import collections
        by = collections.defaultdict(list)
        for i in infos:
            by["no CRS" if i.crs_wkt is None else i.crs_wkt.split('"')[1] if '"' in i.crs_wkt else "a CRS"].append(
                os.path.basename(i.path))
        listing = "; ".join(f"{k}: {', '.join(v[:3])}{' ...' if len(v) > 3 else ''}" for k, v in by.items())
        raise InputError(f"the input files have different CRS ({listing}); reproject them to one first")


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
    values["las"] = None
    if path is not None:
        values["path"] = path
    return PointCloud(**values)


def subset_cloud(cloud: PointCloud, idx) -> PointCloud:
    """The points ``idx`` (indices or boolean mask) of ``cloud``, every per-point field kept."""
    values = {f.name: getattr(cloud, f.name) for f in dataclasses.fields(PointCloud)}
    for name, array in _per_point(cloud):
        values[name] = array[idx]
    values["las"] = None
    return PointCloud(**values)


# -- streaming a file into tile parts ------------------------------------------------------------

@dataclass(frozen=True)
class TileGrid:
    """Square tiles of ``size`` m on multiples of ``size`` (tile (i, j) covers
    ``[i*size, (i+1)*size) x [j*size, (j+1)*size)``), each read with ``buffer`` m around it."""
    size: float
    buffer: float

    def key_of(self, x: np.ndarray, y: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        return (np.floor(x / self.size).astype(np.int64), np.floor(y / self.size).astype(np.int64))

    def bounds(self, key) -> Tuple[float, float, float, float]:
        i, j = key
        return (i * self.size, j * self.size, (i + 1) * self.size, (j + 1) * self.size)


def _part_header(header):
    return copy.deepcopy(header)


@dataclass
class TilePart:
    """The points of one input file that one tile (with its buffer) needs: an uncompressed LAS
    file of the records as they are in the input, and beside it their indices in the input
    (``>= 0``: the tile's own point; ``-1 - index``: a buffer point)."""
    file_index: int
    las_path: str
    index_path: str
    own_count: int = 0      #: points of the tile itself (the rest is buffer)


def _chunks(reader, first: int, stop: Optional[int], chunk_points: int):
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
            raise InputError(f"{reader.header.point_count:,} points announced but the file ends at {pos:,}")
        pos += len(chunk)
        yield chunk


def bin_file(path: str, file_index: int, grid: TileGrid, work_dir: str, *, chunk_points: int = CHUNK_POINTS,
             check=None, first: int = 0, stop: Optional[int] = None, piece: Optional[int] = None,
             records: Optional[str] = None) -> Dict[tuple, TilePart]:
    """Stream ``path`` once (laspy chunks) and write, for every tile its points or buffer touch,
    the part of the file that tile needs into ``work_dir``. Tiles exist only where points are.
    ``first``/``stop`` bin only those points of the file (one ``piece`` of it, named in the parts'
    file names): pieces binned in parallel, their parts taken in file order, give the whole file's.
    ``records``: a file (created if missing) into which the decoded records are also written, at
    their place in file order, so that the classified copy is written from them without decoding
    the input again (:func:`write_classified_piece`)."""
    import laspy
    parts: Dict[tuple, TilePart] = {}
    writers = {}
    index_files = {}
    m = int(math.ceil(grid.buffer / grid.size)) if grid.buffer > 0 else 0
    stem = f"f{file_index:05d}" + (f"p{piece:04d}" if piece is not None else "")
    fd = os.open(records, os.O_WRONLY | os.O_CREAT, 0o644) if records is not None else None
    try:
        with laspy.open(path) as reader:
            start = first
            for chunk in _chunks(reader, first, stop, chunk_points):
                if check is not None:
                    check()
                n = len(chunk)
                if fd is not None:
                    raw = memoryview(np.ascontiguousarray(chunk.array)).cast("B")
                    done = 0
                    while done < len(raw):  # (pwrite may write less than asked)
                        done += os.pwrite(fd, raw[done:], start * chunk.array.dtype.itemsize + done)
                x = np.asarray(chunk.x, dtype=np.float64)
                y = np.asarray(chunk.y, dtype=np.float64)
                kx, ky = grid.key_of(x, y)
                fx = x - kx * grid.size  # position inside the own tile, [0, size)
                fy = y - ky * grid.size
                targets_k, targets_p, targets_own = [], [], []
                local = np.arange(n, dtype=np.int64)
                for dx in range(-m, m + 1):
                    inx = _in_buffer(fx, dx, grid)
                    for dy in range(-m, m + 1):
                        iny = _in_buffer(fy, dy, grid)
                        sel = local[inx & iny]
                        if sel.size == 0:
                            continue
                        key = (kx[sel] + dx) * np.int64(1 << 31) + (ky[sel] + dy)
                        targets_k.append(key)
                        targets_p.append(sel)
                        targets_own.append(np.full(sel.size, dx == 0 and dy == 0))
                keys = np.concatenate(targets_k)
                pts = np.concatenate(targets_p)
                own = np.concatenate(targets_own)
                order = np.argsort(keys, kind="stable")
                keys, pts, own = keys[order], pts[order], own[order]
                # Every target's record in one take, as fixed-size raw bytes (2.4 times faster than
                # laspy's record indexing, per tile); each tile's records are then a slice of it.
                records = chunk.array
                gathered = records.view(np.dtype((np.void, records.dtype.itemsize)))[pts].view(records.dtype)
                cuts = np.flatnonzero(np.diff(keys)) + 1
                for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, keys.size]):
                    k = int(keys[lo])
                    tkey = _split_key(k)
                    sel = pts[lo:hi]
                    if tkey not in writers:
                        name = f"{stem}_{tkey[0]}_{tkey[1]}"
                        part = TilePart(file_index, os.path.join(work_dir, name + ".las"),
                                        os.path.join(work_dir, name + ".idx"))
                        parts[tkey] = part
                        writers[tkey] = laspy.open(part.las_path, mode="w", header=_part_header(reader.header),
                                                   do_compress=False)
                        index_files[tkey] = open(part.index_path, "wb")
                    _write_part_records(writers[tkey], gathered[lo:hi], chunk.point_format)
                    parts[tkey].own_count += int(own[lo:hi].sum())
                    gidx = start + sel
                    index_files[tkey].write(np.where(own[lo:hi], gidx, -1 - gidx).astype(np.int64).tobytes())
                start += n
    except OSError as err:
        raise OutputError(f"{work_dir}: cannot write the temporary tiles of {path} ({err}); "
                          "point the working folder at a disk with more room") from err
    except GroundSieveError:
        raise
    except Exception as err:  # laspy / lazrs on a damaged or truncated file
        raise InputError(f"{path}: cannot read its points ({type(err).__name__}: {err}); "
                         "the file is damaged or truncated") from err
    finally:
        for w in writers.values():
            w.close()
        for f in index_files.values():
            f.close()
        if fd is not None:
            os.close(fd)
    return parts


def _write_part_records(writer, records: np.ndarray, point_format) -> None:
    """Append raw records to a tile part's (uncompressed) laspy writer, its header growing by their
    count and bounds only: laspy's ``write_points`` also counts the returns (``np.unique`` of every
    record's return number), which no reader of a part uses (a third of the part writes' time)."""
    import laspy
    h = writer.header
    writer.point_writer.write_points(laspy.PackedPointRecord(records, point_format))
    h.point_count += records.shape[0]
    ints = [records[name] for name in ("X", "Y", "Z")]
    h.mins = np.minimum(h.mins, [v.min() * sc + off for v, sc, off in zip(ints, h.scales, h.offsets)])
    h.maxs = np.maximum(h.maxs, [v.max() * sc + off for v, sc, off in zip(ints, h.scales, h.offsets)])


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


def _split_key(k: int) -> tuple:
    i, j = divmod(k, 1 << 31)
    if j >= 1 << 30:  # negative j borrowed one from i
        i, j = i + 1, j - (1 << 31)
    return (int(i), int(j))


def read_part(part: TilePart) -> Tuple[PointCloud, np.ndarray]:
    """The cloud of one tile part (every field ``read_cloud`` gives) and its index array."""
    cloud = read_cloud(part.las_path)
    index = np.fromfile(part.index_path, dtype=np.int64)
    if index.shape[0] != len(cloud):
        raise InputError(f"{part.las_path}: {len(cloud)} points but {index.shape[0]} indices; "
                         "the working folder was changed during the run")
    cloud.las = None
    return cloud, index


# -- the classified copy --------------------------------------------------------------------------

def write_classified_stream(src: str, dst: str, classification: np.ndarray, *,
                            chunk_points: int = CHUNK_POINTS, check=None) -> None:
    """Copy ``src`` to ``dst`` (LAZ when it ends in .laz) with ``classification`` (one uint8 per
    point, in file order; a memmap is fine) in one streamed pass, every other dimension, the VLRs
    and the CRS kept. Atomic: ``dst`` appears only when complete."""
    import laspy
    from .copc import plain_evlrs, plain_header
    classification = np.asarray(classification)
    try:
        with laspy.open(src) as reader:
            n_total = int(reader.header.point_count)
            if classification.shape[0] != n_total:
                raise OutputError(f"{dst}: {classification.shape[0]} classes for {n_total} points of {src}")
            if reader.header.point_format.id < 6 and n_total and int(classification.max()) > 31:
                raise OutputError(f"{dst}: point format {reader.header.point_format.id} stores classes 0-31 only")
            with atomic_path(dst) as tmp:
                # Not COPC any more (the LAZ chunks are not the octree's nodes): no COPC records.
                with laspy.open(tmp, mode="w", header=plain_header(reader.header),
                                do_compress=_ext(dst) == ".laz") as writer:
                    start = 0
                    for chunk in reader.chunk_iterator(chunk_points):
                        if check is not None:
                            check()
                        n = len(chunk)
                        chunk.classification = classification[start:start + n]
                        writer.write_points(chunk)
                        start += n
                    if reader.header.version.minor >= 4 and plain_evlrs(reader.header):
                        writer.write_evlrs(plain_evlrs(reader.header))
    except OSError as err:
        raise OutputError(f"{dst}: cannot be written ({err})") from err
    except GroundSieveError:
        raise
    except Exception as err:  # laspy / lazrs on a damaged or truncated input
        raise InputError(f"{src}: cannot read its points ({type(err).__name__}: {err}); "
                         "the file is damaged or truncated") from err


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
        if pf.id < 6 and classification.size and int(classification.max()) > 31:
            raise OutputError(f"{src}: point format {pf.id} stores classes 0-31 only")
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
    eb = [(s._raw_min().tolist(), s._raw_max().tolist())
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
            lo[:] = np.min([s["eb"][i][0] for s in stats], axis=0).astype(lo.dtype)
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


def assemble_classified(src: str, dst: str, pieces: Sequence[dict]) -> None:
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
        with atomic_path(dst) as tmp, open(tmp, "wb") as f:
            writer = laspy.LasWriter(f, header=header, do_compress=compress, closefd=False,
                                     laz_backend=_pieces_backend(pieces) if compress else None)
            _merge_stats(writer.header, [p["stats"] for p in pieces])
            if not compress:
                for piece in pieces:
                    with open(piece["path"], "rb") as g:
                        _copy_bytes(g, f, os.path.getsize(piece["path"]))
            if evlrs:  # after the points (the LAZ backend's done() writes the chunks first)
                writer.write_evlrs(evlrs)
            writer.close()
    except OSError as err:
        raise OutputError(f"{dst}: cannot be written ({err})") from err


def iter_chunks(path: str, chunk_points: int = CHUNK_POINTS) -> Iterable:
    """laspy point records of ``path``, ``chunk_points`` at a time; a damaged or truncated file is an
    :class:`InputError` naming it (laspy and lazrs raise many types)."""
    import laspy
    try:
        with laspy.open(path) as reader:
            yield from reader.chunk_iterator(chunk_points)
    except GroundSieveError:
        raise
    except Exception as err:
        raise InputError(f"{path}: cannot read its points ({type(err).__name__}: {err}); "
                         "the file is damaged or truncated") from err
