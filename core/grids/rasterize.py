"""Points to grids: per-cell statistics and the TIN-interpolated DTM."""
from __future__ import annotations

import math
from typing import Callable, Optional

import numpy as np

from ..errors import InputError, InvalidParameterError
from ..progress import Steps, run_cancellable
from .spec import GridSpec

#: seconds per point measured on this machine (5 M point cloud, 1.2 M thinned ground points),
#: for the progress shown while a kernel runs: thinning, triangulation, rasterisation per cell
THIN_S_PER_POINT = 2e-8
SWEEP_S_PER_POINT = 6e-7
#: seconds per point and thread of the DTM in strips (triangulation, certification, rasterisation):
#: 1.35 M points in 2 threads took 2.2-3.4 s under a load of 3-4 (scripts/desktop_profile.py)
STRIP_S_PER_POINT = 2.5e-6
QHULL_S_PER_POINT = 1e-5
RASTER_S_PER_CELL = 2e-8

#: ``tin_dtm`` with threads > 1 triangulates vertical strips of the grid in parallel when at least
#: this many points are triangulated (below, one triangulation costs under a second)
STRIP_MIN_POINTS = 1_000_000
#: each strip triangulates its own columns' points and those this far beyond its edges: at least
#: STRIP_BUFFER_M metres and STRIP_BUFFER_CELLS cells (docs/BENCHMARKS.md "Fast DTM": how the strips'
#: DTM compares with one triangulation's)
STRIP_BUFFER_M = 25.0
STRIP_BUFFER_CELLS = 50
#: and at least one strip per this many points (smaller triangulations run faster per point)
STRIP_POINTS = 2_500_000
#: strips per thread asked for, all run at once: the system balances them over the cores (20 M
#: point scene, 0.5 m DTM, 2 cores: 4 strips 2 at a time 7.5-8.6 s, all 4 at once 6.8 s)
STRIPS_PER_THREAD = 2
#: a strip with cells of the hull that none of its certified triangles holds is triangulated again
#: with a buffer this many times wider (then what is still missing comes from one triangulation)
STRIP_WIDEN = 4


def _xyz(x, y, z):
    return (np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(y, dtype=np.float64),
            np.ascontiguousarray(z, dtype=np.float64))


def cell_min(x, y, z, grid: GridSpec, steps: Optional[Steps] = None) -> np.ndarray:
    """Lowest z per cell of ``grid``; NaN where a cell holds no point. With ``steps``, the kernel
    runs in a worker thread and a cancel is honoured at once (:func:`run_cancellable`)."""
    from ._kernels import _cell_min_kernel
    x, y, z = _xyz(x, y, z)
    out = np.empty(grid.shape, dtype=np.float64)
    args = (x, y, z, grid.x0, grid.top, grid.cell, grid.nrows, grid.ncols, out)
    if steps is None:
        _cell_min_kernel(*args)
    else:
        run_cancellable(_cell_min_kernel, *args, steps=steps, expected_s=THIN_S_PER_POINT * x.size)
    return out


def cell_mean(x, y, z, grid: GridSpec) -> tuple:
    """Mean z per cell (NaN where empty) and the point count per cell."""
    from ._kernels import _cell_mean_kernel
    x, y, z = _xyz(x, y, z)
    total = np.zeros(grid.shape, dtype=np.float64)
    count = np.zeros(grid.shape, dtype=np.int64)
    _cell_mean_kernel(x, y, z, grid.x0, grid.top, grid.cell, grid.nrows, grid.ncols, total, count)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return mean, count


def thin_for_grid(x, y, z, grid: GridSpec, points_per_cell: int, steps: Optional[Steps] = None):
    """Indices of at most ``points_per_cell`` points per cell of ``grid`` (a square number is
    used: 1, 4, 9, ...): each cell is split into sub-cells and the point nearest each sub-cell
    centre is kept (the lowest on a tie). The result is ordered sub-cell by sub-cell, row-major,
    which also speeds up the triangulation.

    When the sub-cells are not many more than the points, one pass of a numba kernel over a
    sub-cell array does it (:func:`_thin_sorted` otherwise, a sort: same result)."""
    from ._kernels import _compact_kernel, _thin_dense_kernel
    k = max(1, int(np.floor(np.sqrt(points_per_cell))))
    x, y, z = _xyz(x, y, z)
    nrows_sub, ncols_sub = grid.nrows * k, grid.ncols * k
    if nrows_sub * ncols_sub <= 4 * x.size + 1_000_000:
        best = np.full(nrows_sub * ncols_sub, -1, dtype=np.int64)
        sub = grid.cell / k
        if run_cancellable(_thin_dense_kernel, x, y, z, *_lattice_origin(grid, sub), sub,
                           nrows_sub, ncols_sub, best, steps=steps):
            return _compact_kernel(best)
    if steps is not None:
        steps.check()
    return _thin_sorted(x, y, z, grid, k)


