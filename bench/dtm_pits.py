"""Cost of the DTM's isolated-pit count (core/grids/rasterize.py isolated_pits): on a DTM in memory (a run
of the whole cloud) and read back from the tiled run's mosaic (core/raster/geotiff.py
BlockGeoTIFF.isolated_pits), against the time to write that mosaic's blocks and flush them (the peer).

    .venv/bin/python bench/dtm_pits.py [--cells 8000]

A generated smooth surface with 5 cm noise (no pit) of cells x cells 1 m cells, float32 as the DTMs.
"""
import argparse
import os
import tempfile
import time

from _checkout import PLUGINS  # noqa: F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core.grids.rasterize import isolated_pits  # noqa: E402
from groundsieve.core.grids.spec import GridSpec  # noqa: E402
from groundsieve.core.raster.geotiff import BlockGeoTIFF  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=8000)
    args = parser.parse_args()
    n = args.cells
    rng = np.random.default_rng(0)
    xx = np.arange(n)[None, :]
    with tempfile.TemporaryDirectory() as folder:
        writer = BlockGeoTIFF(os.path.join(folder, "work.tif"), GridSpec(0.0, float(n), 1.0, n, n))
        t0 = time.perf_counter()
        for row in range(0, n, 1000):
            yy = np.arange(row, min(row + 1000, n))[:, None]
            writer.write_block(row, 0, (np.sin(xx / 50.0) * 5 + np.cos(yy / 70.0) * 5
                                        + rng.normal(0, 0.05, (yy.size, n))).astype(np.float32))
        writer._band.FlushCache()
        written = time.perf_counter() - t0
        t0 = time.perf_counter()
        found = writer.isolated_pits()
        read_back = time.perf_counter() - t0
        t0 = time.perf_counter()
        whole = writer._band.ReadAsArray().astype(np.float64)
        read = time.perf_counter() - t0
        writer.close()
    t0 = time.perf_counter()
    in_memory = isolated_pits(whole)
    counted = time.perf_counter() - t0
    print(f"{n:,} x {n:,} cells: blocks written and flushed {written:.1f} s; pits read back from the mosaic "
          f"{read_back:.1f} s {found[:1]}; the raster read whole {read:.1f} s; pits of the DTM in memory "
          f"{counted:.2f} s {in_memory[:1]}")


if __name__ == "__main__":
    main()
