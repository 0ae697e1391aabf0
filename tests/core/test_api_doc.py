"""docs/API.md, the Python API for scripts and servers: every ```python example in it runs, in
order, in an empty folder, and the page names every filter and every exception of the core (so
neither the examples nor the list can drift from the code)."""
from __future__ import annotations

import contextlib
import inspect
import io
import re
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "API.md"


def python_blocks(text: str):
    """The ```python blocks of a Markdown text, in order."""
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.M | re.S)


def test_the_extraction_finds_the_blocks_and_only_them():
    text = "a\n```python\nx = 1\n```\n```sh\nls\n```\n```python\ny = 2\nz = 3\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = 2\nz = 3\n"]


def test_every_python_example_runs(tmp_path, monkeypatch):
    blocks = python_blocks(DOC.read_text(encoding="utf-8"))
    assert len(blocks) >= 10
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "api_doc"}
    printed = io.StringIO()
    for i, block in enumerate(blocks, 1):
        code = compile(block, f"docs/API.md, python block {i}", "exec")
        with contextlib.redirect_stdout(printed):
            try:
                exec(code, namespace)
            except Exception as err:  # which block, then the error itself
                pytest.fail(f"docs/API.md, python block {i} ({block.splitlines()[0]!r}): "
                            f"{type(err).__name__}: {err}\n{printed.getvalue()[-2000:]}")
    text = printed.getvalue()
    # what the examples say they show
    assert "stopped: cancelled by the user" in text
    assert "parameter: slope (rise/run) must be >= 0 (got -1)" in text
    assert "input: missing.laz: no such file or folder" in text
    assert (tmp_path / "out" / "classified" / "west.laz").exists() and (tmp_path / "out" / "dtm.tif").exists()
    assert (tmp_path / "model.npz").exists() and (tmp_path / "tuned-smrf.json").exists()
    # the job of one file of the survey: that file's copy and DTM, with the whole run's classes
    import laspy
    import numpy as np
    assert sorted(p.name for p in (tmp_path / "out" / "jobs").iterdir()) == ["east.laz"]
    assert (tmp_path / "out" / "jobs_dtm" / "east.tif").exists()
    assert np.array_equal(laspy.read(tmp_path / "out" / "jobs" / "east.laz").classification,
                          laspy.read(tmp_path / "out" / "classified" / "east.laz").classification)


def test_the_page_names_every_filter_and_every_error():
    from groundsieve.core import errors
    from groundsieve.core.engine import parameters as P
    text = DOC.read_text(encoding="utf-8")
    for name in P.FILTERS:
        cls = P.filter_class(name)
        assert f"from {cls.__module__} import {cls.__name__}" in text
    assert "from groundsieve.core.learn.hybrid import Hybrid" in text
    classes = [c for _n, c in inspect.getmembers(errors, inspect.isclass)
               if issubclass(c, errors.GroundSieveError)]
    assert len(classes) >= 7
    for cls in classes:
        assert f"| `{cls.__name__}`" in text, cls.__name__
