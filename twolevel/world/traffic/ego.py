"""The ego as other traffic sees it: where its body is on the lanes, and which lane it is moving into.

Its lane is the one its centre is on (heading within 90°). Its body is an entry of that lane and
of a neighbouring lane it reaches into (so vehicles there follow it). It *signals* a move into a
neighbouring lane — what others read from a turn signal and the car's motion — when its route
runs along that lane and not along the one it is on (it has to get over: a merge), or when it
drifts towards it at :data:`SIGNAL_SPEED` or more and would reach it within :data:`SIGNAL_TIME`
at that rate. It also signals a merge where its lane *ends into* a lane its route continues on
that other lanes lead into too (an on-ramp joining the main road): within :data:`MERGE_AHEAD` of
its lane's end, it is a merging car on each of those other lanes, placed as far before their end
as it is before its own (the "virtual leader" of zipper merging). Vehicles behind it on such a
lane then let it in if that costs them no harder braking than their politeness allows
(:func:`twolevel.world.traffic.step.step`) — while it moves (:data:`MERGE_SPEED`): a car that stands
at the end of a ramp waits for a gap, nobody stops beside it to wait for it (which would leave
both waiting).

Its extents along and across a lane are those of its box turned by its heading relative to the
lane (a car at an angle across a lane line reaches further into the next lane than its centre
and half width say).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twolevel.world.geometry import LaneSet
from twolevel.world.traffic.neighbours import transfer
from twolevel.world.traffic.state import EgoBox

__all__ = ["SIGNAL_SPEED", "SIGNAL_TIME", "MERGE_AHEAD", "MERGE_SPEED", "EgoView", "view"]

EDGE_MARGIN = 0.5
"""[m] The lane beside is looked at once the body comes this close to the edge towards it."""
SIGNAL_SPEED = 0.25
"""[m/s] Least lateral speed towards a neighbouring lane that signals a move into it."""
SIGNAL_TIME = 3.0
"""[s] A drift signals a move when it would bring the body into the lane within this time."""
MERGE_AHEAD = 60.0
"""[m] Within this distance of the end of a lane that merges into its route the ego signals the merge."""
MERGE_SPEED = 2.0
"""[m/s] Least speed at which others let the ego in (slower, it waits for a gap)."""


@dataclass(frozen=True)
class EgoView:
    """The ego on the lanes: its lane (−1: off every lane), s, lateral offset [m], speed along
    the lane [m/s], half length and half width [m]; ``body`` (lanes, s, lateral, speed along
    each) of the lanes its body is on; ``merging`` (lanes, s, speed along each) of the lanes it
    signals it is moving into."""

    box: EgoBox
    lane: int
    s: float
    lat: float
    v: float
    hl: float
    hw: float
    body: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    merging: tuple[np.ndarray, np.ndarray, np.ndarray]


def view(lanes: LaneSet, ego: EgoBox) -> EgoView:
    """How traffic sees ``ego`` on ``lanes``."""
    el, es, elat = lanes.lookup(np.array([[ego.x, ego.y]]), heading=np.array([ego.psi]))
    lane, s, lat = int(el[0]), float(es[0]), float(elat[0])
    none3 = (np.zeros(0, dtype=int), np.zeros(0), np.zeros(0))
    if lane < 0:
        return EgoView(ego, -1, 0.0, 0.0, 0.0, ego.length / 2, ego.width / 2, (*none3, np.zeros(0)), none3)
    h = lanes.pose(el, es)[1][0]
    c, sn = abs(np.cos(ego.psi - h)), abs(np.sin(ego.psi - h))
    hl = float(ego.length / 2 * c + ego.width / 2 * sn)
    hw = float(ego.length / 2 * sn + ego.width / 2 * c)
    v = ego.v * np.cos(ego.psi - h)
    body_l, body_s, body_lat, body_v = [lane], [s], [lat], [v]
    merge_l, merge_s, merge_v = [], [], []
    sides = np.array([lanes.left[lane], lanes.right[lane]])
    drift = ego.v * np.sin(ego.psi - h)  # + left
    toward = np.array([1.0, -1.0])
    # only a body near its lane's edge on that side, or drifting towards it, may reach the next lane
    wanted = np.array([int(x) in ego.route and lane not in ego.route for x in sides])
    there = (sides >= 0) & ((toward * lat > lanes.width[lane] / 2 - EDGE_MARGIN - hw)
                            | (toward * drift >= SIGNAL_SPEED) | wanted)
    if there.any():
        to = sides[there]
        st, latt, ht = transfer(lanes, np.full(len(to), lane), np.full(len(to), s), np.full(len(to), lat), to)
        for k, (sign, wants) in enumerate(zip(toward[there], wanted[there])):
            reach = lanes.width[to[k]] / 2 + hw
            v_to = ego.v * np.cos(ego.psi - ht[k])
            if abs(latt[k]) < reach:
                body_l.append(int(to[k])), body_s.append(float(st[k])), body_lat.append(float(latt[k])), body_v.append(v_to)
            elif wants or (sign * drift >= SIGNAL_SPEED and abs(latt[k]) - sign * drift * SIGNAL_TIME < reach):
                merge_l.append(int(to[k])), merge_s.append(float(st[k])), merge_v.append(v_to)
    for p, s_p in _joining(lanes, ego.route, lane, s):
        merge_l.append(p), merge_s.append(s_p), merge_v.append(float(v))
    if v < MERGE_SPEED:
        merge_l, merge_s, merge_v = [], [], []
    return EgoView(ego, lane, s, lat, float(v), hl, hw,
                   (np.array(body_l), np.array(body_s), np.array(body_lat), np.array(body_v, dtype=float)),
                   (np.array(merge_l, dtype=int), np.array(merge_s, dtype=float), np.array(merge_v, dtype=float)))


def _joining(lanes: LaneSet, route: tuple[int, ...], lane: int, s: float) -> list[tuple[int, float]]:
    """The other lanes leading into the lane the route continues on after ``lane``, when the ego
    is within :data:`MERGE_AHEAD` of ``lane``'s end at ``s`` [m]: (lane, the ego's place on it
    [m], as far before its end as the ego is before its own)."""
    to_end = float(lanes.length[lane]) - s
    if to_end > MERGE_AHEAD:
        return []
    into = [k for k in lanes.lanes[lane].successors if k in route]
    feeding = sorted({int(p) for k in into for p in lanes.pred[lanes.pred_ptr[k]:lanes.pred_ptr[k + 1]]} - {lane})
    return [(p, float(lanes.length[p]) - to_end) for p in feeding if lanes.length[p] >= to_end]
