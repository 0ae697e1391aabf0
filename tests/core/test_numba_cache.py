"""Where numba caches the kernels (core/__init__.py _numba_cache_folder)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import groundsieve

PLUGINS = os.path.dirname(os.path.dirname(os.path.abspath(groundsieve.__file__)))  # the folder holding the package


def test_kernels_import_for_a_user_who_can_write_neither_the_install_nor_a_home():
    """A root-owned install run by a service account with an unwritable HOME (cron, QGIS Server,
    docker --user) stopped with numba's "cannot cache function '_cell_of': no locator available"
    and a traceback (a release engineer). The cache then goes to <temp>/groundsieve-numba-<uid>."""
    if os.geteuid() != 0 or not shutil.which("setpriv"):
        pytest.skip("needs root and setpriv to run as another user (nobody)")
    if not os.access(PLUGINS, os.X_OK) or any(not os.stat(p).st_mode & 0o001 for p in Path(PLUGINS).parents
                                              if str(p) != "/"):
        pytest.skip(f"{PLUGINS} cannot be reached by another user")
    code = ("import os, groundsieve.core.grids._kernels as k\n"
            "print(os.environ.get('NUMBA_CACHE_DIR', ''))\n")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME")}
    env.update(HOME="/nonexistent", PYTHONPATH=PLUGINS)
    proc = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable, "-c", code],
                          capture_output=True, text=True, env=env, cwd="/", timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    folder = proc.stdout.strip()
    assert os.path.basename(folder).startswith("groundsieve-numba-"), proc.stdout
    st = os.stat(folder)
    assert st.st_uid == 65534 and not st.st_mode & 0o077  # nobody's own, no one else's to write


def test_an_empty_cache_is_said_before_a_run_and_the_command_line_says_it(tmp_path, monkeypatch):
    """The command line said nothing while the first run compiled (the bar at 21.5 % for 8 s), and the
    plugin's note was not given for an algorithm run first after another had filled the cache (PTD:
    30 s): core/engine/kernels.py tells each algorithm's kernels apart."""
    import io

    from groundsieve.core.engine import kernels
    from groundsieve.core.engine.cli import main
    code = ("from groundsieve.core.engine.kernels import about_to_compile, modules_for\n"
            "print(about_to_compile('ptd'), about_to_compile('smrf'), modules_for('ptd'))\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "empty"), PYTHONPATH=PLUGINS)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("True True ['groundsieve.core.filters._ptd_kernels'"), proc.stdout
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    src = tmp_path / "s.laz"
    write_scene(make_scene(SceneSpec(size_m=20.0, density_per_m2=2.0, seed=1)), str(src))
    for compiles in (True, False):
        monkeypatch.setattr(kernels, "about_to_compile", lambda name, c=compiles: c and name == "smrf")
        out = io.StringIO()
        assert main(["smrf", "--input", str(src), "--output", str(tmp_path / "o.laz")], out=out) == 0
        assert (kernels.COMPILING in out.getvalue()) == compiles


def test_a_numba_cache_dir_that_cannot_be_written_is_treated_as_none():
    """A NUMBA_CACHE_DIR compiled into a container's image or on a read-only share made every run fail
    with numba's "cannot cache function ...: no locator available" (a research software engineer):
    numba uses only a cache it may write. The cache then goes where it would without the variable."""
    if os.geteuid() != 0 or not shutil.which("setpriv"):
        pytest.skip("needs root and setpriv to run as another user (nobody)")
    if not os.access(PLUGINS, os.X_OK) or any(not os.stat(p).st_mode & 0o001 for p in Path(PLUGINS).parents
                                              if str(p) != "/"):
        pytest.skip(f"{PLUGINS} cannot be reached by another user")
    import tempfile
    readonly = tempfile.mkdtemp(prefix="gs-ro-cache-")
    try:
        os.chmod(readonly, 0o555)
        code = ("import os, groundsieve.core.grids._kernels as k\n"
                "import numpy as np\n"
                "print(os.environ.get('NUMBA_CACHE_DIR', ''))\n")
        env = {k: v for k, v in os.environ.items() if k not in ("XDG_CACHE_HOME",)}
        env.update(HOME="/nonexistent", PYTHONPATH=PLUGINS, NUMBA_CACHE_DIR=readonly)
        proc = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable, "-c",
                               code], capture_output=True, text=True, env=env, cwd="/", timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert os.path.basename(proc.stdout.strip()).startswith("groundsieve-numba-"), proc.stdout
    finally:
        os.chmod(readonly, 0o755)
        shutil.rmtree(readonly, ignore_errors=True)


def test_the_compile_note_is_said_until_a_run_of_the_algorithm_finished(tmp_path):
    """The note was said at every run of a fresh install (a new user: "First run ... compiling" three times),
    a run compiling only its own path's kernels (SMRF with a DTM: 13 of the 39 shared). A finished run is
    remembered beside numba's cache: its algorithm's next runs say nothing, another algorithm's first run still
    does, and so does a run after the cache was cleared."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    src = tmp_path / "s.laz"
    write_scene(make_scene(SceneSpec(size_m=30.0, density_per_m2=2.0, seed=1)), str(src))
    cache = tmp_path / "cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=PLUGINS)

    def said(*args):
        proc = subprocess.run([sys.executable, "-m", "groundsieve", *args], capture_output=True, text=True, env=env,
                              timeout=600)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return "First run of this algorithm" in proc.stdout + proc.stderr

    smrf = ["smrf", "--input", str(src), "--output", str(tmp_path / "o.laz"), "--dtm", str(tmp_path / "d.tif")]
    assert said(*smrf)
    assert not said(*smrf) and not said(*smrf)
    assert said("ptd", "--input", str(src), "--output", str(tmp_path / "p.laz"))
    for index in cache.rglob("*.nbi"):  # numba's cache cleared (the stamp left)
        index.unlink()
    assert said(*smrf)
