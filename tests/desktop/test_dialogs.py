"""The real QGIS desktop dialogs on a virtual display (tests/desktop/harness.py drives them):
SMRF, CSF and the learned hybrid on a generated cloud of over 5 M points. A click on Cancel while
the cloud is read, filtered, triangulated into the DTM or written stops the run within 1.5 s and
leaves no output and no temporary file, and the dialog stays responsive (the click lands when
due); over a whole run the progress bar never stands still for more than 10 % of the run's time
(or one second, whichever is longer: the whole run now takes about 5 s, and a stand-still under a
second is not one a user sees) and shows 100 % only once every output is on disk.

About 70 s on a quiet machine for the three filters (175 s for two at a load average of 10):
``make test-desktop``; ``make test`` runs it too. Skipped without Xvfb (``scripts/bootstrap``
installs it), except under ``CI=true``, where it fails."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from .display import virtual_display

REPO = Path(__file__).resolve().parents[2]
CACHE = REPO / ".build" / "desktop"
CLOUD = CACHE / "cloud5m.laz"
N_POINTS = 5_200_000
STOP_S = 1.5
STILL_SHARE = 0.10
STILL_FLOOR_S = 1.0



def big_cloud() -> Path:
    """The generated cloud (over 5 M points), made once into .build/desktop (about 10 s)."""
    if not CLOUD.exists():
        CACHE.mkdir(parents=True, exist_ok=True)
        from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
        scene = make_scene(SceneSpec.for_points(N_POINTS, seed=13))
        assert len(scene) >= 5_000_000
        write_scene(scene, str(CLOUD))
    return CLOUD


@pytest.fixture(scope="module")
def harness_results(tmp_path_factory):
    import shutil
    if shutil.which("Xvfb") is None:
        if os.environ.get("CI") == "true":
            pytest.fail("Xvfb is missing (scripts/bootstrap installs it)")
        pytest.skip("Xvfb is missing (scripts/bootstrap installs it)")
    cloud = big_cloud()
    work = tmp_path_factory.mktemp("desktop")
    with virtual_display() as env:
        env["QGIS_CUSTOM_CONFIG_PATH"] = str(work / "profile")
        done = subprocess.run([sys.executable, str(REPO / "tests" / "desktop" / "harness.py"), "--cloud", str(cloud),
                               "--work", str(work / "runs"), "--algs", "smrf,csf,hybrid"],
                              env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    results = json.loads(done.stdout.strip().splitlines()[-1])
    return {(r["alg"].split(":")[1], r.get("stage", "full")): r for r in results}


STAGES = ["reading", "filtering", "dtm", "writing"]
#: SMRF, CSF, and the learned hybrid (its forest's prediction once ran 1.4 s without a cancel check)
ALGS = ["smrf", "csf", "hybrid"]


@pytest.mark.parametrize("stage", STAGES)
@pytest.mark.parametrize("alg", ALGS)
def test_cancel_stops_within_a_second_and_a_half_leaving_nothing(harness_results, alg, stage):
    r = harness_results[(alg, stage)]
    assert r["clicked_in"] == stage, f"the click came too late for the {stage} stage: {r}"
    assert r["stop_s"] is not None, f"the run did not end after the click: {r}"
    # the dialog answered the click when it was due (a run holding Python's lock freezes it)
    assert r["click_late_s"] <= 0.5, f"{alg}: the dialog froze {r['click_late_s']:.2f} s during {stage}"
    assert r["stop_s"] <= STOP_S, f"{alg}: the run went on {r['stop_s']:.2f} s after Cancel during {stage}"
    assert r["left"] == [], f"{alg}: a run cancelled during {stage} left {r['left']}"


@pytest.mark.parametrize("alg", ALGS)
def test_progress_moves_steadily_and_shows_100_only_when_done(harness_results, alg):
    r = harness_results[(alg, "full")]
    assert r["ended"] and r["outputs"] == ["classified.laz", "dtm.tif"], r
    assert r["hundred_before_outputs"] == 0, f"{alg}: 100 % shown before every output was on disk"
    assert r["longest_still_s"] <= max(STILL_SHARE * r["seconds"], STILL_FLOOR_S), (
        f"{alg}: the bar stood still {r['longest_still_s']:.2f} s of a {r['seconds']:.1f} s run "
        f"({100 * r['still_share']:.0f} %): {r['trace']}")
