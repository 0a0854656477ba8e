"""A lane change as lateral motion over time, not a jump.

A participant that begins a change moves into the lane it changes to at once in its state (lane,
s, lateral offset in that lane's frame — the offset starts at the side of the lane it leaves),
and its offset then follows the minimum-jerk profile to the lane's centre (or the place it keeps
in it) over the change's duration: lateral(u) = lat1 + (lat0 − lat1)·(1 − q(u)), u = t / T,
q(u) = 10u³ − 15u⁴ + 6u⁵ (Flash & Hogan 1985), peak lateral speed 1.875·|lat0 − lat1| / T. Its
heading turns with the lateral speed, so that what others sense and predict from its pose shows
the change. While it changes it is also an entry of the lane it leaves (until its body is out of
it): bodies there keep it as their leader, and it keeps theirs.

Durations: 4 s by default (Toledo & Zohar, "Modeling duration of lane changes", Transportation
Research Record 1999, 2007, measured between 4 and 5 s on average on a US freeway).
"""

from __future__ import annotations

import numpy as np

from twolevel.world.geometry import LaneSet
from twolevel.world.traffic.neighbours import transfer
from twolevel.world.traffic.state import Memory

__all__ = ["KEEP_RIGHT", "SETTLE", "home_lateral", "begin", "advance"]

KEEP_RIGHT = 0.3
"""[m] Default room a participant that keeps right (a cyclist) leaves to the lane's right edge."""
SETTLE = 1.0
"""[s] Least time after a lane change ends before MOBIL considers another."""


def home_lateral(lanes: LaneSet, lane: np.ndarray, width: np.ndarray, keep_right: np.ndarray,
                 lateral: np.ndarray) -> np.ndarray:
    """The lateral offset [m] a participant keeps in ``lane``: ``keep_right`` [m] from the right
    edge (NaN: its current ``lateral``), never left of the centre."""
    w = lanes.width[np.maximum(lane, 0)]
    right = -np.maximum(0.0, w / 2 - width / 2 - np.nan_to_num(keep_right))
    return np.where(np.isnan(keep_right), lateral, right)


def begin(lanes: LaneSet, mem: Memory, who: np.ndarray, lane: np.ndarray, s: np.ndarray, lateral: np.ndarray,
          target: np.ndarray, lat1: np.ndarray, duration: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Memory]:
    """Participants ``who`` begin changing from their ``lane`` (s, lateral [m]) to ``target``,
    ending at offset ``lat1`` [m] after ``duration`` [s] (arrays over ``who``). Returns the
    full (N,) lane, s and lateral arrays in the new frames and the memory."""
    if not len(who):
        return lane, s, lateral, mem
    s_t, lat_t, _ = transfer(lanes, lane[who], s[who], lateral[who], target)
    lane, s, lateral = lane.copy(), s.copy(), lateral.copy()
    f, l0, l1, t, T = mem.lc_from.copy(), mem.lc_lat0.copy(), mem.lc_lat1.copy(), mem.lc_t.copy(), mem.lc_T.copy()
    f[who], l0[who], l1[who], t[who], T[who] = lane[who], lat_t, lat1, 0.0, duration
    lane[who], s[who], lateral[who] = target, s_t, lat_t
    return lane, s, lateral, mem.but(lc_from=f, lc_lat0=l0, lc_lat1=l1, lc_t=t, lc_T=T)


def advance(mem: Memory, lateral: np.ndarray, dt: float, t_end: float) -> tuple[np.ndarray, np.ndarray, Memory]:
    """Every change under way moved on by ``dt`` [s] (ending at ``t_end`` [s]): the lateral
    offsets [m], lateral speeds [m/s] (+ left) and the memory (a finished change is forgotten)."""
    on = mem.lc_from >= 0
    if not on.any():
        return lateral, np.zeros(len(lateral)), mem
    t = np.where(on, mem.lc_t + dt, mem.lc_t)
    u = np.minimum(np.maximum(t / mem.lc_T, 0.0), 1.0)
    q = u**3 * (10 - 15 * u + 6 * u**2)
    dq = 30 * u**2 * (1 - u) ** 2
    d = mem.lc_lat0 - mem.lc_lat1
    lat = np.where(on, mem.lc_lat1 + d * (1 - q), lateral)
    v_lat = np.where(on & (u < 1), -d * dq / mem.lc_T, 0.0)
    done = on & (u >= 1)
    return lat, v_lat, mem.but(lc_t=t, lc_from=np.where(done, -1, mem.lc_from),
                                lc_done=np.where(done, t_end, mem.lc_done))
