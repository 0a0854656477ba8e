"""Metrics of one run: the paper's numbers, computed from a run directory's trace.

Pure numpy over the columns :func:`twolevel.sim.trace.read_run` returns. Every group is
optional: a column that is missing (an older trace, a damaged file) drops its group and says so
in ``Metrics.problems``; nothing here raises on a partial run.

Conventions:

* Each sample stands for the time until the next one: ``duration_i = t_{i+1} - t_i`` and the
  last sample lasts the median step (``settings.dt`` for a single row). Times "over the limit"
  or "below the line" are sums of these durations [s]; shares are fractions of the total.
* Percentiles interpolate linearly between samples (``numpy.percentile``'s default).
* A violation is a maximal run of consecutive samples with robustness < 0; its ``t_end`` is the
  time of its last violating sample and its ``depth`` the most negative robustness in it.
  ``NaN`` robustness (unknown) is never a violation and ends an interval.
* A collision episode is a maximal run of samples with ``min_gap < 0`` (the oriented boxes
  overlap). The paper's own measure is the centre distance ``min_dist`` below
  :data:`COLLISION_LINE_M` (4.22 m, the vehicles' length), reported beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from twolevel.control.low_level.guard import Outcome
from twolevel.sim.extra_columns import CRITICALITY_COLUMNS
from twolevel.sim.summary import HARD_BRAKING
from twolevel.sim.summary import LEVEL as _LEVEL
from twolevel.sim.summary import LEVELS as _LEVELS
from twolevel.sim.summary import StepDecision
from twolevel.sim.summary import intervals
from twolevel.sim.summary import jsonable as _jsonable
from twolevel.sim.trace import RunData

#: The paper's collision line: centre-to-centre distance [m] below one vehicle length (4.22 m).
COLLISION_LINE_M = 4.22
#: The paper's real-time requirement: one control step within 100 ms (10 Hz).
STEP_BUDGET_MS = 100.0
DECISIONS: tuple[str, ...] = tuple(d.value for d in StepDecision)
#: Which part of the controller chose the applied control, per decision (one table: the simulator's).
DECISION_LEVEL: Mapping[str, str] = _LEVEL
LEVELS: tuple[str, ...] = _LEVELS
#: The safety layer's outcomes per step (the trace's ``verification``).
OUTCOMES: tuple[str, ...] = tuple(o.value for o in Outcome)
LIGHT_STATES: tuple[str, ...] = ("none", "green", "yellow", "red")
RULE_PREFIX = "rob_"


class _Serialisable:
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (NaN → None, ±inf → "inf"/"-inf")."""
        return _jsonable(self)


@dataclass(frozen=True)
class Distribution(_Serialisable):
    """Summary of a sample: count, extremes, mean and percentiles (NaN when empty)."""

    n: int
    min: float
    mean: float
    p1: float
    p5: float
    p50: float
    p95: float
    p99: float
    max: float


