"""The HTML report of a DTM's accuracy check (core/raster/accuracy.py): one self-contained page (an
inline SVG histogram drawn here, nothing downloaded) for the Processing results viewer or a browser:
the figures of each land cover under both editions of the ASPRS standards, saying which figure
belongs to which edition, the warnings, the checkpoints skipped and every residual."""
from __future__ import annotations

import html
import math
from datetime import datetime, timezone
from typing import Optional

import numpy as np

from ..io.provenance import software
from .accuracy import (ED2_NOTE, MIN_CHECKPOINTS, MIN_CHECKPOINTS_ED2, NVA_FACTOR, OUTLIER_FACTOR, SIGN_CONVENTION, USED,
                       AccuracyResult, Figures, residual_rows)

NAMES = {"all": "All checkpoints used", "NVA": "NVA (non-vegetated)", "VVA": "VVA (vegetated)"}


def _num(value: Optional[float], signed: bool = False) -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value:+.4f}" if signed else f"{value:.4f}"


def _figures_row(f: Figures) -> str:
    ed1 = f"{_num(f.ed1_95)} <span class='small'>({html.escape(f.ed1_label)})</span>"
    ed2 = _num(f.rmse) if f.land_cover != "all" else "<span class='small'>(per land cover)</span>"
    return (f"<tr><th>{NAMES[f.land_cover]}</th><td>{f.count}</td><td>{_num(f.mean, True)}</td><td>{_num(f.std)}</td>"
            f"<td><b>{_num(f.rmse)}</b></td><td>{_num(f.min, True)}</td><td>{_num(f.max, True)}</td>"
            f"<td>{_num(f.p95_abs)}</td><td>{ed1}</td><td>{ed2}</td></tr>")


def histogram_svg(dz: np.ndarray, unit: str, width: int = 520, height: int = 220) -> str:
    """A histogram of the residuals, zero marked."""
    pad_l, pad_r, pad_t, pad_b = 44, 24, 12, 38
    lo, hi = float(dz.min()), float(dz.max())
    lo, hi = min(lo, 0.0), max(hi, 0.0)
    if hi - lo < 1e-9:
        lo, hi = lo - 0.5, hi + 0.5
    bins = int(min(30, max(5, math.ceil(math.sqrt(len(dz))))))
    counts, edges = np.histogram(dz, bins=bins, range=(lo, hi))
    pw, ph = width - pad_l - pad_r, height - pad_t - pad_b
    top = max(int(counts.max()), 1)

    def px(v):
        return pad_l + (v - lo) / (hi - lo) * pw
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" '
           'font-family="sans-serif" font-size="10">',
           f'<rect x="{pad_l}" y="{pad_t}" width="{pw}" height="{ph}" fill="#fafafa" stroke="#999"/>']
    for c, a, b in zip(counts, edges[:-1], edges[1:]):
        h = c / top * ph
        out.append(f'<rect x="{px(a):.1f}" y="{pad_t + ph - h:.1f}" width="{max(px(b) - px(a) - 1, 1):.1f}" '
                   f'height="{h:.1f}" fill="#3c78b4" fill-opacity="0.75"/>')
    out.append(f'<line x1="{px(0):.1f}" x2="{px(0):.1f}" y1="{pad_t}" y2="{pad_t + ph}" stroke="#d62728" '
               'stroke-width="1.5"/>')
    for v in np.linspace(lo, hi, 5):
        out.append(f'<text x="{px(v):.1f}" y="{pad_t + ph + 13}" text-anchor="middle">{v:.3g}</text>')
    out.append(f'<text x="{pad_l - 5}" y="{pad_t + 9}" text-anchor="end">{top}</text>'
               f'<text x="{pad_l - 5}" y="{pad_t + ph}" text-anchor="end">0</text>')
    out.append(f'<text x="{pad_l + pw / 2:.0f}" y="{height - 6}" text-anchor="middle" font-size="11">'
               f'dz = DTM - checkpoint z{f" ({html.escape(unit)})" if unit else ""}; red: 0</text>')
    out.append("</svg>")
    return "".join(out)


def _edition_lines(result: AccuracyResult, u: str) -> str:
    items = []
    for f in result.by_class():
        items.append(f"<li><b>{f.land_cover}</b>, ASPRS Edition 2 (2023): RMSEz = <b>{_num(f.rmse)}{u}</b> "
                     f"({f.count} checkpoints)</li>")
        items.append(f"<li><b>{f.land_cover}</b> at 95 %, ASPRS Edition 1 (2014): {html.escape(f.ed1_label)} = "
                     f"<b>{_num(f.ed1_95)}{u}</b></li>")
    if not items:
        items.append("<li>No land cover was given: NVA and VVA are not computed. The overall RMSEz is "
                     f"<b>{_num(result.overall.rmse)}{u}</b> (1.96 x RMSEz = {_num(NVA_FACTOR * result.overall.rmse)}{u}, "
                     f"the NSSDA's 95 % figure, which assumes normally distributed errors).</li>")
    return "<ul>" + "".join(items) + "</ul>"


