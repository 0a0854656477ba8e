"""What a closed-loop run reports: progress per step, collisions, and the closing summary.

Plain frozen dataclasses (no numpy in the fields) so they go straight into ``run.json`` and the
CLI's table. Times of the control step are wall-clock [ms]; everything else is simulated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from twolevel.milp.solution import ValueEnum
from twolevel.sim.trace import RunStatus

__all__ = ["StepDecision", "LEVELS", "LEVEL", "StepInfo", "Collision", "Closest", "Unsatisfiable", "RuleViolations",
           "RunSummary",
           "summarise", "jsonable", "intervals", "HARD_BRAKING"]

class StepDecision(ValueEnum):
    """The trace's ``decision``: whose control a step applied. With the monitor, the low level's
    :class:`~twolevel.control.low_level.decision.Action` (same values); without it, the planner's
    first control under the planner's ``label``; ``fallback`` when that was the MPC's fallback
    plan. Every action and every planner label must be a member (a test checks it)."""

    MPC = "mpc"
    SAMPLED = "sampled"
    LEAST_VIOLATION = "least_violation"
    BRAKE = "brake"
    FALLBACK = "fallback"
    FAILSAFE = "failsafe"
    NMPC = "nmpc"
    RECKLESS = "reckless"

    @property
    def level(self) -> str:
        """Which part of the controller chose the control: ``high``, ``low``, ``safety`` (the
        fail-safe verified earlier) or ``nmpc``."""
        return _LEVEL_OF[self]


_LEVEL_OF = {StepDecision.MPC: "high", StepDecision.FALLBACK: "high", StepDecision.SAMPLED: "low",
             StepDecision.BRAKE: "low", StepDecision.LEAST_VIOLATION: "low", StepDecision.FAILSAFE: "safety",
             StepDecision.NMPC: "nmpc", StepDecision.RECKLESS: "high"}

LEVELS: tuple[str, ...] = ("high", "low", "safety", "nmpc")
"""The levels, in the order the report lists them."""

LEVEL: Mapping[str, str] = {d.value: d.level for d in StepDecision}
"""Decision → level, by the decision's text (as the report reads it from a trace)."""
HARD_BRAKING = 4.0
"""[m/s²] Braking harder than this counts as hard (RSS's brake_min: what a follower may expect;
the gentlest fail-safe brakes at it)."""


@dataclass(frozen=True)
class StepInfo:
    """One completed step, for a progress display: step ``step`` of ``steps``; simulated time
    ``t`` of ``duration`` [s]; control rate ``rate_hz`` (control steps per second of controller
    time over the last ~20 steps); this step's control time ``step_ms`` [ms]; nearby vehicles
    ``n_near``; the ``decision``; ``realtime`` = simulated / wall time so far."""

    step: int
    steps: int
    t: float
    duration: float
    rate_hz: float
    step_ms: float
    n_near: int
    decision: StepDecision
    realtime: float


@dataclass(frozen=True)
class Collision:
    """An overlap of the ego's and another vehicle's boxes: from ``t`` to ``t_end`` [s], where
    it began (``x``, ``y`` [m]), the other vehicle's id, the deepest overlap ``gap`` [m] (< 0),
    and who is responsible (:mod:`twolevel.sim.collisions`): ``at_fault`` (the ego's fault;
    None: not classified), the ``verdict`` (ego_at_fault, ego_standing, hit_from_behind, cut_in,
    other_broke_assumptions) and the ``reason`` in a sentence."""

    t: float
    t_end: float
    x: float
    y: float
    other: str
    gap: float
    at_fault: bool | None = None
    verdict: str = ""
    reason: str = ""


@dataclass(frozen=True)
class Closest:
    """How close one other vehicle came: its id, the smallest centre-to-centre distance [m]
    and when [s]."""

    other: str
    distance: float
    t: float


@dataclass(frozen=True)
class Unsatisfiable:
    """An episode of steps in which no plan satisfied every rule (the high level fell back):
    from ``t_start`` to ``t_end`` [s] (both steps included), the ``rules`` that conflicted at its
    first step (empty with ``explained`` False: the planner cannot say, or no single rule or pair
    explains it), what the car did instead (``decisions``: steps per decision) and its speed
    [m/s] at the first and the last step."""

    t_start: float
    t_end: float
    steps: int
    rules: tuple[str, ...]
    explained: bool
    decisions: Mapping[str, int]
    v_start: float
    v_end: float

    def describe(self) -> str:
        """One sentence: when, which rules, what the car did."""
        why = (f"rules {', '.join(self.rules)} conflict" if len(self.rules) > 1 else f"rule {self.rules[0]} cannot hold"
               ) if self.rules else "no single rule or pair of rules explains it"
        did = ", ".join(f"{d} {n}" for d, n in sorted(self.decisions.items(), key=lambda kv: (-kv[1], kv[0])))
        return (f"from t = {self.t_start:.1f} s to {self.t_end:.1f} s ({self.steps} step{'s' if self.steps != 1 else ''}) no plan satisfied every rule "
                f"({why}); the high level fell back on its previous plan or braking, and the car applied: {did}; "
                f"speed {self.v_start:.1f} → {self.v_end:.1f} m/s")


