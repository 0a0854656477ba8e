"""What the ego senses: the rules' named signals over K predicted trajectories at once.

The definitions are those of :mod:`twolevel.world.signals` (the reference; the tests check
that these values equal :func:`~twolevel.world.signals.signals_along` on the same trajectory),
written for the closed loop:

* **batched** over K candidate trajectories of T samples (the low level evaluates every
  candidate in one pass of numpy calls);
* **incremental**: what the definitions need from the past (stop signs served, the current
  standstill at each stop line, lights crossed and whether on red) is a :class:`Memory`
  carried from step to step, so the current sample costs O(1), not a replay of the run.

Other vehicles are :class:`Others`: their poses over the same T samples (the actual traffic for
the current step; over the horizon for the low level the predictions of
:func:`~twolevel.world.motion.predicted_poses` — along their lanes for lane followers — as
:func:`~twolevel.world.signals.horizon_constants` predicts them for the MPC). Sensing is limited
to ``r_near`` [m] at every sample, but for ``rss_gap``'s vehicle ahead, sensed within the sensing
range. Units: m, rad, m/s, s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twolevel.models.obb import pose_separation
from twolevel.stl.analysis import PRESENT, participant_key
from twolevel.world.area import overtaking_signals
from twolevel.world.motion import predicted_poses
from twolevel.world.relations import acceleration, relations
from twolevel.world.right_of_way import ZONE_PARTICIPANT_SIGNALS, participant_zone_signals, zone_signals
from twolevel.world.signals import (PASS_MARGIN, STOP_ZONE, StopMemory, ahead_in_lane, crosswalks_seen, rss_gap,
                                    sensing_window, update_stop_memory)
from twolevel.world.traffic import RED, YELLOW, TrafficState
from twolevel.world.world import World

__all__ = ["Memory", "Others", "others_now", "others_predicted", "sense", "min_box_gap"]


@dataclass(frozen=True)
class Memory:
    """The past as the signal definitions need it: the stop-sign memory (one entry per stop line
    on the route), and per light on the route whether the ego has crossed its line and whether
    the light was red when it did."""

    stops: StopMemory
    crossed: tuple[bool, ...]
    on_red: tuple[bool, ...]

    @classmethod
    def fresh(cls, world: World) -> "Memory":
        n = len(world.route_lights)
        return cls(StopMemory.fresh(world), (False,) * n, (False,) * n)

    def after(self, world: World, t: float, s: float, v: float) -> "Memory":
        """The memory once the sample at time ``t`` [s], route position ``s`` [m] and speed
        ``v`` [m/s] has been taken (stop lines served, lights crossed)."""
        stops = update_stop_memory(self.stops, world, s, v, world.settings.dt)
        d = world.route_lights - s
        crossed = np.asarray(self.crossed, dtype=bool)
        new = (d < 0) & ~crossed
        state = world.lights.state_at(t)[world.route_light_index] if len(d) else np.zeros(0, int)
        on_red = np.where(new, state == RED, np.asarray(self.on_red, dtype=bool))
        return Memory(stops, tuple(bool(c) for c in crossed | new), tuple(bool(r) for r in on_red))


@dataclass(frozen=True, eq=False)
class Others:
    """n other vehicles over T samples: centres ``x``/``y`` (n, T) [m], heading ``psi`` (n, T)
    [rad], speed ``v`` (n, T) [m/s], route coordinates ``s``/``e`` (n, T) [m], boxes ``length``/
    ``width`` (n,) [m] and their participant ``index`` (n,). Sample 0 is when they were sensed
    (now): a vehicle counts for the signals of the neighbourhood (``d_lead``, ``min_gap``,
    ``n_near``) at the samples where it is within ``r_near`` of the ego and was at sample 0; the
    vehicle ahead sensed beyond r_near (:func:`others_now`) is there for ``rss_gap``."""

    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    v: np.ndarray
    s: np.ndarray
    e: np.ndarray
    length: np.ndarray
    width: np.ndarray
    index: np.ndarray

    @property
    def n(self) -> int:
        return int(self.x.shape[0])


def _others(world: World, idx: np.ndarray, x: np.ndarray, y: np.ndarray, psi: np.ndarray, v: np.ndarray,
            s_center: np.ndarray, half: float) -> Others:
    """``s_center``: where to search each sample's projection, (T,) or (n, T) [m]."""
    n, T = x.shape
    if n:
        s, e = world.route.project_near(np.stack([x.ravel(), y.ravel()], axis=1),
                                        np.broadcast_to(s_center, (n, T)).ravel(), half)
        s, e = s.reshape(n, T), e.reshape(n, T)
    else:
        s = e = np.zeros((0, T))
    return Others(x, y, psi, v, s, e, world.parts.length[idx], world.parts.width[idx], idx)


