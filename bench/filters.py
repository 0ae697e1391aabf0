"""The benches' filter registry: a name mapped to a function that builds the filter from a
row of per-sample parameters (a dict of CSV columns) or, with None, from its defaults."""
from typing import Callable, Dict, Optional

ParamsRow = Optional[Dict[str, str]]


def make_smrf(row: ParamsRow, **fixed):
    """SMRF with Pingel's per-sample parameters (cell 1 m, as in his runs), or the defaults."""
    from groundsieve.core.smrf import SMRF
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
    from groundsieve.core.echogrid import EchoGrid
    return EchoGrid(**fixed)


def make_evc(row: ParamsRow, **fixed):
    """The multiscale EVC filter (fan2023), paper defaults unless fixed; ``row`` is ignored."""
    from groundsieve.core.evc import EVC
    return EVC(**fixed)


def make_pmf(row: ParamsRow, **fixed):
    """PMF (Zhang et al. 2003) with PDAL's defaults unless fixed; ``row`` (SMRF parameters) is ignored."""
    from groundsieve.core.pmf import PMF
    return PMF(**fixed)


FILTERS: Dict[str, Callable[[ParamsRow], Callable]] = {
    "smrf": make_smrf,
    # As Pingel's Python code runs by default: low-outlier cells are not refilled before the opening.
    "smrf-nofill": lambda row: make_smrf(row, low_outlier_fill=False),
    "echogrid": make_echogrid,
    "echogrid-evidence": lambda row: make_echogrid(row, mode="evidence"),
    "evc": make_evc,
    "evc-3.2": lambda row: make_evc(row, large_scale_m=3.2),
    "evc-offset": lambda row: make_evc(row, ground_offset_m=0.1),
    "pmf": make_pmf,
    "pmf-linear": lambda row: make_pmf(row, exponential=False),
}


def make_filter(name: str, row: ParamsRow = None):
    if name not in FILTERS:
        raise SystemExit(f"unknown filter {name!r}; known: {', '.join(sorted(FILTERS))}")
    return FILTERS[name](row)
