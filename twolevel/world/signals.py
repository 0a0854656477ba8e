"""THE one place that turns a world and an ego state into the named signals rules read.

Two faces, one set of definitions (see :mod:`twolevel.world.provided` for the list and units):

* :func:`signals_along` — per step along a recorded or simulated ego trajectory (monitors);
* :func:`horizon_constants` — over an MPC horizon, the values known at solve time (limits at
  the predicted positions, light states (from their programs with ``v2i``, else the state now
  held over the horizon), stop-line positions, other vehicles' predictions: constant velocity
  relative to their lanes, :mod:`twolevel.world.motion`). The MPC treats v_k and s_k as affine in
  its decision variables and forms d_stop,k = s_stop − s_k, d_light,k = s_light − s_k itself.

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
  in the ego's lane (|e_i − e| < lane width / 2) and heading the same way (within
  :data:`LEAD_HEADING` of the route's heading there: a vehicle crossing at right angles, or
  turning across, is no car ahead), the nearest: bumper-to-bumper gap s_i − s − (L_ego + L_i)/2
  and its speed along the route. +inf / v if none.
* ``min_gap``: signed oriented-box separation to the nearest vehicle within r_near (+inf if none).
* ``rss_gap``: the vehicle ahead as for ``d_lead`` but within the sensing range
  (``settings.sensor_range`` ≥ r_near, what the ego must be able to stop for), its bumper-to-bumper
  gap less RSS's safe distance behind it with the ego as the rear car
  (:func:`twolevel.world.assumptions.safe_distance` with ``settings.response``:
  :class:`~twolevel.world.loader.Sensing`) — ≥ 0 when the ego can stop behind it whatever it does
  within the assumptions. +inf if none.
* ``over_centre``, ``solid_left``, ``no_overtaking``: the centre line left of the route (the
  boundary to the first lane running against it) at s, :func:`twolevel.world.area.overtaking_signals`.
* ``xwalk_busy``, ``d_xwalk``: the marked crosswalks on the route and their pedestrians,
  :func:`twolevel.world.crosswalks.crosswalk_signals` (pedestrians within r_near).
* Participant signals (``d_lon[ID]``, ``present[ID]``, …; :mod:`twolevel.world.provided`):
  :func:`participant_signals_along`, with each participant projected as for ``d_lead``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from twolevel.models.obb import box_corners, box_separation
from twolevel.stl.analysis import PRESENT, participant_key
from twolevel.world.area import overtaking_signals
from twolevel.world.assumptions import ResponseBounds, safe_distance
from twolevel.world.crosswalks import YIELD_DECEL, crosswalk_signals, positions_of
from twolevel.world.geometry import Route
from twolevel.world.motion import predicted_poses
from twolevel.world.provided import PARTICIPANT_SIGNALS, PROVIDED_SIGNALS
from twolevel.world.relations import LEAD_HEADING, acceleration, relations, same_way
from twolevel.world.right_of_way import ZONE_PARTICIPANT_SIGNALS, participant_zone_signals, zone_signals
from twolevel.world.traffic import RED, YELLOW, TrafficState
from twolevel.world.world import World

__all__ = ["PASS_MARGIN", "STOP_ZONE", "LEAD_HEADING", "TrafficLog", "StopMemory", "HorizonConstants", "signals_along",
           "participant_signals_along", "horizon_constants", "route_lookups", "update_stop_memory", "same_way",
           "ahead_in_lane", "rss_gap", "sensing_window", "crosswalks_seen"]

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


def crosswalks_seen(world: World, s: np.ndarray, v: np.ndarray, index: np.ndarray, x: np.ndarray, y: np.ndarray,
                    present: np.ndarray, *, reach: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``xwalk_busy`` and ``d_xwalk`` (shape S) for an ego at route positions ``s`` [m] with speeds
    ``v`` [m/s] (shape S) among participants ``index`` (n,) at ``x``, ``y`` [m] (S + (n,)),
    ``present`` (S + (n,)) where active and within r_near (:mod:`twolevel.world.crosswalks`);
    ``reach`` [m]: how far ahead a crosswalk applies (None: r_near, the signals' definition)."""
    cw = world.crosswalks
    xy, here = positions_of(cw, np.asarray(index), x, y, present)
    return crosswalk_signals(cw, s, v, xy, here, r_near=world.settings.r_near if reach is None else reach,
                             decel=YIELD_DECEL, pass_margin=PASS_MARGIN)


