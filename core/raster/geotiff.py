"""GeoTIFF writing: the one module of the core that uses GDAL."""
from __future__ import annotations

import contextlib
import math
import os
from typing import Optional, Sequence, Tuple

import numpy as np

from ..errors import OutputError
from ..grids.spec import GridSpec
from ..io import atomic_path
from ..io.provenance import software
from .crs import elevation_unit, geotiff_crs

#: a DTM band's description (QGIS names the band after it in the legend: "Band 1: elevation")
ELEVATION_BAND = "elevation"

NODATA = -9999.0
#: every raster is a cloud-optimised GeoTIFF with these options (the floating-point predictor besides for heights)
COG_OPTIONS = ["COMPRESS=DEFLATE", "BIGTIFF=IF_SAFER", "OVERVIEWS=AUTO"]
RASTER_EXTENSIONS = (".tif", ".tiff")


def check_raster_path(path: str, *, inputs=()) -> str:
    from ..io import check_output_path
    return check_output_path(path, inputs=inputs, extensions=RASTER_EXTENSIONS, what="raster output")


#: heights from this magnitude on are written as Float64: Float32 keeps them to 1/256 of a unit (4 mm) at
#: most; a cloud with z in the millions (a geocentric export, a huge offset) gave a DTM in 0.5 m steps
#: (a UAV photogrammetry user). The Earth's heights stay below it in metres and in feet.
FLOAT32_LARGEST_HEIGHT = 32768.0


def float_type_for(largest_abs: float) -> str:
    """"float32", or "float64" for values of magnitude ``largest_abs`` that Float32 would round coarsely."""
    return "float64" if math.isfinite(largest_abs) and largest_abs >= FLOAT32_LARGEST_HEIGHT else "float32"


def write_geotiff(path: str, values: np.ndarray, grid: GridSpec, *, crs_wkt: Optional[str] = None,
                  nodata: float = NODATA, dtype: str = "float32", atomic: bool = True,
                  categories: Sequence[Tuple[int, str, str]] = (), elevation: bool = False,
                  name: Optional[str] = None) -> None:
    """Write ``values`` (row 0 = north, NaN = no data) as a single-band GeoTIFF, atomically unless
    the caller already writes to a temporary path of its own (``atomic=False``). ``categories``
    ``(value, name, "#rrggbb")`` of a class raster (``dtype`` uint8) are stored in the file: a
    palette, and the names in the band's description and metadata. ``elevation``: the values are
    heights (a DTM): the band's unit is the CRS's linear unit (:func:`elevation_unit`). ``name``: the
    output the messages name when ``path`` is the caller's temporary."""
    from osgeo import gdal
    gdal.UseExceptions()
    path = check_raster_path(path) if atomic else os.fspath(path)
    name = name or path
    if values.shape != grid.shape:
        raise OutputError(f"{path}: raster of shape {values.shape} does not match its grid {grid.shape}")
    if dtype not in ("float32", "float64", "uint8", "int16"):
        raise OutputError(f"{path}: cannot write a raster of type {dtype}")
    if elevation and dtype == "float32" and values.dtype.kind == "f" and values.size and np.isfinite(values).any():
        dtype = float_type_for(float(np.nanmax(np.abs(values))))
    data = np.where(np.isnan(values), nodata, values).astype(dtype) if values.dtype.kind == "f" else values.astype(dtype)
    try:
        # the array as an in-memory dataset (no copy), written as a cloud-optimised GeoTIFF: tiles,
        # overviews, DEFLATE, as a tiled run's DTM (BlockGeoTIFF.finish), so that a delivery's format
        # does not depend on whether the run was tiled (a surveyor: 256-pixel blocks without
        # overviews whole, a COG with 512-pixel blocks tiled)
        from osgeo import gdal_array
        data = np.ascontiguousarray(data)  # kept alive while the dataset reads from it
        mem = gdal_array.OpenArray(data)
        mem.SetGeoTransform(grid.geotransform)
        mem.SetMetadataItem("TIFFTAG_SOFTWARE", software())
        if crs_wkt:
            mem.SetProjection(geotiff_crs(crs_wkt))
        band = mem.GetRasterBand(1)
        band.SetNoDataValue(nodata)
        if elevation:
            band.SetUnitType(elevation_unit(crs_wkt))
            band.SetDescription(ELEVATION_BAND)
        if categories:
            _set_categories(band, categories)
        with (atomic_path(path) if atomic else contextlib.nullcontext(path)) as tmp:
            _cog(tmp, mem, COG_OPTIONS + (["PREDICTOR=YES"] if dtype.startswith("float") else []))
        band = mem = None
    except RuntimeError as err:
        raise OutputError(f"{name}: cannot write the GeoTIFF ({_gdal_reason(err, path)})") from err
    if not os.path.exists(path):
        raise OutputError(f"{name}: the GeoTIFF was not written")


