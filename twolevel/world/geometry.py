"""Lanes and routes as sampled centre lines, vectorised with numpy.

A centre line is a polyline of vertices with their arc length ``s`` [m] (exact for arcs and
lines: vertices are dense on arcs, sagitta ≤ 1 mm), heading [rad] (the analytic tangent, unwrapped)
and the curvature [1/m] of each interval. Positions between vertices are interpolated linearly,
projections are onto the polyline, so ``local_coordinates(position(s, 0)) == (s, 0)``.
HighwayEnv's lane API: ``lane.position(s, lateral)``, ``lane.local_coordinates(points)``,
``lane.heading_at(s)``. Conventions: lateral offsets positive to the left of travel.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np

from twolevel.world.schema import Road

__all__ = [
    "Polyline", "Lane", "LaneSet", "Markings", "Zones", "Route", "sample_road", "lane_from_reference", "concatenate",
    "resample", "step_index", "LANE_KINDS", "MARKINGS", "CROSSABLE", "MIRRORED", "MarkingRow",
]

_SAGITTA = 1e-3  # [m] maximum distance of an arc from its chords
_MAX_STEP = 0.01  # [rad] maximum angle between arc vertices


@dataclass(frozen=True, eq=False)
class Polyline:
    """A sampled centre line: vertices ``points`` (K, 2) [m], ``s`` (K,) [m] non-decreasing,
    ``heading`` (K,) [rad] (unwrapped), ``kappa`` (K−1,) [1/m] per interval."""

    points: np.ndarray
    s: np.ndarray
    heading: np.ndarray
    kappa: np.ndarray

    @property
    def length(self) -> float:
        """Total arc length [m]."""
        return float(self.s[-1] - self.s[0])

    def _index(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i = _clamp(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.s) - 2)
        ds = self.s[i + 1] - self.s[i]
        t = np.where(ds > 0, (s - self.s[i]) / np.where(ds > 0, ds, 1.0), 0.0)
        return i, t

    def position(self, s: np.ndarray | float, lateral: np.ndarray | float = 0.0) -> np.ndarray:
        """Points (..., 2) [m] at arc length ``s`` [m] and ``lateral`` offset [m] (+ left);
        beyond either end the first/last interval is extended in a straight line."""
        s = np.asarray(s, dtype=float)
        i, t = self._index(s)
        p = self.points[i] + t[..., None] * (self.points[i + 1] - self.points[i])
        h = self.heading_at(s)
        lat = np.asarray(lateral, dtype=float)
        return p + lat[..., None] * np.stack([-np.sin(h), np.cos(h)], axis=-1)

    def heading_at(self, s: np.ndarray | float) -> np.ndarray:
        """Heading [rad] at arc length ``s`` [m] (interpolated between vertices)."""
        s = np.asarray(s, dtype=float)
        i, t = self._index(s)
        t = _clamp(t, 0.0, 1.0)
        return self.heading[i] + t * (self.heading[i + 1] - self.heading[i])

    def curvature_at(self, s: np.ndarray | float) -> np.ndarray:
        """Curvature [1/m] at arc length ``s`` [m] (+ turning left)."""
        i, _ = self._index(np.asarray(s, dtype=float))
        return self.kappa[i]

    def local_coordinates(
        self, points: np.ndarray, window: tuple[float, float] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Project points (..., 2) [m] onto the line: arc length ``s`` [m] and lateral offset [m].

        Vectorised over points and intervals. ``window`` = (s_lo, s_hi) [m] restricts the search
        to the intervals overlapping it (faster on long lines). Points before the start or past
        the end get ``s`` < 0 or > length, extrapolated along the end intervals.
        """
        pts = np.asarray(points, dtype=float)
        flat = pts.reshape(-1, 2)
        lo, hi = 0, len(self.s) - 1
        if window is not None:
            lo = int(max(np.searchsorted(self.s, window[0], side="right") - 1, 0))
            hi = int(min(np.searchsorted(self.s, window[1], side="left") + 1, len(self.s) - 1))
            hi = max(hi, lo + 1)
        a = self.points[lo:hi]
        d = self.points[lo + 1 : hi + 1] - a
        l2 = np.einsum("kj,kj->k", d, d)
        rel = flat[:, None, :] - a[None, :, :]  # (M, K, 2)
        safe = np.where(l2 > 0, l2, 1.0)
        t_raw = np.einsum("mkj,kj->mk", rel, d) / safe
        low, high = np.zeros(len(l2)), np.ones(len(l2))
        if lo == 0:
            low[0] = -np.inf
        if hi == len(self.s) - 1:
            high[-1] = np.inf
        t = _clamp(t_raw, low, high)
        diff = rel - t[..., None] * d[None]
        dist2 = np.einsum("mkj,mkj->mk", diff, diff)
        dist2 = np.where(l2[None, :] > 0, dist2, np.inf)
        k = np.argmin(dist2, axis=1)
        m = np.arange(flat.shape[0])
        tk = t[m, k]
        s = self.s[lo + k] + tk * (self.s[lo + k + 1] - self.s[lo + k])
        dk = d[k]
        cross = dk[:, 0] * rel[m, k, 1] - dk[:, 1] * rel[m, k, 0]
        lateral = cross / np.sqrt(np.where(l2[k] > 0, l2[k], 1.0))
        shape = pts.shape[:-1]
        return s.reshape(shape), lateral.reshape(shape)


