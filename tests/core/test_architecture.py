"""The core's architecture, checked on its source: free of QGIS and Qt, GDAL (osgeo) only in
core/raster/ (and, imported where it is used, in core/io/geokeys.py: a LAS file's GeoTIFF keys are read by
GDAL's libgeotiff where laspy misreads them, and without GDAL as laspy reads them), imports one way down the layers, and no filter importing another filter.

The checker is a plain function of a folder, so the tests below also run it on planted trees
that break each rule: a rule that cannot fail would prove nothing."""
from __future__ import annotations

import ast
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Iterator, List, Optional, Tuple

import pytest

REPO = Path(__file__).resolve().parents[2]
CORE = REPO / "core"

FORBIDDEN = ("qgis", "PyQt5", "PyQt6", "PyQt4", "PySide2", "PySide6", "sip")
GDAL = ("osgeo", "gdal", "ogr", "osr")
GDAL_PACKAGE = "raster"
#: modules outside GDAL_PACKAGE that may import GDAL inside a function (the core imports without it)
GDAL_MODULES = ("io/geokeys.py",)

#: The layers, lowest first: a module imports only from lower layers or from its own package
#: (folder). Two names on one layer (e.g. filters and learn) must not import each other.
LAYERS = (
    ("errors",),
    ("progress", "validate", "metrics", "machine"),
    ("io", "grids"),
    ("raster",),
    ("filters",),
    ("learn",),      # learned classifiers may use the filters' surfaces as features
    ("engine", "synthetic"),
)
RANK = {name: rank for rank, names in enumerate(LAYERS) for name in names}


def core_files(root: Path = CORE) -> List[Path]:
    return sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts)


def imported_modules(tree: ast.AST):
    """(line, absolute module name) of every absolute import, including import_module("...") and
    __import__("...") calls with a literal name. Relative imports: see :func:`core_imports`."""
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


