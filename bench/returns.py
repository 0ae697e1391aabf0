#!/usr/bin/env python3
"""The echo grid filter against SMRF on real multi-return data (issue 3).

Usage (from the repository root):

    .venv/bin/python bench/returns.py [--data ../shared/data] [--sets isprs lidr bcts autzen]
        [--isprs-returns file|echoes|both] [--repeat 5] [--csv OUT.csv]

For every data set, three filters run in the same process on the same arrays: ``echogrid``
(matrone2024 Method 2 as published: 5 m kernels, dz 2 m, kernels of first returns only taken as
ground), ``echogrid-evidence`` (the same grid using the echoes as evidence, see
core/filters/echogrid.py) and ``smrf`` (defaults). The table gives Type I, Type II, total error and
Cohen's kappa (ISPRS definitions, in %), the filter time and the time relative to SMRF.

Timing: each filter is called once untimed on the data set's arrays (numba compilation and
first-touch costs), then ``--repeat`` rounds call the three filters in turn; the best time of
each is reported. Only the filter call is timed: no file reading, no array building, no
scoring. The machine is shared and noisy: compare the ratios within one run.

Data sets (paths relative to ``--data``; see its SOURCES.md):

1. **ISPRS reference samples on the raw sites** (``isprs/samp*.txt`` + ``isprs_sites/*.laz``).
   The reference samples are ``x y z label`` text without echoes; the raw sites hold every pulse
   twice (first pulse, then last pulse, record i and i + N/2 the same pulse) and no labels. Each
   reference point is joined to its last-pulse record on x, y, z rounded to 0.01 m; reference
   points without a match are left out and counted. samp11 (and samp12) come from CSite1, which
   is not in the data: skipped.

   What the filters see, and why: all site records of *both* pulses whose x, y fall in the
   sample's bounding box, with the site's outliers (none removed: the ISPRS test left them in
   on purpose and SMRF has to live with them too). Feeding only the reference points would hide
   the first pulses, which are the whole point of an echo filter; feeding the whole site would
   score nothing more and only time a larger cloud. Only the joined reference points (their
   last-pulse records) are scored, against the reference labels (0 = ground), so every filter is
   scored on exactly the points and labels of the ISPRS reference. Points in the box that are not
   in the reference (first pulses, and any last pulse the reference left out) shape the filters'
   surfaces but are not scored.

   Return numbers: ``--isprs-returns file`` gives the filters the file's fields as they are: the
   first pulse is return 1 of 2 and the last pulse return 2 of 2 for *every* pulse, also where
   both pulses hit the same surface (on the four sites 80-88 % of pulses have first and last
   within 0.2 m, and only 28-49 pairs per site are 0.3 to 3 m apart: the sensor's pulse
   separation). Under that encoding a kernel is
   almost never "first returns only" (every kernel holds last pulses, return 2; only at the
   box's edge can a first pulse fall in a kernel without its last pulse), so the faithful echo
   grid is in effect its height test alone and the evidence mode never bypasses.
   ``--isprs-returns echoes`` encodes the same pulses as a modern LAS file would: a pulse whose
   first and last pulse lie within ``SINGLE_ECHO_M`` (1 m) of each other is one echo (its
   last-pulse record, return 1 of 1; the first-pulse duplicate is dropped), any other pulse two
   echoes (1 of 2 and 2 of 2). The scored records are the same under both encodings.
   ``both`` (the default) runs the two.

2. **Producer-labelled ALS** (``lidR/Topography.laz``, ``lidR/Megaplot.laz``,
   ``lidR/MixedConifer.laz``, ``lasR_bcts/bcts_1.laz``, ``lasR_bcts/bcts_2.laz``,
   ``laspy/autzen_trim.laz``): the filters see every point except noise (classes 7, 18), as the
   plugin's driver does by default; water (class 9) stays in the input, as the filter cannot know
   it is water. Scored: every point but noise and water, class 2 = ground. The labels are the
   data producers', not a manual reference. MixedConifer holds first returns only (every return
   number is 1): the published rule then takes every kernel as ground. As a check of the labels
   the notes give, per file, the share of points *not* labelled ground that lie within 0.3 m
   (vertically) of the labelled ground around them (median z of the 8 nearest class-2 points):
   a large share means the producer left ground-level points unclassified (autzen_trim: about
   two thirds), and Type II there measures the labels more than the filters. Megaplot and
   MixedConifer are height-normalised (ground at z = 0): flat terrain by construction.

   Units: the filters' lengths are in the unit of the cloud's CRS. autzen_trim's CRS is in
   international feet (and its z too: there is no vertical CRS and the heights are in feet), so
   every length parameter (``*_m``, and SMRF's elevation scalar) is converted explicitly from
   its metre value: kernel 5 m = 16.40 ft, dz 2 m = 6.56 ft, the evidence neighbourhood 20 m,
   SMRF's cell 1 m, window 18 m, threshold 0.5 m and elevation scalar 1.25 m per unit slope
   likewise; slopes are ratios and stay. A parameter the bench cannot classify as a length or a
   ratio stops it. A note lists the converted values.
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple

from _checkout import REPO  # noqa: E402,F401 (puts this checkout's groundsieve on sys.path)

import numpy as np  # noqa: E402

from groundsieve.core.io import CLASS_GROUND, NOISE_CLASSES, read_cloud  # noqa: E402
from groundsieve.core.metrics import GroundAccuracy, ground_accuracy  # noqa: E402

from filters import make_filter  # noqa: E402

FILTER_NAMES = ("echogrid", "echogrid-evidence", "smrf")
REFERENCE_FILTER = "smrf"
CLASS_WATER = 9
SINGLE_ECHO_M = 1.0          #: first and last pulse closer than this: one echo (see the docstring)
JOIN_DECIMALS = 2            #: the reference join rounds x, y, z to 0.01 m
FOOT_M = 0.3048              #: the international foot

#: How each numeric filter parameter scales with the CRS unit. Lengths (in the CRS's unit, named
#: ``*_m``) are converted; SMRF's elevation scalar multiplies a slope (rise/run) to give a height,
#: so it is a length too. Ratios stay. A numeric parameter in neither list stops the bench rather
#: than be converted wrongly.
EXTRA_LENGTHS = ("elevation_scalar",)
RATIOS = ("slope", "low_outlier_slope")

#: ISPRS reference sample -> raw site file (Sithole & Vosselman 2003).
SAMPLE_SITES = {
    "samp11": "CSite1", "samp12": "CSite1",
    "samp21": "CSite2", "samp22": "CSite2", "samp23": "CSite2", "samp24": "CSite2",
    "samp31": "CSite3",
    "samp41": "CSite4", "samp42": "CSite4",
    "samp51": "FSite5", "samp52": "FSite5", "samp53": "FSite5", "samp54": "FSite5",
    "samp61": "FSite6",
    "samp71": "FSite7",
}

#: Producer-labelled files: set name -> (path under --data, note).
PRODUCER_SETS = {
    "topography": ("lidR/Topography.laz", "hilly, lakes"),
    "megaplot": ("lidR/Megaplot.laz", "forest"),
    "mixedconifer": ("lidR/MixedConifer.laz", "conifer forest, FIRST RETURNS ONLY"),
    "bcts_1": ("lasR_bcts/bcts_1.laz", "dense forest"),
    "bcts_2": ("lasR_bcts/bcts_2.laz", "dense forest"),
    "autzen": ("laspy/autzen_trim.laz", "suburban, feet"),
}
GROUPS = {
    "isprs": (),  # every isprs/samp*.txt under --data (filled in by expand_sets)
    "lidr": ("topography", "megaplot", "mixedconifer"),
    "bcts": ("bcts_1", "bcts_2"),
    "laspy": ("autzen",),
}
GROUPS["all"] = ("isprs",) + sum(GROUPS.values(), ())


# ---------------------------------------------------------------------------------------------
# Data sets
# ---------------------------------------------------------------------------------------------

@dataclass
class DataSet:
    name: str
    xyz: np.ndarray                 #: (n, 3) float64, what the filters see
    return_number: np.ndarray       #: uint8 (n,)
    number_of_returns: np.ndarray   #: uint8 (n,)
    scored: np.ndarray              #: int index into xyz of each scored point (may repeat)
    reference_ground: np.ndarray    #: bool, one per scored point
    metres_per_unit: float = 1.0
    group: str = ""
    note: str = ""
    intensity: Optional[np.ndarray] = None  #: per input point, where the file has it

    @property
    def fields(self) -> Dict[str, np.ndarray]:
        return {"return_number": self.return_number, "number_of_returns": self.number_of_returns}


@dataclass
class JoinStats:
    sample: str
    site: str
    reference: int = 0
    joined: int = 0
    unmatched: int = 0
    ambiguous: int = 0                  #: reference points whose key has more than one last-pulse record
    shared: int = 0                     #: reference points sharing a record with another one
    last_in_box: int = 0                #: last-pulse records in the sample's box
    last_in_box_not_reference: int = 0
    input_file: int = 0                 #: records given to the filters, file encoding
    input_echoes: int = 0               #: records given to the filters, echo encoding
    below_reference: int = 0            #: input records below the lowest reference point
    above_reference: int = 0            #: input records above the highest reference point
    single_echo_share: float = 0.0      #: pulses in the box whose first and last pulse agree


def _keys(x, y, z) -> np.ndarray:
    scale = 10.0 ** JOIN_DECIMALS
    return np.rint(np.column_stack([x, y, z]) * scale).astype(np.int64)


def _occurrence(ids: np.ndarray) -> np.ndarray:
    """For each element, how many equal ids come before it (0 for the first of each id)."""
    order = np.argsort(ids, kind="stable")
    sorted_ids = ids[order]
    starts = np.flatnonzero(np.r_[True, sorted_ids[1:] != sorted_ids[:-1]])
    run_start = np.repeat(starts, np.diff(np.r_[starts, ids.size]))
    rank = np.empty(ids.size, dtype=np.int64)
    rank[order] = np.arange(ids.size) - run_start
    return rank


def _site_layout(site) -> int:
    """Half the record count, after checking the layout SOURCES.md describes."""
    n = len(site)
    half = n // 2
    rn, nr = site.return_number, site.number_of_returns
    if n % 2 or not ((rn[:half] == 1).all() and (rn[half:] == 2).all() and (nr == 2).all()):
        raise SystemExit(f"{site.path}: not the expected layout (first pulses 1 of 2, then last pulses 2 of 2)")
    return half


class SiteCache:
    def __init__(self):
        self._sites = {}

    def get(self, path: str):
        if path not in self._sites:
            site = read_cloud(path)
            half = _site_layout(site)
            d = np.sqrt((site.x[:half] - site.x[half:]) ** 2 + (site.y[:half] - site.y[half:]) ** 2
                        + (site.z[:half] - site.z[half:]) ** 2)
            self._sites[path] = (site, half, d < SINGLE_ECHO_M)
        return self._sites[path]


def load_isprs(name: str, data: str, encodings: Tuple[str, ...], sites: SiteCache,
               log: Callable[[str], None]) -> Tuple[List[DataSet], Optional[JoinStats]]:
    ref_path = os.path.join(data, "isprs", f"{name}.txt")
    site_name = SAMPLE_SITES.get(name)
    if not os.path.isfile(ref_path):
        log(f"{name}: {ref_path} is missing; skipped")
        return [], None
    site_path = os.path.join(data, "isprs_sites", f"{site_name}_orig-utm.laz")
    if not os.path.isfile(site_path):
        log(f"{name}: its raw site {site_name} is not in {os.path.dirname(site_path)}; skipped")
        return [], None
    ref = read_cloud(ref_path)
    site, half, single = sites.get(site_path)
    stats = JoinStats(name, site_name, reference=len(ref))

    # The box and the records in it.
    x0, x1, y0, y1 = ref.x.min(), ref.x.max(), ref.y.min(), ref.y.max()
    in_box = (site.x >= x0) & (site.x <= x1) & (site.y >= y0) & (site.y <= y1)
    box = np.flatnonzero(in_box)
    last_box = box[box >= half]
    stats.last_in_box = int(last_box.size)

    # Join the reference points to last-pulse records on x, y, z rounded to 0.01 m.
    ref_keys = _keys(ref.x, ref.y, ref.z)
    last_keys = _keys(site.x[last_box], site.y[last_box], site.z[last_box])
    uniq, inverse = np.unique(np.vstack([ref_keys, last_keys]), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    ref_id, last_id = inverse[:len(ref)], inverse[len(ref):]
    per_key = np.bincount(last_id, minlength=len(uniq))
    stats.ambiguous = int((per_key[ref_id] > 1).sum())
    # Repeated coordinates (a few per sample, in the reference and the site alike) are paired in
    # file order: the k-th reference point of a key takes the k-th last-pulse record of that key,
    # or the key's first record when the site has fewer.
    ref_rank, last_rank = _occurrence(ref_id), _occurrence(last_id)
    width = int(max(ref_rank.max(initial=0), last_rank.max(initial=0))) + 1
    record_of_pair = np.full(len(uniq) * width, -1, dtype=np.int64)
    record_of_pair[last_id * width + last_rank] = last_box
    record = record_of_pair[ref_id * width + ref_rank]
    fallback = (record < 0) & (per_key[ref_id] > 0)
    record[fallback] = record_of_pair[ref_id[fallback] * width]
    matched = record >= 0
    stats.joined = int(matched.sum())
    stats.unmatched = int((~matched).sum())
    _, counts = np.unique(record[matched], return_counts=True)
    stats.shared = int(counts[counts > 1].sum())
    in_reference = np.zeros(len(uniq), dtype=bool)
    in_reference[ref_id] = True
    stats.last_in_box_not_reference = int((~in_reference[last_id]).sum())
    ref_ground = ref.reference_label[matched] == 0
    record = record[matched]

    pulses_in_box = np.unique(np.where(box >= half, box - half, box))
    stats.single_echo_share = float(single[pulses_in_box].mean()) if pulses_in_box.size else 0.0

    stats.below_reference = int((site.z[box] < ref.z.min()).sum())
    stats.above_reference = int((site.z[box] > ref.z.max()).sum())
    out = []
    for encoding in encodings:
        n_site = len(site)
        rn = site.return_number.copy()
        nr = site.number_of_returns.copy()
        keep = in_box.copy()
        if encoding == "echoes":
            single_all = np.concatenate([single, single])
            keep[:half] &= ~single          # the first-pulse duplicate of a one-echo pulse
            rn[half:][single] = 1
            nr[single_all] = 1
        sel = np.flatnonzero(keep)
        position = np.full(n_site, -1, dtype=np.int64)
        position[sel] = np.arange(sel.size)
        scored = position[record]
        assert (scored >= 0).all()
        xyz = np.column_stack([site.x[sel], site.y[sel], site.z[sel]])
        if encoding == "file":
            stats.input_file = int(sel.size)
        else:
            stats.input_echoes = int(sel.size)
        label = name if encoding == "file" else f"{name} [echoes]"
        out.append(DataSet(label, xyz, np.ascontiguousarray(rn[sel]), np.ascontiguousarray(nr[sel]),
                           scored, ref_ground, group=f"isprs-{encoding}", note=site_name,
                           intensity=np.asarray(site.intensity)[sel]))
    return out, stats


def crs_metres_per_unit(crs_wkt: Optional[str]) -> Tuple[float, str]:
    """Metres per horizontal unit of a CRS (1.0 and a note when it cannot be read)."""
    if not crs_wkt:
        return 1.0, "no CRS; lengths taken as metres"
    try:
        import pyproj
        crs = pyproj.CRS.from_wkt(crs_wkt)
        axes = crs.axis_info
        if axes:
            return float(axes[0].unit_conversion_factor), axes[0].unit_name
    except Exception as err:  # pyproj missing or an odd WKT: say so, assume metres
        return 1.0, f"CRS unit unreadable ({err}); lengths taken as metres"
    return 1.0, "CRS without axes; lengths taken as metres"


def load_producer(name: str, data: str, log: Callable[[str], None]) -> List[DataSet]:
    rel, note = PRODUCER_SETS[name]
    path = os.path.join(data, rel)
    if not os.path.isfile(path):
        log(f"{name}: {path} is missing; skipped")
        return []
    cloud = read_cloud(path)
    cls = cloud.classification
    noise = np.isin(cls, NOISE_CLASSES)
    water = cls == CLASS_WATER
    sel = np.flatnonzero(~noise)
    xyz = np.column_stack([cloud.x[sel], cloud.y[sel], cloud.z[sel]])
    scored = np.flatnonzero(~water[sel])
    factor, unit = crs_metres_per_unit(cloud.crs_wkt)
    extra = [label_check(xyz[scored], cls[sel][scored] == CLASS_GROUND, 0.3 / factor)]
    if noise.any():
        extra.append(f"{int(noise.sum())} noise points (class 7/18) left out")
    zg = xyz[scored][cls[sel][scored] == CLASS_GROUND, 2]
    if zg.size and abs(float(np.median(zg))) < 0.1 / factor and float(np.percentile(zg, 99)) < 0.5 / factor:
        extra.append("heights normalised above ground (class 2 at z = 0): the terrain is flat by construction")
    if water.any():
        extra.append(f"{int(water.sum())} water points (class 9) filtered but not scored")
    if (cloud.return_number == 1).all() and (cloud.number_of_returns > 1).any():
        extra.append("first returns only (return number always 1)")
    if factor != 1.0:
        extra.append(f"CRS unit {unit} ({factor:g} m); z taken in the same unit")
    log(f"{name}: {rel}, {len(cloud):,} points, classes "
        + ", ".join(f"{c}: {k:,}" for c, k in zip(*np.unique(cls, return_counts=True)))
        + (f"; {'; '.join(extra)}" if extra else ""))
    return [DataSet(name, xyz, np.ascontiguousarray(cloud.return_number[sel]),
                    np.ascontiguousarray(cloud.number_of_returns[sel]), scored,
                    cls[sel][scored] == CLASS_GROUND, metres_per_unit=factor, group="producer",
                    note=note)]


def label_check(xyz: np.ndarray, ground: np.ndarray, near: float) -> str:
    """Share of points not labelled ground within ``near`` (vertically) of the labelled ground."""
    from scipy.spatial import cKDTree
    if ground.sum() < 8 or ground.all():
        return "label check: too few ground points"
    tree = cKDTree(xyz[ground, :2])
    _, idx = tree.query(xyz[~ground, :2], k=8)
    h = xyz[~ground, 2] - np.median(xyz[ground, 2][idx], axis=1)
    return (f"label check: {100 * np.mean(np.abs(h) <= near):.1f} % of the points not labelled ground "
            f"lie within 0.3 m of the labelled ground around them")


# ---------------------------------------------------------------------------------------------
# Filters
# ---------------------------------------------------------------------------------------------

def length_parameters(algorithm) -> Tuple[str, ...]:
    """The names of the filter's parameters that are lengths (see EXTRA_LENGTHS, RATIOS)."""
    names = []
    for f in dataclasses.fields(algorithm):
        value = getattr(algorithm, f.name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        if f.name.endswith("_m") or f.name in EXTRA_LENGTHS:
            names.append(f.name)
        elif f.name not in RATIOS:
            raise SystemExit(f"{type(algorithm).__name__}.{f.name}: not known as a length or a ratio; "
                             "add it to EXTRA_LENGTHS or RATIOS in bench/returns.py")
    return tuple(names)


def in_cloud_units(algorithm, metres_per_unit: float):
    """The filter with every length parameter converted from metres to the cloud's unit."""
    if metres_per_unit == 1.0:
        return algorithm
    return dataclasses.replace(algorithm, **{n: getattr(algorithm, n) / metres_per_unit
                                             for n in length_parameters(algorithm)})


def describe_lengths(algorithm) -> str:
    return ", ".join(f"{n} {getattr(algorithm, n):.4g}" for n in length_parameters(algorithm))


def call(algorithm, ds: DataSet, messages: List[str]):
    """One filter call as core.engine.workflow.call_filter makes it (fields and log on request)."""
    extra = {name: ds.fields[name] for name in getattr(algorithm, "point_fields", ())}
    if getattr(algorithm, "wants_log", False):
        extra["log"] = messages.append
    if hasattr(algorithm, "run"):
        detail = algorithm.run(ds.xyz, **extra)
        return np.asarray(detail.ground, dtype=bool), detail
    return np.asarray(algorithm(ds.xyz, **extra), dtype=bool), None


def run_set(ds: DataSet, repeat: int) -> List[dict]:
    algorithms = {f: in_cloud_units(make_filter(f, None), ds.metres_per_unit) for f in FILTER_NAMES}
    messages: Dict[str, List[str]] = {f: [] for f in FILTER_NAMES}
    outputs = {f: call(a, ds, messages[f]) for f, a in algorithms.items()}  # warm-up: compilation excluded
    best = {f: math.inf for f in FILTER_NAMES}
    # Rounds over the filters, so that a busy spell of the machine hits them alike.
    for _ in range(max(1, repeat)):
        for fname, algorithm in algorithms.items():
            t0 = time.perf_counter()
            outputs[fname] = call(algorithm, ds, [])
            best[fname] = min(best[fname], time.perf_counter() - t0)
    rows = []
    for fname, algorithm in algorithms.items():
        ground, detail = outputs[fname]
        acc = ground_accuracy(ds.reference_ground, ground[ds.scored])
        bypass = ""
        if detail is not None and hasattr(detail, "bypassed"):
            bypass = f"{detail.bypassed}/{detail.kernels}"
        rows.append({"set": ds.name, "group": ds.group, "note": ds.note, "input": len(ds.xyz),
                     "scored": int(ds.scored.size), "filter": fname, "type1": 100 * acc.type1,
                     "type2": 100 * acc.type2, "total": 100 * acc.total, "kappa": 100 * acc.kappa,
                     "seconds": best[fname], "bypass": bypass, "accuracy": acc,
                     "lengths": describe_lengths(algorithm), "messages": sorted(set(messages[fname]))})
    t_ref = next(r["seconds"] for r in rows if r["filter"] == REFERENCE_FILTER)
    for r in rows:
        r["ratio"] = r["seconds"] / t_ref if t_ref > 0 else float("nan")
    return rows


# ---------------------------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------------------------

def results_table(rows: List[dict]) -> str:
    lines = ["| Data set | Points (input / scored) | Filter | Type I % | Type II % | Total % | Kappa % "
             "| Time s | Time / SMRF | Kernels bypassed |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['set']} | {r['input']:,} / {r['scored']:,} | {r['filter']} | {r['type1']:.2f} | "
                     f"{r['type2']:.2f} | {r['total']:.2f} | {r['kappa']:.2f} | {r['seconds']:.4f} | "
                     f"{r['ratio']:.3g} | {r['bypass'] or '-'} |")
    return "\n".join(lines)


def mean_table(rows: List[dict]) -> str:
    lines = ["| Samples | Filter | mean Type I % | mean Type II % | mean Total % | mean Kappa % "
             "| Time s (sum) | Time / SMRF (sums) |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    groups = list(dict.fromkeys(r["group"] for r in rows))
    for g in groups:
        sub = [r for r in rows if r["group"] == g]
        t_ref = sum(r["seconds"] for r in sub if r["filter"] == REFERENCE_FILTER)
        n = len({r["set"] for r in sub})
        for fname in FILTER_NAMES:
            fr = [r for r in sub if r["filter"] == fname]
            if not fr:
                continue
            m = {k: float(np.mean([r[k] for r in fr])) for k in ("type1", "type2", "total", "kappa")}
            t = sum(r["seconds"] for r in fr)
            lines.append(f"| {g} ({n}) | {fname} | {m['type1']:.2f} | {m['type2']:.2f} | {m['total']:.2f} | "
                         f"{m['kappa']:.2f} | {t:.4f} | {t / t_ref if t_ref else float('nan'):.3g} |")
    return "\n".join(lines)


def _count(n: int) -> str:
    return f"{n:,}" if n else "-"


def join_table(stats: List[JoinStats]) -> str:
    lines = ["| Sample | Site | Reference pts | Joined | Unmatched (left out) | Repeated xyz "
             "| Sharing a record | Last pulses in box | ... not in reference | Input (file) | Input (echoes) "
             "| One-echo pulses % | Box records below / above reference z |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for s in stats:
        lines.append(f"| {s.sample} | {s.site} | {s.reference:,} | {s.joined:,} | {s.unmatched} | "
                     f"{s.ambiguous} | {s.shared} | {s.last_in_box:,} | {s.last_in_box_not_reference:,} | "
                     f"{_count(s.input_file)} | {_count(s.input_echoes)} | {100 * s.single_echo_share:.1f} | "
                     f"{s.below_reference} / {s.above_reference} |")
    return "\n".join(lines)


def write_csv(rows: List[dict], path: str) -> None:
    keys = ["set", "group", "note", "input", "scored", "filter", "type1", "type2", "total", "kappa",
            "seconds", "ratio", "bypass", "lengths"]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys + ["tp", "fn", "fp", "tn"])
        for r in rows:
            acc: GroundAccuracy = r["accuracy"]
            w.writerow([f"{r[k]:.6g}" if isinstance(r[k], float) else r[k] for k in keys]
                       + [acc.tp, acc.fn, acc.fp, acc.tn])


def code_state() -> str:
    """The commit and any uncommitted core module (with a short hash), to tell runs apart."""
    import hashlib
    import subprocess
    try:
        head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
        status = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "--", "core"],
                                capture_output=True, text=True, check=True).stdout.splitlines()
    except (OSError, subprocess.CalledProcessError):
        return "code: not a git checkout"
    changed = [line[3:] for line in status if line.strip()]
    parts = [f"{f} ({hashlib.sha256((REPO / f).read_bytes()).hexdigest()[:10]})"
             for f in changed if (REPO / f).is_file()]
    return f"code: commit {head}; " + (f"uncommitted: {', '.join(parts)}" if parts else "core unchanged")