def distribution(values: np.ndarray) -> Distribution:
    """Distribution of the finite entries of ``values``."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        nan = math.nan
        return Distribution(0, nan, nan, nan, nan, nan, nan, nan, nan)
    p = np.percentile(v, [1, 5, 50, 95, 99])
    return Distribution(int(v.size), float(v.min()), float(v.mean()), *map(float, p), float(v.max()))


@dataclass(frozen=True)
class RateMetrics(_Serialisable):
    """Control rate 1000 / t_step_ms [Hz] per step."""

    hz: Distribution
    steps_below_10hz: int


@dataclass(frozen=True)
class LatencyMetrics(_Serialisable):
    """Control-step latency [ms], total and per level."""

    total: Distribution
    high: Distribution
    low: Distribution
    budget_ms: float
    steps_over_budget: int
    share_over_budget: float


@dataclass(frozen=True)
class TrackingMetrics(_Serialisable):
    """Distance from the reference path [m]."""

    max_m: float
    mean_m: float
    rms_m: float
    t_max_s: float


@dataclass(frozen=True)
class SpeedMetrics(_Serialisable):
    """Speed [m/s] against the limit in force ``v_max`` (samples without a finite limit are
    not judged)."""

    max_mps: float
    mean_mps: float
    max_overspeed_mps: float
    t_max_overspeed_s: float
    time_over_limit_s: float
    share_over_limit: float
    episodes_over_limit: int


@dataclass(frozen=True)
class DistanceMetrics(_Serialisable):
    """Nearest other vehicle: centre distance ``min_dist`` and box gap ``min_gap`` [m]. ``inf``
    when no vehicle was ever near."""

    min_dist_m: float
    t_min_dist_s: float
    min_gap_m: float
    t_min_gap_s: float
    collision_line_m: float
    time_below_line_s: float
    below_line: bool


@dataclass(frozen=True)
class CriticalityMetrics(_Serialisable):
    """The smallest criticality measures of the run and when (the trace's ``ttc_s``, ``thw_s``,
    ``dhw_m``, ``ttc_any_s``: :mod:`twolevel.world.criticality`); ``inf`` when the measure never
    applied (no vehicle ahead, no collision course)."""

    min_ttc_s: float
    t_min_ttc_s: float
    min_thw_s: float
    t_min_thw_s: float
    min_dhw_m: float
    t_min_dhw_s: float
    min_ttc_any_s: float
    t_min_ttc_any_s: float


@dataclass(frozen=True)
class NearbyMetrics(_Serialisable):
    """Number of vehicles within r_near."""

    max: int
    mean: float


@dataclass(frozen=True)
class LightMetrics(_Serialisable):
    """Time [s] and share of the run spent in each traffic-light state ahead."""

    time_s: tuple[tuple[str, float], ...]
    shares: tuple[tuple[str, float], ...]

    def share(self, state: str) -> float:
        return dict(self.shares).get(state, 0.0)


@dataclass(frozen=True)
class Violation(_Serialisable):
    """One interval of consecutive samples where a rule's robustness is negative."""

    rule: str
    t_start: float
    t_end: float
    depth: float
    t_depth: float
    steps: int


@dataclass(frozen=True)
class RuleMetrics(_Serialisable):
    """Robustness of one rule over the run."""

    rule: str
    min: float
    t_min: float
    initial: float
    final: float
    satisfied: bool
    violations: int
    time_violated_s: float


@dataclass(frozen=True)
class DecisionMetrics(_Serialisable):
    """Which decision produced the applied control, per step."""

    counts: tuple[tuple[str, int], ...]
    shares: tuple[tuple[str, float], ...]
    level_counts: tuple[tuple[str, int], ...]
    level_shares: tuple[tuple[str, float], ...]

    def count(self, decision: str) -> int:
        return dict(self.counts).get(decision, 0)

    def share(self, decision: str) -> float:
        return dict(self.shares).get(decision, 0.0)


@dataclass(frozen=True)
class CollisionEpisode(_Serialisable):
    """Consecutive samples with overlapping boxes (min_gap < 0)."""

    t_start: float
    t_end: float
    depth_m: float
    x: float
    y: float


@dataclass(frozen=True)
class ReportedCollision(_Serialisable):
    """A collision the simulator recorded in run.json's summary, with whether it was the ego's
    fault (None: not recorded, an older run), the verdict and the reason."""

    t: float
    x: float
    y: float
    other: str
    at_fault: bool | None = None
    verdict: str = ""
    reason: str = ""


@dataclass(frozen=True)
class CollisionMetrics(_Serialisable):
    episodes: tuple[CollisionEpisode, ...]
    reported: tuple[ReportedCollision, ...]

    @property
    def collided(self) -> bool:
        return bool(self.episodes or self.reported)

    @property
    def count(self) -> int:
        return max(len(self.episodes), len(self.reported))

    @property
    def at_fault(self) -> int:
        """Recorded collisions that were the ego's fault."""
        return sum(1 for r in self.reported if r.at_fault)


@dataclass(frozen=True)
class SafetyMetrics(_Serialisable):
    """The safety layer per step (the trace's ``verification``): steps per outcome, the smallest
    time to react recorded [s] (``ttr_s``), and braking: the peak deceleration over one step
    [m/s²] and the share of steps braking harder than ``hard_mps2`` (from the speed column)."""

    outcomes: tuple[tuple[str, int], ...]
    ttr_min_s: float
    decel_peak_mps2: float
    hard_braking_share: float
    hard_mps2: float = HARD_BRAKING

