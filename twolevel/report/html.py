"""One self-contained ``report.html``: figures embedded as base64 PNG, styles inline, and no
reference to anything outside the file (no CDN, no remote font, no link to a sibling file)."""

from __future__ import annotations

import base64
import html
from typing import Any, Mapping, Sequence

from twolevel.report.figures import RenderedFigure
from twolevel.report.comparison import ComparisonTable
from twolevel.report.metrics import DECISION_LEVEL, Metrics
from twolevel.report.summary import (
    COLLISION_HEADER, alerts, collision_rows, comparison_rows, fmt, headline, pct, provenance, provenance_text,
)

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;margin:2em auto;max-width:1100px;color:#222;padding:0 1em}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0;font-size:.92em}td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left;vertical-align:top}
th{background:#f2f2f2}td.num{text-align:right;font-variant-numeric:tabular-nums}
.alert{background:#fde2e1;border:2px solid #c0392b;color:#7b1d14;padding:.6em 1em;margin:.5em 0;font-weight:600}
.warn{background:#fff6d6;border:1px solid #d4a017;padding:.5em 1em;margin:.5em 0}
.ok{background:#e6f4e6;border:1px solid #2c8a2c;padding:.5em 1em;margin:.5em 0}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #eee}figcaption{font-size:.85em;color:#555}
code{background:#f4f4f4;padding:0 .2em}.prov td:last-child{font-family:ui-monospace,monospace;font-size:.85em;word-break:break-all}
"""


def _e(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], *, numeric_from: int = 1, cls: str = "") -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = []
    for r in rows:
        cells = "".join(f'<td class="num">{_e(c)}</td>' if k >= numeric_from else f"<td>{_e(c)}</td>" for k, c in enumerate(r))
        body.append(f"<tr>{cells}</tr>")
    klass = f' class="{cls}"' if cls else ""
    return f"<table{klass}><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _run_row(m: Metrics, meta: Mapping[str, Any]) -> tuple[str, ...]:
    settings = meta.get("settings") if isinstance(meta.get("settings"), Mapping) else {}
    scen = meta.get("scenario")
    return (m.label, m.run_dir, str(meta.get("status", "unknown")), str(settings.get("controller", "—")),
            str(settings.get("monitor", "—")), str(scen.get("name") if isinstance(scen, Mapping) else scen or "—"),
            str(meta.get("seed", "—")), str(m.rows))


def _verdict_section(meta: Mapping[str, Any]) -> str:
    from twolevel.report.verdict import CRITERIA_HEADER, criteria_rows, goal_status, ride_line, verdict_line, verdict_of

    verdict = verdict_of(meta)
    klass = "warn" if verdict is None else ("ok" if verdict.passed else "alert")
    parts = ["<h2>Verdict</h2>", f'<div class="{klass}">{_e(verdict_line(verdict))}</div>',
             f"<p><strong>Goal:</strong> {_e(goal_status(verdict))}</p>"]
    if ride_line(meta):
        parts.append(f"<p><strong>Ride:</strong> {_e(ride_line(meta))}</p>")
    rows = criteria_rows(verdict)
    if rows:
        parts.append(_table(CRITERIA_HEADER, rows, numeric_from=2))
        parts.append("<p>Margin: how far a criterion is from failing, in the unit of its bound (&lt; 0 fails).</p>")
    return "".join(parts)


def _latency_table(m: Metrics) -> str:
    if m.latency is None:
        return ""
    rows = []
    for level, d in (("total step", m.latency.total), ("high level", m.latency.high), ("low level", m.latency.low)):
        rows.append((level, str(d.n), fmt(d.p50, 2), fmt(d.p95, 2), fmt(d.p99, 2), fmt(d.max, 2), fmt(d.mean, 2)))
    return "<h3>Control-step latency [ms]</h3>" + _table(("level", "steps", "p50", "p95", "p99", "max", "mean"), rows)


def _rules_section(m: Metrics) -> str:
    parts = ["<h2>Rules and violations</h2>"]
    if m.rules:
        parts.append(_table(
            ("rule", "min ρ", "at [s]", "ρ at t = 0", "final ρ", "violations", "time violated [s]"),
            [(r.rule, fmt(r.min), fmt(r.t_min, 2), fmt(r.initial), fmt(r.final), str(r.violations), fmt(r.time_violated_s, 2)) for r in m.rules],
        ))
    else:
        parts.append("<p>The trace records no rule robustness.</p>")
    if m.violations:
        parts.append(f"<h3>Every violation ({len(m.violations)})</h3>")
        parts.append(_table(
            ("rule", "from [s]", "to [s]", "steps", "depth (most negative ρ)", "deepest at [s]"),
            [(v.rule, fmt(v.t_start, 2), fmt(v.t_end, 2), str(v.steps), fmt(v.depth), fmt(v.t_depth, 2)) for v in m.violations],
        ))
    elif m.rules:
        parts.append('<p class="ok">No violation: every rule\'s robustness stayed ≥ 0 at every step.</p>')
    return "".join(parts)


def _collisions_section(m: Metrics) -> str:
    c = m.collisions
    parts = ["<h2>Collisions</h2>"]
    if not c.collided:
        parts.append('<p class="ok">No collision: the boxes never overlapped and the simulator recorded none.</p>')
        return "".join(parts)
    if c.episodes:
        parts.append("<h3>Box overlaps in the trace (min_gap &lt; 0)</h3>")
        parts.append(_table(("from [s]", "to [s]", "deepest overlap [m]", "x [m]", "y [m]"),
                            [(fmt(e.t_start, 2), fmt(e.t_end, 2), fmt(e.depth_m), fmt(e.x, 2), fmt(e.y, 2)) for e in c.episodes], numeric_from=0))
    if c.reported:
        parts.append("<h3>Recorded by the simulator (run.json)</h3>")
        parts.append(_table(COLLISION_HEADER, collision_rows(c.reported), numeric_from=0))
    return "".join(parts)


def _other_tables(m: Metrics) -> str:
    parts = []
    if m.decisions is not None:
        parts.append("<h3>Decisions by level</h3>")
        rows = [(d, DECISION_LEVEL.get(d, "other"), str(n), pct(s)) for (d, n), (_, s) in zip(m.decisions.counts, m.decisions.shares)]
        parts.append(_table(("decision", "level", "steps", "share"), rows, numeric_from=2))
    if m.lights is not None:
        parts.append("<h3>Traffic-light state ahead</h3>")
        rows = [(s, fmt(tm, 2), pct(sh)) for (s, tm), (_, sh) in zip(m.lights.time_s, m.lights.shares)]
        parts.append(_table(("state", "time [s]", "share"), rows))
    return "".join(parts)


def _figures_section(figures: Sequence[RenderedFigure]) -> str:
    if not figures:
        return ""
    parts = ["<h2>Figures</h2>"]
    for f in figures:
        data = base64.b64encode(f.png).decode("ascii")
        names = ", ".join(_e(p.rsplit("/", 1)[-1]) for p in f.files)
        parts.append(
            f'<figure id="fig-{_e(f.name)}"><img alt="{_e(f.title)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{_e(f.title)}{' — files: ' + names if names else ''}</figcaption></figure>"
        )
    return "".join(parts)


def _animation_section(gif: bytes | None, note: str | None) -> str:
    parts = ["<h2>Animation</h2>"] if gif or note else []
    if gif:
        data = base64.b64encode(gif).decode("ascii")
        parts.append(f'<figure><img alt="top-down animation of the run" src="data:image/gif;base64,{data}">'
                     "<figcaption>Top view centred on the ego (blue; outlined red while the boxes overlap) with its plan (orange), nearby vehicles (grey), the travelled path (light blue), lane centre lines (dashed) and the lights (coloured dots).</figcaption></figure>")
    if note:
        parts.append(f'<p class="warn">{_e(note)}</p>')
    return "".join(parts)


def render_html(
    metrics: Metrics,
    meta: Mapping[str, Any],
    figures: Sequence[RenderedFigure] = (),
    *,
    comparison: ComparisonTable | None = None,
    compared: Sequence[tuple[Metrics, Mapping[str, Any]]] = (),
    problems: Sequence[str] = (),
    gif: bytes | None = None,
    gif_note: str | None = None,
    version: str = "",
) -> str:
    """The whole page as one string."""
    scen = meta.get("scenario")
    name = scen.get("name") if isinstance(scen, Mapping) else scen
    title = f"twolevel report — {name or metrics.label}"
    body = [f"<h1>{_e(title)}</h1>", f"<p>Run directory <code>{_e(metrics.run_dir)}</code>, label <code>{_e(metrics.label)}</code>.</p>"]
    body += [f'<div class="alert">{_e(a)}</div>' for a in alerts(metrics, meta)]
    if problems:
        items = "".join(f"<li>{_e(p)}</li>" for p in problems)
        body.append(f'<div class="warn"><strong>This report is partial or has caveats:</strong><ul>{items}</ul></div>')
    body.append(_verdict_section(meta))
    body.append("<h2>Summary</h2>" + _table(("metric", "value"), headline(metrics)))
    body.append(_latency_table(metrics))
    body.append(_rules_section(metrics))
    body.append(_collisions_section(metrics))
    body.append(_other_tables(metrics))
    if comparison is not None:
        body.append("<h2>Comparison</h2>")
        runs = [(metrics, meta), *compared]
        body.append(_table(("run", "directory", "status", "controller", "monitor", "scenario", "seed", "steps"),
                           [_run_row(m, mt) for m, mt in runs], numeric_from=99))
        body.append("<p>Values per run; in brackets the ratio to the first run.</p>")
        body.append(_table(("metric", *comparison.runs), comparison_rows(comparison)))
    body.append(_figures_section(figures))
    body.append(_animation_section(gif, gif_note))
    prov = [(k, provenance_text(v)) for k, v in provenance(meta)]
    body.append("<h2>Settings and provenance</h2>" + (_table(("run.json", "value"), prov, numeric_from=99, cls="prov") if prov else "<p>run.json is missing: settings and provenance unknown.</p>"))
    body.append(f"<p><small>Generated by twolevel {_e(version)} from this run directory's trace.csv and run.json.</small></p>")
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>\n" + "\n".join(b for b in body if b) + "\n</body></html>\n"
    )
