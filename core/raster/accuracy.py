"""A DTM's vertical accuracy against independently surveyed checkpoints, as a surveyor's QA reports it
under the ASPRS Positional Accuracy Standards for Digital Geospatial Data.

**Sampling.** dz = DTM - checkpoint z (positive: the DTM lies above the ground surveyed). The DTM is
read with GDAL, whose geotransform gives the cells' corners (pixel-is-area; a GeoTIFF marked
pixel-is-point is shifted by half a cell by GDAL itself), so cell (row, col)'s centre is at
``x0 + (col + 0.5) * dx, y0 + (row + 0.5) * dy``. The DTM's height at a checkpoint is the bilinear
interpolation of the four cell centres around it; when one of the four is nodata or beyond the
raster's edge (a checkpoint in the outer half cell), the value of the cell the checkpoint lies in is
taken instead, and when that cell is nodata too, or the checkpoint lies outside the raster, the
checkpoint is skipped, counted and named. Only the windows around the checkpoints are read, never the
whole raster.

**Figures**, for all checkpoints used and for each land cover (NVA: non-vegetated, VVA: vegetated):
count, mean error (bias), standard deviation (n - 1), RMSEz, minimum, maximum, and the 95th percentile of
|dz| (linear interpolation between order statistics, numpy's default). What each edition reports:

- Edition 1 (2014): NVA at the 95 % confidence level = 1.96 x RMSEz (errors taken as normal); VVA at
  the 95th percentile of |dz| (vegetated errors are not normal).
- Edition 2 (2023): the 95 % figures are dropped; NVA and VVA are each reported as their RMSEz. Its
  product accuracy also counts the checkpoints' own survey accuracy: not included here (:data:`ED2_NOTE`).

Checkpoints with |dz| > 3 x their land cover's RMSEz (the overall RMSEz for unlabelled ones) are named as
outliers and kept in every figure: removing them is the surveyor's decision. A class with fewer than
:data:`MIN_CHECKPOINTS` checkpoints is warned about. With 9 checkpoints or fewer, no residual can exceed
3 x RMSEz (the largest |dz| is at most sqrt(n) x RMSEz), so none can be named."""
from __future__ import annotations

import math
import os
import dataclasses
from dataclasses import dataclass, field
from typing import Optional, Sequence, Tuple

import numpy as np

from ..errors import InputError
from ..io.checkpoints import NVA, UNLABELLED, VVA, Checkpoints
from ..io.outputs import check_output_path

#: ASPRS Edition 1 (2014): NVA at 95 % confidence = this x RMSEz
NVA_FACTOR = 1.96
#: a land cover with fewer checkpoints than this is warned about (ASPRS Edition 1's minimum of 20)
MIN_CHECKPOINTS = 20
#: ASPRS Edition 2 (2023)'s minimum for a product's accuracy assessment
MIN_CHECKPOINTS_ED2 = 30
#: in a DTM that declares no nodata value, a cell at or below this is nodata all the same (the usual -9999,
#: -32767, -3.4e38: no DTM of a lidar or photogrammetric survey lies 9,999 m or ft below its datum); a
#: surveyor's DTM without its nodata tag gave an RMSEz of 10,164 m, the -9999 cells blended into the samples
UNDECLARED_NODATA = -9999.0
#: a mean error above this many times the standard deviation is said as a systematic offset (a flood
#: modeller's checkpoints in metres against a DTM in feet: a mean of +47.2 ft, a deviation of 3.3 ft, no word)
OFFSET_FACTOR = 3.0
#: |dz| above this many times its class's RMSEz names a checkpoint an outlier
OUTLIER_FACTOR = 3.0

#: how each checkpoint was sampled: bilinear, or the value of the cell it lies in (a neighbour nodata
#: or beyond the edge); skipped: outside the raster, or on nodata
BILINEAR, CELL, OUTSIDE, NODATA = "bilinear", "cell", "outside", "nodata"
USED = (BILINEAR, CELL)
#: what the Edition 2 figures here leave out (a surveyor: a reviewer would not take them as Edition 2's
#: product accuracy without it)
ED2_NOTE = "of the DTM against the checkpoints; Edition 2's product accuracy also counts the checkpoints' own survey " \
           "accuracy, which is not included here"
SIGN_CONVENTION = "dz = DTM - checkpoint z (positive: the DTM lies above the checkpoint)"


