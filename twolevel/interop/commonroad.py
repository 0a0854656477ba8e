"""CommonRoad XML scenarios as twolevel maps and scenarios (``twolevel import``).

What becomes what (commonroad-io ≥ 2024.3 reads the file: ``pip install 'twolevel[commonroad]'``;
lxml, which it brings, gives each element's line for the findings):

* **lanelets** → free-form lanes ``L<id>``: boundaries point by point, successors, adjacency,
  use (``type``: driving, shoulder, bus, bicycle, …), road categories (interstate, urban,
  main_carriageway, access_ramp, …), line markings;
* **traffic signs** → a lane's ``speed_limit`` (MAX_SPEED, value in m/s, on every lanelet that
  references the sign), stop signs at the lanelet's stop line (STOP; the lanelet's end without
  one), no-overtaking zones over the lanelet (NO_OVERTAKING_START); lanes without a sign get the
  German legal limit of their category (urban 50 km/h, country 100 km/h, interstate and highway
  the advisory 130 km/h), else the map's default (50 km/h);
* **traffic lights** → one light per lanelet that references it, at its stop line (else the
  lanelet's end): a green–yellow–red cycle when the CommonRoad cycle is one (red-yellow counts
  as red), else a script of its state changes over the run;
* **static obstacles** → ``stationary`` participants; **dynamic obstacles** with a trajectory →
  ``scripted`` participants (every state a waypoint, t = time step · dt), without one →
  ``constant_velocity`` (or ``stationary`` at speed 0); their ``kind`` (car, truck, bus,
  motorcycle, bicycle, pedestrian, other) from the obstacle type; rectangles give the box, a
  circle the square around it, a polygon its bounding box;
* **the planning problem** (the first) → the ego's start (pose, speed), the route from the
  lanelet it starts on to the goal, and the goal: a region's centre on the lanelet under it, a
  goal lanelet's middle, or without a position the end of the lanes straight ahead; the route
  stops there (the run ends when the ego stands in the goal: CommonRoad's solutions end in the
  goal region, and the route has no lanes beyond it) unless the goal's speed window excludes
  standing; a time window → ``expect.goal`` ``after`` / ``by`` [s]; dt → ``controller.dt``.

Everything else (yield and priority signs, intersections' right of way, goal speeds and
headings, further planning problems, environment obstacles, …) is an ``IMP710`` finding at its
element's line; conversions that lose detail are ``IMP714`` (:mod:`twolevel.interop.codes`).
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Any, Sequence

from twolevel.diagnostics import Diagnostic, Span
from twolevel.interop.codes import IMP701, IMP702, IMP703, IMP704, IMP706, IMP710, IMP714
from twolevel.interop import ImportResult
from twolevel.interop.output import MAP_FILE, SCENARIO_FILE, Imported, write_imported

__all__ = ["import_file", "import_commonroad", "lane_id", "obstacle_id", "LANE_TYPES", "CATEGORIES", "MARKINGS", "KINDS"]

KMH = 1.0 / 3.6
LANE_TYPES = {"shoulder": "shoulder", "busLane": "bus", "busStop": "bus", "bicycleLane": "bicycle",
              "sidewalk": "sidewalk", "crosswalk": "crosswalk", "parking": "parking", "border": "restricted",
              "restricted": "restricted", "restricted_area": "restricted"}
"""CommonRoad lanelet type (its XML value) → a lane's ``type``; the others are driving lanes."""
CATEGORIES = {"interstate": "interstate", "highway": "highway", "country": "country", "urban": "urban",
              "mainCarriageWay": "main_carriageway", "accessRamp": "access_ramp", "exitRamp": "exit_ramp",
              "driveWay": "drive_way", "intersection": "intersection"}
"""CommonRoad lanelet type → a lane's road category."""
CATEGORY_LIMITS = {"urban": 50 * KMH, "country": 100 * KMH, "highway": 130 * KMH, "interstate": 130 * KMH}
"""Speed [m/s] where no sign says otherwise, by road category (German StVO §3, advisory 130 km/h)."""
MARKINGS = {"dashed": "dashed", "broad_dashed": "dashed", "solid": "solid", "broad_solid": "solid",
            "solid_solid": "double_solid", "dashed_dashed": "dashed", "solid_dashed": "solid_dashed",
            "dashed_solid": "dashed_solid", "curb": "curb", "lowered_curb": "curb", "no_marking": "none"}
"""CommonRoad line marking → twolevel marking (``unknown`` is left unset)."""
KINDS = {"car": "car", "taxi": "car", "priorityVehicle": "car", "parkedVehicle": "car", "truck": "truck",
         "bus": "bus", "motorcycle": "motorcycle", "bicycle": "bicycle", "pedestrian": "pedestrian"}
