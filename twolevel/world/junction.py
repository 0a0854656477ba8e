"""Junctions from a compact description, planned in pure Python (``twolevel check`` plans them too).

A map's ``junctions:`` name the roads meeting at each junction (which end of each road, with which
priority: ``priority`` road, ``yield``, ``stop`` or ``signal``). :func:`plan_junctions` turns that
into everything a junction is made of:

* **Arms**: per road end, its incoming lanes (travelling into the junction) and outgoing lanes,
  each ranked from the right in its own direction of travel (driving lanes only). The arm's
  heading is the direction of travel into the junction.
* **Connections** (turning lanes), by rule: *straight on* from every incoming lane into the
  outgoing lane of the same rank (or the leftmost there is); *right turns* from the rightmost
  incoming lane into the rightmost outgoing one; *left turns* from the leftmost into the leftmost;
  *U-turns* (back into the arm's own road) only with ``u_turns: true``. A turn is classified by
  the angle between the arms' headings (within 45° of straight on: straight). ``connections:``
  removes (``allow: false``) or adds connections by lane.
* **Geometry** of each connection: a biarc from the incoming lane's end pose to the outgoing
  lane's start pose — two circular arcs (or a line, where both lie on one) meeting tangentially,
  tangent to both lanes (G1 at both ends, curvature constant on each arc and bounded by
  ``min_radius``). Written as a road's segments (arcs of radius and angle), so the sampled lane is
  exact. The width goes linearly from the incoming lane's to the outgoing lane's.
* **Stop lines** ``setback`` [m] before the incoming lanes' ends on ``stop``, ``yield`` and
  ``signal`` arms; a stop sign on each stop arm's lane, a light on each signal arm's lane with
  a fixed-time program: phases in turn (opposite arms share one unless ``phase`` says otherwise),
  each green, yellow, then all red for the clearance.

Generated lanes are named ``<junction>:<incoming>><outgoing>``, stop signs and lights
``<junction>:<incoming>``. What cannot be built is returned as :class:`Problem` entries at the
YAML path that causes it (:mod:`twolevel.world.loader` turns them into diagnostics); conflicts
between the connections are computed from the sampled lanes (:mod:`twolevel.world.conflicts`).
Angles in radians inside, degrees in the segments (as the schema's). Standard library only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from twolevel.world.layout import Pose, lane_ends, lane_length
from twolevel.world.schema import MIN_PIECE, JunctionSpec, LaneSpec, MapFile, Road

__all__ = ["TURNS", "PRIORITIES", "Arm", "Connection", "StopLine", "Problem", "Plan", "plan_junctions",
           "biarc", "segments_end", "STRAIGHT_WITHIN"]

TURNS = ("straight", "left", "right", "uturn")
PRIORITIES = ("priority", "yield", "stop", "signal")
STRAIGHT_WITHIN = math.radians(45.0)
"""A connection whose heading changes by less than this is straight on [rad]."""

Path_ = tuple[str | int, ...]


@dataclass(frozen=True)
class Arm:
    """A road end at a junction: ``point`` (x, y) [m] where its reference line ends there,
    ``heading`` [rad] of travel into the junction, lanes ``incoming`` / ``outgoing`` ranked from
    the right (ids), its ``priority`` (one of :data:`PRIORITIES`), signal ``phase`` (−1: none)."""

    index: int
    road: str
    end: str
    priority: str
    phase: int
    stop_time: float
    point: tuple[float, float]
    heading: float
    incoming: tuple[str, ...]
    outgoing: tuple[str, ...]


@dataclass(frozen=True)
class Connection:
    """A connecting lane ``id`` from lane ``incoming`` (arm ``arm_in``) to lane ``outgoing`` (arm
    ``arm_out``), a ``turn`` (one of :data:`TURNS`): its centre line starts at ``start`` and runs
    along ``segments`` (``{"line": L}`` / ``{"arc": {"radius", "angle" [deg]}}``), ``length`` [m]
    long; widths ``width_in`` → ``width_out`` [m]; ``radius`` [m] its tightest arc (inf: straight)."""

    id: str
    incoming: str
    outgoing: str
    arm_in: int
    arm_out: int
    turn: str
    start: Pose
    segments: tuple[dict, ...]
    length: float
    width_in: float
    width_out: float
    radius: float

    def road(self) -> Road:
        """The connection's centre line as a road (for sampling it exactly)."""
        return Road(id=self.id, start={"x": self.start.x, "y": self.start.y, "heading": math.degrees(self.start.heading)},
                    segments=list(self.segments))


