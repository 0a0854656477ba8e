"""Right of way at junctions as signals: the ego's next conflict zone on its route, and for each
other participant the time it needs to reach and to clear that zone and whether it goes first.

Built on :mod:`twolevel.world.conflicts` (the conflict zones between a junction's connecting lanes
and ``first``, who goes first by the arms' priorities). Definitions (the table of
:mod:`twolevel.world.provided` states names and units):

* **The ego's conflict area** on a connecting lane of its route: from the first entry to the last
  exit, along the route, of the zones that lane shares with other connecting lanes
  (:class:`RouteZones`). The *next* area is the first whose exit the ego's rear has not passed
  and whose entry is within ``r_near`` of the ego's front. ``d_zone`` [m] = entry − front
  (≤ 0 once the front is in), ``d_zone_out`` [m] = exit − rear (> 0 until the ego has left it);
  the ego is *inside* while d_zone ≤ 0 < d_zone_out. No area: +inf and −inf. ``t_zone`` [s] =
  max(d_zone, 0)/v and ``t_zone_out`` [s] = max(d_zone_out, 0)/v at the current speed (+inf when
  standing short of it, :data:`STANDING`; no area: +inf, 0).
* **A participant's way to the area**: it is *on* a conflicting connecting lane, or on that
  lane's incoming lane, when its centre lies within half the lane's width of the lane's centre
  line, within the lane's length, and it heads the lane's way (within
  :data:`~twolevel.world.relations.LEAD_HEADING`). Its distance to the zone's entry is
  d_in = zone start − front and to its exit d_out = zone end − rear, along its lane (from an
  incoming lane: the rest of that lane plus the way into the connecting lane; a participant
  still on the incoming lane is taken to go straight on or to cross the ego's way — a *turn* that
  merges into the ego's way counts once it is on its turning lane, as a driver reads the
  indicator). ``t_reach(o)`` =
  max(d_in, 0)/v_o (0 inside; +inf once past, or standing short of it), ``t_clear(o)`` =
  max(d_out, 0)/v_o (+inf standing in or before it). On an incoming lane a participant's turn is
  not known: every connecting lane from it that conflicts counts, the earliest reach, the latest
  clearing and the priority of any of them (a careful driver's reading).
* **priority(o)** = 1 when o goes first at that conflict: ``first`` names o's lane; with no fixed
  order (−1: lights of different phases, or equal lanes) o goes first unless a red light holds
  it; and never while o's own arm shows red (a light on o's incoming lane, red or yellow with o
  able to stop is not asked: red only). 0 otherwise, and where o is absent.
* **d_exit(o)** [m]: how far the ego's rear still has to go along the route to leave its own zone
  of the conflict(s) with o's way (the latest exit of those o's reach and clearing count; < 0
  once left), so that the ego's time to get out of o's way is d_exit(o) over its speed.

Absent participants (not within ``r_near``, or on no conflicting lane): t_reach +inf,
t_clear 0, priority 0, d_exit −inf — a rule body reads "nobody coming". Everything is vectorised over any
leading shape (samples, candidate trajectories) with participants on the last axis. Units: m, s,
m/s, rad.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from twolevel.world.conflicts import MERGING
from twolevel.world.junction import TURNS
from twolevel.world.relations import same_way
from twolevel.world.traffic import RED

STRAIGHT = TURNS.index("straight")

__all__ = ["STANDING", "REACH_DISTANCE", "RouteZones", "route_zones", "next_area", "zone_signals",
           "participant_zone_signals", "ZONE_SIGNALS", "ZONE_PARTICIPANT_SIGNALS"]

STANDING = 0.1
"""[m/s] At or below this speed a body stands: it reaches nothing (time +inf)."""

REACH_DISTANCE = "reach_distance"
"""The key under which :func:`participant_zone_signals` also returns each participant's distance
[m] to the area along its way (0 inside, +inf: none): for predictions beyond constant velocity."""

ZONE_SIGNALS = ("d_zone", "d_zone_out", "t_zone", "t_zone_out")
"""The ego's signals of its next conflict area (in :data:`twolevel.world.provided.SIGNALS`)."""

ZONE_PARTICIPANT_SIGNALS = ("t_reach", "t_clear", "priority", "d_exit")
"""The participant signals of the ego's next conflict area."""


