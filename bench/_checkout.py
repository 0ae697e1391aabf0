"""Puts this checkout's ``groundsieve`` package on ``sys.path`` for the benchmark scripts,
through the link ``.build/plugins/groundsieve`` that scripts/bootstrap makes (so the package
imports under its own name from any clone folder); stops with a clear message when the link is
missing. The scripts import it before anything from groundsieve: ``from _checkout import REPO``.
"""
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PLUGINS = REPO / ".build" / "plugins"
if not (PLUGINS / "groundsieve").exists():
    sys.exit(f"{PLUGINS / 'groundsieve'} is missing: run scripts/bootstrap first")
if str(PLUGINS) not in sys.path:
    sys.path.insert(0, str(PLUGINS))
