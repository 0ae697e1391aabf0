"""The HTML report of ``groundsieve:tune``: one self-contained file (inline SVG plots drawn here,
nothing downloaded) for the Processing results viewer or a browser: the honest (cross-validated)
figure, the chosen parameters, the confusion matrices, the sensitivity of the score to each
parameter, the folds, and every set tried."""
from __future__ import annotations

import html
import math
from typing import List, Sequence, Tuple

from ..io.outputs import atomic_path
from . import parameters as P
from .tune import METRIC_LABELS, TuneResult, accuracy, score

W, H = 340, 220
PAD_L, PAD_R, PAD_T, PAD_B = 52, 12, 14, 40


SELECTION_NOTE = (" Sets chosen by the one-standard-error rule: of the sets within one standard error of the"
                  " lowest error on the blocks they are chosen on, the one nearest the starting set.")


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "on" if v else "off"
    if isinstance(v, float):
        return f"{v:.4g}"
    return html.escape(str(v))


def _pct(v: float) -> str:
    return f"{100 * v:.2f} %"


def _ticks(lo: float, hi: float, n: int = 5) -> List[float]:
    if hi <= lo:
        return [lo]
    raw = (hi - lo) / n
    mag = 10 ** math.floor(math.log10(raw))
    step = min((m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw), default=raw)
    start = math.ceil(lo / step) * step
    out, v = [], start
    while v <= hi + 1e-9 * step:
        out.append(round(v, 10))
        v += step
    return out


def _frame(xs, ys, categories: Sequence[str] = ()):
    """The plot's data ranges (padded) and its plot area in pixels: x0, x1, y0, y1, width, height."""
    if categories:
        x0, x1 = -0.5, len(categories) - 0.5
    else:
        x0, x1 = min(xs), max(xs)
        if x1 == x0:
            x0, x1 = x0 - 1, x1 + 1
        pad = 0.03 * (x1 - x0)
        x0, x1 = x0 - pad, x1 + pad
    y0, y1 = min(ys), max(ys)
    if y1 == y0:
        y0, y1 = y0 - 0.5, y1 + 0.5
    pad = 0.05 * (y1 - y0)
    return x0, x1, y0 - pad, y1 + pad, W - PAD_L - PAD_R, H - PAD_T - PAD_B


def scatter_svg(points: Sequence[Tuple[float, float, str]], xlabel: str, ylabel: str,
                categories: Sequence[str] = ()) -> str:
    """An SVG scatter plot; points (x, y, css class: "", "best" or "start"); with ``categories``
    x is the category's index."""
    xs = [p[0] for p in points]
    ys = [p[1] for p in points]
    x0, x1, y0, y1, pw, ph = _frame(xs, ys, categories)

    def px(x):
        return PAD_L + (x - x0) / (x1 - x0) * pw

    def py(y):
        return PAD_T + (1 - (y - y0) / (y1 - y0)) * ph
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" '
           f'font-family="sans-serif" font-size="10">',
           f'<rect x="{PAD_L}" y="{PAD_T}" width="{pw}" height="{ph}" fill="#fafafa" stroke="#999"/>']
    for t in _ticks(y0, y1):
        out.append(f'<line x1="{PAD_L - 3}" x2="{PAD_L + pw}" y1="{py(t):.1f}" y2="{py(t):.1f}" stroke="#e4e4e4"/>'
                   f'<text x="{PAD_L - 5}" y="{py(t) + 3:.1f}" text-anchor="end">{t:g}</text>')
    if categories:
        xt = [(i, c) for i, c in enumerate(categories)]
    else:
        xt = [(t, f"{t:g}") for t in _ticks(x0, x1)]
    for t, label in xt:
        out.append(f'<line x1="{px(t):.1f}" x2="{px(t):.1f}" y1="{PAD_T + ph}" y2="{PAD_T + ph + 3}" stroke="#666"/>'
                   f'<text x="{px(t):.1f}" y="{PAD_T + ph + 14}" text-anchor="middle">{html.escape(label)}</text>')
    out.append(f'<text x="{PAD_L + pw / 2:.0f}" y="{H - 6}" text-anchor="middle" font-size="11">'
               f'{html.escape(xlabel)}</text>')
    out.append(f'<text x="12" y="{PAD_T + ph / 2:.0f}" text-anchor="middle" font-size="11" '
               f'transform="rotate(-90 12 {PAD_T + ph / 2:.0f})">{html.escape(ylabel)}</text>')
    style = {"": ('r="2.5" fill="#3c78b4" fill-opacity="0.55"'),
             "start": 'r="4.5" fill="none" stroke="#222" stroke-width="1.5"',
             "best": 'r="5" fill="#d62728" stroke="#700" stroke-width="1"'}
    for kind in ("", "start", "best"):
        for x, y, k in points:
            if k == kind:
                out.append(f'<circle cx="{px(x):.1f}" cy="{py(y):.1f}" {style[k]}/>')
    out.append("</svg>")
    return "".join(out)


