"""The steering's share of the cost and its bound, in the lateral acceleration the steering causes.

The paper weighs the inputs u = [δ, a] in their own units (rad, m/s²) with unit weights. A
steering angle δ turns the kinematic bicycle with lateral acceleration v²·tan δ/l_f: at walking
pace a radian is little, at 25 m/s 0.01 rad is 3 m/s². Weighed as radians, the steering is
almost free at speed, so the plan corrects an offset with as much steering as its bound allows
and the closed loop on the detailed plant — whose yaw follows the steering ≈ 0.15–0.2 s late at
25–35 m/s (tyre slip, yaw inertia) with ≈ 0.8 of the bicycle's gain (its wheelbase a + b is
longer than the paper's l_f) — becomes a relay: δ switching between its bounds, a weave of
±0.4–0.5 m with a 2 s period (for 10 s at 25 m/s, 20 s at 30 m/s; at 35 m/s the car left the
road; docs/architecture.md, "Lateral stability").

Here the steering terms are weighed by the lateral acceleration they cause: the residuals of
‖δ_k − δ_ref,k‖² and ‖δ_k − δ_{k−1}‖² carry the weight :func:`steering_weight` =
1 + (v_k²/l_f)² (per radian, squared: the paper's weight plus that of the lateral acceleration in
m/s², as the acceleration a is weighed), at the step's speed v_k. ``δ_ref`` is the steering that
follows the route's curvature (:func:`steering_reference`), so bends cost nothing extra. The
factor multiplies the configured weights w_u and w_du (``controller: weights``), which keep their
meaning at standstill. The
closed loop then behaves like a unit-weight LQR of a double integrator in the lateral offset
(≈ 1 rad/s): no saturation, margin for the plant's lag; measured, an offset settles within 5 cm
in 3–6 s from 15 to 35 m/s.

While the ego passes over the oncoming lane the heading's tracking term is weighed the same way,
by the lateral velocity it causes (:func:`heading_weight`): a pass is due beside the vehicle at a
fixed time, so the car arrives in the oncoming lane with 1.5–2 m/s of lateral velocity (more from
a crawl, where steering is cheap and the heading grows to 0.3–0.4 rad), and with the heading
weighed in radians only the offset's 1 rad/s loop damped it (ζ ≈ 0.7): the plan swung 0.5–0.6 m
past the passing lane's centre, towards the road's edge. Weighed by :data:`PASS_DAMPING` ·
(lateral velocity)², the loop is over-damped (ζ ≈ 1.1): measured on the passing scenarios, the
widest point of a pass 3.49–3.81 m from the route lane's centre (passing lane 3.5 m) instead of
3.79–4.08 m.

Functions take numpy arrays or casadi symbols (plain arithmetic).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from twolevel.models.params import BicycleParams

__all__ = ["lateral_gain", "steering_weight", "steering_reference", "steering_bound", "heading_weight", "PASS_DAMPING"]

CORRECTION = 0.02
"""[rad] The steering margin beyond what the route's curvature needs, at low speed."""


def lateral_gain(v: Any, l_f: float) -> Any:
    """d(lateral acceleration)/dδ of the kinematic bicycle at δ = 0: v²/l_f [m/s² per rad] at
    speed ``v`` [m/s]."""
    return v * v / l_f


def steering_weight(v: Any, l_f: float) -> Any:
    """The factor [-] on the steering terms' unit weights at speed ``v`` [m/s]: 1 (the paper's
    weight on δ in rad) plus the squared lateral gain (the lateral acceleration in m/s²)."""
    g = lateral_gain(v, l_f)
    return 1.0 + g * g


PASS_DAMPING = 3.0
"""[-] The weight on the squared lateral velocity [(m/s)²] of the heading's tracking term while
the ego passes over the oncoming lane (with unit weights on the offset and the lateral
acceleration, 2 makes the lateral loop critically damped; 3 also takes the speed a pass arrives
with: measured, 1 left the plan 0.5 m past the passing lane's centre, 3 0.3 m)."""


def heading_weight(v: Any) -> Any:
    """The factor [-] on the heading's tracking weight at speed ``v`` [m/s] while the ego passes
    over the oncoming lane: 1 (the paper's weight on ψ in rad) plus :data:`PASS_DAMPING` times
    the squared lateral velocity a radian causes (v²)."""
    return 1.0 + PASS_DAMPING * v * v


def steering_reference(kappa: np.ndarray, params: BicycleParams) -> np.ndarray:
    """The steering [rad] that follows a path of curvature ``kappa`` [1/m], within the limit."""
    return np.clip(np.arctan(params.l_f * np.asarray(kappa, float)), -params.delta_max, params.delta_max)


def steering_bound(v: np.ndarray, kappa: np.ndarray, params: BicycleParams) -> np.ndarray:
    """|δ_k| bound [rad] per step at speeds ``v`` (H,) [m/s] (the linearisation point's, at least
    the current speed, so a plan that brakes less than the last one is still bounded): the steering limit,
    or at speed the steering of ``params.a_lat_max`` lateral acceleration (|tan δ| ≤
    a_lat_max·l_f/v²), never below what the route's curvature ``kappa`` (H,) [1/m] needs plus a
    margin for corrections: :data:`CORRECTION`, at most the steering of half ``a_lat_max`` (at
    35 m/s 0.02 rad would be 11.6 m/s², beyond the tyres). The plan's own speeds may exceed
    ``v`` (accelerating more than the last plan did), so its lateral acceleration may exceed the
    limit by (v_plan/v)²."""
    v2 = np.maximum(np.asarray(v, float) ** 2, 1e-9)
    lat = np.arctan(params.a_lat_max * params.l_f / v2)
    margin = np.minimum(CORRECTION, np.arctan(0.5 * params.a_lat_max * params.l_f / v2))
    need = np.abs(steering_reference(kappa, params)) + margin
    return np.minimum(params.delta_max, np.maximum(lat, need))
