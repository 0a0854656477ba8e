"""The drivable area: the union of a map's carriageway lanes, each its centre line widened to its
width there (every lane kind but sidewalks, crosswalks and cycle lanes: :data:`ROAD_KINDS`).

:func:`outside` gives, for points, how far they are outside it (> 0) or how deep inside the
lane that holds them best (≤ 0); :func:`box_outside` does it for the ego's box over a whole
trace (its worst corner at each step; inside, how close its closest corner comes to the area's
edge, :func:`edge_depth`, the lines between lanes being no edge). "Left the map" is the extreme
case: the reference point itself is outside every lane. Lanes are capsules: past a lane's end the distance is to its
end point, unless the lane continues into another. Vectorised over points and lane intervals, in
blocks. :func:`area_outside` measures the box against the route's drivable area instead (the
lateral interval :func:`twolevel.world.area.drivable_area` allows at each route position).
"""

from __future__ import annotations

import weakref
from typing import Sequence

import numpy as np

from twolevel.models.obb import box_corners
from twolevel.world.geometry import LANE_KINDS, LaneSet, Polyline, Route

__all__ = ["outside", "box_outside", "area_outside", "lane_edges", "road_band", "ROAD_KINDS", "road_lanes",
           "edge_depth", "EDGE_REACH"]

ROAD_KINDS = ("driving", "shoulder", "parking", "bus", "restricted")
"""Lane kinds that make up the road a vehicle may be on (not sidewalks, crosswalks, cycle lanes)."""


def road_lanes(lanes: LaneSet) -> np.ndarray | None:
    """The lanes of the road (:data:`ROAD_KINDS`), or None when that is every lane."""
    road = np.isin(lanes.kind, [LANE_KINDS.index(k) for k in ROAD_KINDS])
    return None if road.all() else np.flatnonzero(road)

_BLOCK = 256  # points per block: keeps the (points × intervals) arrays small


def _dead_ends(lanes: LaneSet, extend: float) -> tuple[np.ndarray, np.ndarray]:
    """Per interval, the lowest and highest projection parameter allowed: [0, 1], stretched by
    ``extend`` [m] at the start of a lane nothing leads into and the end of one leading nowhere."""
    seg = lanes.seg_lane
    n = len(seg)
    low, high = np.zeros(n), np.ones(n)
    if extend <= 0 or n == 0:
        return low, high
    d = np.diff(lanes.points, axis=0)
    length = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
    entered = {j for lane in lanes.lanes for j in lane.successors}
    prev = np.concatenate(([-1], seg[:-1]))
    nxt = np.concatenate((seg[1:], [-1]))
    for k in np.flatnonzero((seg >= 0) & (prev != seg)):
        if int(seg[k]) not in entered:
            low[k] = -extend / length[k]
    for k in np.flatnonzero((seg >= 0) & (nxt != seg)):
        if not lanes.lanes[int(seg[k])].successors:
            high[k] = 1.0 + extend / length[k]
    return low, high


def outside(lanes: LaneSet, points: np.ndarray, only: Sequence[int] | None = None, extend: float = 0.0) -> np.ndarray:
    """Distance [m] of each point (M, 2) outside the drivable area (> 0), or minus its depth
    inside the lane that holds it most (≤ 0). ``only``: lane indices making up the area
    (default: the lanes of the road, :func:`road_lanes`). ``extend`` [m]: the map's dead ends (a
    lane start nothing leads into, a lane end leading nowhere) reach this far on, straight. A
    lane's half width is its width where the point projects (constant past its ends)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    a = lanes.points[:-1]
    d = lanes.points[1:] - a
    l2 = np.einsum("kj,kj->k", d, d)
    low, high = _dead_ends(lanes, extend)
    keep = (lanes.seg_lane >= 0) & (l2 > 0)
    only = road_lanes(lanes) if only is None else only
    if only is not None:
        keep &= np.isin(lanes.seg_lane, np.asarray(list(only), dtype=int))
    w0, w1 = lanes.widths[:-1][keep], lanes.widths[1:][keep]
    a, d, l2, low, high = a[keep], d[keep], l2[keep], low[keep], high[keep]
    out = np.full(len(pts), np.inf)
    if a.size == 0:
        return out
    for lo in range(0, len(pts), _BLOCK):
        rel = pts[lo:lo + _BLOCK, None, :] - a[None]
        t = np.clip(np.einsum("mkj,kj->mk", rel, d) / l2, low, high)
        diff = rel - t[..., None] * d[None]
        dist = np.sqrt(np.einsum("mkj,mkj->mk", diff, diff))
        half = 0.5 * (w0 + np.clip(t, 0.0, 1.0) * (w1 - w0))
        out[lo:lo + _BLOCK] = (dist - half).min(axis=1)
    return out


_EDGE_PROBE = 0.05  # [m] how far beyond a lane's edge a point is probed to tell the area's edge
EDGE_REACH = 25.0
"""[m] How far from a point :func:`edge_depth` looks for the area's edge (deeper counts as that)."""
_EDGES: "weakref.WeakKeyDictionary[LaneSet, dict[tuple[int, ...] | None, tuple[np.ndarray, ...]]]" = \
    weakref.WeakKeyDictionary()