def line_svg(ys: Sequence[float], running: Sequence[float], xlabel: str, ylabel: str) -> str:
    """Score per set (dots) and the best so far (line)."""
    svg = scatter_svg([(i + 1, y, "") for i, y in enumerate(ys)], xlabel, ylabel)
    # the running best as a polyline in the same frame as the dots
    xs = list(range(1, len(ys) + 1))
    x0, x1, y0, y1, pw, ph = _frame(xs, ys)
    pts = " ".join(f"{PAD_L + (x - x0) / (x1 - x0) * pw:.1f},{PAD_T + (1 - (y - y0) / (y1 - y0)) * ph:.1f}"
                   for x, y in zip(xs, running))
    return svg.replace("</svg>", f'<polyline points="{pts}" fill="none" stroke="#d62728" stroke-width="1.5"/></svg>')


def _confusion(a, title: str) -> str:
    return (f'<table class="cm"><caption>{html.escape(title)}</caption>'
            f'<tr><th></th><th>called ground</th><th>called non-ground</th></tr>'
            f'<tr><th>ground</th><td>{a.tp:,}</td><td class="err">{a.fn:,}</td></tr>'
            f'<tr><th>non-ground</th><td class="err">{a.fp:,}</td><td>{a.tn:,}</td></tr></table>'
            f'<p class="small">Type I {_pct(a.type1)}, Type II {_pct(a.type2)}, total {_pct(a.total)}, '
            f'kappa {_pct(a.kappa)}, F1 (ground) {_pct(a.f1)}</p>')


