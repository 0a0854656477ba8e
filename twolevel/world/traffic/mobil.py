"""MOBIL: when an IDM driver changes lanes (Kesting, Treiber, Helbing, "General lane-changing
model MOBIL for car-following models", Transportation Research Record 1999, 2007).

For a driver c considering the lane on one side (the next lane of the same direction), with n
the body that would follow it there and o the one following it now, and ã the IDM accelerations
after the change, a those now:

* **safety**: ã_n ≥ −b_safe and ã_c ≥ −b_safe, neither gap below the jam distance s0 — and when
  n is the ego, a gap of at least RSS's safe distance behind c (the safety layer assumes that a
  vehicle changing into the ego's lane leaves it that much, :mod:`twolevel.world.assumptions`);
* **incentive**: ã_c − a_c + p·(ã_n − a_n + ã_o − a_o) > Δa_th + Δa_bias to the left and
  > Δa_th − Δa_bias to the right: politeness p weighs the others' loss against one's own gain,
  the bias Δa_bias keeps right (right-hand traffic; negative for left-hand traffic, 0 for
  symmetric rules).

The paper's values are the defaults: p = 0.5, Δa_th = 0.1 m/s², b_safe = 4 m/s², Δa_bias =
0.3 m/s². Accelerations compared are car-following ones (lines and lights left out, so that a
red light is no reason to change lanes); the ego counts as an IDM driver with the default
parameters. Evaluated every step for every driver with lane changes on, vectorised.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twolevel.world.assumptions import ResponseBounds, safe_distance
from twolevel.world.geometry import LaneSet
from twolevel.world.traffic.idm import idm_accel
from twolevel.world.traffic.neighbours import Found, LaneTable, transfer

__all__ = ["Drivers", "decide"]


@dataclass(frozen=True)
class Drivers:
    """Every body that may follow or be followed, participants (N) then the ego (index N):
    speed along its lane ``v`` [m/s], desired speed ``v0`` [m/s], IDM parameters ``p`` (N+1, 6),
    half length ``hl`` [m]; ``ego`` is N."""

    v: np.ndarray
    v0: np.ndarray
    p: np.ndarray
    hl: np.ndarray
    ego: int


def _accel(d: Drivers, who: np.ndarray, v: np.ndarray, gap: np.ndarray, v_lead: np.ndarray) -> np.ndarray:
    w = np.maximum(who, 0)
    return idm_accel(v, d.v0[w], gap, v - v_lead, d.p[w])


def _followers(d: Drivers, f: Found, gap_after: np.ndarray, v_after: np.ndarray, gap_before: np.ndarray,
               v_before: np.ndarray, table: LaneTable) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A follower's (owner, speed, acceleration before, after) for found entries (owner −1: none)."""
    has = f.entry >= 0
    who = np.where(has, table.owner[np.maximum(f.entry, 0)], -1)
    v = np.where(has, table.v[np.maximum(f.entry, 0)], 0.0)
    before = np.where(has, _accel(d, who, v, gap_before, v_before), 0.0)
    after = np.where(has, _accel(d, who, v, gap_after, v_after), 0.0)
    return who, v, before, after


def decide(table: LaneTable, net: LaneSet, d: Drivers, c: np.ndarray, lane: np.ndarray, s: np.ndarray,
           lat: np.ndarray, lat_home: np.ndarray, hw: np.ndarray, now: Found, a_c: np.ndarray, mobil: np.ndarray,
           response: ResponseBounds) -> tuple[np.ndarray, np.ndarray]:
    """Which of the drivers ``c`` (C,) change lanes and to which lane: (indices into ``c``,
    target lanes). Per driver: its ``lane``, ``s``, lateral ``lat`` and the offset ``lat_home`` it
    keeps [m], half width ``hw`` [m], the body ahead ``now`` and its car-following acceleration
    ``a_c`` [m/s²]; ``mobil`` (C, 5) its politeness, threshold, b_safe, bias_right, duration."""
    if not len(c):
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    v, hl = d.v[c], d.hl[c]
    p, th, b_safe, bias = mobil[:, 0], mobil[:, 1], mobil[:, 2], mobil[:, 3]
    s0 = d.p[c, 2]
    # the follower now, and how it would fare behind the body ahead of c instead
    old = table.behind(lane, s, hl, lat, hw, c, v)
    _, _, a_o, at_o = _followers(d, old, old.gap + 2 * hl + now.gap, now.v, old.gap, v, table)
    best = np.full(len(c), -np.inf)
    target = np.full(len(c), -1)
    for side, sign in ((net.left, 1.0), (net.right, -1.0)):
        to = side[lane]
        ok = to >= 0
        if not ok.any():
            continue
        to_ = np.maximum(to, 0)
        s_to, _, _ = transfer(net, lane, s, lat, to_)
        ahead = table.ahead(net, np.where(ok, to, -1), s_to, hl, lat_home, hw, c, v)
        behind = table.behind(np.where(ok, to, -1), s_to, hl, lat_home, hw, c, v)
        at_c = idm_accel(v, d.v0[c], ahead.gap, v - ahead.v, d.p[c])
        n, v_n, a_n, at_n = _followers(d, behind, behind.gap, v, behind.gap + 2 * hl + ahead.gap, ahead.v, table)
        has_n = n >= 0
        safe = ok & (at_c >= -b_safe) & (ahead.gap >= s0)
        safe &= ~has_n | ((at_n >= -b_safe) & (behind.gap >= d.p[np.maximum(n, 0), 2]))
        ego_behind = np.flatnonzero(safe & (n == d.ego))
        if len(ego_behind):
            rss = np.array([safe_distance(float(v_n[k]), float(v[k]), response) for k in ego_behind])
            safe[ego_behind] &= behind.gap[ego_behind] >= rss
        gain = at_c - a_c + p * (at_n - a_n + at_o - a_o)
        margin = gain - (th + sign * bias)
        take = safe & (margin > 0) & (margin > best)
        best = np.where(take, margin, best)
        target = np.where(take, to, target)
    who = np.flatnonzero(target >= 0)
    return who, target[who]
