"""The checks every filter and learner applies to its parameters and its points, with the core's
errors: a number that is not a number, a choice that is not offered, an array of points that is
not ``(n, 3)`` finite float coordinates."""
from __future__ import annotations

import numpy as np

from .errors import InputError, InvalidParameterError


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise InvalidParameterError(message)


def check_number(params, name: str) -> None:
    """Refuse a parameter that is not a real number (None, text, ...) with the core's error."""
    value = getattr(params, name)
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InvalidParameterError(f"{name} must be a number (got {value!r})")


def check_choice(params, name: str, choices) -> None:
    """Refuse a parameter that is not one of ``choices`` with the core's error."""
    value = getattr(params, name)
    if value not in choices:
        raise InvalidParameterError(f"{name} must be one of {', '.join(choices)} (got {value!r})")


def check_coordinates(*columns: np.ndarray, what: str) -> None:
    """Refuse coordinates that are NaN, infinite or beyond ±1e9 m: ``columns`` are x, y and z (one
    value a point each) or one (n, 3) array. One min and one max a column, no temporaries (they are
    NaN when any value is, infinite when any is); the points are counted only when one is wrong."""
    ends = [float(f(c)) for c in columns for f in (np.min, np.max)]
    if not all(np.isfinite(ends)):
        finite = np.logical_and.reduce([np.isfinite(c).reshape(len(c), -1).all(axis=1) for c in columns])
        raise InputError(f"{what}: {int((~finite).sum())} point(s) have NaN or infinite coordinates")
    biggest = max(abs(v) for v in ends)
    if biggest > 1e9:
        raise InputError(f"{what}: coordinates beyond ±1e9 m (max |value| {biggest:.3g}); "
                         "the file's scale/offset or coordinate system is probably wrong")


def validate_xyz(xyz: np.ndarray, *, what: str = "point cloud") -> np.ndarray:
    """Return ``xyz`` as a contiguous float64 (n, 3) array; refuse empty or non-finite input."""
    xyz = np.asarray(xyz)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(f"{what}: expected an (n, 3) array of x, y, z (got shape {xyz.shape})")
    if xyz.shape[0] == 0:
        raise InputError(f"{what}: holds no points")
    xyz = np.ascontiguousarray(xyz, dtype=np.float64)
    check_coordinates(xyz, what=what)
    return xyz
