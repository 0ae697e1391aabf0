"""Cost of writing a whole run's DTM as a cloud-optimised GeoTIFF (core/raster/geotiff.py write_geotiff:
tiles, overviews, DEFLATE with the floating-point predictor, as a tiled run's mosaic) against the plain
tiled GeoTIFF it wrote before (the peer: GDAL's GTiff driver, the same compression, no overviews).

    .venv/bin/python bench/dtm_cog.py [--cells 6000] [--repeat 2]

A generated smooth surface with 1 cm noise and a nodata corner, cells x cells 1 m cells, float32.
"""
import argparse
import os
import tempfile
import time

from _checkout import PLUGINS  # noqa: F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core.grids.spec import GridSpec  # noqa: E402
from groundsieve.core.raster.geotiff import NODATA, write_geotiff  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=6000)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    from osgeo import gdal
    gdal.UseExceptions()
    n = args.cells
    grid = GridSpec.covering(np.array([0.0, n - 0.5]), np.array([0.0, n - 0.5]), 1.0, closed=True)
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:grid.nrows, 0:grid.ncols]
    values = (200 + 10 * (np.sin(xx / 50.0) + np.cos(yy / 70.0)) + rng.normal(0, 0.01, grid.shape)).astype(np.float32)
    values[: n // 10, : n // 10] = np.nan
    with tempfile.TemporaryDirectory() as folder:
        cog, plain = os.path.join(folder, "cog.tif"), os.path.join(folder, "plain.tif")
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            write_geotiff(cog, values, grid, elevation=True)
            t1 = time.perf_counter()
            ds = gdal.GetDriverByName("GTiff").Create(plain, grid.ncols, grid.nrows, 1, gdal.GDT_Float32,
                                                      options=["COMPRESS=DEFLATE", "TILED=YES", "BIGTIFF=IF_SAFER",
                                                               "PREDICTOR=3"])
            ds.SetGeoTransform(grid.geotransform)
            band = ds.GetRasterBand(1)
            band.SetNoDataValue(NODATA)
            band.WriteArray(np.where(np.isnan(values), NODATA, values).astype(np.float32))
            band = ds = None
            t2 = time.perf_counter()
            print(f"{grid.ncols} x {grid.nrows} cells: COG {t1 - t0:.2f} s ({os.path.getsize(cog) / 2**20:.0f} MB), "
                  f"plain GeoTIFF {t2 - t1:.2f} s ({os.path.getsize(plain) / 2**20:.0f} MB), "
                  f"ratio {(t1 - t0) / (t2 - t1):.2f}", flush=True)


if __name__ == "__main__":
    main()
