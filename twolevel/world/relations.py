"""Relations between the ego and each other participant: the participant signals, vectorised.

The definitions (units, absent values, the route frame and the lane bands) are stated once in
:mod:`twolevel.world.provided`; :func:`relations` computes them for arrays of any shape with the
participants on the last axis — (T, N) along a recorded trajectory
(:func:`twolevel.world.signals.participant_signals_along`, the reference) or (K, T, n) over K
candidate trajectories (:func:`twolevel.world.sensing.sense`) — so both faces share one piece of
code. ``a(o)`` needs the previous sample and is :func:`acceleration`'s.

The correspondence with CommonRoad's predicates (Maierhofer et al. 2020, commonroad-stl-monitor),
each in metres and unscaled: ``d_lon(o) > 0`` is ``in_front_of(ego, o)``, ``in_same_lane(o)`` is
``in_same_lane(ego, o)`` (lanes as bands of the route lane's width), ``cut_in(o)`` is
``cut_in(o, ego)`` with the lateral motion towards the ego over one second instead of the heading,
``precedes(o)`` is the meta-predicate ``precedes(ego, o)``; ``left_of(o) > 0`` with
``d_lon(o) ≤ 0`` and ``d_behind(o) ≤ 0`` is ``left_of(o, ego)`` (o beside the ego, wholly to its
left), running the route's way.
"""

from __future__ import annotations

from typing import Iterable, Mapping, Sequence

import numpy as np

from twolevel.stl.analysis import PRESENT, participant_signals_read, quantifies
from twolevel.world.geometry import Route
from twolevel.world.provided import PARTICIPANT_ABSENT, PARTICIPANT_SIGNALS

__all__ = ["LEAD_HEADING", "same_way", "LOOK_AHEAD", "relations", "acceleration", "signals_read_by", "absent_sample", "extents", "lanes_occupied"]

LEAD_HEADING = np.pi / 4
"""[rad] Largest heading difference from the route at which another vehicle still travels the same
way (a leader, a follower): a lane change or a bend is well within it, a crossing is not."""


def same_way(psi: np.ndarray | float, heading: np.ndarray | float) -> np.ndarray:
    """Whether vehicles heading ``psi`` [rad] travel the way ``heading`` [rad] points: the
    difference within :data:`LEAD_HEADING` (cos 90° is 6e−17, not 0: a sign test lets a crossing
    vehicle through)."""
    return np.cos(np.asarray(psi) - np.asarray(heading)) >= np.cos(LEAD_HEADING)


LOOK_AHEAD = 1.0
"""[s] How far ahead ``cut_in`` looks at a participant's lateral motion towards the ego."""


def extents(theta: np.ndarray, length: np.ndarray | float, width: np.ndarray | float
            ) -> tuple[np.ndarray, np.ndarray]:
    """Half-extents of a box along and across the route [m] at relative heading ``theta`` [rad]."""
    c, s = np.abs(np.cos(theta)), np.abs(np.sin(theta))
    return 0.5 * (length * c + width * s), 0.5 * (length * s + width * c)


