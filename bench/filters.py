"""The benches' filter registry: a name mapped to a function that builds the filter from a
row of per-sample parameters (a dict of CSV columns) or, with None, from its defaults."""
from typing import Callable, Dict, Optional

ParamsRow = Optional[Dict[str, str]]


def make_smrf(row: ParamsRow):
    """SMRF with Pingel's per-sample parameters (cell 1 m, as in his runs), or the defaults."""
    from groundsieve.core.smrf import SMRF
    if row is None:
        return SMRF()
    return SMRF(cell_size_m=1.0,
                slope=float(row["slope_threshold"]),
                window_m=float(row["windows"]),
                elevation_threshold_m=float(row["elevation_threshold"]),
                elevation_scalar=float(row["elevation_scaler"]))


FILTERS: Dict[str, Callable[[ParamsRow], Callable]] = {
    "smrf": make_smrf,
}


def make_filter(name: str, row: ParamsRow = None):
    if name not in FILTERS:
        raise SystemExit(f"unknown filter {name!r}; known: {', '.join(sorted(FILTERS))}")
    return FILTERS[name](row)