def expand_sets(names: List[str], data: str) -> List[str]:
    samples = sorted(p.name.split(".")[0].lower() for p in Path(data, "isprs").glob("samp*.txt"))
    samples = [s for s in samples if s in SAMPLE_SITES]
    out: List[str] = []

    def add(name: str) -> None:
        if name == "isprs":
            for s in samples:
                add(s)
        elif name in GROUPS:
            for s in GROUPS[name]:
                add(s)
        elif name not in out:
            out.append(name)

    for n in names:
        add(n.lower())
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"),
                    help="folder holding isprs/, isprs_sites/, lidR/, lasR_bcts/, laspy/ (default: %(default)s)")
    choices = sorted(GROUPS) + sorted(set(SAMPLE_SITES) | set(PRODUCER_SETS))
    ap.add_argument("--sets", nargs="+", default=["all"], metavar="SET",
                    help=f"data sets or groups: {', '.join(choices)} (default: all)")
    ap.add_argument("--isprs-returns", choices=("file", "echoes", "both"), default="both",
                    help="return numbers of the ISPRS sites: as in the file (1 of 2 / 2 of 2 for every "
                         "pulse), derived echoes (one echo where first and last pulse agree), or both")
    ap.add_argument("--repeat", type=int, default=5, help="timed calls per filter after the warm-up; best kept")
    ap.add_argument("--csv", help="also write the results to this CSV file")
    args = ap.parse_args(argv)
    if not os.path.isdir(args.data):
        ap.error(f"--data {args.data}: not a folder")
    bad = [s for s in args.sets if s.lower() not in choices]
    if bad:
        ap.error(f"--sets: unknown {', '.join(bad)}; known: {', '.join(choices)}")
    encodings = ("file", "echoes") if args.isprs_returns == "both" else (args.isprs_returns,)

    notes: List[str] = []
    log = notes.append
    warnings.simplefilter("ignore")
    sites = SiteCache()
    all_rows: List[dict] = []
    join_stats: List[JoinStats] = []
    for name in expand_sets(args.sets, args.data):
        if name in SAMPLE_SITES:
            sets, stats = load_isprs(name, args.data, encodings, sites, log)
            if stats is not None:
                join_stats.append(stats)
        else:
            sets = load_producer(name, args.data, log)
        for ds in sets:
            rows = run_set(ds, args.repeat)
            all_rows += rows
            if ds.metres_per_unit != 1.0:
                conv = "; ".join(f"{r['filter']}: {r['lengths']}" for r in rows)
                log(f"NOTE {ds.name}: the CRS unit is {ds.metres_per_unit:g} m; every length parameter was "
                    f"converted from its metre default (x {1 / ds.metres_per_unit:.5g}): {conv}. "
                    "Slopes are ratios and unchanged.")
            for r in rows:
                for m in r["messages"]:
                    log(f"{ds.name} {r['filter']}: {m}")
            print(f"done {ds.name}", file=sys.stderr, flush=True)

    print(f"Filters: {', '.join(FILTER_NAMES)} (defaults); data: {args.data}; ISPRS returns: "
          f"{args.isprs_returns}; time = best of {args.repeat} rounds after a warm-up call, filter only; "
          f"{code_state()}.\n")
    if join_stats:
        print("### ISPRS join (reference points to last-pulse records, x y z rounded to 0.01 m)\n")
        print(join_table(join_stats))
        print()
    isprs_rows = [r for r in all_rows if r["group"].startswith("isprs")]
    other_rows = [r for r in all_rows if not r["group"].startswith("isprs")]
    if isprs_rows:
        print("### ISPRS samples on the raw sites (scored: the joined reference points)\n")
        print(results_table(isprs_rows))
        print()
        print(mean_table(isprs_rows))
        print()
    if other_rows:
        print("### Producer-labelled ALS (scored: all points but noise 7/18 and water 9; class 2 = ground)\n")
        print(results_table(other_rows))
        print()
    if notes:
        print("Notes:")
        for n in notes:
            print(f"- {n}")
    if args.csv:
        write_csv(all_rows, args.csv)
        print(f"\nWrote {args.csv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
