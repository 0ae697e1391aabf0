"""GeoTIFF writing: the one module of the core that uses GDAL."""
from __future__ import annotations

import contextlib
import os
from typing import Optional

import numpy as np

from ..errors import OutputError
from ..grids.spec import GridSpec
from ..io import atomic_path

NODATA = -9999.0
RASTER_EXTENSIONS = (".tif", ".tiff")


def check_raster_path(path: str, *, inputs=()) -> str:
    from ..io import check_output_path
    return check_output_path(path, inputs=inputs, extensions=RASTER_EXTENSIONS, what="raster output")


def write_geotiff(path: str, values: np.ndarray, grid: GridSpec, *, crs_wkt: Optional[str] = None,
                  nodata: float = NODATA, dtype: str = "float32", atomic: bool = True) -> None:
    """Write ``values`` (row 0 = north, NaN = no data) as a single-band GeoTIFF, atomically unless
    the caller already writes to a temporary path of its own (``atomic=False``)."""
    from osgeo import gdal
    gdal.UseExceptions()
    path = check_raster_path(path)
    if values.shape != grid.shape:
        raise OutputError(f"{path}: raster of shape {values.shape} does not match its grid {grid.shape}")
    gdal_type = {"float32": gdal.GDT_Float32, "float64": gdal.GDT_Float64,
                 "uint8": gdal.GDT_Byte, "int16": gdal.GDT_Int16}[dtype]
    data = np.where(np.isnan(values), nodata, values).astype(dtype) if values.dtype.kind == "f" else values.astype(dtype)
    try:
        with (atomic_path(path) if atomic else contextlib.nullcontext(path)) as tmp:
            driver = gdal.GetDriverByName("GTiff")
            ds = driver.Create(tmp, grid.ncols, grid.nrows, 1, gdal_type,
                               options=["COMPRESS=DEFLATE", "TILED=YES", "BIGTIFF=IF_SAFER"])
            ds.SetGeoTransform(grid.geotransform)
            if crs_wkt:
                ds.SetProjection(crs_wkt)
            band = ds.GetRasterBand(1)
            band.SetNoDataValue(nodata)
            band.WriteArray(data)
            band.FlushCache()
            ds = None  # closes and flushes the file
    except RuntimeError as err:
        raise OutputError(f"{path}: cannot write the GeoTIFF ({err})") from err
    if not os.path.exists(path):
        raise OutputError(f"{path}: the GeoTIFF was not written")
