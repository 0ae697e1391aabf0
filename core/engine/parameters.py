"""One definition of every ground filter's user-facing parameters, for the Processing algorithms
and the command line (``python -m groundsieve``).

The defaults are the filter dataclasses' own (never repeated here); this table adds what a user
sees: the Processing name (``CELL``; on the command line ``--cell``), the label, the unit, and for
a choice the values with their labels. Fields of a filter not listed are the core's finer
settings: the command line offers them too (``--low-outlier-max-share``), the toolbox does not.
"""
from __future__ import annotations

import ast
import dataclasses
import functools
import importlib
import os
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple


@dataclass(frozen=True)
class Param:
    field: str                      #: the filter dataclass's field
    name: str                       #: Processing parameter name (command line: --name-in-lower-case)
    label: str                      #: what the dialog shows (without the unit)
    unit: str = ""                  #: "m", "rise/run", "degrees", "cells", ... ("" = none)
    choices: Tuple = ()             #: allowed values of the field, for a choice
    choice_labels: Tuple[str, ...] = ()
    advanced: bool = False
    minimum: Optional[float] = 0.0
    maximum: Optional[float] = None
    #: what it does, for the dialog's tooltip and the command line's help, where the algorithm's help
    #: has no paragraph of its own on it ("" = none)
    help: str = ""

    @property
    def option(self) -> str:
        return "--" + self.name.lower().replace("_", "-")

    def title(self) -> str:
        return f"{self.label} ({self.unit})" if self.unit else self.label


