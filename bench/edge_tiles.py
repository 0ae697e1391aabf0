"""A delivery of files on multiples of the tile size whose last files hold the points on the survey's far
edges: how many tiles a tiled run makes and what they cost.

    .venv/bin/python bench/edge_tiles.py [--files 3] [--side 100] [--density 20] [--strip 0.5]

A generated scene of ``--files`` x ``--files`` squares of ``--side`` m at ``--density`` points/m² is cut into
as many LAZ files; the points within ``--strip`` m of the east and north edges are moved onto them (a
vendor's closed tiles). SMRF then runs on the folder in tiles of ``--side`` m (1 worker), in a fresh
process. Said: the tiles binned, the tile phase's seconds (the engine's "Filtered N tile(s) in X s") and the
points the tiles filtered with their buffers (the sum of the tile lines' counts).
"""
import argparse
import os
import re
import tempfile

from _checkout import REPO  # noqa: F401,E402 (puts this checkout's groundsieve on sys.path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--files", type=int, default=3)
    parser.add_argument("--side", type=float, default=100.0)
    parser.add_argument("--density", type=float, default=20.0)
    parser.add_argument("--strip", type=float, default=0.5)
    args = parser.parse_args()
    import laspy
    import numpy as np
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.io import new_las, write_las
    from groundsieve.core.synthetic import SceneSpec, make_scene
    n, side = args.files, args.side
    scene = make_scene(SceneSpec(size_m=n * side, density_per_m2=args.density, seed=2))
    x, y = scene.x - scene.x.min(), scene.y - scene.y.min()
    x, y = x * (n * side / x.max()), y * (n * side / y.max())
    x[x > n * side - args.strip], y[y > n * side - args.strip] = n * side, n * side
    x, y = np.round(x + 500_000.0, 2), np.round(y + 5_400_000.0, 2)
    las = new_las(x, y, scene.z, classification=scene.classification, return_number=scene.return_number,
                  number_of_returns=scene.number_of_returns)
    work = tempfile.mkdtemp(prefix="edge_tiles_")
    folder = os.path.join(work, "files")
    os.makedirs(folder)
    fx = np.minimum(np.floor((x - 500_000.0) / side), n - 1)
    fy = np.minimum(np.floor((y - 5_400_000.0) / side), n - 1)
    for i in range(n):
        for j in range(n):
            part = laspy.LasData(las.header)
            part.points = las.points[(fx == i) & (fy == j)]
            write_las(part, os.path.join(folder, f"f{i}_{j}.laz"))
    on_edge = int(np.sum((x == 500_000.0 + n * side) | (y == 5_400_000.0 + n * side)))
    lines = []
    run_ground_filter(folder, os.path.join(work, "out.vpc"), SMRF(),
                      options=FilterOptions(tiling=TileOptions(tile_size_m=side, workers=1)), log=lines.append)
    tiles = next(line for line in lines if line.startswith("Binned into"))
    seconds = next(line for line in lines if line.startswith("Filtered"))
    filtered = sum(int(m.group(1).replace(",", "")) + int(m.group(2).replace(",", ""))
                   for m in (re.search(r": ([\d,]+) points \(\+([\d,]+) buffer\)", line) for line in lines) if m)
    print(f"{len(x):,} points in {n * n} files of {side:g} m, {on_edge:,} on the far edges")
    print(tiles)
    print(seconds)
    print(f"points filtered by the tiles with their buffers: {filtered:,} ({filtered / len(x):.2f} x the survey)")


if __name__ == "__main__":
    main()
