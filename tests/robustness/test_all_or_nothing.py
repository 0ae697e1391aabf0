"""Issue 14, items 2 and 3, in the core: a failed run leaves no output (not one of several, no
temporary), the input is unchanged, and the error names the file and the problem (no traceback:
an OSError becomes the core's OutputError)."""
from __future__ import annotations

import errno
import warnings

import numpy as np
import pytest

from groundsieve.core.engine import learning, workflow
from groundsieve.core.errors import InvalidParameterError, OutputError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.learn import rf

from .folders import everything_in, full_disk, read_only_folder, sha256


@pytest.fixture(scope="module")
def labelled(tmp_path_factory):
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    path = tmp_path_factory.mktemp("labelled") / "labelled.laz"
    scene = make_scene(SceneSpec(size_m=40.0, density_per_m2=4.0, seed=41))
    scene.classification[:] = np.where(scene.classification == 2, 2, 1)
    write_scene(scene, str(path))
    return path


OPTIONS = learning.TrainOptions(features=("intensity", "return_number"), params=rf.ForestParams(n_trees=3))


def test_rftrain_disk_full_during_the_report_leaves_no_model(labelled, tmp_path, monkeypatch):
    """The report's writer fails half-way with ENOSPC (monkeypatched: the disk fills up after the
    model is written): neither the model nor the report nor the CSV is left, nor any temporary."""
    from groundsieve.core.learn import report

    def full(path, *, csv_path=None, atomic=True, **_kwargs):
        with open(path, "w") as handle:
            handle.write("<html>half")
        raise OSError(errno.ENOSPC, "No space left on device", path)

    monkeypatch.setattr(report, "write_report", full)
    out = tmp_path / "out"
    out.mkdir()
    before = sha256(labelled)
    with pytest.raises(OutputError) as err:
        learning.train_file(str(labelled), str(out / "m.npz"), str(out / "r.html"), OPTIONS)
    message = str(err.value)
    assert f"{out / 'r.html'}" in message and "No space left on device" in message
    assert "nothing was written" in message
    assert everything_in(out) == []
    assert sha256(labelled) == before


def test_rftrain_on_a_really_full_disk(labelled, tmp_path):
    """The same on a real small tmpfs (root only): the model fits, the model and the report do not."""
    with full_disk(tmp_path, "24k") as out:
        before = sha256(labelled)
        with pytest.raises(OutputError) as err:
            learning.train_file(str(labelled), str(out / "m.npz"), str(out / "r.html"), OPTIONS)
        assert "No space left on device" in str(err.value) and str(out / "m.npz") in str(err.value)
        assert everything_in(out) == []
        assert sha256(labelled) == before


def test_rftrain_into_a_read_only_folder(labelled, tmp_path):
    with read_only_folder(tmp_path) as out:
        before = sha256(labelled)
        with pytest.raises(OutputError, match="cannot be written to") as err:
            learning.train_file(str(labelled), str(out / "m.npz"), str(out / "r.html"), OPTIONS)
        assert str(out / "m.npz") in str(err.value)
        assert everything_in(out) == []
        assert sha256(labelled) == before


@pytest.mark.parametrize("with_dtm", [False, True], ids=["cloud", "cloud+dtm"])
def test_smrf_into_a_read_only_folder(labelled, tmp_path, with_dtm):
    with read_only_folder(tmp_path) as out:
        before = sha256(labelled)
        with pytest.raises(OutputError, match="cannot be written to") as err:
            workflow.run_ground_filter(str(labelled), str(out / "c.laz"), SMRF(),
                                       dtm_path=str(out / "dtm.tif") if with_dtm else None)
        assert str(out / "c.laz") in str(err.value)
        assert everything_in(out) == []
        assert sha256(labelled) == before


def test_smrf_dtm_in_a_read_only_folder_writes_no_cloud(labelled, tmp_path):
    """The DTM's folder is refused before the work: the cloud's own (writable) folder stays empty."""
    cloud_folder = tmp_path / "cloud"
    cloud_folder.mkdir()
    with read_only_folder(tmp_path) as out:
        with pytest.raises(OutputError, match="cannot be written to") as err:
            workflow.run_ground_filter(str(labelled), str(cloud_folder / "c.laz"), SMRF(),
                                       dtm_path=str(out / "dtm.tif"))
        assert str(out / "dtm.tif") in str(err.value)
        assert everything_in(out) == [] and everything_in(cloud_folder) == []


@pytest.mark.parametrize("cell", [1e300, 1e8])
def test_a_dtm_cell_larger_than_any_map_is_refused(labelled, tmp_path, cell):
    with warnings.catch_warnings(record=True) as caught, pytest.raises(InvalidParameterError) as err:
        warnings.simplefilter("always")
        workflow.run_ground_filter(str(labelled), str(tmp_path / "c.laz"), SMRF(), dtm_path=str(tmp_path / "d.tif"),
                                   dtm=workflow.DTMOptions(cell_size_m=cell))
    assert "DTM cell size" in str(err.value) and "larger than" in str(err.value)
    assert not [w for w in caught if "overflow" in str(w.message)]
    assert everything_in(tmp_path) == []


@pytest.mark.parametrize("what", ["cloud", "dtm"])
def test_smrf_on_a_really_full_disk_names_the_output_and_the_reason(labelled, tmp_path, what):
    """On a small tmpfs (root only): the message named the hidden temporary (".o.laz.gs…part.laz")
    and said "[Errno 28] No space left on device", or, for the DTM, only GDAL's "TIFFAppendToStrip:
    Write error at scanline 128" (a reviewer). It names the output and says the disk is full."""
    from groundsieve.core.engine.workflow import DTMOptions
    with full_disk(tmp_path, "8k") as out:
        before = sha256(labelled)
        target = out / ("c.las" if what == "cloud" else "d.tif")
        with pytest.raises(OutputError) as err:
            workflow.run_ground_filter(str(labelled), str(target) if what == "cloud" else None, SMRF(),
                                       dtm_path=str(target) if what == "dtm" else None,
                                       dtm=DTMOptions(cell_size_m=0.25))
        message = str(err.value)
        assert message.startswith(f"{target}: cannot ") and "No space left on device" in message, message
        assert "[Errno" not in message and ".gs" not in message
        assert everything_in(out) == []
        assert sha256(labelled) == before
