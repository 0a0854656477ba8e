"""The desired speed along a route: what a competent driver would drive with nothing ahead.

Computed once per route (:func:`~twolevel.world.world.build_world`) over the route's equally
spaced vertices, vectorised, and read per step by interpolation
(:meth:`~twolevel.world.geometry.Route.desired_speed_at`); the MPC's and the NMPC's reference
follow it (:mod:`twolevel.control.high_level.reference`). The profile is the largest one that

* keeps every cap: the limit in force, the ego's desired speed, the speed from which it stops
  within its sensing range, and in bends sqrt(a_lat / |κ|), the speed at which the bend's
  curvature κ [1/m] asks the comfort lateral acceleration a_lat [m/s²], from half a braking
  ramp (below) before the bend on, so that the car, which follows its reference with a lag,
  is at the bend's speed when it enters it;
* reaches each lower cap ahead (a bend, a lower limit, the goal when the route stops there) by
  braking at the comfort deceleration, and leaves it accelerating at the comfort acceleration —
  a backward and a forward pass over v², each a cumulative minimum
  (v_i² ≤ v_j² + 2·decel·(s_j − s_i) for every j ahead of i);
* changes its deceleration gradually: where braking begins, the passes' v² is replaced by its
  mean over ``decel · v_top / jerk`` [m] around that point when lower (a corner rounded from
  below), so that braking builds up over that distance (at most ``jerk`` [m/s³] at the top
  speed) instead of starting at full comfort deceleration; stretches of constant speed or
  constant deceleration, and the arrival at a bend's speed or the goal, stay as they are.

Stop lines and lights are not in it: whether the ego must stop there depends on the time and on
what it knows then, so the reference adds them per step (:mod:`twolevel.control.high_level.reference`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Comfort", "bend_speed", "speed_profile"]

KAPPA_MIN = 1e-6
"""[1/m] Curvature below which a stretch counts as straight (a radius over 1000 km)."""


@dataclass(frozen=True)
class Comfort:
    """The comfort limits of the desired speed: ``accel`` and ``decel`` [m/s²] along the route,
    ``jerk`` [m/s³] (how fast braking builds up), ``lat_accel`` [m/s²] in bends."""

    accel: float = 2.0
    decel: float = 2.0
    jerk: float = 2.0
    lat_accel: float = 2.0

    def __post_init__(self) -> None:
        for name in ("accel", "decel", "jerk", "lat_accel"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"comfort {name} must be finite and > 0, not {value!r}")


def bend_speed(kappa: np.ndarray, lat_accel: float) -> np.ndarray:
    """[m/s] The speed at which curvature ``kappa`` [1/m] asks lateral acceleration
    ``lat_accel`` [m/s²]: sqrt(lat_accel / |κ|), +inf on straights."""
    k = np.abs(np.asarray(kappa, dtype=float))
    return np.where(k > KAPPA_MIN, np.sqrt(lat_accel / np.maximum(k, KAPPA_MIN)), np.inf)


def _ahead_min(x: np.ndarray, n: int) -> np.ndarray:
    """out[i] = min(x[i : i+n]) (the window clipped at the end)."""
    if n <= 1:
        return x
    padded = np.concatenate([x, np.full(n - 1, x[-1])])
    return np.lib.stride_tricks.sliding_window_view(padded, n).min(axis=1)


def _centred_mean(x: np.ndarray, n: int) -> np.ndarray:
    """out[i] = mean(x[i−n//2 : i+n//2+1]) (``n`` odd), ``x`` extended linearly beyond its ends
    (so that a linear stretch, up to the ends, is its own mean)."""
    h = n // 2
    if h == 0 or len(x) < 2:
        return x
    k = np.arange(1, h + 1, dtype=float)
    padded = np.concatenate([x[0] - (x[1] - x[0]) * k[::-1], x, x[-1] + (x[-1] - x[-2]) * k])
    c = np.concatenate([[0.0], np.cumsum(padded)])
    return (c[n:] - c[:-n]) / n


def speed_profile(s: np.ndarray, cap: np.ndarray, kappa: np.ndarray, comfort: Comfort,
                  v_end: float | None = None) -> np.ndarray:
    """The desired speed (K,) [m/s] at the route's vertices ``s`` (K,) [m] (equally spaced,
    increasing) under the speed caps ``cap`` (K,) [m/s] (limits, desired speed, sensing bound),
    the curvature ``kappa`` (K−1,) [1/m] of each interval (its bend speed caps both ends) and
    the ``comfort`` limits; ``v_end`` [m/s]: the speed at the last vertex (0: stop there;
    None: no constraint). Never above ``cap`` nor the bend speed, never below 0."""
    s = np.asarray(s, dtype=float)
    top = np.minimum(np.asarray(cap, dtype=float), np.inf)
    spacing = float(s[1] - s[0]) if len(s) >= 2 else 0.0
    if len(s) >= 2:
        bend = np.concatenate([bend_speed(kappa, comfort.lat_accel), [np.inf]])
        bend = np.minimum(bend, np.concatenate([[np.inf], bend[:-1]]))
        # a bend's speed is reached half a braking ramp before it (the car tracks with a lag)
        v_fast = float(np.max(top[np.isfinite(top)], initial=0.0))  # [m/s] the fastest the route allows
        lead = 0.5 * comfort.decel * v_fast / comfort.jerk
        top = np.minimum(top, _ahead_min(bend, int(math.ceil(lead / spacing)) + 1 if spacing > 0 else 1))
    if v_end is not None:
        top[-1] = min(top[-1], max(v_end, 0.0))
    top = np.maximum(top, 0.0)
    if len(s) < 2:
        return top
    finite_top = np.where(np.isfinite(top), top, float(np.max(top[np.isfinite(top)], initial=0.0)))
    v2 = finite_top ** 2
    # backward pass (brake at decel for every lower cap ahead), forward pass (accelerate at accel)
    back = np.minimum.accumulate((v2 + 2 * comfort.decel * s)[::-1])[::-1] - 2 * comfort.decel * s
    fwd = np.minimum.accumulate(back - 2 * comfort.accel * s) + 2 * comfort.accel * s
    v2 = np.minimum(back, fwd)
    # braking builds up over `ramp` metres: each corner where braking begins (or acceleration
    # ends) is rounded from below by the mean over `ramp` around it; straight stretches of v²
    # (constant speed, constant deceleration) are their own mean and stay as they are
    v_top = float(np.sqrt(v2.max()))
    ramp = comfort.decel * v_top / comfort.jerk
    n = 2 * int(math.ceil(0.5 * ramp / spacing)) + 1 if spacing > 0 else 1
    v2 = np.minimum(v2, _centred_mean(v2, n))
    return np.sqrt(np.clip(np.minimum(v2, finite_top ** 2), 0.0, None))
