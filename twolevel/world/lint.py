"""Warnings about valid scenarios that cannot do what they say (``twolevel check``).

* YML426: a value within a parameter's range (its ends, every choice, a normal distribution's
  mean ± 3 standard deviations) makes the scenario invalid — found by loading the scenario
  there, one parameter at a time and, for a few parameters, at every corner of their box;
* YML427: the goal is out of reach: at the highest speed the route allows (its speed limits,
  capped by the ego's desired speed) the route takes longer than the run or the goal's
  deadline (``expect.goal.by``);
* YML431: the ego cannot stop within its sensing range from the highest speed the scenario
  allows (the same speed): it will keep below the speed it can stop from
  (:class:`~twolevel.world.loader.Sensing`), slower than the scenario asks;
* YML432: a bend of the route cannot be driven at the speed limit in force there (capped by
  the desired speed) within the comfort lateral acceleration (``controller.comfort_lat_accel``):
  the desired speed (:mod:`twolevel.world.speed_profile`) slows the ego below the limit there.
  Reported at the sign (or the lane's own limit) in force, or at the bend's arc when the map's
  default limit holds.

Imported by ``twolevel check``: pydantic, PyYAML and the standard library only.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import TYPE_CHECKING

from twolevel.diagnostics import Diagnostic
from twolevel.world.codes import YML426, YML427, YML431, YML432
from twolevel.world.schema import LaneSpec, Parameter, Road

if TYPE_CHECKING:
    from twolevel.world.loader import Scenario

__all__ = ["lint_scenario", "lint_world_file", "extremes", "lane_bends", "MAX_CORNERS"]

MAX_CORNERS = 16
"""Parameter boxes with at most this many corners are also checked at every corner."""


def extremes(p: Parameter) -> tuple[float, ...]:
    """The values a parameter is checked at: its range's ends, every choice, or a normal
    distribution's mean ± 3 standard deviations (within its range)."""
    if p.choices is not None:
        values = tuple(p.choices)
    elif p.range is not None:
        values = p.range
    else:
        assert p.normal is not None
        values = (p.normal.mean - 3 * p.normal.std, p.normal.mean + 3 * p.normal.std)
    values = tuple(float(round(v)) if p.integer else float(v) for v in values)
    return tuple(dict.fromkeys(values))


def _first_error(path: str, values: dict[str, float]) -> Diagnostic | None:
    from twolevel.world.loader import load_scenario

    _, diags = load_scenario(path, values)
    return next((d for d in diags if d.is_error), None)


def _parameter_ranges(scn: "Scenario") -> list[Diagnostic]:
    from twolevel.world.loader import _read_kind

    params = scn.spec.parameters
    if not params:
        return []
    doc, _ = _read_kind(Path(scn.path), "scenario", None)
    if doc is None:
        return []
    out: list[Diagnostic] = []
    for name, p in params.items():
        for value in extremes(p):
            err = _first_error(scn.path, {name: value})
            if err is not None:
                key = "choices" if p.choices is not None else "range" if p.range is not None else "normal"
                out.append(YML426(f"with {name} = {value:g} the scenario is invalid: {err.span}: {err.message}",
                                  doc.locate(("parameters", name, key), value=True),
                                  hint="narrow the range, or move what the parameter places"))
                break
    box = [extremes(p) for p in params.values()]
    n_corners = 1
    for values in box:
        n_corners *= len(values)
    if out or len(params) < 2 or n_corners > MAX_CORNERS:
        return out
    for corner in itertools.product(*box):
        values = dict(zip(params, corner))
        err = _first_error(scn.path, values)
        if err is not None:
            shown = ", ".join(f"{k} = {v:g}" for k, v in values.items())
            out.append(YML426(f"with {shown} the scenario is invalid: {err.span}: {err.message}",
                              doc.locate(("parameters",)), hint="these parameters' ranges clash at this corner"))
            break
    return out


def _goal_time(scn: "Scenario") -> list[Diagnostic]:
    from twolevel.world.loader import _read_kind, _route_lanes, all_lengths, fastest, route_length, successors

    spec, m = scn.spec, scn.map.spec
    if spec.expect.goal is None:
        return []
    lanes = _route_lanes(spec, successors(m))
    if lanes is None:
        return []
    length = route_length(spec, lanes, all_lengths(m))
    fastest_v, _ = fastest(scn, lanes)
    least = length / fastest_v  # [s] a lower bound: no acceleration, no stop
    by = spec.expect.goal.by
    deadline, loc = (by, ("expect", "goal", "by")) if by is not None and by < spec.run.duration else \
        (spec.run.duration, ("run", "duration"))
    if least <= deadline:
        return []
    doc, _ = _read_kind(Path(scn.path), "scenario", None)
    span = doc.locate(loc, value=True) if doc is not None else None
    if span is None:
        return []
    return [YML427(f"the goal is out of reach: the route is {length:.0f} m long, at least {least:.1f} s at "
                   f"{fastest_v:g} m/s, but {'the deadline' if loc[0] == 'expect' else 'the run'} is {deadline:g} s",
                   span, hint="lengthen the run, move the goal closer, or set 'expect: {goal: false}'")]


