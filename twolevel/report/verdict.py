"""The verdict of a run in its report: the goal's status and every criterion with its measured
value, bound and margin (from ``run.json``'s ``verdict``, recorded when the run was judged)."""

from __future__ import annotations

from typing import Any, Mapping

from twolevel.verdict.criteria import Verdict
from twolevel.verdict.judge import recorded_ride, recorded_verdict

__all__ = ["verdict_of", "goal_status", "criteria_rows", "verdict_line", "ride_line", "CRITERIA_HEADER"]

CRITERIA_HEADER = ("criterion", "verdict", "measured", "bound", "margin", "detail")


def verdict_of(meta: Mapping[str, Any]) -> Verdict | None:
    """The run's recorded verdict (None when it was never judged)."""
    return recorded_verdict(meta)


def _num(v: float | None, unit: str = "") -> str:
    if v is None:
        return "—"
    return f"{v:.4g} {unit}".strip() if v == v and abs(v) != float("inf") else str(v)


def goal_status(verdict: Verdict | None) -> str:
    """One line on the goal: reached (when), not reached (how far), or not judged."""
    if verdict is None:
        return "not judged (the run has no verdict)"
    goal = verdict.get("goal")
    return "not judged (expect: goal: false)" if goal is None else goal.detail


def verdict_line(verdict: Verdict | None) -> str:
    """PASS / FAIL with the criteria that failed."""
    if verdict is None:
        return "The run was not judged against criteria (judge it with twolevel simulate)."
    if verdict.passed:
        return f"PASS: all {len(verdict.criteria)} criteria met."
    failed = ", ".join(c.name for c in verdict.failed) or f"the run ended '{verdict.status}'"
    return f"FAIL: {failed}."


def criteria_rows(verdict: Verdict | None) -> list[tuple[str, ...]]:
    """One row per criterion, in :data:`CRITERIA_HEADER` order."""
    if verdict is None:
        return []
    return [(c.name, "pass" if c.passed else "FAIL", _num(c.measured, c.unit), _num(c.bound, c.unit), _num(c.margin),
             c.detail) for c in verdict.criteria]


def ride_line(meta: Mapping[str, Any]) -> str:
    """The ride's figures in one line (:mod:`twolevel.verdict.ride`; empty when not recorded)."""
    ride = recorded_ride(meta)
    if ride is None:
        return ""
    goal = "not reached" if ride.goal_t is None else f"{ride.goal_t:.1f} s"
    return (f"goal {goal}; peak |offset| from the lane's centre {_num(ride.lane_offset, 'm')}; peak deceleration "
            f"{_num(ride.decel, 'm/s²')}; peak |jerk| {_num(ride.jerk, 'm/s³')}; stopped {_num(ride.stopped, 's')}")