def sensing_window(world: World) -> float:
    """[m] How far along the route a sensed vehicle is searched from the ego's position: twice
    the sensing range and 5 m (on a bending road the way along it is longer than the straight
    distance within which the vehicle is sensed)."""
    st = world.settings
    return 2.0 * max(st.sensor_range, st.r_near) + 5.0


def ahead_in_lane(route: Route, s_i: np.ndarray, e_i: np.ndarray, psi_i: np.ndarray, s: np.ndarray | float,
                  e: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Which vehicles at route coordinates ``s_i``, ``e_i`` [m] with heading ``psi_i`` [rad] are
    *ahead in the ego's lane* for an ego at ``s``, ``e`` [m] (broadcast): projected ahead, within
    half a lane width of the ego's lateral offset, heading the route's way (:func:`same_way`); and
    the cosine of their heading to the route's (their speed's share along it)."""
    h = route.heading_at(s_i)
    return (s_i > s) & (np.abs(e_i - e) < route.width_at(s_i) / 2) & same_way(psi_i, h), np.cos(psi_i - h)


def rss_gap(gap: np.ndarray, v: np.ndarray, v_front: np.ndarray, response: ResponseBounds) -> np.ndarray:
    """The ``rss_gap`` signal [m]: a bumper-to-bumper ``gap`` [m] to the vehicle ahead (+inf: none)
    less RSS's safe distance of an ego at ``v`` [m/s] behind it at ``v_front`` [m/s] (broadcast)."""
    gap = np.asarray(gap, dtype=float)
    d = safe_distance(np.asarray(v, dtype=float), np.asarray(v_front, dtype=float), response)
    return np.where(np.isfinite(gap), gap - d, np.inf)


