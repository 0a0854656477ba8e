"""Giving way at stop signs (and yield lines): which traffic has priority, and gap acceptance.

**Conflicts.** Beyond a give-way line a vehicle's way on (the rest of its lane and the lanes
that follow, :data:`REACH` metres) crosses other lanes or joins them. :func:`conflicts_of` finds
these from the lanes' centre lines: the first point where the way on crosses another lane's
centre line, or the end of a lane that leads into a lane of the way on (a merge). Traffic on
that lane, or on the lanes leading into it (up to :data:`APPROACH` metres back), has priority.
Maps with junctions that declare their conflict zones and priorities (stop, yield, priority
road) would build the same :class:`~twolevel.world.traffic.state.Conflicts` rows from them; today
the map has stop signs only, so every stop line gets the conflicts its geometry shows.

**Gap acceptance.** A vehicle at a give-way line — standing at a stop line once its stop time
has passed, or within braking distance of a yield line — goes only when every priority body
(the ego included) is at least its ``critical_gap`` [s] away from the conflict point (distance
to it over its speed; a vehicle moving off from a give-way line of its own: the time it takes
accelerating at its IDM ``a``), none stands in the conflict, and no vehicle that has waited at a line of
its own with a lower index waits for the same conflict (all-way stops: one at a time, in a fixed
order). A priority vehicle that must itself stop before the conflict (an unserved stop sign or a
red light on its way) does not count. Default critical gap 6.5 s: the Highway Capacity Manual's
base critical headway for crossing a two-lane major road from a stop-controlled minor road.
"""

from __future__ import annotations

import numpy as np

from twolevel.world.geometry import LaneSet
from twolevel.world.traffic.state import Conflicts

__all__ = ["REACH", "APPROACH", "ZONE", "conflicts_of", "clear_to_go"]

REACH = 60.0
"""[m] How far beyond a give-way line its conflicts are looked for."""
APPROACH = 150.0
"""[m] How far back along the lanes leading into a conflicting lane priority traffic is watched."""
ZONE = 2.5
"""[m] A body within this distance (plus its half length) of a conflict point stands in it."""


def _way_on(lanes: LaneSet, lane: int, s: float) -> list[tuple[int, float, float, float]]:
    """The pieces (lane, s_from, s_to, distance from the line at s_from) of the way on."""
    out: list[tuple[int, float, float, float]] = []
    todo = [(lane, s, 0.0)]
    seen: set[int] = set()
    while todo:
        ln, a, d0 = todo.pop(0)
        if ln in seen:
            continue
        seen.add(ln)
        b = min(float(lanes.length[ln]), a + REACH - d0)
        out.append((ln, a, b, d0))
        if b >= lanes.length[ln] - 1e-9:
            todo += [(k, 0.0, d0 + b - a) for k in lanes.lanes[ln].successors if d0 + b - a < REACH]
    return out