"""CommonRoad obstacle type → participant ``kind`` (the rest: other)."""
NOT_PARTICIPANTS = {"roadBoundary", "building", "median_strip"}
"""Static obstacle types that are the road's edge, not traffic: the lanes already bound the road."""
MIN_BOX, MAX_LENGTH, MAX_WIDTH = 0.3, 30.0, 5.0  # [m] the schema's box limits
STOP_SPEED = 0.5  # [m/s] a goal whose speed window starts above it cannot be reached standing


def lane_id(lanelet: int) -> str:
    """The lane id of CommonRoad lanelet ``lanelet``."""
    return f"L{lanelet}"


def obstacle_id(obstacle: int) -> str:
    """The participant id of CommonRoad obstacle ``obstacle``."""
    return f"O{obstacle}"


class _Lines:
    """The source line of each element with an ``id`` attribute (ids are one namespace per file)."""

    def __init__(self, path: str) -> None:
        from lxml import etree

        self.path = path
        self.by_id: dict[str, int] = {}
        self.by_tag: dict[str, int] = {}
        for el in etree.parse(path, etree.XMLParser(huge_tree=True)).iter():
            if not isinstance(el.tag, str):
                continue
            self.by_tag.setdefault(el.tag, el.sourceline or 1)
            ident = el.get("id")
            if ident is not None:
                self.by_id.setdefault(ident, el.sourceline or 1)

    def at(self, ident: Any = None, tag: str | None = None) -> Span:
        line = self.by_id.get(str(ident)) if ident is not None else None
        if line is None and tag is not None:
            line = self.by_tag.get(tag)
        return Span(self.path, line or 1, 1)


def _polyline_s(centre: Any) -> Any:
    import numpy as np

    d = np.hypot(*np.diff(centre, axis=0).T)
    return np.concatenate([[0.0], np.cumsum(d)])