def others_now(world: World, traffic: TrafficState, x: float, y: float, s0: float) -> Others:
    """The vehicles within ``r_near`` of the ego at (x, y) [m] now (T = 1), and beyond it the
    nearest vehicle ahead in the ego's lane within the sensing range (``rss_gap``'s); ``s0`` [m]
    is the ego's route position (where their projections are searched)."""
    st = world.settings
    dist = np.hypot(traffic.x - x, traffic.y - y)
    idx = np.flatnonzero(traffic.active & (dist <= st.r_near))
    col = lambda a, i: a[i][:, None]  # noqa: E731
    now = _others(world, idx, col(traffic.x, idx), col(traffic.y, idx), col(traffic.psi, idx), col(traffic.v, idx),
                  np.array([s0]), st.r_near + 5.0)
    far = np.flatnonzero(traffic.active & (dist > st.r_near) & (dist <= st.sensor_range))
    if not len(far):
        return now
    out = _others(world, far, col(traffic.x, far), col(traffic.y, far), col(traffic.psi, far), col(traffic.v, far),
                  np.array([s0]), sensing_window(world))
    _, e0 = world.route.project_near(np.array([[x, y]]), np.array([s0]), 5.0)
    mask, _ = ahead_in_lane(world.route, out.s[:, 0], out.e[:, 0], out.psi[:, 0], s0, float(e0[0]))
    if not mask.any():
        return now
    j = np.flatnonzero(mask)[np.argmin(out.s[mask, 0])]
    cat = lambda a, b: np.concatenate([a, b[[j]]])  # noqa: E731
    return Others(*(cat(getattr(now, f), getattr(out, f)) for f in ("x", "y", "psi", "v", "s", "e", "length", "width",
                                                                       "index")))


def others_predicted(world: World, traffic: TrafficState, x: float, y: float, s0: float, H: int,
                     dt: float, *, now: Others | None = None) -> Others:
    """Predictions over k = 0..H of the vehicles within ``r_near`` now
    (:func:`~twolevel.world.motion.predicted_poses`: constant velocity relative to their lanes, as
    :func:`~twolevel.world.signals.horizon_constants` predicts them); ``s0`` [m] is the ego's
    route position. Each vehicle's predicted sample is projected near where its motion along the
    route puts it (s_i + v_i·cos(ψ_i − route heading)·t): a narrow search instead of one as wide
    as everything reachable. ``now``: :func:`others_now` of the same arguments, when the caller
    already has it."""
    if now is None:
        now = others_now(world, traffic, x, y, s0)
    idx = now.index
    tk = dt * np.arange(H + 1)
    v = traffic.v[idx]
    psi = traffic.psi[idx]
    px, py, ppsi = predicted_poses(world, traffic, idx, tk)
    rep = lambda a: np.repeat(a[:, None], H + 1, axis=1)  # noqa: E731
    if not len(idx):
        return _others(world, idx, px, py, ppsi, rep(v), tk, 1.0)
    along = v * np.cos(psi - world.route.heading_at(now.s[:, 0]))
    center = now.s[:, :1] + along[:, None] * tk[None]
    # along a bend of radius R a straight line of length L projects L³/(3R²) short of that
    # (2 m for L = 15 m, R = 20 m): a quarter of the length and 3 m leave room for much tighter
    half = 3.0 + 0.25 * float(np.max(np.abs(v))) * H * dt
    out = _others(world, idx, px[:, 1:], py[:, 1:], ppsi[:, 1:], v[:, None], center[:, 1:], half)
    return Others(px, py, ppsi, rep(v), np.concatenate([now.s, out.s], axis=1),
                  np.concatenate([now.e, out.e], axis=1), now.length, now.width, idx)


