"""The report of a campaign: ``report.html`` (self-contained) beside its results table.

Figures: the objective (robustness) against each parameter, runs that failed in red; the
objective over the simulations in the order they were run with its running minimum and the
first counterexample marked; for two parameters, the runs in the parameter plane coloured by
the objective. Tables: the counts (runs, failures, simulations to the first failure) and every
run that did not pass with its parameters, failed criteria and run directory.
"""

from __future__ import annotations

import base64
import html
import io
import math
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from twolevel.world.schema import Parameter

__all__ = ["write_campaign_report", "REPORT_FILE"]

REPORT_FILE = "report.html"
_RC = {"svg.hashsalt": "twolevel", "font.size": 9, "axes.grid": True, "grid.alpha": 0.3}


def _num(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _figures(rows: Sequence[Mapping[str, Any]], names: Sequence[str], key: str, first: int | None) -> list[tuple[str, str]]:
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    y = np.array([_num(r.get(key)) for r in rows])
    bad = np.array([r.get("outcome") != "passed" for r in rows])
    shown = np.clip(y, -1e3, 1e3)  # infinite margins (nothing to violate here) drawn at the edge
    out = []
    with matplotlib.rc_context(_RC):
        if names:
            fig = Figure(figsize=(4.0 * min(len(names), 3), 3.2), layout="constrained")
            FigureCanvasAgg(fig)
            axes = np.atleast_1d(fig.subplots(1, min(len(names), 3)))
            for ax, name in zip(axes, names):
                x = np.array([_num(r.get(f"p.{name}")) for r in rows])
                ax.scatter(x[~bad], shown[~bad], s=14, color="#1f77b4", label="passed")
                ax.scatter(x[bad], shown[bad], s=18, color="#d62728", marker="x", label="did not pass")
                ax.axhline(0.0, color="k", linestyle="--", linewidth=1.0)
                ax.set(xlabel=name, ylabel=key)
            axes[0].legend(loc="best", fontsize=8)
            out.append(("Robustness against each parameter", _png(fig)))
        fig = Figure(figsize=(8.0, 3.0), layout="constrained")
        FigureCanvasAgg(fig)
        ax = fig.subplots()
        idx = np.arange(1, len(rows) + 1)
        ax.plot(idx, shown, ".", color="#1f77b4", label=key)
        finite = np.where(np.isnan(shown), np.inf, shown)
        ax.step(idx, np.minimum.accumulate(finite), where="post", color="#ff7f0e", label="lowest so far")
        ax.axhline(0.0, color="k", linestyle="--", linewidth=1.0)
        if first is not None:
            ax.axvline(first, color="#d62728", label=f"first counterexample (run {first})")
        ax.set(xlabel="simulation", ylabel=key)
        ax.legend(loc="best", fontsize=8)
        out.append(("Robustness over the simulations", _png(fig)))
        if len(names) == 2:
            fig = Figure(figsize=(5.0, 4.0), layout="constrained")
            FigureCanvasAgg(fig)
            ax = fig.subplots()
            xs = [np.array([_num(r.get(f"p.{n}")) for r in rows]) for n in names]
            sc = ax.scatter(xs[0], xs[1], c=shown, cmap="RdYlGn", s=22)
            ax.scatter(xs[0][bad], xs[1][bad], s=60, facecolors="none", edgecolors="k", label="did not pass")
            fig.colorbar(sc, ax=ax, label=key)
            ax.set(xlabel=names[0], ylabel=names[1])
            ax.legend(loc="best", fontsize=8)
            out.append(("Runs in the parameter plane", _png(fig)))
    return out


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _fmt(v: Any) -> str:
    f = _num(v)
    return str(v) if math.isnan(f) and not isinstance(v, float) else (f"{f:.4g}" if math.isfinite(f) else str(f))


def write_campaign_report(out_dir: str | os.PathLike[str], rows: Sequence[Mapping[str, Any]],
                          params: Mapping[str, Parameter], objective: str, *, title: str,
                          first: int | None = None) -> Path:
    """Write ``report.html`` for a campaign's table ``rows`` into ``out_dir``; returns its path."""
    from twolevel.atomic import write_text_atomic

    names = list(params)
    key = "objective" if rows and "objective" in rows[0] else "index"
    failed = [r for r in rows if r.get("outcome") != "passed"]
    if first is None:
        first = next((int(r["index"]) for r in rows if r.get("outcome") != "passed"), None)
    wall = sum(_num(r.get("wall_s")) for r in rows)
    facts = [("runs", len(rows)), ("passed", len(rows) - len(failed)), ("did not pass", len(failed)),
             ("simulations to the first failure", first if first is not None else "none"),
             ("objective", objective), ("wall time in workers [s]", f"{wall:.1f}")]
    figs = _figures(rows, names, key, first) if rows else []
    bad_rows = [[r["index"], *(_fmt(r.get(f"p.{n}")) for n in names), _fmt(r.get(key)), r.get("outcome"),
                 r.get("failed") or "-", r.get("run_dir") or "-"] for r in failed]
    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>",
        "<style>body{font-family:sans-serif;margin:2em;max-width:1100px}table{border-collapse:collapse;margin:1em 0}"
        "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f3f3f3}img{max-width:100%}</style>",
        f"</head><body><h1>{html.escape(title)}</h1>",
        _table(["", ""], [(k, v) for k, v in facts]),
        *(f"<h2>{html.escape(t)}</h2><img alt='{html.escape(t)}' src='data:image/png;base64,{b}'>" for t, b in figs),
        "<h2>Runs that did not pass</h2>",
        _table(["run", *names, key, "outcome", "failed criteria", "run directory"], bad_rows) if bad_rows else "<p>none</p>",
        "<p>The full table: results.csv / results.json (one row per run; m.&lt;criterion&gt; are margins, "
        "≥ 0 passes).</p></body></html>",
    ]
    return write_text_atomic(Path(out_dir) / REPORT_FILE, "\n".join(parts))
