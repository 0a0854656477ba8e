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

__all__ = ["Area", "CentreLine", "drivable_area", "route_lanes_at", "centre_line", "overtaking_signals"]


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


@dataclass(frozen=True, eq=False)
class CentreLine:
    """The boundary between the lanes running the route's way and the first lane running against
    it, left of the route, at route positions ``s`` (N,) [m]: its ``offset`` (N,) [m] from the route
    lane's centre line (+ left; +inf where no oncoming lane lies to the left), whether it is
    ``solid`` (N,) there (its marking may not be crossed from the ego's side:
    :data:`~twolevel.world.geometry.CROSSABLE`; false without an oncoming lane) and whether the
    route lane is in a ``no_overtaking`` zone (N,) there."""

    offset: np.ndarray
    solid: np.ndarray
    no_overtaking: np.ndarray


def centre_line(lanes: LaneSet, route: Route, s: np.ndarray, *, max_lanes: int = 4) -> CentreLine:
    """The centre line left of the route at route positions ``s`` (N,) [m] (:class:`CentreLine`):
    walks left from the route lane across lanes beside it that run the same way (whatever their
    markings), adding up their widths, to the first one running against it."""
    s = np.asarray(s, dtype=float).reshape(-1)
    lane, s_lane = route_lanes_at(route, s)
    cur, cur_s = lane.copy(), s_lane.copy()
    offset = 0.5 * lanes.width_at(lane, s_lane)
    found_at = np.full(len(s), np.inf)
    solid = np.zeros(len(s), dtype=bool)
    alive = np.ones(len(s), dtype=bool)
    for _ in range(max_lanes):
        nb, nb_s = lanes.beside(cur, cur_s, True)
        here = alive & (nb >= 0)
        against = here & ~lanes.adj_left_same[cur]
        found_at = np.where(against, offset, found_at)
        solid = np.where(against, ~lanes.markings.crossable(cur, cur_s, True), solid)
        alive = here & ~against
        if not alive.any():  # every position has found its line or run out of lanes: no width to add
            break
        nbi = np.maximum(nb, 0)
        offset = np.where(alive, offset + lanes.width_at(nbi, np.where(alive, nb_s, 0.0)), offset)
        cur, cur_s = np.where(alive, nbi, cur), np.where(alive, nb_s, cur_s)
    return CentreLine(found_at, solid, lanes.no_overtaking.contains(lane, s_lane))


def overtaking_signals(lanes: LaneSet, route: Route, s: np.ndarray, e: np.ndarray | float, width: float
                       ) -> dict[str, np.ndarray]:
    """The signals ``over_centre`` [m], ``solid_left`` and ``no_overtaking`` (1/0) of an ego of
    ``width`` [m] at route coordinates ``s``, ``e`` [m] (any shape, broadcast; the shape kept):
    :mod:`twolevel.world.provided`. ``over_centre`` = e + width/2 − the centre line's offset: the
    body's half-width taken across the route (its heading relative to the route left out: affine
    in e, as the MPC encodes it)."""
    s, e = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(e, dtype=float))
    line = centre_line(lanes, route, np.clip(s, 0.0, route.length).ravel())
    return {"over_centre": (e.ravel() + 0.5 * width - line.offset).reshape(s.shape),
            "solid_left": line.solid.astype(float).reshape(s.shape),
            "no_overtaking": line.no_overtaking.astype(float).reshape(s.shape)}
