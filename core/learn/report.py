"""The training report: an HTML page (shown in the Processing results viewer) and a CSV.

Pure text generation: the confusion matrix and the feature importances are inline SVG, so the
report needs no plotting library and opens in any browser.
"""
from __future__ import annotations

import contextlib
import csv
import html
import io
from typing import Dict, List, Optional, Sequence

import numpy as np

from ..io import atomic_path
from ..io.clouds import ASPRS_NAMES
from ..metrics import ClassReport


def class_name(code: int) -> str:
    return f"{code} {ASPRS_NAMES.get(int(code), '')}".strip()


def confusion_svg(report: ClassReport, size: int = 44) -> str:
    """The confusion matrix as an SVG heat map (row-normalised colours, counts in the cells)."""
    k = len(report.classes)
    cm = report.confusion
    rows = cm.sum(axis=1, keepdims=True)
    share = np.divide(cm, rows, out=np.zeros(cm.shape), where=rows > 0)
    left, top = 150, 110
    # the column labels lean 45 degrees to the right: room for the last one's length (about 0.6 em a
    # character at 11 px, times cos 45)
    lean = max(len(class_name(c)) for c in report.classes) * 11 * 0.6 * 0.71 if k else 0
    width, height = int(left + k * size - size / 2 + max(size / 2, lean) + 10), top + k * size + 10
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'font-family="sans-serif" font-size="11">',
             f'<text x="{left + k * size / 2}" y="14" text-anchor="middle" font-weight="bold">predicted</text>',
             f'<text x="12" y="{top + k * size / 2}" text-anchor="middle" font-weight="bold" '
             f'transform="rotate(-90 12 {top + k * size / 2})">reference</text>']
    for j, c in enumerate(report.classes):
        x = left + j * size + size / 2
        parts.append(f'<text x="{x}" y="{top - 6}" text-anchor="start" transform="rotate(-45 {x} {top - 6})">'
                     f'{html.escape(class_name(c))}</text>')
    for i, c in enumerate(report.classes):
        y = top + i * size
        parts.append(f'<text x="{left - 6}" y="{y + size / 2 + 4}" text-anchor="end">{html.escape(class_name(c))}</text>')
        for j in range(k):
            v = share[i, j]
            light = int(255 - 200 * v)  # white (0 %) to dark blue (100 % of the reference class)
            colour = f"rgb({light},{light},255)"
            parts.append(f'<rect x="{left + j * size}" y="{y}" width="{size}" height="{size}" fill="{colour}" '
                         f'stroke="#fff"/>')
            ink = "#fff" if v > 0.55 else "#000"
            parts.append(f'<text x="{left + j * size + size / 2}" y="{y + size / 2 + 4}" text-anchor="middle" '
                         f'fill="{ink}">{cm[i, j]}</text>')
    parts.append("</svg>")
    return "".join(parts)


def bars_svg(names: Sequence[str], values: Sequence[float], width: int = 520) -> str:
    """A horizontal bar chart (feature importances)."""
    values = np.asarray(values, dtype=float)
    scale = max(float(np.nanmax(np.abs(values))) if values.size else 0.0, 1e-12)
    row, left = 18, 190
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{row * len(names) + 6}" '
             f'font-family="sans-serif" font-size="11">']
    for i, (name, v) in enumerate(zip(names, values)):
        w = max(0.0, (width - left - 60) * (v / scale))
        y = i * row + 3
        parts.append(f'<text x="{left - 6}" y="{y + 12}" text-anchor="end">{html.escape(str(name))}</text>')
        parts.append(f'<rect x="{left}" y="{y}" width="{w:.1f}" height="{row - 5}" fill="#4a7ab5"/>')
        parts.append(f'<text x="{left + w + 4:.1f}" y="{y + 12}">{v:.4f}</text>')
    parts.append("</svg>")
    return "".join(parts)


def _report_table(report: ClassReport) -> str:
    rows = ["<table><tr><th>class</th><th>precision</th><th>recall</th><th>F1</th><th>support</th></tr>"]
    for c, p, r, f, s in report.rows():
        rows.append(f"<tr><td>{html.escape(class_name(c))}</td><td>{p:.3f}</td><td>{r:.3f}</td>"
                    f"<td>{f:.3f}</td><td>{s:,}</td></tr>")
    rows.append(f"<tr><th>overall accuracy</th><td></td><td></td><td>{report.accuracy:.3f}</td>"
                f"<td>{int(report.support.sum()):,}</td></tr>")
    rows.append(f"<tr><th>weighted average</th><td>{report.weighted(report.precision):.3f}</td>"
                f"<td>{report.weighted(report.recall):.3f}</td><td>{report.weighted(report.f1):.3f}</td><td></td></tr>")
    rows.append("</table>")
    return "".join(rows)


