"""Which of the Python packages GroundSieve needs are missing (no QGIS import here)."""
import importlib.util

#: import name -> pip requirement
REQUIRED = {"numpy": "numpy", "scipy": "scipy", "laspy": "laspy", "lazrs": "lazrs", "numba": "numba",
            "osgeo": "GDAL (python3-gdal)"}
#: needed by one algorithm only (training a Random Forest)
TRAINING = {"sklearn": "scikit-learn"}

INSTALL_HINT = ("Install them into QGIS's Python, e.g. on Debian/Ubuntu: "
                "/usr/bin/python3 -m pip install --user --break-system-packages "
                "-c constraints.txt -r requirements.txt (from the plugin folder); on Windows, from the "
                "OSGeo4W shell: python -m pip install laspy lazrs numba scikit-learn")


def missing_dependencies(extra=None):
    wanted = dict(REQUIRED, **(extra or {}))
    return [pip for name, pip in wanted.items() if importlib.util.find_spec(name) is None]


def require_dependencies(extra=None):
    """Raise ImportError with an install hint when something is missing."""
    missing = missing_dependencies(extra)
    if missing:
        raise ImportError(f"GroundSieve needs the Python package(s) {', '.join(missing)}, "
                          f"not found in QGIS's Python. {INSTALL_HINT}")
