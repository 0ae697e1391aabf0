"""Test set-up: make the checkout importable as ``groundsieve`` whatever its folder is
called, through the link ``.build/plugins/groundsieve`` (made by scripts/bootstrap, and
here if missing)."""
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PLUGINS = REPO / ".build" / "plugins"

os.environ.setdefault("PROJ_DATA", "/usr/share/proj")
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

link = PLUGINS / "groundsieve"
if not link.exists():
    PLUGINS.mkdir(parents=True, exist_ok=True)
    link.symlink_to(REPO, target_is_directory=True)
if str(PLUGINS) not in sys.path:
    sys.path.insert(0, str(PLUGINS))
