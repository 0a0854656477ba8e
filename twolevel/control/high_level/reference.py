"""The MPC's reference over one horizon: the waypoints ω_k the plan tracks, and where it must stop.

:func:`reference` projects the ego onto the route, reads the route's desired-speed profile (which
already obeys the limits in force and slows for bends, :mod:`twolevel.world.speed_profile`)
forward over the horizon at the scenario's comfort acceleration and deceleration, and gathers
the solve-time constants of :func:`twolevel.world.signals.horizon_constants`. The reference ends with a stop
where the plan must stop — the goal, when the route stops there, and a stop line or red light a
rule guards (:func:`twolevel.control.high_level.guards.stop_lines`) that full braking can still
stop before — and where it waits: for a pedestrian or cyclist crossing ahead and at a guarded
crosswalk seen from the sensing range (:mod:`~twolevel.control.high_level.crossers`), before a
merge with no sign (:mod:`~twolevel.control.high_level.merges`). Units: m, rad, m/s, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from twolevel.control.high_level.crossers import crossing_halt, crosswalk_halt
from twolevel.control.high_level.guards import (BESIDE_FROM, Front, Pass, beside_steps,
                                                drivable_band, free_sides, front_of, stop_lines)
from twolevel.control.high_level.merges import merge_line
from twolevel.control.high_level.neighbours import left_leader
from twolevel.control.high_level.overtaking import (lateral_due, lateral_share, oncoming_band, oncoming_free, out_of_lane,
                                                    room_to_pull_out, waiting_room)
from twolevel.control.high_level.right_of_way import GapRule, ZoneConstants, give_way_line, zone_constants
from twolevel.control.high_level.settings import MPCSettings
from twolevel.control.high_level.steering import steering_reference
from twolevel.models.params import BicycleParams
from twolevel.world.assumptions import ResponseBounds, safe_speed
from twolevel.world.clearance import passing_clearance
from twolevel.world.geometry import Route
from twolevel.world.signals import HorizonConstants, StopMemory, horizon_constants, route_lookups
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["Reference", "reference", "reference_controls", "braking", "wrap_to"]


@dataclass(frozen=True, eq=False)
class Reference:
    """The ego's station now (``s0``, ``e0`` [m] along and across the route), the waypoints'
    route positions ``s_ref`` (N+1,) [m] and speeds ``v_ref`` (N+1,) [m/s], the waypoints
    ``omega`` (N, 4) = (X, Y, ψ, v) for k = 1..N (the whole look-ahead), the solve-time constants
    ``hc`` along them, where full braking from now ends the look-ahead: ``d_brake`` [m]
    further, at ``v_brake`` [m/s], the vehicle ahead of the RSS terminal ``front``
    (:func:`twolevel.control.high_level.guards.front_of`) and whether the ego may pass it,
    ``sides`` (left, right), beside it at ``lateral`` [m] from it at the steps ``beside``,
    ``due`` [s] from now
    (:func:`twolevel.control.high_level.guards.free_sides`); ``oncoming``: the left pass goes over
    the oncoming lane, and the lateral band takes it in
    (:mod:`twolevel.control.high_level.overtaking`), ``early``: the share of the way beside it due
    at the last fine step (None: in proportion to the time); ``zones``: the next conflict area's
    constants when right of way is guarded (:mod:`twolevel.control.high_level.right_of_way`)."""

    s0: float
    e0: float
    s_ref: np.ndarray
    v_ref: np.ndarray
    omega: np.ndarray
    hc: HorizonConstants
    d_brake: float
    v_brake: float
    front: Front | None = None
    sides: tuple[bool, bool] = (False, False)
    lateral: float = 0.0
    beside: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    due: float = 0.0
    oncoming: bool = False
    early: float | None = None
    zones: ZoneConstants | None = None


def wrap_to(angle: np.ndarray | float, ref: float) -> np.ndarray:
    """``angle`` shifted by a multiple of 2π to lie within π of ``ref`` [rad]."""
    return ref + np.mod(np.asarray(angle, float) - ref + math.pi, 2 * math.pi) - math.pi


def reference_controls(route_kappa: np.ndarray, v_ref: np.ndarray, steps: np.ndarray | float,
                       params: BicycleParams) -> np.ndarray:
    """The controls (N, 2) [δ rad, a m/s²] that follow the route's curvature ``route_kappa`` (N,)
    [1/m] at the reference speeds ``v_ref`` (N+1,) [m/s] over steps of ``steps`` (N,) [s] (or one
    length), within the bicycle's limits."""
    delta = steering_reference(route_kappa, params)
    acc = np.clip(np.diff(v_ref) / steps, params.a_min, params.a_max)
    return np.stack([delta, acc], axis=1)


