"""The shared parameter and point checks (core/validate.py) that every filter and learner uses."""
from dataclasses import dataclass

import numpy as np
import pytest

from groundsieve.core.errors import GroundSieveError, InputError, InvalidParameterError
from groundsieve.core.validate import check_choice, check_number, validate_xyz


@dataclass
class Params:
    value: object = 1.0
    mode: object = "a"


@pytest.mark.parametrize("value", [0, 1, -2.5, np.float32(3.0), np.int64(7), float("nan")])
def test_check_number_accepts_numbers(value):
    check_number(Params(value=value), "value")  # NaN is a number: range checks are the filter's


@pytest.mark.parametrize("value", [None, "1", True, False, [1.0], object()])
def test_check_number_refuses_what_is_not_a_number_and_names_the_parameter(value):
    with pytest.raises(InvalidParameterError, match=r"^value must be a number"):
        check_number(Params(value=value), "value")


def test_check_choice():
    check_choice(Params(mode="b"), "mode", ("a", "b"))
    with pytest.raises(InvalidParameterError, match=r"mode must be one of a, b \(got 'c'\)"):
        check_choice(Params(mode="c"), "mode", ("a", "b"))


def test_validate_xyz_returns_contiguous_float64_and_leaves_the_input_alone():
    xyz = np.arange(12, dtype=np.float32).reshape(4, 3)[::-1]
    before = xyz.copy()
    out = validate_xyz(xyz)
    assert out.dtype == np.float64 and out.flags.c_contiguous
    np.testing.assert_array_equal(out, before)
    np.testing.assert_array_equal(xyz, before)


@pytest.mark.parametrize("xyz, message", [
    (np.zeros((3, 2)), r"expected an \(n, 3\) array"),
    (np.zeros(3), r"expected an \(n, 3\) array"),
    (np.zeros((0, 3)), "holds no points"),
    (np.array([[0.0, 0.0, np.nan], [1.0, 1.0, 1.0]]), "1 point\\(s\\) have NaN"),
    (np.array([[0.0, np.inf, 0.0]]), "NaN or infinite"),
    (np.array([[2e9, 0.0, 0.0]]), "beyond ±1e9 m"),
    (np.array([[0.0, 0.0, 0.0], [0.0, -np.inf, 0.0]]), "1 point\\(s\\) have NaN or infinite"),
    (np.array([[1.0, 2.0, 3.0], [0.0, -2e9, 0.0]]), "beyond ±1e9 m"),
    (np.vstack([np.ones((1000, 3)), [[np.nan, np.inf, 1.0]], [[1.0, 1.0, -np.inf]]]), "2 point\\(s\\) have NaN"),
])
def test_validate_xyz_refuses_bad_points_naming_what(xyz, message):
    with pytest.raises(InputError, match=message) as info:
        validate_xyz(xyz, what="tile 3")
    assert str(info.value).startswith("tile 3: ")
    assert isinstance(info.value, GroundSieveError)
