"""Oriented bounding boxes: corners from poses and their exact signed separation distance.

:func:`box_separation` is the low level's ``collision_free`` distance: the Euclidean distance
between two rectangles when they are apart, and minus the penetration depth (the length of the
smallest translation that separates them, found by the separating-axis theorem over the four
edge normals) when they overlap. Both are exact for convex polygons; the sign says whether
the boxes overlap. Touching boxes give 0. Everything is vectorised over leading dimensions.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["box_corners", "box_separation"]


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


def _axes(box: NDArray[np.float64]) -> NDArray[np.float64]:
    """The two unit edge normals of each rectangle (..., 2, 2)."""
    e = box[..., 1:3, :] - box[..., 0:2, :]
    return e / np.linalg.norm(e, axis=-1, keepdims=True)


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
    axes = np.concatenate([_axes(A), _axes(B)], axis=-2)  # (..., 4, 2)
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
