"""Missing Python packages: the message that stays (bar item with an Install button, log line with
the exact command) and the installer, run for real into a QGIS Python that lacks the packages."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import groundsieve.dependencies as deps

REPO = Path(__file__).resolve().parents[2]
SYSTEM_PYTHON = "/usr/bin/python3"  # the Python QGIS runs on Debian (where the bindings live)


def test_install_command_targets_the_user_site_and_pins(tmp_path):
    import numpy
    cmd = deps.install_command(["laspy", "numba"], python="/opt/qgis/python")
    assert cmd[:4] == ["/opt/qgis/python", "-m", "pip", "install"]
    assert "--user" in cmd and cmd.index("laspy") < cmd.index("numba")
    assert f"numpy=={numpy.__version__}" in cmd  # kept at the version QGIS runs
    assert deps.install_command(["laspy"], python="p", pins={})[-1] == "laspy"
    managed = os.path.isfile(os.path.join(__import__("sysconfig").get_path("stdlib"), "EXTERNALLY-MANAGED"))
    assert ("--break-system-packages" in cmd) == managed


def test_qgis_python_is_found_beside_the_qgis_binary(monkeypatch, tmp_path):
    found = deps.qgis_python()  # a plain Python (here the venv's): itself
    assert found and os.path.realpath(found) == os.path.realpath(sys.executable)
    # Inside QGIS sys.executable is QGIS, or another python3 first on the PATH (a pyenv shim, seen
    # on Linux): the interpreter is the one under the prefix that reports the same sys.prefix.
    version = f"{sys.version_info[0]}.{sys.version_info[1]}"
    (tmp_path / "bin").mkdir()
    impostor = tmp_path / "bin" / "python3"  # another Python: answers with another prefix
    impostor.write_text("#!/bin/sh\necho /somewhere/else\\|" + version + "\n")
    impostor.chmod(0o755)
    python = tmp_path / "bin" / f"python{version}"
    python.write_text(f"#!/bin/sh\necho {os.path.realpath(sys.prefix)}\\|{version}\n")
    python.chmod(0o755)
    monkeypatch.setattr(sys, "executable", str(impostor))
    monkeypatch.setattr(sys, "exec_prefix", str(tmp_path))
    monkeypatch.setattr(sys, "base_exec_prefix", str(tmp_path))
    monkeypatch.setattr(os, "name", "posix")
    assert deps.qgis_python() == str(python)
    python.unlink()
    assert deps.qgis_python() is None  # the impostor is never taken
    with pytest.raises(RuntimeError, match="not found"):
        deps.install_command(["laspy"])


def test_not_pip_packages_are_never_handed_to_pip():
    ran = []
    ok, _ = deps.install(["GDAL (python3-gdal)"], run=lambda *a, **k: ran.append(a))
    assert ok and ran == []


def test_without_pip_nothing_runs_and_the_words_say_what_to_do(tmp_path):
    """Debian/Ubuntu's python3 has no pip unless python3-pip is installed (QGIS does not depend on
    it): the check says so, and install() runs nothing else."""
    assert deps.pip_available(sys.executable)[0]  # the venv's Python has pip
    bare = tmp_path / "python3"  # answers as Debian's python3 without python3-pip does
    bare.write_text("#!/bin/sh\necho \"$0: No module named pip\" >&2\nexit 1\n")
    bare.chmod(0o755)
    ok, said = deps.pip_available(str(bare))
    assert not ok and "No module named pip" in said
    ran = []

    def run(cmd, **kwargs):
        ran.append(cmd)
        return subprocess.CompletedProcess(cmd, 1, "", "/usr/bin/python3: No module named pip")
    ok, output = deps.install(["laspy"], run=run)
    assert not ok and len(ran) == 1 and ran[0][1:] == ["-m", "pip", "--version"]  # never pip install
    assert "No module named pip" in output and "sudo apt install python3-pip" in output
    assert "Install… again" in deps.NO_PIP_HINT and deps.MENU_ENTRY in deps.NO_PIP_HINT


def test_install_hint_names_the_menu_and_the_numpy_qgis_runs():
    import numpy
    hint = deps.install_hint()
    assert "Plugins > GroundSieve > Install Python packages…" in hint
    assert f"numpy=={numpy.__version__}" in hint and "<" not in hint  # no placeholder left
    assert "--user --break-system-packages" in hint
    with pytest.raises(ImportError, match="Install Python packages…"):
        deps.require_dependencies({"groundsieve_surely_absent_module": "absent-package"})


class _Iface:
    """What the plugin uses of QGIS's iface, with a real message bar and a record of the menu."""

    def __init__(self):
        from qgis.gui import QgsMessageBar
        self.bar = QgsMessageBar()
        self.menu = []

    def messageBar(self):  # noqa: N802
        return self.bar

    def mainWindow(self):  # noqa: N802
        return None

    def addPluginToMenu(self, name, action):  # noqa: N802
        self.menu.append((name, action))

    def removePluginMenu(self, name, action):  # noqa: N802
        self.menu.remove((name, action))


