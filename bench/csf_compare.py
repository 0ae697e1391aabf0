#!/usr/bin/env python3
"""CSF: GroundSieve's cloth simulation filter against the published ISPRS figures
(Zhang et al. 2016, Table 3) and against the authors' own library, run in the same bench.

Usage (from the repository root; the samples default to ../shared/data/isprs):

    .venv/bin/pip install -c constraints.txt cloth-simulation-filter   # the authors' library, bench only
    .venv/bin/python bench/csf_compare.py --part isprs|diagnose|timestep|scheme2016|agreement|all \
        [--data ../shared/data/isprs] [--points 5e6]

The library (PyPI ``cloth-simulation-filter``, import name ``CSF``, Apache-2.0, by the authors) is
used by this bench only, never by the plugin; without it its columns print "n/a" with this hint.
Its ``do_filtering`` is called with ``exportCloth=False``: by default it writes cloth_nodes.txt in
the working folder. Its progress lines on the C stdout are silenced.

Parts:

* ``isprs``: per sample, with the paper's per-group parameters (cloth 0.5 m, dT 0.65,
  h_cc 0.5 m; rigidness 3 without slope smoothing for 21, 31, 51, 54; rigidness 2 with it for
  11, 23, 41; rigidness 1 with it for 52): our Type I, Type II, total error, kappa and time, the
  published total, the library's total and time, our reference-compatible mode
  (``intersection_height="cell", low_outlier_m=0``) and the % of points each classifies as the
  library does.
* ``diagnose``: the library's total error under each hypothesis for its distance from the
  published figures, and ours with each of our two changes.
* ``timestep``: ours against the time step (the cloth's weight).
* ``scheme2016``: ``constraint_scheme="2016"`` (the authors' 2016 code's constraints) against the
  published Type I / II / total per sample, without the outlier step, and both schemes on the samples
  turned by 0, 90, 180, 270 degrees.
* ``agreement``: ours and the library on the same generated scene (5 million points by default,
  core.synthetic, library defaults), the % of points classified the same and the time ratio.

Findings (measured 2026-11 on the 8 samples here, 2 cores; library 1.1.7):

1. The library with the paper's parameters: mean total error 18.59 % against 4.64 % published,
   i.e. 13.95 points worse ("near 14"). Our reference-compatible mode reproduces it: 18.61 %,
   99.76-99.99 % of the points classified as the library does (the rest: the library's OpenMP
   constraint loop updates neighbours in a thread-dependent order).
2. Not the cause: **coordinate offsets** (the library works in doubles: shifted to the origin,
   identical results on every sample); **point order** (shuffled: identical results);
   **float32 coordinates** (UTM northings in float32 lose 0.5 m: totals move by -9 to +0.1 points,
   mean 16.75 %; a first run through a float32 path would have been noisier, not the 14 points);
   **parameter meaning** of rigidness (1/2/3 index the same 0.3/0.51/0.657 relaxations in the paper's
   description and the code), of the class threshold (|z - cloth| < h_cc) and of h_cp (0.3 m, fixed
   in the library).
3. The main cause, **how particles get their height** (about 11 of the 14 points). The paper gives
   each particle the height of the nearest LiDAR point in the horizontal plane (and the repository's
   early code used a kd-tree for that). The library rounds each point to one particle and fills
   every particle without a point by a scan line: the first particle with a point to the east on
   its row, else west, south, north. At ISPRS spacing (1-3.5 m) under a 0.5 m cloth, 79-96 % of the
   particles have no point, so most take the height of a point metres away, on slopes metres
   lower: the cloth is pinned below the ground (samp54: 57 % Type I; samp52: 38 % total). Same
   dynamics with nearest-point heights: mean 7.79 % (samp52 38.27 -> 5.80, samp54 26.92 -> 4.98).
4. **Low outliers** (about 1.7 points): inverted, a low outlier is a spike that pins a tent of
   cloth far below the ground. samp31 has 18 labelled ones: the library without them 13.27 ->
   1.98 %; ours with the automatic 5 m outlier step 1.96 % (13.91 without). With both changes, in
   the library's fixed sweep order: mean 6.07 %.
5. The rest (+1.42 points with the library's scheme): on every sample our Type I is higher and our
   Type II lower than published: the paper's cloth followed the terrain more closely. The time step
   only enters the gravity step, so ``--part timestep`` sweeps the weight: dT 0.70-0.74 brings 6-8
   samples within 1.5 points but dT 0.76 drops the cloth onto a roof of samp23 (14 %); that would
   be tuning on the test set. **What does reproduce the table is the constraint scheme of the
   authors' first published code** (jianboqi/CSF, folder ``CSFDLL``, read, not copied): rigidness =
   number of passes over the list of neighbour pairs, 0.3 of the difference per pair, and a pair
   moves only when its first particle (west / south) is movable, so pinned particles pull only
   their west, south-west, south and south-east neighbours. ``constraint_scheme="2016"``
   (``--part scheme2016``): all 8 samples within 1.5 points, mean 4.83 % against 4.64 % (+0.18); samp21, 31, 52, 54 within 0.12
   points and their Type I / II close to the published ones. It needs the low-outlier step too
   (without it 7.40 %: samp31 10.0 %, samp23 14.3 %), which the 2016 code did not have: the
   outliers were probably removed before the paper's runs. The asymmetry makes the result depend
   on the cloud's orientation: the samples turned by 90 / 180 / 270 degrees give 6.97 / 7.60 /
   7.32 %; the library's fixed sweep order too: 6.59 / 7.81 / 7.41 % (samp51 alone 2.2-12.6 %).
   The published table is therefore one orientation of an orientation-dependent filter.
6. **Orientation** (``--part scheme2016``, last table): the library's dependence on it comes from
   its sequential (Gauss-Seidel) sweep order. Our default ``sweep_order="rotating"`` runs the
   library's sweep on the cloth turned / mirrored by each of the 8 symmetries of the square in
   turn: 5.58 / 5.42 / 5.44 / 5.75 % at 0 / 90 / 180 / 270 degrees (fixed order 6.07 / 6.59 /
   7.81 / 7.41 %), per-sample spread four times narrower.

Targets (issue 4): with the paper's parameters and ``constraint_scheme="2016"``: 8 of 8 samples
within 1.5 points of the published total, mean +0.18 (target 0.5): met (our default: 7 of 8,
+0.94; the library's scheme in its fixed order: 4 of 8, +1.42; the library itself: 0 of 8,
+13.95). Agreement: the reference-compatible mode 99.94 % of the points on average (>= 99.76 % on
every sample); the default mode 83.5 % (a different, better, cloth at sparse density); on 5 million
generated points (10 pulses/m², denser than the cloth) 99.998 % with the fixed sweep, 99.73 % with
the default rotating one. Speed: see ``--part agreement`` (ours 1.4-2.0 times as fast as the
library, which runs on both cores).
"""
from __future__ import annotations

