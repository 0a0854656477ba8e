"""The runtime world: a loaded :class:`~twolevel.world.loader.Scenario` turned into arrays.

``build_world(scenario)`` samples the map's lanes, builds the route (reference path, limits,
desired speed), the tables of signs and lights (with the conflicts each stop line gives way to),
the participants (:mod:`twolevel.world.participants`: kinds, populations expanded with the seed)
and their initial state. Everything here is frozen dataclasses and numpy arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from types import MappingProxyType
from typing import TYPE_CHECKING, Mapping

import numpy as np

from twolevel.world.assumptions import RSS_BOUNDS, Assumptions, ResponseBounds, from_spec
from twolevel.world.conflicts import Junctions, build_junctions
from twolevel.world.geometry import LaneSet, Route, concatenate, resample, step_index
from twolevel.world.junction import Plan
from twolevel.world.lanes import build_lanes
from twolevel.world.loader import Scenario, _route_lanes, near_radius, sensing_of, successors
from twolevel.world.participants import participants_of, pose_of
from twolevel.world.schema import ControllerSettings, LightCycle, MapFile
from twolevel.world.speed_profile import Comfort, speed_profile
from twolevel.world.traffic import GREEN, RED, YELLOW, Lights, Participants, SpeedLimits, StopLines, TrafficState
from twolevel.world.traffic.junctions import conflicts_of

if TYPE_CHECKING:
    from twolevel.world.crosswalks import RouteCrosswalks
    from twolevel.world.right_of_way import RouteZones

__all__ = ["EgoStart", "Settings", "World", "build_world"]
_STATES = {"green": GREEN, "yellow": YELLOW, "red": RED}


@dataclass(frozen=True)
class EgoStart:
    """The ego's initial state x, y [m], psi [rad], v [m/s], box [m] and vehicle overrides."""

    x: float
    y: float
    psi: float
    v: float
    length: float
    width: float
    vehicle: Mapping[str, float]


@dataclass(frozen=True)
class Settings:
    """Controller and run settings (see :class:`~twolevel.world.schema.ControllerSettings`)."""

    H: int
    dt: float
    r_near: float
    r: float
    D_safe: float
    samples: int
    time_limit: float
    solver: str
    stop_speed: float
    yellow_decel: float
    duration: float
    seed: int
    horizon_s: float | None = None
    """[s] The MPC's look-ahead (None: the default of :mod:`twolevel.control.high_level.settings`)."""
    coarse_dt: float | None = None
    """[s] Its coarse steps' length (None: the default)."""
    coarse_steps: tuple[float, ...] | None = None
    """[s] Its coarse steps, explicitly."""
    rss: bool = True
    """The MPC plans to keep RSS's distance behind the vehicle ahead."""
    sensor_range: float = 100.0
    """[m] How far the ego senses: vehicles ahead for RSS's distance (the ``rss_gap`` signal, the
    MPC's rows) and the speed it can stop from (:class:`~twolevel.world.loader.Sensing`); the
    safety layer's participants. The MPC constrains only the vehicles within ``r_near``."""
    response: ResponseBounds = RSS_BOUNDS
    """RSS's response with the ego as the rear car (:class:`~twolevel.world.loader.Sensing`)."""
    v_sense: float = math.inf
    """[m/s] The speed from which the ego stops within its sensing range (D_safe short of a
    standing car just beyond it)."""
    comfort: Comfort = Comfort()
    """The desired speed's comfort limits (:mod:`twolevel.world.speed_profile`)."""
    v2i: bool = False
    """The planner knows the lights' programs (else only each light's state now)."""
    weights: tuple[float, float, tuple[float, float, float, float]] = (1.0, 1.0, (1.0, 1.0, 1.0, 1.0))
    """The MPC's cost weights (u, du, track per x, y, ψ, v)."""
    margins: tuple[tuple[str, float], ...] | None = None
    """(rule name, margin) pairs: how far inside its bound the MPC keeps that rule, in the rule's
    own units (None: :attr:`~twolevel.control.high_level.settings.MPCSettings.margins`' default)."""