@dataclass(frozen=True, eq=False)
class RouteZones:
    """The conflicts along the ego's route, one row per (conflict, lane o may come along): the
    ego's ``area`` index (A areas: ``area_s0``/``area_s1`` (A,) route s [m] of entry and exit),
    the ``lane`` o is on (the conflicting connecting lane or its incoming lane), ``enter`` /
    ``leave`` [m]: the zone's start and end in that lane's coordinates (beyond its end for an
    incoming lane), ``first`` (1: o goes first, 0: the ego, −1: no fixed order) and ``light``
    (index of the light on o's incoming lane, −1: none)."""

    area_s0: np.ndarray
    area_s1: np.ndarray
    area: np.ndarray
    exit: np.ndarray
    lane: np.ndarray
    enter: np.ndarray
    leave: np.ndarray
    first: np.ndarray
    light: np.ndarray

    @classmethod
    def none(cls) -> "RouteZones":
        f, i = np.zeros(0), np.zeros(0, dtype=int)
        return cls(f, f, i, f, i, f, f, i, i)


def route_zones(world: object) -> RouteZones:
    """The :class:`RouteZones` of ``world`` (a :class:`~twolevel.world.world.World`)."""
    jn, route, lanes = world.junctions, world.route, world.lanes  # type: ignore[attr-defined]
    rows: list[tuple[int, float, int, float, float, int, int]] = []
    s0s, s1s = [], []
    for lane, a, b, start in route.pieces:
        xs, side = np.nonzero(jn.conflict_lane == int(lane))  # the conflicts of this lane, its side in each
        if not len(xs):
            continue
        ez0 = start + jn.conflict_s0[xs, side] - a
        ez1 = start + jn.conflict_s1[xs, side] - a
        k = len(s0s)
        s0s.append(float(ez0.min()))
        s1s.append(float(ez1.max()))
        for x, sd, out in zip(xs.tolist(), side.tolist(), ez1.tolist()):
            other = int(jn.conflict_lane[x, 1 - sd])
            first = int(jn.conflict_first[x])
            mine = -1 if first < 0 else int(first == 1 - sd)
            c = int(np.flatnonzero(jn.conn_lane == other)[0])
            inc = int(jn.conn_from[c])
            lit = np.flatnonzero(world.lights.lane == inc)  # type: ignore[attr-defined]
            light = int(lit[0]) if len(lit) else -1
            z0, z1 = float(jn.conflict_s0[x, 1 - sd]), float(jn.conflict_s1[x, 1 - sd])
            rows.append((k, out, other, z0, z1, mine, light))
            if jn.conflict_kind[x] == MERGING and jn.conn_turn[c] != STRAIGHT:
                continue  # a turn into the ego's way counts once it is under way (see the module docstring)
            extra = float(lanes.length[inc])
            rows.append((k, out, inc, z0 + extra, z1 + extra, mine, light))
    if not rows:
        return RouteZones.none()
    r = np.array(rows, dtype=float)
    return RouteZones(np.array(s0s), np.array(s1s), r[:, 0].astype(int), r[:, 1], r[:, 2].astype(int), r[:, 3], r[:, 4],
                      r[:, 5].astype(int), r[:, 6].astype(int))


def next_area(z: RouteZones, s: np.ndarray, length: float, r_near: float) -> np.ndarray:
    """Index of the next area (−1: none) for route positions ``s`` (...) [m] of the ego's centre."""
    if not len(z.area_s0):
        return np.full(np.shape(s), -1)
    s = np.asarray(s, dtype=float)[..., None]
    ok = (z.area_s1 - (s - length / 2) > 0) & (z.area_s0 - (s + length / 2) <= r_near)
    first = np.argmax(ok, axis=-1)
    return np.where(ok.any(axis=-1), first, -1)


