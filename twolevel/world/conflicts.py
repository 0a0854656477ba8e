"""Junctions at run time as arrays: arms, connecting lanes, stop lines, and the conflicts between
connecting lanes with who goes first — what right-of-way signals and rules read.

**Conflicts.** Two connecting lanes of one junction conflict where their areas overlap: where the
centre of one comes closer to the other's centre line than half their two widths (less
:data:`TOUCHING`), unless both
leave the same incoming lane (they diverge: whoever is ahead goes first). A conflict is
:data:`MERGING` when both lead into the same lane, else :data:`CROSSING`. Its zone on each lane is
the interval of s [m] over which that lane's centre is that close to the other lane (sampled
every :data:`SAMPLE` m, widened by one sample at each end, within the lane).

**Priority** (``first``: which of the pair goes first, 0 or 1; −1: no fixed order), by the arms'
priorities (:data:`~twolevel.world.junction.PRIORITIES`):

1. signalised arms of different phases never have green together: the lights decide (−1);
2. a priority road's lane goes before a yield or stop arm's;
3. between arms of equal priority (a priority road's two arms, an all-way stop, one signal
   phase): a left turn gives way to straight on and right turns from the opposite arm; else the
   lane coming from the right goes first (right before left; at an all-way stop whoever stopped
   first goes first, which this tie-break does not know);
4. between lanes of the same arm: straight on before a turn, else −1.

Units: m, rad. Built once per world, vectorised over connecting lanes and over pairs (in blocks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twolevel.world.geometry import LaneSet
from twolevel.world.junction import PRIORITIES, TURNS, Plan

__all__ = ["Junctions", "build_junctions", "CROSSING", "MERGING", "SAMPLE"]

CROSSING, MERGING = 0, 1
SAMPLE = 0.25
"""Spacing [m] of the samples along connecting lanes at which conflicts are looked for."""
TOUCHING = 0.05
"""Lanes whose areas overlap by less than this [m] only touch (two turns around one corner, side by
side): no conflict."""
_CHUNK = 8  # segments per run of samples tested together
_OPPOSITE = math.radians(45.0)


@dataclass(frozen=True, eq=False)
class Junctions:
    """Every junction of a world (``ids`` (J,)) as arrays.

    Arms (A,): ``arm_junction``, ``arm_priority`` (index into
    :data:`~twolevel.world.junction.PRIORITIES`), ``arm_heading`` [rad] (travel into the junction),
    ``arm_point`` (A, 2) [m] (where the road meets it), ``arm_phase`` (signal phase, −1).
    Connecting lanes (C,): ``conn_lane`` (lane index), ``conn_junction``, ``conn_from`` /
    ``conn_to`` (the incoming / outgoing lane), ``conn_arm_in`` / ``conn_arm_out`` (arm indices),
    ``conn_turn`` (index into :data:`~twolevel.world.junction.TURNS`). Stop lines (Q,):
    ``line_lane``, ``line_s`` [m], ``line_kind`` (index into PRIORITIES: yield, stop or signal),
    ``line_arm``, ``line_stop`` / ``line_light`` (index into the world's stop signs / lights, −1).
    Conflicts (X,): ``conflict_junction``, ``conflict_lane`` (X, 2) lane indices, their zones
    ``conflict_s0`` / ``conflict_s1`` (X, 2) [m] on each, ``conflict_kind`` (CROSSING, MERGING) and
    ``conflict_first`` (0 or 1: which of the two lanes goes first; −1: no fixed order)."""

    ids: tuple[str, ...]
    arm_junction: np.ndarray
    arm_priority: np.ndarray
    arm_heading: np.ndarray
    arm_point: np.ndarray
    arm_phase: np.ndarray
    conn_lane: np.ndarray
    conn_junction: np.ndarray
    conn_from: np.ndarray
    conn_to: np.ndarray
    conn_arm_in: np.ndarray
    conn_arm_out: np.ndarray
    conn_turn: np.ndarray
    line_lane: np.ndarray
    line_s: np.ndarray
    line_kind: np.ndarray
    line_arm: np.ndarray
    line_stop: np.ndarray
    line_light: np.ndarray
    conflict_junction: np.ndarray
    conflict_lane: np.ndarray
    conflict_s0: np.ndarray
    conflict_s1: np.ndarray
    conflict_kind: np.ndarray
    conflict_first: np.ndarray

    @classmethod
    def empty(cls) -> "Junctions":
        """No junction."""
        i, f = np.zeros(0, dtype=int), np.zeros(0)
        return cls((), i, i, f, np.zeros((0, 2)), i, i, i, i, i, i, i, i, i, f, i, i, i, i, i,
                   np.zeros((0, 2), dtype=int), np.zeros((0, 2)), np.zeros((0, 2)), i, i)


def _samples(lanes: LaneSet, conn: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each connecting lane sampled every SAMPLE m or less, one after another: points (S, 2) [m],
    s (S,) [m], half widths (S,) [m], the row of ``conn`` each belongs to (S,), and where each
    row's samples start (C+1,)."""
    n = np.maximum(2, np.ceil(lanes.length[conn] / SAMPLE).astype(int) + 1)
    ptr = np.concatenate([[0], np.cumsum(n)]).astype(int)
    row = np.repeat(np.arange(len(conn)), n)
    k = np.arange(ptr[-1]) - ptr[row]
    s = k / (n[row] - 1) * lanes.length[conn][row]
    pts, _ = lanes.pose(conn[row], s)
    return pts, s, 0.5 * lanes.width_at(conn[row], s), row, ptr


def _chunks(pts: np.ndarray, half: np.ndarray, ptr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Runs of :data:`_CHUNK` segments along each row (their first sample, their row) and their
    bounding boxes grown by the largest half width in them: start (H,), row (H,), lo, hi (H, 2)."""
    n_seg = np.diff(ptr) - 1
    count = (n_seg + _CHUNK - 1) // _CHUNK
    row = np.repeat(np.arange(len(n_seg)), count)
    first = ptr[row] + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)) * _CHUNK
    last = np.minimum(first + _CHUNK, ptr[row + 1] - 1)  # the chunk's points: first..last
    idx = first[:, None] + np.arange(_CHUNK + 1)[None, :]
    idx = np.minimum(idx, last[:, None])
    p = pts[idx]
    grow = half[idx].max(axis=1)[:, None]
    return first, row, p.min(axis=1) - grow, p.max(axis=1) + grow


def _zones(lanes: LaneSet, conn: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For pairs (P, 2) of rows of ``conn``: whether they overlap, and the zone [s0, s1] (P, 2) [m]
    on each. Samples of one lane are tested against the segments between samples of the other, only
    within runs of samples whose grown bounding boxes meet."""
    pts, s, half, row, ptr = _samples(lanes, conn)
    first, crow, lo, hi = _chunks(pts, half, ptr)
    cptr = np.searchsorted(crow, np.arange(len(conn) + 1))
    P = len(pairs)
    hit = np.zeros(P, dtype=bool)
    s0, s1 = np.zeros((P, 2)), np.zeros((P, 2))
    for side, (a, b) in enumerate(((pairs[:, 0], pairs[:, 1]), (pairs[:, 1], pairs[:, 0]))):
        # chunk pairs (of a's chunks, b's chunks) of each pair whose boxes meet
        na, nb = cptr[a + 1] - cptr[a], cptr[b + 1] - cptr[b]
        per = na * nb
        pair = np.repeat(np.arange(P), per)
        j = np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per)
        ca, cb = cptr[a][pair] + j // nb[pair], cptr[b][pair] + j % nb[pair]
        meet = np.all((lo[ca] <= hi[cb]) & (lo[cb] <= hi[ca]), axis=1)
        pair, ca, cb = pair[meet], ca[meet], cb[meet]
        # every sample of a's chunk against every segment of b's chunk
        ia = np.minimum(first[ca][:, None] + np.arange(_CHUNK + 1)[None], ptr[row[first[ca]] + 1][:, None] - 1)
        ib = np.minimum(first[cb][:, None] + np.arange(_CHUNK)[None], ptr[row[first[cb]] + 1][:, None] - 2)
        rel = pts[ia][:, :, None, :] - pts[ib][:, None]  # (H, B+1, B, 2): a's samples from b's segments' starts
        d = pts[ib + 1] - pts[ib]  # (H, B, 2)
        l2 = np.einsum("hbj,hbj->hb", d, d)
        t = np.clip(np.einsum("habj,hbj->hab", rel, d) / np.where(l2 > 0, l2, 1.0)[:, None], 0.0, 1.0)
        off = rel - t[..., None] * d[:, None]
        gap = np.sqrt(np.einsum("habj,habj->hab", off, off)) - (half[ib][:, None] + t * (half[ib + 1] - half[ib])[:, None])
        inside = gap.min(axis=2) < half[ia] - TOUCHING  # (H, B+1)
        h, k = np.nonzero(inside)
        who, where = pair[h], ia[h, k]
        lo_s, hi_s = np.full(P, np.inf), np.full(P, -np.inf)
        np.minimum.at(lo_s, who, s[where])
        np.maximum.at(hi_s, who, s[where])
        found = np.isfinite(lo_s)
        length = lanes.length[conn[a]]
        s0[:, side] = np.where(found, np.maximum(lo_s - SAMPLE, 0.0), 0.0)
        s1[:, side] = np.where(found, np.minimum(hi_s + SAMPLE, length), 0.0)
        hit |= found
    return hit, s0, s1


def _first(arm_a: np.ndarray, arm_b: np.ndarray, turn_a: np.ndarray, turn_b: np.ndarray, prio: np.ndarray,
           phase: np.ndarray, heading: np.ndarray, point: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Which of each pair goes first (0, 1, −1): the rules of the module docstring."""
    signal = PRIORITIES.index("signal")
    rank = np.where(prio == PRIORITIES.index("priority"), 2, 1)
    ra, rb = rank[arm_a], rank[arm_b]
    out = np.where(ra > rb, 0, np.where(rb > ra, 1, -1))
    left, straight, right = TURNS.index("left"), TURNS.index("straight"), TURNS.index("right")
    opposite = np.abs((heading[arm_b] - heading[arm_a] - math.pi + math.pi) % (2 * math.pi) - math.pi) < _OPPOSITE
    a_yields = (turn_a == left) & ((turn_b == straight) | (turn_b == right)) & opposite
    b_yields = (turn_b == left) & ((turn_a == straight) | (turn_a == right)) & opposite
    ta = np.stack([np.cos(heading[arm_a]), np.sin(heading[arm_a])], axis=1)
    tb = np.stack([np.cos(heading[arm_b]), np.sin(heading[arm_b])], axis=1)
    rel_b = point[arm_b] - centre
    rel_a = point[arm_a] - centre
    b_right = ta[:, 0] * rel_b[:, 1] - ta[:, 1] * rel_b[:, 0] < 0  # b's arm on a's right
    a_right = tb[:, 0] * rel_a[:, 1] - tb[:, 1] * rel_a[:, 0] < 0
    equal = np.where(a_yields, 1, np.where(b_yields, 0, np.where(opposite, -1,
                     np.where(b_right & ~a_right, 1, np.where(a_right & ~b_right, 0, -1)))))
    out = np.where(ra == rb, equal, out)
    same_arm = arm_a == arm_b
    out = np.where(same_arm, np.where((turn_a == straight) & (turn_b != straight), 0,
                                      np.where((turn_b == straight) & (turn_a != straight), 1, -1)), out)
    both_signal = (prio[arm_a] == signal) & (prio[arm_b] == signal)
    return np.where(both_signal & (phase[arm_a] != phase[arm_b]), -1, out)


def build_junctions(lanes: LaneSet, index: dict[str, int], plans: list[Plan], stop_ids: tuple[str, ...],
                    light_ids: tuple[str, ...]) -> Junctions:
    """The runtime :class:`Junctions` of ``plans`` on the built ``lanes`` (``index``: lane id →
    index); ``stop_ids`` / ``light_ids``: the world's stop signs and lights (the plans' are among them)."""
    if not plans:
        return Junctions.empty()
    arms = [(pi, a) for pi, p in enumerate(plans) for a in p.arms]
    arm_at = {(pi, a.index): k for k, (pi, a) in enumerate(arms)}
    arm_junction = np.array([pi for pi, _ in arms], dtype=int)
    arm_priority = np.array([PRIORITIES.index(a.priority) for _, a in arms], dtype=int)
    arm_heading = np.array([a.heading for _, a in arms], dtype=float)
    arm_point = np.array([a.point for _, a in arms], dtype=float).reshape(-1, 2)
    arm_phase = np.array([a.phase for _, a in arms], dtype=int)
    conns = [(pi, c) for pi, p in enumerate(plans) for c in p.connections]
    col = lambda f, dtype=int: np.array([f(pi, c) for pi, c in conns], dtype=dtype)  # noqa: E731
    conn_lane = col(lambda pi, c: index[c.id])
    conn_junction = col(lambda pi, c: pi)
    conn_from, conn_to = col(lambda pi, c: index[c.incoming]), col(lambda pi, c: index[c.outgoing])
    conn_arm_in, conn_arm_out = col(lambda pi, c: arm_at[(pi, c.arm_in)]), col(lambda pi, c: arm_at[(pi, c.arm_out)])
    conn_turn = col(lambda pi, c: TURNS.index(c.turn))
    stop_at, light_at = {sid: k for k, sid in enumerate(stop_ids)}, {lid: k for k, lid in enumerate(light_ids)}
    lines = [(pi, ln) for pi, p in enumerate(plans) for ln in p.lines]
    line_lane = np.array([index[ln.lane] for _, ln in lines], dtype=int)
    line_s = np.array([ln.s for _, ln in lines], dtype=float)
    line_kind = np.array([PRIORITIES.index(ln.kind) for _, ln in lines], dtype=int)
    line_arm = np.array([arm_at[(pi, ln.arm)] for pi, ln in lines], dtype=int)
    line_stop = np.array([stop_at.get(ln.id, -1) if ln.kind == "stop" else -1 for _, ln in lines], dtype=int)
    line_light = np.array([light_at.get(ln.id, -1) if ln.kind == "signal" else -1 for _, ln in lines], dtype=int)
    # candidate pairs: connecting lanes of one junction, not from the same incoming lane
    i, j = np.triu_indices(len(conns), k=1)
    keep = (conn_junction[i] == conn_junction[j]) & (conn_from[i] != conn_from[j])
    pairs = np.stack([i[keep], j[keep]], axis=1)
    hit, s0, s1 = _zones(lanes, conn_lane, pairs) if len(pairs) else (np.zeros(0, bool), np.zeros((0, 2)), np.zeros((0, 2)))
    pairs, s0, s1 = pairs[hit], s0[hit], s1[hit]
    a, b = pairs[:, 0], pairs[:, 1]
    count = np.bincount(arm_junction, minlength=len(plans))
    centres = np.stack([np.bincount(arm_junction, arm_point[:, k], len(plans)) for k in (0, 1)], axis=1) / count[:, None]
    centre = centres[conn_junction[a]]
    first = _first(conn_arm_in[a], conn_arm_in[b], conn_turn[a], conn_turn[b], arm_priority, arm_phase, arm_heading,
                   arm_point, centre)
    kind = np.where(conn_to[a] == conn_to[b], MERGING, CROSSING)
    return Junctions(tuple(p.id for p in plans), arm_junction, arm_priority, arm_heading, arm_point, arm_phase,
                     conn_lane, conn_junction, conn_from, conn_to, conn_arm_in, conn_arm_out, conn_turn,
                     line_lane, line_s, line_kind, line_arm, line_stop, line_light,
                     conn_junction[a], np.stack([conn_lane[a], conn_lane[b]], axis=1).reshape(-1, 2), s0, s1,
                     kind.astype(int), first.astype(int))
