"""Model files are data, not code: a crafted model file (edited arrays with a recomputed checksum,
as anyone can make) must either load and give valid predictions or be refused with the core's
InputError naming the file; never crash, hang or raise anything else (issue 14).

The mutations are applied to real small models trained here, re-signed with the module's own
digest, written as files and loaded then applied in a separate process (tests/robustness/
_model_worker.py) with a timeout, so that a segmentation fault or an endless loop fails the test
naming the mutation instead of taking pytest down."""
import itertools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from groundsieve.core.errors import InputError
from groundsieve.core.learn import model_file, rf

WORKER = Path(__file__).with_name("_model_worker.py")
PLUGINS = Path(__file__).resolve().parents[2] / ".build" / "plugins"
ARRAYS = ("classes", "roots", "left", "right", "feature", "threshold", "missing_left", "value")
SEED = 14
TIMEOUT_S = 240  # one batch of every mutation, numba compilation included


# -- models and files ----------------------------------------------------------------------------

def _train(scaler, n_trees, seed):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(600, 4)).astype(np.float32)
    y = np.where(X[:, 0] + 0.5 * X[:, 1] > 0, 2, np.where(X[:, 2] > 0, 1, 6)).astype(np.uint8)
    X[rng.random(X.shape) < 0.1] = np.nan  # missing values: missing_left varies, +inf thresholds
    return rf.train_forest(X, y, ["a", "b", "c", "d"],
                           rf.ForestParams(n_trees=n_trees, max_depth=5, scaler=scaler, seed=seed), n_jobs=1)


def _arrays(path):
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name].copy() for name in data.files}
    header = json.loads(bytes(arrays.pop("header")).decode())
    return arrays, header


