"""Raster files, the only place the core imports GDAL: GeoTIFF writing (``geotiff``), the CRS's units
(``crs``), and a DTM's vertical accuracy against surveyed checkpoints (``accuracy``, its HTML report in
``accuracy_report``). May import: errors, progress, validate, metrics, io, grids."""
