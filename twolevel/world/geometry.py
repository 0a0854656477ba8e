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
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from twolevel.world.schema import Road

__all__ = [
    "Polyline", "Lane", "LaneSet", "Route", "sample_road", "lane_from_reference", "concatenate", "resample",
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
        i = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.s) - 2)
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
        t = np.clip(t, 0.0, 1.0)
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
        t = np.clip(t_raw, low, high)
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


@dataclass(frozen=True, eq=False)
class Lane(Polyline):
    """A lane: its centre line in the direction of travel, ``width`` [m], and the indices of the
    lanes traffic continues into."""

    id: str = ""
    index: int = 0
    width: float = 3.5
    successors: tuple[int, ...] = ()

    def on_lane(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether points (..., 2) lie on the lane (|lateral| ≤ width/2 + margin, 0 ≤ s ≤ length)."""
        s, lat = self.local_coordinates(points)
        return (np.abs(lat) <= self.width / 2 + margin) & (s >= -margin) & (s <= self.length + margin)


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
    successors: tuple[int, ...] = (),
) -> Lane:
    """The lane ``offset`` [m] left of the reference line, ordered in its direction of travel."""
    normal = np.stack([-np.sin(ref.heading), np.cos(ref.heading)], axis=1)
    pts = ref.points + offset * normal
    dref = np.diff(ref.s)
    chord = np.hypot(*np.diff(pts, axis=0).T)
    ds = np.where(ref.kappa != 0, dref * (1 - offset * ref.kappa), chord)
    kappa = ref.kappa / (1 - offset * ref.kappa)
    heading = ref.heading
    if direction == "backward":
        pts, ds, kappa, heading = pts[::-1], ds[::-1], -kappa[::-1], heading[::-1] + math.pi
    s = np.concatenate([[0.0], np.cumsum(ds)])
    return Lane(np.ascontiguousarray(pts), s, np.ascontiguousarray(heading), np.ascontiguousarray(kappa),
                id=lane_id, index=index, width=width, successors=successors)


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


@dataclass(frozen=True, eq=False)
class LaneSet:
    """All lanes of a map in concatenated arrays, for vectorised work over many vehicles on
    many lanes: position and heading from (lane index, s), and lane lookup for points."""

    lanes: tuple[Lane, ...]
    base: np.ndarray  # (L,) offset of each lane's s in the global key [m]
    key: np.ndarray  # (K,) global key = base[lane] + s
    points: np.ndarray  # (K, 2)
    heading: np.ndarray  # (K,)
    seg_lane: np.ndarray  # (K-1,) lane of each interval, -1 between lanes
    length: np.ndarray  # (L,) [m]
    width: np.ndarray  # (L,) [m]
    successor: np.ndarray  # (L,) first successor's index or -1

    @classmethod
    def of(cls, lanes: tuple[Lane, ...]) -> "LaneSet":
        length = np.array([ln.length for ln in lanes])
        base = np.concatenate([[0.0], np.cumsum(length + 1.0)[:-1]])
        key = np.concatenate([b + ln.s for b, ln in zip(base, lanes)])
        lane_of_vertex = np.concatenate([np.full(len(ln.s), i) for i, ln in enumerate(lanes)])
        seg_lane = np.where(lane_of_vertex[:-1] == lane_of_vertex[1:], lane_of_vertex[:-1], -1)
        return cls(
            lanes, base, key, np.concatenate([ln.points for ln in lanes]),
            np.concatenate([ln.heading for ln in lanes]), seg_lane, length,
            np.array([ln.width for ln in lanes]),
            np.array([ln.successors[0] if ln.successors else -1 for ln in lanes]),
        )

    def _interp(self, lane: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = self.base[lane] + s
        i = np.clip(np.searchsorted(self.key, q, side="right") - 1, 0, len(self.key) - 2)
        # keep the interval inside the lane (extrapolate at the ends)
        i = np.where(self.seg_lane[i] == lane, i, np.where(self.seg_lane[np.maximum(i - 1, 0)] == lane, i - 1, i + 1))
        i = np.clip(i, 0, len(self.key) - 2)
        dk = self.key[i + 1] - self.key[i]
        t = np.where(dk > 0, (q - self.key[i]) / np.where(dk > 0, dk, 1.0), 0.0)
        p = self.points[i] + t[:, None] * (self.points[i + 1] - self.points[i])
        h = self.heading[i] + np.clip(t, 0, 1) * (self.heading[i + 1] - self.heading[i])
        return p, h

    def pose(self, lane: np.ndarray, s: np.ndarray, lateral: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 2) [m] and headings (N,) [rad] of points at (lane index, s [m], lateral [m])."""
        lane = np.asarray(lane, dtype=int)
        s = np.asarray(s, dtype=float)
        p, h = self._interp(lane, s)
        lat = np.broadcast_to(np.asarray(lateral, dtype=float), s.shape)
        return p + lat[:, None] * np.stack([-np.sin(h), np.cos(h)], axis=1), h

    def lookup(self, points: np.ndarray, heading: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The lane each point (N, 2) is on: (lane index, s [m], lateral [m]).

        The nearest lane centre line wins; with ``heading`` [rad] given, lanes whose direction
        differs by more than 90° are skipped (so opposite lanes are told apart). Points farther
        than half a lane width from every lane get index −1.
        """
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        a = self.points[:-1]
        d = self.points[1:] - a
        l2 = np.einsum("kj,kj->k", d, d)
        rel = pts[:, None, :] - a[None]
        t = np.clip(np.einsum("mkj,kj->mk", rel, d) / np.where(l2 > 0, l2, 1.0), 0, 1)
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
        s = self.key[k] + t[m, k] * (self.key[k + 1] - self.key[k]) - self.base[np.maximum(lane, 0)]
        cross = d[k, 0] * rel[m, k, 1] - d[k, 1] * rel[m, k, 0]
        lateral = cross / np.sqrt(np.where(l2[k] > 0, l2[k], 1.0))
        off = ~np.isfinite(dist2[m, k]) | (np.abs(lateral) > self.width[np.maximum(lane, 0)] / 2)
        return np.where(off, -1, lane), s, lateral


@dataclass(frozen=True, eq=False)
class Route(Polyline):
    """The reference path from A to B: equally spaced vertices (``spacing`` [m]) with heading,
    the speed limits in force along it and the desired speed profile.

    ``limit_s``/``limit_v``: the limit ``limit_v[j]`` [m/s] holds from route position
    ``limit_s[j]`` [m] on (``limit_s[0] == 0``). ``v_des`` (K,) [m/s] is the desired speed at each
    vertex: the limit, lowered ahead of lower limits (and of B when stopping there) so that
    decelerating at ``decel`` [m/s²] meets them. ``width`` (K,) [m] is the lane width along it.
    ``pieces``: (lane index, s_from, s_to, route s_from) for each lane the route runs along.
    """

    spacing: float = 0.5
    limit_s: np.ndarray = field(default_factory=lambda: np.zeros(1))
    limit_v: np.ndarray = field(default_factory=lambda: np.full(1, 13.89))
    v_des: np.ndarray = field(default_factory=lambda: np.zeros(0))
    width: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pieces: tuple[tuple[int, float, float, float], ...] = ()

    def limit_at(self, s: np.ndarray | float) -> np.ndarray:
        """Speed limit [m/s] in force at route position ``s`` [m]."""
        j = np.clip(np.searchsorted(self.limit_s, np.asarray(s, dtype=float), side="right") - 1, 0, len(self.limit_s) - 1)
        return self.limit_v[j]

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
        i0 = np.clip(np.floor((np.asarray(s_center, dtype=float) - half_window) / self.spacing).astype(int), 0, n - w)
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
        t = np.clip(t_raw, np.where(i == 0, -np.inf, 0.0), np.where(i == n - 1, np.inf, 1.0))
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

    def reference(self, s0: float, v0: float, H: int, dt: float | Sequence[float], a_max: float = 2.0
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Predicted route positions s_k [m] and speeds v_k [m/s], k = 0..H, advancing from
        (s0, v0) towards the desired speed with |acceleration| ≤ ``a_max`` [m/s²], over H steps
        of ``dt`` [s] (or of the H step lengths ``dt``)."""
        s = np.empty(H + 1)
        v = np.empty(H + 1)
        s[0], v[0] = s0, v0
        h = [float(dt)] * H if np.ndim(dt) == 0 else [float(x) for x in dt]  # type: ignore[arg-type, union-attr]
        for k in range(H):  # H ≈ 10–20 scalar steps
            target = float(self.desired_speed_at(s[k]))
            v[k + 1] = min(max(target, v[k] - a_max * h[k]), v[k] + a_max * h[k])
            s[k + 1] = min(s[k] + 0.5 * (v[k] + v[k + 1]) * h[k], self.s[-1])
        return s, v


_INTERVALS: "weakref.WeakKeyDictionary[Polyline, float]" = weakref.WeakKeyDictionary()


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
