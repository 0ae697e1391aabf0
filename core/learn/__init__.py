"""Learning on points: per-point features (``features``), the Random Forest and its presets
(``rf``), the model file (``model_file``) and the training report (``report``).
May import: errors, progress, validate, metrics, io, grids, raster, filters (e.g. a filter's surface
as a feature)."""
