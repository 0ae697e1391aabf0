"""Tune a ground filter on a labelled patch (``groundsieve:tune``, ``python -m groundsieve tune``).

The search, over the ranges of ``parameters.SEARCH`` (spanning the values the papers used or studied):

1. the filter's defaults (or the starting preset's values), then a space-filling design over
   the ranges: a Halton sequence (deterministic; on 3-4 parameters it covers each range far more
   finely than a full grid of the same number of sets), about 40 % of the budget;
2. a local refinement: a pattern search (each parameter up and down by a step; the step halves
   when no move helps) from the best set so far, until the budget (number of filter runs) or the
   time limit is spent.

Honest figure, spatial-block cross-validation: the patch is split into ``blocks`` spatial
blocks of equal point counts. Every set filters the whole patch once and is scored per block
(its confusion counts per block are kept), so a set costs one filter run. For each block b, a
search of its own (step 2 run on the other blocks' score, its pool: the design of step 1 and
its own refinement, never sets proposed by a search that saw block b) chooses a set on the other
blocks; that set's errors on block b are held out. The pooled held-out confusion gives the
cross-validated error. The preset carries the set chosen on all blocks (every set tried).

Deterministic: no random numbers; the same patch, filter and options give the same sets.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from ..errors import Cancelled, GroundSieveError, InputError, InvalidParameterError
from ..io import CLASS_GROUND, PointCloud, read_cloud
from ..metrics import GroundAccuracy
from ..progress import Steps
from . import parameters as P

METRICS = ("total", "kappa", "f1")
#: how a set is chosen among those tried: "best" = the lowest error on the blocks it is chosen on;
#: "one-se" = the one-standard-error rule (Breiman et al. 1984): of the sets whose error is within one
#: standard error (of the paired per-block differences) of the best, the one nearest the set the
#: search started from (the defaults, or the starting preset)
SELECTIONS = ("best", "one-se")
METRIC_LABELS = {"total": "total error", "kappa": "Cohen's kappa", "f1": "F1 of the ground class"}


@dataclass(frozen=True)
class TuneOptions:
    metric: str = "total"       #: what to optimise: total error (lower), kappa or F1 (higher)
    budget: int = 60            #: filter runs (sets differing only in parameters.CHEAP cost none)
    #: spatial blocks of the cross-validation (2-16). 8 rather than 4: each fold's set is then chosen on
    #: 7/8 of the patch, closer to the final set chosen on all of it (on the 8 ISPRS samples, SMRF, budget
    #: 60: CV error lower or equal on every sample measured both ways; docs/BENCHMARKS.md)
    blocks: int = 8
    seconds: float = 0.0        #: stop starting new sets after this long (0 = no limit)
    design_share: float = 0.4   #: share of the budget spent on the space-filling design
    selection: str = "best"     #: how the sets are chosen (SELECTIONS)

    def __post_init__(self):
        if self.metric not in METRICS:
            raise InvalidParameterError(f"metric must be one of {', '.join(METRICS)} (got {self.metric!r})")
        if isinstance(self.budget, bool) or not isinstance(self.budget, int) or self.budget < 4:
            raise InvalidParameterError(f"the search budget must be at least 4 parameter sets (got {self.budget!r})")
        if isinstance(self.blocks, bool) or not isinstance(self.blocks, int) or not 2 <= self.blocks <= 16:
            raise InvalidParameterError(f"cross-validation blocks must be 2 to 16 (got {self.blocks!r})")
        if not (isinstance(self.seconds, (int, float)) and math.isfinite(self.seconds) and self.seconds >= 0):
            raise InvalidParameterError(f"the time limit must be >= 0 seconds (got {self.seconds!r})")
        if self.selection not in SELECTIONS:
            raise InvalidParameterError(f"selection must be one of {', '.join(SELECTIONS)} (got {self.selection!r})")
        if self.selection == "one-se" and self.blocks < 3:
            raise InvalidParameterError("the one-standard-error rule needs at least 3 cross-validation blocks (each "
                                        f"fold chooses on the others, at least 2; got {self.blocks})")
        if not 0.0 < self.design_share <= 1.0:
            raise InvalidParameterError(f"design_share must be in (0, 1] (got {self.design_share})")


@dataclass(frozen=True)
class Dim:
    name: str                   #: Processing name
    field: str
    low: float = 0.0
    high: float = 0.0
    values: Tuple = ()          #: choices / on-off (then low/high unused)
    integer: bool = False

    def value(self, u: float):
        """The value at ``u`` in [0, 1)."""
        if self.values:
            return self.values[min(int(u * len(self.values)), len(self.values) - 1)]
        v = self.low + u * (self.high - self.low)
        return int(round(v)) if self.integer else round(v, 3)

    def clip(self, v):
        v = min(max(v, self.low), self.high)
        return int(round(v)) if self.integer else round(v, 3)

    @property
    def span(self) -> float:
        return self.high - self.low


def _number(v) -> str:
    return f"{float(v):g}"


def search_space(name: str) -> List[Dim]:
    """The dimensions ``groundsieve:tune`` searches for filter ``name`` (parameters.SEARCH)."""
    table = P.by_name(name)
    dims = []
    for key, spec in P.SEARCH[name].items():
        p = table[key]
        kind = P.field_type(name, p.field)
        if p.choices or kind is bool or len(spec) != 2:
            dims.append(Dim(key, p.field, values=tuple(spec)))
        else:
            dims.append(Dim(key, p.field, float(spec[0]), float(spec[1]), integer=kind is int))
    return dims


def halton(i: int, base: int) -> float:
    f, r = 1.0, 0.0
    while i > 0:
        f /= base
        r += f * (i % base)
        i //= base
    return r


_PRIMES = (2, 3, 5, 7, 11, 13, 17, 19)


def design(dims: Sequence[Dim], count: int) -> List[Dict[str, object]]:
    """``count`` sets spread over the ranges (Halton points 1..count, deterministic)."""
    return [{d.field: d.value(halton(i, _PRIMES[j])) for j, d in enumerate(dims)} for i in range(1, count + 1)]


# ---------------------------------------------------------------------------------------------
# Labelled patch and blocks
# ---------------------------------------------------------------------------------------------

NOISE = (7, 18)


def reference_ground(cloud: PointCloud, where: str) -> Tuple[np.ndarray, np.ndarray]:
    """(points scored: bool, reference ground: bool) of a labelled patch. ISPRS text: label 0 =
    ground, 1 = object; LAS/LAZ: class 2 = ground, every other class non-ground except noise (7,
    18) and withheld points, which are neither filtered nor scored."""
    if cloud.reference_label is not None:
        use = np.ones(len(cloud), dtype=bool)
        ground = cloud.reference_label == 0
    elif cloud.has_return_info or cloud.las is not None:
        use = ~cloud.withheld_mask & ~np.isin(cloud.classification, NOISE)
        ground = cloud.classification == CLASS_GROUND
    else:
        raise InputError(f"{where}: the tuning patch has no labels (an ISPRS text file needs the 4th column "
                         f"'label', 0 = ground, 1 = object)")
    n_ground = int(np.count_nonzero(ground & use))
    n_other = int(np.count_nonzero(~ground & use))
    what = "label 0" if cloud.reference_label is not None else "class 2"
    if n_ground == 0:
        raise InputError(f"{where}: the tuning patch holds no ground points ({what}): label ground and "
                         f"non-ground points of a patch to tune on")
    if n_other == 0:
        raise InputError(f"{where}: the tuning patch holds no non-ground points (every point is ground, "
                         f"{what}): a filter cannot be tuned without objects to remove")
    return use, ground


def spatial_blocks(x: np.ndarray, y: np.ndarray, k: int) -> Tuple[np.ndarray, Tuple[int, int]]:
    """Block index (0..k-1) per point: ``nx`` strips along the longer axis, each cut into ``ny``
    blocks along the other (``nx * ny = k``, the pair closest to the patch's shape); equal counts."""
    wx, wy = float(np.ptp(x)) or 1.0, float(np.ptp(y)) or 1.0
    pairs = [(a, k // a) for a in range(1, k + 1) if k % a == 0]
    nx, ny = min(pairs, key=lambda p: abs(math.log((p[0] / p[1]) / (wx / wy))))
    block = np.empty(len(x), dtype=np.int64)
    order = np.argsort(x, kind="stable")
    for i, strip in enumerate(np.array_split(order, nx)):
        sub = strip[np.argsort(y[strip], kind="stable")]
        for j, part in enumerate(np.array_split(sub, ny)):
            block[part] = i * ny + j
    return block, (nx, ny)


def block_counts(ref: np.ndarray, pred: np.ndarray, block: np.ndarray, k: int) -> np.ndarray:
    """(k, 4) confusion counts tp, fn, fp, tn per block."""
    code = (~ref).astype(np.int64) * 2 + (~pred).astype(np.int64)  # tp 0, fn 1, fp 2, tn 3
    return np.bincount(block * 4 + code, minlength=4 * k).reshape(k, 4)


def accuracy(counts) -> GroundAccuracy:
    tp, fn, fp, tn = (int(v) for v in counts)
    return GroundAccuracy(tp=tp, fn=fn, fp=fp, tn=tn)


def loss(counts, metric: str) -> float:
    """Lower is better: the total error, or minus kappa / F1."""
    a = accuracy(counts)
    return a.total if metric == "total" else -(a.kappa if metric == "kappa" else a.f1)


def score(counts, metric: str) -> float:
    """The metric itself (total error, kappa or F1)."""
    return abs(loss(counts, metric))


# ---------------------------------------------------------------------------------------------
# The search
# ---------------------------------------------------------------------------------------------

@dataclass
class Trial:
    values: Dict[str, object]   #: field -> value of the searched parameters
    counts: Optional[np.ndarray]  #: (blocks, 4) tp fn fp tn; None = the set failed
    seconds: float
    phase: str                  #: "start", "design" or "refine"
    track: int = -1             #: refinement: -1 = on all blocks, b = with block b held out (first proposer)
    error: str = ""
    proposed_by: set = field(default_factory=set)  #: refinement tracks that proposed this set

    def loss(self, metric: str, blocks: Optional[Sequence[int]] = None) -> float:
        if self.counts is None:
            return math.inf
        c = self.counts if blocks is None else self.counts[list(blocks)]
        return loss(c.sum(axis=0), metric)


@dataclass
class Fold:
    block: int
    chosen: int                 #: index of the trial chosen on the other blocks
    held_out: GroundAccuracy    #: its result on this block


@dataclass
class TuneResult:
    filter: str
    metric: str
    patch: str
    points: int
    dims: List[Dim]
    fixed: Dict[str, object]    #: field -> value of every field (the base) the search started from
    trials: List[Trial]
    best: int                   #: index of the set chosen on all blocks (the preset's)
    folds: List[Fold]
    block_grid: Tuple[int, int]
    block_sizes: List[int]
    seconds: float
    budget: int
    stopped: str = ""           #: why the search stopped early ("time limit", ...), "" = budget spent
    default_trial: int = 0      #: index of the starting set (defaults or the starting preset)
    runs: int = 0               #: filter runs (the budget's unit; re-scored sets cost none)
    selection: str = "best"     #: how the preset's and the folds' sets were chosen (SELECTIONS)
    extent: Tuple[float, float] = (0.0, 0.0)  #: the patch's width and height (m) of the points scored

    @property
    def cv(self) -> GroundAccuracy:
        """Pooled held-out confusion of the cross-validation (the honest figure)."""
        tp = sum(f.held_out.tp for f in self.folds)
        fn = sum(f.held_out.fn for f in self.folds)
        fp = sum(f.held_out.fp for f in self.folds)
        tn = sum(f.held_out.tn for f in self.folds)
        return GroundAccuracy(tp=tp, fn=fn, fp=fp, tn=tn)

    @property
    def best_accuracy(self) -> GroundAccuracy:
        """The preset's set on the whole patch (in-sample: optimistic)."""
        return accuracy(self.trials[self.best].counts.sum(axis=0))

    @property
    def start_accuracy(self) -> Optional[GroundAccuracy]:
        t = self.trials[self.default_trial]
        return None if t.counts is None else accuracy(t.counts.sum(axis=0))

    @property
    def best_values(self) -> Dict[str, object]:
        """Every field of the filter with the chosen set (what the preset carries)."""
        out = dict(self.fixed)
        out.update(self.trials[self.best].values)
        return out

    @property
    def at_range_ends(self) -> List[Tuple[Dim, str]]:
        """The searched numeric parameters whose chosen value is an end of its range, with "lower"
        or "upper": the best value may lie beyond what was searched."""
        out = []
        values = self.best_values
        bounds = P.by_name(self.filter)
        for d in self.dims:
            if d.values or d.span <= 0:
                continue
            v = float(values[d.field])
            floor = bounds[d.name].minimum if d.name in bounds else None
            if v <= d.low + 1e-6 * d.span:
                if floor is not None and d.low <= floor:  # (the lowest value the filter takes: nothing beyond, e.g.
                    continue                              # EVC's ground offset at the paper's 0: a code reviewer)
                out.append((d, "lower"))
            elif v >= d.high - 1e-6 * d.span:
                out.append((d, "upper"))
        return out

    @property
    def warnings(self) -> List[Tuple[str, str]]:
        """(title, sentence) of what the user should know about the chosen set: values at an end of
        their searched range, sizes wider than the patch."""
        notes = [("No better than the start", self.no_gain_note()), ("At the end of a range", self.range_end_note()),
                 ("Beyond the patch", beyond_patch_note(self))]
        return [(title, text) for title, text in notes if text]

    def no_gain_note(self) -> str:
        """A sentence when the tuned sets' cross-validated figure is no better than the starting set's
        on the whole patch ("" otherwise): the start was fitted to nothing, so its figure is as honest
        as the cross-validation's, and a preset then promises nothing the start did not."""
        start = self.start_accuracy
        if start is None or not self.folds:
            return ""
        cv = self.cv
        tuned, begun = getattr(cv, self.metric), getattr(start, self.metric)
        if (tuned < begun) if self.metric == "total" else (tuned > begun):
            return ""
        name = {"total": "total error", "kappa": "kappa", "f1": "F1"}[self.metric]
        return (f"The tuned sets' cross-validated {name} ({100 * tuned:.2f} %) is no better than the starting set's "
                f"on the whole patch ({100 * begun:.2f} %), to which nothing was fitted: on this patch the search found "
                "nothing that carries to unseen blocks. Keep the starting parameters (the filter's defaults or the "
                "starting preset), or tune on a larger or more typical patch.")

    def range_end_note(self) -> str:
        """A sentence on the parameters chosen at an end of their searched range ("" when none)."""
        ends = self.at_range_ends
        if not ends:
            return ""
        items = [f"{d.name} ({_number(self.best_values[d.field])}) at the {end} end of its searched range "
                 f"({_number(d.low)} to {_number(d.high)})" for d, end in ends]
        return ("; ".join(items) + ": the best value may lie beyond. The ranges span the values the papers used or studied, "
                "wider where a paper gives one setting or few (core/engine/parameters.py SEARCH); to "
                "try beyond, run the filter with this preset and the value set by hand, and compare on the patch.")


#: searched sizes that a patch shows only up to its own size: (filter, dialog name) -> how many times
#: the value spans (SMRF's window is a radius: twice it across)
PATCH_SIZED = {("smrf", "WINDOW"): 2.0, ("pmf", "MAX_WINDOW"): 1.0, ("ptd", "SEED_CELL"): 1.0}


def beyond_patch_note(result: "TuneResult") -> str:
    """A sentence on the chosen sizes wider than the patch ("" when none): on the patch, sizes that
    large all act alike, so the value chosen there says little of what the survey needs."""
    side = max(result.extent)
    if side <= 0:
        return ""
    values = result.best_values
    items = []
    for d in result.dims:
        across = PATCH_SIZED.get((result.filter, d.name))
        if across and float(values[d.field]) * across > side:
            items.append(f"{d.name} ({_number(values[d.field])} m{', a radius' if across == 2 else ''})")
    if not items:
        return ""
    return (" and ".join(items) + f" reaches beyond the patch ({result.extent[0]:.0f} x {result.extent[1]:.0f} m): "
            "on the patch, sizes that large act alike, so this value is not really tuned. On the survey it should "
            "be about the size of the largest non-ground object (e.g. a building's radius for SMRF's window); "
            "tune on a larger patch, or set it by hand over the preset.")


def _distance(values: Mapping[str, object], start: Mapping[str, object], dims: Sequence[Dim]) -> float:
    """Squared distance between two sets, each range scaled to 1 (a different choice counts 1)."""
    d = 0.0
    for dim in dims:
        a, b = values[dim.field], start[dim.field]
        if dim.values or not dim.span:
            d += float(a != b)
        else:
            d += ((float(a) - float(b)) / dim.span) ** 2
    return d


def choose(trials: Sequence[Trial], indices: Sequence[int], blocks: Sequence[int], metric: str,
           selection: str = "best", start: Optional[Mapping[str, object]] = None,
           dims: Sequence[Dim] = ()) -> int:
    """The trial chosen among ``indices`` on ``blocks``: the lowest loss ("best"), or by the
    one-standard-error rule ("one-se", see SELECTIONS; at least 2 blocks): the gap to the best and
    its standard error are the mean and standard error of the per-block differences (so a block
    whose kappa jumps from 1 to 0 on one point weighs in both). Ties go to the earlier trial."""
    best = min(indices, key=lambda i: (trials[i].loss(metric, blocks), i))
    if selection == "best" or start is None:
        return best
    blocks = list(blocks)
    if len(blocks) < 2:
        raise ValueError("the one-standard-error rule needs at least 2 blocks to choose on")
    per_block = lambda i: np.array([loss(trials[i].counts[b], metric) for b in blocks])  # noqa: E731
    base = per_block(best)
    near = []
    for i in indices:
        if trials[i].counts is None:
            continue
        diff = per_block(i) - base
        gap, se = float(diff.mean()), float(np.std(diff, ddof=1)) / math.sqrt(len(blocks))
        if gap <= se + 1e-12:
            near.append((_distance(trials[i].values, start, dims), trials[i].loss(metric, blocks), i))
    return min(near)[2] if near else best


def _key(values: Mapping[str, object]) -> tuple:
    return tuple(sorted(values.items()))


def _pattern_search(start: Dict[str, object], start_loss: float, dims: Sequence[Dim], min_fraction: float = 1 / 64):
    """Generator: yields candidate sets, receives their loss (``send``); ends when converged."""
    x, fx = dict(start), start_loss
    steps = {d.field: (d.span / 4 if not d.values else None) for d in dims}
    rounds = 0
    while True:
        improved = False
        for d in dims:
            if d.values:
                cands = [v for v in d.values if v != x[d.field]] if rounds == 0 else []
            else:
                s = steps[d.field]
                cands = [d.clip(x[d.field] + s), d.clip(x[d.field] - s)]
                cands = [c for c in cands if c != x[d.field]]
            for c in cands:
                cand = dict(x)
                cand[d.field] = c
                f = yield cand
                if f < fx - 1e-12:
                    x, fx, improved = cand, f, True
                    break
        rounds += 1
        if not improved:
            live = False
            for d in dims:
                if not d.values and steps[d.field] / 2 >= d.span * min_fraction:
                    steps[d.field] /= 2
                    if not d.integer or steps[d.field] >= 0.5:
                        live = True
            if not live:
                return


def _smrf_surface(algorithm, xyz, steps, shared: Optional[dict] = None):
    """SMRF's provisional surface and its slope: what the point test (threshold, scalar) reads.
    ``shared``: a dict kept over one search; SMRF's minimum surface (filled, low outliers refilled),
    which the searched slope and window do not change, is made once per cell and low-outlier
    setting there and reused (two of the three harmonic fills of a run), with the progressive
    opening's drops per radius (SMRFMinimum.drops: the openings are then made once per search)."""
    from ..filters.smrf import surface_slope
    minimum = None
    if shared is not None:
        key = algorithm.minimum_key
        minimum = shared.get(key)
        if minimum is None:
            if len(shared) >= 4:
                shared.pop(next(iter(shared)))
            minimum = shared[key] = algorithm.minimum_surface(xyz, steps, keep_openings=True)
    grid, zpro, _objects = algorithm.surface(xyz, steps, minimum)
    return grid, zpro, surface_slope(zpro, algorithm.cell_size_m)


def _smrf_ground(surface, xyz, values):
    """SMRF's last step (filters/smrf.py) with another threshold and scalar; the tests check it
    against the whole filter, bit for bit."""
    from ..filters.smrf import ground_against_surface
    grid, zpro, slope_grid = surface
    return ground_against_surface(xyz[:, 0], xyz[:, 1], xyz[:, 2], zpro, slope_grid, grid,
                                  values["elevation_threshold_m"], values["elevation_scalar"])


#: filter -> (one run: the surface, re-score: ground of a set from the surface); see parameters.CHEAP
RESCORE = {"smrf": (_smrf_surface, _smrf_ground)}
CHEAP_STEPS = 5  #: values per cheap parameter tried on every filter run of the design


def _in_metres(cloud: PointCloud, log) -> PointCloud:
    """The patch with x, y and z in metres when its CRS's unit is another (feet): the search spans
    the papers' ranges in metres and the preset it writes is in metres, as every preset is, converted
    for each cloud it runs on (workflow.defaults_in_crs_unit). A patch in feet was searched over
    3-49 ft windows and gave a preset read in feet on the patch and in metres elsewhere (a code reviewer)."""
    import dataclasses

    from ..raster.crs import horizontal_unit, metres_per_unit
    factor = metres_per_unit(cloud.crs_wkt)
    if factor is None:
        return cloud
    log(f"{cloud.path or 'the tuning patch'}: the CRS's unit is {horizontal_unit(cloud.crs_wkt)}: the patch is "
        "tuned in metres, and the preset's lengths are metres (converted for each cloud it runs on).")
    return dataclasses.replace(cloud, x=cloud.x * factor, y=cloud.y * factor, z=cloud.z * factor)


#: what the tune's two outputs may end in
PRESET_EXTENSIONS, REPORT_EXTENSIONS = (".json",), (".html", ".htm")


def check_tune_outputs(input_path: str, preset_path: Optional[str], report_path: Optional[str]) -> None:
    """Refuse the tune's outputs before the search (it takes minutes): a preset not named .json (the
    filters' PRESET takes only those: a reviewer's p.txt was written, then refused by the filter), a
    report not .html, a missing folder, the patch itself. A missing patch is said first."""
    import os

    from ..io import check_output_path
    if isinstance(input_path, str) and not os.path.exists(input_path):
        raise InputError(f"{input_path}: no such file")
    if preset_path:
        check_output_path(preset_path, inputs=(input_path,), extensions=PRESET_EXTENSIONS, what="preset")
    if report_path:
        check_output_path(report_path, inputs=(input_path,), extensions=REPORT_EXTENSIONS, what="report")


def tune(cloud, name: str, options: TuneOptions = TuneOptions(), *, base: Optional[Mapping[str, object]] = None,
         progress: Optional[Callable[[float], None]] = None, is_cancelled: Optional[Callable[[], bool]] = None,
         log: Optional[Callable[[str], None]] = None) -> TuneResult:
    """Search filter ``name``'s parameters on the labelled patch ``cloud`` (a PointCloud or a
    path). ``base``: field -> value the search starts from (a preset's; default: the filter's
    defaults); the searched parameters move, the others stay. The budget counts filter runs:
    parameters of ``parameters.CHEAP`` (SMRF's threshold and scalar) are re-scored on a run's
    surface, several values per run, at no cost to the budget."""
    from .tiles import refuse_in_a_workers_import
    from .workflow import call_filter
    refuse_in_a_workers_import()
    P.known_filter(name)
    steps = Steps(progress, is_cancelled)
    log = log or (lambda _m: None)
    if isinstance(cloud, (str, os.PathLike)):
        cloud = read_cloud(os.fspath(cloud))
    where = cloud.path or "the tuning patch"
    cloud = _in_metres(cloud, log)
    use, ref_all = reference_ground(cloud, where)
    idx = np.flatnonzero(use)
    ref = ref_all[idx]
    k = options.blocks
    if len(idx) < 50 * k:
        raise InputError(f"{where}: {len(idx)} labelled points are too few to tune on with {k} blocks "
                         f"(at least {50 * k})")
    block, grid = spatial_blocks(cloud.x[idx], cloud.y[idx], k)
    dims = search_space(name)
    rescore = RESCORE.get(name)
    cheap = {d.field for d in dims if rescore and d.name in P.CHEAP.get(name, ())}
    costly_dims = [d for d in dims if d.field not in cheap]
    cheap_dims = [d for d in dims if d.field in cheap]
    fixed = {f.name: f.default for f in P.filter_fields(name)}
    fixed.update(base or {})
    cls = P.filter_class(name)
    xyz = cloud.xyz[idx] if rescore else None
    trials: List[Trial] = []
    seen: Dict[tuple, int] = {}
    surfaces: Dict[tuple, object] = {}   # costly part of a set -> its surface (rescore only)
    shared: dict = {}                    # what the rescore's runs share (SMRF: the minimum surface)
    runs = [0]
    t0 = time.monotonic()
    stopped = [""]

    def out_of_budget() -> bool:
        if runs[0] >= options.budget:
            return True
        if options.seconds and time.monotonic() - t0 > options.seconds:
            stopped[0] = f"time limit of {options.seconds:g} s"
            return True
        return False

    def evaluate(values: Dict[str, object], phase: str, track: int = -1) -> Optional[int]:
        """Index of the set's trial; None when it needs a filter run and none is left."""
        key = _key(values)
        if key in seen:
            return seen[key]
        args = dict(fixed)
        args.update(values)
        costly = _key({f: v for f, v in args.items() if f not in cheap})
        needs_run = not rescore or costly not in surfaces
        if needs_run and out_of_budget():
            return None
        t = time.monotonic()
        try:
            algorithm = cls(**args)
            if rescore:
                if needs_run:
                    steps.report(runs[0] / options.budget)
                    runs[0] += 1
                    if len(surfaces) >= 64:
                        surfaces.pop(next(iter(surfaces)))
                    surfaces[costly] = rescore[0](algorithm, xyz, Steps(None, steps.is_cancelled), shared)
                ground = rescore[1](surfaces[costly], xyz, args)
            else:
                steps.report(runs[0] / options.budget)
                runs[0] += 1
                ground, _detail = call_filter(algorithm, cloud, idx, Steps(None, steps.is_cancelled), log)
            counts, err = block_counts(ref, ground, block, k), ""
        except Cancelled:
            raise
        except GroundSieveError as e:  # e.g. a grid over the memory budget: this set is skipped
            counts, err = None, str(e)
            log(f"set {len(trials) + 1} skipped: {e}")
        trials.append(Trial(dict(values), counts, time.monotonic() - t, phase, track, err))
        seen[key] = len(trials) - 1
        return len(trials) - 1

    def cheap_grid():
        if not cheap_dims:
            return [{}]
        out = [{}]
        for d in cheap_dims:
            vals = d.values or [d.clip(d.low + d.span * i / (CHEAP_STEPS - 1)) for i in range(CHEAP_STEPS)]
            out = [dict(o, **{d.field: v}) for o in out for v in vals]
        return out

    searched = {d.field for d in dims}
    start = {f: fixed[f] for f in searched}
    start_index = evaluate(start, "start")
    n_design = max(1, int(round(options.budget * options.design_share)) - 1)
    for costly_values in design(costly_dims, n_design):
        for cheap_values in cheap_grid():
            values = dict(start)
            values.update(costly_values)
            values.update(cheap_values)
            if evaluate(values, "design") is None:
                break
        if out_of_budget():
            break
    if cheap_dims:  # the start's own run re-scored on the cheap grid too
        for cheap_values in cheap_grid():
            evaluate(dict(start, **cheap_values), "design")
    pool_design = list(range(len(trials)))
    metric = options.metric
    all_blocks = list(range(k))
    tracks = [-1] + all_blocks
    train = {t: ([b for b in all_blocks if b != t] if t >= 0 else all_blocks) for t in tracks}
    pools = {t: list(pool_design) for t in tracks}

    searches = {}
    for t in tracks:  # each refinement starts from the lowest error on its blocks
        b = choose(trials, pools[t], train[t], metric)
        searches[t] = _pattern_search(trials[b].values, trials[b].loss(metric, train[t]), dims)
    pending = {t: next(searches[t], None) for t in tracks}
    while any(v is not None for v in pending.values()):
        for t in tracks:
            cand = pending[t]
            if cand is None:
                continue
            i = evaluate(cand, "refine", t)
            if i is None:  # budget spent
                pending = {t: None for t in tracks}
                break
            trials[i].proposed_by.add(t)
            if i not in pools[t]:
                pools[t].append(i)
            try:
                pending[t] = searches[t].send(trials[i].loss(metric, train[t]))
            except StopIteration:
                pending[t] = None
    steps.report(1.0)
    if all(t.counts is None for t in trials):
        raise InputError(f"{where}: every parameter set failed ({trials[0].error})")

    def chosen_of(indices, t):
        return choose(trials, indices, train[t], metric, options.selection, start, dims)

    best = chosen_of(range(len(trials)), -1)
    folds = []
    for b in all_blocks:
        chosen = chosen_of(pools[b], b)
        folds.append(Fold(b, chosen, accuracy(trials[chosen].counts[b])))
    return TuneResult(filter=name, metric=metric, patch=where, points=len(idx), dims=dims, fixed=fixed,
                      trials=trials, best=best, folds=folds, block_grid=grid,
                      block_sizes=[int(v) for v in np.bincount(block, minlength=k)],
                      seconds=time.monotonic() - t0, budget=options.budget, stopped=stopped[0],
                      default_trial=start_index, runs=runs[0], selection=options.selection,
                      extent=(float(np.ptp(cloud.x[idx])) if len(idx) else 0.0,
                              float(np.ptp(cloud.y[idx])) if len(idx) else 0.0))


def preset_values(result: TuneResult) -> Dict[str, object]:
    """field -> value the preset saves: the dialog's parameters (the searched ones as chosen, the
    others as the search kept them)."""
    values = result.best_values
    return {p.field: values[p.field] for p in P.params(result.filter)}


def preset_source(result: TuneResult) -> Dict[str, object]:
    cv, fit = result.cv, result.best_accuracy
    return {"patch": result.patch, "points": result.points, "metric": result.metric,
            "blocks": len(result.folds), "selection": result.selection, "sets_tried": len(result.trials),
            "cv_total_error": round(cv.total, 5), "cv_kappa": round(cv.kappa, 5), "cv_f1": round(cv.f1, 5),
            "patch_total_error": round(fit.total, 5), "patch_kappa": round(fit.kappa, 5)}
