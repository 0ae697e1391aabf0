"""The drivers: from files to classified files and DTMs for every filter (``workflow``), point
features file to file (``features_run``), training and classification runs (``learning``).
May import everything below it in the core (filters, learn, raster, io, grids, ...)."""