def _lattice_origin(grid: GridSpec, step: float):
    """(col0, row0): ``grid``'s first column and row on the lattice of multiples of ``step`` (the
    cell or a sub-cell): a point's column is ``floor(x / step) - col0``, its row ``row0 + floor(-y / step)``."""
    return int(round(grid.x0 / step)), int(round(grid.top / step))


def _lattice_cells(grid: GridSpec, x, y):
    """(rows, columns) of the points' cells by their index on the lattice of multiples of the cell
    (as the thinning finds them: the same cell whatever grid the points are on), clipped to ``grid``."""
    col0, row0 = _lattice_origin(grid, grid.cell)
    rows = np.floor(-np.asarray(y) / grid.cell) + row0
    cols = np.floor(np.asarray(x) / grid.cell) - col0
    return (np.clip(rows, 0, grid.nrows - 1).astype(np.int64), np.clip(cols, 0, grid.ncols - 1).astype(np.int64))


def _thin_sorted(x, y, z, grid: GridSpec, k: int):
    """The sort's way to :func:`thin_for_grid`'s result (sub-cells on the lattice of multiples of
    the sub-cell, as in ``_thin_dense_kernel``; points off the grid in no sub-cell of it)."""
    sub = grid.cell / k
    col0, row0 = _lattice_origin(grid, sub)
    gx, gy = np.floor(x / sub), np.floor(-y / sub)
    col, row = gx - col0, gy + row0
    ncols = grid.ncols * k
    inside = (col >= 0) & (col < ncols) & (row >= 0) & (row < grid.nrows * k)
    key = np.where(inside, row * ncols + col, -1 - np.arange(x.size)).astype(np.int64)  # (off: a key each)
    dist = (x - (gx + 0.5) * sub) ** 2 + (-(gy + 0.5) * sub - y) ** 2
    order = np.lexsort((z, dist, key))
    first = np.ones(order.size, dtype=bool)
    first[1:] = key[order[1:]] != key[order[:-1]]
    return order[first]


def rasterize_tin(x, y, z, triangles, grid: GridSpec, out: np.ndarray, *, parallel: bool = False,
                  band_rows: int = 64, steps: Optional[Steps] = None) -> np.ndarray:
    """Write into ``out`` (of ``grid.shape``) the plane of the triangle of ``triangles`` (rows of
    point indices) holding each cell centre; cells in no triangle keep their value (a centre on
    a shared edge takes the last triangle's). ``parallel`` spreads bands of ``band_rows`` rows
    over numba's threads, with the same result as the serial kernel. Off by default: on this
    2-core machine shared with other jobs the banded kernel measured 0.78 s against 0.38 s
    serial for a 0.5 m DTM of 2.5 M points (its serial bucketing of the triangles costs more than
    the second core gives back); see docs/BENCHMARKS.md "Fast DTM"."""
    from ._kernels import _rasterize_tin_bands_kernel, _rasterize_tin_kernel
    x, y, z = _xyz(x, y, z)
    ox, oy = float(x.min()), float(y.min())  # relative coordinates for precision
    tri = np.ascontiguousarray(triangles, dtype=np.int64)
    if parallel:
        args = (_rasterize_tin_bands_kernel, x - ox, y - oy, z, tri, grid.x0 - ox, grid.top - oy, grid.cell, out,
                max(1, int(band_rows)))
    else:
        args = (_rasterize_tin_kernel, x - ox, y - oy, z, tri, grid.x0 - ox, grid.top - oy, grid.cell, out)
    if steps is None:
        args[0](*args[1:])
    else:
        run_cancellable(*args, steps=steps, expected_s=RASTER_S_PER_CELL * out.size)
    return out