@dataclass(frozen=True)
class StopLine:
    """A line on incoming lane ``lane`` at ``s`` [m] of arm ``arm``: ``kind`` stop, yield or
    signal; ``id`` of the stop sign or light made for it (stop and signal arms)."""

    id: str
    lane: str
    s: float
    kind: str
    arm: int
    stop_time: float
    phase: int


@dataclass(frozen=True)
class Problem:
    """Something that cannot be built: the YAML path it is at, the code, message and hint."""

    at: Path_
    code: str
    message: str
    hint: str | None = None


@dataclass(frozen=True)
class Plan:
    """One junction planned: its ``arms``, ``connections``, stop ``lines``, and its light program
    ``cycle`` = (green, yellow, clearance, offset [s], number of phases) when signalised."""

    id: str
    index: int
    arms: tuple[Arm, ...]
    connections: tuple[Connection, ...]
    lines: tuple[StopLine, ...]
    cycle: tuple[float, float, float, float, int] | None
    problems: tuple[Problem, ...]

    def light_cycle(self, phase: int) -> tuple[float, float, float, float]:
        """(green, yellow, red, offset) [s] of the lights of ``phase`` (fixed time: each phase
        green, then yellow, then all red for the clearance, in turn)."""
        assert self.cycle is not None
        green, yellow, clear, offset, n = self.cycle
        step = green + yellow + clear
        period = n * step
        return green, yellow, period - green - yellow, (offset - phase * step) % period


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _arc_to(p: tuple[float, float], h: float, q: tuple[float, float]) -> tuple[dict | None, float, float]:
    """The arc (or line) from ``p`` heading ``h`` [rad] to ``q``: (segment, heading at q [rad],
    radius [m], inf for a line); None for a piece shorter than MIN_PIECE."""
    cx, cy = q[0] - p[0], q[1] - p[1]
    c = math.hypot(cx, cy)
    if c < MIN_PIECE:
        return None, h, math.inf
    turn = 2.0 * math.atan2(math.cos(h) * cy - math.sin(h) * cx, math.cos(h) * cx + math.sin(h) * cy)
    if abs(turn) < 1e-9:
        return {"line": c}, h, math.inf
    radius = c / (2.0 * abs(math.sin(turn / 2.0)))
    return {"arc": {"radius": radius, "angle": math.degrees(turn)}}, h + turn, radius


def biarc(start: Pose, end: Pose) -> tuple[tuple[dict, ...], float] | None:
    """The biarc from ``start`` to ``end`` (poses with headings [rad]): two arcs meeting at the
    midpoint of the points d along each tangent, d chosen so those points are 2d apart (the
    equal-tangent biarc); a line when both poses lie on one. Returns (segments, smallest radius
    [m]) or None when there is none (parallel headings with the end straight beside the start)."""
    t0 = (math.cos(start.heading), math.sin(start.heading))
    t1 = (math.cos(end.heading), math.sin(end.heading))
    v = (end.x - start.x, end.y - start.y)
    vv = v[0] ** 2 + v[1] ** 2
    if vv < MIN_PIECE**2:
        return None
    if abs(_wrap(end.heading - start.heading)) < 1e-9 and abs(t0[0] * v[1] - t0[1] * v[0]) < 1e-9 and t0[0] * v[0] + t0[1] * v[1] > 0:
        return ({"line": math.sqrt(vv)},), math.inf
    t = (t0[0] + t1[0], t0[1] + t1[1])
    vt = v[0] * t[0] + v[1] * t[1]
    tt = t[0] ** 2 + t[1] ** 2
    if abs(4.0 - tt) < 1e-12:
        if vt <= 1e-12:
            return None
        d = vv / (2.0 * vt)
    else:
        d = (-vt + math.sqrt(vt * vt + (4.0 - tt) * vv)) / (4.0 - tt)
    if not d > 0 or not math.isfinite(d):
        return None
    q0 = (start.x + d * t0[0], start.y + d * t0[1])
    q1 = (end.x - d * t1[0], end.y - d * t1[1])
    joint = (0.5 * (q0[0] + q1[0]), 0.5 * (q0[1] + q1[1]))
    first, h_joint, r1 = _arc_to((start.x, start.y), start.heading, joint)
    second, h_end, r2 = _arc_to(joint, h_joint, (end.x, end.y))
    segs = tuple(s for s in (first, second) if s is not None)
    if not segs or abs(_wrap(h_end - end.heading)) > 1e-6:
        return None
    return segs, min(r1, r2)


