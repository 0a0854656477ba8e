"""The runtime world: a loaded :class:`~twolevel.world.loader.Scenario` turned into arrays.

``build_world(scenario)`` samples the map's lanes, builds the route (reference path, limits,
desired speed), the tables of signs and lights, the participants (expanding populations with
the seed) and their initial state. Everything here is frozen dataclasses and numpy arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import Mapping

import numpy as np

from twolevel.world.assumptions import RSS_BOUNDS, Assumptions, ResponseBounds, from_spec
from twolevel.world.conflicts import Junctions, build_junctions
from twolevel.world.geometry import LaneSet, Route, concatenate, resample
from twolevel.world.junction import Plan
from twolevel.world.lanes import build_lanes
from twolevel.world.loader import Scenario, _route_lanes, sensing_of, successors
from twolevel.world.schema import ControllerSettings, IDMParams, LightCycle, MapFile, Placement, Population
from twolevel.world.speed_profile import Comfort, speed_profile
from twolevel.world.traffic import (
    CONSTANT_VELOCITY, GREEN, IDM, RED, SCRIPTED, STATIONARY, YELLOW, Lights, Participants, SpeedLimits,
    StopLines, TrafficState,
)

__all__ = ["EgoStart", "Settings", "World", "build_world", "population_slots"]

_KINDS = {"stationary": STATIONARY, "constant_velocity": CONSTANT_VELOCITY, "idm": IDM, "scripted": SCRIPTED}
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


def _limits(spec: MapFile, lanes: LaneSet, index: dict[str, int], plans: list[Plan]) -> SpeedLimits:
    """Limits by (lane, s): each lane's own from its start (a junction's connecting lanes: the
    junction's, else the one in force where the incoming lane ends), then the signs."""
    lane_start = {ln.id: ln.speed_limit for road in spec.roads for ln in road.lane_specs()}
    lane_start.update({ln.id: ln.speed_limit for ln in spec.lanes})
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
    j = np.clip(np.searchsorted(limit_s, s, side="right") - 1, 0, len(limit_s) - 1)
    cap = limit_v[j].astype(float)
    if spec.ego.desired_speed is not None:
        cap = np.minimum(cap, spec.ego.desired_speed)
    v_des = speed_profile(s, np.minimum(cap, v_sense), kappa, comfort, 0.0 if spec.route.stop_at_goal else None)
    bounds = np.array([p[3] for p in pieces] + [start])
    k = np.clip(np.searchsorted(bounds, s, side="right") - 1, 0, len(pieces) - 1)
    piece = np.array([p[:3] for p in pieces])
    width = lanes.width_at(piece[k, 0].astype(int), piece[k, 1] + s - bounds[k])
    return Route(pts, s, np.unwrap(heading), kappa, spacing=float(s[1] - s[0]) if len(s) > 1 else spec.route.spacing,
                 limit_s=limit_s, limit_v=limit_v, v_des=v_des, width=width, pieces=tuple(pieces))


def _pose(p: Placement, lanes: LaneSet, index: dict[str, int]) -> tuple[float, float, float, int, float, float]:
    """x, y [m], psi [rad], lane index (−1), s [m], lateral [m] of a placement."""
    if p.lane is not None:
        i = index[p.lane]
        s = p.s or 0.0
        xy, h = lanes.pose(np.array([i]), np.array([s]), np.array([p.lateral]))
        return float(xy[0, 0]), float(xy[0, 1]), float(h[0]), i, s, p.lateral
    return float(p.x or 0.0), float(p.y or 0.0), math.radians(p.heading or 0.0), -1, 0.0, 0.0


