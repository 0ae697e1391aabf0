"""Speed and accuracy of the TIN DTM (core.grids.rasterize.tin_dtm) with the numba sweep-hull
triangulation against scipy's qhull, on the truth ground points of generated scenes.

    .venv/bin/python bench/dtm_speed.py [--millions 2 5 20] [--cells 0.5 1] [--ppc 4]
    .venv/bin/python bench/dtm_speed.py --millions 20 --methods sweep strips [--threads 2] [--hole 100]

Per scene size (all points, before keeping the ground) and cell size, in one process: the time
of thinning (thin_for_grid), of the triangulation by each method, and of rasterizing each
triangulation; the sweep / qhull ratio of the triangulation and of the whole DTM; the max and
mean absolute difference of the two rasters; and the error of each against the scene's true
terrain at the cell centres (RMSE, and the 99th percentile of |error|) over the cells inside
the ground hull. The numba kernels are compiled on a small cloud first.

``strips`` is tin_dtm's parallel path (``threads`` > 1): vertical strips of the grid triangulated and
rasterised in threads, each with a buffer (its time is in the triangulate column, rasterising
included). Against ``sweep`` (one triangulation) the notes give the cells that differ by more than
1e-9 m and how far the farthest of them lies from the ground hull's border (NaN cells or grid edge).
``--hole D`` removes the ground points within a disc of D metres across centred on the ground's median
x and y (with an even number of strips, their middle cut): a lake wider than the strips' buffer, so
that strips are triangulated again (tin_dtm's log says how many).
"""
import argparse
import time

import numpy as np

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)


def run(millions, cells, ppc, seed, methods, threads, hole=0.0):
    from scipy.ndimage import distance_transform_edt

    from groundsieve.core.grids.rasterize import _strips_tin, rasterize_tin, thin_for_grid, tin_dtm
    from groundsieve.core.grids.spec import GridSpec
    from groundsieve.core.grids.triangulate import delaunay
    from groundsieve.core.synthetic import SceneSpec, make_scene

    warm = make_scene(SceneSpec.for_points(20_000, seed=1))
    g = warm.ground
    wgrid = GridSpec.covering(warm.x, warm.y, 1.0)
    tin_dtm(warm.x[g], warm.y[g], warm.z[g], wgrid)  # and the strips' kernels (bins, hull, certification):
    _strips_tin(warm.x[g], warm.y[g], warm.z[g], wgrid, threads, np.full(wgrid.shape, np.nan))

    print("| points | ground | cell | thinned | thin s | method | triangulate s | rasterize s | DTM s "
          "| RMSE vs truth m | p99 m |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    notes = []
    for m in millions:
        t0 = time.perf_counter()
        scene = make_scene(SceneSpec.for_points(m * 1e6, seed=seed))
        t_gen = time.perf_counter() - t0
        g = scene.ground
        x, y, z = scene.x[g], scene.y[g], scene.z[g]
        if hole:
            cx, cy = np.median(x), np.median(y)
            dry = (x - cx) ** 2 + (y - cy) ** 2 > (hole / 2) ** 2
            x, y, z = x[dry], y[dry], z[dry]
        n_all = len(scene)
        terrain = scene.terrain
        del scene
        for cell in cells:
            grid = GridSpec.covering(x, y, cell)
            t0 = time.perf_counter()
            keep = thin_for_grid(x, y, z, grid, ppc) if ppc else np.arange(x.size)
            t_thin = time.perf_counter() - t0
            xs, ys, zs = x[keep], y[keep], z[keep]
            cx, cy = grid.centers()
            CX, CY = np.meshgrid(cx, cy)
            truth = terrain(CX, CY)
            del CX, CY
            rasters, totals = {}, {}
            for method in methods:
                out = np.full(grid.shape, np.nan)
                if method == "strips":
                    t0 = time.perf_counter()
                    counts = _strips_tin(xs, ys, zs, grid, threads, out)
                    notes.append(f"{n_all / 1e6:.1f} M, {cell:g} m: strips, strips triangulated again, cells from "
                                 f"one triangulation: {counts}")
                    t_tri, t_ras = time.perf_counter() - t0, 0.0
                else:
                    t0 = time.perf_counter()
                    tri = delaunay(xs, ys, method=method)
                    t_tri = time.perf_counter() - t0
                    t0 = time.perf_counter()
                    rasterize_tin(xs, ys, zs, tri, grid, out)
                    t_ras = time.perf_counter() - t0
                    del tri
                err = (out - truth)[np.isfinite(out)]
                totals[method] = (t_thin + t_tri + t_ras, t_tri)
                rasters[method] = out
                print(f"| {n_all / 1e6:.1f} M | {x.size / 1e6:.1f} M | {cell:g} m | {xs.size / 1e6:.2f} M "
                      f"| {t_thin:.2f} | {method} | {t_tri:.2f} | {t_ras:.2f} | {t_thin + t_tri + t_ras:.2f} "
                      f"| {np.sqrt(np.mean(err ** 2)):.4f} | {np.percentile(np.abs(err), 99):.3f} |", flush=True)
            if len(methods) == 2:
                a, b = rasters[methods[0]], rasters[methods[1]]
                both = np.isfinite(a) & np.isfinite(b)
                d = np.abs(a - b)[both]
                differ = both & (np.abs(a - b) > 1e-9)
                inside = distance_transform_edt(np.pad(np.isfinite(a), 1))[1:-1, 1:-1] * cell
                far = f"{inside[differ].max():.1f} m" if differ.any() else "-"
                notes.append(f"{n_all / 1e6:.1f} M, {cell:g} m: cells differing by > 1e-9 m: {int(differ.sum())} "
                             f"of {int(both.sum())}, the farthest {far} from the hull's border")
                notes.append(f"{n_all / 1e6:.1f} M, {cell:g} m: triangulation {methods[0]}/{methods[1]} = "
                             f"{totals[methods[0]][1] / totals[methods[1]][1]:.3f}, whole DTM "
                             f"{totals[methods[0]][0] / totals[methods[1]][0]:.3f}; raster difference max "
                             f"{d.max():.2e} m, mean {d.mean():.2e} m; NaN cells differ: "
                             f"{int((np.isfinite(a) != np.isfinite(b)).sum())}; scene generated in {t_gen:.1f} s")
            del rasters
    print()
    for line in notes:
        print("-", line)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--millions", type=float, nargs="+", default=[2, 5, 20])
    ap.add_argument("--cells", type=float, nargs="+", default=[0.5, 1.0])
    ap.add_argument("--ppc", type=int, default=4, help="points_per_cell of the thinning (0 = all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--methods", nargs="+", default=["sweep", "qhull"], help="sweep, qhull, strips")
    ap.add_argument("--threads", type=int, default=2, help="threads of the strips method")
    ap.add_argument("--hole", type=float, default=0.0, help="metres across a ground hole on a strip cut (0: none)")
    args = ap.parse_args()
    run(args.millions, args.cells, args.ppc, args.seed, args.methods, args.threads, args.hole)


if __name__ == "__main__":
    main()