def segments_end(start: Pose, segments: tuple[dict, ...]) -> tuple[Pose, float]:
    """Where a centre line from ``start`` along ``segments`` ends, and its length [m]."""
    x, y, h, length = start.x, start.y, start.heading, 0.0
    for seg in segments:
        if "line" in seg:
            x, y = x + seg["line"] * math.cos(h), y + seg["line"] * math.sin(h)
            length += seg["line"]
        else:
            r, th = seg["arc"]["radius"], math.radians(seg["arc"]["angle"])
            sign = 1.0 if th > 0 else -1.0
            cx, cy = x - sign * r * math.sin(h), y + sign * r * math.cos(h)
            h += th
            x, y = cx + sign * r * math.sin(h), cy - sign * r * math.cos(h)
            length += r * abs(th)
    return Pose(x, y, h), length


# ------------------------------------------------------------------------------- planning


def _arm(jspec: JunctionSpec, k: int, road: Road) -> Arm:
    a = jspec.arms[k]
    lanes = [ln for ln in road.lane_specs() if ln.type == "driving"]
    into = "forward" if a.end == "end" else "backward"
    # rank from the right in each lane's direction of travel: forward lanes by offset, backward by −offset
    rank = lambda ln: ln.offset if ln.direction == "forward" else -ln.offset  # noqa: E731
    incoming = tuple(ln.id for ln in sorted((ln for ln in lanes if ln.direction == into), key=rank))
    outgoing = tuple(ln.id for ln in sorted((ln for ln in lanes if ln.direction != into), key=rank))
    ref = lane_ends(road, LaneSpec(id=road.id))
    pose = ref[1] if a.end == "end" else ref[0]
    heading = pose.heading if a.end == "end" else pose.heading + math.pi
    return Arm(k, a.road, a.end, a.priority, -1 if a.priority != "signal" else (a.phase if a.phase is not None else -1),
               a.stop_time, (pose.x, pose.y), heading, incoming, outgoing)


def _phases(arms: list[Arm]) -> list[Arm]:
    """Signal phases where none is given: each arm shares the phase of the arm opposite it."""
    out = list(arms)
    given = {a.phase for a in arms if a.phase >= 0}
    nxt = 0
    for i, a in enumerate(out):
        if a.priority != "signal" or a.phase >= 0:
            continue
        while nxt in given:
            nxt += 1
        out[i] = a = _with_phase(a, nxt)
        given.add(nxt)
        for j in range(i + 1, len(out)):
            b = out[j]
            if b.priority == "signal" and b.phase < 0 and abs(_wrap(b.heading - a.heading - math.pi)) < STRAIGHT_WITHIN:
                out[j] = _with_phase(b, nxt)
                break
    return out


def _with_phase(a: Arm, phase: int) -> Arm:
    return Arm(a.index, a.road, a.end, a.priority, phase, a.stop_time, a.point, a.heading, a.incoming, a.outgoing)


def _turn(a: Arm, b: Arm) -> str:
    if a.index == b.index:
        return "uturn"
    d = _wrap((b.heading + math.pi) - a.heading)  # b's outbound heading against a's inbound
    if abs(d) < STRAIGHT_WITHIN:
        return "straight"
    return "left" if d > 0 else "right"


def _by_rule(arms: list[Arm], u_turns: bool) -> list[tuple[str, str, int, int, str]]:
    out = []
    for a in arms:
        if not a.incoming:
            continue
        for b in arms:
            if not b.outgoing:
                continue
            turn = _turn(a, b)
            if turn == "straight":
                out += [(lane, b.outgoing[min(r, len(b.outgoing) - 1)], a.index, b.index, turn)
                        for r, lane in enumerate(a.incoming)]
            elif turn == "right":
                out.append((a.incoming[0], b.outgoing[0], a.index, b.index, turn))
            elif turn == "left" or (turn == "uturn" and u_turns):
                out.append((a.incoming[-1], b.outgoing[-1], a.index, b.index, turn))
    return out