import argparse
import contextlib
import glob
import math
import os
import sys
import time
from pathlib import Path

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core.filters.csf import CSF  # noqa: E402
from groundsieve.core.io import read_cloud  # noqa: E402
from groundsieve.core.metrics import ground_accuracy  # noqa: E402

INSTALL_HINT = ("the authors' library is not installed; for its columns run, from the repository root: "
                ".venv/bin/pip install -c constraints.txt cloth-simulation-filter   "
                "(import name CSF; used by this bench only, never by the plugin)")

#: Zhang et al. (2016) Table 3 (see ../shared/data/isprs/PUBLISHED_RESULTS.md): Type I, Type II, total (%).
PUBLISHED = {
    "samp11": (7.23, 18.44, 12.01), "samp12": (1.15, 4.90, 2.97), "samp21": (3.89, 1.78, 3.42),
    "samp22": (1.29, 25.90, 8.94), "samp23": (3.52, 6.21, 4.79), "samp24": (1.03, 7.73, 2.87),
    "samp31": (0.96, 2.38, 1.61), "samp41": (1.48, 8.78, 5.14), "samp42": (3.28, 0.87, 1.58),
    "samp51": (2.67, 4.57, 3.08), "samp52": (1.01, 28.79, 3.93), "samp53": (3.85, 37.08, 5.20),
    "samp54": (3.79, 2.64, 3.18), "samp61": (0.87, 18.94, 1.49), "samp71": (1.61, 37.85, 5.71),
}
#: The paper's parameter groups (Table 2): rigidness and slope smoothing; GR 0.5 m, dT 0.65,
#: h_cc 0.5 m and h_cp 0.3 m for all.
GROUPS = {
    "samp21": (3, False), "samp31": (3, False), "samp42": (3, False), "samp51": (3, False), "samp54": (3, False),
    "samp11": (2, True), "samp12": (2, True), "samp22": (2, True), "samp23": (2, True), "samp24": (2, True),
    "samp41": (2, True),
    "samp52": (1, True), "samp53": (1, True), "samp61": (1, True), "samp71": (1, True),
}
RESOLUTION_M, TIME_STEP, CLASS_THRESHOLD_M = 0.5, 0.65, 0.5


