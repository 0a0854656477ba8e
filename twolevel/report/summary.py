"""The report's text forms: headline rows, provenance, ``summary.json`` and ``summary.md``.

Shared by the HTML page (``html.py``) so the page and the summaries always say the same numbers.
"""

from __future__ import annotations

import json
import math
from typing import Any, Mapping, Sequence

from twolevel.report.comparison import ComparisonTable
from twolevel.report.metrics import COLLISION_LINE_M, DECISION_LEVEL, Metrics, ReportedCollision, _jsonable

#: run.json keys shown in the provenance table, in order (the rest are listed after them).
PROVENANCE_KEYS = ("scenario", "status", "error", "rows", "seed", "settings", "rules", "versions", "wall_time_s")
#: run.json keys never shown (bulky geometry or id lists, or shown elsewhere).
HIDDEN_KEYS = frozenset({"map_lines", "summary", "verdict", "road_edges", "ride", "participants"})


def fmt(value: Any, digits: int = 3, unit: str = "") -> str:
    """A number for people: None/NaN → '—', ±inf → '∞', floats with ``digits`` decimals."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value}{' ' + unit if unit else ''}"
    try:
        f = float(value)
    except (TypeError, ValueError):
        return str(value)
    if math.isnan(f):
        return "—"
    if math.isinf(f):
        return "∞" if f > 0 else "−∞"
    text = f"{f:.{digits}f}"
    return f"{text} {unit}" if unit else text


def pct(share: float | None) -> str:
    return "—" if share is None or (isinstance(share, float) and math.isnan(share)) else f"{100.0 * share:.1f} %"


def headline(m: Metrics) -> list[tuple[str, str]]:
    """The numbers a reader looks at first, as (label, formatted value) rows."""
    rows: list[tuple[str, str]] = [
        ("steps", fmt(m.rows)),
        ("simulated time", fmt(m.duration_s, 2, "s")),
        ("time step", fmt(m.dt_s, 3, "s")),
    ]
    if m.rate is not None:
        rows += [("control rate, median / lowest", f"{fmt(m.rate.hz.p50, 1)} / {fmt(m.rate.hz.min, 1)} Hz")]
    if m.latency is not None:
        lt = m.latency.total
        rows += [
            ("control step p50 / p95 / p99 / max", f"{fmt(lt.p50, 2)} / {fmt(lt.p95, 2)} / {fmt(lt.p99, 2)} / {fmt(lt.max, 2)} ms"),
            ("steps over 100 ms", f"{m.latency.steps_over_budget} ({pct(m.latency.share_over_budget)})"),
        ]
    if m.tracking is not None:
        rows += [("tracking error, max / mean", f"{fmt(m.tracking.max_m)} / {fmt(m.tracking.mean_m)} m")]
    if m.speed is not None:
        rows += [
            ("speed, max / mean", f"{fmt(m.speed.max_mps, 2)} / {fmt(m.speed.mean_mps, 2)} m/s"),
            ("overspeed, max", fmt(m.speed.max_overspeed_mps, 2, "m/s")),
            ("time over the limit", f"{fmt(m.speed.time_over_limit_s, 2, 's')} ({pct(m.speed.share_over_limit)})"),
        ]
    if m.distance is not None:
        d = m.distance
        rows += [
            ("min. distance (centre to centre)", f"{fmt(d.min_dist_m, 2, 'm')} at {fmt(d.t_min_dist_s, 1, 's')}"),
            (f"time below {COLLISION_LINE_M} m (paper's collision measure)", fmt(d.time_below_line_s, 2, "s")),
            ("min. box gap", f"{fmt(d.min_gap_m, 2, 'm')} at {fmt(d.t_min_gap_s, 1, 's')}"),
        ]
    if m.nearby is not None:
        rows += [("nearby vehicles, max / mean", f"{m.nearby.max} / {fmt(m.nearby.mean, 2)}")]
    if m.criticality is not None:
        c = m.criticality
        rows += [
            ("min. time to collision, vehicle ahead / anyone",
             f"{fmt(c.min_ttc_s, 2, 's')} at {fmt(c.t_min_ttc_s, 1, 's')} / {fmt(c.min_ttc_any_s, 2, 's')}"),
            ("min. time headway", f"{fmt(c.min_thw_s, 2, 's')} at {fmt(c.t_min_thw_s, 1, 's')}"),
            ("min. distance headway", f"{fmt(c.min_dhw_m, 2, 'm')} at {fmt(c.t_min_dhw_s, 1, 's')}"),
        ]
    rows += [
        ("rule violations", f"{len(m.violations)} in {sum(1 for r in m.rules if not r.satisfied)} of {len(m.rules)} rule(s)"),
        ("collisions", fmt(m.collisions.count) + (" — COLLIDED" if m.collisions.collided else "")
         + (f", {m.collisions.at_fault} the ego's fault" if m.collisions.reported else "")),
    ]
    if m.safety is not None:
        sf = m.safety
        rows += [
            ("safety layer", ", ".join(f"{o} {n}" for o, n in sf.outcomes if n) or "—"),
            ("time to react, min", fmt(sf.ttr_min_s, 2, "s")),
            ("peak deceleration", fmt(sf.decel_peak_mps2, 2, "m/s²")),
            (f"steps braking > {sf.hard_mps2:g} m/s²", pct(sf.hard_braking_share)),
        ]
    if m.decisions is not None:
        rows += [("decisions", ", ".join(f"{d} {pct(s)}" for d, s in m.decisions.shares if s > 0) or "—")]
    return rows


def alerts(m: Metrics, meta: Mapping[str, Any]) -> list[str]:
    """What must be said prominently: a run that did not complete, collisions, violations."""
    out = []
    status = meta.get("status")
    if status is not None and status != "complete":
        out.append(f"This run is {str(status).upper()} after {meta.get('rows', '?')} step(s): {meta.get('error', 'no reason recorded')}. The numbers cover only the steps recorded.")
    if any("truncated" in p for p in m.problems):
        out.append("The trace is TRUNCATED: its last row was cut short and ignored.")
    if m.rows == 0:
        out.append("No steps could be read: this report has no metrics or figures.")
    if m.collisions.collided:
        first = min([e.t_start for e in m.collisions.episodes] + [c.t for c in m.collisions.reported])
        fault = f"; {m.collisions.at_fault} the ego's fault" if m.collisions.reported else ""
        out.append(f"COLLISION: {m.collisions.count} collision(s), the first at t = {fmt(first, 2)} s{fault}.")
    if m.violations:
        rules = sorted({v.rule for v in m.violations})
        out.append(f"{len(m.violations)} rule violation(s) in {', '.join(rules)}.")
    return out


def provenance(meta: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """(key, value) rows of run.json worth showing, known keys first."""
    keys = [k for k in PROVENANCE_KEYS if k in meta] + [k for k in meta if k not in PROVENANCE_KEYS and k not in HIDDEN_KEYS]
    return [(k, meta[k]) for k in keys]


def provenance_text(value: Any) -> str:
    """A run.json value as one line of text."""
    if isinstance(value, (dict, list)):
        return json.dumps(_jsonable(value), sort_keys=False, separators=(", ", ": "))
    return str(value)


def summary_payload(
    metrics: Metrics,
    meta: Mapping[str, Any],
    *,
    compared: Sequence[Metrics] = (),
    comparison: ComparisonTable | None = None,
    files: Sequence[str] = (),
    problems: Sequence[str] = (),
    version: str = "",
) -> dict[str, Any]:
    """The content of ``summary.json``."""
    return {
        "report": {"generator": f"twolevel {version}".strip(), "files": list(files), "problems": list(problems)},
        "provenance": {k: _jsonable(v) for k, v in provenance(meta)},
        "verdict": meta.get("verdict"),
        "ride": meta.get("ride"),
        "metrics": metrics.to_dict(),
        "compared": [m.to_dict() for m in compared],
        "comparison": comparison.to_dict() if comparison is not None else None,
    }


COLLISION_HEADER = ("t [s]", "x [m]", "y [m]", "other", "ego at fault", "why")


def collision_rows(reported: Sequence[ReportedCollision]) -> list[tuple[str, ...]]:
    """The simulator's collisions as table rows (see :data:`COLLISION_HEADER`)."""
    return [(fmt(r.t, 2), fmt(r.x, 2), fmt(r.y, 2), r.other,
             "—" if r.at_fault is None else ("YES" if r.at_fault else "no"), r.reason or "—") for r in reported]


