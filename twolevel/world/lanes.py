"""Every lane of a map built into one :class:`~twolevel.world.geometry.LaneSet`, whatever declared it.

Three kinds of declaration, one runtime form:

* **road lanes** — offsets from a road's reference line of lines, arcs and polylines
  (:func:`~twolevel.world.geometry.lane_from_reference`, exact);
* **free-form lanes** — boundaries given point by point (``left_bound[i]`` facing
  ``right_bound[i]``, as CommonRoad's lanelets), or a centre line with its width. The centre line
  is the polyline through the midpoints of facing points, the width their distance (linear in
  between), the heading at a point halfway between the chords before and after it (the tangent,
  for points sampled evenly along an arc), the curvature of each interval its change of heading
  over its length. Built for all free-form lanes at once (:func:`free_lanes`);
* **junctions' connecting lanes** — the biarcs :mod:`twolevel.world.junction` plans, sampled as
  roads (exact arcs), their width linear from the incoming lane's to the outgoing lane's.

The lane graph joins them: successors as declared plus the junctions' connections, predecessors
from them. Adjacency: lanes of one road beside each other (offsets half their widths apart), a
free-form lane's declared ``adjacent_left`` / ``adjacent_right``, and otherwise a free-form lane
and any other lane whose boundaries coincide (start, middle and end within
:data:`SHARED_WITHIN`); made symmetric. Markings: each lane's ``left_marking`` /
``right_marking``, then the map's ``markings`` over parts of boundaries, mirrored onto the lane
across; the map's ``no_overtaking`` zones. Units: m, rad.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from twolevel.world.geometry import MARKINGS, Lane, LaneSet, MarkingRow, lane_from_reference, sample_road
from twolevel.world.junction import Plan, plan_junctions
from twolevel.world.layout import road_neighbours
from twolevel.world.loader import successors
from twolevel.world.schema import FreeLane, MapFile

__all__ = ["build_lanes", "free_lanes", "centre_lines", "SHARED_WITHIN"]

SHARED_WITHIN = 0.1
"""How close [m] two lanes' boundaries must be at their ends and middles to be found adjacent."""