@dataclass(frozen=True)
class Figures:
    """The figures of one group of checkpoints (all used, NVA or VVA); NaN where undefined (the
    standard deviation of one checkpoint)."""
    land_cover: str  # "all", "NVA" or "VVA"
    count: int
    mean: float
    std: float
    rmse: float
    min: float
    max: float
    p95_abs: float

    @property
    def ed1_95(self) -> float:
        """Edition 1's 95 % figure of this group: 1.96 x RMSEz for NVA (and for all checkpoints, as the
        NSSDA's AccuracyZ), the 95th percentile of |dz| for VVA."""
        return self.p95_abs if self.land_cover == VVA else NVA_FACTOR * self.rmse

    @property
    def ed1_label(self) -> str:
        return "95th percentile of |dz|" if self.land_cover == VVA else "1.96 x RMSEz"


def figures(dz: np.ndarray, land_cover: str = "all") -> Figures:
    """The figures of the residuals ``dz`` (at least one)."""
    dz = np.asarray(dz, dtype=np.float64)
    n = len(dz)
    return Figures(land_cover=land_cover, count=n, mean=float(dz.mean()),
                   std=float(dz.std(ddof=1)) if n > 1 else math.nan,
                   rmse=float(np.sqrt(np.mean(dz * dz))), min=float(dz.min()), max=float(dz.max()),
                   p95_abs=float(np.percentile(np.abs(dz), 95)))


@dataclass(frozen=True)
class AccuracyResult:
    """A DTM's accuracy check: every checkpoint (arrays, one value each: its DTM height and dz are
    NaN when skipped) and the figures of those used."""
    dtm: str
    checkpoints: str
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    dtm_z: np.ndarray
    dz: np.ndarray
    ids: Tuple[str, ...]
    land_cover: Tuple[str, ...]
    status: Tuple[str, ...]
    unit: str = ""
    labelled: bool = False
    overall: Optional[Figures] = None
    nva: Optional[Figures] = None
    vva: Optional[Figures] = None
    outlier_indices: Tuple[int, ...] = ()
    warnings: Tuple[str, ...] = field(default=())
    #: the DTM's CRS by name (its vertical part too, where it has one); "" without one
    crs: str = ""

    @property
    def outliers(self) -> Tuple[str, ...]:
        """The ids of the outliers (|dz| > 3 x their land cover's RMSEz), in the checkpoints' order."""
        return tuple(self.ids[i] for i in self.outlier_indices)

    @property
    def used(self) -> np.ndarray:
        return np.isin(np.asarray(self.status), USED)

    @property
    def count(self) -> int:
        return int(self.used.sum())

    @property
    def skipped(self) -> Tuple[Tuple[str, str], ...]:
        """(id, "outside" or "nodata") of each checkpoint skipped."""
        return tuple((i, s) for i, s in zip(self.ids, self.status) if s not in USED)

    @property
    def unlabelled(self) -> int:
        """Checkpoints used without a land cover."""
        return int(sum(1 for u, c in zip(self.used, self.land_cover) if u and c == UNLABELLED))

    def by_class(self) -> Tuple[Figures, ...]:
        return tuple(f for f in (self.nva, self.vva) if f is not None)

    def outlier_mask(self) -> np.ndarray:
        mask = np.zeros(len(self.ids), dtype=bool)
        mask[list(self.outlier_indices)] = True
        return mask