def _buttons(item):
    from qgis.PyQt.QtWidgets import QPushButton
    return [w for w in item.findChildren(QPushButton) if w.text().startswith("Install")]


def test_the_menu_entry_runs_the_installer_and_goes_at_unload(qgis_app, monkeypatch):
    import groundsieve
    from groundsieve import plugin as plugin_module
    monkeypatch.setattr(deps, "missing_dependencies", lambda extra=None: ["numba", "GDAL (python3-gdal)"])
    iface = _Iface()
    plugin = groundsieve.classFactory(iface)
    asked = []
    monkeypatch.setattr(plugin, "ask_and_install", lambda packages, confirm=None: asked.append(packages))
    try:
        plugin.initGui()
        [(menu, action)] = iface.menu
        assert menu == plugin_module.MENU == "&GroundSieve"
        # the entry the messages name is the one there
        assert deps.MENU_ENTRY == f"Plugins > {menu.replace('&', '')} > {action.text()}"
        iface.bar.popWidget(iface.bar.currentItem())  # the user closed the bar's item: the menu still installs
        action.trigger()
        assert asked == [["numba"]]  # what pip can install (GDAL comes with QGIS)
        monkeypatch.setattr(deps, "missing_dependencies", lambda extra=None: [])
        action.trigger()
        assert len(asked) == 1 and "every Python package it needs is installed" in iface.bar.currentItem().text()
    finally:
        plugin.unload()
    assert iface.menu == []


def test_without_pip_the_bar_says_what_to_do_and_keeps_install(qgis_app, monkeypatch, tmp_path):
    """Install… on a QGIS Python without pip: no task, the words (python3-pip), and a button to
    try again once it is installed, without restarting QGIS."""
    from qgis.core import QgsApplication

    import groundsieve
    logged = []
    QgsApplication.messageLog().messageReceived.connect(lambda msg, tag, level: logged.append((tag, msg)))
    bare = tmp_path / "python3"
    bare.write_text("#!/bin/sh\necho \"$0: No module named pip\" >&2\nexit 1\n")
    bare.chmod(0o755)
    monkeypatch.setattr(deps, "qgis_python", lambda: str(bare))
    monkeypatch.setattr(deps, "missing_dependencies", lambda extra=None: ["numba"])
    iface = _Iface()
    plugin = groundsieve.classFactory(iface)
    try:
        plugin.check_dependencies()
        assert plugin.ask_and_install(["numba"], confirm=True) is None
        assert not plugin.installing and plugin.task is None
        item = iface.bar.currentItem()
        assert "sudo apt install python3-pip" in item.text() and "again" in item.text()
        assert len(item.text()) < 130  # the bar cuts longer text: the rest is in the log
        qgis_app.processEvents()
        text = " ".join(msg for tag, msg in logged if tag == "GroundSieve")
        assert "No module named pip" in text and deps.NO_PIP_HINT in text
        assert len(_buttons(item)) == 1 and len(iface.bar.items()) == 1  # replaces the first item, one button
    finally:
        plugin.unload()
    assert iface.bar.items() == []


