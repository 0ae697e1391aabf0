"""The first run of an algorithm after an install or upgrade compiles its numba kernels (20-60 s, the
bar still): the log says so once a session, until a run of it finished (remembered beside numba's cache), when numba's cache holds fewer than half of them
(algorithms/base.py, core/engine/kernels.py)."""
import uuid

import pytest


def test_the_cache_state_is_read_where_numba_keeps_it(tmp_path, monkeypatch):
    """A module of one cached kernel: cold until it runs once, warm after, cold again when its
    __pycache__ is wiped (what an upgrade of the plugin's folder does)."""
    import importlib
    import shutil

    from groundsieve.core.engine import kernels
    name = f"gs_kernel_probe_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(
        "from numba import njit\n\n\n@njit(cache=True)\ndef twice(x):\n    return 2 * x\n\n\n"
        "@njit\ndef not_cached(x):\n    return x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module(name)
    assert kernels.kernel_cache_state([name]) == (0, 1)  # the kernel not cached on disk is not counted
    assert module.twice(3) == 6
    assert kernels.kernel_cache_state([name]) == (1, 1)
    shutil.rmtree(tmp_path / "__pycache__")
    assert kernels.kernel_cache_state([name]) == (0, 1)


def test_the_core_kernels_are_found():
    from groundsieve.core.engine import kernels
    modules = kernels.kernel_modules()
    for kernel in ("core.filters._smrf_kernels", "core.grids._delaunay", "core.grids._kernels",
                   "core.learn._features_kernels"):
        assert f"groundsieve.{kernel}" in modules
    assert not [m for m in modules if m.endswith((".workflow", ".smrf"))]  # only modules of cached kernels
    cached, total = kernels.kernel_cache_state()
    assert total >= 50 and 0 <= cached <= total


class _Feedback:
    def __new__(cls):
        from qgis.core import QgsProcessingFeedback

        class Feedback(QgsProcessingFeedback):
            def __init__(self):
                super().__init__()
                self.infos = []

            def pushInfo(self, info):  # noqa: N802
                self.infos.append(info)
                super().pushInfo(info)
        return Feedback()


@pytest.mark.parametrize("state, said", [((0, 127), True), ((50, 127), True), ((100, 127), False), (None, False)])
def test_the_first_run_of_an_algorithm_in_a_session_says_it_compiles_when_the_cache_lacks_its_kernels(
        groundsieve_provider, scene_laz, tmp_path, monkeypatch, state, said):
    """Said when fewer than half of the algorithm's kernels (or of the grids') are cached: PTD compiled
    for 30 s with nothing said once SMRF had filled the cache (a release engineer)."""
    import processing
    from groundsieve.algorithms import base
    from groundsieve.core.engine import kernels
    monkeypatch.setitem(base._SESSION, "kernels_checked", set())  # a new QGIS session
    checks = []
    monkeypatch.setattr(kernels, "kernel_cache_state", lambda modules=None: checks.append(modules) or state)
    stamp = tmp_path / "runs.json"  # (no algorithm run yet with these kernels: a new install)
    monkeypatch.setattr(kernels, "_stamp_path", lambda: str(stamp))
    src, _scene = scene_laz
    runs = []
    for run, alg in enumerate(("smrf", "smrf", "pmf")):
        feedback = _Feedback()
        processing.run(f"groundsieve:{alg}", {"INPUT": str(src), "OUTPUT": str(tmp_path / f"out{run}.laz"),
                                              "DTM": None}, feedback=feedback)
        runs.append([i for i in feedback.infos if i == base.COMPILING])
    # the first run of each algorithm only
    assert runs == ([[base.COMPILING], [], [base.COMPILING]] if said else [[], [], []])
    own = [m for m in checks if m and any("filters._" in x for x in m)]
    assert [sorted({x.rsplit(".", 1)[1] for x in m}) for m in own] == [["_smrf_kernels"], ["_pmf_kernels"]]
    # its own, then the grids' unless its own already said it: once a session for each algorithm
    assert len(checks) == (2 if said else 4)
    # each finished run is remembered: the next session says nothing for them while their kernels stay cached
    import json
    assert json.loads(stamp.read_text())["ran"] == ["pmf", "smrf"]
    monkeypatch.setitem(base._SESSION, "kernels_checked", set())
    feedback = _Feedback()
    processing.run("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": str(tmp_path / "again.laz"), "DTM": None},
                   feedback=feedback)
    assert (base.COMPILING in feedback.infos) == (state is not None and state[0] == 0)