#: filter name -> (module under core.filters, class name, parameters in dialog order)
FILTERS: Dict[str, Tuple[str, str, Sequence[Param]]] = {
    "smrf": ("smrf", "SMRF", (
        Param("cell_size_m", "CELL", "Cell size", "m", minimum=0.01),
        Param("slope", "SLOPE", "Slope", "rise/run"),
        Param("window_m", "WINDOW", "Maximum window radius", "m", minimum=0.01),
        Param("elevation_threshold_m", "THRESHOLD", "Elevation threshold", "m",
              help="a point is ground within this + the elevation scalar x the local slope of the provisional "
                   "ground surface above or below it (0.5 m)"),
        Param("elevation_scalar", "SCALAR", "Elevation scalar", "m per unit slope",
              help="a point is ground within the elevation threshold + this x the provisional surface's local "
                   "slope of it (1.25)"),
        Param("low_outlier_fill", "LOW_OUTLIER_FILL", "Remove low outliers before the opening"),
        Param("low_outlier_slope", "LOW_OUTLIER_SLOPE",
              "Low-outlier slope: a cell this many cell sizes below the cells around it is a low outlier",
              "rise/run", advanced=True, minimum=0.01),
        Param("low_outlier_max_share", "LOW_OUTLIER_MAX_SHARE",
              "Low-outlier share: refill low outliers only where they are at most this share of the occupied cells "
              "within 10 m (1 = always, for clouds of surface points)", advanced=True, minimum=0.0, maximum=1.0),
    )),
    "pmf": ("pmf", "PMF", (
        Param("cell_size_m", "CELL", "Cell size", "m", minimum=0.01),
        Param("max_window_m", "MAX_WINDOW", "Maximum window size", "m", minimum=0.01),
        Param("slope", "SLOPE", "Slope", "rise/run"),
        Param("initial_distance_m", "INITIAL_DISTANCE", "Initial distance (elevation threshold of the first window)",
              "m"),
        Param("max_distance_m", "MAX_DISTANCE", "Maximum distance (largest elevation threshold)", "m", minimum=0.001),
        Param("exponential", "EXPONENTIAL", "Exponential window growth (off: linear)"),
    )),
    "ptd": ("ptd", "PTD", (
        Param("seed_cell_m", "SEED_CELL", "Seed cell size: largest building size", "m", minimum=0.01,
              maximum=1000.0),
        Param("max_angle_deg", "MAX_ANGLE", "Iteration angle", "degrees", maximum=89.9, minimum=0.1),
        Param("max_distance_m", "MAX_DISTANCE", "Iteration distance", "m", minimum=0.001,
              help="a point joins the TIN when it lies at most this far from its triangle's plane and within the "
                   "iteration angle (Axelsson's two criteria; 1.4 m)"),
        Param("max_edge_m", "MAX_EDGE", "Maximum edge length of an accepting triangle", "m, 0 = off",
              help="a triangle with a longer edge accepts no point, so the TIN does not bridge large gaps"),
        Param("min_edge_m", "MIN_EDGE", "Minimum edge length: stop densifying below", "m, 0 = off", advanced=True,
              help="a triangle whose edges are all shorter is not densified further; its passing points are "
                   "ground but not added (Axelsson's edge-length limit)"),
        Param("max_terrain_angle_deg", "TERRAIN_ANGLE", "Maximum terrain angle", "degrees", advanced=True,
              maximum=90.0, minimum=0.1),
        Param("offset_m", "OFFSET", "Offset: points this close to the final TIN are ground", "m, 0 = off",
              advanced=True),
        Param("mirror", "MIRROR", "Mirror points (Axelsson)", advanced=True),
        Param("low_outlier_check", "LOW_OUTLIERS", "Reject low outliers as seeds", advanced=True,
              help="a seed cell's lowest point that the cells around it do not support is no seed, so that a "
                   "point below the ground does not pull the TIN down"),
        Param("low_outlier_support", "LOW_OUTLIER_SUPPORT",
              "Low-outlier test: share of the cells around that must support a seed", advanced=True,
              minimum=0.01, maximum=1.0),
    )),
    "csf": ("csf", "CSF", (
        Param("cloth_resolution_m", "RESOLUTION", "Cloth resolution", "m", minimum=0.01),
        Param("rigidness", "RIGIDNESS", "Rigidness (scene)", choices=(1, 2, 3),
              choice_labels=("1: steep slope", "2: relief", "3: flat")),
        Param("time_step", "TIME_STEP", "Time step", minimum=0.01,
              help="the simulation's time step (0.65): gravity moves the cloth by 0.2 x its fourth power per "
                   "iteration, as the reference library 1.1.7 does"),
        Param("class_threshold_m", "CLASS_THRESHOLD", "Class threshold", "m", minimum=0.001),
        Param("iterations", "ITERATIONS", "Maximum iterations", minimum=1),
        Param("slope_smooth", "SLOPE_SMOOTH", "Slope post-processing (for steep slopes)"),
        Param("low_outlier_m", "LOW_OUTLIER", "Low-outlier threshold", "m, 0 = off", advanced=True,
              help="a point this far below the ground around it (the lowest points of the 5 m cells around its "
                   "own) is not ground and the cloth does not see it (5 m; the reference library has no such step)"),
        Param("intersection_height", "INTERSECTION_HEIGHT", "Particle heights from", choices=("nearest", "cell"),
              choice_labels=("nearest point (paper)",
                             "points of the particle's cell, scan-line fill (reference library)"), advanced=True),
        Param("sweep_order", "SWEEP_ORDER", "Sweep order", choices=("rotating", "fixed"),
              choice_labels=("rotating: 8 orders in turn (less orientation-dependent)",
                             "fixed: the reference library's"), advanced=True),
        Param("constraint_scheme", "CONSTRAINT_SCHEME", "Cloth constraints", choices=("library", "2016"),
              choice_labels=("reference library 1.1.7",
                             "authors' 2016 code (the paper's ISPRS figures; orientation-dependent)"), advanced=True),
    )),
    "echogrid": ("echogrid", "EchoGrid", (
        Param("kernel_m", "KERNEL", "Kernel size", "m", minimum=0.01,
              help="the side of the square kernels that tile the cloud (5 m, the paper's)"),
        Param("dz_m", "DZ", "Height above the kernel's lowest point", "m",
              help="points higher than the kernel's lowest point + this are non-ground (2 m, the paper's)"),
        Param("mode", "MODE", "Mode", choices=("faithful", "evidence"),
              choice_labels=("faithful (paper: single-return kernels are ground)",
                             "evidence (echoes as evidence, not as a bypass)")),
        Param("neighbourhood_m", "NEIGHBOURHOOD", "Evidence mode: neighbourhood for raised kernels", "m",
              advanced=True, help="a kernel whose lowest point lies more than the height above the lowest points "
                                  "of the kernels within this distance is raised (a roof): half the largest "
                                  "building's width finds the middle of wide roofs"),
        Param("slope", "SLOPE", "Evidence mode: terrain slope between kernels", "rise/run", advanced=True,
              help="the neighbours' lowest points are raised by this x their distance before the comparison, so "
                   "that sloping ground is not taken for a raised kernel"),
    )),
    "evc": ("evc", "EVC", (
        Param("small_scale_m", "SMALL_SCALE", "Small-scale grid", "m", minimum=0.01,
              help="the cell of the fine mean-elevation grid, whose class each point takes (0.2 m)"),
        Param("large_scale_m", "LARGE_SCALE", "Large-scale grid", "m", minimum=0.01,
              help="the cell of the coarse mean-elevation grid the fine one is compared with (2 m; 3.2 m was the "
                   "paper's other optimum)"),
        Param("radius", "RADIUS", "Neighbourhood radius", "cells", minimum=1,
              help="the square window of the EVC around each small cell (1 = 3 x 3 cells)"),
        Param("threshold", "THRESHOLD", "Threshold (EVC)", minimum=0.001,
              help="ground where 0 < EVC <= this, vegetation area where EVC <= 0, vegetation boundary above it "
                   "(1.5; the paper's Table 2)"),
        Param("auto_threshold", "AUTO_THRESHOLD", "Threshold by natural breaks (Jenks)",
              help="the threshold from the EVC values themselves, as the paper picked it, instead of the one set"),
        Param("difference", "DIFFERENCE", "Difference", choices=("large_minus_small", "small_minus_large"),
              choice_labels=("large minus small (paper's sign)", "small minus large"), advanced=True),
        Param("ground_offset_m", "GROUND_OFFSET", "Ground offset added to the mean difference", "m", advanced=True,
              help="added to the mean difference before the ratio, which is unstable on open ground (0 = the "
                   "paper; the ground's roughness, e.g. 0.1 m, keeps open ground ground)"),
        Param("point_tolerance_m", "POINT_TOLERANCE", "Point tolerance around the ground cells", "m", advanced=True,
              help="a point of a ground cell is ground only within this height of the median of the ground cells' "
                   "mean elevations in its window, so that a blunder floating above or sunk below the surface is not "
                   "(0 = the paper: every point takes its cell's class; e.g. 0.3 m)"),
        Param("min_cells", "MIN_CELLS", "Minimum non-empty cells in a window", minimum=2, advanced=True,
              help="a window holding fewer non-empty small cells grows one cell at a time (3)"),
        Param("max_radius", "MAX_RADIUS", "Maximum radius when growing a window", "cells", minimum=1,
              advanced=True, help="a window grows at most to this radius; equal to the neighbourhood radius, it "
                                  "keeps the paper's fixed window (5)"),
    )),
}


