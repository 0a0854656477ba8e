"""Oriented boxes and convex polygons: corners from poses, signed separation, the overlap test.

The one home of the geometry of vehicle bodies (every package that needs a box's corners, the
distance between two boxes or whether two convex polygons overlap calls this module):

* :func:`box_corners` — the corners of boxes from their poses;
* :func:`box_separation` — the low level's ``collision_free`` distance between rectangles given
  by their corners: the Euclidean distance when they are apart, and minus the penetration depth
  (the length of the smallest translation that separates them, found by the separating-axis
  theorem over the four edge normals) when they overlap. Exact for convex polygons; the sign says
  whether the boxes overlap, touching boxes give 0;
* :func:`pose_separation` — the same value from the poses directly, several times faster (the
  sensors' ``min_gap``, the simulator's collisions);
* :func:`intersects` / :func:`overlaps` — the separating-axis test of convex polygons given by
  points and axes (:func:`edge_axes`, :func:`rect_axes`): a boolean, sound for the safety layer's
  swept regions.

Everything is vectorised over leading dimensions. Units: m, rad.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["box_corners", "box_separation", "pose_separation", "edge_axes", "rect_axes", "intersects", "overlaps"]


def box_corners(X: ArrayLike, Y: ArrayLike, psi: ArrayLike, length: ArrayLike, width: ArrayLike) -> NDArray[np.float64]:
    """Corners (..., 4, 2) [m] of boxes length × width [m] centred at (X, Y) [m], heading ψ [rad];
    every argument broadcasts (one size for all boxes, or one per box).

    Counter-clockwise from the rear right: rear-right, front-right, front-left, rear-left.
    """
    X, Y, psi, length, width = np.broadcast_arrays(*(np.asarray(a, float) for a in (X, Y, psi, length, width)))
    c, s = np.cos(psi)[..., None], np.sin(psi)[..., None]
    lx = 0.5 * length[..., None] * np.array([-1.0, 1.0, 1.0, -1.0])
    ly = 0.5 * width[..., None] * np.array([-1.0, -1.0, 1.0, 1.0])
    return np.stack([X[..., None] + c * lx - s * ly, Y[..., None] + s * lx + c * ly], axis=-1)


def _point_segment_distance(p: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance from points p to segments [a, b]; arrays (..., 2) broadcastable."""
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-300), 0.0, 1.0)
    d = p - (a + t[..., None] * ab)
    return np.sqrt(np.sum(d * d, axis=-1))


def box_separation(ego_boxes: ArrayLike, other_boxes: ArrayLike) -> NDArray[np.float64]:
    """Signed distance [m] between convex quadrilaterals (rectangles) (..., 4, 2), broadcast.

    Positive: the gap between them; negative: minus the penetration depth; 0 when touching.
    """
    A = np.asarray(ego_boxes, dtype=float)
    B = np.asarray(other_boxes, dtype=float)
    A, B = np.broadcast_arrays(A, B)
    axes = np.concatenate([rect_axes(A), rect_axes(B)], axis=-2)  # (..., 4, 2)
    pa = np.einsum("...kd,...cd->...kc", axes, A)  # projections (..., 4 axes, 4 corners)
    pb = np.einsum("...kd,...cd->...kc", axes, B)
    overlap = np.minimum(pa.max(-1), pb.max(-1)) - np.maximum(pa.min(-1), pb.min(-1))
    penetration = overlap.min(-1)  # > 0 on every axis ⇔ overlapping; then the exact depth

    # when apart: the closest pair of features is a corner of one box and an edge of the other
    nxt = np.roll(np.arange(4), -1)
    pa_, a0, a1 = A[..., :, None, :], B[..., None, :, :], B[..., None, nxt, :]
    pb_, b0, b1 = B[..., :, None, :], A[..., None, :, :], A[..., None, nxt, :]
    gap = np.minimum(_point_segment_distance(pa_, a0, a1).min(axis=(-1, -2)),
                     _point_segment_distance(pb_, b0, b1).min(axis=(-1, -2)))
    return np.where(penetration > 0.0, -penetration, gap)


