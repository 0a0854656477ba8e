"""Pass criteria judged from what a run recorded.

Each :class:`Criterion` carries the measured value, the bound it is judged against, its unit,
and a **margin** in that unit: ≥ 0 when it passes, < 0 when it fails (how far from passing —
the robustness ``twolevel falsify`` minimises). The criteria (``expect:`` in the scenario,
:class:`~twolevel.world.schema.Expect`):

``goal``
    reached: on a route that stops at its goal, standing still within the goal zone (the run
    ends there); otherwise passing the goal zone on the route's lane. Margin: the time to spare
    [s] before the deadline (``by``, else the end of the run) and, with ``after`` (a time
    window, as CommonRoad's goals), after its opening; not reached: minus the route distance
    still to go [m].
``on_road``
    every corner of the ego's box within the drivable area (any lane of the road, the route's
    lanes with ``boundary: lane``, or the route's drivable area with ``boundary: area``: its
    lane, the lanes the markings let it change to, the oncoming lane where passing is allowed)
    up to ``tolerance`` [m]. Measured: how far the worst corner got outside (negative: how close
    it came to the edge). "Left the map": the reference point itself was off every lane.
``no_collision``
    no collision the ego is at fault for. A recorded collision counts as at fault unless the
    run records ``at_fault: false`` for it. Margin: the deepest at-fault overlap [m] (< 0), or
    else the smallest box gap to any vehicle [m] outside not-at-fault collisions (beyond the
    sensing radius the centre distance less the ego's length stands in for the gap).
``rule:<name>``
    the rule's robustness ≥ 0 at every step of the executed trace (all rules by default, or
    those listed in ``rules``). Margin: the worst robustness.
``max_decel``, ``max_jerk``, ``max_lat_accel``
    peaks of the executed motion (:mod:`twolevel.verdict.motion`) [m/s², m/s³, m/s²].
``min_gap``
    the smallest box gap to any vehicle [m] at least the bound.
``max_stopped``
    the longest standstill (speed ≤ ``stop_speed``) [s], not counting the final one at the goal.

A run that did not complete (interrupted, crashed) never passes.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from twolevel.sim.engine import GOAL_ZONE
from twolevel.sim.summary import intervals
from twolevel.sim.trace import RunStatus
from twolevel.verdict.drivable import area_outside, box_outside
from twolevel.verdict.motion import motion_of
from twolevel.verdict.ride import standstills
from twolevel.world.schema import Expect, GoalCriterion, RoadCriterion

__all__ = ["Criterion", "Verdict", "judge", "RULE_PREFIX"]

RULE_PREFIX = "rule:"
_FAIL = 1e-9  # a failed criterion's margin is at most −_FAIL (never a passing 0)


@dataclass(frozen=True)
class Criterion:
    """One judged criterion: ``margin`` ≥ 0 iff ``passed``; ``t`` [s] when it first failed (or
    the measured peak happened); ``key`` where the scenario states it (for annotations)."""

    name: str
    passed: bool
    measured: float | None
    bound: float | None
    unit: str
    margin: float
    detail: str
    t: float | None = None
    key: tuple[str, ...] = ("expect",)

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["key"] = list(self.key)
        for k in ("measured", "bound", "margin", "t"):
            v = out[k]
            if isinstance(v, float) and not math.isfinite(v):
                out[k] = None if math.isnan(v) else ("inf" if v > 0 else "-inf")
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> "Criterion":
        def num(v: Any) -> float | None:
            return float(v) if v is not None else None

        return cls(str(d["name"]), bool(d["passed"]), num(d.get("measured")), num(d.get("bound")), str(d.get("unit", "")),
                   float(d["margin"]) if d.get("margin") is not None else -math.inf, str(d.get("detail", "")),
                   num(d.get("t")), tuple(d.get("key") or ("expect",)))


@dataclass(frozen=True)
class Verdict:
    """Every criterion of a run, and whether the run passed (completed, every criterion met)."""

    passed: bool
    status: str
    criteria: tuple[Criterion, ...]

    @property
    def failed(self) -> tuple[Criterion, ...]:
        return tuple(c for c in self.criteria if not c.passed)

    def get(self, name: str) -> Criterion | None:
        return next((c for c in self.criteria if c.name == name), None)

    def to_json(self) -> dict[str, Any]:
        return {"passed": self.passed, "status": self.status, "criteria": [c.to_json() for c in self.criteria]}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> "Verdict":
        return cls(bool(d["passed"]), str(d.get("status", "")), tuple(Criterion.from_json(c) for c in d.get("criteria", [])))


def _fail(margin: float) -> float:
    return min(margin, -_FAIL) if not math.isnan(margin) else -math.inf


def _first(mask: np.ndarray, t: np.ndarray) -> float | None:
    idx = np.flatnonzero(mask)
    return float(t[idx[0]]) if idx.size else None


def _goal(c: GoalCriterion, world: Any, cols: Mapping[str, Any], summary: Mapping[str, Any], duration: float) -> Criterion:
    route = world.route
    length = float(route.length)
    t, s = cols["t"], cols.get("s")
    stops = bool(route.v_des.size and route.v_des[-1] <= 1e-9)
    bound = c.by if c.by is not None else duration
    key = ("expect", "goal", "by") if c.by is not None else ("route", "goal")
    if stops:
        reached = summary.get("goal_reached_t")
    else:
        e = cols.get("e")
        there = (s >= length - GOAL_ZONE) & (np.abs(e) <= 0.5 * route.width_at(np.clip(s, 0, length)))
        reached = _first(there, t) if s is not None and e is not None else None
    if reached is None:
        gone = float(np.nanmax(s)) if s is not None and s.size and np.isfinite(s).any() else 0.0
        short = max(length - gone, 0.0)
        end = float(t[-1]) if t.size else 0.0
        detail = (f"not reached: {short:.1f} m short at the end ({end:.1f} s)" if short > GOAL_ZONE else
                  f"not reached: at the goal ({short:.1f} m short) but not stopped there by the end ({end:.1f} s)")
        return Criterion("goal", False, None, bound, "s", _fail(-short), detail, None, key)
    reached = float(reached)
    margin = bound - reached
    if margin < 0:
        return Criterion("goal", False, reached, bound, "s", _fail(margin),
                         f"reached at {reached:.1f} s, {-margin:.1f} s after the deadline", reached, key)
    if c.after is not None and reached < c.after:
        return Criterion("goal", False, reached, bound, "s", _fail(reached - c.after),
                         f"reached at {reached:.1f} s, {c.after - reached:.1f} s before the window opens",
                         reached, ("expect", "goal", "after"))
    if c.after is not None:
        margin = min(margin, reached - c.after)
    return Criterion("goal", True, reached, bound, "s", margin, f"reached at {reached:.1f} s", reached, key)


def _on_road(c: RoadCriterion, world: Any, cols: Mapping[str, Any]) -> Criterion:
    t = cols["t"]
    only = sorted({p[0] for p in world.route.pieces}) if c.boundary == "lane" else None
    worst, centre = box_outside(world.lanes, cols["x"], cols["y"], cols["psi"], world.ego.length, world.ego.width, only)
    if c.boundary == "area":
        worst = area_outside(world.lanes, world.route, cols["x"], cols["y"], cols["psi"], world.ego.length, world.ego.width)
    measured = float(np.max(worst))
    key = ("expect", "on_road")
    where = {"lane": "the route's lanes", "area": "the drivable area"}.get(c.boundary, "the road")
    if measured <= c.tolerance:
        detail = (f"inside {where}; the closest corner {-measured:.2f} m from the edge" if measured <= 0 else
                  f"inside {where} within the tolerance; a corner up to {measured:.2f} m outside")
        return Criterion("on_road", True, measured, c.tolerance, "m", c.tolerance - measured, detail, None, key)
    bad = worst > c.tolerance
    starts, ends = intervals(bad)
    first = float(t[starts[0]])
    detail = (f"left {where} {len(starts)} time(s) from {first:.1f} s, for {float(np.sum(ends - starts + 1)) * _dt(t):.1f} s, "
              f"up to {measured:.2f} m outside")
    if (centre > 0).any():
        detail += f"; left the map at {_first(centre > 0, t):.1f} s (the ego's centre off every lane)"
    return Criterion("on_road", False, measured, c.tolerance, "m", _fail(c.tolerance - measured), detail, first, key)


def _dt(t: np.ndarray) -> float:
    return float(np.median(np.diff(t))) if t.size > 1 else 0.0


def _gaps(world: Any, cols: Mapping[str, Any]) -> np.ndarray:
    """Box gap to the nearest vehicle at each step [m]: the sensed box separation, or beyond the
    sensing radius the centre distance less the ego's length (inf with nobody around)."""
    gap = np.asarray(cols.get("min_gap", np.full(cols["t"].shape, np.inf)), dtype=float)
    dist = np.asarray(cols.get("min_dist", np.full(cols["t"].shape, np.inf)), dtype=float)
    return np.where(np.isfinite(gap), gap, dist - world.ego.length)


