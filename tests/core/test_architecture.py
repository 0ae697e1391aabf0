"""The core stays free of QGIS and Qt; GDAL (osgeo) is confined to core/raster.py."""
from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CORE = REPO / "core"

FORBIDDEN = ("qgis", "PyQt5", "PyQt6", "PyQt4", "PySide2", "PySide6", "sip")
OSGEO_ALLOWED = {"raster.py"}


def core_files():
    return sorted(p for p in CORE.rglob("*.py") if "__pycache__" not in p.parts)


def imported_modules(tree: ast.AST):
    """(line, absolute module name) of every import, including import_module("...") and
    __import__("...") calls with a literal name. Relative imports are inside the package."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0 and node.module:
                yield node.lineno, node.module
                for alias in node.names:
                    yield node.lineno, f"{node.module}.{alias.name}"
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if name in ("import_module", "__import__"):
                yield node.lineno, node.args[0].value


def top(name: str) -> str:
    return name.split(".")[0]


def test_core_files_found():
    names = {p.name for p in core_files()}
    assert {"smrf.py", "io.py", "raster.py", "workflow.py"} <= names


@pytest.mark.parametrize("path", core_files(), ids=lambda p: str(p.relative_to(CORE)))
def test_core_module_imports_no_gui_toolkit(path):
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    bad = [(line, mod) for line, mod in imported_modules(tree) if top(mod) in FORBIDDEN]
    assert not bad, f"{path.relative_to(REPO)} imports QGIS/Qt: " + ", ".join(f"line {ln}: {m}" for ln, m in bad)


@pytest.mark.parametrize("path", core_files(), ids=lambda p: str(p.relative_to(CORE)))
def test_osgeo_only_in_raster(path):
    if path.name in OSGEO_ALLOWED and path.parent == CORE:
        return
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    bad = [(line, mod) for line, mod in imported_modules(tree) if top(mod) in ("osgeo", "gdal", "ogr", "osr")]
    assert not bad, f"{path.relative_to(REPO)} imports GDAL outside core/raster.py: " + \
        ", ".join(f"line {ln}: {m}" for ln, m in bad)


def test_checker_sees_every_import_form():
    tree = ast.parse("import qgis.core\nfrom qgis.PyQt import QtCore\nfrom PyQt5 import QtWidgets\n"
                     "import importlib\nimportlib.import_module('PyQt6.QtCore')\n__import__('osgeo')\n"
                     "from . import grid\n")
    mods = {top(m) for _, m in imported_modules(tree)}
    assert {"qgis", "PyQt5", "PyQt6", "osgeo"} <= mods


def test_importing_the_core_loads_no_qgis_and_no_gdal():
    """At run time too: importing every core module but raster pulls in neither Qt/QGIS nor osgeo."""
    modules = sorted(f"groundsieve.core.{p.stem}" for p in CORE.glob("*.py")
                     if p.stem not in ("__init__", "raster"))
    code = ("import sys, importlib\n"
            f"for m in {modules!r}: importlib.import_module(m)\n"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
            f"{FORBIDDEN + ('osgeo',)!r})\n"
            "print(','.join(bad))\n")
    env_path = str(REPO / ".build" / "plugins")
    env = dict(os.environ)
    env["PYTHONPATH"] = env_path + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "", f"importing the core loaded: {out.stdout.strip()}"