def test_one_install_at_a_time_and_a_short_failure_message(qgis_app, monkeypatch):
    """A second click while pip runs starts nothing (it is said); a failure is short in the bar, with
    pip's output in the log and a button to try again."""
    import threading
    import time
    from qgis.core import QgsApplication

    import groundsieve
    monkeypatch.setattr(deps, "missing_dependencies", lambda extra=None: ["numba"])
    monkeypatch.setattr(deps, "pip_available", lambda python=None, run=None: (True, "pip 23.0"))
    release, calls = threading.Event(), []

    def slow_failing_pip(packages, log=print, **kwargs):
        calls.append(list(packages))
        release.wait(60)
        return False, "ERROR: " + "x" * 3000 + " no matching distribution found for numba"
    monkeypatch.setattr(deps, "install", slow_failing_pip)
    logged = []
    QgsApplication.messageLog().messageReceived.connect(lambda msg, tag, level: logged.append((tag, msg)))
    iface = _Iface()
    plugin = groundsieve.classFactory(iface)
    try:
        plugin.initGui()
        [(_menu, action)] = iface.menu
        task = plugin.ask_and_install(["numba"], confirm=True)
        assert task is not None and plugin.installing and not action.isEnabled()
        assert plugin.ask_and_install(["numba"], confirm=True) is None  # the second click
        assert "already installing" in iface.bar.currentItem().text()
        assert plugin.task is task
        release.set()
        deadline = time.time() + 60
        while plugin.installing and time.time() < deadline:
            qgis_app.processEvents()
            time.sleep(0.02)
        assert not plugin.installing and action.isEnabled()
        assert calls == [["numba"]]  # one pip only
        item = iface.bar.currentItem()
        assert "failed" in item.text() and "Log Messages > GroundSieve" in item.text() and len(item.text()) < 100
        assert len(_buttons(item)) == 1  # try again
        qgis_app.processEvents()
        text = " ".join(msg for tag, msg in logged if tag == "GroundSieve")
        assert "no matching distribution found for numba" in text and "Still missing: numba" in text
    finally:
        release.set()
        plugin.unload()


def test_missing_packages_message_stays_offers_install_and_logs_the_command(qgis_app, monkeypatch):
    from qgis.core import QgsApplication
    from qgis.PyQt.QtWidgets import QPushButton

    import groundsieve
    monkeypatch.setattr(deps, "missing_dependencies", lambda extra=None: ["numba", "scikit-learn"])
    logged = []
    QgsApplication.messageLog().messageReceived.connect(lambda msg, tag, level: logged.append((tag, msg)))
    iface = _Iface()
    plugin = groundsieve.classFactory(iface)
    try:
        plugin.check_dependencies()  # what initGui does after registering the provider
        item = iface.bar.currentItem()
        assert item is not None and item.duration() == 0  # stays until dealt with
        assert "numba, scikit-learn" in item.text()
        buttons = [w for w in item.findChildren(QPushButton) if w.text().startswith("Install")]
        assert len(buttons) == 1
        qgis_app.processEvents()
        text = " ".join(msg for tag, msg in logged if tag == "GroundSieve")
        assert "pip install --user" in text and "numba scikit-learn" in text
        # Asked and declined: nothing runs.
        assert plugin.ask_and_install(["numba"], confirm=False) is None
        # Installed (pretend pip succeeded and the packages are now there): the warning goes away.
        monkeypatch.setattr(deps, "missing_dependencies", lambda extra=None: [])
        assert plugin.installed(True, "Successfully installed numba") == []
        assert iface.bar.currentItem() is not item
    finally:
        plugin.unload()


def _pypi_reachable():
    try:
        import urllib.request
        urllib.request.urlopen("https://pypi.org/simple/lazrs/", timeout=10).close()
        return True
    except Exception:
        return False


