"""An object every tile job shares (core/engine/sent_once.py): pickled once into the working folder,
sent as a reference, loaded once per process."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from groundsieve.core.engine import sent_once
from groundsieve.core.engine.sent_once import Reference, SentOnce, resolve
from groundsieve.core.errors import GroundSieveError


def test_a_large_object_pickles_as_a_small_reference_and_loads_once_per_process(tmp_path, monkeypatch):
    monkeypatch.setattr(sent_once, "_LOADED", type(sent_once._LOADED)())
    big = {"forest": np.arange(2_000_000, dtype=np.float64)}  # 16 MB
    shared = SentOnce(big, str(tmp_path / "algorithm.pickle"))
    assert resolve(shared) is big  # (in this process: the object itself)
    job = pickle.dumps({"algorithm": shared, "key": (0, 0)})
    assert len(job) < 1_000 < shared.nbytes
    first = resolve(pickle.loads(job)["algorithm"])
    assert first is not big and np.array_equal(first["forest"], big["forest"])
    (tmp_path / "algorithm.pickle").unlink()  # a second job's reference is not read from the file again
    assert resolve(pickle.loads(job)["algorithm"]) is first
    assert resolve(7) == 7


def test_an_unreadable_or_changed_file_is_named(tmp_path, monkeypatch):
    monkeypatch.setattr(sent_once, "_LOADED", type(sent_once._LOADED)())
    path = tmp_path / "algorithm.pickle"
    shared = SentOnce([1, 2, 3], str(path))
    ref = pickle.loads(pickle.dumps(shared))
    path.write_bytes(pickle.dumps([1, 2, 4]))
    with pytest.raises(GroundSieveError, match="algorithm.pickle: .* changed during the run"):
        ref.get()
    path.unlink()
    with pytest.raises(GroundSieveError, match="algorithm.pickle: .* cannot be read by this worker .* every worker"):
        Reference(str(path), shared.digest).get()


def test_a_process_keeps_the_last_few_objects_only(tmp_path, monkeypatch):
    monkeypatch.setattr(sent_once, "_LOADED", type(sent_once._LOADED)())
    refs = [pickle.loads(pickle.dumps(SentOnce(list(range(k)), str(tmp_path / f"a{k}.pickle")))) for k in range(4)]
    for ref in refs:
        ref.get()
    assert len(sent_once._LOADED) == sent_once.KEEP
