"""How a run drove, in five figures a driving instructor would ask for: whether and when it
reached its goal, how far it strayed from the centre of the lane it was in, its hardest braking,
its peak jerk and how long it stood still on the way. Computed from the recorded trace (the
executed motion of the detailed model, :mod:`twolevel.verdict.motion`), recorded in ``run.json``
(key ``ride``) when the run is judged (:func:`twolevel.verdict.judge.judge_run`), shown by the
report and printed by ``benchmarks/closed_loop.py``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Mapping

import numpy as np

from twolevel.sim.summary import intervals
from twolevel.verdict.motion import motion_of

__all__ = ["Ride", "ride_of", "standstills", "RIDE_KEY"]

RIDE_KEY = "ride"


@dataclass(frozen=True)
class Ride:
    """``goal_t`` [s] when the goal was reached (None: not reached); ``lane_offset`` [m]: the
    peak |lateral offset| of the ego's reference point from the centre line of the nearest lane
    that runs its way (off every lane: from the nearest such lane); ``decel`` [m/s²] and
    ``jerk`` [m/s³]: the peak deceleration and |jerk|; ``stopped`` [s]: the time spent standing
    still (speed ≤ the stop speed), not counting the final standstill at the goal."""

    goal_t: float | None
    lane_offset: float
    decel: float
    jerk: float
    stopped: float

    def to_json(self) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> "Ride":
        def num(v: Any) -> float:
            return math.nan if v is None else float(v)

        goal = d.get("goal_t")
        return cls(None if goal is None else float(goal), num(d.get("lane_offset")), num(d.get("decel")),
                   num(d.get("jerk")), num(d.get("stopped")))


def standstills(v: np.ndarray, stop_speed: float, *, arrived: bool) -> tuple[np.ndarray, np.ndarray]:
    """First and last sample indices of each standstill (|``v``| ≤ ``stop_speed`` [m/s]) on the
    way; when the ego ``arrived`` at its goal, a standstill lasting to the end is arriving and
    left out."""
    starts, ends = intervals(np.abs(np.asarray(v, dtype=float)) <= stop_speed)
    if arrived and ends.size and ends[-1] == len(v) - 1:
        starts, ends = starts[:-1], ends[:-1]
    return starts, ends


def ride_of(world: Any, cols: Mapping[str, Any], goal_t: float | None, stop_speed: float) -> Ride:
    """The :class:`Ride` of a run: its trace columns ``cols`` (``t``, ``x``, ``y``, ``psi``,
    ``v``), the time its goal was reached ``goal_t`` [s] (None: not reached; the criteria's
    ``goal`` measure), its scenario's ``world`` (the lanes) and ``stop_speed`` [m/s]."""
    t = np.asarray(cols.get("t", np.zeros(0)), dtype=float)
    if t.size == 0:
        return Ride(goal_t, math.nan, math.nan, math.nan, math.nan)
    x, y, psi, v = (np.asarray(cols[k], dtype=float) for k in ("x", "y", "psi", "v"))
    _, _, lateral = world.lanes.lookup(np.stack([x, y], axis=1), psi)
    offset = float(np.nanmax(np.abs(lateral))) if np.isfinite(lateral).any() else math.nan
    mo = motion_of(t, v, psi)
    starts, ends = standstills(v, stop_speed, arrived=goal_t is not None)
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    stopped = float(np.sum(ends - starts + 1) * step) if starts.size else 0.0
    return Ride(goal_t, offset, mo.peak_decel[0], mo.peak_jerk[0], stopped)
