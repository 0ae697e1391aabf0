"""Where the shared test data lives, and what a test does when it is absent.

The public point clouds (ISPRS samples, ...) are not in the repository: they sit
in ``<repo>/../shared/data`` (see ``SOURCES.md`` there). A test that needs them
calls :func:`shared_data_dir` with the files it reads. When something is
missing the test is skipped with the reason, except on CI (environment variable
``CI=true``), where a missing data set is a failure: CI must not go green by
silently skipping the accuracy checks.

Import it as ``from groundsieve.tests.shared_data import shared_data_dir``
(``.build/plugins`` on the path makes the checkout the ``groundsieve`` package,
whatever its folder is called). ``GROUNDSIEVE_SHARED_DATA`` overrides the folder.
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest

#: <repo>/../shared/data, the repository being this file's grandparent.
DEFAULT_SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def on_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def shared_data_dir(*required: str) -> Path:
    """The shared data folder, after checking that it holds every path in ``required``
    (relative to it). Skips the calling test when something is missing, or fails
    it when ``CI=true``."""
    root = Path(os.environ.get("GROUNDSIEVE_SHARED_DATA") or DEFAULT_SHARED_DATA)
    if not root.is_dir():
        missing = [str(root)]
    else:
        missing = [str(root / rel) for rel in required if not (root / rel).exists()]
    if missing:
        reason = ("shared test data not found: " + ", ".join(missing)
                  + " (expected the data folder at <repo>/../shared/data, or set GROUNDSIEVE_SHARED_DATA)")
        if on_ci():
            pytest.fail("CI=true and " + reason, pytrace=False)
        pytest.skip(reason)
    return root