def centre_lines(points: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heading (N,) [rad, unwrapped within each line], arc length s (N,) [m, from 0 on each line]
    and the curvature of each interval (N−1,) [1/m, 0 between lines] of polylines given one after
    another: ``points`` (N, 2) [m], ``counts`` (L,) points per line (each ≥ 2, consecutive points
    apart). The heading at a point is halfway between the chords before and after it."""
    counts = np.asarray(counts, dtype=int)
    n = len(points)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
    first = np.zeros(n, dtype=bool)
    first[start] = True
    last = np.roll(first, -1)
    last[-1] = True
    d = np.diff(points, axis=0)
    inside = ~first[1:]
    chord = np.hypot(d[:, 0], d[:, 1])
    unit = d / np.where(chord > 0, chord, 1.0)[:, None]
    unit[~inside] = 0.0
    before = np.concatenate([np.zeros((1, 2)), unit])
    after = np.concatenate([unit, np.zeros((1, 2))])
    before[first], after[last] = 0.0, 0.0
    both = before + after
    flat = np.hypot(both[:, 0], both[:, 1]) < 1e-9  # a hairpin: keep the chord after (or before)
    both = np.where(flat[:, None], np.where(last[:, None], before, after), both)
    h = np.arctan2(both[:, 1], both[:, 0])
    dh = (np.diff(h) + math.pi) % (2 * math.pi) - math.pi
    dh[~inside] = 0.0
    ds = np.where(inside, chord, 0.0)
    owner = np.repeat(np.arange(len(counts)), counts)
    ch = np.concatenate([[0.0], np.cumsum(dh)])
    cs = np.concatenate([[0.0], np.cumsum(ds)])
    heading = h[start][owner] + ch - ch[start][owner]
    s = cs - cs[start][owner]
    kappa = np.where(inside, dh / np.where(ds > 0, ds, 1.0), 0.0)
    return heading, s, kappa


def free_lanes(specs: Sequence[FreeLane], index: dict[str, int], succ: dict[str, list[str]]) -> list[Lane]:
    """The free-form lanes ``specs``, built together (see the module docstring)."""
    if not specs:
        return []
    centre, widths, left, right = [], [], [], []
    for ln in specs:
        if ln.centre is not None:
            c = np.asarray(ln.centre, dtype=float)
            w = np.asarray(ln.widths if ln.widths is not None else [ln.width] * len(c), dtype=float)
            left.append(None), right.append(None)
        else:
            lb, rb = np.asarray(ln.left_bound, dtype=float), np.asarray(ln.right_bound, dtype=float)
            c, w = 0.5 * (lb + rb), np.hypot(*(lb - rb).T)
            left.append(lb), right.append(rb)
        centre.append(c), widths.append(w)
    counts = np.array([len(c) for c in centre])
    pts = np.concatenate(centre)
    heading, s, kappa = centre_lines(pts, counts)
    w_all = np.concatenate(widths)
    normal = np.stack([-np.sin(heading), np.cos(heading)], axis=1)
    lb_all, rb_all = pts + 0.5 * w_all[:, None] * normal, pts - 0.5 * w_all[:, None] * normal
    bounds = np.concatenate([[0], np.cumsum(counts)])
    out = []
    for k, ln in enumerate(specs):
        a, b = bounds[k], bounds[k + 1]
        out.append(Lane(pts[a:b], s[a:b], heading[a:b], kappa[a:b - 1], id=ln.id, index=index[ln.id],
                        width=float(w_all[a:b].max()), successors=tuple(index[x] for x in succ[ln.id]), kind=ln.type,
                        widths=w_all[a:b], left_bound=left[k] if left[k] is not None else lb_all[a:b],
                        right_bound=right[k] if right[k] is not None else rb_all[a:b]))
    return out


def _road_adjacency(spec: MapFile, index: dict[str, int], adj: dict[bool, np.ndarray]) -> None:
    """Lanes of one road beside each other (:func:`~twolevel.world.layout.road_neighbours`, in place)."""
    for a, b in road_neighbours(spec):  # b is left of a in the road's frame
        ia, ib = index[a.id], index[b.id]
        adj[a.direction == "forward"][ia] = ib  # road-left of a: a's left when a runs forward
        adj[b.direction != "forward"][ib] = ia


def _features(lane: Lane) -> np.ndarray:
    """(2 sides, 3 points, 2) [m]: each boundary's start, middle (by arc length) and end."""
    out = np.empty((2, 3, 2))
    for k, bound in enumerate((lane.left_bound, lane.right_bound)):
        seg = np.hypot(*np.diff(bound, axis=0).T)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        mid = np.array([np.interp(0.5 * cum[-1], cum, bound[:, 0]), np.interp(0.5 * cum[-1], cum, bound[:, 1])])
        out[k] = [bound[0], mid, bound[-1]]
    return out


def _shared(lanes: Sequence[Lane], query: np.ndarray, adj: dict[bool, np.ndarray]) -> None:
    """Adjacency of lanes ``query`` not yet known on a side, found where their boundary on that side
    coincides with another lane's boundary (same way: its right one, ends in order; the other way:
    its left one, reversed) (in place)."""
    feats = np.stack([_features(ln) for ln in lanes])  # (L, 2, 3, 2)
    rev = feats[:, :, ::-1]
    for left in (True, False):
        side = 0 if left else 1
        ask = np.asarray([i for i in query if adj[left][i] < 0], dtype=int)
        for lo in range(0, len(ask), 256):
            q = ask[lo:lo + 256]
            mine = feats[q, side]  # (Q, 3, 2)
            same = np.abs(mine[:, None] - feats[None, :, 1 - side]).max(axis=(2, 3))  # (Q, L) against their other side
            other = np.abs(mine[:, None] - rev[None, :, side]).max(axis=(2, 3))
            same[np.arange(len(q)), q] = np.inf
            other[np.arange(len(q)), q] = np.inf
            best = np.minimum(same, other)
            j = best.argmin(axis=1)
            hit = best[np.arange(len(q)), j] <= SHARED_WITHIN
            adj[left][q[hit]] = j[hit]


def _symmetric(lanes: Sequence[Lane], adj: dict[bool, np.ndarray]) -> None:
    """Each adjacency known from its other side too (a lane's own neighbour is kept) (in place)."""
    for left in (True, False):
        for i in np.flatnonzero(adj[left] >= 0):
            j = int(adj[left][i])
            a, b = lanes[i], lanes[j]
            # the same way if, where i's boundary is, j heads as i does
            ha = a.heading[len(a.heading) // 2]
            s, _ = b.local_coordinates(a.points[len(a.points) // 2][None])
            hb = float(b.heading_at(np.clip(s, 0.0, b.length))[0])
            back = left if math.cos(ha - hb) < 0 else not left  # j's side facing i
            if adj[back][j] < 0:
                adj[back][j] = i


def _marking_rows(spec: MapFile, index: dict[str, int], lengths: np.ndarray) -> list[MarkingRow]:
    rows: list[MarkingRow] = []
    for ln in spec.lane_specs():
        for left, kind in ((True, ln.left_marking), (False, ln.right_marking)):
            if kind is not None:
                rows.append((index[ln.id], left, 0.0, float(lengths[index[ln.id]]), MARKINGS.index(kind)))
    for m in spec.markings:
        i = index[m.lane]
        a, b = m.s_range if m.s_range is not None else (0.0, float(lengths[i]))
        rows.append((i, m.side == "left", float(a), float(b), MARKINGS.index(m.type)))
    return rows


def build_lanes(spec: MapFile, plans: list[Plan] | None = None) -> tuple[LaneSet, dict[str, int], list[Plan]]:
    """All lanes of the map (roads', free-form, junctions'), their index by id, and the junctions'
    plans (:func:`~twolevel.world.junction.plan_junctions`, unless given)."""
    plans = plan_junctions(spec) if plans is None else plans
    conns = [c for plan in plans for c in plan.connections]
    ids = [ln.id for ln in spec.lane_specs()] + [c.id for c in conns]
    index = {lid: i for i, lid in enumerate(ids)}
    succ = successors(spec)
    lanes: list[Lane] = []
    for road in spec.roads:
        ref = sample_road(road)
        for ln in road.lane_specs():
            lanes.append(lane_from_reference(ref, offset=ln.offset, direction=ln.direction, lane_id=ln.id,
                                             index=index[ln.id], width=ln.width, kind=ln.type,
                                             successors=tuple(index[s] for s in succ[ln.id])))
    lanes += free_lanes(spec.lanes, index, succ)
    for c in conns:
        ref = sample_road(c.road())
        frac = ref.s / max(ref.length, 1e-12)
        lanes.append(lane_from_reference(ref, offset=0.0, direction="forward", lane_id=c.id, index=index[c.id],
                                         width=max(c.width_in, c.width_out), successors=(index[c.outgoing],),
                                         widths=c.width_in + frac * (c.width_out - c.width_in)))
    L = len(lanes)
    adj = {True: np.full(L, -1, dtype=int), False: np.full(L, -1, dtype=int)}
    _road_adjacency(spec, index, adj)
    for ln in spec.lanes:
        if ln.adjacent_left is not None:
            adj[True][index[ln.id]] = index[ln.adjacent_left]
        if ln.adjacent_right is not None:
            adj[False][index[ln.id]] = index[ln.adjacent_right]
    free = np.array([index[ln.id] for ln in spec.lanes], dtype=int)
    if len(free):
        _shared(lanes[: L - len(conns)], free, adj)
    _symmetric(lanes, adj)
    usable = [ln.usable if ln.usable is not None else ln.type == "driving" for ln in spec.lane_specs()] + [True] * len(conns)
    junction = [-1] * (L - len(conns)) + [plan.index for plan in plans for _ in plan.connections]
    lengths = np.array([ln.length for ln in lanes])
    zones = [(index[z.lane], float(z.s_range[0]), float(z.s_range[1])) for z in spec.no_overtaking]
    ls = LaneSet.of(lanes, adj_left=adj[True], adj_right=adj[False], usable=usable, junction=junction,
                    markings=_marking_rows(spec, index, lengths), no_overtaking=zones)
    return ls, index, plans