@dataclass(frozen=True)
class RuleViolations:
    """Steps at which a rule's robustness (on the executed trace) was negative: how many, the
    first time [s] and the worst robustness."""

    rule: str
    steps: int
    first_t: float | None
    worst: float


@dataclass(frozen=True)
class RunSummary:
    """The closing summary of a run (see :func:`twolevel.sim.engine.simulate_scenario`).

    Control-step times [ms] cover both controller levels and the sensing they need (not the
    plant or traffic simulation): median / p95 / p99 / max, and per level, wall clock; the same
    step's CPU time of the process (``step_cpu_ms_*``) is what it costs when other jobs share
    the cores. ``control_rate_hz`` = steps per second of controller time; ``realtime`` =
    simulated time / wall time of the whole loop. Tracking error [m] = |lateral offset| from the route. ``min_distance`` [m]: the
    smallest centre-to-centre distance to any other vehicle (the paper's measure);
    ``min_gap`` [m]: the smallest box separation (< 0: overlap); ``closest``: the five vehicles
    that came closest (centre to centre), nearest first. The safety layer (``safety``: it was
    on): ``safe_start`` (the initial state had a fail-safe; None: the layer was off),
    ``verification``: steps per outcome (verified, failsafe, unverified, off), ``at_fault``: collisions that were the ego's
    fault, ``ttr_min_s`` [s]: the smallest time to react recorded. Braking: ``decel_peak``
    [m/s²]: the largest deceleration over one step (from the speeds), ``hard_braking_share``:
    the share of steps decelerating harder than :data:`HARD_BRAKING`. ``unsatisfiable``: the
    episodes in which no plan satisfied every rule (:class:`Unsatisfiable`)."""

    scenario: str
    run_dir: str
    status: RunStatus
    monitor: bool
    controller: str
    seed: int
    duration: float
    steps: int
    wall_time_s: float
    realtime: float
    step_ms_median: float
    step_ms_p95: float
    step_ms_p99: float
    step_ms_max: float
    high_ms_median: float
    high_ms_max: float
    low_ms_median: float
    low_ms_max: float
    control_rate_hz: float
    steps_over_budget: int
    tracking_error_max: float
    tracking_error_mean: float
    speed_over_limit_max: float
    min_distance: float
    min_gap: float
    collisions: tuple[Collision, ...] = ()
    violations: tuple[RuleViolations, ...] = ()
    closest: tuple[Closest, ...] = ()
    decisions: Mapping[str, int] = field(default_factory=dict)
    decisions_by_level: Mapping[str, int] = field(default_factory=dict)
    goal_reached_t: float | None = None  # [s] when the ego reached the goal (stood still there, or passed it)
    step_cpu_ms_median: float = math.nan
    step_cpu_ms_p99: float = math.nan
    step_cpu_ms_max: float = math.nan
    safety: bool = False
    safe_start: bool | None = None
    verification: Mapping[str, int] = field(default_factory=dict)
    at_fault: int = 0
    ttr_min_s: float = math.nan
    decel_peak: float = math.nan
    hard_braking_share: float = math.nan
    unsatisfiable: tuple[Unsatisfiable, ...] = ()

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (infinities as the strings "inf"/"-inf", NaN as null)."""
        return jsonable(self)


def jsonable(value: Any) -> Any:
    """Plain JSON values: dataclasses to dicts, NaN to None, ±inf to the strings "inf"/"-inf"."""
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: jsonable(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, str):
        return str(value)  # a status enum as its plain value
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        f = float(value)
        if math.isnan(f):
            return None
        if math.isinf(f):
            return "inf" if f > 0 else "-inf"
        return f
    return value


def intervals(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end indices (inclusive) of the maximal runs of True in ``mask`` (the episodes in
    which something held, e.g. a rule was violated: the report's and the verdict's)."""
    m = np.concatenate(([0], np.asarray(mask, dtype=np.int8), [0]))
    d = np.diff(m)
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1


def _pct(a: np.ndarray, q: float) -> float:
    return float(np.percentile(a, q)) if a.size else math.nan