def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    esc = [[str(c).replace("|", "\\|") for c in r] for r in rows]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in esc]
    return "\n".join(lines)


def comparison_rows(table: ComparisonTable) -> list[list[str]]:
    """Rows of the comparison table: label, then value (ratio) per run."""
    out = []
    for r in table.rows:
        cells = [f"{r.label}{' [' + r.unit + ']' if r.unit else ''}"]
        for k, (v, q) in enumerate(zip(r.values, r.ratios)):
            cells.append(fmt(v) if k == 0 else f"{fmt(v)} (×{fmt(q, 2)})" if q is not None else fmt(v))
        out.append(cells)
    return out


def render_markdown(
    metrics: Metrics,
    meta: Mapping[str, Any],
    *,
    comparison: ComparisonTable | None = None,
    files: Sequence[str] = (),
    problems: Sequence[str] = (),
) -> str:
    """The content of ``summary.md``."""
    scen = meta.get("scenario")
    name = scen.get("name") if isinstance(scen, Mapping) else scen
    parts = [f"# twolevel run report: {name or metrics.label}", ""]
    for a in alerts(metrics, meta):
        parts.append(f"> **{a}**")
    if problems:
        parts += ["", "## Problems", ""] + [f"- {p}" for p in problems]
    from twolevel.report.verdict import CRITERIA_HEADER, criteria_rows, goal_status, ride_line, verdict_line, verdict_of

    verdict = verdict_of(meta)
    parts += ["", "## Verdict", "", verdict_line(verdict), "", f"Goal: {goal_status(verdict)}"]
    if ride_line(meta):
        parts += ["", f"Ride: {ride_line(meta)}"]
    if verdict is not None:
        parts += ["", _md_table(CRITERIA_HEADER, criteria_rows(verdict))]
    parts += ["", "## Headline", "", _md_table(("metric", "value"), headline(metrics))]
    if metrics.rules:
        parts += ["", "## Rules", "", _md_table(
            ("rule", "min ρ", "at [s]", "ρ at start", "violations", "time violated [s]"),
            [(r.rule, fmt(r.min), fmt(r.t_min, 2), fmt(r.initial), str(r.violations), fmt(r.time_violated_s, 2)) for r in metrics.rules],
        )]
    parts += ["", "## Violations", ""]
    parts.append(_md_table(
        ("rule", "from [s]", "to [s]", "steps", "depth (min ρ)", "deepest at [s]"),
        [(v.rule, fmt(v.t_start, 2), fmt(v.t_end, 2), str(v.steps), fmt(v.depth), fmt(v.t_depth, 2)) for v in metrics.violations],
    ) if metrics.violations else "None: every rule's robustness stayed ≥ 0.")
    c = metrics.collisions
    if c.collided:
        parts += ["", "## Collisions", ""]
        if c.episodes:
            parts.append(_md_table(("from [s]", "to [s]", "deepest overlap [m]", "x [m]", "y [m]"),
                                   [(fmt(e.t_start, 2), fmt(e.t_end, 2), fmt(e.depth_m), fmt(e.x, 2), fmt(e.y, 2)) for e in c.episodes]))
        if c.reported:
            parts += ["", "Recorded by the simulator:", "", _md_table(COLLISION_HEADER, collision_rows(c.reported))]
    if metrics.decisions is not None:
        parts += ["", "## Decisions", "", _md_table(("decision", "level", "steps", "share"),
                  [(d, DECISION_LEVEL.get(d, "other"), str(n), pct(s)) for (d, n), (_, s) in zip(metrics.decisions.counts, metrics.decisions.shares)])]
    if comparison is not None:
        parts += ["", "## Comparison (ratio to the first run)", "", _md_table(("metric", *comparison.runs), comparison_rows(comparison))]
    parts += ["", "## Provenance", "", _md_table(("key", "value"), [(k, provenance_text(v)) for k, v in provenance(meta)])]
    if files:
        parts += ["", "## Files", ""] + [f"- {f}" for f in files]
    return "\n".join(parts) + "\n"
