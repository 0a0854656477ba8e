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
_PAIR_BLOCK = 2_000_000  # (sample, sample) pairs per block
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

    def conflicts_of(self, lane: int) -> tuple[np.ndarray, np.ndarray]:
        """The conflicts lane ``lane`` takes part in and its side in each (0 or 1)."""
        x, side = np.nonzero(self.conflict_lane == lane)
        return x, side


def _samples(lanes: LaneSet, conn: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each connecting lane sampled every SAMPLE m, padded to one length: points (C, K, 2) [m],
    s (C, K) [m], half widths (C, K) [m] and which samples are real (C, K)."""
    n = np.maximum(2, np.ceil(lanes.length[conn] / SAMPLE).astype(int) + 1)
    K = int(n.max(initial=2))
    frac = np.minimum(np.arange(K)[None, :] / (n[:, None] - 1), 1.0)
    s = frac * lanes.length[conn][:, None]
    lane = np.repeat(conn, K)
    pts, _ = lanes.pose(lane, s.ravel())
    half = 0.5 * lanes.width_at(lane, s.ravel())
    return pts.reshape(len(conn), K, 2), s, half.reshape(len(conn), K), np.arange(K)[None, :] < n[:, None]


def _near(pa: np.ndarray, ha: np.ndarray, va: np.ndarray, pb: np.ndarray, hb: np.ndarray, vb: np.ndarray) -> np.ndarray:
    """(P, K): whether each sample of lane a comes closer to lane b's centre line (its polyline of
    samples) than half the two widths there."""
    seg_a, seg_d = pb[:, :-1], pb[:, 1:] - pb[:, :-1]  # (P, K-1, 2)
    seg_ok = vb[:, :-1] & vb[:, 1:]
    l2 = np.einsum("pkj,pkj->pk", seg_d, seg_d)
    rel = pa[:, :, None, :] - seg_a[:, None]  # (P, K, K-1, 2)
    t = np.clip(np.einsum("pmkj,pkj->pmk", rel, seg_d) / np.where(l2 > 0, l2, 1.0)[:, None], 0.0, 1.0)
    diff = rel - t[..., None] * seg_d[:, None]
    dist = np.sqrt(np.einsum("pmkj,pmkj->pmk", diff, diff))
    half_b = hb[:, None, :-1] + t * (hb[:, None, 1:] - hb[:, None, :-1])
    gap = np.where(seg_ok[:, None], dist - half_b, np.inf).min(axis=2)
    return va & (gap < ha - TOUCHING)


def _zones(lanes: LaneSet, conn: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For pairs (P, 2) of rows of ``conn``: whether they overlap, and the zone [s0, s1] (P, 2) [m]
    on each."""
    pts, s, half, valid = _samples(lanes, conn)
    K = pts.shape[1]
    hit = np.zeros(len(pairs), dtype=bool)
    s0, s1 = np.zeros((len(pairs), 2)), np.zeros((len(pairs), 2))
    step = max(1, _PAIR_BLOCK // max(K * K, 1))
    for lo in range(0, len(pairs), step):
        a, b = pairs[lo:lo + step, 0], pairs[lo:lo + step, 1]
        for side, (x, y) in enumerate(((a, b), (b, a))):
            inside = _near(pts[x], half[x], valid[x], pts[y], half[y], valid[y])
            any_in = inside.any(axis=1)
            lo_s = np.where(inside, s[x], np.inf).min(axis=1)
            hi_s = np.where(inside, s[x], -np.inf).max(axis=1)
            length = lanes.length[conn[x]]
            s0[lo:lo + step, side] = np.where(any_in, np.maximum(lo_s - SAMPLE, 0.0), 0.0)
            s1[lo:lo + step, side] = np.where(any_in, np.minimum(hi_s + SAMPLE, length), 0.0)
            hit[lo:lo + step] |= any_in
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