class _Raster:
    """The DTM band, opened with GDAL, read a window at a time."""

    def __init__(self, path: str, band: int, name: str):
        from osgeo import gdal
        gdal.UseExceptions()
        self.name = name
        if os.path.isdir(path):
            raise InputError(f"{name}: is a folder, not a raster")
        try:  # (a path, or any name GDAL opens: /vsizip/..., GPKG:file:table)
            self.ds = gdal.Open(path)
        except RuntimeError as err:
            if not os.path.exists(path):
                raise InputError(f"{name}: no such file") from None
            raise InputError(f"{name}: not a raster GDAL can read ({err})") from None
        if self.ds is None:
            raise InputError(f"{name}: not a raster GDAL can read")
        if not 1 <= band <= self.ds.RasterCount:
            count = self.ds.RasterCount
            raise InputError(f"{name} has no band {band} (it has {count} band{'s' if count != 1 else ''})")
        self.band = self.ds.GetRasterBand(band)
        self.mask = self.band.GetMaskBand()
        gt = self.ds.GetGeoTransform(can_return_null=True)
        if gt is None:
            raise InputError(f"{name}: has no georeferencing (no geotransform): its cells have no coordinates")
        if gt[2] != 0 or gt[4] != 0:
            raise InputError(f"{name}: its grid is rotated (geotransform {tuple(gt)}); warp it to a north-up grid "
                             "first (gdalwarp)")
        self.x0, self.dx, _r1, self.y0, _r2, self.dy = gt
        self.ncols, self.nrows = self.ds.RasterXSize, self.ds.RasterYSize
        self.crs_wkt = self.ds.GetProjection() or None
        self.unit = self.band.GetUnitType() or ""
        #: without a declared nodata value, cells at or below UNDECLARED_NODATA are taken as nodata; counted
        self.declared = self.band.GetNoDataValue() is not None
        self.undeclared = 0

    def extent(self) -> Tuple[float, float, float, float]:
        xs = (self.x0, self.x0 + self.ncols * self.dx)
        ys = (self.y0, self.y0 + self.nrows * self.dy)
        return min(xs), min(ys), max(xs), max(ys)

    def window(self, row: int, col: int, rows: int, cols: int) -> np.ndarray:
        """The values of the window (NaN where nodata or masked)."""
        values = self.band.ReadAsArray(col, row, cols, rows).astype(np.float64)
        valid = (self.mask.ReadAsArray(col, row, cols, rows) != 0) & np.isfinite(values)
        if not self.declared:
            sentinel = valid & (values <= UNDECLARED_NODATA)
            if sentinel.any():
                self._sentinel_seen = True
                valid &= ~sentinel
        return np.where(valid, values, np.nan)

    def sample(self, x: float, y: float) -> Tuple[float, str]:
        """(the DTM's height at x, y, how it was sampled); counts the checkpoints next to an undeclared
        nodata value (once each: a code reviewer saw 6 for 3, the window read twice)."""
        self._sentinel_seen = False
        found = self._sample(x, y)
        self.undeclared += self._sentinel_seen
        return found

    def _sample(self, x: float, y: float) -> Tuple[float, str]:
        col_f = (x - self.x0) / self.dx
        row_f = (y - self.y0) / self.dy
        if not (0.0 <= col_f < self.ncols and 0.0 <= row_f < self.nrows):
            return math.nan, OUTSIDE
        u, v = col_f - 0.5, row_f - 0.5  # in cell-centre units
        c0, r0 = math.floor(u), math.floor(v)
        if 0 <= c0 and c0 + 1 < self.ncols and 0 <= r0 and r0 + 1 < self.nrows:
            w = self.window(r0, c0, 2, 2)
            if not np.isnan(w).any():
                fx, fy = u - c0, v - r0
                value = (w[0, 0] * (1 - fx) * (1 - fy) + w[0, 1] * fx * (1 - fy)
                         + w[1, 0] * (1 - fx) * fy + w[1, 1] * fx * fy)
                return float(value), BILINEAR
        cell = self.window(int(row_f), int(col_f), 1, 1)[0, 0]
        if np.isnan(cell):
            return math.nan, NODATA
        return float(cell), CELL

    def close(self) -> None:
        self.mask = self.band = self.ds = None


def _range(values: np.ndarray) -> str:
    return f"{np.min(values):,.2f}-{np.max(values):,.2f}"