#: one line per filter (the README's table)
SUMMARY = {
    "smrf": "Simple Morphological Filter (Pingel, Clarke & McBride 2013)",
    "pmf": "progressive morphological filter (Zhang et al. 2003; PDAL's defaults)",
    "ptd": "progressive TIN densification (Axelsson 2000)",
    "csf": "cloth simulation (Zhang et al. 2016; the reference implementation's parameters)",
    "echogrid": "return-number grid (Matrone et al. 2024, Method 2)",
    "evc": "multiscale elevation variation coefficient (Fan et al. 2023; UAV photogrammetry)",
}


def known_filter(name) -> str:
    """``name`` if it names a filter of FILTERS, else InvalidParameterError (a script's "SMRF" was a KeyError)."""
    if name not in FILTERS:
        from ..errors import InvalidParameterError
        hint = f" (names are in lower case: {str(name).lower()!r})" if str(name).lower() in FILTERS else ""
        raise InvalidParameterError(f"unknown filter {name!r}{hint} (one of {', '.join(FILTERS)})")
    return name


def filter_class(name: str):
    module, cls, _params = FILTERS[known_filter(name)]
    return getattr(importlib.import_module(f"..filters.{module}", __package__), cls)


#: fields a run sets and no user does: ``metres_per_unit`` (the coordinates' unit, from the cloud's CRS:
#: workflow.defaults_in_crs_unit). Offered as --metres-per-unit and a preset's METRES_PER_UNIT, it only
#: scaled the hidden constants and made CSF worse on a cloud in metres or in feet without a CRS (a code
#: reviewer): it is in no dialog, command line or preset.
RUN_FIELDS = ("metres_per_unit",)


def filter_fields(name: str) -> List[dataclasses.Field]:
    """The filter dataclass's init fields a user may set, in their order (not RUN_FIELDS)."""
    return [f for f in dataclasses.fields(filter_class(name)) if f.init and f.name not in RUN_FIELDS]


def params(name: str) -> Sequence[Param]:
    return FILTERS[known_filter(name)][2]


def default(name: str, field: str):
    """The filter dataclass's default of ``field`` (the one definition of it)."""
    for f in filter_fields(name):
        if f.name == field:
            return f.default
    from ..errors import InvalidParameterError
    raise InvalidParameterError(f"{FILTERS[name][1]} has no parameter {field!r} (its parameters: "
                                f"{', '.join(f.name for f in filter_fields(name))})")


def core_only_fields(name: str) -> List[dataclasses.Field]:
    """Fields of the filter the Processing dialog does not show (the command line does)."""
    shown = {p.field for p in params(name)}
    return [f for f in filter_fields(name) if f.name not in shown]


def field_type(name: str, field: str):
    """bool, int, float or str, from the field's default."""
    value = default(name, field)
    return type(value) if isinstance(value, (bool, int, float, str)) else str