def _no_collision(world: Any, cols: Mapping[str, Any], summary: Mapping[str, Any]) -> Criterion:
    t = cols["t"]
    hits = list(summary.get("collisions") or [])
    fault = [c for c in hits if c.get("at_fault", True) is not False]
    key = ("expect", "no_collision")
    if fault:
        deepest = min(float(c.get("gap", -_FAIL)) for c in fault)
        who = ", ".join(f"{c.get('other')} at {float(c.get('t', 0.0)):.1f} s" for c in fault[:3])
        return Criterion("no_collision", False, float(len(fault)), 0.0, "", _fail(deepest),
                         f"{len(fault)} collision(s) at fault: {who}", float(fault[0].get("t", 0.0)), key)
    gaps = _gaps(world, cols)
    keep = np.ones(t.shape, dtype=bool)
    for c in hits:  # not at fault: those steps do not count against the margin
        keep &= ~((t >= float(c.get("t", 0.0)) - 1e-9) & (t <= float(c.get("t_end", c.get("t", 0.0))) + 1e-9))
    margin = float(np.min(gaps[keep])) if keep.any() else math.inf
    margin = max(margin, 0.0)
    detail = "no collision" if not hits else f"no collision at fault ({len(hits)} the ego was not at fault for)"
    return Criterion("no_collision", True, 0.0, 0.0, "", margin, detail, None, key)