def check_accuracy(dtm_path: str, x, y, z, *, ids: Optional[Sequence[str]] = None,
                   land_cover: Optional[Sequence[str]] = None, band: int = 1, name: Optional[str] = None,
                   checkpoints_name: str = "checkpoints") -> AccuracyResult:
    """Check the DTM at ``dtm_path`` (band ``band``) against checkpoints ``x``, ``y``, ``z`` in the
    DTM's CRS and vertical datum; ``ids`` (default "1", "2", ...) name them in the result;
    ``land_cover`` gives each "NVA", "VVA" or "" (unlabelled; core/io/checkpoints.py reads the usual
    words). ``name`` and ``checkpoints_name`` are what the messages call the DTM and the checkpoints.
    Raises InputError when no checkpoint falls on the DTM's values."""
    from osgeo import gdal
    dtm_path = os.fspath(dtm_path)
    name = name or dtm_path
    x, y, z = (np.asarray(v, dtype=np.float64).ravel() for v in (x, y, z))
    n = len(x)
    if n == 0:
        raise InputError(f"{checkpoints_name}: holds no checkpoints")
    if len(y) != n or len(z) != n:
        raise InputError(f"{checkpoints_name}: x, y and z differ in length ({n}, {len(y)}, {len(z)})")
    finite = np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
    if not finite.all():
        raise InputError(f"{checkpoints_name}: {int((~finite).sum())} checkpoint(s) have NaN or infinite coordinates")
    ids = tuple(str(i) for i in ids) if ids is not None else tuple(str(i + 1) for i in range(n))
    if len(ids) != n:
        raise InputError(f"{checkpoints_name}: {len(ids)} ids for {n} checkpoints")
    labelled = land_cover is not None
    covers = tuple(land_cover) if labelled else (UNLABELLED,) * n
    if len(covers) != n:
        raise InputError(f"{checkpoints_name}: {len(covers)} land covers for {n} checkpoints")
    bad = sorted({c for c in covers if c not in (NVA, VVA, UNLABELLED)})
    if bad:
        raise InputError(f"{checkpoints_name}: land cover must be NVA, VVA or empty (got {', '.join(map(repr, bad))})")
    raster = _Raster(dtm_path, int(band), name)
    try:
        sampled = [raster.sample(float(a), float(b)) for a, b in zip(x, y)]
        extent, unit, undeclared = raster.extent(), raster.unit, raster.undeclared
        crs_name = _crs_name(raster.crs_wkt)
        if not unit and raster.crs_wkt:
            from .crs import elevation_unit
            unit = elevation_unit(raster.crs_wkt)
    except RuntimeError as err:
        raise InputError(f"{name}: cannot be read ({err})") from None
    finally:
        raster.close()
        gdal.ErrorReset()
    dtm_z = np.array([s[0] for s in sampled], dtype=np.float64)
    status = tuple(s[1] for s in sampled)
    used = np.isin(np.asarray(status), USED)
    if not used.any():
        outside = sum(1 for s in status if s == OUTSIDE)
        if outside == n:
            # x and y swapped (a PNEZD file read without its header: northing first) fall on it swapped back
            swapped = np.count_nonzero((y >= extent[0]) & (y <= extent[2]) & (x >= extent[1]) & (x <= extent[3]))
            raise InputError(
                f"none of the {n} checkpoints of {checkpoints_name} falls on {name} (the DTM covers x "
                f"{extent[0]:,.2f}-{extent[2]:,.2f}, y {extent[1]:,.2f}-{extent[3]:,.2f}; the checkpoints x {_range(x)}, "
                f"y {_range(y)}): " + (
                    f"their x and y look swapped ({swapped} of them fall on it as y, x): a file with the northing "
                    "first (PNEZD) needs a header naming its columns, e.g. Point,Northing,Easting,Elevation"
                    if swapped else "are they in another CRS than the DTM?"))
        raise InputError(f"none of the {n} checkpoints of {checkpoints_name} falls on a value of {name} "
                         f"({n - outside} on nodata, {outside} outside it)")
    dz = np.where(used, dtm_z - z, np.nan)
    overall = figures(dz[used])
    covers_arr = np.asarray(covers, dtype=object)
    classes = {}
    for cover in (NVA, VVA):
        mask = used & (covers_arr == cover)
        if mask.any():
            classes[cover] = figures(dz[mask], cover)
    outliers = [int(i) for i in np.flatnonzero(used)
                if abs(dz[i]) > OUTLIER_FACTOR * classes.get(covers[i], overall).rmse]
    warnings = _warnings(n, status, ids, labelled, classes, covers_arr, used, [ids[i] for i in outliers],
                         checkpoints_name, unit)
    if overall.count >= 5 and abs(overall.mean) > OFFSET_FACTOR * overall.std:
        warnings.append(f"the mean error ({overall.mean:+.4f}{' ' + unit if unit else ''}) is more than "
                        f"{OFFSET_FACTOR:g} times the spread (standard deviation {overall.std:.4f}): a systematic "
                        "offset, most often a vertical datum (geoid) or unit difference between the checkpoints and "
                        "the DTM; check both before reading the figures")
    if undeclared:
        warnings.append(f"{name} declares no nodata value, but holds cells of {UNDECLARED_NODATA:g} or less next to "
                        f"{undeclared} checkpoint(s): taken as nodata (an undeclared nodata value such as -9999?); "
                        "declare it, e.g. gdal_edit.py -a_nodata -9999")
    places = {}
    for i in range(n):
        places.setdefault((x[i], y[i]), []).append(ids[i])
    twins = [names for names in places.values() if len(names) > 1]
    if twins:  # (a surveyor's CSV with two checkpoints listed twice counted them twice)
        warnings.append(f"{sum(len(t) for t in twins)} checkpoints share their x and y with another "
                        f"({'; '.join(' = '.join(t) for t in twins[:6])}{'; ...' if len(twins) > 6 else ''}): each is "
                        "counted in every figure; remove the repeats if they are the same shot")
    return AccuracyResult(dtm=name, checkpoints=checkpoints_name, x=x, y=y, z=z, dtm_z=np.where(used, dtm_z, np.nan),
                          dz=dz, ids=ids, land_cover=covers, status=status, unit=unit, labelled=labelled,
                          overall=overall, nva=classes.get(NVA), vva=classes.get(VVA), outlier_indices=tuple(outliers),
                          warnings=tuple(warnings), crs=crs_name)