LANE_KINDS = ("driving", "shoulder", "parking", "bicycle", "bus", "sidewalk", "crosswalk", "restricted")
"""Lane types (:attr:`LaneSet.kind` holds the index): the main ones of CommonRoad's lanelet types,
OpenDRIVE's lane types and SUMO's vehicle classes."""
MARKINGS = ("none", "dashed", "solid", "double_solid", "dashed_solid", "solid_dashed", "curb")
"""Line markings of a lane's boundary as seen from that lane: for a double line the first word is
the line nearer to the lane (``dashed_solid``: the lane may cross it, the neighbour may not)."""
CROSSABLE = np.array([True, True, False, False, True, False, False])
"""Whether traffic may cross a boundary marked ``MARKINGS[i]`` out of the lane that sees it so."""
MIRRORED = np.array([0, 1, 2, 3, 5, 4, 6])
"""The same line as the lane on its other side sees it (``dashed_solid`` ↔ ``solid_dashed``)."""


@dataclass(frozen=True, eq=False)
class Lane(Polyline):
    """A lane: its centre line in the direction of travel; its width ``widths`` (K,) [m] at each
    vertex, linear in between (``width`` [m]: the widest); its boundaries ``left_bound`` /
    ``right_bound`` (K, 2) [m] beside each vertex (default: the centre ± half the width along the
    normal); the lanes traffic continues into (``successors``) and comes from (``predecessors``);
    its ``kind`` (one of :data:`LANE_KINDS`)."""

    id: str = ""
    index: int = 0
    width: float = 3.5
    successors: tuple[int, ...] = ()
    predecessors: tuple[int, ...] = ()
    kind: str = "driving"
    widths: np.ndarray | None = None
    left_bound: np.ndarray | None = None
    right_bound: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.widths is None:
            object.__setattr__(self, "widths", np.full(len(self.s), float(self.width)))
        if self.left_bound is None or self.right_bound is None:
            normal = np.stack([-np.sin(self.heading), np.cos(self.heading)], axis=1)
            half = 0.5 * np.asarray(self.widths)[:, None]
            object.__setattr__(self, "left_bound", self.points + half * normal)
            object.__setattr__(self, "right_bound", self.points - half * normal)

    def width_at(self, s: np.ndarray | float) -> np.ndarray:
        """Width [m] at arc length ``s`` [m] (linear between vertices, constant beyond the ends)."""
        i, t = self._index(np.asarray(s, dtype=float))
        w = np.asarray(self.widths)
        return w[i] + _clamp(t, 0.0, 1.0) * (w[i + 1] - w[i])

    def on_lane(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether points (..., 2) lie on the lane (|lateral| ≤ width(s)/2 + margin, 0 ≤ s ≤ length)."""
        s, lat = self.local_coordinates(points)
        return (np.abs(lat) <= self.width_at(s) / 2 + margin) & (s >= -margin) & (s <= self.length + margin)


def sample_road(road: Road) -> Polyline:
    """The road's reference line sampled exactly (lines: end points; arcs: dense vertices)."""
    x, y, h = road.start.x, road.start.y, math.radians(road.start.heading)
    pts: list[np.ndarray] = [np.array([[x, y]])]
    hs: list[np.ndarray] = [np.array([h])]
    ss: list[np.ndarray] = [np.array([0.0])]
    ks: list[np.ndarray] = []
    s = 0.0
    for seg in road.segments:
        if seg.line is not None:
            x, y = x + seg.line * math.cos(h), y + seg.line * math.sin(h)
            s += seg.line
            pts.append(np.array([[x, y]])); hs.append(np.array([h])); ss.append(np.array([s])); ks.append(np.zeros(1))
        elif seg.arc is not None:
            r, th = seg.arc.radius, math.radians(seg.arc.angle)
            sign = 1.0 if th > 0 else -1.0
            step = min(_MAX_STEP, math.sqrt(8 * _SAGITTA / r))
            n = max(1, math.ceil(abs(th) / step))
            ang = h + th * np.arange(1, n + 1) / n
            cx, cy = x - sign * r * math.sin(h), y + sign * r * math.cos(h)
            px = cx + sign * r * np.sin(ang)
            py = cy - sign * r * np.cos(ang)
            pts.append(np.stack([px, py], axis=1)); hs.append(ang)
            ss.append(s + r * np.abs(ang - h)); ks.append(np.full(n, sign / r))
            x, y, h, s = float(px[-1]), float(py[-1]), float(ang[-1]), s + r * abs(th)
        else:
            for px, py in seg.points or []:
                dist = math.hypot(px - x, py - y)
                if dist == 0:
                    continue
                new_h = math.atan2(py - y, px - x)
                new_h = h + (new_h - h + math.pi) % (2 * math.pi) - math.pi  # unwrap
                if abs(new_h - h) > 1e-12:  # a corner: same vertex, new heading
                    pts.append(np.array([[x, y]])); hs.append(np.array([new_h])); ss.append(np.array([s]))
                    ks.append(np.zeros(1))
                h, x, y, s = new_h, px, py, s + dist
                pts.append(np.array([[x, y]])); hs.append(np.array([h])); ss.append(np.array([s])); ks.append(np.zeros(1))
    return Polyline(np.concatenate(pts), np.concatenate(ss), np.concatenate(hs), np.concatenate(ks) if ks else np.zeros(0))


def lane_from_reference(
    ref: Polyline, *, offset: float, direction: str, lane_id: str, index: int, width: float,
    successors: tuple[int, ...] = (), kind: str = "driving", widths: np.ndarray | None = None,
) -> Lane:
    """The lane ``offset`` [m] left of the reference line, ordered in its direction of travel;
    ``widths`` (K,) [m] at the reference line's vertices (in the line's order) if the width varies."""
    normal = np.stack([-np.sin(ref.heading), np.cos(ref.heading)], axis=1)
    pts = ref.points + offset * normal
    dref = np.diff(ref.s)
    chord = np.hypot(*np.diff(pts, axis=0).T)
    ds = np.where(ref.kappa != 0, dref * (1 - offset * ref.kappa), chord)
    kappa = ref.kappa / (1 - offset * ref.kappa)
    heading = ref.heading
    w = None if widths is None else np.asarray(widths, dtype=float)
    if direction == "backward":
        pts, ds, kappa, heading = pts[::-1], ds[::-1], -kappa[::-1], heading[::-1] + math.pi
        w = None if w is None else w[::-1]
    s = np.concatenate([[0.0], np.cumsum(ds)])
    return Lane(np.ascontiguousarray(pts), s, np.ascontiguousarray(heading), np.ascontiguousarray(kappa),
                id=lane_id, index=index, width=width if w is None else float(w.max()), successors=successors,
                kind=kind, widths=None if w is None else np.ascontiguousarray(w))


def concatenate(pieces: list[tuple[Polyline, float, float]]) -> Polyline:
    """The polyline that runs along each (line, s_from, s_to) piece in turn; ``s`` continues
    across pieces (by the pieces' own arc lengths) and headings stay unwrapped."""
    pts, ss, hs, ks = [], [], [], []
    offset, h_shift = 0.0, 0.0
    for n, (line, a, b) in enumerate(pieces):
        inner = (line.s > a) & (line.s < b)
        s_loc = np.concatenate([[a], line.s[inner], [b]])
        p = line.position(s_loc)
        h = line.heading_at(s_loc)
        k = line.curvature_at(s_loc[:-1])
        if n > 0:
            h_shift = hs[-1][-1] - h[0] + ((h[0] - hs[-1][-1] + math.pi) % (2 * math.pi) - math.pi)
            ks.append(np.zeros(1))  # joint between pieces
            offset_s = ss[-1][-1]
        else:
            offset_s = 0.0
        pts.append(p); ss.append(offset_s + s_loc - a); hs.append(h + h_shift); ks.append(k)
        offset = offset_s + b - a
    del offset
    return Polyline(np.concatenate(pts), np.concatenate(ss), np.concatenate(hs), np.concatenate(ks))


def _clamp(i: np.ndarray, lo: np.ndarray | float, hi: np.ndarray | float) -> np.ndarray:
    """Indices or values ``i`` clipped to [lo, hi] (scalars or arrays broadcast with it): np.clip's
    result, bit for bit, without its wrapper's overhead (the projections and look-ups call it
    thousands of times a step; the fail-safes' segments a few hundred times per verification)."""
    return np.minimum(np.maximum(i, lo), hi)


def step_index(key: np.ndarray, q: np.ndarray | float) -> np.ndarray:
    """Which piece of a piecewise-constant table with sorted breakpoints ``key`` is in force at
    ``q``: the last breakpoint at or before it (the first one before them all); broadcast over ``q``."""
    return _clamp(np.searchsorted(key, q, side="right") - 1, 0, len(key) - 1)


@dataclass(frozen=True, eq=False)
class Markings:
    """The line markings of every lane's two boundaries, piecewise constant along the lane: per side,
    breakpoints at global keys ``base[lane]`` + s [m] (sorted) and the marking (index into
    :data:`MARKINGS`) in force from each on. Seen from the lane: a boundary shared by two lanes
    has an entry on each (mirrored: :data:`MIRRORED`)."""

    base: np.ndarray
    left_key: np.ndarray
    left_type: np.ndarray
    right_key: np.ndarray
    right_type: np.ndarray

    def at(self, lane: np.ndarray, s: np.ndarray, left: np.ndarray | bool) -> np.ndarray:
        """The marking (index into :data:`MARKINGS`) of ``lane``'s left (``left`` true) or right
        boundary at arc length ``s`` [m]; broadcast over the arguments."""
        lane, s, left = np.broadcast_arrays(np.asarray(lane, dtype=int), np.asarray(s, dtype=float), np.asarray(left, dtype=bool))
        q = self.base[lane] + s
        return np.where(left, self.left_type[step_index(self.left_key, q)], self.right_type[step_index(self.right_key, q)])

    def crossable(self, lane: np.ndarray, s: np.ndarray, left: np.ndarray | bool) -> np.ndarray:
        """Whether traffic on ``lane`` at ``s`` [m] may cross its left (or right) boundary."""
        return CROSSABLE[self.at(lane, s, left)]


@dataclass(frozen=True, eq=False)
class Zones:
    """Stretches of lanes (e.g. no-overtaking zones): ``lane`` (Z,) from ``s0`` to ``s1`` (Z,) [m]."""

    lane: np.ndarray
    s0: np.ndarray
    s1: np.ndarray

    def contains(self, lane: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Whether (lane index, s [m]) lies in one of the stretches; broadcast over the arguments."""
        lane, s = np.broadcast_arrays(np.asarray(lane, dtype=int), np.asarray(s, dtype=float))
        if not len(self.lane):
            return np.zeros(lane.shape, dtype=bool)
        hit = (lane[..., None] == self.lane) & (s[..., None] >= self.s0) & (s[..., None] <= self.s1)
        return hit.any(axis=-1)


MarkingRow = tuple[int, bool, float, float, int]
"""A painted marking: (lane index, left side?, from s [m], to s [m], index into :data:`MARKINGS`)."""


@dataclass(frozen=True, eq=False)
class LaneSet:
    """All lanes of a map in concatenated arrays, for vectorised work over many vehicles on many
    lanes: position, heading and width from (lane index, s), the lane points are on, the lane
    graph, and what lies beside each lane (:meth:`of` builds it; every lane kind alike).

    Per vertex (K,), every lane's vertices in a row: the global ``key`` = ``base[lane]`` + s [m],
    ``points`` (K, 2) [m], ``heading`` [rad], ``widths`` [m], the boundaries ``left_bound`` /
    ``right_bound`` (K, 2) [m], and ``beside_left`` / ``beside_right`` [m]: s on the adjacent lane
    on that side level with the vertex (NaN where it has none). ``seg_lane`` (K−1,): the lane of
    each interval (−1 between lanes); ``vptr`` (L+1,): lane i's vertices are ``vptr[i]:vptr[i+1]``.

    Per lane (L,): ``base`` [m], ``length`` [m], ``width`` [m] (its widest); the graph:
    ``successor`` (the first successor, −1), every successor ``succ[succ_ptr[i]:succ_ptr[i+1]]``
    and predecessor ``pred[pred_ptr[i]:pred_ptr[i+1]]``; adjacency: ``adj_left`` / ``adj_right``
    (the lane beside it, either direction, −1: none) with ``adj_left_same`` / ``adj_right_same``
    (it runs the same way), and ``left`` / ``right`` (the adjacent lane running the same way, −1:
    none — where a lane change leads); ``kind`` (index into :data:`LANE_KINDS`); ``usable`` (part
    of the ego's drivable area: driving lanes, others where the map says so); ``junction`` (the
    junction a connecting lane belongs to, −1). ``markings``: both boundaries' line markings along
    every lane; ``no_overtaking``: where passing over the oncoming lane is forbidden; ``index``:
    lane id → index."""

    lanes: tuple[Lane, ...]
    base: np.ndarray
    key: np.ndarray
    points: np.ndarray
    heading: np.ndarray
    seg_lane: np.ndarray
    length: np.ndarray
    width: np.ndarray
    successor: np.ndarray
    vptr: np.ndarray
    widths: np.ndarray
    left_bound: np.ndarray
    right_bound: np.ndarray
    succ_ptr: np.ndarray
    succ: np.ndarray
    pred_ptr: np.ndarray
    pred: np.ndarray
    adj_left: np.ndarray
    adj_right: np.ndarray
    adj_left_same: np.ndarray
    adj_right_same: np.ndarray
    left: np.ndarray
    right: np.ndarray
    kind: np.ndarray
    usable: np.ndarray
    junction: np.ndarray
    beside_left: np.ndarray
    beside_right: np.ndarray
    markings: Markings
    no_overtaking: Zones
    index: Mapping[str, int]

    @classmethod
    def of(cls, lanes: Sequence[Lane], *, adj_left: Sequence[int] | None = None, adj_right: Sequence[int] | None = None,
           usable: Sequence[bool] | None = None, junction: Sequence[int] | None = None,
           markings: Sequence[MarkingRow] = (), no_overtaking: Sequence[tuple[int, float, float]] = ()) -> "LaneSet":
        """The lane set of ``lanes`` (``lanes[i].index == i``). ``adj_left`` / ``adj_right`` (L,):
        the lane beside each on that side (−1; the direction is read from the geometry);
        ``usable`` (L,): default, the driving lanes; ``junction`` (L,): default −1. ``markings``:
        rows painted in order onto the unmarked boundaries, each mirrored onto the lane across
        (a lane's own rows win over mirrored ones); ``no_overtaking``: (lane, s0, s1) [m]."""
        lanes = tuple(lanes)
        L = len(lanes)
        length = np.array([ln.length for ln in lanes])
        base = np.concatenate([[0.0], np.cumsum(length + 1.0)[:-1]])
        counts = np.array([len(ln.s) for ln in lanes])
        vptr = np.concatenate([[0], np.cumsum(counts)]).astype(int)
        key = np.concatenate([b + ln.s for b, ln in zip(base, lanes)])
        lane_of_vertex = np.repeat(np.arange(L), counts)
        seg_lane = np.where(lane_of_vertex[:-1] == lane_of_vertex[1:], lane_of_vertex[:-1], -1)
        succ_n = np.array([len(ln.successors) for ln in lanes], dtype=int)
        succ = np.array([j for ln in lanes for j in ln.successors], dtype=int)
        succ_ptr = np.concatenate([[0], np.cumsum(succ_n)]).astype(int)
        owner = np.repeat(np.arange(L), succ_n)
        order = np.argsort(succ, kind="stable")
        pred = owner[order]
        pred_ptr = np.searchsorted(succ[order], np.arange(L + 1), side="left").astype(int)
        lanes = tuple(ln if ln.predecessors == tuple(pred[pred_ptr[i]:pred_ptr[i + 1]].tolist())
                      else replace(ln, predecessors=tuple(int(j) for j in pred[pred_ptr[i]:pred_ptr[i + 1]]))
                      for i, ln in enumerate(lanes))
        kind = np.array([LANE_KINDS.index(ln.kind) for ln in lanes], dtype=int)
        first = np.full(L, -1, dtype=int)
        first[succ_n > 0] = succ[succ_ptr[:-1][succ_n > 0]]
        al = np.full(L, -1, dtype=int) if adj_left is None else np.asarray(adj_left, dtype=int)
        ar = np.full(L, -1, dtype=int) if adj_right is None else np.asarray(adj_right, dtype=int)
        ls = cls(
            lanes, base, key, np.concatenate([ln.points for ln in lanes]), np.concatenate([ln.heading for ln in lanes]),
            seg_lane, length, np.array([ln.width for ln in lanes]), first,
            vptr, np.concatenate([ln.widths for ln in lanes]), np.concatenate([ln.left_bound for ln in lanes]),
            np.concatenate([ln.right_bound for ln in lanes]), succ_ptr, succ, pred_ptr, pred.astype(int), al, ar,
            np.zeros(L, dtype=bool), np.zeros(L, dtype=bool), np.full(L, -1, dtype=int), np.full(L, -1, dtype=int), kind,
            kind == 0 if usable is None else np.asarray(usable, dtype=bool),
            np.full(L, -1, dtype=int) if junction is None else np.asarray(junction, dtype=int),
            np.full(len(key), np.nan), np.full(len(key), np.nan),
            Markings(base, base - 0.5, np.zeros(L, dtype=int), base - 0.5, np.zeros(L, dtype=int)),
            Zones(*(np.asarray(c) for c in zip(*no_overtaking))) if no_overtaking else
            Zones(np.zeros(0, dtype=int), np.zeros(0), np.zeros(0)),
            MappingProxyType({ln.id: i for i, ln in enumerate(lanes)}),
        )
        bl, same_l = _beside(ls, al, True)
        br, same_r = _beside(ls, ar, False)
        ls = replace(ls, beside_left=bl, beside_right=br, adj_left_same=same_l, adj_right_same=same_r,
                     left=np.where(same_l, al, -1), right=np.where(same_r, ar, -1))
        return replace(ls, markings=_paint(ls, markings)) if markings else ls

    def _vertex(self, lane: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The interval (index into the vertex arrays) holding (lane, s) and the fraction along it
        (beyond a lane's ends: its end interval, the fraction outside [0, 1])."""
        q = self.base[lane] + s
        i = _clamp(np.searchsorted(self.key, q, side="right") - 1, 0, len(self.key) - 2)
        # keep the interval inside the lane (extrapolate at the ends)
        i = np.where(self.seg_lane[i] == lane, i, np.where(self.seg_lane[np.maximum(i - 1, 0)] == lane, i - 1, i + 1))
        i = _clamp(i, 0, len(self.key) - 2)
        dk = self.key[i + 1] - self.key[i]
        return i, np.where(dk > 0, (q - self.key[i]) / np.where(dk > 0, dk, 1.0), 0.0)

    def _interp(self, lane: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i, t = self._vertex(lane, s)
        p = self.points[i] + t[:, None] * (self.points[i + 1] - self.points[i])
        h = self.heading[i] + _clamp(t, 0, 1) * (self.heading[i + 1] - self.heading[i])
        return p, h

    def pose(self, lane: np.ndarray, s: np.ndarray, lateral: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 2) [m] and headings (N,) [rad] of points at (lane index, s [m], lateral [m])."""
        lane = np.asarray(lane, dtype=int)
        s = np.asarray(s, dtype=float)
        p, h = self._interp(lane, s)
        lat = np.broadcast_to(np.asarray(lateral, dtype=float), s.shape)
        return p + lat[:, None] * np.stack([-np.sin(h), np.cos(h)], axis=1), h

    def width_at(self, lane: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Widths (N,) [m] of lanes at (lane index, s [m]) (constant beyond a lane's ends)."""
        lane = np.asarray(lane, dtype=int)
        i, t = self._vertex(lane, np.asarray(s, dtype=float))
        return self.widths[i] + _clamp(t, 0.0, 1.0) * (self.widths[i + 1] - self.widths[i])

    def beside(self, lane: np.ndarray, s: np.ndarray, left: np.ndarray | bool) -> tuple[np.ndarray, np.ndarray]:
        """The lane adjacent to ``lane`` on its left (``left`` true) or right, level with ``s`` [m],
        and s [m] on it: (index (N,), −1 where there is none there; s (N,), NaN then)."""
        lane, s, left = np.broadcast_arrays(np.asarray(lane, dtype=int), np.asarray(s, dtype=float), np.asarray(left, dtype=bool))
        i, t = self._vertex(lane, s)
        table = np.where(left, self.beside_left[i], self.beside_right[i])
        nxt = np.where(left, self.beside_left[i + 1], self.beside_right[i + 1])
        t = _clamp(t, 0.0, 1.0)
        both = ~np.isnan(table) & ~np.isnan(nxt)  # else the nearer end's value, if it has one
        out = np.where(both, table + t * (np.where(both, nxt, 0.0) - np.where(both, table, 0.0)),
                       np.where(t < 0.5, table, nxt))
        nb = np.where(left, self.adj_left[lane], self.adj_right[lane])
        ok = (nb >= 0) & ~np.isnan(out)
        return np.where(ok, nb, -1), np.where(ok, out, np.nan)

    def project(self, lane: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (N, 2) [m] each projected onto its own lane ``lane`` (N,): (s [m], lateral [m]),
        extrapolated along a lane's end intervals beyond its ends. Vectorised over the points and
        their lanes' intervals, in blocks."""
        lane = np.asarray(lane, dtype=int).reshape(-1)
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        s_out, lat_out = np.empty(len(lane)), np.empty(len(lane))
        n_int = (self.vptr[1:] - self.vptr[:-1] - 1)[lane]
        bounds = np.concatenate([[0], np.cumsum(n_int)])
        lo = 0
        while lo < len(lane):  # blocks of about 2 million (point, interval) pairs
            hi = max(lo + 1, int(np.searchsorted(bounds, bounds[lo] + 2_000_000, side="right")) - 1)
            hi = min(hi, len(lane))
            cnt = n_int[lo:hi]
            rep = np.repeat(np.arange(lo, hi), cnt)
            within = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            k = self.vptr[lane[rep]] + within
            a = self.points[k]
            d = self.points[k + 1] - a
            l2 = np.einsum("kj,kj->k", d, d)
            rel = pts[rep] - a
            t = np.einsum("kj,kj->k", rel, d) / np.where(l2 > 0, l2, 1.0)
            t = _clamp(t, np.where(within == 0, -np.inf, 0.0), np.where(within == np.repeat(cnt, cnt) - 1, np.inf, 1.0))
            diff = rel - t[:, None] * d
            dist2 = np.where(l2 > 0, np.einsum("kj,kj->k", diff, diff), np.inf)
            first = _first_min(dist2, cnt)
            kk, tt = k[first], t[first]
            s_out[lo:hi] = self.key[kk] + tt * (self.key[kk + 1] - self.key[kk]) - self.base[lane[lo:hi]]
            dk = d[first]
            cross = dk[:, 0] * rel[first, 1] - dk[:, 1] * rel[first, 0]
            lat_out[lo:hi] = cross / np.sqrt(np.where(l2[first] > 0, l2[first], 1.0))
            lo = hi
        return s_out, lat_out

    def lookup(self, points: np.ndarray, heading: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The lane each point (N, 2) is on: (lane index, s [m], lateral [m]).

        The nearest lane centre line wins; with ``heading`` [rad] given, lanes whose direction
        differs by more than 90° are skipped (so opposite lanes are told apart). Points farther
        than half the lane's width there from every lane get index −1.
        """
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        a = self.points[:-1]
        d = self.points[1:] - a
        l2 = np.einsum("kj,kj->k", d, d)
        rel = pts[:, None, :] - a[None]
        t = _clamp(np.einsum("mkj,kj->mk", rel, d) / np.where(l2 > 0, l2, 1.0), 0, 1)
        diff = rel - t[..., None] * d[None]
        dist2 = np.einsum("mkj,mkj->mk", diff, diff)
        bad = (self.seg_lane < 0) | (l2 <= 0)
        dist2 = np.where(bad[None], np.inf, dist2)
        if heading is not None:
            hs = self.heading[:-1]
            cos = np.cos(np.asarray(heading, dtype=float).reshape(-1, 1) - hs[None])
            dist2 = np.where(cos < 0, np.inf, dist2)
        k = np.argmin(dist2, axis=1)
        m = np.arange(len(pts))
        lane = self.seg_lane[k]
        tk = t[m, k]
        s = self.key[k] + tk * (self.key[k + 1] - self.key[k]) - self.base[np.maximum(lane, 0)]
        cross = d[k, 0] * rel[m, k, 1] - d[k, 1] * rel[m, k, 0]
        lateral = cross / np.sqrt(np.where(l2[k] > 0, l2[k], 1.0))
        half = 0.5 * (self.widths[k] + tk * (self.widths[k + 1] - self.widths[k]))
        off = ~np.isfinite(dist2[m, k]) | (np.abs(lateral) > half)
        return np.where(off, -1, lane), s, lateral


_BESIDE_TOLERANCE = 1.0  # [m] how far past an adjacent lane's end a point may project and still lie beside it (its end)


def _beside(ls: LaneSet, adj: np.ndarray, left: bool) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex, s [m] on the adjacent lane ``adj`` on that side level with it (NaN where the
    point beside it lies past that lane's ends); per lane whether the adjacent lane runs the same
    way. Lanes drawn from one reference line (vertex for vertex, the rungs across both lanes) map
    vertex to vertex exactly; others by projecting the boundary point onto the adjacent lane."""
    K = len(ls.key)
    out = np.full(K, np.nan)
    same = np.zeros(len(adj), dtype=bool)
    have = np.flatnonzero(adj >= 0)
    if not len(have):
        return out, same
    todo = []
    for i in have:  # one pass per adjacency (a handful of array operations each)
        j = int(adj[i])
        a, b = ls.vptr[i], ls.vptr[i + 1]
        c, d = ls.vptr[j], ls.vptr[j + 1]
        if b - a == d - c:
            for rev in (False, True):
                q = ls.points[c:d][::-1] if rev else ls.points[c:d]
                rel = q - ls.points[a:b]
                along = np.cos(ls.heading[a:b]) * rel[:, 0] + np.sin(ls.heading[a:b]) * rel[:, 1]
                if np.all(np.abs(along) <= 1e-6 * (1.0 + np.hypot(rel[:, 0], rel[:, 1]))):
                    sj = ls.key[c:d] - ls.base[j]
                    out[a:b] = sj[::-1] if rev else sj
                    same[i] = not rev
                    break
            else:
                todo.append(i)
        else:
            todo.append(i)
    if todo:
        idx = np.concatenate([np.arange(ls.vptr[i], ls.vptr[i + 1]) for i in todo])
        owner = np.repeat(np.asarray(todo), [ls.vptr[i + 1] - ls.vptr[i] for i in todo])
        edge = ls.left_bound[idx] if left else ls.right_bound[idx]
        nb = adj[owner]
        s, _ = ls.project(nb, edge)
        ok = (s >= -_BESIDE_TOLERANCE) & (s <= ls.length[nb] + _BESIDE_TOLERANCE)
        out[idx] = np.where(ok, np.clip(s, 0.0, ls.length[nb]), np.nan)
        _, h = ls.pose(nb, np.clip(s, 0.0, ls.length[nb]))
        agree = np.cos(h - ls.heading[idx])
        for i in todo:
            m = owner == i
            same[i] = float(np.sum(agree[m])) > 0
    return out, same


def _paint(ls: LaneSet, rows: Sequence[MarkingRow]) -> Markings:
    """The markings of every boundary from painted rows: each row first mirrored onto the lane across
    that boundary (over the stretch beside it), then every lane's own rows, later rows over earlier
    ones; unpainted stretches are unmarked."""
    mirrored: list[MarkingRow] = []
    for lane, left, s0, s1, kind in rows:
        nb = int(ls.adj_left[lane] if left else ls.adj_right[lane])
        if nb < 0:
            continue
        same = bool(ls.adj_left_same[lane] if left else ls.adj_right_same[lane])
        _, sb = ls.beside(np.array([lane, lane]), np.clip(np.array([s0, s1]), 0.0, ls.length[lane]), left)
        if np.isnan(sb).any():
            sb = np.where(np.isnan(sb), np.array([0.0, ls.length[nb]]) if same else np.array([ls.length[nb], 0.0]), sb)
        nb_left = left != same  # across a same-way boundary the neighbour sees it on the other side
        mirrored.append((nb, nb_left, float(sb.min()), float(sb.max()), int(MIRRORED[kind])))
    per_side: dict[tuple[int, bool], list[tuple[float, float, int]]] = {}
    for lane, left, s0, s1, kind in mirrored + list(rows):
        per_side.setdefault((int(lane), bool(left)), []).append((float(s0), float(s1), int(kind)))
    keys: dict[bool, list[float]] = {True: list(ls.base - 0.5), False: list(ls.base - 0.5)}
    types: dict[bool, list[int]] = {True: [0] * len(ls.base), False: [0] * len(ls.base)}
    for (lane, left), paint in per_side.items():
        end = float(ls.length[lane])  # a piece painted to the lane's end holds beyond it
        cuts = sorted({0.0, *(max(a, 0.0) for a, _, _ in paint), *(max(b, 0.0) for _, b, _ in paint if b < end - 1e-9)})
        prev = 0
        for a, b in zip(cuts, cuts[1:] + [math.inf]):
            mid = 0.5 * (a + b) if math.isfinite(b) else a + 1.0
            kind = next((k for s0, s1, k in reversed(paint) if s0 <= mid <= (s1 if s1 < end - 1e-9 else math.inf)), 0)
            if kind != prev:  # (from the lane's first key on when painted from its start)
                keys[left].append(float(ls.base[lane] + a) if a > 0 else float(ls.base[lane] - 0.5))
                types[left].append(kind)
                prev = kind
    out = []
    for left in (True, False):
        order = np.argsort(np.asarray(keys[left]), kind="stable")
        out += [np.asarray(keys[left])[order], np.asarray(types[left], dtype=int)[order]]
    return Markings(ls.base, *out)


@dataclass(frozen=True, eq=False)
class Route(Polyline):
    """The reference path from A to B: equally spaced vertices (``spacing`` [m]) with heading,
    the speed limits in force along it and the desired speed profile.

    ``limit_s``/``limit_v``: the limit ``limit_v[j]`` [m/s] holds from route position
    ``limit_s[j]`` [m] on (``limit_s[0] == 0``). ``v_des`` (K,) [m/s] is the desired speed at each
    vertex (:func:`twolevel.world.speed_profile.speed_profile`): the limit, lowered in and ahead
    of bends, of lower limits and of B when stopping there, within comfort limits. ``width`` (K,) [m] is the lane width along it.
    ``pieces``: (lane index, s_from, s_to, route s_from) for each lane the route runs along.
    """

    spacing: float = 0.5
    limit_s: np.ndarray = field(default_factory=lambda: np.zeros(1))
    limit_v: np.ndarray = field(default_factory=lambda: np.full(1, 13.89))
    v_des: np.ndarray = field(default_factory=lambda: np.zeros(0))
    width: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pieces: tuple[tuple[int, float, float, float], ...] = ()

    @property
    def lanes(self) -> tuple[int, ...]:
        """The indices of the lanes the route runs along, in order."""
        return tuple(p[0] for p in self.pieces)

    def limit_at(self, s: np.ndarray | float) -> np.ndarray:
        """Speed limit [m/s] in force at route position ``s`` [m]."""
        return self.limit_v[step_index(self.limit_s, np.asarray(s, dtype=float))]

    def desired_speed_at(self, s: np.ndarray | float) -> np.ndarray:
        """Desired speed [m/s] at route position ``s`` [m] (linear between vertices)."""
        return np.interp(np.asarray(s, dtype=float), self.s, self.v_des)

    def width_at(self, s: np.ndarray | float) -> np.ndarray:
        """Width [m] of the lane the route runs along at ``s`` [m]."""
        i, _ = self._index(np.asarray(s, dtype=float))
        return self.width[i]

    def from_lane(self, lane: np.ndarray, s_lane: np.ndarray) -> np.ndarray:
        """Route position [m] of points given as (lane index, s on that lane [m]); NaN off the route."""
        lane = np.asarray(lane)
        s_lane = np.asarray(s_lane, dtype=float)
        out = np.full(np.broadcast(lane, s_lane).shape, np.nan)
        for idx, a, b, start in self.pieces:  # a handful of pieces
            hit = (lane == idx) & (s_lane >= a - 1e-9) & (s_lane <= b + 1e-9) & np.isnan(out)
            out = np.where(hit, start + s_lane - a, out)
        return out

    def project_near(self, points: np.ndarray, s_center: np.ndarray, half_window: float) -> tuple[np.ndarray, np.ndarray]:
        """Project points (M, 2) [m], each only onto the route within ``s_center`` ± ``half_window``
        [m] (M,) — a fixed-width search that stays fast for many points on a long route.

        Exact (the nearest interval of the window, the first on ties), found in two passes: the
        distances to the window's vertices bound every interval's distance (≥ the nearer end's
        distance − half its length, ≤ either end's distance), and only the intervals whose lower
        bound does not exceed the smallest upper bound are projected onto."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        M = len(pts)
        n = len(self.s) - 1
        w = min(int(math.ceil(2 * half_window / self.spacing)) + 2, n)
        i0 = _clamp(np.floor((np.asarray(s_center, dtype=float) - half_window) / self.spacing).astype(int), 0, n - w)
        half_len = 0.5 * _max_interval(self)
        vidx = i0[:, None] + np.arange(w + 1)[None, :]  # (M, W+1) vertex indices
        dv = np.hypot(self.points[:, 0][vidx] - pts[:, 0:1], self.points[:, 1][vidx] - pts[:, 1:2])
        ub = dv.min(axis=1, keepdims=True)
        lb = np.minimum(dv[:, :-1], dv[:, 1:]) - half_len
        idx = vidx[:, :-1]
        cand = (lb <= ub + 1e-9) | (idx == 0) | (idx == n - 1)  # end intervals extrapolate: always tried
        m, k = np.nonzero(cand)
        i = idx[m, k]
        a = self.points[i]
        d = self.points[i + 1] - a
        l2 = np.einsum("mj,mj->m", d, d)
        rel = pts[m] - a
        t_raw = np.einsum("mj,mj->m", rel, d) / np.where(l2 > 0, l2, 1.0)
        t = _clamp(t_raw, np.where(i == 0, -np.inf, 0.0), np.where(i == n - 1, np.inf, 1.0))
        diff = rel - t[:, None] * d
        dist2 = np.full((M, w), np.inf)
        dist2[m, k] = np.einsum("mj,mj->m", diff, diff)
        pos = np.full((M, w), -1)
        pos[m, k] = np.arange(len(m))
        c = pos[np.arange(M), np.argmin(dist2, axis=1)]  # the chosen candidate of each point
        i, t, d, rel, l2 = i[c], t[c], d[c], rel[c], l2[c]
        s = self.s[i] + t * (self.s[i + 1] - self.s[i])
        cross = d[:, 0] * rel[:, 1] - d[:, 1] * rel[:, 0]
        return s, cross / np.sqrt(np.where(l2 > 0, l2, 1.0))

    def reference(self, s0: float, v0: float, H: int, dt: float | Sequence[float], a_max: float = 2.0,
                  d_max: float | None = None, *, beyond: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Predicted route positions s_k [m] and speeds v_k [m/s], k = 0..H, advancing from
        (s0, v0) towards the desired speed with acceleration ≤ ``a_max`` and deceleration ≤
        ``d_max`` (None: ``a_max``) [m/s²], over H steps of ``dt`` [s] (or of the H step lengths
        ``dt``); positions stop at the route's end unless ``beyond`` (a route that does not stop
        there: the reference runs on along its last interval's straight extension)."""
        d_max = a_max if d_max is None else d_max
        end = math.inf if beyond else float(self.s[-1])
        s = np.empty(H + 1)
        v = np.empty(H + 1)
        s[0], v[0] = s0, v0
        h = [float(dt)] * H if np.ndim(dt) == 0 else [float(x) for x in dt]  # type: ignore[arg-type, union-attr]
        for k in range(H):  # H ≈ 10–20 scalar steps
            target = float(self.desired_speed_at(s[k]))
            v[k + 1] = min(max(target, v[k] - d_max * h[k]), v[k] + a_max * h[k])
            s[k + 1] = min(s[k] + 0.5 * (v[k] + v[k + 1]) * h[k], end)
        return s, v


_INTERVALS: "weakref.WeakKeyDictionary[Polyline, float]" = weakref.WeakKeyDictionary()


def _first_min(values: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Index into ``values`` of the smallest of each consecutive group of ``counts`` (each ≥ 1)
    values, the first on ties; NaNs are passed over (a group of NaNs only: its first). Linear,
    where sorting the groups (a lexsort) costs n log n."""
    starts = np.cumsum(counts) - counts
    least = np.fmin.reduceat(values, starts)
    pos = np.where(values == np.repeat(least, counts), np.arange(len(values)), len(values))
    first = np.minimum.reduceat(pos, starts)
    return np.where(first == len(values), starts, first)


def _max_interval(line: Polyline) -> float:
    """The longest interval of a polyline [m] (computed once per line)."""
    got = _INTERVALS.get(line)
    if got is None:
        seg = np.diff(line.points, axis=0)
        got = float(np.max(np.hypot(seg[:, 0], seg[:, 1]), initial=0.0))
        _INTERVALS[line] = got
    return got


def resample(line: Polyline, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Equally spaced vertices along ``line`` at most ``spacing`` [m] apart:
    (s, points, heading, kappa per interval)."""
    n = max(1, int(math.ceil(line.length / spacing)))
    s = line.s[0] + np.linspace(0.0, line.length, n + 1)
    mid = 0.5 * (s[:-1] + s[1:])
    return s - line.s[0], line.position(s), line.heading_at(s), line.curvature_at(mid)