def strip_cuts(cols: np.ndarray, ncols: int, strips: int) -> list:
    """Column edges of ``strips`` vertical strips holding about as many points each (``cols``: the
    points' columns); fewer strips when the points are in fewer columns."""
    counts = np.cumsum(np.bincount(cols, minlength=ncols))
    cuts = [0]
    for s in range(1, strips):
        c = int(np.searchsorted(counts, counts[-1] * s / strips, side="left")) + 1
        if cuts[-1] < c < ncols:
            cuts.append(c)
    cuts.append(ncols)
    return cuts


def convex_hull_spans(x, y, grid: GridSpec, shrink: float = 1e-7):
    """Per row of ``grid``, the x-interval (absolute) of the points' convex hull on the row's centre
    line, shrunk by ``shrink`` metres at both ends (an empty interval, lo > hi, where it misses)."""
    from ._strip_kernels import hull_candidates_kernel, hull_row_spans_kernel, monotone_hull_kernel
    x, y = np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(y, dtype=np.float64)
    cand = hull_candidates_kernel(x, y)
    cand = cand[np.lexsort((y[cand], x[cand]))]
    hull = cand[monotone_hull_kernel(x[cand], y[cand])]
    return hull_row_spans_kernel(x[hull], y[hull], grid.top - (np.arange(grid.nrows) + 0.5) * grid.cell, shrink)


def _strips_tin(xs, ys, zs, grid: GridSpec, threads: int, out: np.ndarray) -> tuple:
    """Rasterise the TIN of the points into ``out`` strip by strip, for ``threads`` cores: each
    strip of columns (:data:`STRIPS_PER_THREAD` per thread, or one per :data:`STRIP_POINTS` points if
    more) is triangulated from its points and those within the strip buffer beyond its edges, and
    gives only its own columns, and there only from triangles of the single triangulation of all
    the points: those whose circumcircle holds no point outside the strip's (certified exactly,
    :func:`._strip_kernels.certify_kernel`). A cell of the points' convex hull that no such triangle
    holds (a hole or a concavity wider than the buffer next to the strip's edge) is taken from the
    points around the strip's missing cells triangulated again, with a buffer :data:`STRIP_WIDEN`
    times wider, and what is still missing then from one triangulation of all the points. The DTM
    is therefore the single triangulation's (up to the choice between cocircular points'
    triangles). Returns the numbers of strips, of strips triangulated again, and of cells taken
    from the single triangulation."""
    from concurrent.futures import ThreadPoolExecutor

    from ._strip_kernels import bin_points_kernel, certify_kernel
    from .triangulate import delaunay
    pool_size = STRIPS_PER_THREAD * threads
    cuts = strip_cuts(grid.col_of(xs), grid.ncols, max(pool_size, int(math.ceil(xs.size / STRIP_POINTS))))
    buffer = max(STRIP_BUFFER_M, STRIP_BUFFER_CELLS * grid.cell)
    ox, oy = float(xs.min()), float(ys.min())  # the bins' origin: all relative coordinates >= 0
    size = buffer / 2.0

    def binned():
        rx, ry = xs - ox, ys - oy
        nbx, nby = int(rx.max() / size) + 1, int(ry.max() / size) + 1
        return (rx, ry) + bin_points_kernel(rx, ry, size, nbx, nby) + (nbx, nby)

    def certified(c0, c1, lo, hi, block, blo=-np.inf, bhi=np.inf):
        """Triangulate the points in [lo, hi) x [blo, bhi) and rasterise into ``block`` (columns
        c0..c1) its certified triangles."""
        inside = (xs >= lo) & (xs < hi)
        if np.isfinite(blo) or np.isfinite(bhi):
            inside &= (ys >= blo) & (ys < bhi)
        sel = np.flatnonzero(inside)
        sx, sy, sz = xs[sel], ys[sel], zs[sel]
        triangles = delaunay(sx, sy)  # the numba kernels release the GIL: the strips run at once
        if triangles.size:
            rx, ry, start, order, nbx, nby = bins.result()
            ok = certify_kernel(rx[sel], ry[sel], triangles, lo - ox, hi - ox, blo - oy, bhi - oy, grid.x0 + c0 * grid.cell - ox,
                                grid.x0 + c1 * grid.cell - ox, rx, ry, start, order, size, nbx, nby)
            rasterize_tin(sx, sy, sz, triangles[ok], GridSpec(grid.x0 + c0 * grid.cell, grid.top, grid.cell,
                                                              grid.nrows, c1 - c0), block)
        return block

    def pending(c0, c1, block):
        span_lo, span_hi = spans.result()
        centres = grid.x0 + (np.arange(c0, c1) + 0.5) * grid.cell
        inside = (centres[None, :] >= span_lo[:, None]) & (centres[None, :] <= span_hi[:, None])
        return inside & np.isnan(block)

    def one(k):
        c0, c1 = cuts[k], cuts[k + 1]
        lo, hi = grid.x0 + c0 * grid.cell, grid.x0 + c1 * grid.cell
        block = certified(c0, c1, lo - buffer, hi + buffer, np.full((grid.nrows, c1 - c0), np.nan))
        missing = pending(c0, c1, block)
        again = missing.any()
        if again:  # triangulated again around the missing cells only, with a wider buffer
            wide = STRIP_WIDEN * buffer
            rows, cols = np.flatnonzero(missing.any(axis=1)), np.flatnonzero(missing.any(axis=0))
            wider = certified(c0, c1, lo + cols[0] * grid.cell - wide, lo + (cols[-1] + 1) * grid.cell + wide,
                              np.full_like(block, np.nan), grid.top - (rows[-1] + 1) * grid.cell - wide,
                              grid.top - rows[0] * grid.cell + wide)
            block[missing] = wider[missing]
            missing &= np.isnan(wider)
        return c0, c1, block, missing, again

    left = np.zeros(grid.shape, dtype=bool)
    widened = 0
    # All at once, the system balances them; the bins and the hull are made beside the first
    # triangulations, which need them only once done.
    with ThreadPoolExecutor(max_workers=len(cuts) + 1) as pool:
        bins = pool.submit(binned)
        spans = pool.submit(convex_hull_spans, xs, ys, grid)
        for c0, c1, block, missing, again in pool.map(one, range(len(cuts) - 1)):
            out[:, c0:c1] = block
            left[:, c0:c1] = missing
            widened += again
    rest = int(left.sum())
    if rest:
        triangles = delaunay(xs, ys)
        whole = np.full(grid.shape, np.nan)
        if triangles.size:
            rasterize_tin(xs, ys, zs, triangles, grid, whole)
        out[left] = whole[left]
    return len(cuts) - 1, widened, rest