def _edge_pieces(lanes: LaneSet, only: Sequence[int] | None) -> tuple[np.ndarray, ...]:
    """Every lane edge piece of the area (both sides of every interval): start (M, 2), direction
    (M, 2), the probe point :data:`_EDGE_PROBE` beyond its middle (M, 2) [m], and whether it bounds
    the area (M,) (−1: not yet probed; filled in as pieces are needed). Once per lane set."""
    key = None if only is None else tuple(sorted(int(i) for i in only))
    cached = _EDGES.setdefault(lanes, {})
    if key not in cached:
        keep = lanes.seg_lane >= 0
        area = road_lanes(lanes) if only is None else np.asarray(list(only), dtype=int)
        if area is not None:
            keep &= np.isin(lanes.seg_lane, area)
        k = np.flatnonzero(keep)
        mid_c = 0.5 * (lanes.points[k] + lanes.points[k + 1])
        a = np.concatenate([lanes.left_bound[k], lanes.right_bound[k]]).reshape(-1, 2)
        b = np.concatenate([lanes.left_bound[k + 1], lanes.right_bound[k + 1]]).reshape(-1, 2)
        mid = 0.5 * (a + b)
        away = mid - np.concatenate([mid_c, mid_c]).reshape(-1, 2)
        away /= np.maximum(np.hypot(away[:, 0], away[:, 1]), 1e-12)[:, None]
        cached[key] = (a, b - a, mid + _EDGE_PROBE * away, np.full(len(a), -1, dtype=np.int8))
    return cached[key]


def edge_depth(lanes: LaneSet, points: np.ndarray, only: Sequence[int] | None = None) -> np.ndarray:
    """Distance [m] of each point (M, 2) from the drivable area's edge, at most
    :data:`EDGE_REACH`: for a point inside the area, how deep inside it is — across the line
    between two of its lanes, unlike :func:`outside`'s depth in one lane. The edge is made of the
    lane edge pieces with no lane of the area (``only``, as for :func:`outside`) beyond them
    (probed :data:`_EDGE_PROBE` beyond their middle, only those within reach of the points); the
    ends of lanes leading nowhere are not counted."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    out = np.full(len(pts), EDGE_REACH)
    if not len(pts):
        return out
    a, d, probe, outer = _edge_pieces(lanes, only)
    lo, hi = pts.min(axis=0) - EDGE_REACH, pts.max(axis=0) + EDGE_REACH
    b = a + d
    near = np.all((np.minimum(a, b) <= hi) & (np.maximum(a, b) >= lo), axis=1)  # pieces within reach of the points
    new = near & (outer < 0)
    if new.any():
        outer[new] = outside(lanes, probe[new], only) > 0
    use = np.flatnonzero(near & (outer == 1))
    if not len(use):
        return out
    a, d = a[use], d[use]
    l2 = np.maximum(np.einsum("kj,kj->k", d, d), 1e-12)
    for i in range(0, len(pts), _BLOCK):
        rel = pts[i:i + _BLOCK, None, :] - a[None]
        t = np.clip(np.einsum("mkj,kj->mk", rel, d) / l2, 0.0, 1.0)
        diff = rel - t[..., None] * d[None]
        out[i:i + _BLOCK] = np.minimum(out[i:i + _BLOCK], np.sqrt(np.einsum("mkj,mkj->mk", diff, diff).min(axis=1)))
    return out


def box_outside(lanes: LaneSet, x: np.ndarray, y: np.ndarray, psi: np.ndarray, length: float, width: float,
                only: Sequence[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For each sample of a trajectory, how far the box's worst corner is outside the drivable
    area [m] (≤ 0: every corner inside, and minus how close the closest corner comes to the
    area's edge, :func:`edge_depth`: a corner over the line between two lanes is not at an edge),
    and the reference point's distance outside every lane. At the map's dead ends the area reaches
    half the box's length on: a box is off the end of the map once its reference point is."""
    x, y, psi = (np.asarray(c, dtype=float) for c in (x, y, psi))
    centre = np.stack([x, y], axis=-1)
    corners = box_corners(x, y, psi, length, width).reshape(-1, 2)  # (N·4, 2)
    each = outside(lanes, corners, only, 0.5 * length)
    inside = each <= 0
    if inside.any():  # deeper than in one lane where the lanes beside it are part of the area
        each[inside] = np.minimum(each[inside], -edge_depth(lanes, corners[inside], only))
    worst = each.reshape(-1, 4).max(axis=1)
    return worst, outside(lanes, centre)