def zone_signals(world: object, s: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
    """``d_zone``, ``d_zone_out``, ``t_zone``, ``t_zone_out`` at route positions ``s`` [m] and
    speeds ``v`` [m/s] of the ego (any shape)."""
    z: RouteZones = world.zones  # type: ignore[attr-defined]
    L = float(world.ego.length)  # type: ignore[attr-defined]
    s, v = np.asarray(s, dtype=float), np.asarray(v, dtype=float)
    k = next_area(z, s, L, world.settings.r_near)  # type: ignore[attr-defined]
    has = k >= 0
    kk = np.maximum(k, 0)
    a0 = z.area_s0[kk] if len(z.area_s0) else np.zeros(k.shape)
    a1 = z.area_s1[kk] if len(z.area_s1) else np.zeros(k.shape)
    d_in = np.where(has, a0 - (s + L / 2), np.inf)
    d_out = np.where(has, a1 - (s - L / 2), -np.inf)
    moving = v > STANDING
    vv = np.where(moving, v, 1.0)
    with np.errstate(invalid="ignore"):
        t_in = np.where(d_in <= 0, 0.0, np.where(moving, np.maximum(d_in, 0.0) / vv, np.inf))
        t_out = np.where(~has | (d_out <= 0), 0.0, np.where(moving, np.maximum(d_out, 0.0) / vv, np.inf))
    return {"d_zone": d_in, "d_zone_out": d_out, "t_zone": np.where(has, t_in, np.inf), "t_zone_out": t_out}


def participant_zone_signals(world: object, s: np.ndarray, t: np.ndarray, other: Mapping[str, np.ndarray],
                             length: np.ndarray, near: np.ndarray) -> dict[str, np.ndarray]:
    """``t_reach``, ``t_clear``, ``priority``, ``d_exit`` of n participants (..., n) for an ego at route
    positions ``s`` (...) [m] at times ``t`` (...) [s]. ``other``: ``x``, ``y`` [m], ``psi``
    [rad], ``v`` [m/s], each (..., n); ``length`` (n,) [m]; ``near`` (..., n): where each is
    present. Also returns :data:`REACH_DISTANCE` (not a signal)."""
    z: RouteZones = world.zones  # type: ignore[attr-defined]
    lanes = world.lanes  # type: ignore[attr-defined]
    shape = np.broadcast_shapes(np.shape(other["x"]), np.shape(near))
    out = {"t_reach": np.full(shape, np.inf), "t_clear": np.zeros(shape), "priority": np.zeros(shape),
           "d_exit": np.full(shape, -np.inf), REACH_DISTANCE: np.full(shape, np.inf)}
    if not len(z.area) or not np.any(near):
        return out
    k = np.broadcast_to(np.asarray(next_area(z, s, float(world.ego.length),  # type: ignore[attr-defined]
                                            world.settings.r_near))[..., None], shape)  # type: ignore[attr-defined]
    used = np.unique(k[near & (k >= 0)])
    if not len(used):
        return out
    # each participant sample once (K candidate trajectories share the others' predictions), on
    # every lane a participant may come along to the areas in use
    t_col = np.asarray(t, dtype=float)[..., None]
    own = np.broadcast_shapes(*(np.shape(other[f]) for f in ("x", "y", "psi", "v")), t_col.shape, np.shape(length))
    x, y, psi, v, tt, L = (np.broadcast_to(a, own).ravel() for a in (other["x"], other["y"], other["psi"], other["v"],
                                                                     t_col, np.asarray(length, dtype=float)))
    rows = np.flatnonzero(np.isin(z.area, used))
    p = np.repeat(np.arange(len(x)), len(rows))
    r = np.tile(rows, len(x))
    lane = z.lane[r]
    s_o, lat = lanes.project(lane, np.stack([x[p], y[p]], axis=1))
    s_in = np.clip(s_o, 0.0, lanes.length[lane])
    on = ((np.abs(lat) <= 0.5 * lanes.width_at(lane, s_in)) & (s_o >= -L[p] / 2)
          & (s_o <= lanes.length[lane] + L[p] / 2) & same_way(psi[p], lanes.pose(lane, s_in)[1]))
    d_in = z.enter[r] - (s_o + L[p] / 2)
    d_out = z.leave[r] - (s_o - L[p] / 2)
    moving = v[p] > STANDING
    vv = np.where(moving, v[p], 1.0)
    valid = on & (d_out > 0)
    reach = np.where(~valid, np.inf, np.where(d_in <= 0, 0.0, np.where(moving, d_in / vv, np.inf)))
    clear = np.where(~valid, 0.0, np.where(moving, d_out / vv, np.inf))
    light = z.light[r]
    red = np.zeros(len(r), dtype=bool)
    if (light >= 0).any():
        states = world.lights.state_at(tt[p])  # type: ignore[attr-defined]
        red = (light >= 0) & (np.take_along_axis(states, np.maximum(light, 0)[:, None], axis=1)[:, 0] == RED)
    prio = np.where(~valid | red, 0.0, np.where(z.first[r] < 0, 1.0, z.first[r].astype(float)))
    exit_ = np.where(valid, z.exit[r], -np.inf)
    dist = np.where(valid, np.maximum(d_in, 0.0), np.inf)
    # per (participant sample, area): the earliest reach, the latest clearing, any priority
    A = len(z.area_s0)
    col = p * A + z.area[r]
    tables = {}
    for name, val, init, red_op in (("t_reach", reach, np.inf, np.minimum), ("t_clear", clear, 0.0, np.maximum),
                                    ("priority", prio, 0.0, np.maximum), ("d_exit", exit_, -np.inf, np.maximum),
                                    (REACH_DISTANCE, dist, np.inf, np.minimum)):
        tab = np.full(len(x) * A, init)
        red_op.at(tab, col, val)
        tables[name] = tab
    idx = np.broadcast_to(np.arange(len(x)).reshape(own), shape) * A + np.maximum(k, 0)
    here = near & (k >= 0)
    rear = np.asarray(s, dtype=float)[..., None] - float(world.ego.length) / 2  # type: ignore[attr-defined]
    for name, tab in tables.items():
        got = tab[idx] - (rear if name == "d_exit" else 0.0)
        out[name] = np.where(here, got, out[name])
    return out