@dataclass(frozen=True)
class Metrics(_Serialisable):
    """Everything the report says about one run. Groups are ``None`` when their columns are
    missing from the trace."""

    label: str
    run_dir: str
    status: str | None
    rows: int
    duration_s: float
    dt_s: float
    rate: RateMetrics | None
    latency: LatencyMetrics | None
    tracking: TrackingMetrics | None
    speed: SpeedMetrics | None
    distance: DistanceMetrics | None
    nearby: NearbyMetrics | None
    lights: LightMetrics | None
    rules: tuple[RuleMetrics, ...]
    violations: tuple[Violation, ...]
    decisions: DecisionMetrics | None
    collisions: CollisionMetrics
    safety: SafetyMetrics | None = None
    problems: tuple[str, ...] = field(default=())
    criticality: CriticalityMetrics | None = None

    def to_dict(self) -> dict[str, Any]:
        d = _jsonable(self)
        d["collisions"]["collided"] = self.collisions.collided
        d["collisions"]["count"] = self.collisions.count
        d["collisions"]["at_fault"] = self.collisions.at_fault
        return d


# ---------------------------------------------------------------------------------------------
# helpers


def sample_durations(t: np.ndarray, dt: float | None = None) -> np.ndarray:
    """Time each sample stands for [s]: the gap to the next; the last one lasts the median gap
    (or ``dt`` when there is a single sample)."""
    t = np.asarray(t, dtype=float)
    if t.size == 0:
        return t.copy()
    gaps = np.diff(t)
    last = float(np.median(gaps)) if gaps.size else float(dt or 0.0)
    return np.append(gaps, last)


def _argext(values: np.ndarray, t: np.ndarray, fn: Callable[[np.ndarray], int]) -> tuple[float, float]:
    finite = np.isfinite(values)
    if not finite.any():
        return math.nan, math.nan
    idx = np.flatnonzero(finite)[fn(values[finite])]
    return float(values[idx]), float(t[idx])


class _Columns:
    """Typed access to a run's columns; records what is missing or malformed."""

    def __init__(self, run: RunData) -> None:
        self.run = run
        self.n = max((len(v) for v in run.columns.values()), default=0)
        self.problems: list[str] = []

    def num(self, name: str, what: str) -> np.ndarray | None:
        col = self.run.columns.get(name)
        if col is None:
            if self.n:
                self.problems.append(f"column '{name}' is missing from the trace: {what} not reported")
            return None
        if not isinstance(col, np.ndarray) or len(col) != self.n:
            self.problems.append(f"column '{name}' is not numeric: {what} not reported")
            return None
        return col

    def text(self, name: str, what: str) -> list[str] | None:
        col = self.run.columns.get(name)
        if col is None:
            if self.n:
                self.problems.append(f"column '{name}' is missing from the trace: {what} not reported")
            return None
        return [str(v) for v in col]


# ---------------------------------------------------------------------------------------------
# groups


def _rate_latency(total: np.ndarray | None, high: np.ndarray | None, low: np.ndarray | None) -> tuple[RateMetrics | None, LatencyMetrics | None]:
    if total is None:
        return None, None
    with np.errstate(divide="ignore"):
        hz = np.where(total > 0, 1000.0 / np.where(total > 0, total, 1.0), np.inf)
    finite = np.isfinite(total)
    over = int(np.count_nonzero(total[finite] > STEP_BUDGET_MS))
    empty = np.array([])
    latency = LatencyMetrics(
        total=distribution(total),
        high=distribution(high if high is not None else empty),
        low=distribution(low if low is not None else empty),
        budget_ms=STEP_BUDGET_MS,
        steps_over_budget=over,
        share_over_budget=over / max(1, int(finite.sum())),
    )
    return RateMetrics(hz=distribution(hz), steps_below_10hz=over), latency


