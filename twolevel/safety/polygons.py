"""Convex polygons for the safety layer: lane pieces and growing discs.

They are tested against each other and the ego's boxes by the separating-axis test of
:mod:`twolevel.models.obb` (:func:`~twolevel.models.obb.intersects`).

Everything is vectorised over leading dimensions. A convex polygon is given by its vertices
(..., V, 2) [m] and the axes (..., A, 2) on which the separating-axis theorem tests it (its edge
normals; for a swept region, the axes of the boxes it is the hull of). Two convex sets are
disjoint iff their projections onto some axis are disjoint, and for two convex polygons it
suffices to test the edge normals of both. Testing the edge normals of a *hull of points* whose
true edges are unknown (the ego's swept region over an interval) may miss a separating axis, so
such a test can report an overlap that is not there — never the reverse: the test is sound.

* :func:`band_pieces` — a quad that contains the band of a lane between two arc lengths and two
  lateral offsets, exactly when the piece is straight and with a proven margin on a bend (see the
  function);
* :func:`disc_hull_octagons` — the circumscribed regular-octagon of the convex hull of two discs
  (a growing disc over a time interval).
"""

from __future__ import annotations

import numpy as np

from twolevel.world.geometry import LaneSet

__all__ = ["band_pieces", "lane_point", "disc_hull_octagons", "OCTAGON_NORMALS"]

OCTAGON_NORMALS = np.stack([np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4)], axis=1)
"""The outward normals of the octagons :func:`disc_hull_octagons` builds (8, 2)."""