def population_slots(pop: Population, lanes: LaneSet, index: dict[str, int], ego_lane: int, ego_s: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Places a population may use: (lane index, s [m]) one box length + ``min_gap`` apart along
    each of its lanes within ``s_range``, keeping that pitch clear of the ego."""
    pitch = pop.box.length + pop.min_gap
    ls, ss = [], []
    for name in pop.lanes:
        li = index[name]
        lo, hi = pop.s_range or (0.0, float(lanes.length[li]))
        hi = min(hi, float(lanes.length[li]))
        slots = np.arange(lo + pop.box.length / 2, hi - pop.box.length / 2 + 1e-9, pitch)
        if li == ego_lane:
            slots = slots[np.abs(slots - ego_s) >= pitch]
        ls.append(np.full(len(slots), li))
        ss.append(slots)
    return np.concatenate(ls).astype(int), np.concatenate(ss)


def _idm_row(p: IDMParams) -> list[float]:
    return [math.nan if p.v0 is None else p.v0, p.T, p.s0, p.a, p.b, p.delta]


def build_world(scn: Scenario) -> World:
    """The runtime :class:`World` of a loaded scenario (deterministic for the run's seed)."""
    spec = scn.spec
    m = scn.map.spec
    lanes, index, plans = build_lanes(m)
    limits = _limits(m, lanes, index, plans)
    lights = _lights(m, index, plans)
    stops = _stops(m, index, plans)
    junctions = build_junctions(lanes, index, plans, stops.ids, lights.ids)
    c: ControllerSettings = spec.controller
    sense = sensing_of(spec)
    comfort = Comfort(c.comfort_accel, c.comfort_decel, c.comfort_jerk, c.comfort_lat_accel)
    route = _route(scn, lanes, index, limits, comfort, sense.v_bound)

    rows: list[dict[str, object]] = []
    for p in spec.participants:
        x, y, psi, lane, s, lat = _pose(p.start, lanes, index) if p.start is not None else (0, 0, 0, -1, 0, 0)
        wp = [(w.t, w.x, w.y) for w in p.waypoints or []]
        if wp:
            x, y = wp[0][1], wp[0][2]
            psi = math.atan2(wp[1][2] - wp[0][2], wp[1][1] - wp[0][1])
        rows.append(dict(id=p.id, kind=_KINDS[p.behaviour], x=x, y=y, psi=psi, v=p.speed, lane=lane, s=s, lat=lat,
                         L=p.box.length, W=p.box.width, idm=_idm_row(p.idm), wp=wp))
    ex, ey, epsi, elane, es, _ = _pose(spec.ego.start, lanes, index)
    for pop in spec.populations:
        rng = np.random.default_rng(spec.run.seed if pop.seed is None else pop.seed)
        slot_lane, slot_s = population_slots(pop, lanes, index, elane, es)
        take = np.sort(rng.choice(len(slot_s), size=min(pop.count, len(slot_s)), replace=False))
        li, sv = slot_lane[take], slot_s[take]
        speeds = rng.uniform(*pop.speed_range, size=len(sv))
        xy, h = lanes.pose(li, sv)
        for j in range(len(sv)):
            rows.append(dict(id=f"{pop.id}-{j}", kind=_KINDS[pop.behaviour], x=xy[j, 0], y=xy[j, 1], psi=h[j],
                             v=0.0 if pop.behaviour == "stationary" else speeds[j], lane=li[j], s=sv[j], lat=0.0,
                             L=pop.box.length, W=pop.box.width, idm=_idm_row(pop.idm), wp=[]))
    n = len(rows)
    wmax = max([len(r["wp"]) for r in rows] + [2])  # type: ignore[arg-type]
    st = np.zeros((n, wmax))
    sxy = np.zeros((n, wmax, 2))
    for i, r in enumerate(rows):
        wp = r["wp"] or [(0.0, r["x"], r["y"]), (1.0, r["x"], r["y"])]  # type: ignore[list-item]
        arr = np.asarray(wp, dtype=float)
        st[i, : len(arr)], sxy[i, : len(arr)] = arr[:, 0], arr[:, 1:]
        st[i, len(arr):] = arr[-1, 0] + np.arange(1, wmax - len(arr) + 1)
        sxy[i, len(arr):] = arr[-1, 1:]
    col = lambda name, dtype=float: np.array([r[name] for r in rows], dtype=dtype).reshape(n)  # noqa: E731
    parts = Participants(tuple(str(r["id"]) for r in rows), col("kind", int), col("L"), col("W"),
                         np.array([r["idm"] for r in rows], dtype=float).reshape(n, 6), st, sxy)
    traffic0 = TrafficState(0.0, col("x"), col("y"), col("psi"), col("v"), col("lane", int), col("s"), col("lat"),
                            np.ones(n, dtype=bool), np.zeros(n), np.full(n, -1, dtype=int))
    settings = Settings(c.H, c.dt, c.r_near, c.r, c.D_safe, c.samples, c.time_limit, c.solver, c.stop_speed,
                        c.yellow_decel, spec.run.duration, spec.run.seed, c.horizon_s, c.coarse_dt,
                        None if c.coarse_steps is None else tuple(c.coarse_steps), c.rss, sense.range, sense.response,
                        sense.v_bound, comfort, c.v2i, (c.weights.u, c.weights.du, tuple(c.weights.track)))
    ego = EgoStart(ex, ey, epsi, spec.ego.speed, spec.ego.box.length, spec.ego.box.width,
                   MappingProxyType(dict(spec.ego.vehicle)))
    rs = route.from_lane(stops.lane, stops.s)
    rl = route.from_lane(lights.lane, lights.s)
    on_s, on_l = np.flatnonzero(~np.isnan(rs)), np.flatnonzero(~np.isnan(rl))
    return World(spec.name or scn.path, lanes, route, limits, lights, stops, parts, traffic0, ego, settings,
                 tuple((r.path, r.constants) for r in scn.rules), rs[on_s], on_s, rl[on_l], on_l,
                 from_spec(spec.assumptions, {p.id: p.kind for p in spec.participants}), junctions)


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