@dataclass(frozen=True, eq=False)
class World:
    """Everything static about a scenario plus the initial traffic state."""

    name: str
    lanes: LaneSet
    route: Route
    limits: SpeedLimits
    lights: Lights
    stops: StopLines
    parts: Participants
    traffic0: TrafficState
    ego: EgoStart
    settings: Settings
    rule_files: tuple[tuple[str, tuple[tuple[str, float], ...]], ...]
    route_stops: np.ndarray  # (J,) route s [m] of stop signs on the route
    route_stop_index: np.ndarray  # (J,) index into ``stops``
    route_lights: np.ndarray  # (Q,) route s [m] of light stop lines on the route
    route_light_index: np.ndarray  # (Q,) index into ``lights``
    assumptions: Assumptions = field(default_factory=Assumptions)  # about other road users (safety layer)
    junctions: Junctions = field(default_factory=Junctions.empty)  # arms, connecting lanes, stop lines, conflicts

    @cached_property
    def participant_signals(self) -> tuple[str, ...]:
        """The participant signals the scenario's rules read, ``present`` first; empty when no
        rule quantifies over participants. Sensing computes these for each participant in range,
        and a run records them (:mod:`twolevel.world.relations`)."""
        from twolevel.world.relations import signals_read_by

        return signals_read_by(load_rulesets(self)[0])

    @cached_property
    def on_demand_signals(self) -> tuple[str, ...]:
        """The on-demand signals (:data:`~twolevel.world.provided.ON_DEMAND_SIGNALS`) the
        scenario's rules read, in that order: what a run records besides the others."""
        from twolevel.stl.analysis import signals_read
        from twolevel.world.provided import ON_DEMAND_SIGNALS

        read: set[str] = set()
        for rs in load_rulesets(self)[0]:
            for r in rs.rules:
                read |= signals_read(r.formula)
        return tuple(n for n in ON_DEMAND_SIGNALS if n in read)

    @cached_property
    def crosswalks(self) -> "RouteCrosswalks":
        """The marked crosswalks on the route (:mod:`twolevel.world.crosswalks`)."""
        from twolevel.world.crosswalks import route_crosswalks

        return route_crosswalks(self)

    @cached_property
    def zones(self) -> "RouteZones":
        """The conflict zones along the route (:mod:`twolevel.world.right_of_way`)."""
        from twolevel.world.right_of_way import route_zones

        return route_zones(self)


def _limits(spec: MapFile, lanes: LaneSet, index: dict[str, int], plans: list[Plan]) -> SpeedLimits:
    """Limits by (lane, s): each lane's own from its start (a junction's connecting lanes: the
    junction's, else the one in force where the incoming lane ends), then the signs."""
    lane_start = {ln.id: ln.speed_limit for ln in spec.lane_specs()}
    conns = {c.id: (spec.junctions[plan.index].speed_limit, c.incoming) for plan in plans for c in plan.connections}

    def table(names: list[str], start: dict[str, float]) -> SpeedLimits:
        keys, vals = [], []
        for lid in names:
            keys.append(lanes.base[index[lid]] - 0.5)
            vals.append(start[lid])
        for sign in spec.speed_limits:
            keys.append(lanes.base[index[sign.lane]] + sign.s)
            vals.append(sign.value)
        order = np.argsort(keys, kind="stable")
        return SpeedLimits(np.asarray(keys)[order], np.asarray(vals)[order], lanes.base)

    start = {lid: lane_start.get(lid) or spec.default_speed_limit for lid in index if lid not in conns}
    if conns:
        first = table(list(start), start)
        for cid, (own, incoming) in conns.items():
            i = index[incoming]
            start[cid] = own or float(first.at(np.array([i]), np.array([lanes.length[i]]))[0])
    return table(list(index), start)


