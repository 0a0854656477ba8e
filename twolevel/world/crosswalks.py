"""Marked crosswalks on the route and the signals ``xwalk_busy`` and ``d_xwalk`` they give.

A *crosswalk on the route* is a pedestrian's walk with ``crosswalk: true``
(:mod:`twolevel.world.traffic.pedestrians`) whose path crosses a lane of the ego's route: its
route position ``s`` [m] (where the path meets the route's lane), the ego's *line* there (the
route position of the ego's reference point when its front stands
:data:`~twolevel.world.traffic.pedestrians.STOP_SHORT` before the crossing's centre, where other
traffic stops: s − STOP_SHORT − L_ego/2), and the distances walked along the path where it
enters and leaves that lane [m].

Definitions, per sample, from what the ego sees (positions only: its route position s [m] and
speed v [m/s], each pedestrian's position; a pedestrian is *present* while active and within
``r_near`` of the ego):

* a crosswalk *applies* while −PASS_MARGIN ≤ d ≤ r_near, d = line − s (so passing its line while
  it is busy is seen as a negative distance);
* its pedestrian is *at the ego's lane* when it has walked more than :data:`STEPPED` from where it
  waited and is within ``ENTERING`` of the lane's edge or on it, and *not yet past* the ego's lane
  while it has walked at most :data:`PAST` beyond the lane's far edge (as other traffic judges it,
  :func:`~twolevel.world.traffic.pedestrians.crossing_lines`);
* it is *busy* when it applies and its present pedestrian, not yet past the ego's lane, is at the
  ego's lane — or is waiting at the kerb or walking towards the ego's lane over the others, and
  the ego can still stop before the line at :data:`YIELD_DECEL` (d ≥ v²/(2·YIELD_DECEL)). A driver
  who sees someone waiting at a zebra too late to stop comfortably passes (the pedestrian, who
  waits for a gap, is not endangered: the dilemma of a yellow light); one whose lane the
  pedestrian is stepping onto or walking on stops whatever it takes (the rule then shows what
  could not be kept). A pedestrian standing at a zebra's kerb counts as waiting to cross (a driver
  cannot tell otherwise).

``xwalk_busy`` is 1 while some crosswalk is busy, else 0; ``d_xwalk`` [m] is the distance to the
line of the nearest busy crosswalk, else of the nearest one that applies (+inf if none). Units: m,
m/s, m/s².
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twolevel.world.traffic.pedestrians import ENTERING, STOP_SHORT

__all__ = ["STEPPED", "PAST", "YIELD_DECEL", "RouteCrosswalks", "route_crosswalks", "crosswalk_signals", "positions_of"]

STEPPED = 0.05
"""[m] A pedestrian who has walked further than this from where it waited has stepped out."""
PAST = 0.5
"""[m] How far beyond the far edge of the ego's lane a pedestrian has walked when it is past it."""
YIELD_DECEL = 4.0
"""[m/s²] A pedestrian waiting at a crosswalk binds the ego while it can still stop before the line
at this deceleration. Above the deceleration the planners stop at (``stop_decel``, 3 m/s² by
default): at the same value a stop begun at the last moment turned, with the braking's lag, into
"cannot stop" after a second (measured on scenarios/traffic/zebra.yaml: 13.9 → 12.7 m/s, then on
over the crossing), and the ego drove past the waiting pedestrian."""


@dataclass(frozen=True, eq=False)
class RouteCrosswalks:
    """The C crosswalks on the route: ``owner`` (C,) participant index of the pedestrian, ``s``
    (C,) [m] route position of the crossing, ``line`` (C,) [m] the ego's line before it, ``enter``/
    ``leave`` (C,) [m] walked distance where the path enters and leaves the route's lane,
    ``origin`` (C, 2) [m] and ``direction`` (C, 2) of the path."""

    owner: np.ndarray
    s: np.ndarray
    line: np.ndarray
    enter: np.ndarray
    leave: np.ndarray
    origin: np.ndarray
    direction: np.ndarray

    @property
    def n(self) -> int:
        return len(self.owner)


def route_crosswalks(world: object) -> RouteCrosswalks:
    """The crosswalks on ``world``'s route (a :class:`~twolevel.world.world.World`, which builds
    them: not imported here), in order of their route position."""
    walks, route, L = world.parts.walks, world.route, world.ego.length  # type: ignore[attr-defined]
    rows = np.flatnonzero(walks.crosswalk[walks.row_owner]) if len(walks.row_owner) else np.zeros(0, int)
    s = route.from_lane(walks.row_lane[rows], walks.row_s[rows])
    rows, s = rows[~np.isnan(s)], s[~np.isnan(s)]
    order = np.argsort(s, kind="stable")
    rows, s = rows[order], s[order]
    owner = walks.row_owner[rows]
    h = walks.heading[owner]
    return RouteCrosswalks(owner, s, s - STOP_SHORT - L / 2,
                           walks.row_enter[rows], walks.row_leave[rows], walks.origin[owner].reshape(-1, 2),
                           np.stack([np.cos(h), np.sin(h)], axis=-1).reshape(-1, 2))


def positions_of(cw: RouteCrosswalks, index: np.ndarray, x: np.ndarray, y: np.ndarray, present: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Each crosswalk's pedestrian among participants ``index`` (n,) whose positions ``x``, ``y``
    and presence ``present`` are (..., n): its position (..., C, 2) [m] and presence (..., C)
    (absent where it is not among them)."""
    if x.shape[-1] == 0:
        lead = x.shape[:-1]
        return np.zeros(lead + (cw.n, 2)), np.zeros(lead + (cw.n,), dtype=bool)
    match = cw.owner[:, None] == np.asarray(index)[None, :]  # (C, n)
    j = match.argmax(axis=1)
    return np.stack([x[..., j], y[..., j]], axis=-1), present[..., j] & match.any(axis=1)


def crosswalk_signals(cw: RouteCrosswalks, s: np.ndarray, v: np.ndarray, xy: np.ndarray, present: np.ndarray, *,
                      r_near: float, decel: float, pass_margin: float) -> tuple[np.ndarray, np.ndarray]:
    """``xwalk_busy`` (1/0) and ``d_xwalk`` [m] (see the module docstring) for an ego at route
    positions ``s`` [m] with speeds ``v`` [m/s] (any shape S), its crosswalks' pedestrians at
    ``xy`` (S + (C, 2)) [m], ``present`` (S + (C,)); ``r_near`` [m]; ``decel`` [m/s²]: the
    deceleration that decides whether a waiting pedestrian binds (:data:`YIELD_DECEL`);
    ``pass_margin`` [m]: how far past its line a crosswalk still applies
    (:data:`twolevel.world.signals.PASS_MARGIN`)."""
    s = np.asarray(s, dtype=float)
    shape = s.shape
    if cw.n == 0:
        return np.zeros(shape), np.full(shape, np.inf)
    d = cw.line - s[..., None]  # (S, C)
    applies = (d >= -pass_margin) & (d <= r_near)
    walked = np.einsum("...ck,ck->...c", xy - cw.origin, cw.direction)
    ahead = walked <= cw.leave + PAST
    at_lane = (walked > STEPPED) & (walked >= cw.enter - ENTERING)
    can_stop = d >= np.asarray(v, dtype=float)[..., None] ** 2 / (2.0 * decel)
    busy = applies & present & ahead & (at_lane | can_stop)
    any_busy = busy.any(axis=-1)
    d_busy = np.where(busy, d, np.inf).min(axis=-1)
    d_near = np.where(applies, d, np.inf).min(axis=-1)
    return any_busy.astype(float), np.where(any_busy, d_busy, d_near)