@pytest.mark.skipif(not os.path.exists(SYSTEM_PYTHON), reason="needs Debian's /usr/bin/python3 with QGIS")
def test_installer_puts_the_packages_into_a_bare_qgis_python_and_the_algorithms_run(tmp_path):
    """QGIS's own Python (Debian's, without this project's venv) in a fresh user base: the
    algorithms refuse with the install hint, the installer runs pip for real, and the same process
    then runs groundsieve:smrf without a restart."""
    if not _pypi_reachable():
        if os.environ.get("CI") == "true":
            pytest.fail("the Python Package Index is not reachable: the installer cannot be tested")
        pytest.skip("the Python Package Index is not reachable")
    from groundsieve.core.synthetic import SceneSpec, make_scene, scene_crs_wkt, write_scene
    cloud = tmp_path / "scene.las"
    write_scene(make_scene(SceneSpec(size_m=60.0, density_per_m2=2.0, seed=3)), str(cloud), crs_wkt=scene_crs_wkt())
    script = tmp_path / "qgis_session.py"
    script.write_text(textwrap.dedent(f"""
        import json, sys
        sys.path.insert(0, {str(REPO / '.build' / 'plugins')!r})
        sys.path.insert(0, "/usr/share/qgis/python/plugins")
        from qgis.core import QgsApplication, QgsProcessingException
        app = QgsApplication([], False)
        app.initQgis()
        from processing.core.Processing import Processing
        Processing.initialize()
        import processing
        import groundsieve
        from groundsieve import dependencies
        plugin = groundsieve.classFactory(None)
        plugin.initProcessing()
        report = {{"missing_before": dependencies.missing_dependencies(dependencies.TRAINING)}}
        params = {{"INPUT": {str(cloud)!r}, "OUTPUT": {str(tmp_path / 'out.las')!r}}}
        try:
            processing.run("groundsieve:smrf", params)
            report["before"] = "ran"
        except QgsProcessingException as err:
            report["before"] = str(err)
        ok, output = dependencies.install(report["missing_before"], log=lambda m: None)
        report["pip_ok"] = ok
        report["pip_tail"] = output[-1500:]
        report["missing_after"] = dependencies.missing_dependencies(dependencies.TRAINING)
        result = processing.run("groundsieve:smrf", params)
        report["after"] = sorted(result)
        print("REPORT " + json.dumps(report))
    """))
    userbase = tmp_path / "userbase"
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME", "PYTHONNOUSERSITE",
                        # Debian's own QGIS, also when the tests run with QGIS 3.40's libraries
                        "LD_LIBRARY_PATH", "QGIS_PREFIX_PATH", "QGIS_PROCESS")}
    env.update(PYTHONUSERBASE=str(userbase), QT_QPA_PLATFORM="offscreen", PROJ_DATA="/usr/share/proj",
               QGIS_CUSTOM_CONFIG_PATH=str(tmp_path / "profile"))
    done = subprocess.run([SYSTEM_PYTHON, str(script)], capture_output=True, text=True, env=env, timeout=900)
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("REPORT ")]
    assert done.returncode == 0 and lines, done.stdout[-3000:] + done.stderr[-3000:]
    report = json.loads(lines[-1][len("REPORT "):])
    assert {"laspy", "lazrs", "numba"} <= set(report["missing_before"]), report
    assert "needs the Python package(s)" in report["before"] and "pip install" in report["before"], report
    assert report["pip_ok"], report["pip_tail"]
    assert report["missing_after"] == [], report
    assert "OUTPUT" in report["after"] and (tmp_path / "out.las").is_file()
    # Installed into the user base, numpy left as QGIS runs it (pinned, not reinstalled there).
    site_packages = list(userbase.glob("lib/python3*/site-packages"))
    assert site_packages and (site_packages[0] / "laspy").is_dir()
    assert not (site_packages[0] / "numpy").exists()


def test_scikit_learn_alone_missing_is_said_as_what_it_is_needed_for(qgis_app, monkeypatch):
    """Without scikit-learn alone the bar warned on every start that GroundSieve 'needs the Python packages
    scikit-learn', while 13 of the 14 algorithms ran (a QGIS plugin reviewer): it says what needs it, as
    information, and still offers the install."""
    from qgis.core import Qgis

    import groundsieve
    monkeypatch.setattr(deps, "missing_dependencies", lambda extra=None: ["scikit-learn"] if extra else [])
    iface = _Iface()
    plugin = groundsieve.classFactory(iface)
    try:
        assert plugin.check_dependencies() == ["scikit-learn"]
        item = iface.bar.currentItem()
        assert "needs scikit-learn only to train Random Forest models" in item.text()
        assert item.level() == Qgis.Info and len(_buttons(item)) == 1 and item.duration() == 15  # (it goes away)
        monkeypatch.setattr(deps, "missing_dependencies", lambda extra=None: ["numba", "scikit-learn"] if extra
                            else ["numba"])
        plugin.check_dependencies()
        item = iface.bar.currentItem()
        assert "needs the Python packages numba, scikit-learn" in item.text() and item.level() == Qgis.Warning
        assert item.duration() == 0  # (it stays until dealt with)
    finally:
        plugin.unload()