def _project(centre: Any, p: Any) -> tuple[float, float]:
    """Arc length [m] along polyline ``centre`` (N, 2) of the point nearest to ``p``, and the distance [m]."""
    import numpy as np

    a, b = centre[:-1], centre[1:]
    ab = b - a
    t = np.clip(((p - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
    q = a + t[:, None] * ab
    dist = np.hypot(*(q - p).T)
    i = int(np.argmin(dist))
    s = _polyline_s(centre)
    return float(s[i] + t[i] * np.hypot(*ab[i])), float(dist[i])


def _bounds(lanelet: Any) -> tuple[list[list[float]], list[list[float]]]:
    """Left and right boundary points, pairs whose midpoint is within 1 cm of the last kept one dropped."""
    import numpy as np

    left, right = np.asarray(lanelet.left_vertices, float), np.asarray(lanelet.right_vertices, float)
    mid = 0.5 * (left + right)
    keep = [0]
    for i in range(1, len(mid)):
        if np.hypot(*(mid[i] - mid[keep[-1]])) >= 0.011:
            keep.append(i)
        elif i == len(mid) - 1 and len(keep) > 1:
            keep[-1] = i
    return left[keep].tolist(), right[keep].tolist()


def _referencing(net: Any, attr: str) -> dict[int, list[Any]]:
    """Sign or light id → the lanelets whose ``attr`` (``traffic_signs``, ``traffic_lights``) name it, by id."""
    users: dict[int, list[Any]] = {}
    for ll in sorted(net.lanelets, key=lambda x: x.lanelet_id):
        for ref in getattr(ll, attr):
            users.setdefault(ref, []).append(ll)
    return users


class _Importer:
    def __init__(self, path: str, rules: Sequence[str], out_dir: str | None) -> None:
        self.path, self.rules, self.out_dir = path, rules, out_dir
        self.diags: list[Diagnostic] = []
        self.lines = _Lines(path)

    def note(self, code: Any, message: str, span: Span, hint: str | None = None) -> None:
        self.diags.append(code(message, span, hint))

    # ----------------------------------------------------------------------------- map
    def lanes(self, sc: Any) -> tuple[list[dict[str, Any]], dict[int, Any], dict[int, float]]:
        import numpy as np

        net = sc.lanelet_network
        out, centres, lengths = [], {}, {}
        known = {ll.lanelet_id for ll in net.lanelets}
        for ll in sorted(net.lanelets, key=lambda x: x.lanelet_id):
            left, right = _bounds(ll)
            lid = ll.lanelet_id
            centres[lid] = 0.5 * (np.asarray(left) + np.asarray(right))
            lengths[lid] = float(_polyline_s(centres[lid])[-1])
            types = sorted(t.value for t in (ll.lanelet_type or set()))
            use = sorted({LANE_TYPES[t] for t in types if t in LANE_TYPES})
            lane: dict[str, Any] = {"id": lane_id(lid)}
            if use:
                lane["type"] = use[0]
                if len(use) > 1:
                    self.note(IMP714, f"lanelet {lid} has the uses {', '.join(use)}: imported as a {use[0]} lane",
                              self.lines.at(lid))
            cats = sorted({CATEGORIES[t] for t in types if t in CATEGORIES})
            if cats:
                lane["categories"] = cats
            succ = [lane_id(s) for s in ll.successor if s in known]
            if succ:
                lane["successors"] = succ
            for side, adj, same in (("left", ll.adj_left, ll.adj_left_same_direction),
                                    ("right", ll.adj_right, ll.adj_right_same_direction)):
                if adj is not None and adj in known:
                    lane[f"adjacent_{side}"] = lane_id(adj)
            for side, marking in (("left", ll.line_marking_left_vertices), ("right", ll.line_marking_right_vertices)):
                kind = MARKINGS.get(getattr(marking, "value", ""))
                if kind is not None:
                    lane[f"{side}_marking"] = kind
            if ll.user_bidirectional:
                self.note(IMP710, f"lanelet {lid} is bidirectional for {', '.join(sorted(u.value for u in ll.user_bidirectional))}: "
                          "imported one way, in its boundaries' direction", self.lines.at(lid))
            lane["left_bound"], lane["right_bound"] = left, right
            out.append(lane)
        return out, centres, lengths

    def stop_s(self, ll: Any, centres: dict[int, Any], lengths: dict[int, float]) -> float:
        """Where traffic on lanelet ``ll`` stops [m]: its stop line's middle, else its end."""
        import numpy as np

        if ll.stop_line is not None and ll.stop_line.start is not None and ll.stop_line.end is not None:
            mid = 0.5 * (np.asarray(ll.stop_line.start, float) + np.asarray(ll.stop_line.end, float))
            return min(_project(centres[ll.lanelet_id], mid)[0], lengths[ll.lanelet_id])
        return lengths[ll.lanelet_id]

    def signs(self, sc: Any, lanes: list[dict[str, Any]], centres: dict[int, Any], lengths: dict[int, float],
              m: dict[str, Any]) -> set[int]:
        """Signs onto the lanes (speed limits, stop signs, no-overtaking zones); the lanelets with a stop sign."""
        net = sc.lanelet_network
        by_id = {lane["id"]: lane for lane in lanes}
        users = _referencing(net, "traffic_signs")
        stopped: set[int] = set()
        for sign in sorted(net.traffic_signs, key=lambda s: s.traffic_sign_id):
            sid = sign.traffic_sign_id
            on = users.get(sid, [])
            if not on:
                self.note(IMP710, f"traffic sign {sid} is referenced by no lanelet: it applies nowhere", self.lines.at(sid))
                continue
            for el in sign.traffic_sign_elements:
                name = el.traffic_sign_element_id.name
                code = el.traffic_sign_element_id.value
                if name == "MAX_SPEED" and el.additional_values:
                    try:
                        value = float(el.additional_values[0])
                    except ValueError:
                        value = float("nan")
                    if not 0 < value <= 100:
                        self.note(IMP710, f"traffic sign {sid}: speed limit {el.additional_values[0]!r} is not a speed "
                                  "in m/s between 0 and 100", self.lines.at(sid))
                        continue
                    for ll in on:
                        lane = by_id[lane_id(ll.lanelet_id)]
                        lane["speed_limit"] = min(lane.get("speed_limit", math.inf), value)
                elif name == "STOP":
                    for ll in on:
                        m["stop_signs"].append({"id": f"S{sid}-{lane_id(ll.lanelet_id)}", "lane": lane_id(ll.lanelet_id),
                                                "s": self.stop_s(ll, centres, lengths)})
                        stopped.add(ll.lanelet_id)
                elif name == "NO_OVERTAKING_START":
                    m["no_overtaking"] += [{"lane": lane_id(ll.lanelet_id), "s_range": [0.0, lengths[ll.lanelet_id]]}
                                           for ll in on]
                else:
                    self.note(IMP710, f"traffic sign {sid}: {name} ({code}) has no equivalent on free-form lanes",
                              self.lines.at(sid), hint="speed limits (MAX_SPEED), STOP and NO_OVERTAKING_START convert; "
                              "right of way comes from junction descriptions in twolevel")
        return stopped

    def lights(self, sc: Any, centres: dict[int, Any], lengths: dict[int, float], duration: float,
               m: dict[str, Any]) -> set[int]:
        """Lights onto the lanelets that reference them; the lanelets with a light."""
        net = sc.lanelet_network
        users = _referencing(net, "traffic_lights")
        lit: set[int] = set()
        for light in sorted(net.traffic_lights, key=lambda x: x.traffic_light_id):
            tid = light.traffic_light_id
            span = self.lines.at(tid)
            on = users.get(tid, [])
            if not on:
                self.note(IMP710, f"traffic light {tid} is referenced by no lanelet: it controls nothing", span)
                continue
            if not light.active:
                self.note(IMP710, f"traffic light {tid} is inactive: left out", span)
                continue
            program = self.program(light, sc.dt, duration, span)
            if program is None:
                continue
            if light.direction is not None and light.direction.value != "all":
                self.note(IMP714, f"traffic light {tid} controls only the direction '{light.direction.value}': "
                          "imported for every direction of its lanelets", span)
            for ll in on:
                lid = lane_id(ll.lanelet_id)
                m["traffic_lights"].append({"id": f"T{tid}" if len(on) == 1 else f"T{tid}-{lid}", "lane": lid,
                                            "s": self.stop_s(ll, centres, lengths), **program})
                lit.add(ll.lanelet_id)
        return lit

    def program(self, light: Any, dt: float, duration: float, span: Span) -> dict[str, Any] | None:
        """A light's program: ``{cycle: …}`` when its cycle is green, yellow, red (red-yellow as red), else ``{script: …}``."""
        cyc = light.traffic_light_cycle
        if cyc is None or not cyc.cycle_elements:
            self.note(IMP710, f"traffic light {light.traffic_light_id} has no cycle: left out", span)
            return None
        states = [e.state.value for e in cyc.cycle_elements]
        durs = [int(e.duration) for e in cyc.cycle_elements]
        if "inactive" in states:
            self.note(IMP714, f"traffic light {light.traffic_light_id}: its inactive phases are imported as green", span)
        shown = ["red" if s == "redYellow" else "green" if s == "inactive" else s for s in states]
        if "redYellow" in states:
            self.note(IMP714, f"traffic light {light.traffic_light_id}: red-yellow is imported as red "
                      "(no vehicle may go before green)", span)
        period = sum(durs)
        offset = int(cyc.time_offset or 0)
        # rotate to start where a green run starts, merge runs of one state: green, (yellow,) red?
        n = len(shown)
        heads = [i for i in range(n) if shown[i] == "green" and shown[i - 1] != "green"]
        if heads and period > 0:
            i0 = heads[0]
            runs: list[list[Any]] = []
            for s, d in zip(shown[i0:] + shown[:i0], durs[i0:] + durs[:i0]):
                if runs and runs[-1][0] == s:
                    runs[-1][1] += d
                else:
                    runs.append([s, d])
            by = {s: d for s, d in runs}
            if [r[0] for r in runs] in (["green", "yellow", "red"], ["green", "red"]):
                start = sum(durs[:i0])  # steps into CommonRoad's cycle where green starts
                # CommonRoad: state(k) = cycle[(k - time_offset) mod period]; twolevel: cycle[(t + offset) mod period]
                return {"cycle": {"green": by["green"] * dt, "yellow": by.get("yellow", 0) * dt, "red": by["red"] * dt,
                                  "offset": ((-offset - start) % period) * dt}}
        import numpy as np

        k = np.arange(max(1, int(math.ceil(duration / dt))) + 1)
        phase = np.searchsorted(np.cumsum(durs), (k - offset) % max(period, 1), side="right")
        state = np.asarray(shown)[np.minimum(phase, n - 1)]
        change = np.flatnonzero(np.r_[True, state[1:] != state[:-1]])
        script = [{"t": float(i * dt), "state": str(state[i])} for i in change]
        return {"script": script}

    # ----------------------------------------------------------------------- obstacles
    def box(self, shape: Any, oid: int) -> tuple[dict[str, float], tuple[float, float]]:
        """A shape's box {length, width} [m] and its centre's offset (along, across) [m]."""
        import numpy as np

        kind = type(shape).__name__
        if kind == "Rectangle":
            length, width, off = shape.length, shape.width, (0.0, 0.0)
        elif kind == "Circle":
            length = width = 2 * shape.radius
            off = (0.0, 0.0)
        else:
            pts = (np.asarray(shape.vertices, float) if kind == "Polygon" else
                   np.concatenate([np.asarray(getattr(s, "vertices", [[0, 0]]), float) for s in shape.shapes]))
            lo, hi = pts.min(0), pts.max(0)
            length, width = float(hi[0] - lo[0]), float(hi[1] - lo[1])
            off = (float(0.5 * (hi[0] + lo[0])), float(0.5 * (hi[1] + lo[1])))
            self.note(IMP714, f"obstacle {oid}: its {kind.lower()} shape is imported as its bounding box "
                      f"{length:.2f} m × {width:.2f} m", self.lines.at(oid))
        clipped = (min(max(length, MIN_BOX), MAX_LENGTH), min(max(width, MIN_BOX), MAX_WIDTH))
        if clipped != (length, width) and (length > MAX_LENGTH or width > MAX_WIDTH):
            self.note(IMP714, f"obstacle {oid}: its {length:.2f} m × {width:.2f} m are beyond a participant's box "
                      f"(at most {MAX_LENGTH:g} m × {MAX_WIDTH:g} m): clipped", self.lines.at(oid))
        return {"length": clipped[0], "width": clipped[1]}, off

    def participants(self, sc: Any, duration: float) -> list[dict[str, Any]]:
        import numpy as np

        out = []
        for ob in sorted(sc.static_obstacles + sc.dynamic_obstacles, key=lambda o: o.obstacle_id):
            oid, typ = ob.obstacle_id, ob.obstacle_type.value
            span = self.lines.at(oid)
            if typ in NOT_PARTICIPANTS:
                self.note(IMP710, f"obstacle {oid} ({typ}) is part of the road's edge, not traffic: left out "
                          "(the lanes bound the road)", span)
                continue
            box, off = self.box(ob.obstacle_shape, oid)
            s0 = ob.initial_state
            psi = float(getattr(s0, "orientation", 0.0) or 0.0)
            c, s_ = math.cos(psi), math.sin(psi)
            shift = np.array([c * off[0] - s_ * off[1], s_ * off[0] + c * off[1]])
            pos = np.asarray(s0.position.center if hasattr(s0.position, "center") else s0.position, float) + shift
            part: dict[str, Any] = {"id": obstacle_id(oid), "kind": KINDS.get(typ, "other")}
            v0 = float(getattr(s0, "velocity", 0.0) or 0.0)
            traj = getattr(getattr(ob, "prediction", None), "trajectory", None)
            if ob.obstacle_role.value == "static" or (traj is None and abs(v0) < 1e-9):
                part["behaviour"] = "stationary"
                part["start"] = {"x": float(pos[0]), "y": float(pos[1]), "heading": math.degrees(psi)}
            elif traj is None:
                part["behaviour"] = "constant_velocity"
                part["start"] = {"x": float(pos[0]), "y": float(pos[1]), "heading": math.degrees(psi)}
                part["speed"] = abs(v0)
                self.note(IMP714, f"obstacle {oid} has no trajectory (its prediction is "
                          f"{type(getattr(ob, 'prediction', None)).__name__}): it keeps its initial velocity", span)
            else:
                states = [s0] + list(traj.state_list)
                wps = []
                for st in states:
                    p = np.asarray(st.position.center if hasattr(st.position, "center") else st.position, float)
                    h = float(getattr(st, "orientation", psi) or 0.0)
                    p = p + np.array([math.cos(h) * off[0] - math.sin(h) * off[1], math.sin(h) * off[0] + math.cos(h) * off[1]])
                    t = int(st.time_step.start if hasattr(st.time_step, "start") else st.time_step) * sc.dt
                    if not wps or t > wps[-1]["t"]:
                        wps.append({"t": t, "x": float(p[0]), "y": float(p[1])})
                if len(wps) < 2:
                    part["behaviour"] = "stationary"
                    part["start"] = {"x": wps[0]["x"], "y": wps[0]["y"], "heading": math.degrees(psi)}
                else:
                    part["behaviour"] = "scripted"
                    part["waypoints"] = wps
                    if wps[0]["t"] > 0:
                        self.note(IMP714, f"obstacle {oid} appears at {wps[0]['t']:g} s: it stands at its first "
                                  "position until then", span)
                    if wps[-1]["t"] < duration - 1e-9:
                        self.note(IMP714, f"obstacle {oid}'s trajectory ends at {wps[-1]['t']:g} s: it stands at its "
                                  f"last position until the run's end ({duration:g} s)", span)
            part["box"] = box
            out.append(part)
        for what in ("environment_obstacle", "phantom_obstacle"):
            for ob in getattr(sc, what, None) or []:
                self.note(IMP710, f"{what.replace('_', ' ')} {ob.obstacle_id}: left out (no equivalent)",
                          self.lines.at(ob.obstacle_id))
        return out

    # ------------------------------------------------------------------- planning problem
    def on_lanelet(self, sc: Any, centres: dict[int, Any], p: Any, heading: float | None) -> tuple[int, float, float]:
        """The lanelet under point ``p`` [m] (facing ``heading`` [rad] best), else the nearest: (id, s [m], distance [m])."""
        import numpy as np

        p = np.asarray(p, float)
        under = [lid for lid in sc.lanelet_network.find_lanelet_by_position([p])[0] if lid in centres]
        candidates = under or list(centres)
        best = None
        for lid in candidates:
            s, d = _project(centres[lid], p)
            turn = 0.0
            if heading is not None:
                c = centres[lid]
                i = min(int(np.searchsorted(_polyline_s(c), s, side="right")) - 1, len(c) - 2)
                h = math.atan2(*(c[i + 1] - c[i])[::-1])
                turn = abs((h - heading + math.pi) % (2 * math.pi) - math.pi)
            key = (0 if lid in under else 1, turn > math.pi / 2, d)
            if best is None or key < best[0]:
                best = (key, lid, s, d)
        assert best is not None
        return best[1], best[2], best[3]

    def reachable(self, sc: Any, start: int) -> dict[int, int | None]:
        """Lanelets reachable from ``start`` by successors (breadth first) → the one before."""
        net = sc.lanelet_network
        seen: dict[int, int | None] = {start: None}
        todo = [start]
        while todo:
            nxt = []
            for lid in todo:
                for s in net.find_lanelet_by_id(lid).successor:
                    if s not in seen and net.find_lanelet_by_id(s) is not None:
                        seen[s] = lid
                        nxt.append(s)
            todo = nxt
        return seen

    def ego(self, sc: Any, pps: Any, centres: dict[int, Any], lengths: dict[int, float],
            scenario: dict[str, Any]) -> float | None:
        """Ego, route and goal from the first planning problem; the goal's deadline [s] (None: none)."""
        import numpy as np

        problems = sorted(pps.planning_problem_dict.values(), key=lambda p: p.planning_problem_id)
        if not problems:
            self.note(IMP710, "the file has no planning problem: the ego starts on the first lanelet, "
                      "its goal at the end of the lanes ahead", self.lines.at(tag="commonRoad"))
            first = min(centres)
            c = centres[first]
            start_lid, start_s, psi = first, 0.0, math.atan2(*(c[1] - c[0])[::-1])
            scenario["ego"] = {"start": {"lane": lane_id(first), "s": 0.0}, "speed": 0.0}
            goal_state, pp = None, None
        else:
            pp = problems[0]
            for other in problems[1:]:
                self.note(IMP710, f"planning problem {other.planning_problem_id}: only the first "
                          f"({pp.planning_problem_id}) is imported (a scenario has one ego)",
                          self.lines.at(other.planning_problem_id))
            s0 = pp.initial_state
            pos = np.asarray(s0.position, float)
            psi = float(getattr(s0, "orientation", 0.0) or 0.0)
            scenario["ego"] = {"start": {"x": float(pos[0]), "y": float(pos[1]), "heading": math.degrees(psi)},
                               "speed": max(float(getattr(s0, "velocity", 0.0) or 0.0), 0.0)}
            start_lid, start_s, dist = self.on_lanelet(sc, centres, pos, psi)
            if dist > 0.5 * 3.5 + 1.0:
                self.note(IMP714, f"planning problem {pp.planning_problem_id}: the initial position is {dist:.1f} m "
                          f"off every lanelet: the route starts on the nearest, {start_lid}",
                          self.lines.at(pp.planning_problem_id))
            goal_states = list(pp.goal.state_list)
            for k in range(1, len(goal_states)):
                self.note(IMP710, f"planning problem {pp.planning_problem_id}: goal state {k + 1} of "
                          f"{len(goal_states)} (an alternative) is not imported: the first is",
                          self.lines.at(pp.planning_problem_id))
            goal_state = goal_states[0] if goal_states else None
        span = self.lines.at(pp.planning_problem_id if pp is not None else None, tag="planningProblem")
        reach = self.reachable(sc, start_lid)
        goal_lid, goal_s = None, None
        lanes_of_goal = (getattr(pp.goal, "lanelets_of_goal_position", None) or {}) if pp is not None else {}
        position = getattr(goal_state, "position", None) if goal_state is not None else None
        if lanes_of_goal.get(0):
            options = [lid for lid in lanes_of_goal[0] if lid in reach] or list(lanes_of_goal[0])
            goal_lid = options[0]
            goal_s = 0.5 * lengths[goal_lid]
        elif position is not None:
            shapes = list(position.shapes) if type(position).__name__ == "ShapeGroup" else [position]
            if len(shapes) > 1:
                self.note(IMP714, f"the goal region is {len(shapes)} shapes: imported as the first", span)
            centre = np.asarray(shapes[0].center, float)
            lid, s, dist = self.on_lanelet(sc, {k: centres[k] for k in reach} if reach else centres, centre, None)
            goal_lid, goal_s = lid, s
            if dist > 2.0:
                self.note(IMP714, f"the goal region's centre is {dist:.1f} m from lanelet {lid}, the nearest the "
                          "ego can reach: the goal is its nearest point on it", span)
        else:
            lid, seen = start_lid, {start_lid}
            while True:
                nxt = [s for s in sc.lanelet_network.find_lanelet_by_id(lid).successor if s in centres and s not in seen]
                if not nxt:
                    break
                lid = nxt[0]
                seen.add(lid)
            goal_lid, goal_s = lid, max(lengths[lid] - 1.0, 0.5 * lengths[lid])
            if pp is not None:
                self.note(IMP714, "the goal has no position: the route follows the lanes straight ahead to the end of "
                          f"lanelet {lid}", span)
        if goal_lid == start_lid and goal_s is not None and goal_s <= start_s + 1.0:
            goal_s = lengths[goal_lid]
        if goal_lid not in reach:
            self.note(IMP714, f"the goal's lanelet {goal_lid} is not reachable by successors from the start's "
                      f"{start_lid}", span)
        scenario["route"] = {"start": {"lane": lane_id(start_lid), "s": start_s},
                             "goal": {"lane": lane_id(goal_lid), "s": min(goal_s, lengths[goal_lid])},
                             "stop_at_goal": True}
        deadline = None
        if goal_state is not None:
            ts = getattr(goal_state, "time_step", None)
            if ts is not None:
                lo, hi = (ts.start, ts.end) if hasattr(ts, "start") else (ts, ts)
                goal: dict[str, Any] = {}
                if hi is not None and hi > 0:
                    goal["by"] = hi * sc.dt
                    deadline = hi * sc.dt
                if lo is not None and lo > 0:
                    goal["after"] = lo * sc.dt
                if goal:
                    scenario.setdefault("expect", {})["goal"] = goal
            v = getattr(goal_state, "velocity", None)
            if v is not None:
                lo_v, hi_v = (v.start, v.end) if hasattr(v, "start") else (v, v)
                if lo_v is not None and lo_v > STOP_SPEED:
                    scenario["route"]["stop_at_goal"] = False
                    self.note(IMP710, f"the goal's speed window [{lo_v:g}, {hi_v:g}] m/s is not judged; the ego passes "
                              "the goal without stopping (and has no route beyond it)", span)
                elif hi_v is None or hi_v > STOP_SPEED:
                    self.note(IMP710, f"the goal's speed window [{lo_v:g}, {hi_v:g}] m/s is not judged", span)
            if getattr(goal_state, "orientation", None) is not None:
                o = goal_state.orientation
                self.note(IMP710, f"the goal's heading window [{math.degrees(o.start):.0f}, {math.degrees(o.end):.0f}] deg "
                          "is not judged", span)
        return deadline

    # -------------------------------------------------------------------------------- all
    def run(self) -> Imported:
        from commonroad.common.file_reader import CommonRoadFileReader

        logging.getLogger("commonroad").setLevel(logging.ERROR)
        try:
            sc, pps = CommonRoadFileReader(self.path).open()
        except Exception as exc:  # commonroad-io raises anything on a file it cannot read
            raise _Unreadable(f"commonroad-io cannot read the scenario: {type(exc).__name__}: {exc}") from exc
        m: dict[str, Any] = {"kind": "map", "name": str(sc.scenario_id), "stop_signs": [], "traffic_lights": [],
                             "no_overtaking": []}
        if not sc.lanelet_network.lanelets:
            raise _Unreadable("the scenario has no lanelet: nothing to drive on", IMP706)
        lanes, centres, lengths = self.lanes(sc)
        scenario: dict[str, Any] = {"kind": "scenario", "name": str(sc.scenario_id), "map": MAP_FILE}
        deadline = self.ego(sc, pps, centres, lengths, scenario)
        ends = [len(t.prediction.trajectory.state_list) + t.prediction.trajectory.initial_time_step
                for t in sc.dynamic_obstacles if getattr(getattr(t, "prediction", None), "trajectory", None) is not None]
        duration = deadline if deadline is not None else (max(ends) * sc.dt if ends else 30.0)
        duration = min(max(duration, 1.0), 3600.0)
        stopped = self.signs(sc, lanes, centres, lengths, m)
        lit = self.lights(sc, centres, lengths, duration, m)
        for ll in sc.lanelet_network.lanelets:
            if ll.stop_line is not None and ll.lanelet_id not in stopped | lit:
                self.note(IMP710, f"lanelet {ll.lanelet_id}'s stop line belongs to no stop sign or light: it obliges "
                          "nobody to stop", self.lines.at(ll.lanelet_id))
        for lane in lanes:
            if "speed_limit" not in lane:
                limits = [CATEGORY_LIMITS[c] for c in lane.get("categories", []) if c in CATEGORY_LIMITS]
                if limits:
                    lane["speed_limit"] = min(limits)
        for inter in sc.lanelet_network.intersections:
            self.note(IMP710, f"intersection {inter.intersection_id}: its turns are the lanelets' successors; who "
                      "yields to whom is not imported (stop signs and lights are)", self.lines.at(inter.intersection_id))
        m = {"kind": "map", "name": m["name"],
             "lanes": [{k: v for k, v in lane.items() if not k.endswith("_bound")}
                       | {"left_bound": lane["left_bound"], "right_bound": lane["right_bound"]} for lane in lanes],
             **{key: m[key] for key in ("stop_signs", "traffic_lights", "no_overtaking") if m[key]}}
        scenario["participants"] = self.participants(sc, duration)
        if self.rules:
            base = self.out_dir or os.path.dirname(self.path)
            scenario["rules"] = [os.path.relpath(os.path.abspath(r), os.path.abspath(base)) for r in self.rules]
        dt = float(sc.dt)
        if 0.01 <= dt <= 1.0:
            scenario["controller"] = {"dt": dt}
        else:
            self.note(IMP710, f"the scenario's time step {dt:g} s is outside twolevel's 0.01–1 s: the controller "
                      "runs at 0.1 s", self.lines.at(tag="commonRoad"))
        scenario["run"] = {"duration": duration}
        if "expect" in scenario:
            scenario["expect"] = scenario.pop("expect")
        return Imported(m, scenario, tuple(self.diags), self.path)


class _Unreadable(Exception):
    """The file cannot be used: ``code`` says why (IMP703 commonroad-io cannot read it, IMP706 it
    has nothing to convert)."""

    def __init__(self, message: str, code: Any = IMP703) -> None:
        super().__init__(message)
        self.code = code


def import_commonroad(path: str | os.PathLike[str], *, rules: Sequence[str] = (),
                      out_dir: str | os.PathLike[str] | None = None) -> tuple[Imported | None, list[Diagnostic]]:
    """Convert the CommonRoad scenario at ``path``: ``(Imported, findings)``, or ``(None,
    findings)`` when it cannot be read (IMP704 without commonroad-io, IMP701–IMP703 and IMP706 a file it
    cannot read or use). ``rules``: rule files the scenario lists, written relative to ``out_dir``."""
    path = str(path)
    try:
        import commonroad  # noqa: F401
        import lxml  # noqa: F401
    except ImportError:
        return None, [IMP704("reading CommonRoad scenarios needs commonroad-io", Span.whole_file(path),
                             hint="pip install 'twolevel[commonroad]'")]
    if not Path(path).is_file():
        return None, [IMP701(f"no such file: '{path}'", Span.whole_file(path))]
    try:
        importer = _Importer(path, rules, None if out_dir is None else str(out_dir))
    except Exception as exc:  # lxml's XMLSyntaxError carries the line
        line = getattr(exc, "lineno", None) or getattr(getattr(exc, "position", None), "__getitem__", lambda i: 1)(0)
        return None, [IMP702(f"not well-formed XML: {exc}", Span(path, int(line or 1), 1))]
    try:
        result = importer.run()
    except _Unreadable as exc:
        return None, importer.diags + [exc.code(str(exc), Span.whole_file(path))]
    return result, list(result.diagnostics)


def import_file(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], rules: Sequence[str] = ()) -> ImportResult:
    """Convert the CommonRoad scenario at ``path`` into ``out_dir/map.yaml`` and
    ``out_dir/scenario.yaml``, listing ``rules`` (paths of rule files), and check what was written:
    the importer's findings, then the checks' (at the written files' lines)."""
    from twolevel.world.lint import lint_world_file
    from twolevel.world.loader import check_world_file

    imported, diags = import_commonroad(path, rules=rules, out_dir=out_dir)
    if imported is None:
        return ImportResult((), tuple(diags))
    written = tuple(write_imported(imported, out_dir))
    scenario = Path(out_dir) / SCENARIO_FILE
    found = check_world_file(scenario) + lint_world_file(scenario)
    m = imported.map
    summary = (f"{len(m.get('lanes', []))} lanes, {len(imported.scenario.get('participants', []))} participants, "
               f"{len(m.get('traffic_lights', []))} lights")
    return ImportResult(written, tuple(diags + found), m, summary)
