"""The crafted model files of issue 14, one by one: each crashed, hung or gave a traceback before.
Each file is re-signed (a valid checksum), so only the checks of the arrays and trees stand
between it and the predictor; each must be refused with an InputError naming the file and the
problem. The predictor itself must also survive the same arrays when handed them directly,
without load_model's checks (run in a subprocess: a failure there is a crash)."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from groundsieve.core.errors import InputError
from groundsieve.core.learn import model_file

from .test_model_fuzz import PLUGINS, _arrays, _train, _write


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    path = tmp_path_factory.mktemp("model_cases") / "base.npz"
    model_file.save_model(_train("standard", 3, 7), str(path))
    return path


def _damaged(arrays):
    """name -> (change of the arrays and header, message expected). ``arrays`` is the base's."""
    left, right, roots = arrays["left"], arrays["right"], arrays["roots"]
    n = left.size
    r0 = int(roots[0])

    def setting(name, index, value):
        def change(a, h):
            a[name] = a[name].copy()
            a[name][index] = value
        return change

    def replacing(**new):
        def change(a, h):
            a.update(new)
        return change

    return {
        "root-out-of-range": (setting("roots", 0, n), r"'roots' holds \d+, outside 0\.\.\d+"),
        "value-wrong-width": (replacing(value=np.hstack([arrays["value"], np.zeros((n, 1))])),
                              r"'value' has shape \(\d+, 4\), expected \(\d+, 3\)"),
        "negative-child": (setting("left", r0, -7), r"'left' holds -7, outside -1\.\."),
        "cycle": (setting("left", int(left[r0]), r0) if left[int(left[r0])] != -1 else setting("right", r0, r0),
                  r"(child of two nodes|is also a child)"),
        "cycle-below-root": (_cycle_below_root(left), r"child of two nodes"),
        "zero-trees": (replacing(roots=roots[:0]), r"the forest has no tree"),
        "shared-node": (setting("left", r0, int(left[int(roots[1])])), r"child of two nodes"),
        "stray-cycle": (_stray_cycle(arrays), r"not reached from any tree's root"),
        "feature-out-of-range": (setting("feature", r0, 4), r"'feature' holds 4, outside 0\.\.3"),
        "threshold-nan": (setting("threshold", r0, np.nan), r"threshold is not a number"),
        "one-class": (replacing(classes=arrays["classes"][:1], value=arrays["value"][:, :1]),
                      r"knows 1 class\(es\)"),
        "header-list": (lambda a, h: h.update(_list=True), r"its header is a JSON list, not an object"),
        "scaler-arrays-missing": (lambda a, h: (a.pop("scaler_center"), a.pop("scaler_scale")),
                                  r"standard scaler's centre and scale arrays are missing"),
        "scaler-zero-scale": (setting("scaler_scale", 0, 0.0), r"'scaler_scale' holds a scale <= 0"),
        "array-missing": (lambda a, h: a.pop("right"), r"no right array"),
    }


def _cycle_below_root(left):
    """An inner node's left child sent back to that inner node's parent (two parents)."""
    def change(a, h):
        parent = np.full(left.size, -1)
        inner = np.flatnonzero(left != -1)
        parent[left[inner]] = inner
        grand = next(int(i) for i in inner if parent[i] != -1 and parent[parent[i]] != -1)
        a["left"] = a["left"].copy()
        a["left"][grand] = parent[grand]
    return change


def _stray_cycle(arrays):
    """Four extra nodes, reached from no root, where A and B are each other's child (A: B and C,
    B: A and D, C and D leaves): every node has one parent, so only reachability catches it."""
    def change(a, h):
        n = a["left"].size
        a["left"] = np.concatenate([a["left"], np.array([n + 1, n, -1, -1], dtype=a["left"].dtype)])
        a["right"] = np.concatenate([a["right"], np.array([n + 2, n + 3, -1, -1], dtype=a["right"].dtype)])
        leaf = int(np.flatnonzero(arrays["left"] == -1)[0])
        for name in ("feature", "threshold", "missing_left", "value"):
            a[name] = np.concatenate([a[name], a[name][[leaf] * 4]])
    return change