# ---------------------------------------------------------------------------------------------
# The authors' library
# ---------------------------------------------------------------------------------------------

def load_library():
    try:
        import CSF as lib  # noqa: N811
    except ImportError:
        return None
    return lib


@contextlib.contextmanager
def quiet_stdout():
    """The library prints its progress on the C stdout; keep it out of the tables."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def run_library(lib, xyz, rigidness, smooth, resolution=RESOLUTION_M, time_step=TIME_STEP,
                class_threshold=CLASS_THRESHOLD_M, iterations=500):
    """Ground mask and seconds (conversion of the array included) of the library's CSF."""
    t0 = time.perf_counter()
    with quiet_stdout():
        c = lib.CSF()
        c.params.bSloopSmooth = bool(smooth)
        c.params.cloth_resolution = float(resolution)
        c.params.rigidness = int(rigidness)
        c.params.time_step = float(time_step)
        c.params.class_threshold = float(class_threshold)
        c.params.interations = int(iterations)
        c.setPointCloud(np.ascontiguousarray(xyz, dtype=np.float64))
        ground_idx, other_idx = lib.VecInt(), lib.VecInt()
        c.do_filtering(ground_idx, other_idx, False)  # False: no cloth_nodes.txt in the working folder
    seconds = time.perf_counter() - t0
    ground = np.zeros(len(xyz), dtype=bool)
    ground[np.asarray(ground_idx, dtype=np.int64)] = True
    return ground, seconds


def ours(rigidness, smooth, **kw):
    return CSF(cloth_resolution_m=RESOLUTION_M, rigidness=rigidness, time_step=TIME_STEP,
               class_threshold_m=CLASS_THRESHOLD_M, slope_smooth=smooth, **kw)


def run_ours(algorithm, xyz):
    t0 = time.perf_counter()
    res = algorithm.run(xyz)
    return res.ground, time.perf_counter() - t0, res


# ---------------------------------------------------------------------------------------------
# Samples
# ---------------------------------------------------------------------------------------------

def load_samples(folder):
    samples = {}
    for path in sorted(glob.glob(os.path.join(folder, "samp*.txt"))):
        name = Path(path).stem.split(".")[0].lower()
        if name not in GROUPS:
            continue
        cloud = read_cloud(path)
        samples[name] = (np.ascontiguousarray(cloud.xyz), cloud.reference_label == 0)
    if not samples:
        raise SystemExit(f"{folder}: no ISPRS sample samp*.txt found")
    return samples


