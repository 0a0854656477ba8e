"""Collisions and near misses of a run: overlaps of the ego's box with any vehicle's, as episodes.

Every step the ego's oriented box is checked against every active vehicle (not only the sensed
ones): an overlap opens an episode (time, place, the other vehicle) that lasts while it
continues, deepest overlap kept, and closes when it ends — recorded, never hidden. The smallest
centre distance to each vehicle, and when, is kept for the summary's ``closest``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twolevel.sim.summary import Closest, Collision
from twolevel.models.obb import pose_separation
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["CollisionLog"]


@dataclass
class _Episode:
    """An overlap still going on: since ``t`` [s], begun at (``x``, ``y``) [m], the deepest
    ``gap`` so far [m] (< 0), last seen at ``t_last`` [s]."""

    t: float
    x: float
    y: float
    gap: float
    t_last: float


class CollisionLog:
    """The collision episodes and closest approaches of one run in ``world``."""

    def __init__(self, world: World) -> None:
        self.world = world
        self.collisions: list[Collision] = []
        self._open: dict[int, _Episode] = {}  # other vehicle's index → its episode
        n_parts = len(world.parts.ids)
        self._closest = np.full(n_parts, np.inf)  # per vehicle: smallest centre distance [m] ...
        self._closest_t = np.zeros(n_parts)  # ... and when [s]

    def observe(self, t: float, X: float, Y: float, psi: float, traffic: TrafficState) -> float:
        """The ego at (X, Y) [m] heading ψ [rad] among ``traffic`` at time ``t`` [s]: opens or
        extends episodes, closes those that ended; returns the centre distance to the nearest
        vehicle [m] (+inf when none is active)."""
        w = self.world
        if traffic.x.size == 0 or not traffic.active.any():
            self.close(t)
            return math.inf
        dist = np.where(traffic.active, np.hypot(traffic.x - X, traffic.y - Y), np.inf)
        closer = dist < self._closest
        self._closest = np.where(closer, dist, self._closest)
        self._closest_t = np.where(closer, t, self._closest_t)
        close = np.flatnonzero(dist <= 0.5 * (np.hypot(w.ego.length, w.ego.width)
                                              + np.hypot(w.parts.length, w.parts.width)))
        hit: dict[int, float] = {}
        if close.size:
            sep = pose_separation(X, Y, psi, w.ego.length, w.ego.width, traffic.x[close], traffic.y[close],
                                  traffic.psi[close], w.parts.length[close], w.parts.width[close])
            hit = {int(i): float(g) for i, g in zip(close, sep) if g < 0}
        for i, g in hit.items():
            ep = self._open.get(i)
            if ep is None:
                self._open[i] = _Episode(t, X, Y, g, t)
            else:
                ep.gap, ep.t_last = min(ep.gap, g), t
        self.close(t, keep=set(hit))
        return float(dist.min())

    def close(self, t: float, keep: set[int] | None = None) -> None:
        """Record every open episode except those of the vehicles in ``keep`` as ended."""
        for i in [i for i in self._open if keep is None or i not in keep]:
            ep = self._open.pop(i)
            self.collisions.append(Collision(ep.t, ep.t_last, ep.x, ep.y, self.world.parts.ids[i], ep.gap))

    def closest(self, n: int = 5) -> list[Closest]:
        """The ``n`` vehicles that came closest (centre to centre), nearest first."""
        return [Closest(self.world.parts.ids[i], float(self._closest[i]), float(self._closest_t[i]))
                for i in np.argsort(self._closest, kind="stable")[:n] if np.isfinite(self._closest[i])]
