"""THE one place that turns a world and an ego state into the named signals rules read.

Two faces, one set of definitions (see :mod:`twolevel.world.provided` for the list and units):

* :func:`signals_along` — per step along a recorded or simulated ego trajectory (monitors);
* :func:`horizon_constants` — over an MPC horizon, the values known at solve time (limits at
  the predicted positions, light states from their programs, stop-line positions, other
  vehicles' constant-velocity predictions). The MPC treats v_k and s_k as affine in its decision
  variables and forms d_stop,k = s_stop − s_k, d_light,k = s_light − s_k itself.

Definitions (sensing is limited to ``r_near``):

* ``s``, ``e``: projection of the ego's reference point on the route; e + left.
* ``v_max``: the limit in force at route position s (the last sign passed along the route).
* Stop signs. A stop line on the route at s_j *applies* at a step while the ego is within
  −PASS_MARGIN ≤ s_j − s ≤ r_near and has not yet *served* it. The ego serves it at the first step
  at which it has stood still (v ≤ stop_speed) without interruption for the sign's ``stop_time``
  close to the line (−PASS_MARGIN ≤ s_j − s ≤ STOP_ZONE); from that step on the line no longer
  applies. ``d_stop`` = s_j − s of
  the nearest line that applies, +inf if none (so it turns negative if the ego runs the line).
* Lights. A light on the route applies while 0 ≤ s_j − s ≤ r_near; once the ego has crossed its
  line the light no longer applies, unless it crossed while the light was red, in which case it
  keeps applying (with negative ``d_light``) until PASS_MARGIN past the line, so a rule sees the
  violation. ``light_red`` = 1 when the applying light is red, or yellow and the ego can still stop
  (d_light ≥ v²/(2·yellow_decel)); otherwise 0. (Not "yellow and cannot stop", which reads
  inverted: a driver who can stop at yellow must; one who cannot proceeds.)
* ``d_lead``/``v_lead``: among vehicles within r_near whose route projection is ahead (s_i > s),
  in the ego's lane (|e_i − e| < lane width / 2) and heading the same way, the nearest: bumper-to-
  bumper gap s_i − s − (L_ego + L_i)/2 and its speed along the route. +inf / v if none.
* ``min_gap``: signed oriented-box separation to the nearest vehicle within r_near (+inf if none).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from twolevel.models.obb import box_corners, box_separation
from twolevel.world.provided import PROVIDED_SIGNALS
from twolevel.world.traffic import RED, YELLOW, TrafficState
from twolevel.world.world import World

__all__ = ["PASS_MARGIN", "STOP_ZONE", "TrafficLog", "StopMemory", "HorizonConstants", "signals_along",
           "horizon_constants", "update_stop_memory"]

PASS_MARGIN = 5.0  # [m] how far past a stop line it still counts (so running it is visible)
STOP_ZONE = 3.0  # [m] a stop counts for a stop sign when made at most this far before its line


@dataclass(frozen=True, eq=False)
class TrafficLog:
    """Other vehicles over T steps: x, y [m], psi [rad], v [m/s], active (T, N); boxes (N,) [m]."""

    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    v: np.ndarray
    active: np.ndarray
    length: np.ndarray
    width: np.ndarray

    @classmethod
    def of(cls, states: Sequence[TrafficState], length: np.ndarray, width: np.ndarray) -> "TrafficLog":
        """Stack per-step states (e.g. as a simulation produced them)."""
        st = list(states)
        return cls(*(np.stack([getattr(s, f) for s in st]) for f in ("x", "y", "psi", "v", "active")), length, width)


@dataclass(frozen=True)
class StopMemory:
    """Closed-loop stop-sign memory, one entry per stop line on the route: ``served`` and the
    length [s] of the current standstill in its zone (−1 when not standing in it)."""

    served: tuple[bool, ...]
    still: tuple[float, ...]

    @classmethod
    def fresh(cls, world: World) -> "StopMemory":
        n = len(world.route_stops)
        return cls((False,) * n, (-1.0,) * n)


def update_stop_memory(mem: StopMemory, world: World, s: float, v: float, dt: float) -> StopMemory:
    """The memory after a step at route position ``s`` [m] and speed ``v`` [m/s] (the
    incremental form of :func:`signals_along`'s stop-sign definition)."""
    d = world.route_stops - s
    need = world.stops.stop_time[world.route_stop_index]
    cond = (v <= world.settings.stop_speed) & (d >= -PASS_MARGIN) & (d <= STOP_ZONE)
    still = np.where(cond, np.where(np.asarray(mem.still) >= 0, np.asarray(mem.still) + dt, 0.0), -1.0)
    served = np.asarray(mem.served, dtype=bool) | (cond & (still >= need - 1e-9))
    return StopMemory(tuple(bool(b) for b in served), tuple(float(x) for x in still))


def _stop_distance(world: World, s: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
    r_near = world.settings.r_near
    if len(world.route_stops) == 0:
        return np.full(len(s), np.inf)
    d = world.route_stops[None, :] - s[:, None]  # (T, J)
    zone = (d >= -PASS_MARGIN) & (d <= r_near)
    cond = (v <= world.settings.stop_speed)[:, None] & (d >= -PASS_MARGIN) & (d <= STOP_ZONE)
    idx = np.arange(len(s))[:, None]
    last_false = np.maximum.accumulate(np.where(~cond, idx, -1), axis=0)
    duration = (idx - (last_false + 1)) * dt
    need = world.stops.stop_time[world.route_stop_index][None, :]
    done = cond & (duration >= need - 1e-9)
    served_from = np.where(done.any(axis=0), done.argmax(axis=0), len(s))
    applies = zone & (idx < served_from[None, :])
    return np.where(applies, d, np.inf).min(axis=1)


def _light(world: World, t: np.ndarray, s: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = len(s)
    if len(world.route_lights) == 0:
        return np.zeros(n), np.full(n, np.inf)
    d = world.route_lights[None, :] - s[:, None]  # (T, Q)
    state = world.lights.state_at(t)[:, world.route_light_index]
    must = (state == RED) | ((state == YELLOW) & (d >= v[:, None] ** 2 / (2 * world.settings.yellow_decel)))
    idx = np.arange(n)[:, None]
    crossed = d < 0
    c = np.where(crossed.any(axis=0), crossed.argmax(axis=0), n)
    on_red = (state[np.minimum(c, n - 1), np.arange(d.shape[1])] == RED) & (c < n)
    applies = ((d >= 0) & (d <= world.settings.r_near)) | ((idx >= c[None]) & on_red[None] & (d >= -PASS_MARGIN))
    dd = np.where(applies, d, np.inf)
    j = dd.argmin(axis=1)
    r = np.arange(n)
    d_light = dd[r, j]
    red = np.where(np.isfinite(d_light), must[r, j], False).astype(float)
    return red, d_light


def _others(world: World, traffic: TrafficLog | None, x: np.ndarray, y: np.ndarray, psi: np.ndarray, s: np.ndarray,
            e: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
    n = len(s)
    out = {"d_lead": np.full(n, np.inf), "v_lead": v.astype(float).copy(), "min_gap": np.full(n, np.inf),
           "n_near": np.zeros(n)}
    if traffic is None or traffic.x.shape[1] == 0:
        return out
    r_near = world.settings.r_near
    dist = np.hypot(traffic.x - x[:, None], traffic.y - y[:, None])
    near = traffic.active & (dist <= r_near)
    out["n_near"] = near.sum(axis=1).astype(float)
    k, i = np.nonzero(near)
    if len(k) == 0:
        return out
    route = world.route
    si, ei = route.project_near(np.stack([traffic.x[k, i], traffic.y[k, i]], axis=1), s[k], r_near + 5.0)
    rh = route.heading_at(si)
    along = np.cos(traffic.psi[k, i] - rh)
    lead = (si > s[k]) & (np.abs(ei - e[k]) < route.width_at(si) / 2) & (along > 0)
    gap = si - s[k] - (world.ego.length + traffic.length[i]) / 2
    g = np.full(near.shape, np.inf)
    g[k[lead], i[lead]] = gap[lead]
    best = g.argmin(axis=1)
    r = np.arange(n)
    has = np.isfinite(g[r, best])
    out["d_lead"] = np.where(has, g[r, best], np.inf)
    vl = np.zeros(near.shape)
    vl[k, i] = traffic.v[k, i] * along
    out["v_lead"] = np.where(has, vl[r, best], v)
    sep = box_separation(box_corners(x[k], y[k], psi[k], world.ego.length, world.ego.width),
                         box_corners(traffic.x[k, i], traffic.y[k, i], traffic.psi[k, i], traffic.length[i],
                                     traffic.width[i]))
    mg = np.full(near.shape, np.inf)
    mg[k, i] = sep
    out["min_gap"] = mg.min(axis=1)
    return out


def signals_along(
    world: World, traffic: TrafficLog | None, ego: Mapping[str, np.ndarray], *, t0: float = 0.0, dt: float | None = None,
) -> dict[str, np.ndarray]:
    """Every provided signal along an ego trajectory: a (T,) array per name.

    ``ego`` maps ``x``, ``y`` [m], ``psi`` [rad], ``v`` [m/s] (and optionally ``a`` [m/s²],
    ``delta`` [rad]; zeros otherwise) to (T,) arrays sampled every ``dt`` [s] (default: the
    scenario's) from time ``t0`` [s]; ``traffic`` holds the other vehicles at the same steps.
    """
    dt = world.settings.dt if dt is None else dt
    x, y, psi, v = (np.asarray(ego[k], dtype=float) for k in ("x", "y", "psi", "v"))
    n = len(x)
    t = t0 + dt * np.arange(n)
    route = world.route
    s, e = route.local_coordinates(np.stack([x, y], axis=1))
    out: dict[str, np.ndarray] = {
        "x": x, "y": y, "psi": psi, "v": v,
        "a": np.asarray(ego.get("a", np.zeros(n)), dtype=float),
        "delta": np.asarray(ego.get("delta", np.zeros(n)), dtype=float),
        "s": s, "e": e, "v_max": route.limit_at(s).astype(float),
        "d_stop": _stop_distance(world, s, v, dt),
    }
    out["light_red"], out["d_light"] = _light(world, t, s, v)
    out.update(_others(world, traffic, x, y, psi, s, e, v))
    assert set(out) == PROVIDED_SIGNALS
    return out


@dataclass(frozen=True, eq=False)
class HorizonConstants:
    """What is known at solve time over steps k = 0..H (times ``t`` (H+1,) [s]).

    ``s_ref`` (H+1,) [m]: predicted route positions used for the lookups; ``v_max`` (H+1,) [m/s]
    there. ``s_stop`` [m]: route position of the stop line that applies (+inf if none within
    r_near); ``s_light`` [m] and ``light_red`` (H+1,) ∈ {0, 1} for the light that applies (yellow
    counts as red when the ego can stop at t0). Other vehicles within r_near at t0 (n of them,
    ``index`` into the participants): constant-velocity predictions ``xy`` (n, H+1, 2) [m], ``psi``
    (n, H+1) [rad], boxes ``length``/``width`` (n,) [m], speeds ``v`` (n,) [m/s]. ``lead`` is the
    row of the vehicle ahead in the ego's lane (−1 if none), ``s_lead`` (H+1,) [m] its predicted
    route position (centre) and ``lead_offset`` [m] = (L_ego + L_lead)/2, so that
    d_lead,k = s_lead,k − s_k − lead_offset.
    """

    t: np.ndarray
    s_ref: np.ndarray
    v_max: np.ndarray
    s_stop: float
    s_light: float
    light_red: np.ndarray
    index: np.ndarray
    xy: np.ndarray
    psi: np.ndarray
    length: np.ndarray
    width: np.ndarray
    v: np.ndarray
    lead: int
    s_lead: np.ndarray
    lead_offset: float


def horizon_constants(
    world: World, traffic: TrafficState, t0: float, ego: Sequence[float], *, H: int | None = None,
    dt: float | None = None, s_pred: np.ndarray | None = None, memory: StopMemory | None = None,
    station: tuple[float, float] | None = None,
) -> HorizonConstants:
    """The solve-time constants over the horizon from the ego state ``ego`` = (x, y, psi, v)
    [m, m, rad, m/s] at time ``t0`` [s]. ``s_pred`` (H+1,) [m]: the predicted route positions
    (e.g. the shifted previous plan's); default: the route's reference advance from the ego's
    position. ``memory``: which stop lines are served (default: none). ``station`` = (s, e) [m]:
    the ego's route position and lateral offset when the caller has already projected it
    (default: projected here onto the whole route)."""
    H = world.settings.H if H is None else H
    dt = world.settings.dt if dt is None else dt
    x, y, psi, v = (float(c) for c in ego[:4])
    route = world.route
    r_near = world.settings.r_near
    if station is None:
        s_at, e_at = route.local_coordinates(np.array([[x, y]]))
        station = (float(s_at[0]), float(e_at[0]))
    s0, e0 = float(station[0]), float(station[1])
    t = t0 + dt * np.arange(H + 1)
    if s_pred is None:
        s_pred, _ = route.reference(s0, v, H, dt)
    v_max = route.limit_at(s_pred).astype(float)
    # stop line
    mem = memory or StopMemory.fresh(world)
    d = world.route_stops - s0
    ok = (d >= -PASS_MARGIN) & (d <= r_near) & ~np.asarray(mem.served, dtype=bool)
    s_stop = float(world.route_stops[ok].min()) if ok.any() else np.inf
    # light (as seen at t0; no memory of red crossings is needed ahead of a solve)
    dl = world.route_lights - s0
    okl = (dl >= 0) & (dl <= r_near)
    s_light, light_red = np.inf, np.zeros(H + 1)
    if okl.any():
        j = int(np.flatnonzero(okl)[np.argmin(dl[okl])])
        s_light = float(world.route_lights[j])
        states = world.lights.state_at(t)[:, world.route_light_index[j]]
        can_stop = dl[j] >= v**2 / (2 * world.settings.yellow_decel)
        light_red = ((states == RED) | ((states == YELLOW) & can_stop)).astype(float)
    # other vehicles within r_near, constant velocity
    near = np.flatnonzero(traffic.active & (np.hypot(traffic.x - x, traffic.y - y) <= r_near))
    vel = traffic.v[near, None] * np.stack([np.cos(traffic.psi[near]), np.sin(traffic.psi[near])], axis=1)
    xy = traffic.xy[near][:, None, :] + vel[:, None, :] * (dt * np.arange(H + 1))[None, :, None]
    lead, s_lead, lead_offset = -1, np.full(H + 1, np.inf), 0.0
    if len(near):
        si, ei = route.project_near(traffic.xy[near], np.full(len(near), s0), r_near + 5.0)
        along = np.cos(traffic.psi[near] - route.heading_at(si))
        ahead = (si > s0) & (np.abs(ei - e0) < route.width_at(si) / 2) & (along > 0)
        if ahead.any():
            lead = int(np.flatnonzero(ahead)[np.argmin(np.where(ahead, si, np.inf)[ahead])])
            s_lead = si[lead] + traffic.v[near[lead]] * along[lead] * dt * np.arange(H + 1)
            lead_offset = (world.ego.length + float(world.parts.length[near[lead]])) / 2
    return HorizonConstants(t, np.asarray(s_pred, dtype=float), v_max, s_stop, s_light, light_red, near, xy,
                            np.repeat(traffic.psi[near, None], H + 1, axis=1), world.parts.length[near],
                            world.parts.width[near], traffic.v[near], lead, s_lead, lead_offset)
