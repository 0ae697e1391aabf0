#!/usr/bin/env python3
"""Drive the real QGIS desktop algorithm dialog (processing's AlgorithmDialog, the one the
toolbox opens) on a display, and report what a user would have seen, as JSON on stdout.

    harness.py --cloud CLOUD --work FOLDER [--algs smrf,csf] [--stages reading,filtering,dtm,writing]

For each algorithm: one full run, the progress bar sampled every 20 ms (value, and whether every
output is on disk yet), then one run per stage with a click on the dialog's Cancel button while
that stage is under way (told by the dialog's log), timing the click to the end of the task and
listing what is left in the output folder. Needs a display (Xvfb: see tests/desktop/conftest.py).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", ".build", "plugins"))
sys.path.insert(0, "/usr/share/qgis/python/plugins")

#: what the log says as each stage starts (core/engine/workflow.py), and how long into it to click
STAGES = {"reading": ("Reading ", 0.3), "filtering": ("Filtering (", 0.4),
          "dtm": ("DTM: triangulating", 0.3), "writing": ("Writing ", 0.5)}
ORDER = ["reading", "filtering", "dtm", "writing"]


class Driver:
    def __init__(self, app):
        from qgis.core import QgsApplication
        self.app = app
        self.tm = QgsApplication.taskManager()
        self.tm.statusChanged.connect(self._status)
        self.ended = None

    def _status(self, _task_id, status):
        from qgis.core import QgsTask
        if status in (QgsTask.Complete, QgsTask.Terminated) and self.ended is None:
            self.ended = time.perf_counter()

    def spin(self, seconds):
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            self.app.processEvents()
            time.sleep(0.005)

    def dialog(self, alg_id, params):
        from processing.gui.AlgorithmDialog import AlgorithmDialog
        from qgis.core import QgsApplication
        alg = QgsApplication.processingRegistry().createAlgorithmById(alg_id)
        dlg = AlgorithmDialog(alg)
        dlg.setParameters(params)
        dlg.resize(900, 700)
        dlg.show()
        self.spin(0.3)
        return dlg

    @staticmethod
    def log_text(dlg):
        from qgis.PyQt.QtWidgets import QTextBrowser, QTextEdit
        box = dlg.findChild(QTextBrowser, "txtLog") or dlg.findChild(QTextEdit, "txtLog")
        return box.toPlainText() if box is not None else ""

    def press_run(self, dlg):
        self.ended = None
        button = dlg.runButton() if hasattr(dlg, "runButton") else None
        if button is not None:
            button.click()
        else:
            dlg.runAlgorithm()
        return time.perf_counter()


def outputs_for(folder):
    return {"OUTPUT": os.path.join(folder, "classified.laz"), "DTM": os.path.join(folder, "dtm.tif")}


def fresh(folder):
    shutil.rmtree(folder, ignore_errors=True)
    os.makedirs(folder)
    return folder


def full_run(driver, alg_id, cloud, folder, timeout):
    outs = outputs_for(fresh(folder))
    dlg = driver.dialog(alg_id, {"INPUT": cloud, "DTM_CELL": 1.0, **outs})
    samples = []
    start = driver.press_run(dlg)
    from qgis.PyQt.QtWidgets import QProgressBar
    bar = dlg.findChild(QProgressBar, "progressBar")
    while driver.ended is None and time.perf_counter() - start < timeout:
        driver.app.processEvents()
        samples.append((time.perf_counter() - start, bar.value(), all(os.path.exists(p) for p in outs.values())))
        time.sleep(0.02)
    end = (driver.ended or time.perf_counter()) - start
    driver.spin(0.5)
    log = driver.log_text(dlg)
    dlg.close()
    # stand-stills: the longest time the bar's value did not change, from the click to the end
    changes = [0.0] + [t for (t, v), (_t0, v0) in zip(((s[0], s[1]) for s in samples[1:]),
                                                      ((s[0], s[1]) for s in samples[:-1])) if v != v0] + [end]
    still, still_from = max((b - a, a) for a, b in zip(changes, changes[1:]))
    still_value = next((v for t, v, _d in samples if t >= still_from), None)
    full_before_outputs = [t for t, v, done in samples if v >= 100 and not done]
    return {"alg": alg_id, "kind": "full", "seconds": end, "longest_still_s": still,
            "still_share": still / end, "still_from_s": still_from, "still_at_value": still_value,
            "samples": len(samples),
            "first_100_s": next((t for t, v, _d in samples if v >= 100), None),
            "hundred_before_outputs": len(full_before_outputs), "ended": driver.ended is not None,
            "outputs": sorted(os.listdir(folder)), "log_tail": log[-600:],
            "trace": [(round(t, 2), v) for t, v, _d in samples][::10]}


def cancel_at(driver, alg_id, cloud, folder, at_s, timeout):
    """Click Cancel ``at_s`` seconds after Run whatever the log says (for code that logs no stages)."""
    outs = outputs_for(fresh(folder))
    dlg = driver.dialog(alg_id, {"INPUT": cloud, "DTM_CELL": 1.0, **outs})
    start = driver.press_run(dlg)
    clicked = None
    while driver.ended is None and time.perf_counter() - start < timeout:
        driver.app.processEvents()
        if clicked is None and time.perf_counter() - start >= at_s:
            dlg.cancelButton().click()
            clicked = time.perf_counter()
        time.sleep(0.01)
    ended = driver.ended
    driver.spin(0.5)
    log = driver.log_text(dlg)
    dlg.close()
    driver.spin(0.2)
    return {"alg": alg_id, "kind": "cancel", "stage": f"t={at_s:g}s", "clicked_in": f"t={at_s:g}s",
            "click_late_s": None if clicked is None else clicked - start - at_s,
            "clicked_after_s": None if clicked is None else clicked - start,
            "stop_s": None if (clicked is None or ended is None) else ended - clicked,
            "left": sorted(os.listdir(folder)), "log_tail": log[-400:]}


def cancel_run(driver, alg_id, cloud, folder, stage, timeout):
    outs = outputs_for(fresh(folder))
    dlg = driver.dialog(alg_id, {"INPUT": cloud, "DTM_CELL": 1.0, **outs})
    key, delay = STAGES[stage]
    later = [STAGES[s][0] for s in ORDER[ORDER.index(stage) + 1:]]
    start = driver.press_run(dlg)
    seen_at, clicked, clicked_in = None, None, None
    while driver.ended is None and time.perf_counter() - start < timeout:
        driver.app.processEvents()
        text = driver.log_text(dlg)
        if seen_at is None and key in text:
            seen_at = time.perf_counter()
        if seen_at is not None and clicked is None and time.perf_counter() - seen_at >= delay:
            # still in the stage? (the next stage's line not in the log yet)
            clicked_in = stage if not any(k in text.split(key, 1)[1] for k in later) else "later"
            dlg.cancelButton().click()
            clicked = time.perf_counter()
            late = clicked - seen_at - delay
        time.sleep(0.01)
    ended = driver.ended
    driver.spin(0.5)
    log = driver.log_text(dlg)
    dlg.close()
    driver.spin(0.2)
    left = sorted(os.listdir(folder))
    return {"alg": alg_id, "kind": "cancel", "stage": stage, "clicked_in": clicked_in,
            "click_late_s": None if clicked is None else late,
            "clicked_after_s": None if clicked is None else clicked - start,
            "stop_s": None if (clicked is None or ended is None) else ended - clicked,
            "left": left, "log_tail": log[-400:]}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cloud", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--algs", default="smrf,csf")
    ap.add_argument("--stages", default=",".join(ORDER))
    ap.add_argument("--no-full", action="store_true")
    ap.add_argument("--at", default="", help="also cancel at these seconds after Run (e.g. 1,4,6,8)")
    ap.add_argument("--timeout", type=float, default=120.0)
    args = ap.parse_args()

    from qgis.core import QgsApplication
    app = QgsApplication([], True)
    app.initQgis()
    from processing.core.Processing import Processing
    Processing.initialize()
    from groundsieve.provider.provider import GroundSieveProvider
    provider = GroundSieveProvider()
    QgsApplication.processingRegistry().addProvider(provider)
    driver = Driver(app)
    results = []
    for alg in args.algs.split(","):
        alg_id = f"groundsieve:{alg}"
        if not args.no_full:
            results.append(full_run(driver, alg_id, args.cloud, os.path.join(args.work, alg, "full"), args.timeout))
            print(json.dumps(results[-1]), file=sys.stderr, flush=True)
        for stage in [s for s in args.stages.split(",") if s]:
            results.append(cancel_run(driver, alg_id, args.cloud, os.path.join(args.work, alg, stage), stage,
                                      args.timeout))
            print(json.dumps(results[-1]), file=sys.stderr, flush=True)
        for at_s in [float(t) for t in args.at.split(",") if t]:
            results.append(cancel_at(driver, alg_id, args.cloud, os.path.join(args.work, alg, f"at{at_s:g}"), at_s,
                                     args.timeout))
            print(json.dumps(results[-1]), file=sys.stderr, flush=True)
    print(json.dumps(results))
    QgsApplication.processingRegistry().removeProvider(provider)
    app.exitQgis()
    return 0


if __name__ == "__main__":
    sys.exit(main())
