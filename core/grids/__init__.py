"""The shared raster machinery on arrays: the grid spec (cell edges, extent), rasterizing points
(cell minimum, mean, TIN), harmonic inpainting and disk morphology, with their numba kernels.
May import: errors, validate, progress."""