def summarise(
    *, scenario: str, run_dir: str, status: RunStatus, monitor: bool, controller: str, seed: int, dt: float,
    wall_time_s: float, step_ms: Sequence[float], high_ms: Sequence[float], low_ms: Sequence[float],
    tracking: Sequence[float], over_limit: Sequence[float], min_dist: Sequence[float], min_gap: Sequence[float],
    decisions: Sequence[StepDecision], collisions: Sequence[Collision], robustness: Mapping[str, np.ndarray],
    closest: Sequence[Closest] = (), budget_ms: float = 100.0, goal_reached_t: float | None = None,
    speeds: Sequence[float] = (), verification: Sequence[str] = (), safety: bool = False,
    safe_start: bool | None = None, ttr: Sequence[float] = (), cpu_ms: Sequence[float] = (),
    unsatisfiable: Sequence[Unsatisfiable] = (),
) -> RunSummary:
    """The summary of the steps recorded so far (``speeds`` [m/s] per step, ``verification``
    outcome per step, ``ttr`` [s] the time to react where recorded, NaN elsewhere)."""
    st, hi, lo = (np.asarray(a, dtype=float) for a in (step_ms, high_ms, low_ms))
    n = int(st.size)
    tr = np.asarray(tracking, dtype=float)
    counts: dict[str, int] = {}
    for d in decisions:
        counts[d] = counts.get(d, 0) + 1
    levels: dict[str, int] = {}
    for d, c in counts.items():
        levels[LEVEL.get(d, "other")] = levels.get(LEVEL.get(d, "other"), 0) + c
    viol = []
    for rule, rob in robustness.items():
        rob = np.asarray(rob, dtype=float)[:n]
        bad = np.flatnonzero(~(rob >= 0))  # a NaN robustness is no evidence the rule held
        viol.append(RuleViolations(rule, int(bad.size), float(bad[0] * dt) if bad.size else None,
                                   float(rob.min()) if rob.size else math.nan))
    total = float(st.sum())
    v = np.asarray(speeds, dtype=float)
    decel = -np.diff(v) / dt if v.size > 1 else np.zeros(0)
    outcomes: dict[str, int] = {}
    for o in verification:
        outcomes[o] = outcomes.get(o, 0) + 1
    ttr_a = np.asarray(ttr, dtype=float)
    ttr_a = ttr_a[np.isfinite(ttr_a)]
    cpu = np.asarray(cpu_ms, dtype=float)
    return RunSummary(
        scenario=scenario, run_dir=run_dir, status=status, monitor=monitor, controller=controller, seed=seed,
        duration=round(n * dt, 9), steps=n, wall_time_s=round(wall_time_s, 3),
        realtime=(n * dt / wall_time_s) if wall_time_s > 0 else math.inf,
        step_ms_median=_pct(st, 50), step_ms_p95=_pct(st, 95), step_ms_p99=_pct(st, 99),
        step_ms_max=float(st.max()) if n else math.nan,
        high_ms_median=_pct(hi, 50), high_ms_max=float(hi.max()) if n else math.nan,
        low_ms_median=_pct(lo, 50), low_ms_max=float(lo.max()) if n else math.nan,
        control_rate_hz=(1000.0 * n / total) if total > 0 else math.nan,
        steps_over_budget=int(np.count_nonzero(st > budget_ms)),
        tracking_error_max=float(tr.max()) if tr.size else math.nan,
        tracking_error_mean=float(tr.mean()) if tr.size else math.nan,
        speed_over_limit_max=float(np.max(over_limit)) if len(over_limit) else math.nan,
        min_distance=float(np.min(min_dist)) if len(min_dist) else math.inf,
        min_gap=float(np.min(min_gap)) if len(min_gap) else math.inf,
        collisions=tuple(collisions), violations=tuple(viol), closest=tuple(closest), decisions=counts, decisions_by_level=levels,
        goal_reached_t=goal_reached_t, step_cpu_ms_median=_pct(cpu, 50), step_cpu_ms_p99=_pct(cpu, 99),
        step_cpu_ms_max=float(cpu.max()) if cpu.size else math.nan, safety=safety, safe_start=safe_start,
        verification=outcomes,
        at_fault=sum(1 for c in collisions if c.at_fault),
        ttr_min_s=float(ttr_a.min()) if ttr_a.size else math.nan,
        decel_peak=float(max(decel.max(), 0.0)) if decel.size else math.nan,
        hard_braking_share=float(np.mean(decel > HARD_BRAKING)) if decel.size else math.nan,
        unsatisfiable=tuple(unsatisfiable),
    )