@functools.lru_cache(maxsize=None)
def source_defaults(name: str) -> Dict[str, object]:
    """The filter dataclass's defaults read from its source (``field: type = value`` lines of its
    class), without importing it: the Processing dialog is built where numpy or numba may be
    missing (the plugin then loads and says what to install). tests check them against the class."""
    module, cls, _params = FILTERS[name]
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "filters", module + ".py")
    with open(path, encoding="utf-8") as f:
        tree = ast.parse(f.read())
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == cls:
            return {stmt.target.id: ast.literal_eval(stmt.value) for stmt in node.body
                    if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and stmt.value is not None
                    and stmt.target.id not in RUN_FIELDS}
    raise KeyError(f"no class {cls} in {path}")


#: What ``groundsieve:tune`` searches, per filter: a parameter's Processing name -> its range
#: ``(low, high)`` (numbers; an int default makes it an integer) or a tuple of allowed values
#: (choices, on/off). The ranges span the values the papers used or studied, widened where a paper
#: gives one setting only: SMRF the span of Pingel's per-sample ISPRS optimum
#: (isprs_smrf_settings.txt: slope .05-.45, window 3-49 m, threshold .1-1.1 m, scalar 0-3.8); PMF
#: Zhang et al.'s and PDAL's (slope, windows to 50 m, distances); PTD Axelsson's angles and
#: distances and building sizes; CSF the cloth resolutions and class thresholds of Zhang et al.
#: 2016 and the three scene rigidnesses; EchoGrid around Matrone et al. 2024's one setting (5 m
#: kernel, 2 m: they give no grid); EVC around Fan et al. 2023's study (small 0.1-3.2 m, large to
#: 6.4 m, radius 1-6, threshold 1.0-2.0; here small 0.1-1 m, large 1-10 m, radius 1-3, threshold
#: 0.3-3.0, and our ground offset 0-0.3 m, 0 being the paper: a photogrammetry reviewer's cloud had 19.5 %
#: total error with the EVC preset, 15.3 % with an offset of 0.1 m, which tune did not search). Parameters
#: not listed keep the preset's / filter's value (e.g. the cell of 1 m).
SEARCH: Dict[str, Dict[str, tuple]] = {
    "smrf": {"SLOPE": (0.05, 0.45), "WINDOW": (3.0, 49.0), "THRESHOLD": (0.1, 1.1), "SCALAR": (0.0, 3.8)},
    "pmf": {"MAX_WINDOW": (5.0, 50.0), "SLOPE": (0.05, 1.5), "INITIAL_DISTANCE": (0.05, 1.0),
            "MAX_DISTANCE": (0.5, 5.0)},
    "ptd": {"SEED_CELL": (10.0, 60.0), "MAX_ANGLE": (4.0, 30.0), "MAX_DISTANCE": (0.5, 2.5)},
    "csf": {"RESOLUTION": (0.3, 3.0), "RIGIDNESS": (1, 2, 3), "CLASS_THRESHOLD": (0.2, 1.0)},
    "echogrid": {"KERNEL": (0.5, 8.0), "DZ": (0.1, 2.5)},
    "evc": {"SMALL_SCALE": (0.1, 1.0), "LARGE_SCALE": (1.0, 10.0), "RADIUS": (1, 2, 3), "THRESHOLD": (0.3, 3.0),
            "GROUND_OFFSET": (0.0, 0.3)},
}

#: Parameters that only change a filter's last step (the point test against its surface): the
#: search re-scores them on one filter run (engine/tune.py), so they cost no budget.
CHEAP: Dict[str, Tuple[str, ...]] = {"smrf": ("THRESHOLD", "SCALAR")}


def by_name(name: str) -> Dict[str, Param]:
    """The filter's dialog parameters by Processing name."""
    return {p.name: p for p in params(name)}


def preset_names(name: str) -> Dict[str, str]:
    """Every name a preset may give for the filter -> the dataclass field: the Processing names
    of the dialog's parameters and, for the core's finer settings, the field in upper case
    (``LOW_OUTLIER_MAX_SHARE``), as on the command line."""
    names = {p.name: p.field for p in params(name)}
    for f in core_only_fields(name):
        names.setdefault(f.name.upper(), f.name)
    return names


def mark_user_set(algorithm, fields):
    """``algorithm`` (a table filter) noting which of its fields the user set (a dialog value other than
    the default, an option typed on the command line): their lengths are in the cloud's CRS unit, while
    the others (defaults and a preset's values) are metres, converted for a cloud in feet
    (workflow.defaults_in_crs_unit). Kept on the object, not a field: it never changes what the filter
    computes, nor its equality."""
    object.__setattr__(algorithm, "user_set", frozenset(fields))
    return algorithm


def user_set(algorithm):
    """The fields :func:`mark_user_set` noted, or None when the filter was built otherwise (the Python
    API: then a field equal to its default is taken for the default)."""
    return getattr(algorithm, "user_set", None)