def min_box_gap(x: np.ndarray, y: np.ndarray, psi: np.ndarray, length: float, width: float, others: Others,
                near: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Minimum signed box separation (K, T) [m] between the ego's poses (K, T) and the ``near``
    (K, T, n) others (+inf where none is near). Exact: pairs whose bounding-circle lower bound
    exceeds the smallest inscribed-circle upper bound cannot be the nearest and are skipped."""
    K, T = x.shape
    if others.n == 0 or not near.any():
        return np.full((K, T), np.inf)
    r_out = 0.5 * np.hypot(length, width) + 0.5 * np.hypot(others.length, others.width)
    r_in = 0.5 * width + 0.5 * others.width
    ub = np.where(near, dist - r_in, np.inf).min(axis=-1, keepdims=True)
    pick = near & (dist - r_out <= ub)
    k, t, i = np.nonzero(pick)
    sep = pose_separation(x[k, t], y[k, t], psi[k, t], length, width, others.x[i, t], others.y[i, t],
                          others.psi[i, t], others.length[i], others.width[i])
    out = np.full((K, T), np.inf)
    np.minimum.at(out, (k, t), sep)
    return out


def sense(world: World, t0: float, dt: float, memory: Memory, others: Others, x: np.ndarray, y: np.ndarray,
          psi: np.ndarray, v: np.ndarray, a: np.ndarray, delta: np.ndarray, *, s_center: np.ndarray | None = None,
          half_window: float = 10.0) -> dict[str, np.ndarray]:
    """Every provided signal (K, T) (of the on-demand ones, those the scenario's rules read:
    :attr:`~twolevel.world.world.World.on_demand_signals`) along K ego trajectories sampled every
    ``dt`` [s] from ``t0`` [s]: poses x, y [m], psi [rad], speed v [m/s] and inputs a [m/s²], delta [rad], each (K, T);
    and, when the scenario's rules quantify over participants, the participant signals they read
    of each of ``others`` (``name[ID]``, :func:`twolevel.world.signals.participant_signals_along`).
    ``memory`` is the state of the past *before* sample 0; ``others`` the other vehicles at the
    same T samples. Route projections search ``s_center`` (T,) ± ``half_window`` [m]
    (default: the whole route)."""
    K, T = x.shape
    route = world.route
    pts = np.stack([x.ravel(), y.ravel()], axis=1)
    if s_center is None:
        s, e = route.local_coordinates(pts)
    else:
        s, e = route.project_near(pts, np.broadcast_to(s_center, (K, T)).ravel(), half_window)
    s, e = s.reshape(K, T), e.reshape(K, T)
    out: dict[str, np.ndarray] = {"x": x, "y": y, "psi": psi, "v": v, "a": a, "delta": delta, "s": s, "e": e,
                                  "v_max": route.limit_at(s).astype(float)}
    out["d_stop"] = _stop_distance(world, memory.stops, s, v, dt)
    out["light_red"], out["d_light"] = _light(world, memory, t0 + dt * np.arange(T), s, v)
    out.update(_lead_and_gap(world, others, x, y, psi, s, e, v))
    out.update(zone_signals(world, s, v))
    out.update(overtaking_signals(world.lanes, route, s, e, world.ego.width))
    if world.on_demand_signals:  # only those a rule reads: a run records (and keeps a history of) only these
        busy, d = _crosswalks(world, others, x, y, s, v)
        out.update({n: a for n, a in (("xwalk_busy", busy), ("d_xwalk", d)) if n in world.on_demand_signals})
    if world.participant_signals and others.n:
        out.update(_participants(world, others, x, y, psi, s, e, dt, t0))
    return out


def _crosswalks(world: World, others: Others, x: np.ndarray, y: np.ndarray, s: np.ndarray, v: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """``xwalk_busy`` and ``d_xwalk`` (K, T): the pedestrians among ``others`` present where they
    are within r_near and were when sensed (as for the neighbourhood's signals)."""
    _, near = _sensed(world, others, x, y)
    return crosswalks_seen(world, s, v, others.index, others.x.T[None], others.y.T[None], near)


def _sensed(world: World, others: Others, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distances (K, T, n) [m] of ``others`` from the ego at ``x``, ``y`` (K, T) [m], and
    where each is sensed: within r_near there, and at sample 0 (when sensed)."""
    dist = np.hypot(others.x.T[None] - x[..., None], others.y.T[None] - y[..., None])
    r = world.settings.r_near
    return dist, (dist <= r) & (dist[:, :1] <= r)


def _participants(world: World, others: Others, x: np.ndarray, y: np.ndarray, psi: np.ndarray, s: np.ndarray,
                  e: np.ndarray, dt: float, t0: float) -> dict[str, np.ndarray]:
    """The participant signals the scenario's rules read (``world.participant_signals``), (K, T)
    per participant among ``others`` (sample 0 at ``t0`` [s]): present where it is within r_near."""
    near = np.hypot(others.x.T[None] - x[..., None], others.y.T[None] - y[..., None]) <= world.settings.r_near
    other = {"s": others.s.T[None], "e": others.e.T[None], "psi": others.psi.T[None], "v": others.v.T[None]}
    rel = relations(world.route, {"s": s[..., None], "e": e[..., None], "psi": psi[..., None]},
                    (world.ego.length, world.ego.width), other, others.length, others.width, near)
    names = world.participant_signals
    if "a" in names:
        rel["a"] = acceleration(rel["v"], near, dt)
    rel[PRESENT] = np.where(near, np.inf, -np.inf)
    if any(n in ZONE_PARTICIPANT_SIGNALS for n in names):
        T = s.shape[1]
        rel.update(participant_zone_signals(world, s, (t0 + dt * np.arange(T))[None],
                                            {"x": others.x.T[None], "y": others.y.T[None], "psi": others.psi.T[None],
                                             "v": others.v.T[None]}, others.length, near))
    ids = world.parts.ids
    return {participant_key(n, ids[j]): rel[n][..., i] for n in names for i, j in enumerate(others.index)}


def _stop_distance(world: World, mem: StopMemory, s: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
    if len(world.route_stops) == 0:
        return np.full(s.shape, np.inf)
    st = world.settings
    d = world.route_stops - s[..., None]  # (K, T, J)
    zone = (d >= -PASS_MARGIN) & (d <= st.r_near)
    cond = (v <= st.stop_speed)[..., None] & (d >= -PASS_MARGIN) & (d <= STOP_ZONE)
    idx = np.arange(s.shape[1])[None, :, None]
    last_false = np.maximum.accumulate(np.where(~cond, idx, -1), axis=1)
    still = np.asarray(mem.still)
    base = np.where(still >= 0, still + dt, 0.0)
    duration = np.where(last_false >= 0, (idx - last_false - 1) * dt, base + idx * dt)
    need = world.stops.stop_time[world.route_stop_index]
    done = cond & (duration >= need - 1e-9)
    served = np.asarray(mem.served, dtype=bool) | np.logical_or.accumulate(done, axis=1)
    return np.where(zone & ~served, d, np.inf).min(axis=-1)


def _light(world: World, mem: Memory, t: np.ndarray, s: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    K, T = s.shape
    if len(world.route_lights) == 0:
        return np.zeros((K, T)), np.full((K, T), np.inf)
    st = world.settings
    d = world.route_lights - s[..., None]  # (K, T, Q)
    state = world.lights.state_at(t)[:, world.route_light_index][None]  # (1, T, Q)
    must = (state == RED) | ((state == YELLOW) & (d >= v[..., None] ** 2 / (2 * st.yellow_decel)))
    idx = np.arange(T)[None, :, None]
    crossed = d < 0
    first = np.where(crossed.any(axis=1), crossed.argmax(axis=1), T)  # (K, Q)
    state_at_first = np.take_along_axis(np.broadcast_to(state, d.shape), np.minimum(first, T - 1)[:, None, :], axis=1)[:, 0]
    before = np.asarray(mem.crossed, dtype=bool)[None]
    c = np.where(before, -1, first)
    on_red = np.where(before, np.asarray(mem.on_red, dtype=bool)[None], (state_at_first == RED) & (first < T))
    applies = ((d >= 0) & (d <= st.r_near)) | ((idx >= c[:, None]) & on_red[:, None] & (d >= -PASS_MARGIN))
    dd = np.where(applies, d, np.inf)
    j = dd.argmin(axis=-1)[..., None]
    d_light = np.take_along_axis(dd, j, axis=-1)[..., 0]
    red = np.where(np.isfinite(d_light), np.take_along_axis(must, j, axis=-1)[..., 0], False).astype(float)
    return red, d_light


def _lead_and_gap(world: World, others: Others, x: np.ndarray, y: np.ndarray, psi: np.ndarray, s: np.ndarray,
                  e: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
    K, T = x.shape
    out = {"d_lead": np.full((K, T), np.inf), "v_lead": v.astype(float).copy(), "min_gap": np.full((K, T), np.inf),
           "n_near": np.zeros((K, T)), "rss_gap": np.full((K, T), np.inf)}
    if others.n == 0:
        return out
    st = world.settings
    dist, near = _sensed(world, others, x, y)  # (K, T, n)
    out["n_near"] = near.sum(axis=-1).astype(float)
    route = world.route
    ahead, along = ahead_in_lane(route, others.s.T[None], others.e.T[None], others.psi.T[None], s[..., None],
                                 e[..., None])  # (K, T, n), (1, T, n)
    v_other = np.broadcast_to(others.v.T[None] * along, dist.shape)
    bumper = others.s.T[None] - s[..., None] - (world.ego.length + others.length) / 2
    for name, mask in (("d_lead", ahead & near), ("rss_gap", ahead & (dist <= st.sensor_range))):
        gap = np.where(mask, bumper, np.inf)
        best = gap.argmin(axis=-1)[..., None]
        g = np.take_along_axis(gap, best, axis=-1)[..., 0]
        v_front = np.take_along_axis(v_other, best, axis=-1)[..., 0]
        if name == "d_lead":
            out["d_lead"] = g
            out["v_lead"] = np.where(np.isfinite(g), v_front, v)
        else:
            out["rss_gap"] = rss_gap(g, v, v_front, st.response)
    out["min_gap"] = min_box_gap(x, y, psi, world.ego.length, world.ego.width, others, near, dist)
    return out