def _write(path, arrays, header, resign=True):
    """``arrays`` and ``header`` (any JSON value) as a model file, with a valid checksum when the
    header is an object (computed by the module's own digest)."""
    if isinstance(header, dict) and resign:
        header = dict(header)
        header.pop("sha256", None)
        header["sha256"] = model_file._digest(arrays, header)
    out = dict(arrays, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
    with open(path, "wb") as handle:
        np.savez(handle, **out)  # object arrays are pickled here; the loader must refuse them


# -- mutations -----------------------------------------------------------------------------------

def _int_values(n, rng):
    return [-1, -2, 0, 1, n - 1, n, n + 1, 2 ** 15, -2 ** 15, 255, 256, 2 ** 31 - 1, -2 ** 31, 2 ** 62,
            int(rng.integers(-n, 2 * n))]


FLOATS = [np.nan, np.inf, -np.inf, 1e300, -1e300, -1.0, 0.0, 0.5, 1.0, 2.0, 1e-300, 3.4e38]


def _edit(a, rng, n_nodes):
    """``a`` with one to three elements set to an extreme, negative, NaN or random value."""
    a = a.copy()
    if a.size == 0:
        return a
    flat = a.reshape(-1)
    for _ in range(int(rng.integers(1, 4))):
        i = int(rng.integers(flat.size))
        if a.dtype.kind == "f":
            flat[i] = FLOATS[int(rng.integers(len(FLOATS)))] if rng.random() < 0.8 else rng.normal() * 10
        else:
            values = _int_values(n_nodes, rng)
            flat[i] = np.array(values[int(rng.integers(len(values)))], dtype=np.int64).astype(a.dtype)
    return a


def _dtype_changes(a):
    with np.errstate(invalid="ignore"):  # NaN or inf cast to integers: whatever comes out
        yield from _dtype_changes_(a)


def _dtype_changes_(a):
    yield "float32", a.astype(np.float32)
    yield "float64", a.astype(np.float64)
    yield "int8", a.astype(np.int8)
    yield "int16", a.astype(np.int16)
    yield "int64", a.astype(np.int64)
    yield "uint8", a.astype(np.uint8)
    yield "uint64", a.astype(np.uint64)
    yield "bool", a.astype(bool)
    yield "complex", a.astype(np.complex64)
    yield "text", a.astype("U8")
    yield "bigendian", a.astype(a.dtype.newbyteorder(">"))
    yield "object", a.astype(object)
    yield "2d", a.reshape(1, -1) if a.ndim == 1 else a.reshape(-1)
    yield "0d", np.array(a.reshape(-1)[0]) if a.size else np.array(0)
    yield "empty", a[:0]
    yield "structured", np.zeros(a.shape[0], dtype=[("x", "i4"), ("y", "f8")])


def _header_mutations(header):
    yield "list", [header]
    yield "string", "groundsieve-rf"
    yield "number", 1
    yield "null", None
    yield "nested", {"format": {"format": "groundsieve-rf"}}
    for key in ("format", "format_version", "features", "scaler", "params", "preset_features"):
        yield f"without-{key}", {k: v for k, v in header.items() if k != key}
    wrong = {
        "features": ["abcd", [1, 2, 3, 4], [], ["a", "a", "c", "d"], ["a", "b", "c"], ["a", "b", "c", "d", "e"],
                     ["", "b", "c", "d"], None, {"a": 1}, ["a", "b", "c", None], ["a"] * 40000],
        "scaler": ["minmax", 1, None, "none", "standard", "robust", ["none"]],
        "format_version": ["1", 1.0, True, 2, 0, None],
        "format": ["groundsieve-RF", None, 1],
        "preset_features": [5, "radiometry", [], [1], ["radiometry", 2], None],
        "params": [None, [], "x"],
        "impurity_importance": [None, "x", [1e308]],
    }
    for key, values in wrong.items():
        for i, value in enumerate(values):
            yield f"{key}={i}", dict(header, **{key: value})


def _structural(arrays):
    """Hand-made tree damage (random edits find most of it, these make sure)."""
    left, right, roots = arrays["left"], arrays["right"], arrays["roots"]
    inner = np.flatnonzero(left != -1)
    leaves = np.flatnonzero(left == -1)
    r0, r1 = int(roots[0]), int(roots[1])
    n = left.size

    def with_(**changes):
        return dict(arrays, **{k: np.asarray(v, dtype=arrays[k].dtype) for k, v in changes.items()})

    def setting(name, index, value):
        a = arrays[name].copy()
        a[index] = value
        return with_(**{name: a})

    yield "root-out-of-range", setting("roots", 0, n)
    yield "root-huge", setting("roots", 0, 2 ** 40)
    yield "root-negative", setting("roots", 0, -1)
    yield "roots-duplicate", setting("roots", 1, r0)
    yield "root-is-inner-node", setting("roots", 1, int(left[r0]))
    yield "zero-trees", with_(roots=roots[:0])
    yield "child-negative", setting("left", r0, -5)
    yield "child-out-of-range", setting("right", r0, n)
    yield "cycle-to-root", setting("left", int(inner[-1]), r0)
    yield "cycle-self", setting("right", r0, r0)
    child = int(left[r0])
    grandchild = int(left[child])
    if grandchild != -1:
        yield "cycle-deep", setting("left", grandchild, child)
    yield "shared-node-across-trees", setting("left", r0, int(left[r1]))
    yield "same-child-twice", setting("right", r0, int(left[r0]))
    yield "half-leaf", setting("left", int(leaves[0]), int(leaves[1]))
    yield "leaf-with-right-only", setting("right", int(leaves[0]), int(leaves[1]))
    yield "stray-node", with_(**{k: np.concatenate([arrays[k], arrays[k][-1:]]) for k in
                                 ("left", "right", "feature", "threshold", "missing_left", "value")})
    yield "feature-out-of-range", setting("feature", r0, 4)
    yield "feature-negative", setting("feature", r0, -1)
    yield "threshold-nan", setting("threshold", r0, np.nan)
    yield "threshold-inf", setting("threshold", r0, np.inf)  # legitimate: loads
    yield "value-wider", with_(value=np.hstack([arrays["value"], np.zeros((n, 1))]))
    yield "value-narrower", with_(value=arrays["value"][:, :-1])
    yield "value-negative", setting("value", (int(leaves[0]), 0), -0.5)
    yield "value-nan", setting("value", (int(leaves[0]), 0), np.nan)
    yield "classes-one", with_(classes=arrays["classes"][:1], value=arrays["value"][:, :1])
    yield "classes-duplicate", setting("classes", 1, int(arrays["classes"][0]))
    yield "classes-300", dict(arrays, classes=np.array([1, 2, 300], dtype=np.int64))
    yield "missing-left-2", setting("missing_left", r0, 2)
    yield "all-leaves", with_(left=np.full(n, -1), right=np.full(n, -1))
    yield "mirrored-trees", with_(left=right, right=left)  # a valid (different) forest: loads


def mutations(base, seed=SEED):
    """(name, arrays, header) of every mutation of the model file ``base``, deterministic."""
    arrays, header = _arrays(base)
    rng = np.random.default_rng(seed)
    n = arrays["left"].size
    names = [k for k in arrays]  # incl. the scaler's arrays when there are some
    for name in names:
        for k in range(28):
            yield f"edit-{name}-{k}", dict(arrays, **{name: _edit(arrays[name], rng, n)}), header
    for a, b in itertools.combinations(names, 2):
        yield f"swap-{a}-{b}", dict(arrays, **{a: arrays[b], b: arrays[a]}), header
    for name in names:
        a = arrays[name]
        fill = a[-1:] if a.size else a
        yield f"truncate1-{name}", dict(arrays, **{name: a[:-1]}), header
        yield f"truncatehalf-{name}", dict(arrays, **{name: a[: a.shape[0] // 2]}), header
        yield f"extend1-{name}", dict(arrays, **{name: np.concatenate([a, fill])}), header
        yield f"extendneg-{name}", dict(arrays, **{name: np.concatenate([a, -np.ones_like(fill)])}), header
        yield f"extend5-{name}", dict(arrays, **{name: np.concatenate([a] + [np.zeros_like(fill)] * 5)}), header
        for label, changed in _dtype_changes(a):
            yield f"dtype-{label}-{name}", dict(arrays, **{name: changed}), header
        yield f"without-{name}", {k: v for k, v in arrays.items() if k != name}, header
    yield "extra-array", dict(arrays, extra=np.arange(5)), header
    if "scaler_center" not in arrays:
        yield "scaler-arrays-added", dict(arrays, scaler_center=np.zeros(4), scaler_scale=np.ones(4)), header
    for label, changed in _header_mutations(header):
        yield f"header-{label}", arrays, changed
    for label, changed in _structural(arrays):
        yield f"tree-{label}", changed, header


# -- the fuzz test -------------------------------------------------------------------------------

def _run(paths, folder):
    """Status per file name from the worker, restarting after a crash or hang (each recorded as
    the failure of the mutation it was working on)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(PLUGINS), os.environ.get("PYTHONPATH", "")]))
    statuses, todo = {}, list(paths)
    for attempt in range(10):
        if not todo:
            break
        listing = folder / f"list{attempt}.txt"
        listing.write_text("\n".join(str(p) for p in todo))
        proc = None
        try:
            proc = subprocess.run([sys.executable, str(WORKER), str(listing)], capture_output=True,
                                  text=True, timeout=TIMEOUT_S, env=env)
            stdout, trouble = proc.stdout, f"the worker died (exit code {proc.returncode}): {proc.stderr[-500:]}"
        except subprocess.TimeoutExpired as err:
            stdout = err.stdout.decode() if isinstance(err.stdout, bytes) else (err.stdout or "")
            trouble = f"no answer within {TIMEOUT_S} s (a hang)"
        started = None
        for line in stdout.splitlines():
            fields = line.split("\t")
            if fields[0] == "START":
                started = fields[1]
            elif len(fields) >= 2:
                statuses[fields[1]] = (fields[0], fields[2] if len(fields) > 2 else "")
                started = None
        if started is not None:  # crashed or hung on this one
            statuses[started] = ("CRASH", trouble)
        rest = [p for p in todo if Path(p).name not in statuses]
        if rest and started is None and (proc is None or proc.returncode != 0):
            statuses[Path(rest[0]).name] = ("CRASH", trouble)  # died before starting any file
            rest = rest[1:]
        todo = rest
    return statuses


@pytest.fixture(scope="module")
def fuzz_results(tmp_path_factory):
    folder = tmp_path_factory.mktemp("model_fuzz")
    paths, kinds = [], {}
    for label, scaler, n_trees, seed in (("std", "standard", 4, 1), ("raw", "none", 3, 2)):
        base = folder / f"base-{label}.npz"
        model_file.save_model(_train(scaler, n_trees, seed), str(base))
        control = folder / f"{label}-unchanged.npz"
        arrays, header = _arrays(base)
        _write(control, arrays, header)
        paths.append(control)
        kinds[control.name] = "control"
        for name, arrays, header in mutations(base, SEED + seed):
            path = folder / f"{label}-{name}.npz"
            _write(path, arrays, header)
            paths.append(path)
            kinds[path.name] = name.split("-")[0]
    statuses = _run(paths, folder)
    return paths, kinds, statuses


def test_at_least_500_mutations_each_load_or_are_refused_never_crash(fuzz_results):
    paths, kinds, statuses = fuzz_results
    assert len(paths) >= 500
    missing = [p.name for p in paths if p.name not in statuses]
    assert not missing, f"no answer for {missing[:10]}"
    bad = {name: s for name, s in statuses.items() if s[0] not in ("OK", "REFUSED")}
    assert not bad, "\n".join(f"{name}: {status} {detail}" for name, (status, detail) in sorted(bad.items()))
    table = {}
    for name, (status, _) in statuses.items():
        table.setdefault(kinds[name], {"OK": 0, "REFUSED": 0})[status] += 1
    print("\nmodel fuzz:", len(paths), "files;", ", ".join(
        f"{kind}: {c['OK']} loaded, {c['REFUSED']} refused" for kind, c in sorted(table.items())))


def test_fuzz_is_not_vacuous(fuzz_results):
    """The unchanged files load, the harmless edits load, most damage is refused."""
    _, _, statuses = fuzz_results
    for name in ("std-unchanged.npz", "raw-unchanged.npz", "std-tree-threshold-inf.npz",
                 "std-tree-mirrored-trees.npz", "std-extra-array.npz"):
        assert statuses[name][0] == "OK", (name, statuses[name])
    refused = sum(s[0] == "REFUSED" for s in statuses.values())
    assert refused > 0.7 * len(statuses)
    for name in ("std-tree-cycle-to-root.npz", "std-tree-zero-trees.npz", "std-header-list.npz",
                 "std-without-scaler_center.npz", "std-tree-stray-node.npz"):
        assert statuses[name][0] == "REFUSED", (name, statuses[name])


def test_a_crash_in_the_worker_is_caught_and_named(tmp_path):
    """The harness itself: a file that kills the worker is reported as a crash of that file, and
    the files after it are still tried."""
    good = tmp_path / "fine.npz"
    model_file.save_model(_train("none", 2, 3), str(good))
    poison = tmp_path / "poison.npz"
    poison.write_bytes(b"")
    env_hook = tmp_path / "sitecustomize.py"  # makes the worker abort on 'poison.npz'
    env_hook.write_text("import builtins, os\n_open = builtins.open\n"
                        "def _o(f, *a, **k):\n"
                        "    if str(f).endswith('poison.npz'):\n        os.abort()\n"
                        "    return _open(f, *a, **k)\nbuiltins.open = _o\n")
    old = os.environ.get("PYTHONPATH", "")
    os.environ["PYTHONPATH"] = os.pathsep.join([str(tmp_path), old])
    try:
        statuses = _run([poison, good], tmp_path)
    finally:
        os.environ["PYTHONPATH"] = old
    assert statuses["poison.npz"][0] == "CRASH"
    assert statuses["fine.npz"][0] == "OK"