def lanes_occupied(lo: np.ndarray, hi: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lateral interval [m] covered by the lane bands (width ``w`` [m], band j: |e − j·w| ≤
    w/2) that a body spanning [lo, hi] overlaps."""
    first = np.floor(lo / w - 0.5) + 1.0
    last = np.ceil(hi / w + 0.5) - 1.0
    return (first - 0.5) * w, (last + 0.5) * w


def _depth(lo: np.ndarray, hi: np.ndarray, u_lo: np.ndarray, u_hi: np.ndarray) -> np.ndarray:
    """How far [lo, hi] reaches into [u_lo, u_hi] (> 0), or the gap between them (< 0) [m]."""
    return np.minimum(hi - u_lo, u_hi - lo)


def _relative(route: Route, s: np.ndarray, psi: np.ndarray) -> np.ndarray:
    d = np.asarray(psi, dtype=float) - route.heading_at(np.asarray(s, dtype=float))
    return np.arctan2(np.sin(d), np.cos(d))


def relations(route: Route, ego: Mapping[str, np.ndarray], ego_box: tuple[float, float],
              other: Mapping[str, np.ndarray], length: np.ndarray, width: np.ndarray,
              near: np.ndarray) -> dict[str, np.ndarray]:
    """Every participant signal but ``a`` (and ``present``) of n others relative to the ego.

    ``ego``: route coordinates ``s``, ``e`` [m], heading ``psi`` [rad], shaped (..., 1);
    ``ego_box`` its (length, width) [m]. ``other``: ``s``, ``e`` [m], ``psi`` [rad], speed ``v``
    [m/s], shaped (..., n), and their boxes ``length``/``width`` (n,) [m]. ``near`` (..., n): where
    each is present; elsewhere its signals take their absent values. Returns (..., n) arrays."""
    s, e = ego["s"], ego["e"]
    so, eo, vo = other["s"], other["e"], other["v"]
    th = _relative(route, s, ego["psi"])
    tho = _relative(route, so, other["psi"])
    l, h = extents(th, *ego_box)
    lo_, ho = extents(tho, length, width)
    out: dict[str, np.ndarray] = {"v": vo * np.cos(tho), "d_lon": (so - lo_) - (s + l), "d_lat": eo - e}
    w, wo = route.width_at(s), route.width_at(so)
    ue = lanes_occupied(e - h, e + h, w)
    uo = lanes_occupied(eo - ho, eo + ho, wo)
    same = np.minimum(_depth(eo - ho, eo + ho, *ue), _depth(e - h, e + h, *uo))
    out["in_same_lane"] = same
    boundary = (np.round(eo / wo - 0.5) + 0.5) * wo
    crossing = np.minimum(eo + ho - boundary, boundary - (eo - ho))
    lateral = vo * np.sin(tho) * LOOK_AHEAD
    d_lat = out["d_lat"]
    toward = np.maximum(np.minimum(-d_lat, lateral), np.minimum(d_lat, -lateral))
    out["cut_in"] = np.minimum(np.minimum(same, crossing), toward)
    # precedes: nobody q in the ego's lane ahead of it is in front of o's rear
    rear, front = so - lo_, so + lo_
    between = np.maximum(np.maximum(-same, -out["d_lon"])[..., None, :], front[..., None, :] - rear[..., :, None])
    n = near.shape[-1]
    others_near = np.broadcast_to(near[..., None, :], between.shape) & ~np.eye(n, dtype=bool)
    free = np.where(others_near, between, np.inf).min(axis=-1, initial=np.inf)
    out["precedes"] = np.minimum(np.minimum(same, out["d_lon"]), free)
    # the ego's box along the route here (its heading left out: affine in s and e)
    out["d_behind"] = (s - 0.5 * ego_box[0]) - front
    out["left_of"] = np.where(same_way(tho, 0.0), (eo - ho) - (e + 0.5 * ego_box[1]), -np.inf)
    with np.errstate(invalid="ignore"):
        return {name: np.where(near, val, PARTICIPANT_ABSENT[name]) for name, val in out.items()}


def acceleration(v: np.ndarray, near: np.ndarray, dt: float) -> np.ndarray:
    """``a(o)`` [m/s²] from ``v(o)`` (..., T, n) [m/s] along the time axis (−2): the change over
    the last sample / ``dt`` where o was present at both samples, else 0 (the first sample too)."""
    out = np.zeros(np.broadcast_shapes(v.shape, near.shape))
    both = near[..., 1:, :] & near[..., :-1, :]
    out[..., 1:, :] = np.where(both, (v[..., 1:, :] - v[..., :-1, :]) / dt, 0.0)
    return out


def signals_read_by(rulesets: Iterable[object]) -> tuple[str, ...]:
    """The participant signals rule sets read, in :data:`~twolevel.world.provided.PARTICIPANT_SIGNALS`
    order and ``present`` first; empty when no rule quantifies over participants. What sensing
    computes, and a run records, for each participant."""
    read: set[str] = set()
    any_quantifier = False
    for rs in rulesets:
        for r in getattr(rs, "rules", ()):
            any_quantifier = any_quantifier or quantifies(r.formula)
            read |= participant_signals_read(r.formula)
    if not any_quantifier:
        return ()
    return (PRESENT,) + tuple(n for n in PARTICIPANT_SIGNALS if n in read)


def absent_sample(names: Sequence[str]) -> dict[str, float]:
    """A participant's values at a sample where it is absent (``present`` −inf)."""
    return {n: (-np.inf if n == PRESENT else PARTICIPANT_ABSENT[n]) for n in names}