def core_imports(path: Path, root: Path, tree: ast.AST) -> Iterator[Tuple[int, Tuple[str, ...]]]:
    """(line, parts of the core module imported, relative to ``root``) of every import of a core
    module: relative imports resolved against the file's package, and absolute
    ``groundsieve.core...`` ones. ``from . import x`` yields the module ``x`` of the package."""
    package = path.relative_to(root).parts[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level > 0:
            if node.level - 1 > len(package):
                continue  # above the core: not a core module
            base = package[:len(package) - (node.level - 1)]
            module = tuple(node.module.split(".")) if node.module else ()
            if module:
                yield node.lineno, base + module
            else:
                for alias in node.names:
                    yield node.lineno, base + (alias.name,)
        else:
            mods = []
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                mods = [node.module]
            elif isinstance(node, ast.Import):
                mods = [alias.name for alias in node.names]
            for mod in mods:
                parts = mod.split(".")
                if parts[:2] == ["groundsieve", "core"] and len(parts) > 2:
                    yield node.lineno, tuple(parts[2:])


def top(name: str) -> str:
    return name.split(".")[0]


def group(parts: Tuple[str, ...]) -> str:
    """The layer name of a core module: its package (folder), or its own name at the top."""
    return parts[0][:-3] if parts[0].endswith(".py") else parts[0]


def filter_family(name: str) -> str:
    """``smrf`` for filters/smrf.py and filters/_smrf_kernels.py; ``ptd`` for _ptd_tin.py."""
    return name.lstrip("_").split("_")[0]


def violations(root: Path = CORE) -> List[str]:
    """Every broken rule in the core tree at ``root``, as 'file:line: what'."""
    found = []
    for path in core_files(root):
        rel = path.relative_to(root)
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        where = f"core/{rel.as_posix()}"
        for line, mod in imported_modules(tree):
            if top(mod) in FORBIDDEN:
                found.append(f"{where}:{line}: imports QGIS/Qt ({mod})")
            if top(mod) in GDAL and rel.parts[0] != GDAL_PACKAGE and rel.as_posix() not in GDAL_MODULES:
                found.append(f"{where}:{line}: imports GDAL ({mod}) outside core/{GDAL_PACKAGE}/")
        if rel.parts == ("__init__.py",):
            continue  # the core's own docstring
        src = group(rel.parts)
        if src not in RANK:
            found.append(f"{where}: is on no layer: add its folder or module to LAYERS")
            continue
        for line, target in core_imports(path, root, tree):
            dst = target[0]
            if dst not in RANK:
                continue  # not a core module (e.g. a package's sibling resolved above it)
            if dst == src:
                if src == "filters" and len(rel.parts) == 2 and len(target) > 1:
                    mine, theirs = filter_family(Path(rel.parts[1]).stem), filter_family(target[1])
                    if mine != theirs:
                        found.append(f"{where}:{line}: the {mine} filter imports the {theirs} filter "
                                     f"(core.{'.'.join(target)}); shared code belongs in a lower layer")
                continue
            if RANK[dst] >= RANK[src]:
                found.append(f"{where}:{line}: {src} imports {dst} (core.{'.'.join(target)}), "
                             f"which is {'on the same layer' if RANK[dst] == RANK[src] else 'above it'}")
    return found


def test_core_files_found():
    names = {p.relative_to(CORE).as_posix() for p in core_files()}
    assert {"filters/smrf.py", "io/clouds.py", "raster/geotiff.py", "engine/workflow.py", "validate.py"} <= names


def test_every_core_folder_says_what_lives_there():
    for folder in sorted(p for p in CORE.iterdir() if p.is_dir() and p.name != "__pycache__"):
        init = folder / "__init__.py"
        assert init.is_file(), f"core/{folder.name} has no __init__.py"
        doc = ast.get_docstring(ast.parse(init.read_text(encoding="utf-8")))
        assert doc and "import" in doc, f"core/{folder.name}/__init__.py must say what lives there and what it may import"


def test_the_core_keeps_its_architecture():
    assert violations() == []


@pytest.mark.parametrize("layout, expected", [
    ({"filters/pmf.py": "from .smrf import SMRF\n", "filters/smrf.py": ""},
     "the pmf filter imports the smrf filter"),
    ({"filters/_pmf_kernels.py": "from . import _csf_cloth\n", "filters/_csf_cloth.py": ""},
     "the pmf filter imports the csf filter"),
    ({"filters/csf.py": "from groundsieve.core.filters.ptd import PTD\n", "filters/ptd.py": ""},
     "the csf filter imports the ptd filter"),
    ({"filters/smrf.py": "import qgis.core\n"}, "imports QGIS/Qt"),
    ({"io/clouds.py": "def f():\n    from qgis.PyQt import QtCore\n"}, "imports QGIS/Qt"),
    ({"validate.py": "import importlib\nimportlib.import_module('PyQt5.QtCore')\n"}, "imports QGIS/Qt"),
    ({"grids/spec.py": "from osgeo import gdal\n"}, "imports GDAL"),
    ({"grids/rasterize.py": "from ..filters.smrf import SMRF\n"}, "grids imports filters"),
    ({"io/clouds.py": "from ..engine import workflow\n"}, "io imports engine"),
    ({"errors.py": "from .progress import Steps\n"}, "errors imports progress"),
    ({"learn/rf.py": "from ..engine.workflow import make_dtm\n"}, "learn imports engine"),
    ({"synthetic.py": "from .engine import workflow\n"}, "synthetic imports engine"),
    ({"filters/evc.py": "from ..learn.features import compute_features\n"}, "filters imports learn"),
    ({"io/clouds.py": "from ..grids.spec import GridSpec\n"}, "io imports grids"),
    ({"tiles/plan.py": "x = 1\n"}, "is on no layer"),
])
def test_the_checker_catches_a_planted_violation(tmp_path, layout, expected):
    for rel, text in layout.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text), encoding="utf-8")
    found = violations(tmp_path)
    assert any(expected in v for v in found), found


def test_the_checker_allows_what_the_layers_allow(tmp_path):
    layout = {"filters/smrf.py": "from ._smrf_kernels import k\nfrom ..grids.spec import GridSpec\n"
                                 "from ..validate import check_number\nfrom ..errors import InputError\n",
              "filters/_ptd_kernels.py": "from ._ptd_tin import CANDIDATE\n",
              "filters/ptd.py": "from . import _ptd_tin as T\n",
              "engine/workflow.py": "from ..filters.smrf import SMRF\nfrom ..raster.geotiff import write\n",
              "raster/geotiff.py": "from osgeo import gdal\nfrom ..io import atomic_path\n",
              "learn/model_file.py": "from .rf import Model\nfrom ..io import atomic_path\n",
              "learn/hybrid.py": "from ..filters.smrf import SMRF\n"}
    for rel, text in layout.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    assert violations(tmp_path) == []


def test_checker_sees_every_import_form():
    tree = ast.parse("import qgis.core\nfrom qgis.PyQt import QtCore\nfrom PyQt5 import QtWidgets\n"
                     "import importlib\nimportlib.import_module('PyQt6.QtCore')\n__import__('osgeo')\n"
                     "from . import grid\n")
    mods = {top(m) for _, m in imported_modules(tree)}
    assert {"qgis", "PyQt5", "PyQt6", "osgeo"} <= mods


def _module_name(path: Path) -> Optional[str]:
    rel = path.relative_to(CORE).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(("groundsieve", "core") + parts)


def test_importing_the_core_loads_no_qgis_and_no_gdal():
    """At run time too: importing every core module outside core/raster/ pulls in neither Qt/QGIS
    nor osgeo."""
    modules = sorted(_module_name(p) for p in core_files() if p.relative_to(CORE).parts[0] != GDAL_PACKAGE)
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