def area_outside(lanes: LaneSet, route: Route, x: np.ndarray, y: np.ndarray, psi: np.ndarray, length: float,
                 width: float) -> np.ndarray:
    """For each sample of a trajectory, how far the box's worst corner is outside the route's
    drivable area [m] (:func:`twolevel.world.area.drivable_area`, the oncoming lane included where
    passing is allowed; ≤ 0: every corner inside): each corner projected onto the route near the
    reference point's route position, against the lateral interval allowed there."""
    from twolevel.world.area import drivable_area

    x, y, psi = (np.asarray(c, dtype=float) for c in (x, y, psi))
    s_ref, _ = route.local_coordinates(np.stack([x, y], axis=-1))
    corners = box_corners(x, y, psi, length, width).reshape(-1, 2)
    s, e = route.project_near(corners, np.repeat(s_ref, 4), 0.5 * float(np.hypot(length, width)) + 2.0)
    area = drivable_area(lanes, route, np.clip(s, 0.0, route.length))
    return np.maximum(e - area.hi, area.lo - e).reshape(-1, 4).max(axis=1)


def lane_edges(lanes: LaneSet, spacing: float = 2.0) -> list[list[list[float]]]:
    """Both edges of every lane as polylines [[x, y], …] sampled about every ``spacing`` [m]
    (for figures: the boundary of the drivable area is where an edge borders no other lane)."""
    out = []
    for lane in lanes.lanes:
        n = max(2, int(np.ceil(lane.length / spacing)) + 1)
        s = np.linspace(lane.s[0], lane.s[-1], n)
        for side in (-0.5, 0.5):
            out.append(np.round(lane.position(s, side * lane.width_at(s)), 2).tolist())
    return out


def road_band(lanes: LaneSet, route: Polyline, s: np.ndarray, reach: float = 15.0, step: float = 0.1
              ) -> tuple[np.ndarray, np.ndarray]:
    """How far the drivable area reaches to the left (+) and right (−) of the route [m] at route
    positions ``s`` (N,) [m]: the first lateral offset (within ``reach``, every ``step``) whose
    point is outside every lane."""
    s = np.asarray(s, dtype=float)
    offsets = np.arange(step, reach + step / 2, step)
    out = []
    for sign in (1.0, -1.0):
        lat = sign * offsets
        pts = route.position(np.repeat(s, lat.size), np.tile(lat, s.size)).reshape(-1, 2)
        off = outside(lanes, pts).reshape(s.size, lat.size) > 0
        first = np.where(off.any(axis=1), np.argmax(off, axis=1), lat.size - 1)
        out.append(lat[first] - sign * step / 2)
    return out[0], out[1]