def pose_separation(x1: np.ndarray, y1: np.ndarray, psi1: np.ndarray, l1: np.ndarray | float, w1: np.ndarray | float,
                    x2: np.ndarray, y2: np.ndarray, psi2: np.ndarray, l2: np.ndarray | float,
                    w2: np.ndarray | float) -> np.ndarray:
    """Signed separation [m] of oriented rectangles given by centre (x, y) [m], heading ψ [rad],
    length and width [m], elementwise with broadcasting: the distance between them when apart,
    minus the smallest overlap of their projections on the four edge normals (SAT) when they
    overlap — the value of :func:`box_separation`, computed from the poses (corner-to-rectangle
    distances in each box's frame), several times faster. The sensors' ``min_gap`` and the
    simulator's collisions use it."""
    c1, s1, c2, s2 = np.cos(psi1), np.sin(psi1), np.cos(psi2), np.sin(psi2)
    h1, k1, h2, k2 = np.asarray(l1) / 2, np.asarray(w1) / 2, np.asarray(l2) / 2, np.asarray(w2) / 2
    dx, dy = x2 - x1, y2 - y1
    # SAT: overlap along the four edge normals
    depth = None
    for ax, ay in ((c1, s1), (-s1, c1), (c2, s2), (-s2, c2)):
        e1 = h1 * np.abs(c1 * ax + s1 * ay) + k1 * np.abs(-s1 * ax + c1 * ay)
        e2 = h2 * np.abs(c2 * ax + s2 * ay) + k2 * np.abs(-s2 * ax + c2 * ay)
        ov = np.minimum(e1 + e2 - np.abs(dx * ax + dy * ay), 2 * np.minimum(e1, e2))  # interval overlap
        depth = ov if depth is None else np.minimum(depth, ov)
    # apart: the nearest feature pair is a corner of one box and the other box
    gap = None
    for (px, py, pc, ps, ph, pk), (qc, qs, qh, qk, sign) in (
        ((x1, y1, c1, s1, h1, k1), (c2, s2, h2, k2, 1.0)),
        ((x2, y2, c2, s2, h2, k2), (c1, s1, h1, k1, -1.0)),
    ):
        # corner offsets of box p relative to the centre of box q, in q's frame
        ox, oy = -sign * dx, -sign * dy  # p's centre minus q's centre
        bx, by = ox * qc + oy * qs, -ox * qs + oy * qc
        for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            cx = sx * ph * pc - sy * pk * ps
            cy = sx * ph * ps + sy * pk * pc
            u = bx + cx * qc + cy * qs
            w = by - cx * qs + cy * qc
            d = np.hypot(np.maximum(np.abs(u) - qh, 0.0), np.maximum(np.abs(w) - qk, 0.0))
            gap = d if gap is None else np.minimum(gap, d)
    return np.where(depth > 0.0, -depth, gap)


def edge_axes(poly: np.ndarray, count: int) -> np.ndarray:
    """Unit normals (..., count, 2) of the first ``count`` edges of ordered polygons (..., V, 2)
    (a rectangle needs 2, an octagon with opposite edges parallel 4)."""
    e = poly[..., 1:count + 1, :] - poly[..., :count, :]
    norm = np.linalg.norm(e, axis=-1, keepdims=True)
    e = np.where(norm > 1e-12, e / np.where(norm > 1e-12, norm, 1.0), np.array([1.0, 0.0]))
    return np.stack([-e[..., 1], e[..., 0]], axis=-1)


def rect_axes(rect: np.ndarray) -> np.ndarray:
    """The two edge normals (..., 2, 2) of rectangles (..., 4, 2)."""
    return edge_axes(rect, 2)


def intersects(pa: np.ndarray, axa: np.ndarray, pb: np.ndarray, axb: np.ndarray) -> np.ndarray:
    """Whether the convex hulls of the point sets ``pa`` (..., P, 2) and ``pb`` (..., Q, 2) [m]
    overlap on every axis of ``axa`` (..., A, 2) and ``axb`` (..., B, 2) (broadcast): False proves
    them disjoint; True is an overlap when the axes include every edge normal of both."""
    shape = np.broadcast_shapes(axa.shape[:-2], axb.shape[:-2])
    axes = np.concatenate([np.broadcast_to(axa, shape + axa.shape[-2:]), np.broadcast_to(axb, shape + axb.shape[-2:])],
                          axis=-2)
    ax, ay = axes[..., :, 0:1], axes[..., :, 1:2]  # (..., K, 1)
    qa = ax * pa[..., None, :, 0] + ay * pa[..., None, :, 1]  # (..., K, P)
    qb = ax * pb[..., None, :, 0] + ay * pb[..., None, :, 1]
    return np.all((qa.max(-1) >= qb.min(-1)) & (qb.max(-1) >= qa.min(-1)), axis=-1)


def overlaps(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether rectangles ``a`` (..., 4, 2) and ``b`` (..., 4, 2) [m] overlap (touching counts),
    broadcast over the leading dimensions."""
    return intersects(a, rect_axes(a), b, rect_axes(b))
