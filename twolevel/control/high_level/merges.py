"""Merging where the ego's lane ends into a lane that others lead into too: where the ego waits for a gap.

At a merge with no sign (an on-ramp that joins the main road, a lane that ends, StVO § 7(4))
the cars take turns, and other traffic lets the ego in (:mod:`twolevel.world.traffic.ego`); but
the safety layer verifies only what is safe whatever the others lawfully do — a car coming up
the other lane may still accelerate, up to its bound of the world's assumptions —, so a car that
arrives at the lanes' meeting beside the ego is met by the fail-safe's full braking. This is the
MPC's reference seeing that coming: it waits before the merge, as at a give-way line, while a
car on the other lane could arrive first, so the ego slows at comfort instead.

Definitions, from what the ego senses now:

* a *merge* on the route is where the route runs from lane a into lane b and b has other
  predecessors (its *feeders*), none of them in a junction (at a junction right of way decides,
  :mod:`twolevel.control.high_level.right_of_way`); its route position ``s_m`` [m] is where b
  begins, and its *line* is the route position of the ego's centre
  :data:`~twolevel.control.high_level.right_of_way.RUN_UP` before its box (centred on the route,
  turned with it) first comes within D_safe of a feeder's lane;
* it *applies* while it is ahead of the ego within the sensing range, for the vehicles on its
  feeders within the sensing range;
* the ego *waits* (:func:`merge_line`) while one of them could, at its earliest under the world's
  assumptions (:func:`twolevel.safety.occupancy.reach_bounds`, the verifier's and the right-of-way
  gap acceptance's model), reach where the ego's box meets its lane before the ego, clearing at
  :data:`~twolevel.control.high_level.right_of_way.CLEAR_ACCEL` from its speed now, has its rear
  past ``s_m``.

Units: m, m/s, s.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from twolevel.control.high_level.right_of_way import CLEAR_ACCEL, RUN_UP
from twolevel.safety.network import network_of
from twolevel.safety.occupancy import reach_bounds, time_to_travel
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["RouteMerges", "route_merges", "merge_line"]


@dataclass(frozen=True, eq=False)
class RouteMerges:
    """The M merges on a route: ``s`` (M,) [m] their route positions and ``line`` (M,) [m] their
    lines (the module docstring); per feeder (F,) its ``lane`` index, ``length`` [m], ``enter``
    [m] (where on it the ego's box first comes within D_safe) and ``merge`` (its merge's index)."""

    s: np.ndarray
    line: np.ndarray
    lane: np.ndarray
    length: np.ndarray
    enter: np.ndarray
    merge: np.ndarray


_MERGES: "weakref.WeakKeyDictionary[World, RouteMerges]" = weakref.WeakKeyDictionary()
_APPROACH = 150.0
"""[m] How far before a merge point the route is searched for where the ego's body reaches a feeder."""


def _first_contact(world: World, s_m: float, feeder: int) -> tuple[float, float]:
    """(route position of the ego's centre, s on ``feeder`` [m]) where the ego's box, centred on
    the route before ``s_m`` [m] and turned with it, first has a corner on ``feeder``'s lane or
    within the world's D_safe of it (``s_m`` and the feeder's end when it never does before)."""
    route, ls, ego = world.route, world.lanes, world.ego
    s = route.s[(route.s >= s_m - _APPROACH) & (route.s <= s_m)]
    xy, h = route.position(s), route.heading_at(s)
    c, n = np.stack([np.cos(h), np.sin(h)], axis=1), np.stack([-np.sin(h), np.cos(h)], axis=1)
    corners = np.concatenate([xy + a * ego.length / 2 * c + b * ego.width / 2 * n
                              for a in (1, -1) for b in (1, -1)])  # (4K, 2), corner-major
    f_s, f_lat = ls.project(np.full(len(corners), feeder), corners)
    reach = ls.width[feeder] / 2 + world.settings.D_safe
    inside = ((np.abs(f_lat) < reach) & (f_s >= 0) & (f_s <= ls.length[feeder])).reshape(4, -1)
    hit = inside.any(axis=0)
    if not hit.any():
        return s_m, float(ls.length[feeder])
    k = int(np.argmax(hit))
    return float(s[k]), float(f_s.reshape(4, -1)[inside[:, k], k].min())


