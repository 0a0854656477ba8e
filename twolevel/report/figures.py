"""The paper's figure set, for one run or several overlaid.

Figures are drawn on ``matplotlib.figure.Figure`` objects with the Agg canvas (no pyplot, no
global state); matplotlib is imported only when a figure is drawn. Every figure has a title,
axes with units, a legend, and the limits it is judged against drawn dashed (the 10 Hz / 100 ms
real-time requirement, the speed limit in force, the 4.22 m collision line, robustness zero).
Output is deterministic (fixed SVG id salt, no dates in the metadata).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from twolevel.atomic import write_bytes_atomic
from twolevel.report.metrics import COLLISION_LINE_M, DECISIONS, LIGHT_STATES, RULE_PREFIX, STEP_BUDGET_MS, Metrics
from twolevel.sim.trace import RunData

LIGHT_COLOURS = {"none": "#d0d0d0", "green": "#2ca02c", "yellow": "#f2c200", "red": "#d62728"}
VIEW_M = 60.0  # distance plots show the nearest 60 m (the sensing range of the animation)
LIMIT = dict(linestyle="--", linewidth=1.2)
_RC = {"svg.hashsalt": "twolevel", "svg.fonttype": "path", "font.size": 9, "axes.grid": True, "grid.alpha": 0.3}


@dataclass(frozen=True)
class Series:
    """One run to draw: its label (legend entry), columns and metrics."""

    label: str
    run: RunData
    metrics: Metrics
    road: Any = None  # twolevel.report.road.Road: lane edges and the road band along the run

    def col(self, name: str) -> np.ndarray | None:
        c = self.run.columns.get(name)
        if isinstance(c, np.ndarray) and c.size and c.size == self.t.size:
            return c
        return None

    def text(self, name: str) -> list[str] | None:
        c = self.run.columns.get(name)
        return [str(v).strip().lower() for v in c] if c is not None and len(c) == self.t.size and len(c) else None

    @property
    def t(self) -> np.ndarray:
        t = self.run.columns.get("t")
        return t if isinstance(t, np.ndarray) else np.array([])


@dataclass(frozen=True)
class RenderedFigure:
    """A drawn figure: where its files went and its PNG bytes (for embedding)."""

    name: str
    title: str
    files: tuple[str, ...]
    png: bytes


def _colour(i: int) -> str:
    return f"C{i % 10}"


def _finite(a: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(a), a, np.nan)


def _legend(ax: Any, **kw: Any) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(fontsize=8, loc=kw.pop("loc", "best"), framealpha=0.85, **kw)


def _run_suffix(series: Sequence[Series], s: Series, what: str) -> str:
    return f"{what} ({s.label})" if len(series) > 1 else what


# ---------------------------------------------------------------------------------------------
# figures: each takes a Figure and the runs, draws, returns False when there was nothing to draw


def _control_rate(fig: Any, series: Sequence[Series]) -> bool:
    ax = fig.subplots()
    drawn = False
    hz_all = []
    for i, s in enumerate(series):
        step = s.col("t_step_ms")
        if step is None:
            continue
        with np.errstate(divide="ignore"):
            hz = np.where(step > 0, 1000.0 / np.where(step > 0, step, 1.0), np.nan)
        ax.plot(s.t, hz, color=_colour(i), linewidth=1.0, label=s.label if len(series) > 1 else "control rate")
        hz_all.append(hz[np.isfinite(hz)])
        drawn = True
    if not drawn:
        return False
    ax.axhline(1000.0 / STEP_BUDGET_MS, color="k", label="10 Hz requirement (100 ms per step)", **LIMIT)
    allv = np.concatenate(hz_all) if hz_all else np.array([])
    if allv.size and allv.min() > 0 and allv.max() / allv.min() > 20:
        ax.set_yscale("log")
    ax.set(xlabel="time [s]", ylabel="control rate [Hz] (1 / step time)", title="Control rate over time")
    _legend(ax)
    return True


def _latency(fig: Any, series: Sequence[Series]) -> bool:
    data = []
    for i, s in enumerate(series):
        for level, col, ls in (("total", "t_step_ms", "-"), ("high level", "t_high_ms", "--"), ("low level", "t_low_ms", ":")):
            c = s.col(col)
            if c is not None and np.isfinite(c).any():
                data.append((i, s, level, np.sort(c[np.isfinite(c)]), ls))
    if not data:
        return False
    ax_h, ax_c = fig.subplots(1, 2)
    allv = np.concatenate([d[3] for d in data])
    lo, hi = max(float(allv[allv > 0].min()) if (allv > 0).any() else 0.01, 1e-3), max(float(allv.max()), 1e-2)
    logx = hi / lo > 30
    bins = np.geomspace(lo, hi * 1.0001, 40) if logx else np.linspace(0.0, hi * 1.0001, 40)
    for i, s, level, v, ls in data:
        label = f"{s.label}: {level}" if len(series) > 1 else level
        ax_h.hist(v, bins=bins, histtype="step", color=_colour(i), linestyle=ls, linewidth=1.2, label=label)
        ax_c.plot(v, np.arange(1, v.size + 1) / v.size, color=_colour(i), linestyle=ls, drawstyle="steps-post", label=label)
    for ax in (ax_h, ax_c):
        if logx:
            from matplotlib.ticker import FormatStrFormatter

            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.axvline(STEP_BUDGET_MS, color="k", label="100 ms requirement", **LIMIT)
    ax_h.set(xlabel="time per control step [ms]", ylabel="steps", title="Control-step latency by level")
    ax_c.set(xlabel="time per control step [ms]", ylabel="share of steps ≤ x", title="Latency CDF", ylim=(0, 1.02))
    _legend(ax_c, loc="lower right")
    return True


def _bound(s: Series, name: str) -> float | None:
    """A criterion's bound from the run's recorded verdict (None when not judged)."""
    for c in (s.run.meta.get("verdict") or {}).get("criteria", []):
        if c.get("name") == name and isinstance(c.get("bound"), (int, float)):
            return float(c["bound"])
    return None


def _path(fig: Any, series: Sequence[Series]) -> bool:
    drawn = [s for s in series if s.col("x") is not None and s.col("y") is not None]
    if not drawn:
        return False
    ax = fig.subplots()
    edges = next((s.road.edges for s in drawn if s.road is not None), None) or drawn[0].run.meta.get("road_edges")
    for k, line in enumerate(edges or []):
        xy = np.asarray(line, dtype=float)
        ax.plot(xy[:, 0], xy[:, 1], color="0.55", linewidth=0.8, label="lane edges" if k == 0 else None)
    for i, s in enumerate(drawn):
        x, y = s.col("x"), s.col("y")
        ax.plot(x, y, color=_colour(i), linewidth=1.4, label=s.label if len(series) > 1 else "ego path")
        ax.plot(x[:1], y[:1], "o", color=_colour(i), markersize=4)
        ax.plot(x[-1:], y[-1:], "s", color=_colour(i), markersize=4)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set(xlabel="x [m]", ylabel="y [m]", title="Path and road edges (o start, ■ end)")
    _legend(ax)
    return True


def _motion(fig: Any, series: Sequence[Series]) -> bool:
    from twolevel.verdict.motion import motion_of

    drawn = [s for s in series if all(s.col(c) is not None for c in ("v", "psi")) and s.t.size > 2]
    if not drawn:
        return False
    ax_a, ax_l, ax_j = fig.subplots(3, 1, sharex=True)
    for i, s in enumerate(drawn):
        mo = motion_of(s.t, s.col("v"), s.col("psi"))
        lab = s.label if len(series) > 1 else None
        ax_a.plot(mo.t_acc, mo.accel, color=_colour(i), linewidth=1.0, label=lab or "longitudinal")
        ax_l.plot(mo.t_acc, mo.lat_accel, color=_colour(i), linewidth=1.0, label=lab or "lateral")
        ax_j.plot(mo.t_jerk, mo.jerk, color=_colour(i), linewidth=1.0, label=lab or "jerk")
        for ax, name, sign in ((ax_a, "max_decel", -1), (ax_l, "max_lat_accel", 0), (ax_j, "max_jerk", 0)):
            b = _bound(s, name)
            if b is not None:
                for y in ((-b,) if sign < 0 else (-b, b)):
                    ax.axhline(y, color=_colour(i), label=f"bound {b:g}" if y == -b else None, **LIMIT)
    ax_a.set(ylabel="accel. [m/s²]", title="Acceleration (< 0: deceleration), lateral acceleration, jerk")
    ax_l.set(ylabel="lateral [m/s²]")
    ax_j.set(xlabel="time [s]", ylabel="jerk [m/s³]")
    for ax in (ax_a, ax_l, ax_j):
        _legend(ax)
    return True


def _tracking(fig: Any, series: Sequence[Series]) -> bool:
    road = [s for s in series if s.road is not None and s.col("e") is not None]
    if road:
        return _tracking_road(fig, series, road)
    ax = fig.subplots()
    drawn = False
    for i, s in enumerate(series):
        e = s.col("tracking_error")
        if e is None:
            continue
        ax.plot(s.t, _finite(e), color=_colour(i), linewidth=1.0, label=s.label if len(series) > 1 else "tracking error")
        tr = s.metrics.tracking
        if tr is not None and math.isfinite(tr.max_m):
            ax.plot([tr.t_max_s], [tr.max_m], "v", color=_colour(i), label=_run_suffix(series, s, f"max {tr.max_m:.2f} m at {tr.t_max_s:.1f} s"))
        drawn = True
    if not drawn:
        return False
    ax.set_ylim(bottom=0)
    ax.set(xlabel="time [s]", ylabel="distance from reference path [m]", title="Tracking error")
    _legend(ax)
    return True


def _tracking_road(fig: Any, series: Sequence[Series], road: Sequence[Series]) -> bool:
    ax = fig.subplots()
    first = road[0].road
    ax.fill_between(first.t, first.right, first.left, color="0.92", step="mid", label="road")
    ax.plot(first.t, first.left, color="0.4", linewidth=1.0, label="road edges")
    ax.plot(first.t, first.right, color="0.4", linewidth=1.0)
    ax.plot(first.t, first.lane, color="0.4", label="route lane edges", **LIMIT)
    ax.plot(first.t, -first.lane, color="0.4", **LIMIT)
    for i, s in enumerate(series):
        e = s.col("e")
        if e is not None:
            ax.plot(s.t, e, color=_colour(i), linewidth=1.2, label=s.label if len(series) > 1 else "lateral offset of the ego")
    ax.axhline(0.0, color="k", linewidth=0.6)
    ax.set(xlabel="time [s]", ylabel="offset from the route [m], + left", title="Tracking error and road edges")
    _legend(ax)
    return True


def _speed(fig: Any, series: Sequence[Series]) -> bool:
    ax = fig.subplots()
    drawn = False
    for i, s in enumerate(series):
        v = s.col("v")
        if v is None:
            continue
        ax.plot(s.t, v, color=_colour(i), linewidth=1.2, label=s.label if len(series) > 1 else "speed")
        vmax = s.col("v_max")
        if vmax is not None and np.isfinite(vmax).any():
            ax.plot(s.t, _finite(vmax), color=_colour(i) if len(series) > 1 else "k", drawstyle="steps-post",
                    label=_run_suffix(series, s, "speed limit in force"), **LIMIT)
            over = np.isfinite(vmax) & (v > np.where(np.isfinite(vmax), vmax, np.inf))
            if over.any():
                ax.fill_between(s.t, v, np.where(np.isfinite(vmax), vmax, v), where=over, color="#d62728", alpha=0.3,
                                step="post", label=_run_suffix(series, s, "over the limit"))
        drawn = True
    if not drawn:
        return False
    ax.set_ylim(bottom=0)
    ax.set(xlabel="time [s]", ylabel="speed [m/s]", title="Speed and the speed limit in force")
    _legend(ax)
    return True


def _lights(fig: Any, series: Sequence[Series]) -> bool:
    rows = [(s, s.text("light_state")) for s in series]
    rows = [(s, st) for s, st in rows if st is not None and s.t.size]
    if not rows:
        return False
    fig.set_figheight(1.4 + 0.45 * len(rows))
    ax = fig.subplots()
    from matplotlib.patches import Patch

    for k, (s, states) in enumerate(rows):
        t = s.t
        dur = np.append(np.diff(t), np.median(np.diff(t)) if t.size > 1 else 0.1)
        arr = np.array(states, dtype=object)
        change = np.flatnonzero(np.concatenate(([True], arr[1:] != arr[:-1])))
        ends = np.append(change[1:], arr.size)
        for a, b in zip(change.tolist(), ends.tolist()):
            start, width = float(t[a]), float(t[b - 1] + dur[b - 1] - t[a])
            ax.broken_barh([(start, width)], (k - 0.35, 0.7), facecolors=LIGHT_COLOURS.get(arr[a], "#9467bd"), edgecolor="none")
    ax.set_yticks(range(len(rows)), [s.label if len(series) > 1 else "light ahead" for s, _ in rows])
    ax.set_ylim(-0.6, len(rows) - 0.4)
    ax.grid(False, axis="y")
    ax.legend(handles=[Patch(color=LIGHT_COLOURS[s], label=s) for s in LIGHT_STATES], fontsize=8, ncol=4,
              loc="upper center", bbox_to_anchor=(0.5, -0.35 if len(rows) == 1 else -0.2), frameon=False)
    ax.set(xlabel="time [s]", title="Traffic-light state ahead of the ego")
    return True


def _distance(fig: Any, series: Sequence[Series]) -> bool:
    have = [(i, s) for i, s in enumerate(series) if s.col("min_dist") is not None or s.col("min_gap") is not None]
    if not have:
        return False
    fig.set_figheight(5.4)
    ax_d, ax_g = fig.subplots(2, 1, sharex=True)
    for i, s in have:
        d, g = s.col("min_dist"), s.col("min_gap")
        name = s.label if len(series) > 1 else None
        if d is not None:
            ax_d.plot(s.t, _finite(d), color=_colour(i), linewidth=1.2, label=name or "nearest vehicle, centre to centre")
        if g is not None:
            ax_g.plot(s.t, _finite(g), color=_colour(i), linewidth=1.2, label=name or "nearest vehicle, box to box")
            for k, ep in enumerate(s.metrics.collisions.episodes):
                ax_g.axvspan(ep.t_start, ep.t_end + s.metrics.dt_s if math.isfinite(s.metrics.dt_s) else ep.t_end,
                             color="#d62728" if len(series) == 1 else _colour(i), alpha=0.25,
                             label=_run_suffix(series, s, "boxes overlap (collision)") if k == 0 else None)
    ax_d.axhline(COLLISION_LINE_M, color="#d62728", label=f"{COLLISION_LINE_M} m: collision (paper's measure)", **LIMIT)
    ax_g.axhline(0.0, color="#d62728", label="0 m: boxes touch", **LIMIT)
    ax_d.set(ylabel="min. distance [m]", title="Distance to the nearest other vehicle")
    ax_g.set(xlabel="time [s]", ylabel="min. box gap [m]")
    _clip_top(ax_d, [s.col("min_dist") for _, s in have], VIEW_M, bottom=0.0)
    _clip_top(ax_g, [s.col("min_gap") for _, s in have], VIEW_M)
    _legend(ax_d)
    _legend(ax_g)
    return True


def _clip_top(ax: Any, cols: Sequence[np.ndarray | None], top: float, bottom: float | None = None,
              unit: str = "m") -> None:
    """Keep the interesting range in view: the axis stops at ``top`` (in ``unit``) and says so."""
    vals = np.concatenate([c[np.isfinite(c)] for c in cols if c is not None] or [np.array([])])
    if vals.size and vals.max() > top:
        low = bottom if bottom is not None else min(float(vals.min()), 0.0)
        ax.set_ylim(low - (0.0 if bottom is not None else 0.04 * (top - low)), top)
        ax.text(0.995, 0.97, f"axis clipped at {top:g} {unit}", transform=ax.transAxes, ha="right", va="top", fontsize=7, color="0.4")
    elif bottom is not None:
        ax.set_ylim(bottom=bottom)


CRITICAL_VIEW_S = 10.0  # time measures are shown up to 10 s (the interesting range)


def _criticality(fig: Any, series: Sequence[Series]) -> bool:
    """Time to collision (the vehicle ahead; anyone, dotted; the safety layer's time to react,
    dots, where the trace has it), time headway and distance headway over time."""
    have = [(i, s) for i, s in enumerate(series) if s.col("ttc_s") is not None or s.col("thw_s") is not None]
    if not have:
        return False
    fig.set_figheight(6.6)
    ax_t, ax_h, ax_d = fig.subplots(3, 1, sharex=True)
    for i, s in have:
        name = s.label if len(series) > 1 else None
        ttc, ttc_any, ttr = s.col("ttc_s"), s.col("ttc_any_s"), s.col("ttr_s")
        if ttc is not None:
            ax_t.plot(s.t, _finite(ttc), color=_colour(i), linewidth=1.2, label=name or "TTC, vehicle ahead")
        if ttc_any is not None:
            ax_t.plot(s.t, _finite(ttc_any), color=_colour(i), linewidth=1.0, linestyle=":",
                      label=_run_suffix(series, s, "TTC, anyone"))
        if ttr is not None:
            ax_t.plot(s.t, _finite(ttr), color=_colour(i), marker=".", linestyle="none", markersize=3,
                      label=_run_suffix(series, s, "time to react (safety layer)"))
        for ax, col, what in ((ax_h, "thw_s", "time headway"), (ax_d, "dhw_m", "distance headway")):
            c = s.col(col)
            if c is not None:
                ax.plot(s.t, _finite(c), color=_colour(i), linewidth=1.2, label=name or what)
    ax_t.set(ylabel="time [s]", title="Criticality: to the vehicle ahead (and anyone)")
    ax_h.set(ylabel="time headway [s]")
    ax_d.set(xlabel="time [s]", ylabel="distance headway [m]")
    for ax, col, top, unit in ((ax_t, "ttc_s", CRITICAL_VIEW_S, "s"), (ax_h, "thw_s", CRITICAL_VIEW_S, "s"),
                               (ax_d, "dhw_m", VIEW_M, "m")):
        _clip_top(ax, [s.col(col) for _, s in have], top, bottom=0.0, unit=unit)
        _legend(ax)
    return True


def _nearby(fig: Any, series: Sequence[Series]) -> bool:
    ax = fig.subplots()
    drawn = False
    for i, s in enumerate(series):
        n = s.col("n_near")
        if n is None:
            continue
        ax.plot(s.t, n, color=_colour(i), drawstyle="steps-post", linewidth=1.2, label=s.label if len(series) > 1 else "vehicles within r_near")
        drawn = True
    if not drawn:
        return False
    from matplotlib.ticker import MaxNLocator

    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylim(bottom=0)
    ax.set(xlabel="time [s]", ylabel="nearby vehicles [count]", title="Vehicles within sensing range r_near")
    _legend(ax)
    return True


def _robustness(fig: Any, series: Sequence[Series]) -> bool:
    rules: list[str] = []
    for s in series:
        for c in s.run.columns:
            if c.startswith(RULE_PREFIX) and c[len(RULE_PREFIX):] not in rules and s.col(c) is not None:
                rules.append(c[len(RULE_PREFIX):])
    if not rules:
        return False
    fig.set_figheight(1.0 + 1.7 * len(rules))
    axes = np.atleast_1d(fig.subplots(len(rules), 1, sharex=True, squeeze=False)[:, 0])
    for ax, rule in zip(axes, rules):
        for i, s in enumerate(series):
            rob = s.col(RULE_PREFIX + rule)
            if rob is None:
                continue
            ax.plot(s.t, _finite(rob), color=_colour(i), linewidth=1.1, label=s.label if len(series) > 1 else "robustness")
            step = s.metrics.dt_s if math.isfinite(s.metrics.dt_s) else 0.0
            for k, v in enumerate(w for w in s.metrics.violations if w.rule == rule):
                ax.axvspan(v.t_start, v.t_end + step, color="#d62728" if len(series) == 1 else _colour(i), alpha=0.2,
                           label=_run_suffix(series, s, "violated (ρ < 0)") if k == 0 else None)
        ax.axhline(0.0, color="k", label="ρ = 0 (satisfied above)", **LIMIT)
        ax.set_ylabel(f"ρ {rule}")
        ax.set_title(f"rule '{rule}'", fontsize=9, loc="left")
        _legend(ax, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[-1].set_xlabel("time [s]")
    fig.suptitle("Robustness of each rule over time (negative = violated)")
    return True


def _decisions(fig: Any, series: Sequence[Series]) -> bool:
    rows = [(i, s, s.text("decision")) for i, s in enumerate(series)]
    rows = [(i, s, d) for i, s, d in rows if d]
    if not rows:
        return False
    names = list(DECISIONS) + sorted({x for _, _, d in rows for x in d} - set(DECISIONS))
    idx = {n: k for k, n in enumerate(names)}
    ax = fig.subplots()
    off = np.linspace(-0.25, 0.25, len(rows)) if len(rows) > 1 else [0.0]
    for (i, s, d), o in zip(rows, off):
        y = np.array([idx[x] for x in d], dtype=float) + o
        ax.scatter(s.t, y, marker="|", s=60, color=_colour(i), label=s.label if len(series) > 1 else "applied control")
    ax.set_yticks(range(len(names)), names)
    ax.set_ylim(-0.6, len(names) - 0.4)
    ax.set(xlabel="time [s]", ylabel="decision", title="Which level decided the applied control")
    _legend(ax)
    return True


#: name → (title, drawing function, base height [in]) — the paper's figure set and ours.
FIGURES: dict[str, tuple[str, Callable[[Any, Sequence[Series]], bool], float]] = {
    "control_rate": ("Control rate over time", _control_rate, 3.4),
    "latency": ("Control-step latency by level", _latency, 3.6),
    "path": ("Path and road edges", _path, 4.2),
    "tracking_error": ("Tracking error", _tracking, 3.4),
    "motion": ("Acceleration, deceleration and jerk", _motion, 5.4),
    "speed": ("Speed and speed limit", _speed, 3.4),
    "light_state": ("Traffic-light state", _lights, 1.9),
    "distance": ("Distance to other vehicles", _distance, 5.4),
    "criticality": ("Criticality: time to collision, time and distance headway", _criticality, 6.6),
    "nearby": ("Nearby vehicles", _nearby, 3.0),
    "robustness": ("Rule robustness", _robustness, 3.0),
    "decisions": ("Decisions by level", _decisions, 3.0),
}


def render_figures(
    series: Sequence[Series], out_dir: str | Path | None, formats: Sequence[str] = ("png", "svg"), *, dpi: int = 110
) -> tuple[tuple[RenderedFigure, ...], tuple[str, ...]]:
    """Draw every figure of :data:`FIGURES` for ``series`` (overlaid when several) and write
    each as ``<out_dir>/<name>.<fmt>``. Returns the figures drawn and the names skipped with the
    reason. PNG bytes are always kept for embedding, even when ``png`` is not in ``formats``."""
    import matplotlib

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    done: list[RenderedFigure] = []
    skipped: list[str] = []
    with matplotlib.rc_context(_RC):
        for name, (title, draw, height) in FIGURES.items():
            fig = Figure(figsize=(8.0, height), layout="constrained")
            FigureCanvasAgg(fig)
            if not draw(fig, series):
                skipped.append(f"figure '{name}' skipped: no run has the data it needs")
                continue
            files = []
            blobs: dict[str, bytes] = {}
            for fmt in dict.fromkeys(("png", *formats)):
                buf = io.BytesIO()
                meta = {"Date": None} if fmt == "svg" else ({"CreationDate": None} if fmt == "pdf" else None)
                fig.savefig(buf, format=fmt, dpi=dpi, metadata=meta)
                blobs[fmt] = buf.getvalue()
                if out is not None and fmt in formats:
                    files.append(str(write_bytes_atomic(out / f"{name}.{fmt}", blobs[fmt])))
            done.append(RenderedFigure(name, title, tuple(files), blobs["png"]))
    return tuple(done), tuple(skipped)
