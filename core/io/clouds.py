"""Reading and writing point clouds: LAS/LAZ (laspy + lazrs) and the ISPRS text format.

Writes are atomic (``outputs.atomic_path``): the file is written under a temporary name in the target folder
and renamed over the target only when complete, so a failed or cancelled run leaves
nothing half-written. Input files are only ever opened for reading.
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..errors import InputError, OutputError, UnsupportedFormatError
from .outputs import LAS_EXTENSIONS, _ext, atomic_path, check_output_path


TEXT_EXTENSIONS = (".txt",)
READ_EXTENSIONS = LAS_EXTENSIONS + TEXT_EXTENSIONS

#: ASPRS classification codes used by the filters.
CLASS_UNCLASSIFIED = 1
CLASS_GROUND = 2
NOISE_CLASSES = (7, 18)


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

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def xyz(self) -> np.ndarray:
        return np.column_stack([self.x, self.y, self.z])


def read_cloud(path: str) -> PointCloud:
    """Read a LAS/LAZ file or an ISPRS ``x y z [label]`` text file."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file")
    if os.path.isdir(path):
        raise InputError(f"{path}: is a folder, not a point-cloud file")
    ext = _ext(path)
    if ext in LAS_EXTENSIONS:
        cloud = _read_las(path)
    elif ext in TEXT_EXTENSIONS:
        cloud = _read_isprs_text(path)
    else:
        raise UnsupportedFormatError(
            f"{path}: unsupported file type '{ext or '(none)'}'; expected .las, .laz or ISPRS .txt")
    if len(cloud) == 0:
        raise InputError(f"{path}: the file holds no points")
    finite = np.isfinite(cloud.x) & np.isfinite(cloud.y) & np.isfinite(cloud.z)
    if not finite.all():
        raise InputError(f"{path}: {int((~finite).sum())} point(s) have NaN or infinite coordinates")
    biggest = max(np.abs(cloud.x).max(), np.abs(cloud.y).max(), np.abs(cloud.z).max())
    if biggest > 1e9:
        raise InputError(f"{path}: coordinates reach {biggest:.3g}, beyond ±1e9 m; "
                         "the header's scale/offset or the coordinate system is probably wrong")
    return cloud


def _read_las(path: str) -> PointCloud:
    import laspy
    try:
        las = laspy.read(path)
    except Exception as err:  # laspy raises many types for damaged files
        msg = str(err) or type(err).__name__
        if "signature" in msg.lower():
            raise UnsupportedFormatError(f"{path}: not a LAS/LAZ file ({msg})") from err
        raise InputError(f"{path}: cannot be read; the file is damaged or truncated ({msg})") from err
    n = int(len(las.points))
    if n != int(las.header.point_count):
        raise InputError(f"{path}: header announces {las.header.point_count} points but {n} could be read; "
                         "the file is truncated")
    crs_wkt = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            crs = las.header.parse_crs()
            crs_wkt = crs.to_wkt() if crs is not None else None
        except Exception:
            crs_wkt = None
    rn = np.asarray(las.return_number, dtype=np.uint8)
    nr = np.asarray(las.number_of_returns, dtype=np.uint8)
    return PointCloud(
        path=path,
        x=np.asarray(las.x, dtype=np.float64), y=np.asarray(las.y, dtype=np.float64),
        z=np.asarray(las.z, dtype=np.float64),
        classification=np.asarray(las.classification, dtype=np.uint8),
        return_number=rn, number_of_returns=nr,
        intensity=np.asarray(las.intensity), crs_wkt=crs_wkt, has_return_info=True, las=las)


def _read_isprs_text(path: str) -> PointCloud:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "empty input file" is reported below
            data = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except (ValueError, UnicodeDecodeError) as err:
        raise UnsupportedFormatError(
            f"{path}: not an ISPRS text file of 'x y z [label]' numbers ({err})") from err
    if data.size == 0:
        raise InputError(f"{path}: the file holds no points")
    if data.shape[1] < 3:
        raise UnsupportedFormatError(f"{path}: expected at least 3 columns 'x y z', found {data.shape[1]}")
    n = data.shape[0]
    label = data[:, 3].astype(np.uint8) if data.shape[1] >= 4 else None
    ones = np.ones(n, dtype=np.uint8)
    return PointCloud(path=path, x=data[:, 0].copy(), y=data[:, 1].copy(), z=data[:, 2].copy(),
                      classification=np.zeros(n, dtype=np.uint8), return_number=ones,
                      number_of_returns=ones.copy(), crs_wkt=None, has_return_info=False,
                      reference_label=label)


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


def write_las(las, path: str, *, atomic: bool = True) -> None:
    """Write a laspy ``LasData`` (LAZ when the name ends in .laz), atomically unless the caller
    already writes to a temporary path of its own (``atomic=False``)."""
    path = check_output_path(path)
    try:
        if atomic:
            with atomic_path(path) as tmp:
                las.write(tmp, do_compress=_ext(path) == ".laz")
        else:
            las.write(path, do_compress=_ext(path) == ".laz")
    except OSError as err:
        raise OutputError(f"{path}: cannot be written ({err})") from err


def write_classified(cloud: PointCloud, classification: np.ndarray, path: str, *, atomic: bool = True) -> None:
    """Write ``cloud`` with a new classification, keeping every other dimension, the
    extra bytes, the VLRs and the CRS of a LAS/LAZ input. An ISPRS text input becomes
    LAS 1.2 point format 0 with its label column kept as the extra dimension
    ``reference_label`` (0 = ground, 1 = object)."""
    classification = np.asarray(classification, dtype=np.uint8)
    if classification.shape != (len(cloud),):
        raise OutputError(f"{path}: classification has {classification.shape} values for {len(cloud)} points")
    if cloud.las is not None:
        las = cloud.las
        if las.point_format.id < 6 and classification.max(initial=0) > 31:
            raise OutputError(f"{path}: point format {las.point_format.id} stores classes 0-31 only")
        original = np.array(las.classification)
        las.classification = classification
        try:
            write_las(las, path, atomic=atomic)
        finally:
            las.classification = original  # the in-memory input stays as read
    else:
        extra = {"reference_label": cloud.reference_label} if cloud.reference_label is not None else None
        las = new_las(cloud.x, cloud.y, cloud.z, point_format=0, crs_wkt=cloud.crs_wkt, extra=extra,
                      classification=classification)
        write_las(las, path, atomic=atomic)