def _tracking(err: np.ndarray, t: np.ndarray) -> TrackingMetrics:
    e = err[np.isfinite(err)]
    mx, tmx = _argext(err, t, np.argmax)
    mean = float(e.mean()) if e.size else math.nan
    rms = float(np.sqrt(np.mean(e**2))) if e.size else math.nan
    return TrackingMetrics(max_m=mx, mean_m=mean, rms_m=rms, t_max_s=tmx)


def _speed(v: np.ndarray, vmax: np.ndarray | None, t: np.ndarray, dur: np.ndarray) -> SpeedMetrics:
    vf = v[np.isfinite(v)]
    vmax_ = vmax if vmax is not None else np.full_like(v, np.nan)
    judged = np.isfinite(v) & np.isfinite(vmax_)
    excess = np.where(judged, v - np.where(judged, vmax_, 0.0), np.nan)
    over = judged & (excess > 0)
    worst, t_worst = _argext(excess, t, np.argmax)
    if not over.any():
        worst, t_worst = 0.0, math.nan
    judged_time = float(dur[judged].sum())
    over_time = float(dur[over].sum())
    return SpeedMetrics(
        max_mps=float(vf.max()) if vf.size else math.nan,
        mean_mps=float(vf.mean()) if vf.size else math.nan,
        max_overspeed_mps=worst,
        t_max_overspeed_s=t_worst,
        time_over_limit_s=over_time,
        share_over_limit=over_time / judged_time if judged_time > 0 else 0.0,
        episodes_over_limit=int(intervals(over)[0].size),
    )


def _distance(dist: np.ndarray | None, gap: np.ndarray | None, t: np.ndarray, dur: np.ndarray) -> DistanceMetrics:
    nan = np.full_like(t, np.nan)
    d = dist if dist is not None else nan
    g = gap if gap is not None else nan
    md, tmd = _argext(d, t, np.argmin)
    mg, tmg = _argext(g, t, np.argmin)
    if dist is not None and math.isnan(md):
        md = math.inf  # the column exists but no vehicle was ever near
    if gap is not None and math.isnan(mg):
        mg = math.inf
    below = np.isfinite(d) & (d < COLLISION_LINE_M)
    return DistanceMetrics(
        min_dist_m=md, t_min_dist_s=tmd, min_gap_m=mg, t_min_gap_s=tmg,
        collision_line_m=COLLISION_LINE_M, time_below_line_s=float(dur[below].sum()), below_line=bool(below.any()),
    )


def _criticality(run: RunData, t: np.ndarray) -> CriticalityMetrics | None:
    """The minima of the criticality columns the trace has (None without any: an older trace)."""
    values: list[float] = []
    for col in CRITICALITY_COLUMNS:
        c = run.columns.get(col)
        if not isinstance(c, np.ndarray) or c.size != t.size or not c.size:
            values += [math.nan, math.nan]
            continue
        c = np.asarray(c, dtype=float)
        m, tm = _argext(c, t, np.argmin)
        values += [math.inf, math.nan] if math.isnan(m) else [m, tm]
    return None if all(math.isnan(v) for v in values[::2]) else CriticalityMetrics(*values)


def _lights(states: list[str], dur: np.ndarray) -> LightMetrics:
    arr = np.array([s.strip().lower() or "none" for s in states], dtype=object)
    names = list(LIGHT_STATES) + sorted(set(arr.tolist()) - set(LIGHT_STATES))
    total = float(dur.sum())
    times = tuple((s, float(dur[arr == s].sum())) for s in names)
    return LightMetrics(time_s=times, shares=tuple((s, tm / total if total > 0 else 0.0) for s, tm in times))


def find_violations(rule: str, rob: np.ndarray, t: np.ndarray) -> tuple[Violation, ...]:
    """Every maximal interval of consecutive samples with ``rob < 0``."""
    rob = np.asarray(rob, dtype=float)
    with np.errstate(invalid="ignore"):
        starts, ends = intervals(rob < 0)
    out = []
    for s, e in zip(starts.tolist(), ends.tolist()):
        k = s + int(np.argmin(rob[s : e + 1]))
        out.append(Violation(rule, float(t[s]), float(t[e]), float(rob[k]), float(t[k]), e - s + 1))
    return tuple(out)


