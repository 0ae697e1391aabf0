"""The benches' filter registry: a name mapped to a function that builds the filter from a
row of per-sample parameters (a dict of CSV columns) or, with None, from its defaults."""
from typing import Callable, Dict, Optional

ParamsRow = Optional[Dict[str, str]]


def make_smrf(row: ParamsRow, **fixed):
    """SMRF with Pingel's per-sample parameters (cell 1 m, as in his runs), or the defaults."""
    from groundsieve.core.filters.smrf import SMRF
    if row is None:
        return SMRF(**fixed)
    return SMRF(cell_size_m=1.0,
                slope=float(row["slope_threshold"]),
                window_m=float(row["windows"]),
                elevation_threshold_m=float(row["elevation_threshold"]),
                elevation_scalar=float(row["elevation_scaler"]), **fixed)


def make_echogrid(row: ParamsRow, **fixed):
    """The echo grid filter (matrone2024 Method 2), paper defaults (5 m kernels, dz 2 m); the
    per-sample rows hold SMRF parameters, so ``row`` is ignored."""
    from groundsieve.core.filters.echogrid import EchoGrid
    return EchoGrid(**fixed)


def make_evc(row: ParamsRow, **fixed):
    """The multiscale EVC filter (fan2023), paper defaults unless fixed; ``row`` is ignored."""
    from groundsieve.core.filters.evc import EVC
    return EVC(**fixed)


def make_pmf(row: ParamsRow, **fixed):
    """PMF (Zhang et al. 2003) with PDAL's defaults unless fixed; ``row`` (SMRF parameters) is ignored."""
    from groundsieve.core.filters.pmf import PMF
    return PMF(**fixed)


#: Zhang et al. (2016) Table 2: rigidness and slope smoothing of each ISPRS sample's group
#: (cloth 0.5 m, time step 0.65, class threshold 0.5 m for all).
CSF_PAPER_GROUPS = {**{s: (3, False) for s in ("samp21", "samp31", "samp42", "samp51", "samp54")},
                    **{s: (2, True) for s in ("samp11", "samp12", "samp22", "samp23", "samp24", "samp41")},
                    **{s: (1, True) for s in ("samp52", "samp53", "samp61", "samp71")}}


def make_csf(row: ParamsRow, **fixed):
    """CSF with the reference implementation's defaults; ``row`` (SMRF parameters) is ignored."""
    from groundsieve.core.filters.csf import CSF
    return CSF(**fixed)


def make_csf_paper(row: ParamsRow, **fixed):
    """CSF with Zhang et al.'s ISPRS settings: a 0.5 m cloth and the rigidness and slope smoothing
    of the sample's group, found from the row's file name (run bench/isprs.py with --params);
    without a row, the 0.5 m cloth with the other defaults."""
    from groundsieve.core.filters.csf import CSF
    kw = {"cloth_resolution_m": 0.5}
    if row is not None:
        name = row["filename"].strip().split(".")[0].split("-")[0].lower()
        if name in CSF_PAPER_GROUPS:
            kw["rigidness"], kw["slope_smooth"] = CSF_PAPER_GROUPS[name]
    kw.update(fixed)
    return CSF(**kw)


def make_ptd(row: ParamsRow, **fixed):
    """Progressive TIN densification (Axelsson 2000) with its defaults unless fixed; ``row`` is ignored."""
    from groundsieve.core.filters.ptd import PTD
    return PTD(**fixed)


def make_hybrid(row: ParamsRow, **fixed):
    """The learned hybrid filter with the shipped model unless fixed; ``row`` is ignored (the model
    was trained on the shared ISPRS samples: scores on them are not an estimate of its error, see
    bench/hybrid_train.py for the leave-one-sample-out figures)."""
    from groundsieve.core.learn.hybrid import Hybrid
    return Hybrid(**fixed)


FILTERS: Dict[str, Callable[[ParamsRow], Callable]] = {
    "smrf": make_smrf,
    # As Pingel's Python code runs by default: low-outlier cells are not refilled before the opening.
    "smrf-nofill": lambda row: make_smrf(row, low_outlier_fill=False),
    # SMRF's low-outlier slope below the paper's 5 (the dialog's LOW_OUTLIER_SLOPE): 1 catches low points 1 m deep
    "smrf-lo3": lambda row: make_smrf(row, low_outlier_slope=3.0),
    "smrf-lo2": lambda row: make_smrf(row, low_outlier_slope=2.0),
    "smrf-lo1": lambda row: make_smrf(row, low_outlier_slope=1.0),
    "echogrid": make_echogrid,
    "echogrid-evidence": lambda row: make_echogrid(row, mode="evidence"),
    "evc": make_evc,
    "evc-3.2": lambda row: make_evc(row, large_scale_m=3.2),
    "evc-offset": lambda row: make_evc(row, ground_offset_m=0.1),
    "pmf": make_pmf,
    "pmf-linear": lambda row: make_pmf(row, exponential=False),
    "csf": make_csf,
    # The authors' library's behaviour: cell heights with scan-line fill, no low-outlier step, its sweep order.
    "csf-ref": lambda row: make_csf(row, intersection_height="cell", low_outlier_m=0.0, sweep_order="fixed",
                                    cloth_origin="cloud"),
    "csf-paper": make_csf_paper,
    "csf-paper-ref": lambda row: make_csf_paper(row, intersection_height="cell", low_outlier_m=0.0,
                                                sweep_order="fixed", cloth_origin="cloud"),
    # The reference's fixed sweep order (the default cycles through 8 orders).
    "csf-fixed": lambda row: make_csf(row, sweep_order="fixed"),
    "csf-paper-fixed": lambda row: make_csf_paper(row, sweep_order="fixed"),
    "csf-2016": lambda row: make_csf(row, constraint_scheme="2016"),
    # The authors' 2016 code's constraints (the scheme that reproduces the paper's ISPRS table).
    "csf-paper-2016": lambda row: make_csf_paper(row, constraint_scheme="2016"),
    "ptd": make_ptd,
    "ptd-mirror": lambda row: make_ptd(row, mirror=True),
    "ptd-nooffset": lambda row: make_ptd(row, offset_m=0.0),
    "ptd-terrascan": lambda row: make_ptd(row, seed_cell_m=60.0, max_angle_deg=6.0),
    "hybrid": make_hybrid,
    "hybrid-accurate": lambda row: make_hybrid(row, shipped_model="accurate"),
}


def make_filter(name: str, row: ParamsRow = None):
    if name not in FILTERS:
        raise SystemExit(f"unknown filter {name!r}; known: {', '.join(sorted(FILTERS))}")
    return FILTERS[name](row)