def _sensing(scn: "Scenario") -> list[Diagnostic]:
    """YML431, at ``controller.sensor_range`` (or the section, or the file, where it is not given)."""
    from twolevel.world.assumptions import safe_distance
    from twolevel.world.loader import _read_kind, _route_lanes, fastest, sensing_of, successors

    spec = scn.spec
    lanes = _route_lanes(spec, successors(scn.map.spec)) or [spec.route.start.lane]
    v, why = fastest(scn, lanes)
    sense = sensing_of(spec)
    need = float(safe_distance(v, 0.0, sense.response)) + spec.ego.box.length + sense.margin
    if need <= sense.range + 1e-9:
        return []
    doc, _ = _read_kind(Path(scn.path), "scenario", None)
    if doc is None:
        return []
    r = sense.response
    return [YML431(
        f"sensing range {sense.range:g} m is shorter than the {need:.1f} m the ego needs to stop behind a standing "
        f"car at {v:g} m/s ({why}; response {r.time:g} s, braking {r.brake_min:g} m/s², one car length and "
        f"{sense.margin:g} m); it will drive at most {sense.v_bound:.1f} m/s",
        doc.locate(("controller", "sensor_range"), value=True),
        hint=f"set controller.sensor_range to at least {math.ceil(need)} m, or lower the speed this scenario allows")]


def lane_bends(road: "Road", lane: "LaneSpec") -> list[tuple[float, float, float, int]]:
    """The bends of ``lane`` of ``road``: (s_from, s_to [m] along the lane in its direction of
    travel, radius [m] of the lane's centre line, the road's segment index), one per arc."""
    from twolevel.world.layout import lane_pieces

    pieces = list(lane_pieces(road, lane.offset))
    out = [(a, b, abs(1.0 / p.curvature - lane.offset), p.segment) for a, b, p in pieces if p.curvature]
    if lane.direction == "backward":
        total = pieces[-1][1] if pieces else 0.0
        out = [(total - b, total - a, r, j) for a, b, r, j in reversed(out)]
    return out


def _bends(scn: "Scenario") -> list[Diagnostic]:
    """YML432 at the speed-limit sign (or the lane's own limit) in force in a bend of the route
    that cannot be driven at the comfort lateral acceleration, else at the bend's arc."""
    from twolevel.world.loader import _read_kind, _route_lanes, successors

    spec, m = scn.spec, scn.map.spec
    lanes = _route_lanes(spec, successors(m)) or [spec.route.start.lane]
    a_lat = spec.controller.comfort_lat_accel
    where = {ln.id: (i, j, road, ln) for i, road in enumerate(m.roads) for j, ln in enumerate(road.lane_specs())}
    out: list[Diagnostic] = []
    docs: dict[str, object] = {}
    for n, lane_id in enumerate(lanes):
        if lane_id not in where:  # a junction's connecting lane or a free-form lane: no road arcs to read
            continue
        i, j, road, lane = where[lane_id]
        lo = spec.route.start.s if n == 0 else -math.inf
        hi = spec.route.goal.s if n == len(lanes) - 1 else math.inf
        signs = sorted(((sign.s, k, sign.value) for k, sign in enumerate(m.speed_limits) if sign.lane == lane_id))
        for a, b, radius, seg in lane_bends(road, lane):
            a, b = max(a, lo), min(b, hi)
            if b <= a:
                continue
            # the limits in force over [a, b]: the last sign before a (or the lane's own), the signs within
            before = [x for x in signs if x[0] <= a]
            in_force = ([(None, before[-1][1], before[-1][2])] if before else
                        [(("roads", i, "lanes", j, "speed_limit") if lane.speed_limit else None, None,
                          lane.speed_limit or m.default_speed_limit)])
            in_force += [(None, k, value) for s_sign, k, value in signs if a < s_sign < b]
            key, k, v = max(in_force, key=lambda x: x[2])
            v_drive = min(v, spec.ego.desired_speed) if spec.ego.desired_speed is not None else v
            need = v_drive * v_drive / radius
            if need <= a_lat + 1e-9:
                continue
            if scn.map.path not in docs:
                docs[scn.map.path], _ = _read_kind(Path(scn.map.path), "map", None)
            doc = docs[scn.map.path]
            if doc is None:
                continue
            loc = ("speed_limits", k, "value") if k is not None else key or ("roads", i, "segments", seg, "arc")
            v_ok = math.sqrt(a_lat * radius)
            out.append(YML432(
                f"the limit {v:g} m/s{'' if v_drive == v else f' (desired speed {v_drive:g} m/s)'} cannot be driven "
                f"through the {radius:.1f} m bend of lane '{lane_id}' (route {scn.path}): {need:.1f} m/s² of lateral "
                f"acceleration, more than the comfort {a_lat:g} m/s²; the ego will slow to {v_ok:.1f} m/s there",
                doc.locate(loc, value=True),  # type: ignore[attr-defined]
                hint=f"a sign of at most {math.floor(v_ok * 10) / 10:g} m/s before the bend, or "
                     "controller.comfort_lat_accel if this is meant"))
    return out


def lint_scenario(scn: "Scenario") -> list[Diagnostic]:
    """Every warning of this module for a loaded scenario."""
    return _parameter_ranges(scn) + _goal_time(scn) + _sensing(scn) + _bends(scn)


def lint_world_file(path: str) -> list[Diagnostic]:
    """The warnings of this module for a ``.yaml`` file: none for a map or a scenario that does
    not load (``check_world_file`` reports why)."""
    from twolevel.world.document import read_document
    from twolevel.world.loader import file_kind, load_scenario

    doc, _ = read_document(path)
    if doc is None or file_kind(doc.data) != "scenario":
        return []
    scn, _ = load_scenario(path)
    return lint_scenario(scn) if scn is not None else []
