"""Outputs keep the input's precision, two outputs on one file are refused before any work, and
stale temporaries of a killed run are removed by the next run to the same output (issue 16)."""
from __future__ import annotations

import os
import subprocess
import sys

import laspy
import numpy as np
import pytest

from groundsieve.core.engine import learning
from groundsieve.core.engine.workflow import run_ground_filter
from groundsieve.core.errors import OutputError
from groundsieve.core.filters.evc import EVC
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.io import atomic_path, read_cloud
from groundsieve.core.io.clouds import decimals_scale
from groundsieve.core.io.outputs import remove_stale_temporaries

X0, Y0 = 512000.0, 5403000.0


def plane_las(path, *, scale=0.00025, offset=(511987.125, 5402993.5, -3.75), n=4000, seed=0):
    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = np.array([scale] * 3)
    header.offsets = np.array(offset)
    las = laspy.LasData(header)
    las.x = X0 + rng.uniform(0, 40, n)
    las.y = Y0 + rng.uniform(0, 40, n)
    las.z = rng.normal(0, 0.05, n)
    las.write(str(path))
    return las


def test_las_input_keeps_its_scales_offsets_and_integer_coordinates(tmp_path):
    src, out = tmp_path / "in.las", tmp_path / "out.laz"
    plane_las(src)
    run_ground_filter(str(src), str(out), SMRF())
    a, b = laspy.read(str(src)), laspy.read(str(out))
    np.testing.assert_array_equal(b.header.scales, a.header.scales)
    np.testing.assert_array_equal(b.header.offsets, a.header.offsets)
    for dim in "XYZ":
        np.testing.assert_array_equal(np.asarray(b[dim]), np.asarray(a[dim]))


@pytest.mark.parametrize("decimals, scale", [(3, 0.001), (2, 0.01), (1, 0.01), (4, 0.0001)])
def test_text_input_is_written_with_a_scale_fine_enough_for_its_decimals(tmp_path, decimals, scale):
    rng = np.random.default_rng(decimals)
    n = 3000
    xyz = np.column_stack([X0 + rng.uniform(0, 40, n), Y0 + rng.uniform(0, 40, n), 100 + rng.normal(0, 0.05, n)])
    xyz = np.round(xyz, decimals)
    src = tmp_path / "in.txt"
    np.savetxt(src, np.column_stack([xyz, np.zeros(n)]), fmt=f"%.{decimals}f %.{decimals}f %.{decimals}f %d")
    assert read_cloud(str(src)).scale == pytest.approx(scale)
    out = tmp_path / "out.las"
    run_ground_filter(str(src), str(out), SMRF())
    las = laspy.read(str(out))
    assert las.header.scales[0] == pytest.approx(scale)
    # Every coordinate comes back as written in the text, to the last decimal.
    back = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    np.testing.assert_allclose(back, xyz, rtol=0, atol=scale / 100)


def test_decimals_scale_stays_within_the_32_bit_records():
    # A 0.1 µm decimal over 5 km cannot be stored: the finest scale the span allows is kept.
    assert decimals_scale(np.array([0.1234567, 5000.0])) == pytest.approx(1e-5)
    assert decimals_scale(np.array([1.5, 2.0])) == pytest.approx(0.01)