def braking(v0: float, n: int, dt: float, params: BicycleParams) -> tuple[float, float]:
    """Distance [m] and speed [m/s] after ``n`` periods ``dt`` [s] of full braking from ``v0``
    (no reversing)."""
    T = min(n * dt, v0 / -params.a_min)
    return v0 * T + 0.5 * params.a_min * T * T, max(v0 + params.a_min * dt * n, 0.0)


@dataclass(frozen=True)
class Follow:
    """The vehicle ahead the reference keeps RSS's distance behind: its predicted route position
    ``s_front`` (N+1,) [m] less ``room`` [m] (half the two lengths and the margin kept), its speed
    ``v_front`` [m/s] and the ego's RSS ``response``."""

    s_front: np.ndarray
    v_front: float
    room: float
    response: ResponseBounds


def _reference_to(route: Route, s0: float, v0: float, steps: Sequence[float], s_end: float, decel: float,
                  a_max: float = 2.0, follow: Follow | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Like :meth:`~twolevel.world.geometry.Route.reference` over the step lengths ``steps`` [s],
    but ending with a stop at ``s_end`` [m] (+inf: none): the target speed is at most
    sqrt(2·``decel``·(s_end − s)), the reference brakes as hard as reaching it needs, and
    positions never pass ``s_end``; and, ``follow``-ing a vehicle ahead, at most the speed whose
    RSS distance is the gap to it (:func:`twolevel.world.assumptions.safe_speed`), braking at
    up to the response's brake_min for it, never closer than ``follow.room``."""
    N = len(steps)
    s = np.empty(N + 1)
    v = np.empty(N + 1)
    s[0], v[0] = s0, v0
    for k, dt in enumerate(steps):  # N ≈ 10–20 scalar steps
        d = max(s_end - s[k], 0.0)
        target = min(float(route.desired_speed_at(s[k])), math.sqrt(2.0 * decel * d))
        need = v[k] * v[k] / (2.0 * max(d, 1e-3))
        end = max(s_end, s[k])
        if follow is not None:
            target = min(target, safe_speed(follow.s_front[k] - follow.room - s[k], follow.v_front, follow.response))
            need = max(need, follow.response.brake_min)
            end = min(end, max(follow.s_front[k + 1] - follow.room, s[k]))
        v[k + 1] = min(max(target, v[k] - max(a_max, need) * dt, 0.0), v[k] + a_max * dt)
        s[k + 1] = min(s[k] + 0.5 * (v[k] + v[k + 1]) * dt, end)
        if s[k + 1] >= s_end - 1e-9:
            v[k + 1] = 0.0
    return s, v


def reference(world: World, x0: np.ndarray, t: float, traffic: TrafficState, settings: MPCSettings,
              params: BicycleParams, *, memory: StopMemory | None = None, s_hint: float | None = None,
              stop_rules: tuple[bool, bool, bool] = (False, False, False), passing: Pass | None = None,
              gap: GapRule | None = None) -> Reference:
    """The reference at time ``t`` [s] for ego state ``x0`` = (X, Y, ψ, v) over the look-ahead of
    ``settings``: the ego is projected near ``s_hint`` [m] when given (else onto the whole
    route); ``stop_rules`` = (a rule reads d_stop, a rule reads light_red/d_light, a rule reads
    xwalk_busy/d_xwalk) says which
    lines the reference stops before (at ``settings.stop_decel``, ``settings.stop_margin``
    before the line); with ``gap`` (the right-of-way rule's, None: not guarded) it stops before
    the give-way line as well, while that holds (a reference that runs on past it pulls the plan
    along: the NMPC baseline, which has no lateral band, slid sideways along the line off the
    road). With ``settings.rss``, when the ego may not pass the vehicle ahead sensed
    in its lane (:func:`~twolevel.control.high_level.guards.free_sides`, judged where the desired
    speeds would take it, beside it from :data:`~twolevel.control.high_level.guards.BESIDE_FROM`
    on, or, ``passing`` it already, from the pass's due time on its side; while it passes, the
    reference runs in the lane it passes in), the reference keeps RSS's distance (and
    D_safe) behind that vehicle — braking for it at ``settings.stop_decel`` at most, so it
    slows down before RSS's braking would be needed —, as the plan must at the end of the look-ahead
    (:func:`~twolevel.control.high_level.guards.rss_terminal`): a reference that runs into it
    would pull the plan's coarse steps against that row (and a linearised plan then swerves to
    gain progress the row does not count). When it may, the reference keeps the desired speeds,
    so that passing pays."""
    steps, dt = settings.steps, settings.dt
    route = world.route
    if s_hint is not None and math.isfinite(s_hint):
        s_arr, e_arr = route.project_near(x0[None, :2], np.array([s_hint]), 15.0)
    else:
        s_arr, e_arr = route.local_coordinates(x0[None, :2])
    s0 = float(s_arr[0])
    comfort = world.settings.comfort
    stops = bool(route.v_des.size and route.v_des[-1] <= 1e-9)
    s_ref, v_ref = route.reference(s0, max(float(x0[3]), 0.0), len(steps), steps, comfort.accel, comfort.decel,
                                   beyond=not stops)
    hc = horizon_constants(world, traffic, t, x0, dt=dt, s_pred=s_ref, memory=memory, station=(s0, float(e_arr[0])),
                           ticks=np.asarray(settings.ticks))
    # the reference ends with a stop where the plan must stop: the goal (when the route stops
    # there), and a stop line / red light a rule guards or the give-way line while it holds
    # that full braking can still stop before
    d_brake, v_brake = braking(float(x0[3]), settings.ticks[-1], dt, params)
    s_end = float(route.s[-1]) if stops else math.inf
    zones = zone_constants(world, hc, s0, settings.H, traffic, float(x0[3]), gap) if gap is not None else None
    xy = (float(x0[0]), float(x0[1]))
    halts = [give_way_line(zones), crossing_halt(world, traffic, xy, s0, float(e_arr[0]), float(x0[3])),
             merge_line(world, traffic, xy, s0, float(x0[3]))]
    if any(stop_rules):
        lines = stop_lines(hc, stop=stop_rules[0], light=stop_rules[1], xwalk=stop_rules[2])
        halts.append(float(min(lines[0], lines[-1])))
    if stop_rules[2]:  # the crosswalk rule's line, its pedestrians seen from further than r_near
        halts.append(crosswalk_halt(world, traffic, xy, s0, float(x0[3])))
    for s_halt in halts:
        if s0 + d_brake <= s_halt + 1e-6:
            s_end = min(s_end, max(s_halt - settings.stop_margin, s0))
    follow, sides, lateral, lane, oncoming, early = None, (False, False), 0.0, 0.0, False, None
    ticks = np.asarray(settings.ticks)
    times = dt * ticks
    front = front_of(world, hc, passing, s0, dt, ticks) if settings.rss else None
    if front is None or passing is None or front.index != passing.vehicle:
        passing = None  # no pass under way (any more)
    due = BESIDE_FROM if passing is None else passing.by - t
    beside = beside_steps(times, due)
    if front is not None:
        # beside it with the clearance its kind of road user is owed (a cyclist 1.5 m, 2 m out of town)
        lateral = 0.5 * (world.ego.width + front.width) + passing_clearance(int(world.parts.user[front.index]),
                                                                            float(route.limit_at(s0)))
        lo, hi = drivable_band(world, s_ref[beside])
        sides = free_sides(world, hc, front, lateral=lateral, band=(float(lo.max()), float(hi.min())),
                           s=s_ref[beside], v=v_ref[beside], t=times[beside])
        if not sides[0]:  # over the oncoming lane: a new pass from low speed needs longer to get beside
            lateral_o = max(lateral, out_of_lane(world, s0) - front.e)  # wholly out of the vehicle's lane
            due_o = due if passing is not None else max(due, lateral_due(world, params, float(x0[3]),
                                                                          front.e + lateral_o - float(e_arr[0])))
            beside_o = beside_steps(times, due_o)
            sides_o, oncoming = _over_oncoming(world, hc, front, sides, lateral=lateral_o, s0=s0, v0=float(x0[3]),
                                               s=s_ref[beside_o], v=v_ref[beside_o], t=times[beside_o])
            if oncoming and passing is None:  # a new pass: only with room to pull out behind the vehicle
                oncoming = room_to_pull_out(world, params, front, s0, float(x0[3]),
                                            front.e + lateral_o - float(e_arr[0]))
            if oncoming:
                sides, due, beside, lateral = sides_o, due_o, beside_o, lateral_o
                early = lateral_share(world, float(x0[3]), due, float(times[settings.H]))
        if passing is not None:  # the side the pass began on, the reference in that lane
            sides = (sides[0] and passing.side == 1, sides[1] and passing.side == 2)
            lane = passing.lane if any(sides) else 0.0
        if not any(sides):
            # approached as a stop line is (settings.stop_decel), more gently than RSS's braking
            gentle = replace(world.settings.response, brake_min=min(world.settings.response.brake_min,
                                                                    settings.stop_decel))
            room = waiting_room(world, params, front, s0, float(e_arr[0]), lateral)  # to pull out from
            follow = Follow(front.s, front.v, front.offset + world.settings.D_safe + room, gentle)
    if follow is None and "left_of" in world.participant_signals:  # a rule reads it: no_passing_right
        left = left_leader(hc, world.parts.length, world.parts.width, s0, float(e_arr[0]), world.ego.length,
                           world.ego.width, float(v_ref.max()), times)
        if left is not None:  # draw level with it no faster than it, braking gently
            b = settings.stop_decel  # safe_speed is then sqrt(v_o² + 2·b·gap)
            follow = Follow(left[0], left[1], 0.0, ResponseBounds(time=0.0, accel_max=0.0, brake_min=b, brake_max=b))
    if math.isfinite(s_end) or follow is not None:
        s_ref, v_ref = _reference_to(route, s0, max(float(x0[3]), 0.0), steps, s_end, settings.stop_decel,
                                     comfort.accel, follow)
        hc = replace(hc, s_ref=s_ref, **route_lookups(world, s_ref))
    v_ref = np.minimum(v_ref, route.limit_at(s_ref))
    pts = route.position(s_ref, lane)
    head = wrap_to(route.heading_at(s_ref), float(x0[2]))
    # the ego's heading now, turned as the route turns; over the oncoming lane the route's own
    # heading, towards which the heading is damped there (heading_weight)
    head = (head[0] if oncoming else x0[2]) + np.concatenate([[0.0], np.cumsum(wrap_to(np.diff(head), 0.0))])
    omega = np.column_stack([pts[1:], head[1:], v_ref[1:]])
    return Reference(s0, float(e_arr[0]), s_ref, v_ref, omega, hc, d_brake, v_brake, front, sides, lateral, beside,
                     due, oncoming, early, zones)


def _over_oncoming(world: World, hc: HorizonConstants, front: Front, sides: tuple[bool, bool], *, lateral: float,
                   s0: float, v0: float, s: np.ndarray, v: np.ndarray, t: np.ndarray) -> tuple[tuple[bool, bool], bool]:
    """The sides on which the ego may pass ``front`` when the oncoming lane is taken in: the left
    one too where the band with the oncoming lane reaches beside it at route positions ``s`` [m]
    (speeds ``v`` [m/s], times ``t`` [s]; :func:`free_sides`) and the oncoming lane is free for
    the pass (:func:`~twolevel.control.high_level.overtaking.oncoming_free`); and whether that
    pass goes over the oncoming lane."""
    lo, hi, open_ = oncoming_band(world, s)
    if not open_.all():
        return sides, False
    left = free_sides(world, hc, front, lateral=lateral, band=(float(lo.max()), float(hi.min())), s=s, v=v, t=t)[0]
    if not (left and oncoming_free(world, hc, front, s0, v0)):
        return sides, False
    return (True, sides[1]), True