def tin_dtm(x, y, z, grid: GridSpec, *, fill_outside: bool = False, points_per_cell: int = 4,
            triangulator: str = "sweep", threads: Optional[int] = 1, steps: Optional[Steps] = None,
            log: Optional[Callable[[str], None]] = None, max_distance: float = 0.0, unit: str = "m") -> np.ndarray:
    """DTM of ``grid`` by linear interpolation on the Delaunay triangulation of the
    points (normally the ground points). Cells whose centre is outside the convex
    hull are NaN, or with ``fill_outside`` take the value of the nearest filled cell.

    Where the points are denser than the grid needs, at most ``points_per_cell`` points per
    cell are triangulated (:func:`thin_for_grid`, the points nearest the centres of 2 x 2
    sub-cells by default): the value at a cell centre then comes from points within a
    quarter cell of it, as with all points, at a fraction of the triangulation's cost (qhull
    takes about 10 µs a point). ``points_per_cell=0`` triangulates every point.
    Points with the same x, y are reduced to the lowest one before triangulating.

    ``triangulator`` is ``"sweep"`` (the numba sweep-hull Delaunay of :mod:`.triangulate`,
    several times faster) or ``"qhull"`` (scipy's). Both give the Delaunay triangulation, so
    the same surface wherever it is unique; where four or more points are cocircular (regular
    grids) a square may be split along the other diagonal.

    ``threads`` > 1 (None: numba's thread count) triangulates and rasterises vertical strips of the
    grid in that many threads when at least :data:`STRIP_MIN_POINTS` points are triangulated (sweep
    only): each strip from its own points and those within a buffer beyond its edges, keeping only
    the triangles that are the single triangulation's (their circumcircle holds no other point), the
    rest of the hull from wider strips (:func:`_strips_tin`): the same surface as one triangulation.

    ``max_distance`` > 0: a cell whose centre lies farther than that from the centre of every cell
    holding a point is left empty (NaN), after the fill if any: a data gap keeps no invented
    terrain beyond that distance from its edge.

    ``steps`` gets the progress of the thinning, the triangulation and the rasterisation, and a
    cancel is honoured within a twentieth of a second in each (:func:`..progress.run_cancellable`);
    ``log`` is told how many points are triangulated.
    """
    from scipy.ndimage import distance_transform_edt

    from .triangulate import TRIANGULATORS, delaunay
    if triangulator not in TRIANGULATORS:
        raise InvalidParameterError(f"triangulator must be one of {', '.join(TRIANGULATORS)} (got {triangulator!r})")
    x, y, z = _xyz(x, y, z)
    if x.size == 0:
        raise InputError("no ground points to make a DTM from")
    steps = steps or Steps()
    out = np.full(grid.shape, np.nan, dtype=np.float64)
    # The thinning and the cells holding a point on the grid grown by a cell: a point on a closed
    # grid's eastern or southern edge (GridSpec.covering(closed=True)) lies just outside it, as the
    # points of a tile's buffer lie outside its block (engine/tiles.py _dtm_block): the same points
    # are kept, whole or tiled.
    around = grid.padded(1)
    if points_per_cell:
        keep = thin_for_grid(x, y, z, around, points_per_cell, steps.sub(0.0, 0.1))  # also unique positions
        xs, ys, zs = x[keep], y[keep], z[keep]
    else:
        # Unique planimetric positions (lowest z first).
        order = np.lexsort((z, y, x))
        xs, ys, zs = x[order], y[order], z[order]
        keep = np.ones(xs.size, dtype=bool)
        keep[1:] = (xs[1:] != xs[:-1]) | (ys[1:] != ys[:-1])
        xs, ys, zs = xs[keep], ys[keep], zs[keep]
    steps.report(0.1)
    if log is not None:
        log(f"DTM: triangulating {xs.size:,} ground points ({x.size:,} before thinning to at most "
            f"{points_per_cell} per cell), {grid.ncols:,} x {grid.nrows:,} cells of {grid.cell:g} {unit} ..."
            if points_per_cell else f"DTM: triangulating {xs.size:,} ground points, {grid.ncols:,} x "
            f"{grid.nrows:,} cells of {grid.cell:g} {unit} ...")
    rate = SWEEP_S_PER_POINT if triangulator == "sweep" else QHULL_S_PER_POINT
    if threads is None:
        import numba
        threads = numba.get_num_threads()
    if threads > 1 and triangulator == "sweep" and xs.size >= STRIP_MIN_POINTS:
        strips, again, rest = run_cancellable(lambda: _strips_tin(xs, ys, zs, grid, threads, out),
                                              steps=steps.sub(0.1, 0.95),
                                              expected_s=(STRIP_S_PER_POINT * xs.size
                                                          + RASTER_S_PER_CELL * out.size) / threads)
        if log is not None:
            log(f"DTM: {strips} strips triangulated in {threads} threads"
                + (f", {again} again with a wider buffer (holes or concave borders wider than the buffer)"
                   if again else "")
                + (f", {rest:,} cells from one triangulation of all points" if rest else "") + ".")
    else:
        triangles = run_cancellable(lambda: delaunay(xs, ys, method=triangulator), steps=steps.sub(0.1, 0.75),
                                    expected_s=rate * xs.size)  # (0, 3) when collinear
        if triangles.size:
            rasterize_tin(xs, ys, zs, triangles, grid, out, steps=steps.sub(0.75, 0.95))
        else:
            # Fewer than three distinct positions, or all on a line: the cells holding them.
            out[grid.row_of(ys), grid.col_of(xs)] = zs
    if fill_outside:
        missing = np.isnan(out)
        if missing.all():
            out[grid.row_of(ys), grid.col_of(xs)] = zs
            missing = np.isnan(out)
        if missing.any():
            steps.check()
            idx = distance_transform_edt(missing, return_distances=False, return_indices=True)
            out = out[tuple(idx)]
    if max_distance > 0:
        steps.check()
        empty = np.ones(around.shape, dtype=bool)
        empty[_lattice_cells(around, xs, ys)] = False
        far = distance_transform_edt(empty, sampling=grid.cell)[1:-1, 1:-1] > max_distance
        out[far] = np.nan
    steps.report(1.0)
    return out


