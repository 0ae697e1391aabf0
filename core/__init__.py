"""GroundSieve core: ground filtering of point clouds and DTMs from them, free of QGIS and Qt.

Layers, each importing only from the ones below it (tests/core/test_architecture.py checks it):

    engine/     drivers: file to file (read, select, filter, classify, write, DTM), training runs
    learn/      point features, the Random Forest, its model file and report (may use filters)
    filters/    one module per ground filter, its numba kernels beside it; no filter imports another
    raster/     GeoTIFF writing (the only place GDAL is imported)
    io/ grids/  point clouds in and out, atomic outputs | grid spec, rasterize, inpaint, morphology
    validate.py progress.py metrics.py errors.py   shared checks, progress/cancel callables,
                accuracy measures, the one exception family

``synthetic.py`` makes scenes with known truth for tests, benches and the demo (it uses io).
"""
