"""`make zip` gives an installable plugin: no tests or dev files, and qgis_process loads it."""
import os
import subprocess
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
QGIS_PROCESS = os.environ.get("QGIS_PROCESS", "/usr/bin/qgis_process.bin")


def test_zip_is_installable_and_lean(tmp_path):
    archive = tmp_path / "groundsieve.zip"
    subprocess.run(["git", "archive", "--format=zip", "--prefix=groundsieve/", "-o", str(archive), "HEAD"],
                   cwd=REPO, check=True)
    names = zipfile.ZipFile(archive).namelist()
    assert "groundsieve/metadata.txt" in names and "groundsieve/__init__.py" in names
    assert "groundsieve/core/filters/smrf.py" in names and "groundsieve/icons/groundsieve.svg" in names
    for dev in ("tests/", "bench/", "scripts/", ".ci/", "Makefile", "pytest.ini"):
        assert not [n for n in names if n.startswith("groundsieve/" + dev)], dev
    plugins = tmp_path / "plugins"
    zipfile.ZipFile(archive).extractall(plugins)
    site = subprocess.run([str(REPO / ".venv" / "bin" / "python"), "-c",
                           "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    runtime = tmp_path / "xdg"
    runtime.mkdir(mode=0o700)
    env = dict(os.environ, QGIS_PLUGINPATH=str(plugins), QGIS_CUSTOM_CONFIG_PATH=str(tmp_path / "profile"),
               QT_QPA_PLATFORM="offscreen", PROJ_DATA="/usr/share/proj", XDG_RUNTIME_DIR=str(runtime),
               PYTHONPATH=os.pathsep.join(p for p in (site, os.environ.get("PYTHONPATH")) if p))
    subprocess.run([QGIS_PROCESS, "plugins", "enable", "groundsieve"], env=env,
                   capture_output=True, timeout=300)
    listing = subprocess.run([QGIS_PROCESS, "list"], env=env, capture_output=True, text=True,
                             timeout=300)
    assert "groundsieve:smrf" in listing.stdout, listing.stdout[-2000:] + listing.stderr[-2000:]
