"""``python -m groundsieve``: the ground filters without QGIS (see core/engine/cli.py)."""
import sys

from .core.engine.cli import main

if __name__ == "__main__":
    sys.exit(main())