def _crossing(lanes: LaneSet, piece: tuple[int, float, float, float], other: int) -> tuple[float, float] | None:
    """The first point where the piece of way crosses lane ``other``'s centre line: (distance
    from the line [m], s on ``other`` [m]), or None."""
    ln, a, b, d0 = piece
    line = lanes.lanes[ln]
    inner = (line.s > a) & (line.s < b)
    s_path = np.concatenate([[a], line.s[inner], [b]])
    P = line.position(s_path)
    Q, sq = lanes.lanes[other].points, lanes.lanes[other].s
    dA, dB = np.diff(P, axis=0), np.diff(Q, axis=0)
    rel = Q[None, :-1, :] - P[:-1, None, :]  # (A, B, 2)
    den = dA[:, None, 0] * dB[None, :, 1] - dA[:, None, 1] * dB[None, :, 0]
    safe = np.where(np.abs(den) > 1e-12, den, np.nan)
    t = (rel[..., 0] * dB[None, :, 1] - rel[..., 1] * dB[None, :, 0]) / safe
    u = (rel[..., 0] * dA[:, None, 1] - rel[..., 1] * dA[:, None, 0]) / safe
    hit = (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    if not hit.any():
        return None
    i, j = np.nonzero(hit)
    along = d0 + (s_path[i] - a) + t[i, j] * np.diff(s_path)[i]
    k = int(np.argmin(along))
    return float(along[k]), float(sq[j[k]] + u[i[k], j[k]] * (sq[j[k] + 1] - sq[j[k]]))


def conflicts_of(lanes: LaneSet, line_lane: np.ndarray, line_s: np.ndarray) -> Conflicts:
    """The conflicts of each give-way line at (lane index, s [m])."""
    preds: dict[int, list[int]] = {i: [] for i in range(len(lanes.lanes))}
    for i, ln in enumerate(lanes.lanes):
        for k in ln.successors:
            preds[k].append(i)
    rows: list[tuple[int, int, float, float]] = []
    for q, (ln, s) in enumerate(zip(line_lane.tolist(), line_s.tolist())):
        way = _way_on(lanes, int(ln), float(s))
        on_way = {p[0] for p in way}
        behind = set(preds[int(ln)])
        for other in range(len(lanes.lanes)):
            if other in on_way or other in behind:
                continue
            found = [c for c in (_crossing(lanes, piece, other) for piece in way) if c is not None]
            found += [(p[3], float(lanes.length[other])) for p in way
                      if p[0] != ln and p[0] in lanes.lanes[other].successors]  # merges into the way on
            if not found:
                continue
            path, s_other = min(found)
            # the conflicting lane and the lanes leading into it, within APPROACH
            todo = [(other, s_other)]
            seen: set[int] = set()
            while todo:
                a, sa = todo.pop(0)
                if a in seen or a in on_way:
                    continue
                seen.add(a)
                rows.append((q, a, sa, path))
                todo += [(p, float(lanes.length[p]) + sa) for p in preds[a] if sa < APPROACH]
    if not rows:
        return Conflicts.none()
    r = np.array(rows, dtype=float)
    return Conflicts(r[:, 0].astype(int), r[:, 1].astype(int), r[:, 2], r[:, 3])


def clear_to_go(conf: Conflicts, line: np.ndarray, who: np.ndarray, gap: np.ndarray, lane: np.ndarray,
                s: np.ndarray, hl: np.ndarray, v: np.ndarray, accel: np.ndarray, held: np.ndarray,
                waiting: np.ndarray, body: np.ndarray) -> np.ndarray:
    """Whether each vehicle ``who`` (M,) at give-way ``line`` (M,) may go, accepting a time gap
    ``gap`` (M,) [s]. The bodies (B,) that may have priority — participants, then the ego — are
    given by ``lane``, ``s`` [m], half length ``hl`` [m], speed along the lane ``v`` [m/s], the
    acceleration ``accel`` [m/s²] of those moving off from a line of their own (else 0), the s
    [m] of a line they must stop at on their lane (``held``; +inf: none), ``waiting`` (standing
    ready at a give-way line of their own) and ``body`` (a mask of those on a lane)."""
    rows = np.flatnonzero(np.isin(conf.line, line))
    if not len(rows):
        return np.ones(len(who), dtype=bool)
    rl, rs = conf.lane[rows], conf.s[rows]
    on = body[None, :] & (lane[None, :] == rl[:, None])  # (R, B)
    dist = rs[:, None] - s[None, :] - hl[None, :]
    inside = on & (np.abs(s[None, :] - rs[:, None]) < hl[None, :] + ZONE)
    coming = on & (dist >= 0) & (held[None, :] > rs[:, None])
    d, vb, ab = np.maximum(dist, 0.0), v[None, :], accel[None, :]
    reach = np.where(ab > 0, (np.sqrt(vb**2 + 2 * ab * d) - vb) / np.where(ab > 0, ab, 1.0), d / np.maximum(vb, 0.1))
    tta = np.where(inside, 0.0, np.where(coming, reach, np.inf))
    first = on & (dist >= -ZONE) & waiting[None, :]  # waits for the same conflict
    B = len(lane)
    mine = conf.line[rows][None, :] == line[:, None]  # (M, R)
    order = np.arange(B)[None, None, :] < who[:, None, None]  # (M, 1, B): the others ahead in order
    other = np.arange(B)[None, None, :] != who[:, None, None]
    t = np.where(other & (first[None] & order), 0.0, np.where(other, tta[None], np.inf))  # (M, R, B)
    worst = np.where(mine[:, :, None], t, np.inf).min(axis=(1, 2))
    return worst > gap
