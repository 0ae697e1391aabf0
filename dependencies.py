"""Which of the Python packages GroundSieve needs are missing, and how to install them into the
Python that QGIS runs (no QGIS import here: plugin.py shows the message and asks first).

The installer runs ``<QGIS's python> -m pip install --user ...``: the user site needs no
administrator rights on any platform, is on QGIS's ``sys.path`` on Windows (OSGeo4W and the
standalone installer), macOS and Linux, and is added to ``sys.path`` after the install so the
algorithms run without a restart. numpy (and scipy) are pinned to the versions QGIS runs with, so
pip never replaces the numpy that QGIS's own modules (GDAL's gdal_array) were built against.
"""
import importlib
import importlib.util
import os
import site
import subprocess
import sys
import sysconfig

#: import name -> pip requirement
REQUIRED = {"numpy": "numpy", "scipy": "scipy", "laspy": "laspy", "lazrs": "lazrs", "numba": "numba",
            "osgeo": "GDAL (python3-gdal)"}
#: needed by one algorithm only (training a Random Forest)
TRAINING = {"sklearn": "scikit-learn"}
#: what pip cannot install into QGIS's Python: it comes with QGIS (or the system's GDAL bindings)
NOT_PIP = {"GDAL (python3-gdal)"}

#: where the installer is in the desktop (plugin.py adds this menu entry)
MENU_ENTRY = "Plugins > GroundSieve > Install Python packages…"

#: what to do when QGIS's Python has no pip (Debian and Ubuntu package it apart: python3-pip)
NO_PIP_HINT = ("QGIS's Python has no pip. On Debian/Ubuntu install it with: sudo apt install python3-pip, "
               f"then click Install… again (or {MENU_ENTRY}); on other systems see the README's "
               "'Install into desktop QGIS'.")


def install_hint():
    """How to install the missing packages, in words: the desktop's menu entry, and the commands
    by hand with numpy pinned to the version QGIS runs (read from the running numpy)."""
    try:
        numpy_pin = f" numpy=={importlib.import_module('numpy').__version__}"
    except Exception:  # absent or broken: nothing to pin
        numpy_pin = ""
    return ("Install them into QGIS's Python: in desktop QGIS with " + MENU_ENTRY + " (or the message bar's "
            "Install… button), or by hand (the command is also in Log Messages > GroundSieve), e.g. on "
            "Debian/Ubuntu (pip comes with python3-pip): /usr/bin/python3 -m pip install --user "
            f"--break-system-packages laspy lazrs numba scikit-learn{numpy_pin}; on Windows, from the "
            "OSGeo4W shell: python -m pip install --user laspy lazrs numba scikit-learn")


def missing_dependencies(extra=None):
    wanted = dict(REQUIRED, **(extra or {}))
    return [pip for name, pip in wanted.items() if importlib.util.find_spec(name) is None]


def require_dependencies(extra=None):
    """Raise ImportError with an install hint when something is missing."""
    missing = missing_dependencies(extra)
    if missing:
        raise ImportError(f"GroundSieve needs the Python package(s) {', '.join(missing)}, "
                          f"not found in QGIS's Python. {install_hint()}")


def qgis_python():
    """The Python interpreter of the running QGIS, or None. Inside QGIS ``sys.executable`` is QGIS
    itself or whatever ``python3`` comes first on the PATH (seen on Linux: a pyenv shim), so the
    candidates are looked for in the running Python's prefix (OSGeo4W and the Windows installer keep
    python.exe in ``sys.exec_prefix``, QGIS.app in ``Contents/MacOS/bin``, Linux in ``<prefix>/bin``)
    and each is asked for its ``sys.prefix`` and version: only the very Python QGIS runs is taken."""
    version = f"{sys.version_info[0]}.{sys.version_info[1]}"
    names = ("python.exe", "python3.exe") if os.name == "nt" else (f"python{version}", "python3", "python")
    folders = []
    for prefix in (sys.exec_prefix, sys.base_exec_prefix):
        folders += [prefix, os.path.join(prefix, "bin")]
    candidates = [os.path.join(folder, name) for folder in folders for name in names]
    candidates.append(sys.executable)
    seen = set()
    for path in candidates:
        if not path or path in seen or not os.path.isfile(path) or not os.access(path, os.X_OK):
            continue
        seen.add(path)
        if _same_python(path):
            return path
    return None