def _others(world: World, traffic: TrafficLog | None, x: np.ndarray, y: np.ndarray, psi: np.ndarray, s: np.ndarray,
            e: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
    n = len(s)
    out = {"d_lead": np.full(n, np.inf), "v_lead": v.astype(float).copy(), "min_gap": np.full(n, np.inf),
           "n_near": np.zeros(n), "rss_gap": np.full(n, np.inf)}
    if traffic is None or traffic.x.shape[1] == 0:
        return out
    st = world.settings
    dist = np.hypot(traffic.x - x[:, None], traffic.y - y[:, None])
    seen = traffic.active & (dist <= max(st.sensor_range, st.r_near))
    near = traffic.active & (dist <= st.r_near)
    out["n_near"] = near.sum(axis=1).astype(float)
    k, i = np.nonzero(seen)
    if len(k) == 0:
        return out
    route = world.route
    si, ei = route.project_near(np.stack([traffic.x[k, i], traffic.y[k, i]], axis=1), s[k],
                                sensing_window(world))
    ahead, along = ahead_in_lane(route, si, ei, traffic.psi[k, i], s[k], e[k])
    gap = si - s[k] - (world.ego.length + traffic.length[i]) / 2
    r = np.arange(n)
    vl = np.zeros(seen.shape)
    vl[k, i] = traffic.v[k, i] * along
    for name, mask in (("rss_gap", ahead), ("d_lead", ahead & near[k, i])):
        g = np.full(seen.shape, np.inf)
        g[k[mask], i[mask]] = gap[mask]
        best = g.argmin(axis=1)
        has = np.isfinite(g[r, best])
        if name == "rss_gap":
            out[name] = rss_gap(g[r, best], v, vl[r, best], st.response)
        else:
            out["d_lead"] = np.where(has, g[r, best], np.inf)
            out["v_lead"] = np.where(has, vl[r, best], v)
    k, i = np.nonzero(near)
    if len(k) == 0:
        return out
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
    out.update(zone_signals(world, s, v))
    out.update(overtaking_signals(world.lanes, route, s, e, world.ego.width))
    if traffic is None:
        nobody = np.zeros((n, 0))
        out["xwalk_busy"], out["d_xwalk"] = crosswalks_seen(world, s, v, np.zeros(0, int), nobody, nobody,
                                                            nobody.astype(bool))
    else:
        near = traffic.active & (np.hypot(traffic.x - x[:, None], traffic.y - y[:, None]) <= world.settings.r_near)
        out["xwalk_busy"], out["d_xwalk"] = crosswalks_seen(world, s, v, np.arange(traffic.x.shape[1]), traffic.x,
                                                            traffic.y, near)
    assert set(out) == PROVIDED_SIGNALS
    return out


def participant_signals_along(
    world: World, traffic: TrafficLog, ego: Mapping[str, np.ndarray], *, dt: float | None = None,
    names: Sequence[str] = (PRESENT,) + PARTICIPANT_SIGNALS, ids: Sequence[str] | None = None, t0: float = 0.0,
) -> dict[str, np.ndarray]:
    """Participant signals along an ego trajectory: for every participant of ``traffic`` (N of
    them, named ``ids``, default the world's participants) and each of ``names``, the (T,) array
    ``name[ID]`` (:func:`~twolevel.stl.analysis.participant_key`). ``ego`` as for
    :func:`signals_along` (x, y [m], psi [rad], sampled every ``dt`` [s] from ``t0`` [s]); a
    participant is present where it is active and within r_near."""
    dt = world.settings.dt if dt is None else dt
    ids = world.parts.ids if ids is None else ids
    x, y, psi = (np.asarray(ego[k], dtype=float) for k in ("x", "y", "psi"))
    T, N = traffic.x.shape
    route = world.route
    s, e = route.local_coordinates(np.stack([x, y], axis=1))
    r_near = world.settings.r_near
    near = traffic.active & (np.hypot(traffic.x - x[:, None], traffic.y - y[:, None]) <= r_near)
    so, eo = np.full((T, N), np.nan), np.full((T, N), np.nan)
    k, i = np.nonzero(near)
    if len(k):
        so[k, i], eo[k, i] = route.project_near(np.stack([traffic.x[k, i], traffic.y[k, i]], axis=1), s[k],
                                                r_near + 5.0)
    rel = relations(route, {"s": s[:, None], "e": e[:, None], "psi": psi[:, None]}, (world.ego.length, world.ego.width),
                    {"s": so, "e": eo, "psi": traffic.psi, "v": traffic.v}, traffic.length, traffic.width, near)
    rel["a"] = acceleration(rel["v"], near, dt)
    rel[PRESENT] = np.where(near, np.inf, -np.inf)
    if any(n in ZONE_PARTICIPANT_SIGNALS for n in names):
        rel.update(participant_zone_signals(world, s, t0 + dt * np.arange(T), {"x": traffic.x, "y": traffic.y,
                                            "psi": traffic.psi, "v": traffic.v}, traffic.length, near))
    return {participant_key(n, pid): rel[n][:, j] for n in names for j, pid in enumerate(ids)}


@dataclass(frozen=True, eq=False)
class HorizonConstants:
    """What is known at solve time over steps k = 0..H (times ``t`` (H+1,) [s]; the steps may
    differ in length, :func:`horizon_constants`).

    ``s_ref`` (H+1,) [m]: predicted route positions used for the lookups; ``v_max`` (H+1,) [m/s]
    there. ``s_stop`` [m]: route position of the stop line that applies (+inf if none within
    r_near); ``s_light`` [m] and ``light_red`` (H+1,) ∈ {0, 1} for the light that applies (yellow
    counts as red when the ego can stop at t0). Other vehicles within r_near at t0 (n of them,
    ``index`` into the participants): predictions (:func:`~twolevel.world.motion.predicted_poses`)
    ``xy`` (n, H+1, 2) [m], ``psi``
    (n, H+1) [rad], boxes ``length``/``width`` (n,) [m], speeds ``v`` (n,) [m/s]. ``lead`` is the
    row of the vehicle ahead in the ego's lane (−1 if none), ``s_lead`` (H+1,) [m] its predicted
    route position (centre) and ``lead_offset`` [m] = (L_ego + L_lead)/2, so that
    d_lead,k = s_lead,k − s_k − lead_offset. ``ahead`` is the participant index of the vehicle ahead
    in the ego's lane within the sensing range (−1 if none; ``lead``'s vehicle when that is within
    r_near), ``s_ahead`` (H+1,) [m] its predicted route position, ``v_ahead`` [m/s] its speed along
    the route, ``e_ahead`` [m] its lateral offset from the route and ``ahead_offset`` [m] =
    (L_ego + L_ahead)/2 (``rss_gap``'s vehicle). Every vehicle within the sensing range: ``seen``
    (m,) participant indices, ``seen_s``/``seen_e`` (m,) [m] route coordinates now, ``seen_v``
    (m,) [m/s] speeds along the route (< 0 against it). ``s_xwalk`` [m]: the line of the crosswalk
    ``d_xwalk`` measures to now (+inf if none), ``xwalk_busy`` (H+1,) ∈ {0, 1} its ``xwalk_busy``
    now, held over the horizon (where the pedestrians will be is not predicted: one waiting or
    crossing now keeps the line closed until a later solve sees them past the ego's lane).
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
    ahead: int = -1
    s_ahead: np.ndarray = field(default_factory=lambda: np.full(1, np.inf))
    v_ahead: float = 0.0
    ahead_offset: float = 0.0
    e_ahead: float = 0.0
    seen: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    seen_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    seen_e: np.ndarray = field(default_factory=lambda: np.zeros(0))
    seen_v: np.ndarray = field(default_factory=lambda: np.zeros(0))
    s_xwalk: float = np.inf
    xwalk_busy: np.ndarray = field(default_factory=lambda: np.zeros(1))
    over_offset: np.ndarray = field(default_factory=lambda: np.full(1, -np.inf))
    solid_left: np.ndarray = field(default_factory=lambda: np.zeros(1))
    no_overtaking: np.ndarray = field(default_factory=lambda: np.zeros(1))


def horizon_constants(
    world: World, traffic: TrafficState, t0: float, ego: Sequence[float], *, H: int | None = None,
    dt: float | None = None, s_pred: np.ndarray | None = None, memory: StopMemory | None = None,
    station: tuple[float, float] | None = None, ticks: np.ndarray | None = None,
) -> HorizonConstants:
    """The solve-time constants over the horizon from the ego state ``ego`` = (x, y, psi, v)
    [m, m, rad, m/s] at time ``t0`` [s]: H steps of ``dt`` [s] (default the world's), or at
    the times t0 + dt·``ticks`` of a horizon whose steps differ (``ticks`` (N+1,): whole periods
    from now, 0 first). ``s_pred`` (H+1,) [m]: the predicted route positions (e.g. the shifted
    previous plan's; needed with ``ticks``); default: the route's reference advance from the
    ego's position. ``memory``: which stop lines are served (default: none). ``station`` =
    (s, e) [m]: the ego's route position and lateral offset when the caller has already
    projected it (default: projected here onto the whole route)."""
    H = world.settings.H if H is None else H
    dt = world.settings.dt if dt is None else dt
    x, y, psi, v = (float(c) for c in ego[:4])
    route = world.route
    r_near = world.settings.r_near
    if station is None:
        s_at, e_at = route.local_coordinates(np.array([[x, y]]))
        station = (float(s_at[0]), float(e_at[0]))
    s0, e0 = float(station[0]), float(station[1])
    ticks = np.arange(H + 1) if ticks is None else np.asarray(ticks)
    H = len(ticks) - 1
    tau = dt * ticks
    t = t0 + tau
    if s_pred is None:
        s_pred, _ = route.reference(s0, v, H, dt)
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
        # what the planner knows: the light's program (V2I), else only its state now, held
        states = world.lights.state_at(t if world.settings.v2i else np.full_like(t, t0))[:, world.route_light_index[j]]
        can_stop = dl[j] >= v**2 / (2 * world.settings.yellow_decel)
        light_red = ((states == RED) | ((states == YELLOW) & can_stop)).astype(float)
    # other vehicles within r_near, constant velocity (relative to their lanes: world.motion)
    dist = np.hypot(traffic.x - x, traffic.y - y)
    near = np.flatnonzero(traffic.active & (dist <= r_near))
    ox, oy, opsi = predicted_poses(world, traffic, near, tau)
    xy = np.stack([ox, oy], axis=2)
    lead, s_lead, lead_offset = -1, np.full(H + 1, np.inf), 0.0
    # the vehicle ahead within the sensing range (lead's, when that is within r_near)
    rng = max(world.settings.sensor_range, r_near)
    seen = np.flatnonzero(traffic.active & (dist <= rng))
    ahead, s_ahead, v_ahead, ahead_offset, e_ahead = -1, np.full(H + 1, np.inf), 0.0, 0.0, 0.0
    si, ei, along = np.zeros(0), np.zeros(0), np.zeros(0)
    if len(seen):
        si, ei = route.project_near(traffic.xy[seen], np.full(len(seen), s0), sensing_window(world))
        mask, along = ahead_in_lane(route, si, ei, traffic.psi[seen], s0, e0)
        if mask.any():
            j = int(np.flatnonzero(mask)[np.argmin(si[mask])])
            ahead = int(seen[j])
            v_ahead = float(traffic.v[ahead] * along[j])
            s_ahead = si[j] + v_ahead * dt * ticks
            ahead_offset = (world.ego.length + float(world.parts.length[ahead])) / 2
            e_ahead = float(ei[j])
            if dist[ahead] <= r_near:
                lead = int(np.searchsorted(near, ahead))
                s_lead, lead_offset = s_ahead, ahead_offset
    at = route_lookups(world, np.asarray(s_pred, dtype=float))
    busy, d_x = crosswalks_seen(world, np.array(s0), np.array(v), near, traffic.x[near], traffic.y[near],
                                np.ones(len(near), dtype=bool))
    s_xwalk = s0 + float(d_x) if np.isfinite(d_x) else np.inf
    return HorizonConstants(t, np.asarray(s_pred, dtype=float), at["v_max"], s_stop, s_light, light_red, near, xy,
                            opsi, world.parts.length[near],
                            world.parts.width[near], traffic.v[near], lead, s_lead, lead_offset, ahead, s_ahead,
                            v_ahead, ahead_offset, e_ahead, seen, si, ei, traffic.v[seen] * along,
                            s_xwalk, np.full(H + 1, float(busy)), at["over_offset"], at["solid_left"],
                            at["no_overtaking"])


def route_lookups(world: World, s_ref: np.ndarray) -> dict[str, np.ndarray]:
    """What :class:`HorizonConstants` looks up at the predicted route positions ``s_ref``
    (H+1,) [m]: ``v_max`` [m/s], ``over_offset`` [m] (``over_centre`` at e = 0), ``solid_left`` and
    ``no_overtaking`` (1/0) — replace them all together when the reference's positions change."""
    at = overtaking_signals(world.lanes, world.route, s_ref, 0.0, world.ego.width)
    return {"v_max": world.route.limit_at(s_ref).astype(float), "over_offset": at["over_centre"],
            "solid_left": at["solid_left"], "no_overtaking": at["no_overtaking"]}