def labelled_low_outliers(xyz, ref):
    """Object points more than 1 m below the lowest of the 8 nearest reference ground points
    (2-D). Uses the reference labels: a diagnosis only, never a filter."""
    from scipy.spatial import cKDTree
    _, idx = cKDTree(xyz[ref, :2]).query(xyz[:, :2], k=8)
    return ~ref & (xyz[:, 2] < xyz[ref, 2][idx].min(axis=1) - 1.0)


def total(ref, ground):
    return 100.0 * ground_accuracy(ref, ground).total


def fmt(v, digits=2):
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}f}"


# ---------------------------------------------------------------------------------------------
# Parts
# ---------------------------------------------------------------------------------------------

def part_isprs(samples, lib):
    print("## ISPRS samples, the paper's per-group parameters (GR 0.5 m, dT 0.65, h_cc 0.5 m)\n")
    print("ours = GroundSieve CSF with its defaults for the other knobs (nearest-point particle heights, "
          "low outliers 5 m); ours-ref = intersection_height='cell', low_outlier_m=0 (the library's way); "
          "same = % of points classified the same as the library.\n")
    print("| Sample | RI | smooth | ours Type I % | ours Type II % | ours total % | ours kappa % | ours s "
          "| published total % | ours - published | library total % | library s | ours-ref total % "
          "| same: ours % | same: ours-ref % |")
    print("|---|---:|:---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    rows = []
    for name, (xyz, ref) in samples.items():
        ri, smooth = GROUPS[name]
        g, sec, _ = run_ours(ours(ri, smooth), xyz)
        acc = ground_accuracy(ref, g)
        gr, _, _ = run_ours(ours(ri, smooth, intersection_height="cell", low_outlier_m=0.0, sweep_order="fixed",
                                     cloth_origin="cloud"), xyz)
        pub = PUBLISHED[name][2]
        row = {"type1": 100 * acc.type1, "type2": 100 * acc.type2, "total": 100 * acc.total,
               "kappa": 100 * acc.kappa, "s": sec, "pub": pub, "ref": total(ref, gr),
               "lib": math.nan, "lib_s": math.nan, "same": math.nan, "same_ref": math.nan}
        if lib is not None:
            gl, lsec = run_library(lib, xyz, ri, smooth)
            row.update(lib=total(ref, gl), lib_s=lsec, same=100 * (g == gl).mean(), same_ref=100 * (gr == gl).mean())
        rows.append(row)
        print(f"| {name} | {ri} | {'on' if smooth else 'off'} | {row['type1']:.2f} | {row['type2']:.2f} | "
              f"{row['total']:.2f} | {row['kappa']:.2f} | {sec:.2f} | {pub:.2f} | {row['total'] - pub:+.2f} | "
              f"{fmt(row['lib'])} | {fmt(row['lib_s'])} | {row['ref']:.2f} | {fmt(row['same'])} | "
              f"{fmt(row['same_ref'])} |", flush=True)
    mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}
    print(f"| **mean** | | | {mean['type1']:.2f} | {mean['type2']:.2f} | {mean['total']:.2f} | "
          f"{mean['kappa']:.2f} | {sum(r['s'] for r in rows):.2f} (sum) | {mean['pub']:.2f} | "
          f"{mean['total'] - mean['pub']:+.2f} | {fmt(mean['lib'])} | "
          f"{fmt(sum(r['lib_s'] for r in rows))} (sum) | {mean['ref']:.2f} | {fmt(mean['same'])} | "
          f"{fmt(mean['same_ref'])} |")
    within = sum(abs(r["total"] - r["pub"]) <= 1.5 for r in rows)
    print(f"\nWithin 1.5 points of the published total: {within} of {len(rows)} samples; "
          f"mean {mean['total']:.2f} % against {mean['pub']:.2f} % published.")
    if lib is None:
        print(f"\nLibrary columns skipped: {INSTALL_HINT}")
    print()