def _rules(selected: str | Sequence[str], cols: Mapping[str, Any]) -> list[Criterion]:
    t = cols["t"]
    present = [name[4:] for name in cols if name.startswith("rob_")]
    names = present if selected == "all" else list(selected)
    out = []
    for i, name in enumerate(names):
        key = ("expect", "rules", i) if selected != "all" else ("rules",)
        rob = cols.get(f"rob_{name}")
        if rob is None:
            out.append(Criterion(RULE_PREFIX + name, False, None, 0.0, "", -math.inf,
                                 f"no rule named '{name}' in the scenario's rule files "
                                 f"(rules: {', '.join(present) or 'none'})", None, key))
            continue
        rob = np.asarray(rob, dtype=float)
        bad = ~(rob >= 0)  # NaN is no evidence the rule held
        worst = float(np.nanmin(rob)) if (~np.isnan(rob)).any() else -math.inf
        if not bad.any():
            out.append(Criterion(RULE_PREFIX + name, True, worst, 0.0, "", worst, f"holds (worst robustness {worst:.3g})",
                                 None, key))
            continue
        first = _first(bad, t)
        out.append(Criterion(RULE_PREFIX + name, False, worst, 0.0, "", _fail(worst),
                             f"violated in {int(bad.sum())} step(s) from {first:.1f} s (worst robustness {worst:.3g})",
                             first, key))
    return out


