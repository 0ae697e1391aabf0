#!/usr/bin/env python3
"""Open every GroundSieve algorithm's dialog (processing's AlgorithmDialog, as the toolbox does) on
a virtual display and save a PNG of each to docs/img/<algorithm>.png; also one of the SMRF dialog
during a run (its log and progress bar), if a cloud is given. Run through scripts/screenshots.

Robust to changes of the dialogs: every algorithm the provider lists is shot, whatever its
parameters; the PNGs are rewritten only when the picture changed."""
from __future__ import annotations

import argparse
import os
import sys
import time

REPO = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.join(REPO, ".build", "plugins"))
sys.path.insert(0, "/usr/share/qgis/python/plugins")


def spin(app, seconds):
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        app.processEvents()
        time.sleep(0.01)


def save(widget, path):
    """Save the widget's picture to ``path`` unless the file already holds the same picture."""
    from qgis.PyQt.QtGui import QImage
    image = widget.grab().toImage()
    if os.path.exists(path) and QImage(path).convertToFormat(image.format()) == image:
        return False
    tmp = path + ".part.png"
    if not image.save(tmp, "PNG"):
        raise RuntimeError(f"{path}: cannot be written")
    os.replace(tmp, path)
    return True


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=os.path.join(REPO, "docs", "img"))
    ap.add_argument("--cloud", default="", help="a LAS/LAZ for the picture of a dialog during a run")
    ap.add_argument("--only", default="", help="comma-separated algorithm names (default: all)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)

    from qgis.core import QgsApplication
    app = QgsApplication([], True)
    app.initQgis()
    from processing.core.Processing import Processing
    Processing.initialize()
    from processing.gui.AlgorithmDialog import AlgorithmDialog

    from groundsieve.provider.provider import GroundSieveProvider
    provider = GroundSieveProvider()
    QgsApplication.processingRegistry().addProvider(provider)
    only = {n for n in args.only.split(",") if n}
    names = sorted(a.name() for a in provider.algorithms())
    written = 0
    for name in names:
        if only and name not in only:
            continue
        alg = QgsApplication.processingRegistry().createAlgorithmById(f"groundsieve:{name}")
        dlg = AlgorithmDialog(alg)
        dlg.resize(1000, 760)
        dlg.show()
        spin(app, 0.4)
        changed = save(dlg, os.path.join(args.out, f"{name}.png"))
        written += changed
        print(f"{name}.png{'' if changed else ' (unchanged)'}")
        dlg.close()
        dlg.deleteLater()
        spin(app, 0.05)
    if args.cloud and (not only or "smrf" in only):
        import tempfile
        out = tempfile.mkdtemp(prefix="gs-shot-")
        alg = QgsApplication.processingRegistry().createAlgorithmById("groundsieve:smrf")
        dlg = AlgorithmDialog(alg)
        dlg.setParameters({"INPUT": args.cloud, "OUTPUT": os.path.join(out, "classified.laz"),
                           "DTM": os.path.join(out, "dtm.tif"), "DTM_CELL": 1.0})
        dlg.resize(1000, 760)
        dlg.show()
        spin(app, 0.3)
        from qgis.PyQt.QtWidgets import QTextEdit
        dlg.runButton().click()
        log = dlg.findChild(QTextEdit, "txtLog")
        start = time.perf_counter()
        while "DTM: triangulating" not in log.toPlainText() and time.perf_counter() - start < 120:
            spin(app, 0.02)
        spin(app, 0.3)
        changed = save(dlg, os.path.join(args.out, "smrf_running.png"))
        print(f"smrf_running.png{'' if changed else ' (unchanged)'}")
        dlg.cancelButton().click()
        spin(app, 1.5)
        dlg.close()
    QgsApplication.processingRegistry().removeProvider(provider)
    app.exitQgis()
    print(f"{written} picture(s) written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