def _cog(path: str, source, options, window=None, geotransform=None, output_type: Optional[str] = None) -> None:
    """Write ``source`` (a dataset or a file) to ``path`` as a COG, then check that the file holds every
    block its header points at: GDAL's COG driver only logged a full disk ("_tiffWriteProc: No space
    left on device", past any error handler) and returned, leaving a truncated DTM after a run that said
    it was done (a reviewer's small disk). ``window`` (xoff, yoff, xsize, ysize): that part of the
    source, its geotransform ``geotransform`` (GDAL's own, x0 + xoff x cell, is 500001.89999999997 where
    the grid's is 500001.9: a tiled DTM's origin differed from a whole run's in its last bit). Raises
    RuntimeError."""
    from osgeo import gdal
    if window is not None:
        source = gdal.Translate("", source, format="VRT", srcWin=list(window))
        if geotransform is not None:
            source.SetGeoTransform(list(geotransform))
    extra = {} if output_type is None else dict(outputType=gdal.GetDataTypeByName(output_type.title()))
    gdal.Translate(path, source, format="COG", creationOptions=options, **extra)  # (closed at once)
    source = None
    size = os.path.getsize(path)
    ds = gdal.Open(path)
    band = ds.GetRasterBand(1)
    bx, by = band.GetBlockSize()
    end = 0
    for row in range(-(-ds.RasterYSize // by)):
        for col in range(-(-ds.RasterXSize // bx)):
            offset = band.GetMetadataItem(f"BLOCK_OFFSET_{col}_{row}", "TIFF")
            length = band.GetMetadataItem(f"BLOCK_SIZE_{col}_{row}", "TIFF")
            if offset and length:
                end = max(end, int(offset) + int(length))
    band = ds = None
    if end > size:
        raise RuntimeError(f"the file was cut short ({size:,} of {end:,} bytes written)")


#: below this many bytes free, a GDAL write error is taken for a full disk
FULL_DISK_BYTES = 64 * 2**20


def _gdal_reason(err: RuntimeError, path: str) -> str:
    """GDAL's error in the user's words: a full disk says so (GDAL said "TIFFAppendToStrip:Write error
    at scanline 128", a reviewer), with what the disk has left."""
    import shutil
    try:
        free = shutil.disk_usage(os.path.dirname(os.path.abspath(path)) or ".").free
    except OSError:
        return str(err)
    if free < FULL_DISK_BYTES:
        return f"No space left on device: {free / 2**20:.1f} MB free there; GDAL said: {err}"
    return str(err)


def _set_categories(band, categories) -> None:
    """The classes in the TIFF itself (no .aux.xml beside it, which GDAL keeps category names in):
    a palette, and each class's name in the band's description and metadata (``CLASS_<value>``)."""
    from osgeo import gdal
    table = gdal.ColorTable()
    for value, _name, colour in categories:
        table.SetColorEntry(int(value), tuple(int(colour[i:i + 2], 16) for i in (1, 3, 5)) + (255,))
    band.SetColorTable(table)
    band.SetColorInterpretation(gdal.GCI_PaletteIndex)
    band.SetDescription(", ".join(f"{value} {name}" for value, name, _colour in categories))
    band.SetMetadata({f"CLASS_{value}": name for value, name, _colour in categories})


def _ends(valued: np.ndarray, axis: int):
    """The rows (``axis`` 1) or columns (``axis`` 0) of ``valued`` holding a True, and the index of
    their first and last True along ``axis``."""
    lines = np.flatnonzero(valued.any(axis=axis))
    along = valued[lines] if axis == 1 else valued[:, lines]
    first = along.argmax(axis=axis)
    last = along.shape[axis] - 1 - np.flip(along, axis=axis).argmax(axis=axis)
    return lines, first, last


class BlockGeoTIFF:
    """One raster written block by block (each tile its cells), never whole in memory: a tiled,
    compressed GeoTIFF at ``work_path``, then :meth:`finish` makes the cloud-optimised GeoTIFF
    (internal tiles, DEFLATE, overviews) at the output path, atomically. Blocks never written stay
    nodata. ``write_block`` may be called from several threads."""

    def __init__(self, work_path: str, grid: GridSpec, *, crs_wkt: Optional[str] = None, nodata: float = NODATA,
                 largest_abs: float = 0.0):
        """The work raster is Float64 when heights of ``largest_abs`` (the headers' largest) need it, else Float32
        (Float64 always cost 3 times the temporary disk and half as long again to finish, for a Float32 DTM:
        an HPC reviewer); the COG is Float32 or Float64 by the largest magnitude of the values written
        (:func:`float_type_for`), as a whole run's DTM decides from its values (deciding from the headers, a
        noise point's height made a tiled DTM Float64 where the whole run's was Float32)."""
        import threading

        from osgeo import gdal
        gdal.UseExceptions()
        self.grid, self.nodata, self.work_path = grid, nodata, work_path
        self._largest = 0.0  # the largest magnitude written
        self._work_type = np.dtype(float_type_for(largest_abs))
        self._lock = threading.Lock()
        # each row's first and last cell with a value and its count of such cells (blocks never
        # overlap): the cells between a row's first and last value that have none (empty_cells)
        self._first = np.full(grid.nrows, np.iinfo(np.int64).max, dtype=np.int64)
        self._last = np.full(grid.nrows, -1, dtype=np.int64)
        self._valued = np.zeros(grid.nrows, dtype=np.int64)
        # and each column's first and last row with a value (empty_cells' second test)
        self._top = np.full(grid.ncols, np.iinfo(np.int64).max, dtype=np.int64)
        self._bottom = np.full(grid.ncols, -1, dtype=np.int64)
        try:
            self._ds = gdal.GetDriverByName("GTiff").Create(
                work_path, grid.ncols, grid.nrows, 1,
                gdal.GDT_Float64 if self._work_type == np.float64 else gdal.GDT_Float32,
                options=["COMPRESS=DEFLATE", "TILED=YES", "BIGTIFF=IF_SAFER", "SPARSE_OK=TRUE", "PREDICTOR=3"])
            self._ds.SetGeoTransform(grid.geotransform)
            self._ds.SetMetadataItem("TIFFTAG_SOFTWARE", software())
            if crs_wkt:
                self._ds.SetProjection(geotiff_crs(crs_wkt))
            self._band = self._ds.GetRasterBand(1)
            self._band.SetNoDataValue(nodata)
            self._band.SetUnitType(elevation_unit(crs_wkt))
            self._band.SetDescription(ELEVATION_BAND)
        except RuntimeError as err:
            raise OutputError(f"{work_path}: cannot create the temporary raster ({err})") from err

    def write_block(self, row0: int, col0: int, values: np.ndarray) -> None:
        """Write ``values`` (row 0 north, NaN = no data) with its north-west cell at (row0, col0)."""
        row0, col0 = int(row0), int(col0)
        valued = ~np.isnan(values)
        data = np.where(valued, values, self.nodata).astype(self._work_type)
        largest = float(np.nanmax(np.abs(values))) if valued.any() else 0.0
        with self._lock:
            self._largest = max(self._largest, largest)
            self._band.WriteArray(data, xoff=col0, yoff=row0)
            self._track(row0, col0, valued)

    def _track(self, row0: int, col0: int, valued: np.ndarray) -> None:
        """Add the cells ``valued`` (a block's, its north-west cell at ``row0``, ``col0``) to each row's first
        and last value and count of values, and each column's first and last row with one."""
        r, first, last = _ends(valued, 1)
        if r.size:
            c, top, bottom = _ends(valued, 0)
            self._first[row0 + r] = np.minimum(self._first[row0 + r], col0 + first)
            self._last[row0 + r] = np.maximum(self._last[row0 + r], col0 + last)
            self._valued[row0 + r] += valued[r].sum(axis=1)
            self._top[col0 + c] = np.minimum(self._top[col0 + c], row0 + top)
            self._bottom[col0 + c] = np.maximum(self._bottom[col0 + c], row0 + bottom)

    def _strip_rows(self, strip_rows: int, width: int) -> int:
        """At most ``strip_rows`` rows of ``width`` cells, and at most STRIP_BYTES, a strip read back."""
        return max(1, min(strip_rows, self.STRIP_BYTES // (8 * width)))

    def blank_outside(self, grid: GridSpec, strip_rows: int = 1024) -> None:
        """Set every cell of this raster outside ``grid`` (a part of it, on its lattice) to nodata, in strips
        of rows: a tiled DTM given an extent beyond its points keeps no value there, as a whole run's (the
        tiles' blocks, filled, reached to the tiles' edges)."""
        col0, row0 = self.grid.offset_of(grid)
        col1, row1 = col0 + grid.ncols, row0 + grid.nrows
        self._band.FlushCache()
        box = self._written_box()  # (beyond it nothing was written: nodata already)
        # the rows' and columns' ends of the values (empty_cells reads them) are made anew from what is left
        self._first[:], self._last[:], self._valued[:] = np.iinfo(np.int64).max, -1, 0
        self._top[:], self._bottom[:] = np.iinfo(np.int64).max, -1
        if box is None:
            return
        r0, r1, c0, c1 = box
        strip_rows = self._strip_rows(strip_rows, c1 - c0)
        for start in range(r0, r1, strip_rows):
            stop = min(start + strip_rows, r1)
            strip = self._band.ReadAsArray(c0, start, c1 - c0, stop - start)
            keep = np.zeros(strip.shape, dtype=bool)
            keep[max(row0, start) - start:max(min(row1, stop) - start, 0),
                 max(col0 - c0, 0):max(min(col1, c1) - c0, 0)] = True
            if not keep.all():
                strip[~keep] = self.nodata
                self._band.WriteArray(strip, xoff=c0, yoff=start)
            self._track(start, c0, strip != self.nodata)

    def has_values_in(self, grid: GridSpec) -> bool:
        """Whether a cell of ``grid`` (a part of this raster, on its lattice) may hold a value: a row of it
        whose first and last written values reach into its columns."""
        col0, row0 = self.grid.offset_of(grid)
        rows = slice(max(row0, 0), max(min(row0 + grid.nrows, self.grid.nrows), 0))
        return bool(np.any((self._first[rows] <= col0 + grid.ncols - 1) & (self._last[rows] >= col0)))

    def _window(self, grid: Optional[GridSpec]):
        """(xoff, yoff, xsize, ysize) of ``grid`` in this raster's cells; None for the whole raster."""
        if grid is None or grid == self.grid:
            return None
        c = self.grid.cell
        col0, row0 = self.grid.offset_of(grid)
        if abs(grid.cell - c) > 1e-9 * c or col0 < 0 or row0 < 0 or col0 + grid.ncols > self.grid.ncols \
                or row0 + grid.nrows > self.grid.nrows:
            raise ValueError(f"the grid {grid} is not a part of the raster's {self.grid}")
        return col0, row0, grid.ncols, grid.nrows

    @property
    def valued_cells(self) -> int:
        """Cells written with a value so far."""
        return int(self._valued.sum())

    #: bytes of one strip read back (its rows follow the width read)
    STRIP_BYTES = 64 << 20

    def _written_box(self, halo: int = 0):
        """(row0, row1, col0, col1), the half-open box of the rows and columns holding a written value, grown
        by ``halo`` cells and clipped to the raster; None when nothing holds one. Beyond it every cell is
        nodata: a DTM extent far wider than the survey was read back whole (an HPC reviewer: 400 M cells and
        4.8 GB for 5 M values)."""
        rows, cols = np.flatnonzero(self._last >= 0), np.flatnonzero(self._bottom >= 0)
        if rows.size == 0 or cols.size == 0:
            return None
        g = self.grid
        return (max(int(rows[0]) - halo, 0), min(int(rows[-1]) + 1 + halo, g.nrows),
                max(int(cols[0]) - halo, 0), min(int(cols[-1]) + 1 + halo, g.ncols))

    def _strips(self, strip_rows: int, halo: int = 0):
        """The part of the raster that holds values (:meth:`_written_box`, with ``halo`` cells around), read
        back at most ``strip_rows`` rows (and STRIP_BYTES) at a time with up to ``halo`` rows above and below
        each strip: (its first row, its rows, the rows read above it, its first column, the values read). The
        caller holds the lock."""
        self._band.FlushCache()
        box = self._written_box(halo)
        if box is None:
            return
        r0, r1, c0, c1 = box
        width = c1 - c0
        strip_rows = self._strip_rows(strip_rows, width)
        for row0 in range(r0, r1, strip_rows):
            n = min(strip_rows, r1 - row0)
            above, below = min(halo, row0 - r0), min(halo, r1 - row0 - n)
            yield row0, n, above, c0, self._band.ReadAsArray(c0, row0 - above, width, n + above + below)

    def isolated_pits_and_spikes(self, strip_rows: int = 1024, check=None, depth: Optional[float] = None) -> tuple:
        """(pits, spikes) of the raster written, each :func:`~groundsieve.core.grids.rasterize.isolated_pits`'
        (count, the deepest's depth, its row and column; the spikes are the pits of the negated raster),
        read back once in strips with the two rows around each. Counted on the mosaic, not tile by tile: a
        tile's own interpolation has no values beyond its buffer, so with a small buffer it missed pits near
        its edges, and with a fill it counted cells on the survey's edge a run of the whole cloud never counts
        (a code reviewer)."""
        from ..grids.rasterize import PIT_DEPTH, isolated_pits_and_spikes
        depth = PIT_DEPTH if depth is None else depth
        found = [[0, 0.0, (-1, -1)], [0, 0.0, (-1, -1)]]  # pits, spikes: count, deepest, where
        with self._lock:
            for row0, n, above, col0, values in self._strips(strip_rows, halo=2):
                values = values.astype(np.float64)
                values[values == self.nodata] = np.nan
                for kind, (count, drop, r, k) in zip(found, isolated_pits_and_spikes(
                        values, depth=depth, inner=(above, above + n, 0, values.shape[1]), check=check)):
                    kind[0] += count
                    if count and drop > kind[1]:
                        kind[1], kind[2] = drop, (row0 - above + r, col0 + k)
        return tuple((count, deepest, where[0], where[1]) for count, deepest, where in found)

    def empty_cells(self, polygon: Optional[np.ndarray] = None, margin_cells: float = 1.0,
                    strip_rows: int = 512) -> Tuple[int, int]:
        """(enclosed, inside) cells without a value, over the blocks written so far, the raster read back once.

        *Enclosed*: between cells with one both in their row and in their column. A linear TIN of one
        cloud fills its ground's convex hull, which holds the segment between any two of its cells: such a
        cell has a value in a run of the whole cloud (without a maximum distance), and stays empty in
        blocks only where a tile saw no ground across it, as in a lake wider than the buffer; a bay of the
        data open on one side is not counted (a code reviewer's coastline was).

        *Inside*: those whose centres lie inside the convex ``polygon`` ((k, 2) x, y vertices) by
        ``margin_cells`` or more, what one triangulation of the whole cloud fills when ``polygon`` is the
        convex hull of its ground (a flood modeller's river running off the survey: no cell of it had values
        on both sides in its column, and none of its 40,002 was enclosed); 0 without a polygon.

        Without a polygon the rows' spans count first, and the raster is read back only when some cells lie
        inside them, ``strip_rows`` rows at a time."""
        g = self.grid
        poly = None if polygon is None else np.asarray(polygon, dtype=np.float64)
        if poly is not None and poly.shape[0] < 3:
            poly = None
        if poly is not None:
            a, b = poly, np.roll(poly, -1, axis=0)
            slanted = a[:, 1] != b[:, 1]
            a, b = a[slanted], b[slanted]
            lo, hi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
            margin = margin_cells * g.cell
            cx = g.x0 + (np.arange(g.ncols) + 0.5) * g.cell
        enclosed = inside_count = 0
        with self._lock:
            has = self._last >= 0
            holes = bool(np.any(self._last[has] - self._first[has] + 1 - self._valued[has]))
            if not holes and poly is None:
                return 0, 0
            for row0, n, _above, col0, values in self._strips(strip_rows):
                empty = values == self.nodata
                rows = np.arange(row0, row0 + n)[:, None]
                cols = np.arange(col0, col0 + values.shape[1])
                if holes:
                    between = ((cols[None, :] >= self._first[rows]) & (cols[None, :] <= self._last[rows])
                               & (rows >= self._top[None, cols]) & (rows <= self._bottom[None, cols]))
                    enclosed += int(np.sum(empty & between))
                if poly is not None:
                    yc = g.top - (rows[:, 0] + 0.5) * g.cell
                    cross = (yc[:, None] >= lo[None, :]) & (yc[:, None] <= hi[None, :])
                    with np.errstate(invalid="ignore", divide="ignore"):
                        xs = a[None, :, 0] + (yc[:, None] - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) \
                            / (b[None, :, 1] - a[None, :, 1])
                    left = np.where(cross, xs, np.inf).min(axis=1) + margin
                    right = np.where(cross, xs, -np.inf).max(axis=1) - margin
                    inside_y = (yc >= poly[:, 1].min() + margin) & (yc <= poly[:, 1].max() - margin)
                    xs_c = cx[cols]
                    inside = inside_y[:, None] & (xs_c[None, :] >= left[:, None]) & (xs_c[None, :] <= right[:, None])
                    inside_count += int(np.sum(empty & inside))
        return enclosed, inside_count

    def close(self) -> None:
        """Close the work raster, band before dataset (left to the garbage collector, e.g. kept
        alive by a traceback, GDAL may free them in the wrong order and crash). Idempotent."""
        with self._lock:
            if self._band is not None:
                self._band.FlushCache()
            self._band = None
            self._ds = None

    def finish(self, path: str, *, atomic: bool = True, name: Optional[str] = None,
               grid: Optional[GridSpec] = None) -> None:
        """Close the work raster and write the COG to ``path`` (atomically; ``atomic=False`` when
        ``path`` is already a staged temporary: a second one inside it, ``..dtm.tif.gs<pid>-<random>.part.tif
        .gs<pid>-<random>.part.tif``, was not found by the next run's clean-up when a run was killed).
        ``grid``: only this part of the raster (cells on the same lattice, inside it)."""
        path = check_raster_path(path) if atomic else os.fspath(path)
        name = name or path
        self.close()
        try:
            with (atomic_path(path) if atomic else contextlib.nullcontext(path)) as tmp:
                window = self._window(grid)
                _cog(tmp, self.work_path, COG_OPTIONS + ["PREDICTOR=YES"], window,
                     grid.geotransform if window is not None else None, float_type_for(self._largest))
        except RuntimeError as err:
            raise OutputError(f"{name}: cannot write the DTM ({_gdal_reason(err, path)})") from err