def write_report(path: str, *, title: str, evaluations: Dict[str, ClassReport], features: List[str],
                 impurity: Sequence[float], permutation: Optional[Sequence[float]], timings: Dict[str, float],
                 settings: Dict[str, object], notes: Sequence[str] = (), grid: Optional[List[dict]] = None,
                 csv_path: Optional[str] = None, atomic: bool = True) -> None:
    """Write the HTML report to ``path`` and the same figures as CSV beside it (``.csv``, or
    ``csv_path``), each atomically unless the caller already writes to temporary paths of its own
    (``atomic=False``, e.g. to commit them together with a model file)."""
    out = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title><style>"
           "body{font-family:sans-serif;margin:1.5em;max-width:60em}table{border-collapse:collapse;margin:.5em 0}"
           "td,th{border:1px solid #bbb;padding:.25em .6em;text-align:right}th:first-child,td:first-child"
           "{text-align:left}</style></head><body>", f"<h1>{html.escape(title)}</h1>"]
    out.append("<h2>Settings</h2><table>" + "".join(
        f"<tr><td>{html.escape(str(k))}</td><td>{html.escape(str(v))}</td></tr>" for k, v in settings.items())
        + "</table>")
    for note in notes:
        out.append(f"<p>{html.escape(note)}</p>")
    for name, report in evaluations.items():
        out.append(f"<h2>{html.escape(name)}</h2>{_report_table(report)}{confusion_svg(report)}")
    out.append("<h2>Feature importances</h2><h3>Impurity (mean decrease, from training)</h3>")
    out.append(bars_svg(features, impurity))
    if permutation is not None:
        out.append("<h3>Permutation (drop in accuracy when the feature is shuffled)</h3>")
        out.append(bars_svg(features, permutation))
    if grid:
        out.append("<h2>Parameter grid (validation set)</h2><table><tr><th>criterion</th><th>trees</th>"
                   "<th>scaler</th><th>accuracy</th><th>weighted F1</th><th>seconds</th></tr>")
        for g in grid:
            out.append(f"<tr><td>{g['criterion']}</td><td>{g['n_trees']}</td><td>{g['scaler']}</td>"
                       f"<td>{g['accuracy']:.4f}</td><td>{g['f1']:.4f}</td><td>{g['seconds']:.1f}</td></tr>")
        out.append("</table>")
    out.append("<h2>Timings (s)</h2><table>" + "".join(
        f"<tr><td>{html.escape(k)}</td><td>{v:.2f}</td></tr>" for k, v in timings.items()) + "</table>")
    out.append("</body></html>")
    with (atomic_path(path) if atomic else contextlib.nullcontext(path)) as tmp:
        with open(tmp, "w", encoding="utf-8") as handle:
            handle.write("\n".join(out))
    csv_path = csv_path or report_csv_path(path)
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(["set", "class", "precision", "recall", "f1", "support"])
    for name, report in evaluations.items():
        for c, p, r, f, s in report.rows():
            writer.writerow([name, c, f"{p:.5f}", f"{r:.5f}", f"{f:.5f}", s])
        writer.writerow([name, "overall_accuracy", "", "", f"{report.accuracy:.5f}", int(report.support.sum())])
        writer.writerow([name, "weighted_average", f"{report.weighted(report.precision):.5f}",
                         f"{report.weighted(report.recall):.5f}", f"{report.weighted(report.f1):.5f}", ""])
    writer.writerow([])
    writer.writerow(["feature", "impurity_importance", "permutation_importance"])
    for i, name in enumerate(features):
        writer.writerow([name, f"{impurity[i]:.6f}", "" if permutation is None else f"{permutation[i]:.6f}"])
    with (atomic_path(csv_path) if atomic else contextlib.nullcontext(csv_path)) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as handle:
            handle.write(buffer.getvalue())


def report_csv_path(path: str) -> str:
    """The CSV written beside the HTML report ``path``."""
    return str(path).rsplit(".", 1)[0] + ".csv"