#: How far below every other cell of its 5 x 5 window a DTM cell must lie to be an isolated pit (CRS unit).
PIT_DEPTH = 0.5


def isolated_pits_and_spikes(values: np.ndarray, depth: float = PIT_DEPTH, inner: Optional[tuple] = None,
                             check: Optional[Callable[[], None]] = None) -> tuple:
    """(pits, spikes) of a DTM, each :func:`isolated_pits`' (count, deepest, row, column): the spikes are the
    pits of the negated DTM (a surveyor's class 2 held points 20 m up, not a word). ``values`` is negated in
    place for them and put back (no copy of the grid)."""
    pits = isolated_pits(values, depth=depth, inner=inner, check=check)
    np.negative(values, out=values)
    try:
        spikes = isolated_pits(values, depth=depth, inner=inner, check=check)
    finally:
        np.negative(values, out=values)
    return pits, spikes


def isolated_pits(values: np.ndarray, depth: float = PIT_DEPTH, inner: Optional[tuple] = None,
                  strip_rows: int = 1024, check: Optional[Callable[[], None]] = None,
                  batch: int = 200_000) -> tuple:
    """The cells of a DTM (NaN = no value) lying more than ``depth`` below every other cell of the 5 x 5
    window around them, all of which have a value: (count, the deepest's depth, its row, its column), or
    (0, 0.0, -1, -1). A low point made ground (a multipath or noise echo) is one, a 1-2 m pit in a
    hillshade; a ditch or a valley is not, at any angle to the grid: a ditch one cell wide crossing the
    grid at a steep angle has all 8 nearest cells on its banks (a code reviewer found 7 such "pits" per
    100 m), but cells of it two cells away. ``inner``: (row0, row1, col0, col1), the cells to count (their
    window may reach outside: a strip read with two rows above and below); the outer two rows and
    columns of ``values`` are never counted. Cells lower than their 4 nearest by ``depth`` are found in
    row strips of ``strip_rows`` (few are), then tested against their whole window ``batch`` at a time
    (a rough DTM has many); ``check`` (e.g. a run's cancel check) is called between strips."""
    nrows, ncols = values.shape
    r0, r1, c0, c1 = inner if inner is not None else (0, nrows, 0, ncols)
    r0, c0, r1, c1 = max(r0, 2), max(c0, 2), min(r1, nrows - 2), min(c1, ncols - 2)
    if r1 <= r0 or c1 <= c0:
        return 0, 0.0, -1, -1
    window = [(dr, dc) for dr in range(-2, 3) for dc in range(-2, 3) if dr or dc]
    dr, dc = (np.array(v, dtype=np.intp) for v in zip(*window))
    count, deepest, where = 0, 0.0, (-1, -1)
    for top in range(r0, r1, strip_rows):
        if check is not None:
            check()
        bottom = min(top + strip_rows, r1)
        centre = values[top:bottom, c0:c1]
        nearest = np.minimum(np.minimum(values[top - 1:bottom - 1, c0:c1], values[top + 1:bottom + 1, c0:c1]),
                             np.minimum(values[top:bottom, c0 - 1:c1 - 1], values[top:bottom, c0 + 1:c1 + 1]))
        rows, cols = np.nonzero(nearest - centre > depth)  # (NaN anywhere: no candidate)
        for start in range(0, rows.size, batch):
            r, k = rows[start:start + batch] + top, cols[start:start + batch] + c0
            around = values[r[:, None] + dr, k[:, None] + dc]
            drop = np.where(np.isnan(around), -np.inf, around).min(axis=1) - values[r, k]
            pits = drop > depth
            if pits.any():
                count += int(pits.sum())
                j = int(np.argmax(np.where(pits, drop, -np.inf)))
                if drop[j] > deepest:
                    deepest, where = float(drop[j]), (int(r[j]), int(k[j]))
    return count, deepest, where[0], where[1]
