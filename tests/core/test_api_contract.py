"""The Python API as a script or notebook uses it (a research software engineer's probes): paths as
pathlib.Path, a filter by its name, one exception family, and the same result fields and warnings
whether a run comes back whole (FilterRun) or tiled (TiledRun)."""
from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import pytest

from groundsieve.core.engine.presets import load_preset, write_preset
from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.tune import TuneOptions, tune
from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
from groundsieve.core.errors import GroundSieveError, InvalidParameterError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("api") / "scene.laz"
    write_scene(make_scene(SceneSpec(size_m=60.0, density_per_m2=2.0, seed=3)), str(path))
    return path


def _without_crs(src: Path, dst: Path) -> Path:
    las = laspy.read(str(src))
    out = laspy.LasData(laspy.LasHeader(point_format=las.header.point_format.id, version="1.2"))
    out.header.scales, out.header.offsets = las.header.scales, las.header.offsets
    out.x, out.y, out.z, out.classification = las.x, las.y, las.z, las.classification
    out.write(str(dst))
    return dst


@pytest.mark.parametrize("tiled", [False, True])
def test_whole_and_tiled_runs_answer_the_same_questions_with_paths_and_names(scene, tmp_path, tiled):
    src = _without_crs(scene, tmp_path / "nocrs.laz")
    options = FilterOptions(tiling=TileOptions(tile_size_m=30.0, workers=1)) if tiled else None
    run = run_ground_filter(src, tmp_path / "out.laz", "smrf", dtm_path=tmp_path / "dtm.tif", options=options)
    assert type(run).__name__ == ("TiledRun" if tiled else "FilterRun")
    assert run.point_count == laspy.open(str(src)).header.point_count and 0 < run.ground_count < run.point_count
    assert [Path(p).resolve() for p in run.outputs] == [(tmp_path / "out.laz").resolve()]
    assert Path(run.dtm_path).resolve() == (tmp_path / "dtm.tif").resolve() and (tmp_path / "dtm.tif").exists()
    assert any(w.startswith(f"{src}: no CRS in the file") for w in run.warnings), run.warnings
    assert not any(w.startswith("Warning") for w in run.warnings)


def test_a_filter_given_by_name_runs_with_its_defaults_and_bad_ones_are_refused_in_words(scene, tmp_path):
    by_name = run_ground_filter(scene, None, "smrf")
    by_object = run_ground_filter(str(scene), None, SMRF())
    assert np.array_equal(by_name.classification, by_object.classification)
    with pytest.raises(InvalidParameterError, match=r"unknown filter 'SMRF' \(names are in lower case: 'smrf'\)"):
        run_ground_filter(scene, None, "SMRF")
    with pytest.raises(InvalidParameterError, match="the filter must be a filter object"):
        run_ground_filter(scene, None, 3)
    with pytest.raises(InvalidParameterError, match="the output must be a path"):
        run_ground_filter(scene, 3.5, SMRF())


def test_presets_and_tuning_refuse_bad_names_as_groundsieve_errors_and_take_paths(scene, tmp_path):
    with pytest.raises(InvalidParameterError, match="unknown filter 'SMRF'"):
        load_preset("uav-lidar-smrf", "SMRF")
    with pytest.raises(InvalidParameterError, match="unknown filter 'nosuch'"):
        write_preset(str(tmp_path / "x.json"), "nosuch", {})
    with pytest.raises(InvalidParameterError, match="SMRF has no parameter 'nosuch'"):
        load_preset("uav-lidar-smrf", "smrf").build({"nosuch": 1})
    with pytest.raises(GroundSieveError, match="SMRF has no parameter 'nosuch'"):
        write_preset(str(tmp_path / "x.json"), "smrf", {"nosuch": 1})
    assert load_preset(Path(load_preset("uav-lidar-smrf").path), "smrf").filter == "smrf"
    result = tune(scene, "smrf", TuneOptions(budget=4, blocks=3))
    assert result.best is not None


def test_a_filter_class_given_for_an_instance_runs_with_its_defaults(scene):
    """SMRF for SMRF() was a TypeError traceback once the file was read (a code reviewer)."""
    assert np.array_equal(run_ground_filter(scene, None, SMRF).classification,
                          run_ground_filter(scene, None, SMRF()).classification)
