"""GroundSieve core: ground filtering of point clouds, free of QGIS and Qt.

Modules: ``io`` (LAS/LAZ/ISPRS text), ``smrf`` (the SMRF filter), ``workflow``
(file-to-file driver shared by the filters), ``rasterize``/``raster``/``grid``
(DTM and GeoTIFF), ``metrics`` (ISPRS errors, kappa, ...), ``synthetic`` (generated
scenes with known truth).
"""