def _rule(rule: str, rob: np.ndarray, t: np.ndarray, dur: np.ndarray) -> tuple[RuleMetrics, tuple[Violation, ...]]:
    viol = find_violations(rule, rob, t)
    mn, tmn = _argext(rob, t, np.argmin)
    with np.errstate(invalid="ignore"):
        neg = rob < 0
    return RuleMetrics(
        rule=rule, min=mn, t_min=tmn,
        initial=float(rob[0]) if rob.size else math.nan,
        final=float(rob[-1]) if rob.size else math.nan,
        satisfied=not viol, violations=len(viol), time_violated_s=float(dur[neg].sum()),
    ), viol


def _decisions(dec: list[str]) -> DecisionMetrics:
    arr = np.array([d.strip().lower() for d in dec], dtype=object)
    n = max(1, arr.size)
    names = list(DECISIONS) + sorted(set(arr.tolist()) - set(DECISIONS))
    counts = tuple((d, int(np.count_nonzero(arr == d))) for d in names)
    levels: dict[str, int] = {lv: 0 for lv in LEVELS}
    for d, c in counts:
        lv = DECISION_LEVEL.get(d, "other")
        levels[lv] = levels.get(lv, 0) + c
    return DecisionMetrics(
        counts=counts, shares=tuple((d, c / n) for d, c in counts),
        level_counts=tuple(levels.items()), level_shares=tuple((lv, c / n) for lv, c in levels.items()),
    )


def _collisions(gap: np.ndarray | None, t: np.ndarray, x: np.ndarray | None, y: np.ndarray | None, meta: Mapping[str, Any], problems: list[str]) -> CollisionMetrics:
    episodes: list[CollisionEpisode] = []
    if gap is not None:
        with np.errstate(invalid="ignore"):
            starts, ends = intervals(gap < 0)
        for s, e in zip(starts.tolist(), ends.tolist()):
            episodes.append(CollisionEpisode(
                float(t[s]), float(t[e]), float(np.min(gap[s : e + 1])),
                float(x[s]) if x is not None else math.nan, float(y[s]) if y is not None else math.nan,
            ))
    reported: list[ReportedCollision] = []
    summary = meta.get("summary")
    raw = summary.get("collisions", []) if isinstance(summary, Mapping) else []
    for c in raw if isinstance(raw, list) else []:
        if isinstance(c, Mapping):
            fault = c.get("at_fault")
            reported.append(ReportedCollision(_f(c.get("t")), _f(c.get("x")), _f(c.get("y")), str(c.get("other", "")),
                                              fault if isinstance(fault, bool) else None, str(c.get("verdict", "")),
                                              str(c.get("reason", ""))))
    if summary is not None and gap is not None and bool(episodes) != bool(reported):
        problems.append(
            f"run.json's summary records {len(reported)} collision(s) but the trace's min_gap shows "
            f"{len(episodes)} overlap episode(s)"
        )
    return CollisionMetrics(tuple(episodes), tuple(reported))


def _safety(outcomes: list[str] | None, ttr: np.ndarray | None, v: np.ndarray | None, t: np.ndarray
            ) -> SafetyMetrics | None:
    if outcomes is None and v is None:
        return None
    arr = np.array([o.strip() for o in outcomes or []], dtype=object)
    names = list(OUTCOMES) + sorted(set(arr.tolist()) - set(OUTCOMES))
    counts = tuple((o, int(np.count_nonzero(arr == o))) for o in names)
    finite = ttr[np.isfinite(ttr)] if ttr is not None else np.zeros(0)
    decel = -np.diff(v) / np.diff(t) if v is not None and v.size > 1 and np.all(np.diff(t) > 0) else np.zeros(0)
    return SafetyMetrics(counts, float(finite.min()) if finite.size else math.nan,
                         float(max(decel.max(), 0.0)) if decel.size else math.nan,
                         float(np.mean(decel > HARD_BRAKING)) if decel.size else math.nan)