def report_html(result: AccuracyResult) -> str:
    u = f" {html.escape(result.unit)}" if result.unit else ""
    hu = f" ({html.escape(result.unit)})" if result.unit else ""
    unit_text = html.escape(result.unit) if result.unit else "the DTM's own unit (not recorded in the file)"
    used = result.used
    parts = [f"""<!DOCTYPE html><html><head><meta charset="utf-8">
<title>GroundSieve: vertical accuracy of {html.escape(result.dtm)}</title>
<style>
body {{ font-family: sans-serif; margin: 1.2em; color: #222; max-width: 1100px; }}
h1 {{ font-size: 1.35em; }} h2 {{ font-size: 1.1em; margin-top: 1.4em; border-bottom: 1px solid #ccc; }}
table {{ border-collapse: collapse; margin: .4em 0; }} td, th {{ border: 1px solid #ccc; padding: 2px 7px; }}
td {{ text-align: right; }} th {{ background: #f0f0f0; }} td.l {{ text-align: left; }}
.small {{ font-size: .9em; color: #444; }} .warn {{ background: #fff4d6; padding: 4px 8px; margin: 3px 0; }}
tr.outlier td {{ background: #fde2e2; }} tr.skipped td {{ color: #888; }}
</style></head><body>
<h1>Vertical accuracy of {html.escape(result.dtm)}</h1>
<p class="small">{html.escape(software())}, {datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}. The DTM's
CRS: {html.escape(result.crs) if result.crs else "none recorded in the file"}.</p>
<p>Checkpoints: {html.escape(result.checkpoints)}. <b>{result.count}</b> of {len(result.ids)} used,
{len(result.skipped)} skipped (outside the DTM or on its nodata). Heights in {unit_text}.
<b>Sign: {html.escape(SIGN_CONVENTION)}</b>; a positive mean error is a DTM too high.</p>
<h2>Accuracy</h2>
{_edition_lines(result, u)}
<table><tr><th></th><th>n</th><th>mean error (bias){hu}</th><th>standard deviation{hu}</th><th>RMSEz{hu}</th>
<th>min dz{hu}</th><th>max dz{hu}</th><th>95th percentile of |dz|{hu}</th><th>Edition 1 (2014): 95 % figure{hu}</th>
<th>Edition 2 (2023): RMSEz{hu}</th></tr>"""]
    parts.append(_figures_row(result.overall))
    for f in result.by_class():
        parts.append(_figures_row(f))
    parts.append("</table>")
    parts.append("<p class='small'>ASPRS Positional Accuracy Standards for Digital Geospatial Data. Edition 1 (2014): "
                 f"non-vegetated vertical accuracy (NVA) at the 95 % confidence level = {NVA_FACTOR} x RMSEz, which "
                 "assumes normally distributed errors; vegetated vertical accuracy (VVA) at the 95th percentile of the "
                 "absolute errors, as vegetated errors need not be normal. Edition 2 (2023) dropped the 95 % figures: "
                 "NVA and VVA are each reported as their RMSEz; the RMSEz here is " + html.escape(ED2_NOTE) + ". The Edition 1 figure of all checkpoints together is "
                 "1.96 x RMSEz (the NSSDA's AccuracyZ). Standard deviation with n - 1; percentile by linear "
                 "interpolation between the sorted |dz|.</p>")
    if result.warnings:
        parts.append("<h2>Warnings</h2>")
        for text in result.warnings:
            parts.append(f"<p class='warn'>{html.escape(text)}</p>")
    parts.append("<h2>Residuals</h2>")
    parts.append(histogram_svg(result.dz[used], result.unit))
    parts.append(f"<p class='small'>Outliers (red rows): |dz| > {OUTLIER_FACTOR:g} x the RMSEz of the checkpoint's land "
                 "cover (of all checkpoints when it has none), named and kept in every figure. Skipped checkpoints "
                 "(grey rows) are in no figure. At least "
                 f"{MIN_CHECKPOINTS} checkpoints a land cover (ASPRS Edition 1; Edition 2 asks for {MIN_CHECKPOINTS_ED2}).</p>")
    _header, rows = residual_rows(result)
    header = ["id", "x", "y", f"checkpoint z{hu}", f"DTM z{hu}", f"dz = DTM - checkpoint{hu}", f"|dz|{hu}",
              "land cover", "sampling", "outlier"]
    parts.append("<table><tr>" + "".join(f"<th>{h}</th>" for h in header) + "</tr>")
    for row, status in zip(rows, result.status):
        kind = " class='outlier'" if row[-1] else (" class='skipped'" if status not in USED else "")
        cells = "".join(f"<td{' class=l' if k in (0, 7, 8) else ''}>{html.escape(str(v))}</td>" for k, v in enumerate(row))
        parts.append(f"<tr{kind}>{cells}</tr>")
    parts.append("</table>")
    parts.append("<h2>Method</h2><p class='small'>The DTM's height at each checkpoint is the bilinear interpolation "
                 "of the four cell centres around it (GDAL's geotransform: cell corners, pixel-is-area). When one of "
                 "the four is nodata or beyond the raster's edge, the value of the cell the checkpoint lies in is "
                 "taken (sampling 'cell'); when that cell is nodata too, or the checkpoint lies outside the raster, "
                 "the checkpoint is skipped. The checkpoints' heights are taken as they are: they must be in the "
                 "DTM's vertical datum and unit.</p>"
                 "<p class='small'>GroundSieve groundsieve:accuracy.</p></body></html>\n")
    return "\n".join(parts)