def test_two_outputs_on_one_file_are_refused_before_any_work(tmp_path):
    src = tmp_path / "in.las"
    plane_las(src)
    same = tmp_path / "r.tif"
    with pytest.raises(OutputError, match=r"r.tif: chosen for two outputs \(DTM and raster 2\)"):
        run_ground_filter(str(src), str(tmp_path / "o.las"), EVC(), dtm_path=str(same),
                          rasters={str(same): lambda run: None})
    with pytest.raises(OutputError, match="chosen for two outputs"):
        learning.classify_file(str(src), str(tmp_path / "o.las"), str(tmp_path / "no-model.npz"),
                               dtm_path=str(tmp_path / "o.las"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.las"]


def test_a_later_run_removes_the_temporaries_of_a_killed_run(tmp_path):
    out = tmp_path / "out.las"
    # A run killed while writing: a child process that dies inside atomic_path.
    code = ("import os, sys; sys.path.insert(0, %r)\n"
            "from groundsieve.core.io import atomic_path\n"
            "with atomic_path(%r) as tmp:\n"
            "    open(tmp, 'wb').write(b'half')\n"
            "    os._exit(9)\n") % (os.path.dirname(os.path.dirname(os.path.abspath(
                __import__("groundsieve").__file__))), str(out))
    assert subprocess.run([sys.executable, "-c", code]).returncode == 9
    left = [p.name for p in tmp_path.iterdir()]
    assert len(left) == 1 and left[0].startswith(".out.las.gs") and left[0].endswith(".part.las")
    other = tmp_path / ".other.las.gs1-x.part.las"   # another output's: left alone
    other.write_bytes(b"")
    assert remove_stale_temporaries(str(out)) == [str(tmp_path / left[0])]
    # The temporary of a live writer (this process) is left alone.
    with atomic_path(str(out)) as mine:
        open(mine, "wb").close()
        assert remove_stale_temporaries(str(out)) == []
        assert os.path.exists(mine)
    src = tmp_path / "in.las"
    plane_las(src)
    # The next real run to the same output cleans up after a killed one.
    assert subprocess.run([sys.executable, "-c", code]).returncode == 9
    run_ground_filter(str(src), str(out), SMRF())
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([".other.las.gs1-x.part.las", "in.las", "out.las"])


def test_a_dtm_killed_while_gdal_wrote_it_leaves_nothing_the_next_run_keeps(tmp_path):
    """GDAL's COG writer keeps the overviews in "<its output>.ovr.tmp" until it ends, and a tiled
    run's DTM was written to a temporary inside its staged temporary: killed while writing, a run
    left "..dtm.tif.gs<pid>-x.part.tif.gs<pid>-y.part.tif" and its ".ovr.tmp", which the next run's
    clean-up did not match (an HPC reviewer). The DTM goes straight to the staged temporary now, and
    a dead process's ".ovr.tmp" goes with its temporary."""
    dtm = tmp_path / "dtm.tif"
    dead = 2 ** 22 + 12345  # no such process (above the default pid_max)
    left = tmp_path / f".dtm.tif.gs{dead}-abc.part.tif"
    for name in (left.name, left.name + ".ovr.tmp"):
        (tmp_path / name).write_bytes(b"half")
    assert sorted(remove_stale_temporaries(str(dtm))) == sorted([str(left), str(left) + ".ovr.tmp"])
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import DTMOptions, FilterOptions
    src = tmp_path / "in.las"
    plane_las(src)
    seen = []
    import groundsieve.core.raster.geotiff as geotiff
    original = geotiff.BlockGeoTIFF.finish

    def spy(self, path, **kw):
        seen.append((os.path.basename(path), kw))
        return original(self, path, **kw)
    geotiff.BlockGeoTIFF.finish = spy
    try:
        run_ground_filter(str(src), None, SMRF(), dtm_path=str(dtm), dtm=DTMOptions(),
                          options=FilterOptions(tiling=TileOptions(tile_size_m=20.0, workers=1)))
    finally:
        geotiff.BlockGeoTIFF.finish = original
    assert len(seen) == 1 and seen[0][0].startswith(".dtm.tif.gs")
    assert {k: v for k, v in seen[0][1].items() if k != "grid"} == {"atomic": False, "name": str(dtm)}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dtm.tif", "in.las"]


def test_a_failed_commit_puts_nothing_in_place_and_keeps_what_was_there(tmp_path):
    """A rename that failed while a run put its outputs in place (a reviewer's immutable classified
    file; on Windows, one open in QGIS) left the new DTM beside the old cloud: the commit is now all
    or none, what was there before moved aside and put back."""
    from groundsieve.core.io.outputs import StagedOutputs
    old = tmp_path / "a.tif"
    old.write_bytes(b"old dtm")
    blocked = tmp_path / "b.las"
    blocked.mkdir()  # a rename cannot replace a folder that holds a file: the commit's second step fails
    (blocked / "x").write_bytes(b"")
    with pytest.raises(OutputError, match=r"b\.las: cannot be written .*no output of the run was put in place"):
        with StagedOutputs() as staging:
            for path in (old, blocked):
                open(staging.stage(str(path)), "wb").write(b"new")
            staging.commit()
    assert old.read_bytes() == b"old dtm"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.tif", "b.las"]  # no temporary, no backup left
    with StagedOutputs() as staging:  # and when every rename works, every output is the new one
        open(staging.stage(str(old)), "wb").write(b"new dtm")
        open(staging.stage(str(tmp_path / "c.las")), "wb").write(b"new cloud")
        staging.commit()
    assert old.read_bytes() == b"new dtm" and (tmp_path / "c.las").read_bytes() == b"new cloud"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.tif", "b.las", "c.las"]


def test_long_output_names_work_and_one_too_long_is_said_before_the_work(tmp_path):
    """A legal 204-byte output name ran the whole job, then failed: its temporary (the name plus 27
    bytes) and the probe of a second check on that temporary were past the file system's 255 bytes,
    and the message blamed the folder (a reviewer)."""
    src = tmp_path / "in.las"
    plane_las(src)
    name = "a" * 200 + ".las"
    run_ground_filter(str(src), str(tmp_path / name), SMRF())
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["in.las", name])
    cjk = "\u6797" * 90 + ".las"  # 270 bytes of UTF-8
    seen = []
    with pytest.raises(OutputError, match=r"the file name is too long \(274 bytes; .* at most 255\)"):
        run_ground_filter(str(src), str(tmp_path / cjk), SMRF(), progress=seen.append)
    assert seen == []


def test_another_machines_temporary_is_removed_by_age_only(tmp_path):
    """On a shared drive a process id means nothing on another machine: a reviewer's run removed a
    live temporary of a writer elsewhere whose id was not running here. A temporary names its host."""
    import socket
    import time
    from groundsieve.core.io.outputs import _host
    out = tmp_path / "o.las"
    dead = 2 ** 22 + 12345
    elsewhere = tmp_path / f".o.las.gsotherhost.{dead}-abc.part.las"
    here = tmp_path / f".o.las.gs{_host()}.{dead}-def.part.las"
    for p in (elsewhere, here):
        p.write_bytes(b"half")
    assert remove_stale_temporaries(str(out)) == [str(here)]
    week = time.time() - 7 * 86400
    os.utime(elsewhere, (week, week))
    assert remove_stale_temporaries(str(out)) == [str(elsewhere)]
    with atomic_path(str(out)) as tmp:
        assert os.path.basename(tmp).startswith(f".o.las.gs{_host()}.{os.getpid()}-")
    assert socket.gethostname()


def test_an_interrupted_commit_puts_back_what_was_there_and_a_killed_ones_kept_file_is_restored(tmp_path,
                                                                                              monkeypatch):
    """A Ctrl-C or SIGTERM (python -m groundsieve makes them KeyboardInterrupt) between two renames
    skipped the rollback, and a kill left the previous output under a temporary's name, which the next
    run deleted (a code reviewer). The previous file is kept as a hard link, put back on any exception,
    and a kept file whose output is missing is put back by the next run."""
    import groundsieve.core.io.outputs as outputs
    from groundsieve.core.io.outputs import StagedOutputs, _host
    a, b = tmp_path / "a.tif", tmp_path / "b.las"
    a.write_bytes(b"old a")
    b.write_bytes(b"old b")
    real = os.replace
    calls = []

    def interrupted(src, dst):
        calls.append(dst)
        if str(dst) == str(b) and str(src).endswith(".part.las"):
            raise KeyboardInterrupt
        return real(src, dst)
    monkeypatch.setattr(outputs.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        with StagedOutputs() as staging:
            for path in (a, b):
                open(staging.stage(str(path)), "wb").write(b"new")
            staging.commit()
    monkeypatch.setattr(outputs.os, "replace", real)
    assert (a.read_bytes(), b.read_bytes()) == (b"old a", b"old b")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.tif", "b.las"]
    # a commit killed where the output was moved aside (no hard links): the next run puts it back
    dead = 2 ** 22 + 12345
    kept = tmp_path / f".c.las.gs{_host()}.{dead}-xyz.keep.las"
    kept.write_bytes(b"old c")
    assert remove_stale_temporaries(str(tmp_path / "c.las")) == [str(kept)]
    assert (tmp_path / "c.las").read_bytes() == b"old c" and not kept.exists()
    # where the output is there (the link kept it), the kept copy just goes
    kept.write_bytes(b"older c")
    assert remove_stale_temporaries(str(tmp_path / "c.las")) == [str(kept)]
    assert (tmp_path / "c.las").read_bytes() == b"old c"


def test_a_surveys_classified_copies_are_written_straight_to_their_staged_temporaries(tmp_path, monkeypatch):
    """A survey's classified copy went to a temporary inside its staged temporary; a killed run left
    "..t1.laz.gs…part.laz.gs…part.laz", which no later run removed, as large as the copy (a code reviewer)."""
    import groundsieve.core.io.lasfiles as lasfiles
    from groundsieve.core.engine.tiles import TileOptions
    from groundsieve.core.engine.workflow import FilterOptions
    src = tmp_path / "in.las"
    plane_las(src)
    seen = []
    real = lasfiles.atomic_path
    monkeypatch.setattr(lasfiles, "atomic_path", lambda path: seen.append(os.path.basename(path)) or real(path))
    run_ground_filter(str(src), str(tmp_path / "out.las"), SMRF(),
                      options=FilterOptions(tiling=TileOptions(tile_size_m=20.0, workers=1, parallel="threads")))
    assert [name for name in seen if name.startswith(".")] == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.las", "out.las"]


@pytest.mark.parametrize("when", ["after b's rename", "after b was moved aside, no hard links"])
def test_an_interrupt_at_either_side_of_a_rename_puts_back_what_was_there(tmp_path, monkeypatch, when):
    """An interrupt just after b's rename took b's new file for its old one and deleted the kept copy;
    one just after b was moved aside (no hard links: FAT, SMB) left b missing (a code reviewer)."""
    import groundsieve.core.io.outputs as outputs
    a, b = tmp_path / "a.laz", tmp_path / "b.laz"
    for p in (a, b):
        p.write_bytes(b"old " + p.name.encode())
    real = os.replace
    fired = []

    def replace(src, dst):  # one interrupt, right after the rename it follows
        real(src, dst)
        if not fired and ((str(dst) == str(b)) if when.startswith("after b's") else (str(src) == str(b))):
            fired.append(1)
            raise KeyboardInterrupt
    monkeypatch.setattr(outputs.os, "replace", replace)
    if "no hard links" in when:
        monkeypatch.setattr(outputs.os, "link", lambda *a, **k: (_ for _ in ()).throw(PermissionError(1, "no")))
    _commit_interrupted_keeps_the_old(tmp_path, a, b)


def test_long_names_sharing_their_first_bytes_do_not_share_temporaries(tmp_path):
    """Temporaries hold 100 bytes of their output's name: two outputs sharing those shared their
    temporaries, and one's clean-up deleted the other's kept previous file (a code reviewer)."""
    from groundsieve.core.io.outputs import _short
    one, two = "x" * 120 + "_001.laz", "x" * 120 + "_002.laz"
    assert _short(one) != _short(two) and len(_short(one).encode()) <= 100
    assert _short("short.laz") == "short.laz"
    dead = 2 ** 22 + 12345
    from groundsieve.core.io.outputs import _host
    kept = tmp_path / f".{_short(two)}.gs{_host()}.{dead}-abc.keep.laz"
    kept.write_bytes(b"old 002")
    assert remove_stale_temporaries(str(tmp_path / one)) == []
    assert remove_stale_temporaries(str(tmp_path / two)) == [str(kept)]
    assert (tmp_path / two).read_bytes() == b"old 002"


def test_a_second_interrupt_while_a_commit_is_undone_still_leaves_the_previous_outputs(tmp_path, monkeypatch):
    """Ctrl-C twice (or a scheduler's repeated SIGTERM): the second, during the undo, left one output new
    and the other old, the old copy in a kept file the next run deleted (a code reviewer)."""
    import groundsieve.core.io.outputs as outputs
    a, b = tmp_path / "a.laz", tmp_path / "b.laz"
    for p in (a, b):
        p.write_bytes(b"old " + p.name.encode())
    real = os.replace
    calls = []

    def replace(src, dst):
        real(src, dst)
        calls.append((str(src), str(dst)))
        renamed_in = [c for c in calls if c[1] in (str(a), str(b)) and ".part" in c[0]]
        put_back = [c for c in calls if c[1] in (str(a), str(b)) and ".keep" in c[0]]
        if len(renamed_in) == 2 and len(put_back) in (0, 1) and len(calls) in (2, 3):
            raise KeyboardInterrupt  # after b's rename, then again after the first undo step
    monkeypatch.setattr(outputs.os, "replace", replace)
    _commit_interrupted_keeps_the_old(tmp_path, a, b)


def _commit_interrupted_keeps_the_old(folder, a, b):
    """Commit new a and b (an interrupt injected by the caller): both are their old selves after, and
    nothing else is left in ``folder``."""
    from groundsieve.core.io.outputs import StagedOutputs
    with pytest.raises(KeyboardInterrupt):
        with StagedOutputs() as staging:
            for p in (a, b):
                open(staging.stage(str(p)), "wb").write(b"new")
            staging.commit()
    assert (a.read_bytes(), b.read_bytes()) == (b"old a.laz", b"old b.laz")
    assert sorted(p.name for p in folder.iterdir()) == ["a.laz", "b.laz"]