def _cycle_row(c: LightCycle | tuple[float, float, float, float]) -> tuple[list[float], list[int], float, float]:
    green, yellow, red, offset = (c.green, c.yellow, c.red, c.offset) if isinstance(c, LightCycle) else c
    return [0.0, green, green + yellow], [GREEN, YELLOW, RED], green + yellow + red, offset


def _lights(spec: MapFile, index: dict[str, int], plans: list[Plan]) -> Lights:
    """The map's lights, then one per incoming lane of every signalised junction arm."""
    rows, ids, lanes, ss = [], [], [], []
    for tl in spec.traffic_lights:
        if tl.cycle is not None:
            rows.append(_cycle_row(tl.cycle))
        else:
            rows.append(([st.t for st in tl.script or []], [_STATES[st.state] for st in tl.script or []], math.inf, 0.0))
        ids.append(tl.id), lanes.append(index[tl.lane]), ss.append(tl.s)
    for plan in plans:
        for line in plan.lines:
            if line.kind == "signal":
                rows.append(_cycle_row(plan.light_cycle(line.phase)))
                ids.append(line.id), lanes.append(index[line.lane]), ss.append(line.s)
    width = max((len(r[0]) for r in rows), default=1)
    times = np.full((len(rows), width), np.inf)
    states = np.zeros((len(rows), width), dtype=int)
    for i, (t, s, _, _) in enumerate(rows):
        times[i, : len(t)] = t
        states[i, : len(s)] = s
        states[i, len(s):] = s[-1] if s else GREEN
    return Lights(tuple(ids), np.array(lanes, dtype=int), np.array(ss, dtype=float), times, states,
                  np.array([r[2] for r in rows], dtype=float), np.array([r[3] for r in rows], dtype=float))


def _stops(spec: MapFile, index: dict[str, int], plans: list[Plan]) -> StopLines:
    """The map's stop signs, then one per incoming lane of every stop arm."""
    rows = [(s.id, index[s.lane], s.s, s.stop_time) for s in spec.stop_signs]
    rows += [(ln.id, index[ln.lane], ln.s, ln.stop_time) for plan in plans for ln in plan.lines if ln.kind == "stop"]
    return StopLines(tuple(r[0] for r in rows), np.array([r[1] for r in rows], dtype=int),
                     np.array([r[2] for r in rows], dtype=float), np.array([r[3] for r in rows], dtype=float))


def _route(scn: Scenario, lanes: LaneSet, index: dict[str, int], limits: SpeedLimits, comfort: Comfort,
           v_sense: float) -> Route:
    """The route with its limits and its desired speed (:func:`~twolevel.world.speed_profile.speed_profile`
    under the ``comfort`` limits, at most ``v_sense`` [m/s])."""
    spec = scn.spec
    names = _route_lanes(spec, successors(scn.map.spec)) or [spec.route.start.lane]
    pieces = []
    start = 0.0
    for k, name in enumerate(names):
        i = index[name]
        a = spec.route.start.s if k == 0 else 0.0
        b = spec.route.goal.s if k == len(names) - 1 else float(lanes.length[i])
        pieces.append((i, a, b, start))
        start += b - a
    line = concatenate([(lanes.lanes[i], a, b) for i, a, b, _ in pieces])
    s, pts, heading, kappa = resample(line, spec.route.spacing)
    # limits in force along the route: the limit at each piece's start, then its signs
    ls, lv = [], []
    for i, a, b, s0 in pieces:
        inner = (limits.key > limits.base[i] + a) & (limits.key <= limits.base[i] + b)
        ls += [s0] + list(s0 + limits.key[inner] - limits.base[i] - a)
        lv += [float(limits.at(np.array([i]), np.array([a]))[0])] + list(limits.value[inner])
    limit_s, limit_v = np.asarray(ls), np.asarray(lv)
    keep = np.append(np.diff(limit_s) > 0, True)  # a later breakpoint at the same s wins
    limit_s, limit_v = limit_s[keep], limit_v[keep]
    cap = limit_v[step_index(limit_s, s)].astype(float)
    if spec.ego.desired_speed is not None:
        cap = np.minimum(cap, spec.ego.desired_speed)
    v_des = speed_profile(s, np.minimum(cap, v_sense), kappa, comfort, 0.0 if spec.route.stop_at_goal else None)
    bounds = np.array([p[3] for p in pieces] + [start])
    k = np.minimum(step_index(bounds, s), len(pieces) - 1)
    piece = np.array([p[:3] for p in pieces])
    width = lanes.width_at(piece[k, 0].astype(int), piece[k, 1] + s - bounds[k])
    return Route(pts, s, np.unwrap(heading), kappa, spacing=float(s[1] - s[0]) if len(s) > 1 else spec.route.spacing,
                 limit_s=limit_s, limit_v=limit_v, v_des=v_des, width=width, pieces=tuple(pieces))


