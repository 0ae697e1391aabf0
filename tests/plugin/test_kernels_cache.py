"""The first run after an install or upgrade compiles the numba kernels (15-20 s, the bar still):
the log says so once, when numba's cache holds none of them (algorithms/base.py)."""
import uuid

import pytest


def test_the_cache_state_is_read_where_numba_keeps_it(tmp_path, monkeypatch):
    """A module of one cached kernel: cold until it runs once, warm after, cold again when its
    __pycache__ is wiped (what an upgrade of the plugin's folder does)."""
    import importlib
    import shutil

    from groundsieve.algorithms import base
    name = f"gs_kernel_probe_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(
        "from numba import njit\n\n\n@njit(cache=True)\ndef twice(x):\n    return 2 * x\n\n\n"
        "@njit\ndef not_cached(x):\n    return x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module(name)
    assert base.kernel_cache_state([name]) == (0, 1)  # the kernel not cached on disk is not counted
    assert module.twice(3) == 6
    assert base.kernel_cache_state([name]) == (1, 1)
    shutil.rmtree(tmp_path / "__pycache__")
    assert base.kernel_cache_state([name]) == (0, 1)


def test_the_core_kernels_are_found():
    from groundsieve.algorithms import base
    modules = base.kernel_modules()
    for kernel in ("core.filters._smrf_kernels", "core.grids._delaunay", "core.grids._kernels",
                   "core.learn._features_kernels"):
        assert f"groundsieve.{kernel}" in modules
    assert not [m for m in modules if m.endswith((".workflow", ".smrf"))]  # only modules of cached kernels
    cached, total = base.kernel_cache_state()
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


@pytest.mark.parametrize("state, said", [((0, 127), True), ((3, 127), False), (None, False)])
def test_the_first_run_of_a_session_says_it_compiles_when_the_cache_is_empty(
        groundsieve_provider, scene_laz, tmp_path, monkeypatch, state, said):
    import processing
    from groundsieve.algorithms import base
    monkeypatch.setitem(base._SESSION, "kernels_checked", False)  # a new QGIS session
    checks = []
    monkeypatch.setattr(base, "kernel_cache_state", lambda modules=None: checks.append(1) or state)
    src, _scene = scene_laz
    runs = []
    for run in range(2):
        feedback = _Feedback()
        processing.run("groundsieve:smrf", {"INPUT": str(src), "OUTPUT": str(tmp_path / f"out{run}.laz"),
                                            "DTM": None}, feedback=feedback)
        runs.append([i for i in feedback.infos if i == base.COMPILING])
    assert runs == ([[base.COMPILING], []] if said else [[], []])  # the first run only
    assert len(checks) == 1  # checked once a session