def _upper(name: str, measured: float, at: float | None, bound: float, unit: str, what: str) -> Criterion:
    margin = bound - measured
    passed = margin >= 0
    detail = f"{what} {measured:.3g} {unit}" + (f" at {at:.1f} s" if at is not None else "")
    return Criterion(name, passed, measured, bound, unit, margin if passed else _fail(margin), detail,
                     at, ("expect", name))


def _stopped(world: Any, cols: Mapping[str, Any], summary: Mapping[str, Any], stop_speed: float) -> tuple[float, float | None]:
    t = cols["t"]
    starts, ends = standstills(cols["v"], stop_speed, arrived=summary.get("goal_reached_t") is not None)
    if not starts.size:
        return 0.0, None
    lengths = (ends - starts + 1) * _dt(t)
    k = int(np.argmax(lengths))
    return float(lengths[k]), float(t[starts[k]])


def judge(expect: Expect, world: Any, cols: Mapping[str, Any], summary: Mapping[str, Any], status: str,
          settings: Mapping[str, Any] | None = None) -> Verdict:
    """Judge every criterion of ``expect`` on a run: its trace columns ``cols`` (``t``, ``x``,
    ``y``, ``psi``, ``v``, ``s``, ``e``, ``min_gap``, ``min_dist``, ``rob_<rule>``), its
    ``summary`` (as in ``run.json``), its ``status``, and the scenario's ``world`` (lanes, route,
    ego box). ``settings`` (``run.json``'s) override the world's duration and stop speed."""
    settings = settings or {}
    duration = float(settings.get("duration", world.settings.duration))
    stop_speed = float(settings.get("stop_speed", world.settings.stop_speed))
    t = np.asarray(cols.get("t", np.zeros(0)), dtype=float)
    if t.size == 0:
        none = Criterion("run", False, None, None, "", -math.inf, f"no step was recorded (status {status})")
        return Verdict(False, status, (none,))
    cols = dict(cols)
    out: list[Criterion] = []
    if expect.goal is not None:
        out.append(_goal(expect.goal, world, cols, summary, duration))
    if expect.on_road is not None:
        out.append(_on_road(expect.on_road, world, cols))
    if expect.no_collision:
        out.append(_no_collision(world, cols, summary))
    out += _rules(expect.rules, cols)
    mo = motion_of(t, cols["v"], cols["psi"])
    if expect.max_decel is not None:
        out.append(_upper("max_decel", *mo.peak_decel, expect.max_decel, "m/s²", "peak deceleration"))
    if expect.max_jerk is not None:
        out.append(_upper("max_jerk", *mo.peak_jerk, expect.max_jerk, "m/s³", "peak |jerk|"))
    if expect.max_lat_accel is not None:
        out.append(_upper("max_lat_accel", *mo.peak_lat_accel, expect.max_lat_accel, "m/s²", "peak |lateral acceleration|"))
    if expect.min_gap is not None:
        gaps = _gaps(world, cols)
        k = int(np.argmin(gaps))
        smallest, margin = float(gaps[k]), float(gaps[k]) - expect.min_gap
        out.append(Criterion("min_gap", margin >= 0, smallest, expect.min_gap, "m", margin if margin >= 0 else _fail(margin),
                             f"smallest gap {smallest:.3g} m at {float(t[k]):.1f} s", float(t[k]), ("expect", "min_gap")))
    if expect.max_stopped is not None:
        longest, at = _stopped(world, cols, summary, stop_speed)
        out.append(_upper("max_stopped", longest, at, expect.max_stopped, "s", "longest standstill"))
    passed = status == RunStatus.COMPLETE and all(c.passed for c in out)
    return Verdict(passed, status, tuple(out))