CASES = ["root-out-of-range", "value-wrong-width", "negative-child", "cycle", "cycle-below-root",
         "zero-trees", "shared-node", "stray-cycle", "feature-out-of-range", "threshold-nan", "one-class",
         "header-list", "scaler-arrays-missing", "scaler-zero-scale", "array-missing"]


@pytest.mark.parametrize("case", CASES)
def test_crafted_model_file_is_refused_naming_file_and_problem(base, tmp_path, case):
    arrays, header = _arrays(base)
    change, expected = _damaged(arrays)[case]
    change(arrays, header)
    if header.pop("_list", False):
        header = [header]
    path = tmp_path / f"{case}.npz"
    _write(path, arrays, header)
    with pytest.raises(InputError, match=expected) as err:
        model_file.load_model(str(path))
    assert str(path) in str(err.value)
    assert "Traceback" not in str(err.value)


def test_the_stray_cycle_passes_the_one_parent_check(base):
    """So that the stray-cycle case above shows the reachability check at work."""
    arrays, header = _arrays(base)
    _damaged(arrays)["stray-cycle"][0](arrays, header)
    inner = arrays["left"] != -1
    children = np.concatenate([arrays["left"][inner], arrays["right"][inner]])
    assert np.bincount(children).max() == 1
    assert not np.isin(arrays["roots"], children).any()


PREDICTOR_SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    from groundsieve.core.errors import InputError
    from groundsieve.core.learn.rf import Model, Scaler
    # a stump: node 0 splits feature 0 at 0.0 into leaves 1 and 2
    base = dict(classes=np.array([1, 2], np.uint8), roots=np.array([0], np.int64),
                left=np.array([1, -1, -1], np.int32), right=np.array([2, -1, -1], np.int32),
                feature=np.array([0, 0, 0], np.int16), threshold=np.array([0.0, -2, -2]),
                missing_left=np.array([1, 0, 0], np.uint8),
                value=np.array([[0.5, 0.5], [1.0, 0.0], [0.0, 1.0]]))
    cases = {
        "intact": {},
        "root-out-of-range": dict(roots=np.array([10 ** 9], np.int64)),
        "root-negative": dict(roots=np.array([-5], np.int64)),
        "value-wrong-width": dict(value=np.zeros((3, 5))),
        "value-too-few-rows": dict(value=np.zeros((1, 2))),
        "negative-child": dict(left=np.array([-7, -1, -1], np.int32)),
        "child-out-of-range": dict(right=np.array([2 ** 30, -1, -1], np.int32)),
        "cycle": dict(left=np.array([0, -1, -1], np.int32), right=np.array([0, -1, -1], np.int32)),
        "zero-trees": dict(roots=np.array([], np.int64)),
        "feature-out-of-range": dict(feature=np.array([9, 0, 0], np.int16)),
        "short-right": dict(right=np.array([2], np.int32)),
    }
    X = np.array([[-1.0], [1.0], [np.nan]] * 3000, dtype=np.float32)
    for name, change in cases.items():
        arrays = dict(base, **change)
        model = Model(["f0"], scaler=Scaler(), meta={}, **arrays)
        try:
            p = model.predict_proba(X)
            print(name, "OK", p[:3].tolist(), flush=True)
        except InputError as err:
            print(name, "REFUSED", err, flush=True)
""")


def test_the_predictor_survives_malformed_arrays_without_the_file_checks(tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(PLUGINS), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", PREDICTOR_SCRIPT], capture_output=True, text=True,
                          timeout=240, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = {line.split()[0]: line.split()[1:] for line in proc.stdout.splitlines()}
    assert lines.pop("intact")[0] == "OK"
    assert "[[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]]" in proc.stdout  # the stump's answers
    assert set(lines) == {"root-out-of-range", "root-negative", "value-wrong-width", "value-too-few-rows",
                          "negative-child", "child-out-of-range", "cycle", "zero-trees",
                          "feature-out-of-range", "short-right"}
    for name, words in lines.items():
        assert words[0] == "REFUSED", (name, words)
