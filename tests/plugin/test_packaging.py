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
    # the README's links to the docs resolve inside the zip (they had been left out: a new user)
    import re
    readme = (REPO / "README.md").read_text()
    links = {m.split("#")[0] for m in re.findall(r"\]\(([^)#:]+(?:#[^)]*)?)\)", readme)}
    assert "docs/USER_GUIDE.md" in links
    assert not [link for link in links if f"groundsieve/{link}" not in names], links
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


def test_metadata_reads_as_qgis_reads_it_and_says_how_to_install():
    """QGIS's plugin manager reads metadata.txt with configparser (interpolation on: a '%' breaks
    it) and shows ``about`` as HTML (a '<' would be eaten). The about text names the installer the
    plugin has and the command by hand that the README gives (pip -r requirements.txt fails on
    Debian 12: externally-managed-environment)."""
    import configparser
    import re

    import groundsieve.dependencies as deps
    parser = configparser.ConfigParser()
    with open(REPO / "metadata.txt", encoding="utf-8") as f:
        parser.read_file(f)
    fields = {key: parser.get("general", key) for key in parser.options("general")}
    for key in ("name", "qgisminimumversion", "description", "about", "version", "author", "email",
                "repository", "hasprocessingprovider"):
        assert fields.get(key), key
    about = fields["about"]
    assert "<" not in about and "requirements.txt" not in about
    assert "Install…" in about and deps.MENU_ENTRY in about
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    debian = re.search(r"^- Debian/Ubuntu: `([^`]+)`", readme, re.M)
    assert debian and "--break-system-packages" in debian.group(1)
    assert debian.group(1) in about  # the README's command, word for word