def report_html(result: TuneResult) -> str:
    metric = result.metric
    label = METRIC_LABELS[metric]
    unit = "%"
    cls_name = P.FILTERS[result.filter][1]
    names = {d.field: d.name for d in result.dims}
    table = P.by_name(result.filter)
    ok = [i for i, t in enumerate(result.trials) if t.counts is not None]

    def value_of(i):
        return 100 * score(result.trials[i].counts.sum(axis=0), metric)
    cv, fit, start = result.cv, result.best_accuracy, result.start_accuracy
    parts = [f"""<!DOCTYPE html><html><head><meta charset="utf-8">
<title>GroundSieve tune: {html.escape(cls_name)} on {html.escape(result.patch)}</title>
<style>
body {{ font-family: sans-serif; margin: 1.2em; color: #222; max-width: 1100px; }}
h1 {{ font-size: 1.35em; }} h2 {{ font-size: 1.1em; margin-top: 1.4em; border-bottom: 1px solid #ccc; }}
table {{ border-collapse: collapse; margin: .4em 0; }} td, th {{ border: 1px solid #ccc; padding: 2px 7px; }}
td {{ text-align: right; }} th {{ background: #f0f0f0; }} .err {{ color: #b00; }}
.cm {{ display: inline-table; margin-right: 2em; vertical-align: top; }} caption {{ font-weight: bold; }}
.small {{ font-size: .9em; color: #444; }} .plots svg {{ margin: 4px 8px 4px 0; }}
.big {{ font-size: 1.15em; }} tr.best td {{ background: #fde2e2; }} .warn {{ background: #fff4d6; padding: 4px 8px; }}
</style></head><body>
<h1>Tuning of {html.escape(cls_name)} on {html.escape(result.patch)}</h1>
<p>{result.points:,} labelled points, {len(result.trials)} parameter sets tried
({result.runs} filter runs, budget {result.budget}) in
{result.seconds:.0f} s, optimising the {html.escape(label)}; {len(result.folds)} spatial blocks
({result.block_grid[0]} x {result.block_grid[1]}; points per block: {", ".join(f"{s:,}" for s in result.block_sizes)})
for the cross-validation.{SELECTION_NOTE if result.selection == "one-se" else ""}{" Stopped early: " + html.escape(result.stopped) + "." if result.stopped else ""}</p>
<p class="big"><b>Cross-validated total error {_pct(cv.total)}</b> (kappa {_pct(cv.kappa)}, F1 {_pct(cv.f1)}): each
block classified with the set chosen without it. This is what to expect on similar data. The chosen set on the
whole patch: total error {_pct(fit.total)} (in-sample, optimistic){"" if start is None else
f"; the starting set (filter defaults or starting preset): {_pct(start.total)}"}.</p>
<h2>Chosen parameters (saved in the preset)</h2>
<table><tr><th>Parameter</th><th>Processing name</th><th>Value</th><th>Start</th><th>Searched range</th></tr>"""]
    best_values = result.best_values
    ranges = {d.field: d for d in result.dims}
    for p in P.params(result.filter):
        d = ranges.get(p.field)
        rng = "" if d is None else (" / ".join(_fmt(v) for v in d.values) if d.values else
                                    f"{_fmt(d.low)} to {_fmt(d.high)}")
        parts.append(f"<tr><td style='text-align:left'>{html.escape(p.title())}</td><td>{p.name}</td>"
                     f"<td><b>{_fmt(best_values[p.field])}</b></td><td>{_fmt(result.fixed[p.field])}</td>"
                     f"<td>{rng or 'kept'}</td></tr>")
    parts.append("</table>")
    for title, text in result.warnings:
        parts.append(f"<p class='warn'><b>{html.escape(title)}:</b> {html.escape(text)}</p>")
    parts.append("<h2>Confusion matrices</h2>")
    parts.append(_confusion(cv, "Cross-validated (held-out blocks)"))
    parts.append(_confusion(fit, "Chosen set on the whole patch"))
    if start is not None:
        parts.append(_confusion(start, "Starting set on the whole patch"))
    parts.append(f"<h2>Sensitivity: {html.escape(label)} of each set against each parameter</h2>"
                 f"<p class='small'>Each dot is one set (whole patch); red: the chosen set; ring: the starting set. "
                 f"A flat cloud means the parameter matters little on this patch. The last plot: each set in the "
                 f"order tried, and the line the best so far.</p><div class='plots'>")
    for d in result.dims:
        pts = []
        for i in ok:
            v = result.trials[i].values[d.field]
            x = list(d.values).index(v) if d.values else float(v)
            kind = "best" if i == result.best else ("start" if i == result.default_trial else "")
            pts.append((x, value_of(i), kind))
        title = table[d.name].title() if d.name in table else d.name
        parts.append(scatter_svg(pts, title, f"{label} ({unit})", [_fmt(v) for v in d.values]))
    ys = [value_of(i) for i in ok]
    lower = metric == "total"
    running, cur = [], None
    for y in ys:
        cur = y if cur is None else (min(cur, y) if lower else max(cur, y))
        running.append(cur)
    parts.append(line_svg(ys, running, "set number (design, then refinement)", f"{label} ({unit})"))
    parts.append("</div><h2>Cross-validation folds</h2><table><tr><th>Held-out block</th><th>points</th>"
                 "<th>set chosen on the other blocks</th><th>held-out total error</th><th>held-out kappa</th></tr>")
    for f in result.folds:
        vals = ", ".join(f"{names[k]} {_fmt(v)}" for k, v in result.trials[f.chosen].values.items())
        parts.append(f"<tr><td>{f.block + 1}</td><td>{result.block_sizes[f.block]:,}</td>"
                     f"<td style='text-align:left'>#{f.chosen + 1}: {vals}</td><td>{_pct(f.held_out.total)}</td>"
                     f"<td>{_pct(f.held_out.kappa)}</td></tr>")
    shown = 300
    best_of = f" (the best {shown} of {len(result.trials)})" if len(result.trials) > shown else ""
    parts.append(f"</table><h2>Sets tried{best_of}"
                 f"</h2><p class='small'>{result.runs} filter runs; sets differing only in "
                 f"{', '.join(P.CHEAP.get(result.filter, ())) or 'nothing'} re-scored on a run's surface.</p>"
                 "<table><tr><th>#</th><th>phase</th>"
                 + "".join(f"<th>{d.name}</th>" for d in result.dims)
                 + "<th>total error</th><th>kappa</th><th>F1</th><th>seconds</th></tr>")
    order = sorted(range(len(result.trials)), key=lambda i: (result.trials[i].loss(metric), i))
    for i in order[:shown]:
        t = result.trials[i]
        cells = "".join(f"<td>{_fmt(t.values[d.field])}</td>" for d in result.dims)
        if t.counts is None:
            res = f"<td colspan='3' class='err'>failed: {html.escape(t.error)}</td>"
        else:
            a = accuracy(t.counts.sum(axis=0))
            res = f"<td>{_pct(a.total)}</td><td>{_pct(a.kappa)}</td><td>{_pct(a.f1)}</td>"
        phase = t.phase if t.track < 0 else f"{t.phase} (block {t.track + 1} held out)"
        parts.append(f"<tr{' class=best' if i == result.best else ''}><td>{i + 1}</td>"
                     f"<td style='text-align:left'>{phase}</td>{cells}{res}<td>{t.seconds:.2f}</td></tr>")
    parts.append("</table><p class='small'>GroundSieve groundsieve:tune. Design: Halton points over ranges spanning "
                 "the values the papers used or studied, wider where a paper gives one setting or few "
                 "(core/engine/parameters.py SEARCH); refinement: pattern search.</p>"
                 "</body></html>\n")
    return "\n".join(parts)


def write_report(path: str, result: TuneResult) -> None:
    text = report_html(result)
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