def part_diagnose(samples, lib):
    """Why the library with the paper's parameters is far from the published figures."""
    print("## Why the library is far from the published figures: each hypothesis, total error %\n")
    cols = ["library", "float32 xyz", "shifted to 0", "shuffled", "no labelled low outliers",
            "gravity dT^2", "ours-ref", "ours nearest", "ours nearest + outliers (default)",
            "empty particles %"]
    print("| Sample | " + " | ".join(cols) + " | published |")
    print("|---|" + "---:|" * (len(cols) + 1))
    table = []
    for name, (xyz, ref) in samples.items():
        ri, smooth = GROUPS[name]
        row = {}
        if lib is not None:
            row["library"] = total(ref, run_library(lib, xyz, ri, smooth)[0])
            row["float32 xyz"] = total(ref, run_library(lib, xyz.astype(np.float32).astype(np.float64), ri, smooth)[0])
            row["shifted to 0"] = total(ref, run_library(lib, xyz - xyz.min(axis=0), ri, smooth)[0])
            perm = np.random.default_rng(0).permutation(len(xyz))
            gp = np.empty(len(xyz), dtype=bool)
            gp[perm] = run_library(lib, xyz[perm], ri, smooth)[0]
            row["shuffled"] = total(ref, gp)
            low = labelled_low_outliers(xyz, ref)
            g = np.zeros(len(xyz), dtype=bool)
            g[~low] = run_library(lib, xyz[~low], ri, smooth)[0]
            row["no labelled low outliers"] = total(ref, g)
            # The library's gravity step is 0.2 dT^4; later repository sources use 0.2 dT^2. The time
            # step enters only there, so dT' = sqrt(0.65) gives the library that gravity.
            row["gravity dT^2"] = total(ref, run_library(lib, xyz, ri, smooth, time_step=math.sqrt(TIME_STEP))[0])
        else:
            for c in cols[:6]:
                row[c] = math.nan
        row["ours-ref"] = total(ref, ours(ri, smooth, intersection_height="cell", low_outlier_m=0.0,
                                          sweep_order="fixed", cloth_origin="cloud")(xyz))
        row["ours nearest"] = total(ref, ours(ri, smooth, low_outlier_m=0.0)(xyz))
        row["ours nearest + outliers (default)"] = total(ref, ours(ri, smooth)(xyz))
        row["empty particles %"] = 100.0 * empty_particle_share(xyz, RESOLUTION_M)
        table.append(row)
        print(f"| {name} | " + " | ".join(fmt(row[c]) for c in cols) + f" | {PUBLISHED[name][2]:.2f} |",
              flush=True)
    print("| **mean** | " + " | ".join(fmt(float(np.mean([r[c] for r in table]))) for c in cols) +
          f" | {np.mean([PUBLISHED[n][2] for n in samples]):.2f} |")
    if lib is None:
        print(f"\nLibrary columns skipped: {INSTALL_HINT}")
    print()


def part_timestep(samples):
    """The published figures against the cloth's weight: the time step enters only the gravity step
    (0.2 dT^4 per iteration in the library), so a sweep of dT is a sweep of the cloth's weight."""
    print("## Our CSF (defaults otherwise) against the time step, total error %\n")
    names = list(samples)
    print("| time step | gravity step (mm) | " + " | ".join(names) + " | mean | mean abs. dev. from published "
          "| samples within 1.5 |")
    print("|---:|---:|" + "---:|" * (len(names) + 3))
    pub = np.array([PUBLISHED[n][2] for n in names])
    for dt in (0.60, 0.65, 0.68, 0.70, 0.72, 0.74, 0.76, round(math.sqrt(TIME_STEP), 3)):
        row = []
        for name in names:
            xyz, ref = samples[name]
            ri, smooth = GROUPS[name]
            row.append(total(ref, CSF(cloth_resolution_m=RESOLUTION_M, rigidness=ri, time_step=dt,
                                      class_threshold_m=CLASS_THRESHOLD_M, slope_smooth=smooth)(xyz)))
        row = np.array(row)
        print(f"| {dt:.3f} | {1000 * 0.2 * dt ** 4:.1f} | " + " | ".join(f"{v:.2f}" for v in row) +
              f" | {row.mean():.2f} | {np.abs(row - pub).mean():.2f} | {int((np.abs(row - pub) <= 1.5).sum())} |",
              flush=True)
    print("| published | | " + " | ".join(f"{v:.2f}" for v in pub) + f" | {pub.mean():.2f} | | |\n")


