"""Raster files: GeoTIFF writing (``geotiff``), the only place the core imports GDAL.
May import: errors, io, grids."""
