"""The learned hybrid filter (core/learn/hybrid.py) keeps the project's promise on a long run: the
progress moves in every stage and a cancel is honoured within about a second, the forest's
prediction over all the points included (core/learn/rf.py predicts in blocks between which it
checks; the blocks change nothing in the probabilities)."""
import time

import numpy as np
import pytest

from groundsieve.core.errors import Cancelled
from groundsieve.core.learn.hybrid import Hybrid, load_hybrid_model
from groundsieve.core.progress import Steps

#: The promise: a cancel stops the run within about a second.
CANCEL_BOUND_S = 1.0


class Recorder:
    """``progress`` and ``is_cancelled`` for a run: the time of every cancel check and every
    progress value; ``is_cancelled`` turns True ``cancel_after_s`` after the recorder is made."""

    def __init__(self, cancel_after_s=None):
        self.checks = []
        self.values = []
        self.flip = None if cancel_after_s is None else time.perf_counter() + cancel_after_s

    def progress(self, value):
        self.values.append(value)

    def is_cancelled(self):
        now = time.perf_counter()
        self.checks.append(now)
        return self.flip is not None and now >= self.flip

    def steps(self):
        return Steps(self.progress, self.is_cancelled)


@pytest.fixture(scope="module")
def cloud():
    """2 M points at 10 per m² (runs of about 0.6 s with the fast model on two cores; the accurate
    model, about three times slower, gets every other point)."""
    from groundsieve.core.synthetic import SceneSpec, make_scene
    scene = make_scene(SceneSpec.for_points(2_000_000, density_per_m2=10, seed=0))
    return np.column_stack([scene.x, scene.y, scene.z])


def test_prediction_in_blocks_reports_progress_honours_cancel_and_changes_nothing():
    """The forest's prediction over 300 000 rows goes in blocks: a cancel check and a rising
    progress between them, and the probabilities of one kernel call over all the rows, bit for bit."""
    from groundsieve.core.learn._rf_kernels import _forest_proba_kernel
    model = load_hybrid_model("")
    X = np.random.default_rng(0).normal(0, 3, size=(300_000, len(model.features))).astype(np.float32)
    X[::97, 1] = np.nan  # blocks with and without missing values
    whole = np.empty((len(X), model.classes.size))
    assert _forest_proba_kernel(X, model.roots, model.left, model.right, model.feature, model.threshold,
                                model.missing_left, model.value, whole)
    rec = Recorder()
    proba = model.predict_proba(X, steps=rec.steps())
    assert proba.tobytes() == whole.tobytes()
    assert len(rec.checks) >= 2 and len(rec.values) >= 2
    assert all(b > a for a, b in zip(rec.values, rec.values[1:])) and rec.values[-1] == 1.0
    asked = []
    with pytest.raises(Cancelled):  # cancelled after the first block
        model.predict_proba(X, steps=Steps(is_cancelled=lambda: asked.append(1) or True))
    assert len(asked) == 1
    assert model.predict_proba(X[:0], steps=rec.steps()).shape == (0, model.classes.size)


@pytest.mark.parametrize("shipped", ["fast", "accurate"])
def test_the_hybrid_checks_cancel_often_and_stops_soon_after_a_cancel(cloud, shipped):
    """A whole run: the progress never goes back and reaches 1, and no stretch without a cancel
    check lasts a second or a quarter of the run (before the prediction checked, it was 60 % of
    the fast model's run, on clouds of any size). Then runs cancelled at five moments stop within
    a second of the cancel (a run that ends before its moment, on a busy machine, is not counted;
    three of the five must be cancelled)."""
    hybrid = Hybrid(shipped_model=shipped)
    cloud = cloud if shipped == "fast" else cloud[::2]
    hybrid(cloud)  # a whole run first: every kernel compiled or loaded from the cache, the memory touched
    measured = []
    for _ in range(2):  # the better of two runs: a stretch the code makes shows in both, a pause of a
        rec = Recorder()  # busy machine in one (a CI run saw 0.41 s once where 0.1 s is the rule)
        start = time.perf_counter()
        hybrid.run(cloud, rec.steps())
        run_s = time.perf_counter() - start
        assert all(b >= a for a, b in zip(rec.values, rec.values[1:])) and rec.values[-1] == 1.0
        assert len(set(rec.values)) >= 20
        times = [start] + rec.checks + [start + run_s]
        measured.append((max(b - a for a, b in zip(times, times[1:])), run_s))
    gap, run_s = min(measured)
    # (a quarter of the run, but not below 0.2 s: on a quiet machine the fast run took 0.40 s and its longest
    # stretch 0.1004 s, a hair over a quarter, in a fresh-clone CI run; the fault this catches was 0.49 s of 0.86)
    assert gap < min(CANCEL_BOUND_S, max(run_s / 4, 0.2)), measured
    fastest = min(r for _, r in measured)  # the moments as shares of the faster run: a run slowed by a busy
    cancelled = 0  # machine set them late, and later runs ended before them (2 of 5 cancelled once)
    for share in (0.1, 0.25, 0.4, 0.55, 0.7):
        rec = Recorder(cancel_after_s=share * fastest)
        try:
            hybrid.run(cloud, rec.steps())
        except Cancelled:
            cancelled += 1
        late = time.perf_counter() - rec.flip  # < 0: the run ended before the cancel
        print(f"{shipped}: run {run_s:.2f} s, longest stretch without a check {gap:.3f} s, "
              f"cancelled at {share:.0%}: {late:.3f} s later")
        assert late < CANCEL_BOUND_S, (share, late)
    assert cancelled >= 3