def rotated(xyz, quarter_turns):
    """``xyz`` turned by quarter_turns x 90 degrees counter-clockwise about its centre."""
    x = xyz[:, 0] - xyz[:, 0].mean()
    y = xyz[:, 1] - xyz[:, 1].mean()
    for _ in range(quarter_turns % 4):
        x, y = -y, x
    return np.ascontiguousarray(np.column_stack([x, y, xyz[:, 2]]))


def part_scheme2016(samples):
    """The authors' 2016 constraint scheme (constraint_scheme="2016") beside the library's, with
    the paper's per-group parameters, and both on the same samples turned by 90, 180, 270 degrees."""
    names = list(samples)
    pub = np.array([PUBLISHED[n][2] for n in names])
    print("## The 2016 code's constraint scheme against the published figures\n")
    print("| Sample | 2016 Type I / II % | 2016 total % | published Type I / II % | published total % "
          "| 2016 - published | 2016 without the outlier step | library scheme, fixed sweep total % "
          "| library scheme, rotating sweep (default) total % |")
    print("|---|---|---:|---|---:|---:|---:|---:|---:|")
    rows = []
    for name in names:
        xyz, ref = samples[name]
        ri, smooth = GROUPS[name]
        acc = ground_accuracy(ref, ours(ri, smooth, constraint_scheme="2016")(xyz))
        raw = total(ref, ours(ri, smooth, constraint_scheme="2016", low_outlier_m=0.0)(xyz))
        fixed = total(ref, ours(ri, smooth, sweep_order="fixed")(xyz))
        lib_scheme = total(ref, ours(ri, smooth)(xyz))
        t1, t2, pt = PUBLISHED[name]
        rows.append((100 * acc.total, raw, fixed, lib_scheme))
        print(f"| {name} | {100 * acc.type1:.2f} / {100 * acc.type2:.2f} | {100 * acc.total:.2f} | {t1:.2f} / {t2:.2f} "
              f"| {pt:.2f} | {100 * acc.total - pt:+.2f} | {raw:.2f} | {fixed:.2f} | {lib_scheme:.2f} |", flush=True)
    m = np.array(rows).mean(axis=0)
    within = sum(abs(r[0] - p) <= 1.5 for r, p in zip(rows, pub))
    print(f"| **mean** | | {m[0]:.2f} | | {pub.mean():.2f} | {m[0] - pub.mean():+.2f} | {m[1]:.2f} | {m[2]:.2f} "
          f"| {m[3]:.2f} |\n")
    print(f"2016 scheme: {within} of {len(names)} samples within 1.5 points of the published total.\n")
    print("### The same, the samples turned about their centre: mean total error %\n")
    print("| scheme | 0° | 90° | 180° | 270° | mean of the four | mean per-sample range | widest sample range |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    variants = (("2016", {"constraint_scheme": "2016"}),
                ("library, fixed sweep (the reference's order)", {"sweep_order": "fixed"}),
                ("library, rotating sweep (default)", {}))
    for label, kw in variants:
        per_turn = []
        for turns in range(4):
            per_turn.append([total(samples[n][1], ours(*GROUPS[n], **kw)(rotated(samples[n][0], turns)))
                             for n in names])
        a = np.array(per_turn)
        spread = (a.max(axis=0) - a.min(axis=0))
        worst = int(spread.argmax())
        print(f"| {label} | " + " | ".join(f"{v:.2f}" for v in a.mean(axis=1)) +
              f" | {a.mean():.2f} | {spread.mean():.2f} | {names[worst]} {a[:, worst].min():.2f}-{a[:, worst].max():.2f} |",
              flush=True)
    print()


