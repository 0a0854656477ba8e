"""Criticality measures of the ego's situation, vectorised: time to collision, time and distance
headway to the vehicle ahead, and a time to collision with any participant.

The vehicle ahead is the one the signal ``d_lead`` measures (the nearest vehicle ahead in the
ego's lane within r_near, :mod:`twolevel.world.signals`), so these read the provided signals
``d_lead`` [m], ``v_lead`` [m/s] and ``v`` [m/s] (arrays of any shape, or floats):

* **distance headway** ``dhw`` [m]: the bumper-to-bumper gap ``d_lead`` (CommonRoad-CriMe's HW);
* **time headway** ``thw`` [s]: ``d_lead / v``, the time the ego needs to reach where the vehicle
  ahead's rear is now (CriMe's THW); +inf when the ego stands or nobody is ahead;
* **time to collision** ``ttc`` [s]: ``d_lead / (v − v_lead)`` while the ego closes in, the time
  until the bumpers touch if both keep their speeds (constant velocity; CriMe's TTC uses constant
  accelerations); +inf when not closing in, 0 once touching;
* **time to collision with anyone** ``ttc_any`` [s] (:func:`time_to_collision_any`): the first time
  any participant within r_near would touch the ego if every one kept its velocity, each body
  covered by three discs along its length (conservative: the discs cover the box). +inf if never.

The time to react (how long the ego may still follow its plan before it must brake) is the safety
layer's (``ttr_s`` in a run's trace), not computed here.
"""

from __future__ import annotations

import numpy as np

__all__ = ["STANDSTILL", "headways", "time_to_collision_any", "discs"]

STANDSTILL = 1e-3
"""[m/s] Below this speed the ego stands: its time headway and closing speed are infinite / 0."""


def headways(d_lead: np.ndarray | float, v: np.ndarray | float, v_lead: np.ndarray | float
             ) -> dict[str, np.ndarray]:
    """``dhw`` [m], ``thw`` [s] and ``ttc`` [s] to the vehicle ahead (see the module docstring)
    from its gap ``d_lead`` [m] (+inf: none), the ego's speed ``v`` and its speed ``v_lead`` [m/s]."""
    gap = np.asarray(d_lead, dtype=float)
    v = np.asarray(v, dtype=float)
    closing = v - np.asarray(v_lead, dtype=float)
    touching = gap <= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        thw = np.where(touching, 0.0, np.where(v > STANDSTILL, gap / np.where(v > STANDSTILL, v, 1.0), np.inf))
        ttc = np.where(touching, 0.0, np.where(closing > STANDSTILL, gap / np.where(closing > STANDSTILL, closing, 1.0),
                                               np.inf))
    inf = ~np.isfinite(gap) & (gap > 0)
    return {"dhw": gap, "thw": np.where(inf, np.inf, thw), "ttc": np.where(inf, np.inf, ttc)}


def discs(x: np.ndarray, y: np.ndarray, psi: np.ndarray, length: np.ndarray | float, width: np.ndarray | float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Three discs covering each box (centre x, y [m], heading psi [rad], length, width [m]):
    centres (..., 3) x and y [m] at −L/3, 0, +L/3 along the heading, radius (...) [m]."""
    x, y, psi = (np.asarray(a, dtype=float) for a in (x, y, psi))
    length, width = np.asarray(length, dtype=float), np.asarray(width, dtype=float)
    off = np.array([-1.0, 0.0, 1.0]) * (length[..., None] / 3.0)
    cx = x[..., None] + off * np.cos(psi)[..., None]
    cy = y[..., None] + off * np.sin(psi)[..., None]
    return cx, cy, np.hypot(length / 6.0, width / 2.0)


def time_to_collision_any(ego: tuple[np.ndarray, ...], ego_box: tuple[float, float], others: tuple[np.ndarray, ...],
                          length: np.ndarray, width: np.ndarray, near: np.ndarray) -> np.ndarray:
    """``ttc_any`` [s]: the ego ``(x, y, psi, v)`` [m, m, rad, m/s] (arrays of shape S) and n others
    ``(x, y, psi, v)`` of shape S + (n,) with boxes ``length``/``width`` (n,) [m]; only where
    ``near`` (S + (n,)). Every pair of discs moving at constant velocity: the first t ≥ 0 at which
    their distance reaches the sum of their radii (0 if they overlap now). Shape S."""
    ex, ey, epsi, ev = (np.asarray(a, dtype=float) for a in ego)
    ox, oy, opsi, ov = (np.asarray(a, dtype=float) for a in others)
    ecx, ecy, er = discs(ex, ey, epsi, ego_box[0], ego_box[1])  # S + (3,)
    ocx, ocy, orad = discs(ox, oy, opsi, length, width)  # S + (n, 3)
    dpx = ocx[..., :, None, :] - ecx[..., None, :, None]  # S + (n, 3 ego discs, 3 other discs)
    dpy = ocy[..., :, None, :] - ecy[..., None, :, None]
    dvx = (ov * np.cos(opsi) - (ev * np.cos(epsi))[..., None])[..., None, None]
    dvy = (ov * np.sin(opsi) - (ev * np.sin(epsi))[..., None])[..., None, None]
    reach = (er + orad)[..., None, None]
    a = dvx * dvx + dvy * dvy
    b = dpx * dvx + dpy * dvy
    c = dpx * dpx + dpy * dpy - reach * reach
    disc = b * b - a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where((b < 0) & (disc >= 0) & (a > 0), (-b - np.sqrt(np.maximum(disc, 0.0))) / a, np.inf)
    t = np.where(c <= 0, 0.0, t)
    t = np.where(np.asarray(near)[..., None, None], t, np.inf)
    return t.reshape(t.shape[:-3] + (-1,)).min(axis=-1, initial=np.inf)
