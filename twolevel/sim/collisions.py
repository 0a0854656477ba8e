"""Collisions and near misses of a run: overlaps of the ego's box with any vehicle's, as episodes,
each with who is responsible.

Every step the ego's oriented box is checked against every active vehicle (not only the sensed
ones): an overlap opens an episode (time, place, the other vehicle) that lasts while it
continues, deepest overlap kept, and closes when it ends — recorded, never hidden. The smallest
centre distance to each vehicle, and when, is kept for the summary's ``closest``.

**Responsibility.** When an episode opens it is classified from the last :data:`WINDOW` [s] of
the run (the ego's poses and speeds, the lane it was on, the traffic states) by
:func:`twolevel.safety.responsibility.classify`: whether the other stayed inside the occupancy
predicted for it under the scenario's assumptions (:func:`~twolevel.safety.responsibility.stayed_within`),
whether the ego was standing outside every other lane
(:func:`~twolevel.safety.verify.standstill_lane`), whether it was hit from behind or cut in on. The episode's
:class:`~twolevel.sim.summary.Collision` records ``at_fault``, the ``verdict`` and the ``reason``.
Classification runs in every run, the safety layer on or off.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from twolevel.safety.responsibility import Responsibility, classify, stayed_within
from twolevel.safety.verify import Context, standstill_lane
from twolevel.sim.summary import Closest, Collision
from twolevel.models.obb import pose_separation
from twolevel.world.traffic import TrafficState

__all__ = ["CollisionLog", "WINDOW"]

WINDOW = 1.0
"""[s] History kept for classifying a collision beyond the others' response time ρ (so that
"hit from behind after ρ in the lane" can be established)."""


@dataclass
class _Episode:
    """An overlap still going on: since ``t`` [s], begun at (``x``, ``y``) [m], the deepest
    ``gap`` so far [m] (< 0), last seen at ``t_last`` [s]; who is responsible (``blame``)."""

    t: float
    x: float
    y: float
    gap: float
    t_last: float
    blame: Responsibility


class CollisionLog:
    """The collision episodes and closest approaches of one run in the world of ``ctx`` (the
    safety layer's context: network, assumptions, kinds of road users)."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        w = self.world = ctx.world
        self.collisions: list[Collision] = []
        self._open: dict[int, _Episode] = {}  # other vehicle's index → its episode
        n_parts = len(w.parts.ids)
        self._closest = np.full(n_parts, np.inf)  # per vehicle: smallest centre distance [m] ...
        self._closest_t = np.zeros(n_parts)  # ... and when [s]
        keep = int(math.ceil((w.assumptions.response.time + WINDOW) / w.settings.dt)) + 1
        self._recent: deque[tuple[float, np.ndarray, TrafficState]] = deque(maxlen=keep)

    def observe(self, t: float, X: float, Y: float, psi: float, v: float, traffic: TrafficState) -> float:
        """The ego at (X, Y) [m] heading ψ [rad] at speed v [m/s] among ``traffic`` at time ``t``
        [s]: opens (and classifies) or extends episodes, closes those that ended; returns the
        centre distance to the nearest vehicle [m] (+inf when none is active)."""
        w = self.world
        self._recent.append((t, np.array([X, Y, psi, v]), traffic))
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
                self._open[i] = _Episode(t, X, Y, g, t, self.blame(i))
            else:
                ep.gap, ep.t_last = min(ep.gap, g), t
        self.close(t, keep=set(hit))
        return float(dist.min())

    def blame(self, i: int) -> Responsibility:
        """Who is responsible for the contact with participant ``i`` now (the last sample
        observed), from the recent samples."""
        w = self.world
        t = np.array([r[0] for r in self._recent])
        ego = np.stack([r[1] for r in self._recent])
        traffic = [r[2] for r in self._recent]
        other = np.stack([[s.x[i], s.y[i], s.psi[i], s.v[i]] for s in traffic])
        ego_lane = w.lanes.lookup(ego[:, :2], heading=ego[:, 2])[0]
        other_lane = np.array([s.lane[i] for s in traffic])
        if (other_lane < 0).any():  # scripted and free participants: the lane their pose lies on
            other_lane = np.where(other_lane < 0, w.lanes.lookup(other[:, :2], heading=other[:, 2])[0], other_lane)
        inside = stayed_within(self.ctx, traffic, i)
        lane = standstill_lane(self.ctx, ego[-1])
        return classify(t, ego, other, (w.ego.length, w.ego.width), (float(w.parts.length[i]), float(w.parts.width[i])),
                        other_inside=inside, ego_lane=ego_lane, other_lane=other_lane,
                        stop_speed=w.settings.stop_speed, response_time=w.assumptions.response.time,
                        standing_in=None if lane is None else w.lanes.lanes[lane].id,
                        brake_min=w.assumptions.response.brake_min, brake_max=w.assumptions.response.brake_max)

    def close(self, t: float, keep: set[int] | None = None) -> None:
        """Record every open episode except those of the vehicles in ``keep`` as ended."""
        for i in [i for i in self._open if keep is None or i not in keep]:
            ep = self._open.pop(i)
            b = ep.blame
            self.collisions.append(Collision(ep.t, ep.t_last, ep.x, ep.y, self.world.parts.ids[i], ep.gap,
                                             b.at_fault, b.verdict, b.reason))

    def closest(self, n: int = 5) -> list[Closest]:
        """The ``n`` vehicles that came closest (centre to centre), nearest first."""
        return [Closest(self.world.parts.ids[i], float(self._closest[i]), float(self._closest_t[i]))
                for i in np.argsort(self._closest, kind="stable")[:n] if np.isfinite(self._closest[i])]