def empty_particle_share(xyz, res):
    """Share of the cloth's particles that no point rounds to (the library fills them by scan line)."""
    x, y = xyz[:, 0], xyz[:, 1]
    W = int(math.floor((x.max() - x.min()) / res)) + 4
    H = int(math.floor((y.max() - y.min()) / res)) + 4
    c = ((x - x.min() + 2 * res) / res + 0.5).astype(np.int64)
    r = ((y - y.min() + 2 * res) / res + 0.5).astype(np.int64)
    return 1.0 - np.unique(r * W + c).size / (W * H)


def part_agreement(lib, n_points, density):
    from groundsieve.core.synthetic import SceneSpec, make_scene
    print(f"## Agreement and speed on a generated scene, library defaults (resolution 1 m, RI 3, smoothing on)\n")
    scene = make_scene(SceneSpec.for_points(n_points, density_per_m2=density, seed=0))
    xyz = np.column_stack([scene.x, scene.y, scene.z])
    truth = scene.ground
    del scene
    CSF()(xyz[:20000])  # compile (numba caches on disk)
    print(f"{len(xyz):,} points, {density:g} pulses/m².\n")
    print("| run | seconds | points/s | error vs truth % | same as library % | library s / ours s |")
    print("|---|---:|---:|---:|---:|---:|")
    gl, lsec = (None, None)
    if lib is not None:
        gl, lsec = run_library(lib, xyz, 3, True, resolution=1.0)
        print(f"| library 1.1.7 | {lsec:.2f} | {len(xyz) / lsec:,.0f} | {100 * (gl != truth).mean():.2f} | 100 | 1 |",
              flush=True)
    for label, algorithm in (("ours (defaults)", CSF()),
                             ("ours, fixed sweep", CSF(sweep_order="fixed")),
                             ("ours-ref (cell heights, no outlier step)",
                              CSF(intersection_height="cell", low_outlier_m=0.0, sweep_order="fixed",
                                  cloth_origin="cloud"))):
        g, sec, res = run_ours(algorithm, xyz)
        same = fmt(100 * (g == gl).mean(), 3) if gl is not None else "n/a"
        ratio = fmt(lsec / sec) if lsec is not None else "n/a"
        print(f"| {label} | {sec:.2f} | {len(xyz) / sec:,.0f} | {100 * (g != truth).mean():.2f} | {same} | {ratio} |",
              flush=True)
    if lib is None:
        print(f"\nLibrary rows skipped: {INSTALL_HINT}")
    print()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data" / "isprs"),
                    help="folder of the ISPRS samp*.txt files (label 0 = ground)")
    ap.add_argument("--part", choices=["isprs", "diagnose", "timestep", "scheme2016", "agreement", "all"],
                    default="isprs")
    ap.add_argument("--points", type=float, default=5e6, help="points of the generated scene (agreement)")
    ap.add_argument("--density", type=float, default=10.0, help="pulses per m² of the generated scene")
    args = ap.parse_args(argv)
    lib = load_library()
    if lib is None:
        print(f"note: {INSTALL_HINT}\n", file=sys.stderr)
    warm = np.random.default_rng(0).uniform(0.0, 60.0, (3000, 3)) * [1.0, 1.0, 0.05]
    CSF()(warm)
    CSF(intersection_height="cell")(warm)
    if args.part in ("isprs", "diagnose", "timestep", "scheme2016", "all"):
        if not os.path.isdir(args.data):
            ap.error(f"--data {args.data}: not a folder")
        samples = load_samples(args.data)
    if args.part in ("isprs", "all"):
        part_isprs(samples, lib)
    if args.part in ("diagnose", "all"):
        part_diagnose(samples, lib)
    if args.part in ("timestep", "all"):
        part_timestep(samples)
    if args.part in ("scheme2016", "all"):
        part_scheme2016(samples)
    if args.part in ("agreement", "all"):
        part_agreement(lib, int(args.points), args.density)
    return 0


if __name__ == "__main__":
    sys.exit(main())