def _same_python(path):
    """Whether ``path`` runs as the current Python (same prefix and version)."""
    want = f"{os.path.realpath(sys.prefix)}|{sys.version_info[0]}.{sys.version_info[1]}"
    code = "import os, sys; print(os.path.realpath(sys.prefix) + '|%d.%d' % sys.version_info[:2])"
    try:
        done = subprocess.run([path, "-I", "-c", code], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0 and done.stdout.strip() == want


def _externally_managed():
    """Debian/Ubuntu (PEP 668) refuse pip into the system Python unless told it is meant."""
    return os.path.isfile(os.path.join(sysconfig.get_path("stdlib"), "EXTERNALLY-MANAGED"))


def pinned_versions():
    """numpy and scipy as QGIS runs them (left out when not importable)."""
    pins = {}
    for name in ("numpy", "scipy"):
        try:
            pins[name] = importlib.import_module(name).__version__
        except Exception:  # absent or broken: nothing to pin
            pass
    return pins


def install_command(packages, python=None, pins=None):
    """The pip command that installs ``packages`` (pip names) into the user site of QGIS's
    Python, with numpy and scipy required at the versions QGIS runs (``pins``, default
    :func:`pinned_versions`), so pip keeps them instead of upgrading them."""
    python = python or qgis_python()
    if python is None:
        raise RuntimeError("QGIS's Python interpreter was not found next to "
                           f"{sys.exec_prefix}; install the packages {', '.join(packages)} by hand")
    cmd = [python, "-m", "pip", "install", "--user", "--disable-pip-version-check", "--no-input"]
    if _externally_managed():
        cmd.append("--break-system-packages")
    pins = pinned_versions() if pins is None else pins
    return cmd + list(packages) + [f"{name}=={version}" for name, version in pins.items()]


def command_text(cmd):
    return " ".join(f'"{a}"' if " " in a else a for a in cmd)


def pip_available(python=None, run=subprocess.run):
    """(True, pip's version line) when ``python -m pip --version`` works for QGIS's Python
    (``python``, default :func:`qgis_python`); else (False, why). Debian and Ubuntu ship pip apart
    (python3-pip), and QGIS does not depend on it."""
    python = python or qgis_python()
    if python is None:
        return False, f"QGIS's Python interpreter was not found next to {sys.exec_prefix}"
    try:
        done = run([python, "-m", "pip", "--version"], capture_output=True, text=True, timeout=60,
                   env=dict(os.environ, PIP_NO_INPUT="1"))
    except (OSError, subprocess.TimeoutExpired) as err:
        return False, f"{python} -m pip --version: {err}"
    output = ((done.stdout or "") + (done.stderr or "")).strip()
    return done.returncode == 0, output or f"{python} -m pip --version exited with {done.returncode}"


def install(packages, log=print, run=subprocess.run, timeout=1800):
    """Install ``packages`` (pip names) into QGIS's Python; return (ok, what pip printed).
    Blocking: call it off the GUI thread. Activates the user site afterwards. Without pip, nothing
    runs: (False, what pip's check said and :data:`NO_PIP_HINT`)."""
    packages = [p for p in packages if p not in NOT_PIP]
    if not packages:
        return True, ""
    cmd = install_command(packages)
    has_pip, said = pip_available(cmd[0], run=run)
    if not has_pip:
        return False, f"{said}\n{NO_PIP_HINT}"
    log(f"Running: {command_text(cmd)}")
    try:
        done = run(cmd, capture_output=True, text=True, timeout=timeout, env=dict(os.environ, PIP_NO_INPUT="1"))
    except (OSError, subprocess.TimeoutExpired) as err:
        return False, str(err)
    output = (done.stdout or "") + (done.stderr or "")
    activate_user_site()
    return done.returncode == 0, output


def activate_user_site():
    """Put the user site on sys.path when pip has just created it (Python adds it at start-up
    only if it existed then), so newly installed packages import without restarting QGIS."""
    user_site = site.getusersitepackages()
    if site.ENABLE_USER_SITE is not False and os.path.isdir(user_site) and user_site not in sys.path:
        site.addsitedir(user_site)
    importlib.invalidate_caches()