def build_world(scn: Scenario) -> World:
    """The runtime :class:`World` of a loaded scenario (deterministic for the run's seed)."""
    spec = scn.spec
    m = scn.map.spec
    lanes, index, plans = build_lanes(m)
    limits = _limits(m, lanes, index, plans)
    lights = _lights(m, index, plans)
    stops = _stops(m, index, plans)
    junctions = build_junctions(lanes, index, plans, stops.ids, lights.ids)
    stops = replace(stops, must_stop=np.ones(len(stops.ids), dtype=bool), conflicts=conflicts_of(lanes, stops.lane, stops.s))
    c: ControllerSettings = spec.controller
    sense = sensing_of(spec)
    comfort = Comfort(c.comfort_accel, c.comfort_decel, c.comfort_jerk, c.comfort_lat_accel)
    route = _route(scn, lanes, index, limits, comfort, sense.v_bound)

    assumptions = from_spec(spec.assumptions, {p.id: p.kind for p in spec.participants})
    ex, ey, epsi, elane, es, _ = pose_of(spec.ego.start, lanes, index)
    parts, traffic0 = participants_of(spec, lanes, index, assumptions, elane, es)
    settings = Settings(c.H, c.dt, near_radius(scn), c.r, c.D_safe, c.samples, c.time_limit, c.solver, c.stop_speed,
                        c.yellow_decel, spec.run.duration, spec.run.seed, c.horizon_s, c.coarse_dt,
                        None if c.coarse_steps is None else tuple(c.coarse_steps), c.rss, sense.range, sense.response,
                        sense.v_bound, comfort, c.v2i, (c.weights.u, c.weights.du, tuple(c.weights.track)),
                        None if c.margins is None else tuple(sorted(c.margins.items())))
    ego = EgoStart(ex, ey, epsi, spec.ego.speed, spec.ego.box.length, spec.ego.box.width,
                   MappingProxyType(dict(spec.ego.vehicle)))
    rs = route.from_lane(stops.lane, stops.s)
    rl = route.from_lane(lights.lane, lights.s)
    on_s, on_l = np.flatnonzero(~np.isnan(rs)), np.flatnonzero(~np.isnan(rl))
    return World(spec.name or scn.path, lanes, route, limits, lights, stops, parts, traffic0, ego, settings,
                 tuple((r.path, r.constants) for r in scn.rules), rs[on_s], on_s, rl[on_l], on_l,
                 assumptions, junctions)


def load_rulesets(world: World) -> tuple[list, list]:
    """The checked rule sets of the scenario's rule files, its constant bindings applied and its
    signals checked against what the world provides: ``(rule sets, diagnostics)``. The one
    place the controllers and the simulator load a world's rules from."""
    from twolevel.stl.lint import load_ruleset
    from twolevel.world.provided import PROVIDED_PARTICIPANT_SIGNALS, PROVIDED_SIGNALS

    diags: list = []
    sets: list = []
    for path, consts in world.rule_files:
        rs, d = load_ruleset(path, dict(consts), dt=world.settings.dt, provided_signals=PROVIDED_SIGNALS,
                             participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
        diags += d
        if rs is not None:
            sets.append(rs)
    return sets, diags