def _f(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


# ---------------------------------------------------------------------------------------------
# entry points


def rule_names(run: RunData) -> tuple[str, ...]:
    """The rules a trace records, in column order (``rob_<rule>`` columns)."""
    return tuple(c[len(RULE_PREFIX):] for c in run.columns if c.startswith(RULE_PREFIX))


def compute_metrics(run: RunData, label: str | None = None) -> Metrics:
    """All metrics of one run. Never raises on a partial run; see ``Metrics.problems``."""
    cols = _Columns(run)
    meta = run.meta if isinstance(run.meta, Mapping) else {}
    settings = meta.get("settings") if isinstance(meta.get("settings"), Mapping) else {}
    dt_setting = _f(settings.get("dt")) if settings else math.nan
    t = cols.num("t", "time")
    if t is None:
        t = np.arange(cols.n, dtype=float) * (dt_setting if math.isfinite(dt_setting) else 1.0)
    dur = sample_durations(t, dt_setting if math.isfinite(dt_setting) else None)
    dt = float(np.median(np.diff(t))) if t.size > 1 else (dt_setting if math.isfinite(dt_setting) else math.nan)
    rate, latency = _rate_latency(cols.num("t_step_ms", "control rate and latency"), cols.num("t_high_ms", "high-level latency"), cols.num("t_low_ms", "low-level latency"))
    err = cols.num("tracking_error", "tracking error")
    v = cols.num("v", "speed")
    vmax = cols.num("v_max", "speed limit")
    dist, gap = cols.num("min_dist", "centre distance"), cols.num("min_gap", "box gap and collisions")
    near = cols.num("n_near", "nearby count")
    light = cols.text("light_state", "light state")
    dec = cols.text("decision", "decisions")
    outcomes = cols.text("verification", "the safety layer's outcomes")
    ttr = cols.num("ttr_s", "time to react")
    x, y = cols.num("x", "position"), cols.num("y", "position")
    rules, violations = [], []
    for name in rule_names(run):
        rob = cols.num(RULE_PREFIX + name, f"robustness of '{name}'")
        if rob is not None and rob.size:
            rm, viol = _rule(name, rob, t, dur)
            rules.append(rm)
            violations.extend(viol)
    violations.sort(key=lambda w: (w.t_start, w.rule))
    near_f = near[np.isfinite(near)] if near is not None else np.array([])
    problems = list(run.problems)
    steps = np.diff(t)
    if steps.size and not np.all(steps > 0):
        k = int(np.flatnonzero(~(steps > 0))[0]) + 1
        problems.append(f"the time column does not increase at row {k + 2} (t = {t[k - 1]:g} s, then {t[k]:g} s): "
                        "durations and rates are unreliable")
    collisions = _collisions(gap, t, x, y, meta, cols.problems)
    has = cols.n > 0
    return Metrics(
        label=label or _default_label(run),
        run_dir=run.run_dir,
        status=meta.get("status"),
        rows=cols.n,
        duration_s=float(dur.sum()),
        dt_s=dt,
        rate=rate,
        latency=latency,
        tracking=_tracking(err, t) if err is not None and has else None,
        speed=_speed(v, vmax, t, dur) if v is not None and has else None,
        distance=_distance(dist, gap, t, dur) if (dist is not None or gap is not None) and has else None,
        nearby=NearbyMetrics(int(near_f.max()), float(near_f.mean())) if near_f.size else None,
        lights=_lights(light, dur) if light is not None and has else None,
        rules=tuple(rules),
        violations=tuple(violations),
        decisions=_decisions(dec) if dec is not None and has else None,
        collisions=collisions,
        safety=_safety(outcomes, ttr, v, t) if has else None,
        problems=tuple(problems + [p for p in cols.problems if p not in problems]),
        criticality=_criticality(run, t) if has else None,
    )


def _default_label(run: RunData) -> str:
    from pathlib import Path

    return Path(run.run_dir).name or str(run.run_dir)


__all__ = [
    "COLLISION_LINE_M", "STEP_BUDGET_MS", "Distribution", "Metrics", "Violation", "RuleMetrics", "SafetyMetrics",
    "CriticalityMetrics",
    "compute_metrics", "find_violations",
    "distribution", "intervals", "sample_durations", "rule_names",
]