def plan_junctions(spec: MapFile) -> list[Plan]:
    """Every junction of ``spec`` planned (see the module docstring); references to roads and
    lanes that do not exist are :class:`Problem` entries of their junction."""
    roads = {r.id: r for r in spec.roads}
    widths = {ln.id: ln.width for r in spec.roads for ln in r.lane_specs()}
    road_lanes = {ln.id: (r, ln) for r in spec.roads for ln in r.lane_specs()}
    plans: list[Plan] = []
    used: dict[tuple[str, str], str] = {}  # road end → the junction it meets
    for ji, j in enumerate(spec.junctions):
        at = ("junctions", ji)
        problems: list[Problem] = []
        arms: list[Arm] = []
        for k, a in enumerate(j.arms):
            road = roads.get(a.road)
            if road is None:
                problems.append(Problem(at + ("arms", k, "road"), "YML416", f"no road '{a.road}' in the map",
                                        f"roads: {', '.join(sorted(roads)[:12])}"))
                continue
            arm = _arm(j, k, road)
            if (a.road, a.end) in used:
                problems.append(Problem(at + ("arms", k, "end"), "YML420",
                                        f"the {a.end} of road '{a.road}' already meets junction '{used[(a.road, a.end)]}'",
                                        "a road end meets one junction, once"))
            used[(a.road, a.end)] = j.id
            if not arm.incoming and not arm.outgoing:
                problems.append(Problem(at + ("arms", k, "road"), "YML420", f"road '{a.road}' has no driving lane to meet the junction with"))
            arms.append(arm)
        signal = [a.priority == "signal" for a in j.arms]
        if any(signal) and not all(signal):
            k = signal.index(False) if signal[0] else signal.index(True)
            problems.append(Problem(at + ("arms", k, "priority"), "YML415",
                                    "a junction is signalised on every arm or on none",
                                    "give every arm 'priority: signal', or none of them"))
        if any(signal) and j.signals is None:
            problems.append(Problem(at, "YML415", "signal arms need the junction's light program",
                                    "add 'signals: {green: 20, yellow: 3}' [s] to the junction"))
        arms = _phases(arms)
        links = _by_rule(arms, j.u_turns)
        for n, c in enumerate(j.connections):
            src = next((a for a in arms if c.incoming in a.incoming), None)
            dst = next((a for a in arms if c.outgoing in a.outgoing), None)
            if src is None or dst is None:
                which, lane = ("incoming", c.incoming) if src is None else ("outgoing", c.outgoing)
                lanes = sorted({x for a in arms for x in (a.incoming if which == "incoming" else a.outgoing)})
                problems.append(Problem(at + ("connections", n, which), "YML416",
                                        f"lane '{lane}' is not an {which} lane of junction '{j.id}'",
                                        f"{which} lanes here: {', '.join(lanes[:12])}"))
                continue
            links = [x for x in links if (x[0], x[1]) != (c.incoming, c.outgoing)]
            if c.allow:
                links.append((c.incoming, c.outgoing, src.index, dst.index, _turn(src, dst)))
        conns: list[Connection] = []
        for lane_in, lane_out, ai, bi, turn in links:
            r_in, l_in = road_lanes[lane_in]
            r_out, l_out = road_lanes[lane_out]
            p0 = lane_ends(r_in, l_in)[1]
            p1 = lane_ends(r_out, l_out)[0]
            geo = biarc(p0, p1)
            cid = f"{j.id}:{lane_in}>{lane_out}"
            where = next((at + ("connections", n) for n, c in enumerate(j.connections)
                          if (c.incoming, c.outgoing) == (lane_in, lane_out)), at + ("arms", ai))
            if geo is None or geo[1] < j.min_radius - 1e-9:
                radius = "no smooth curve joins them" if geo is None else f"it would turn at radius {geo[1]:.3g} m"
                problems.append(Problem(where, "YML420",
                                        f"no {turn} connection from lane '{lane_in}' to lane '{lane_out}': {radius} "
                                        f"(min_radius {j.min_radius:g} m)",
                                        "move the roads' ends further from the junction, lower 'min_radius', or leave the "
                                        f"connection out with 'connections: [{{incoming: {lane_in}, outgoing: {lane_out}, allow: false}}]'"))
                continue
            segs, radius = geo
            _, length = segments_end(p0, segs)
            conns.append(Connection(cid, lane_in, lane_out, ai, bi, turn, p0, segs, length, widths[lane_in], widths[lane_out], radius))
        lines = []
        for a in arms:
            if a.priority == "priority":
                continue
            for lane in a.incoming:
                r, ln = road_lanes[lane]
                length = lane_length(r, ln.offset)
                if j.setback >= length:
                    problems.append(Problem(at + ("setback",), "YML420",
                                            f"the stop line {j.setback:g} m before the end of lane '{lane}' ({length:.3g} m long) "
                                            "would lie before its start", "lower 'setback'"))
                    continue
                lines.append(StopLine(f"{j.id}:{lane}", lane, length - j.setback, a.priority, a.index, a.stop_time, a.phase))
        cycle = None
        if j.signals is not None and any(signal):
            n = max((a.phase for a in arms), default=0) + 1
            cycle = (j.signals.green, j.signals.yellow, j.signals.clearance, j.signals.offset, n)
        plans.append(Plan(j.id, ji, tuple(arms), tuple(conns), tuple(lines), cycle, tuple(problems)))
    return plans