def route_merges(world: World) -> RouteMerges:
    """The merges on ``world``'s route (computed once per world)."""
    if world in _MERGES:
        return _MERGES[world]
    ls, pieces = world.lanes, world.route.pieces
    s_m, line, lanes, lengths, enter, merge = [], [], [], [], [], []
    for (a, *_), (b, _, _, start) in zip(pieces, pieces[1:]):
        feeders = sorted({int(p) for p in ls.pred[ls.pred_ptr[b]:ls.pred_ptr[b + 1]]} - {int(a)})
        if not feeders or any(ls.junction[k] >= 0 for k in [a, b, *feeders]):
            continue
        contacts = [_first_contact(world, float(start), f) for f in feeders]
        s_m.append(float(start))
        line.append(min(c[0] for c in contacts) - RUN_UP)
        lanes += feeders
        lengths += [float(ls.length[f]) for f in feeders]
        enter += [c[1] for c in contacts]
        merge += [len(s_m) - 1] * len(feeders)
    arr = lambda v, t=float: np.array(v, dtype=t)  # noqa: E731
    out = RouteMerges(arr(s_m), arr(line), arr(lanes, int), arr(lengths), arr(enter), arr(merge, int))
    _MERGES[world] = out
    return out


def _next(world: World, traffic: TrafficState, xy: tuple[float, float], s0: float
          ) -> tuple[RouteMerges, int, np.ndarray, np.ndarray] | None:
    """The next merge, when it is ahead within the sensing range of the ego at ``xy`` [m], route
    position ``s0`` [m], the feeder vehicles sensed (participant indices) and each one's row
    among the route's feeders; None where there is none or nobody is on its feeders."""
    rm = route_merges(world)
    ahead = (rm.s > s0) & (rm.s - s0 <= world.settings.sensor_range)
    if not ahead.any():
        return None
    k = int(np.flatnonzero(ahead)[0])
    rows = np.flatnonzero(rm.merge == k)
    on = traffic.active & np.isin(traffic.lane, rm.lane[rows])
    on &= np.hypot(traffic.x - xy[0], traffic.y - xy[1]) <= world.settings.sensor_range
    idx = np.flatnonzero(on)
    if not len(idx):
        return None
    return rm, k, idx, rows[np.searchsorted(rm.lane[rows], traffic.lane[idx])]


def merge_line(world: World, traffic: TrafficState, xy: tuple[float, float], s0: float, v0: float) -> float:
    """[m] Where the ego's centre must be able to stop while it waits at the next merge (the
    module docstring): the merge's line; once it has crept past that line, where it can stop at
    the comfort deceleration from ``v0`` [m/s]; +inf when it need not wait, or when its box is at
    the feeder (it has committed: the safety layer's to judge). The ego is at ``xy`` [m], route
    position ``s0`` [m]."""
    got = _next(world, traffic, xy, s0)
    if got is None:
        return math.inf
    rm, k, idx, rows = got
    if s0 >= rm.line[k] + RUN_UP:  # its body is at the feeder: committed (the safety layer's to judge)
        return math.inf
    front = traffic.s[idx] + 0.5 * world.parts.length[idx]
    reach = reach_bounds(network_of(world), traffic, idx, world.assumptions, world.parts.user)
    worst = reach.earliest(np.maximum(rm.enter[rows] - front, 0.0))
    n = len(idx)
    clear = time_to_travel(np.full(n, max(v0, 0.0)), np.full(n, np.inf), np.full(n, CLEAR_ACCEL), np.full(n, np.inf),
                           np.full(n, rm.s[k] + 0.5 * world.ego.length - s0))
    if not np.any(worst < clear):
        return math.inf
    if s0 < rm.line[k]:
        return float(rm.line[k])
    return s0 + v0 * v0 / (2.0 * world.settings.comfort.decel)  # crept past it: stop at comfort
