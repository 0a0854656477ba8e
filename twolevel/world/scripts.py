"""Checks of what scenarios script other road users to do: manoeuvre chains and pedestrians' walks.

What the schema cannot see alone, each at the value that causes it:

* a lane that does not exist (YML416), a crossing beyond the end of its lane (YML420), a lane
  change to a side without a lane of the same direction there, or to a lane that is not beside
  the one the participant is on by then (YML420; followed from its start lane through the
  chain's lane changes — one that drives onto a successor first should name the lane);
* an acceleration or deceleration no road user can reach (YML433: beyond
  :data:`PHYSICAL_ACCEL`, about 1.2 g, the friction of the best tyres on dry asphalt);
* motion beyond what the safety layer assumes of the participant's kind
  (:mod:`twolevel.world.assumptions`; YML434, a warning): a deceleration, acceleration or the
  slope of a speed profile above its ``a_max``, a speed above its ``v_max``. The simulation
  keeps every behaviour within the assumptions (:mod:`twolevel.world.traffic.idm`), so such a
  request is limited; raise the scenario's ``assumptions:`` to let it through.

Imported by ``twolevel check``: standard library only (no numpy).
"""

from __future__ import annotations

from twolevel.diagnostics import Diagnostic
from twolevel.world.assumptions import KIND_NAMES, Assumptions, MotionBounds, from_spec, kinds_of, user_of
from twolevel.world.codes import YML416, YML420, YML433, YML434
from twolevel.world.document import Document, Path_
from twolevel.world.layout import lane_lengths, lanes_beside
from twolevel.world.schema import MapFile, Manoeuvre, Participant, ScenarioFile

__all__ = ["PHYSICAL_ACCEL", "check_scripts"]

PHYSICAL_ACCEL = 11.8
"""[m/s²] More acceleration or braking than any road user's tyres give (1.2 g: μ ≈ 1.2 of the best
tyres on dry asphalt)."""


def _rates(m: Manoeuvre, at: Path_, doc: Document, bounds: MotionBounds, kind: str) -> list[Diagnostic]:
    out: list[Diagnostic] = []
    for name in ("decel", "accel"):
        value = getattr(m, name)
        if value is None:
            continue
        where = doc.locate(at + (name,), value=True)
        if value > PHYSICAL_ACCEL:
            out.append(YML433(f"'{name}' = {value:g} m/s² is more than any tyre gives (at most {PHYSICAL_ACCEL:g} m/s²)",
                              where, hint="a hard emergency stop is 8–10 m/s²"))
        elif value > bounds.a_max:
            out.append(_beyond(f"'{name}' = {value:g} m/s²", f"a_max = {bounds.a_max:g} m/s²", kind, where))
    speeds = [(k, getattr(m, k)) for k in ("brake_to", "accelerate_to", "follow_lane") if getattr(m, k) is not None]
    speeds += [("speed_profile", v) for _, v in m.speed_profile or []]
    for name, v in speeds:
        if v > bounds.v_max:
            out.append(_beyond(f"a speed of {v:g} m/s", f"v_max = {bounds.v_max:g} m/s", kind,
                               doc.locate(at + (name,), value=True)))
            break
    pts = m.speed_profile or []
    for k, ((x0, v0), (x1, v1)) in enumerate(zip(pts, pts[1:])):
        slope = abs(v1 - v0) / (x1 - x0) if m.along == "time" else abs(v1**2 - v0**2) / (2 * (x1 - x0))
        if slope > bounds.a_max + 1e-9:
            out.append(_beyond(f"the profile's {slope:.3g} m/s² between points {k} and {k + 1}",
                               f"a_max = {bounds.a_max:g} m/s²", kind, doc.locate(at + ("speed_profile", k + 1), value=True)))
            break
    return out


def _beyond(what: str, bound: str, kind: str, where: object) -> Diagnostic:
    return YML434(f"{what} is beyond what the safety layer assumes of a {kind} ({bound}): it is limited to that",
                  where, hint="raise assumptions.<kind> in the scenario to let it through (the guarantee then covers it)")  # type: ignore[arg-type]


def _chain(p: Participant, at: Path_, doc: Document, side: dict[str, tuple[str | None, str | None]],
           lengths: dict[str, float], bounds: MotionBounds, kind: str) -> list[Diagnostic]:
    out: list[Diagnostic] = []
    lane = p.start.lane if p.start is not None else None
    for k, m in enumerate(p.manoeuvres or []):
        here = at + ("manoeuvres", k)
        out += _rates(m, here, doc, bounds, kind)
        if m.lane_change is None or lane is None or lane not in side:
            continue
        where = doc.locate(here + ("lane_change",), value=True)
        left, right = side[lane]
        if m.lane_change in ("left", "right"):
            to = left if m.lane_change == "left" else right
            if to is None:
                out.append(YML420(f"lane '{lane}' has no lane of its direction on its {m.lane_change}", where,
                                  hint=f"the participant is on lane '{lane}' here (its start and the lane changes before)"))
        elif m.lane_change not in lengths:
            out.append(YML416(f"no lane '{m.lane_change}' in the map", where))
            to = None
        elif m.lane_change not in (left, right):
            out.append(YML420(f"lane '{m.lane_change}' is not beside lane '{lane}'", where,
                              hint=f"beside '{lane}': {', '.join(x for x in (left, right) if x) or 'no lane'}"))
            to = None
        else:
            to = m.lane_change
        lane = to or lane
    return out


def _walk(p: Participant, at: Path_, doc: Document, lengths: dict[str, float], bounds: MotionBounds) -> list[Diagnostic]:
    w = p.walk
    if w is None:
        return []
    out: list[Diagnostic] = []
    if w.lane is not None:
        if w.lane not in lengths:
            out.append(YML416(f"no lane '{w.lane}' in the map", doc.locate(at + ("walk", "lane"), value=True)))
        elif (w.s or 0.0) > lengths[w.lane] + 1e-6:
            out.append(YML420(f"s = {w.s:g} m is beyond the end of lane '{w.lane}' ({lengths[w.lane]:.1f} m long)",
                              doc.locate(at + ("walk", "s"), value=True)))
    if w.speed > bounds.v_max:
        out.append(_beyond(f"a walking speed of {w.speed:g} m/s", f"v_max = {bounds.v_max:g} m/s", "pedestrian",
                           doc.locate(at + ("walk", "speed"), value=True)))
    return out


def check_scripts(spec: ScenarioFile, doc: Document, m: MapFile) -> list[Diagnostic]:
    """Every finding about the scenario's manoeuvre chains and walks."""
    if not any(p.manoeuvres or p.walk for p in spec.participants):
        return []
    a: Assumptions = from_spec(spec.assumptions)
    ids = [p.id for p in spec.participants]
    users = kinds_of(ids, a, default=[user_of(p.kind) for p in spec.participants])
    side, lengths = lanes_beside(m), lane_lengths(m)
    out: list[Diagnostic] = []
    for i, (p, user) in enumerate(zip(spec.participants, users)):
        at: Path_ = ("participants", i)
        kind = KIND_NAMES[user]
        out += _chain(p, at, doc, side, lengths, a.bounds(user), kind)
        out += _walk(p, at, doc, lengths, a.bounds(user))
    return out