def _crs_name(crs_wkt: Optional[str]) -> str:
    """The CRS's name (a compound CRS's names both parts: "NAD83 / ... + NAVD88 height"); "" without one."""
    from .crs import _spatial_reference
    ref = _spatial_reference(crs_wkt)
    return (ref.GetName() or "") if ref is not None else ""


def _some(names: Sequence[str], most: int = 12) -> str:
    shown = ", ".join(names[:most])
    return shown + (f" and {len(names) - most} more" if len(names) > most else "")


def _warnings(n, status, ids, labelled, classes, covers, used, outliers, checkpoints_name, unit) -> list:
    warnings = []
    for kind, words in ((OUTSIDE, "outside the DTM"), (NODATA, "on the DTM's nodata")):
        names = [i for i, s in zip(ids, status) if s == kind]
        if names:
            warnings.append(f"{len(names)} of the {n} checkpoints lie {words} and were skipped: {_some(names)}")
    if not labelled:
        warnings.append(f"{checkpoints_name}: no land cover given: NVA and VVA need each checkpoint labelled "
                        "(non-vegetated or vegetated); the overall figures are given alone")
    else:
        blank = int((used & (covers == UNLABELLED)).sum())
        if blank:
            warnings.append(f"{blank} checkpoint(s) have no land cover: they count in the overall figures only")
    for cover in (NVA, VVA):
        f = classes.get(cover)
        if f is not None and f.count < MIN_CHECKPOINTS:
            warnings.append(f"{cover}: {f.count} checkpoint(s), fewer than the {MIN_CHECKPOINTS} the ASPRS standards "
                            f"ask for a land cover (Edition 2 asks for {MIN_CHECKPOINTS_ED2} in all): the figures "
                            "are weakly supported")
    if not labelled and int(used.sum()) < MIN_CHECKPOINTS:
        warnings.append(f"{int(used.sum())} checkpoint(s) used, fewer than the {MIN_CHECKPOINTS} the ASPRS standards "
                        "ask for: the figures are weakly supported")
    elif int(used.sum()) < MIN_CHECKPOINTS_ED2:  # (a surveyor: 25 were used without a word)
        warnings.append(f"{int(used.sum())} checkpoint(s) used, fewer than the {MIN_CHECKPOINTS_ED2} ASPRS Edition 2 "
                        "(2023) asks for a product's accuracy assessment")
    if outliers:
        warnings.append(f"{len(outliers)} outlier(s), |dz| > {OUTLIER_FACTOR:g} x their land cover's RMSEz, kept in every "
                        f"figure: {_some(outliers)}")
    if not unit:
        warnings.append("the DTM's height unit is not recorded (no unit and no projected CRS): figures are in "
                        "its own unit")
    return warnings


def check_accuracy_of(dtm_path: str, checkpoints: Checkpoints, *, band: int = 1,
                      name: Optional[str] = None) -> AccuracyResult:
    """:func:`check_accuracy` of checkpoints read by core/io/checkpoints.py; those left out for an empty
    height are named in the warnings."""
    result = check_accuracy(dtm_path, checkpoints.x, checkpoints.y, checkpoints.z, ids=checkpoints.ids,
                            land_cover=checkpoints.land_cover, band=band, name=name,
                            checkpoints_name=checkpoints.source)
    return dataclasses.replace(result, warnings=empty_heights(checkpoints) + result.warnings)


def empty_heights(checkpoints: Checkpoints) -> tuple:
    """The warning on the checkpoints of a file left out for an empty height, as a tuple (empty without)."""
    left = checkpoints.no_height
    if not left:
        return ()
    return (f"{len(left)} checkpoint(s) with an empty height left out: {', '.join(left[:12])}"
            + (" ..." if len(left) > 12 else ""),)


# -- outputs ----------------------------------------------------------------------------------
REPORT_EXTENSIONS = (".html", ".htm")
CSV_EXTENSIONS = (".csv", ".txt")


