"""Who is ahead and behind on a lane: the lane table of one step and its searches.

Every body on a lane is an *entry* (lane, s [m], half length, lateral offset [m] and half width,
speed along the lane [m/s], owner): each participant on its lane, a participant changing lanes
also on the lane it leaves, the ego on the lane it is on and on a neighbouring lane its body
reaches into. Entries are sorted by ``lane · BIG + s`` once per step; a search walks from a
query's key to the next entry on the same lane that is not the querier and that *overlaps it
sideways*: the two bodies' lateral extents come closer than :data:`CLEARANCE`. So a car parked
half on the kerb, a cyclist keeping right of a wide lane or a vehicle in the next lane is no
leader for a body that passes it with room to spare, while one that intrudes into its path is.
Searches ahead continue onto the lane's first successor. Vectorised: each round of the walk is
one array operation over the queries still looking; few need more than one round.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twolevel.world.geometry import LaneSet
from twolevel.world.traffic.state import BIG

__all__ = ["CLEARANCE", "LaneTable", "Found", "transfer"]

CLEARANCE = 0.3
"""[m] Least lateral room between two bodies for one to pass the other in its lane."""
_NEWTON = 2  # projection steps of transfer()
_ROUNDS = 8  # entries skipped at most per search (bodies beside one's path) before giving up


def transfer(lanes: LaneSet, src: np.ndarray, s: np.ndarray, lateral: np.ndarray, dst: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points (lane ``src``, s [m], lateral [m]) in the coordinates of lanes ``dst``:
    (s [m], lateral [m], the lane's heading there [rad]), by projecting onto ``dst`` with Newton
    steps from the point's proportional place along it (neighbouring lanes: exact on straight
    pieces, within a millimetre on bends)."""
    src = np.asarray(src, dtype=int)
    dst = np.asarray(dst, dtype=int)
    if not len(src):
        z = np.zeros(0)
        return z, z, z
    p, _ = lanes.pose(src, s, lateral)
    g = s * lanes.length[dst] / np.maximum(lanes.length[src], 1e-9)
    for _ in range(_NEWTON):
        q, h = lanes.pose(dst, g)
        c, sn = np.cos(h), np.sin(h)
        g = g + (p[:, 0] - q[:, 0]) * c + (p[:, 1] - q[:, 1]) * sn
    q, h = lanes.pose(dst, g)
    return g, -(p[:, 0] - q[:, 0]) * np.sin(h) + (p[:, 1] - q[:, 1]) * np.cos(h), h


@dataclass(frozen=True)
class Found:
    """Search results per query: the entry found (−1: none), the bumper-to-bumper ``gap`` [m]
    (+inf when none) and the entry's speed ``v`` [m/s] (the querier's own speed when none)."""

    entry: np.ndarray
    gap: np.ndarray
    v: np.ndarray


@dataclass(frozen=True, eq=False)
class LaneTable:
    """Entries (E,) sorted by key: ``lane``, ``s`` [m], half length ``hl`` [m], ``lat`` [m], half
    width ``hw`` [m], speed ``v`` [m/s], ``owner`` (participant index; N for the ego); ``key``
    their sort keys, ``order`` the sorting permutation and ``sk`` the sorted keys."""

    lane: np.ndarray
    s: np.ndarray
    hl: np.ndarray
    lat: np.ndarray
    hw: np.ndarray
    v: np.ndarray
    owner: np.ndarray
    key: np.ndarray
    order: np.ndarray
    sk: np.ndarray

    @classmethod
    def of(cls, lane: np.ndarray, s: np.ndarray, hl: np.ndarray, lat: np.ndarray, hw: np.ndarray, v: np.ndarray,
           owner: np.ndarray) -> "LaneTable":
        """The table of these entries (an entry on lane −1 is left out of every search)."""
        key = np.where(lane >= 0, lane * BIG + s, np.inf)
        order = np.argsort(key, kind="stable")
        return cls(lane, s, hl, lat, hw, v, owner, key, order, key[order])

    def _match(self, e: np.ndarray, lane: np.ndarray, lat: np.ndarray, hw: np.ndarray, owner: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """(on the query's lane, and a body in its way) for entries ``e``."""
        on = (self.lane[e] == lane) & np.isfinite(self.key[e])
        return on, on & (self.owner[e] != owner) & (np.abs(self.lat[e] - lat) < self.hw[e] + hw + CLEARANCE)

    def _walk(self, j: np.ndarray, lane: np.ndarray, lat: np.ndarray, hw: np.ndarray, owner: np.ndarray,
              step: int) -> np.ndarray:
        """From sorted positions ``j``, the first matching entry walking by ``step`` (±1) while
        on the query's lane; −1 where none (or after :data:`_ROUNDS` bodies beside the path)."""
        E = len(self.sk)
        out = np.full(len(j), -1)
        todo = np.arange(len(j))
        j = j.copy()
        for _ in range(_ROUNDS):
            inside = (j[todo] >= 0) & (j[todo] < E)
            todo = todo[inside]
            if not len(todo):
                break
            e = self.order[j[todo]]
            on, hit = self._match(e, lane[todo], lat[todo], hw[todo], owner[todo])
            out[todo[hit]] = e[hit]
            todo = todo[on & ~hit]
            j[todo] += step
        return out

    def ahead(self, lanes: LaneSet, lane: np.ndarray, s: np.ndarray, hl: np.ndarray, lat: np.ndarray,
              hw: np.ndarray, owner: np.ndarray, v: np.ndarray) -> Found:
        """The body ahead of each query (lane, s, half length, lateral, half width, owner, own
        speed) on its lane, else the first on the lane's first successor."""
        key = lane * BIG + s
        e = self._walk(np.searchsorted(self.sk, key, side="right"), lane, lat, hw, owner, +1)
        gap = np.where(e >= 0, self.key[e] - key - self.hl[e] - hl, np.inf)
        succ = lanes.successor[np.maximum(lane, 0)]
        more = (e < 0) & (succ >= 0) & (lane >= 0)
        if more.any():
            q = np.flatnonzero(more)
            e2 = self._walk(np.searchsorted(self.sk, succ[q] * BIG - 0.5 * BIG, side="left"), succ[q], lat[q], hw[q],
                            owner[q], +1)
            ok = e2 >= 0
            q, e2 = q[ok], e2[ok]
            gap[q] = lanes.length[lane[q]] - s[q] + (self.key[e2] - succ[q] * BIG) - self.hl[e2] - hl[q]
            e = e.copy()
            e[q] = e2
        return Found(e, gap, np.where(e >= 0, self.v[np.maximum(e, 0)], v))

    def behind(self, lane: np.ndarray, s: np.ndarray, hl: np.ndarray, lat: np.ndarray, hw: np.ndarray,
               owner: np.ndarray, v: np.ndarray) -> Found:
        """The body behind each query on its lane (not on lanes leading into it)."""
        key = lane * BIG + s
        e = self._walk(np.searchsorted(self.sk, key, side="left") - 1, lane, lat, hw, owner, -1)
        gap = np.where(e >= 0, key - self.key[np.maximum(e, 0)] - self.hl[np.maximum(e, 0)] - hl, np.inf)
        return Found(e, gap, np.where(e >= 0, self.v[np.maximum(e, 0)], v))