def band_pieces(lanes: LaneSet, lane: np.ndarray, a: np.ndarray, b: np.ndarray, lat_lo: np.ndarray,
                lat_hi: np.ndarray, turn: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rectangles containing the points at arc length s ∈ [a, b] [m] and lateral offset
    λ ∈ [lat_lo, lat_hi] [m] (+ left) of lane ``lane``, where the centre line turns by at most
    ``turn`` [rad] monotonically over [a, b] (one :mod:`~twolevel.safety.network` cell: small
    turns along a stretch, or a polyline's corner of any angle up to π at one point).

    In the frame of the chord from C(a) to C(b) (length c; u along, v across): a convex arc with
    its heading within ``turn`` of the chord lies within the triangle of the chord and the end
    tangents, so |v| ≤ (c/2)·tan(turn/2); its projection on u stays in [0, c]; the normal at
    every point turns by φ ≤ t from the chord's normal, so λ·n(s) adds λ·cos φ across (between
    its values at φ = 0 and φ = t, λ ∈ {lo, hi}) and at most max(|lo|, |hi|)·sin(min(t, π/2))
    along. Exact for a straight piece (turn = 0); beyond the lane's ends the centre line continues
    straight. A turn ≥ π marks a kink (a stretch running off its own headings, where nothing is
    known of the normals): its piece is the rectangle around the chord grown by max(|lo|, |hi|)
    on every side, which holds the discs of that radius about every point of the chord.

    ``lat_lo``/``lat_hi`` are (N,) or (N, M) (M bands across the same stretch: the frame is
    computed once). Returns the corners (N[, M], 4, 2) [m] (counter-clockwise from the rear
    right), the two edge normals (N[, M], 2, 2), the centre (N[, M], 2) [m], the half diagonal
    (N[, M]) [m] and the half sizes of the axis-aligned bounding box (N[, M], 2) [m]."""
    lane = np.asarray(lane, dtype=int)
    pa, ha = lane_point(lanes, lane, np.asarray(a, dtype=float))
    pb, _ = lane_point(lanes, lane, np.asarray(b, dtype=float))
    d = pb - pa
    c = np.hypot(d[:, 0], d[:, 1])
    fallback = np.stack([np.cos(ha), np.sin(ha)], axis=1)
    u = np.where((c > 1e-9)[:, None], d / np.maximum(c, 1e-12)[:, None], fallback)
    v = np.stack([-u[:, 1], u[:, 0]], axis=1)
    t = np.minimum(np.asarray(turn, dtype=float), np.pi)
    lo, hi = np.asarray(lat_lo, dtype=float), np.asarray(lat_hi, dtype=float)
    wide = lo.ndim == 2
    if wide:  # one frame, M bands
        c, t, pa, u, v = c[:, None], t[:, None], pa[:, None], u[:, None], v[:, None]
    dev = 0.5 * c * np.tan(0.5 * np.minimum(t, 1.5))  # (a long stretch turns little: see the cells)
    over = np.maximum(np.abs(lo), np.abs(hi)) * np.sin(np.minimum(t, 0.5 * np.pi))
    cos = np.cos(t)
    v_lo = np.minimum(np.minimum(lo, lo * cos), hi * cos) - dev
    v_hi = np.maximum(np.maximum(hi, hi * cos), lo * cos) + dev
    kink = t >= np.pi - 1e-12
    if np.any(kink):
        big = np.maximum(np.abs(lo), np.abs(hi))
        v_lo, v_hi = np.where(kink, -big, v_lo), np.where(kink, big, v_hi)
        over = np.where(kink, big, over)
    u_lo, u_hi = -over, c + over
    corners_u = np.stack([u_lo, u_hi, u_hi, u_lo], axis=-1)  # counter-clockwise from rear right
    corners_v = np.stack([v_lo, v_lo, v_hi, v_hi], axis=-1)
    quad = pa[..., None, :] + corners_u[..., None] * u[..., None, :] + corners_v[..., None] * v[..., None, :]
    centre = pa + (0.5 * (u_lo + u_hi))[..., None] * u + (0.5 * (v_lo + v_hi))[..., None] * v
    axes = np.broadcast_to(np.stack([v, u], axis=-2), quad.shape[:-2] + (2, 2))
    hu, hv = 0.5 * (u_hi - u_lo), 0.5 * (v_hi - v_lo)
    extent = np.abs(u) * hu[..., None] + np.abs(v) * hv[..., None]
    return quad, axes, centre, np.hypot(hu, hv), extent


def lane_point(lanes: LaneSet, lane: np.ndarray, s: np.ndarray, lateral: np.ndarray | float = 0.0
               ) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 2) [m] and headings (N,) [rad] of ``lane`` at arc length ``s`` [m] and
    ``lateral`` offset [m] (+ left), the lane continued straight along its end headings beyond
    either end."""
    lane = np.asarray(lane, dtype=int)
    s = np.asarray(s, dtype=float)
    inside = np.clip(s, 0.0, lanes.length[lane])
    p, h = lanes.pose(lane, inside, lateral)
    beyond = s - inside
    return p + beyond[:, None] * np.stack([np.cos(h), np.sin(h)], axis=1), h


def disc_hull_octagons(c0: np.ndarray, r0: np.ndarray, c1: np.ndarray, r1: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Octagons (..., 8, 2) [m] circumscribing the convex hull of the discs (c0, r0) and (c1, r1)
    (centres (..., 2) [m], radii (...) [m]): the half-planes n_k·x ≤ max(n_k·c0 + r0, n_k·c1 + r1)
    for the eight normals of :data:`OCTAGON_NORMALS` (the support function of the hull in those
    directions, so every half-plane touches it), vertices where consecutive ones meet. Returns the
    vertices, a bounding circle's centre (..., 2) and radius (...) [m] (the octagon's vertices
    are at most r / cos(π/8) from a disc's centre)."""
    n = OCTAGON_NORMALS
    h = np.maximum(np.einsum("...j,kj->...k", c0, n) + np.asarray(r0)[..., None],
                   np.einsum("...j,kj->...k", c1, n) + np.asarray(r1)[..., None])  # (..., 8)
    h2 = np.roll(h, -1, axis=-1)
    n2 = np.roll(n, -1, axis=0)
    det = n[:, 0] * n2[:, 1] - n[:, 1] * n2[:, 0]  # sin(π/4) for every pair
    x = (h * n2[:, 1] - h2 * n[:, 1]) / det
    y = (n[:, 0] * h2 - n2[:, 0] * h) / det
    centre = 0.5 * (c0 + c1)
    half = 0.5 * np.hypot(c1[..., 0] - c0[..., 0], c1[..., 1] - c0[..., 1])
    return np.stack([x, y], axis=-1), centre, half + np.maximum(r0, r1) / np.cos(np.pi / 8)
