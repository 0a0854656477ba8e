"""The drivable area along a route: at each route position, the lateral interval the ego may use.

At route position s the route runs along lane i at s_i (its ``pieces``). From there the area
reaches sideways lane by lane, across the lane set's adjacency (the lane beside, level with s_i:
:meth:`~twolevel.world.geometry.LaneSet.beside`), for as long as

* the boundary crossed may be crossed from the lane it is crossed from (its marking as that lane
  sees it: none, dashed, dashed_solid — :data:`~twolevel.world.geometry.CROSSABLE`);
* the lane reached is ``usable`` (driving lanes; a shoulder, parking or bus lane only where the
  map declares it usable; never a sidewalk unless declared);
* it runs the way the route does — or, with ``oncoming`` allowed, it is the first lane running the
  other way and s_i is outside the no-overtaking zones of lane i (nothing beyond an oncoming lane
  is added).

The offsets add up the lanes' widths at their level positions (adjacent lanes share a boundary),
measured from the route lane's centre line, which the route follows: + left, [m].
:func:`drivable_area` returns three nested intervals (:class:`Area`): the route lane's own edges,
with the same-direction lanes one may change into, and with the oncoming lane where passing is
allowed. Vectorised over route positions; the loop runs over lanes sideways (at most
``max_lanes`` each way). This is what the MPC's lateral band and the verdict's ``on_road:
{boundary: area}`` read.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twolevel.world.geometry import LaneSet, Route, step_index

__all__ = ["Area", "drivable_area", "route_lanes_at"]


@dataclass(frozen=True, eq=False)
class Area:
    """The drivable area at route positions ``s`` (N,) [m]: lateral bounds [m] (+ left of the
    route) of the route's lane (``lane_lo`` / ``lane_hi``), with the lanes running the same way one
    may change into (``same_lo`` / ``same_hi``), and with the oncoming lane where passing over it
    is allowed (``lo`` / ``hi``); ``oncoming`` (N,): whether ``lo`` / ``hi`` take in an oncoming
    lane; ``lane`` (N,) and ``s_lane`` (N,) [m]: the route's lane there and s on it."""

    s: np.ndarray
    lane: np.ndarray
    s_lane: np.ndarray
    lane_lo: np.ndarray
    lane_hi: np.ndarray
    same_lo: np.ndarray
    same_hi: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    oncoming: np.ndarray


def route_lanes_at(route: Route, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lane (N,) the route runs along at route positions ``s`` (N,) [m], and s on it [m]."""
    s = np.asarray(s, dtype=float)
    pieces = np.array([p[:4] for p in route.pieces], dtype=float).reshape(-1, 4)
    k = step_index(pieces[:, 3], s)
    return pieces[k, 0].astype(int), pieces[k, 1] + s - pieces[k, 3]


def drivable_area(lanes: LaneSet, route: Route, s: np.ndarray, *, oncoming: bool = True, max_lanes: int = 4) -> Area:
    """The drivable area at route positions ``s`` (N,) [m] (see the module docstring); ``oncoming``:
    whether passing over the oncoming lane is allowed at all (where markings and zones allow it)."""
    s = np.asarray(s, dtype=float).reshape(-1)
    lane, s_lane = route_lanes_at(route, s)
    half = 0.5 * lanes.width_at(lane, s_lane)
    passing = oncoming & ~lanes.no_overtaking.contains(lane, s_lane)
    out: dict[str, np.ndarray] = {}
    for sign, name in ((1.0, "hi"), (-1.0, "lo")):
        cur, cur_s = lane.copy(), s_lane.copy()
        flip = np.zeros(len(s), dtype=bool)  # the current lane runs against the route
        alive = np.ones(len(s), dtype=bool)
        edge = half.copy()
        same, full = edge.copy(), edge.copy()
        crossed = np.zeros(len(s), dtype=bool)
        for _ in range(max_lanes):
            if not alive.any():
                break
            left = (sign > 0) != flip  # the side of the current lane facing away from the route
            may = lanes.markings.crossable(cur, cur_s, left)
            nb, nb_s = lanes.beside(cur, cur_s, left)
            found = nb >= 0
            nbi = np.maximum(nb, 0)
            same_way = np.where(left, lanes.adj_left_same[cur], lanes.adj_right_same[cur])
            against = flip ^ ~same_way  # the lane reached runs against the route
            ok = alive & may & found & lanes.usable[nbi] & (~against | passing)
            edge = np.where(ok, edge + lanes.width_at(nbi, np.where(found, nb_s, 0.0)), edge)
            same = np.where(ok & ~against & ~crossed, edge, same)
            full = np.where(ok, edge, full)
            crossed |= ok & against
            alive = ok & ~against
            cur, cur_s, flip = np.where(ok, nbi, cur), np.where(ok, nb_s, cur_s), np.where(ok, against, flip)
        out[f"same_{name}"], out[name] = sign * same, sign * full
        out[f"crossed_{name}"] = crossed
    return Area(s, lane, s_lane, -half, half, out["same_lo"], out["same_hi"], out["lo"], out["hi"],
                out["crossed_lo"] | out["crossed_hi"])