def check_accuracy_outputs(inputs: Sequence[str], report: Optional[str] = None, csv: Optional[str] = None) -> None:
    """Refuse output paths that cannot be written, or that are an input, before any work."""
    if report:
        check_output_path(report, inputs=inputs, extensions=REPORT_EXTENSIONS, what="report")
    if csv:
        check_output_path(csv, inputs=inputs, extensions=CSV_EXTENSIONS, what="residuals CSV")
    # (never one file: their extensions differ)


def _cell(value: float, digits: int = 4) -> str:
    return "" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def residual_rows(result: AccuracyResult):
    """(header, rows) of the residuals: one row per checkpoint, skipped ones too (empty DTM z and dz)."""
    header = ["id", "x", "y", "z_checkpoint", "z_dtm", "dz_dtm_minus_checkpoint", "abs_dz", "land_cover", "sampling",
              "outlier"]
    outliers = set(result.outlier_indices)
    rows = []
    for i, ident in enumerate(result.ids):
        rows.append([ident, f"{result.x[i]:.4f}", f"{result.y[i]:.4f}", f"{result.z[i]:.4f}", _cell(result.dtm_z[i]),
                     _cell(result.dz[i]), _cell(abs(result.dz[i])), result.land_cover[i], result.status[i],
                     "yes" if i in outliers else ""])
    return header, rows


def write_residuals_csv(path: str, result: AccuracyResult) -> None:
    """The residuals as CSV (comma, UTF-8) at ``path`` as it is (:func:`write_outputs` stages it); the dz
    column's name says the sign convention."""
    import csv
    header, rows = residual_rows(result)
    with open(path, "w", encoding="utf-8", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)


def write_report(path: str, result: AccuracyResult) -> None:
    """The HTML report (core/raster/accuracy_report.py) at ``path`` as it is (:func:`write_outputs` stages it)."""
    from .accuracy_report import report_html
    text = report_html(result)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


def write_outputs(result: AccuracyResult, report: Optional[str] = None, csv: Optional[str] = None) -> None:
    """The report and the residuals' CSV, each written under a temporary name and put in place together or
    not at all (a code reviewer: a CSV that failed left the report behind)."""
    from ..errors import OutputError
    from ..io.outputs import StagedOutputs, _reason
    with StagedOutputs() as staging:
        for path, write in ((report, write_report), (csv, write_residuals_csv)):
            if path:
                try:
                    write(staging.stage(path), result)
                except OSError as err:
                    raise OutputError(f"{path}: cannot be written ({_reason(err)})") from err
        staging.commit()


def summary_lines(result: AccuracyResult) -> list:
    """The figures as log lines (the command line and the Processing log)."""
    u = f" {result.unit}" if result.unit else ""
    o = result.overall
    lines = [f"{result.count} of {len(result.ids)} checkpoints used ({len(result.skipped)} skipped); {SIGN_CONVENTION}.",
             f"All: mean {o.mean:+.4f}{u}, standard deviation {_cell(o.std) or 'n/a'}{u}, RMSEz {o.rmse:.4f}{u}, "
             f"min {o.min:+.4f}{u}, max {o.max:+.4f}{u}."]
    for f in result.by_class():
        lines.append(f"{f.land_cover} ({f.count} checkpoint{'s' if f.count != 1 else ''}): RMSEz {f.rmse:.4f}{u} (ASPRS Edition 2, 2023: "
                     f"{f.land_cover} = RMSEz, {ED2_NOTE}); {f.land_cover} at 95 % {f.ed1_95:.4f}{u} (Edition 1, 2014: "
                     f"{f.ed1_label}); mean {f.mean:+.4f}{u}.")
    return lines


def document(result: AccuracyResult) -> dict:
    """The figures as plain data (the command line's ``--json``)."""
    def figs(f: Optional[Figures]):
        if f is None:
            return None
        return {"count": f.count, "mean": f.mean, "std": f.std, "rmse": f.rmse, "min": f.min, "max": f.max,
                "p95_abs": f.p95_abs, "ed1_95": f.ed1_95, "ed1_95_method": f.ed1_label, "ed2_rmse": f.rmse}
    return {"dtm": result.dtm, "checkpoints": result.checkpoints, "unit": result.unit, "crs": result.crs,
            "sign": SIGN_CONVENTION, "count": result.count, "skipped": [{"id": i, "reason": s} for i, s in result.skipped],
            "all": figs(result.overall), "nva": figs(result.nva), "vva": figs(result.vva),
            "outliers": list(result.outliers), "warnings": list(result.warnings)}
