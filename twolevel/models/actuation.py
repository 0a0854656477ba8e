"""Throttle/brake γ ∈ [−1, 1] → wheel torques, and desired acceleration → γ.

γ > 0 drives: the drive force at the wheels is γ·F_e(v) with the engine map
F_e(v) = min(F_max, P_max / v) [N], split between the axles by ``rear_drive_share`` and
between left and right equally, each wheel's share capped by its friction μ·D_x·Fz.
γ < 0 brakes: each wheel's brake torque is |γ|·min(T_b,max, η·μ·D_x·Fz·R_w) (η =
``brake_friction_use``), i.e. an ideal, load-proportional distribution just below the tyre's
peak, so full braking decelerates at ≈ η·μ·g without locking the wheels.

The wheel-torque map (:func:`wheel_torques`) is written on columns so that it runs on numpy
arrays and on casadi SX expressions alike (``xp`` is :data:`twolevel.models.fourwheel.NP` or
``CA``). The quasi-static maps (:func:`accel_from_gamma`, :func:`gamma_from_accel`) use the
static axle loads and the road resistances; they are exact inverses of each other inside the
actuator range and are what the high-level MPC's acceleration a is turned into.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twolevel.models.params import G, VehicleParams

__all__ = [
    "engine_force",
    "wheel_torques",
    "resistance_force",
    "drive_force_available",
    "brake_force_available",
    "accel_from_gamma",
    "gamma_from_accel",
]

_V_ENGINE = 0.1  # [m/s] speed floor in P/v so the engine map is finite at standstill
V_RR = 0.1
"""Speed scale of the rolling-resistance sign smoothing tanh(v / V_RR) [m/s]."""


def engine_force(v: Any, p: VehicleParams, xp: Any = np) -> Any:
    """Largest drive force at the wheels at speed v [m/s] → [N] (engine map, before friction)."""
    return xp.fmin(p.engine_force_max, p.engine_power_max / xp.fmax(xp.fabs(v), _V_ENGINE))


def wheel_torques(
    gamma: Any, vx: Any, fz: Sequence[Any], p: VehicleParams, xp: Any = np
) -> tuple[list[Any], list[Any]]:
    """Drive and brake torque per wheel [N·m] (order FL, FR, RL, RR), brake as a magnitude ≥ 0.

    gamma: throttle/brake in [−1, 1] (clipped); vx: longitudinal speed [m/s];
    fz: the four normal loads [N] (current, with load transfer).
    """
    g = xp.fmin(xp.fmax(gamma, -1.0), 1.0)
    throttle = xp.fmax(g, 0.0)
    brake = xp.fmax(-g, 0.0)
    f_drive = throttle * engine_force(vx, p, xp)
    shares = (0.5 * (1.0 - p.rear_drive_share),) * 2 + (0.5 * p.rear_drive_share,) * 2
    grip = [p.mu * p.D_x * xp.fmax(fz_i, 0.0) for fz_i in fz]
    drive = [xp.fmin(share * f_drive, grip_i) * p.R_w for share, grip_i in zip(shares, grip)]
    brake_t = [
        brake * xp.fmin(p.brake_torque_max, p.brake_friction_use * grip_i * p.R_w) for grip_i in grip
    ]
    return drive, brake_t


def _static_loads(p: VehicleParams) -> NDArray[np.float64]:
    """Static normal load per wheel FL, FR, RL, RR [N]."""
    front = p.m * G * p.b / p.wheelbase / 2.0
    rear = p.m * G * p.a / p.wheelbase / 2.0
    return np.array([front, front, rear, rear])


def resistance_force(v: ArrayLike, p: VehicleParams) -> NDArray[np.float64]:
    """Rolling resistance plus aerodynamic drag opposing the motion at speed v [m/s] → [N]."""
    v = np.asarray(v, dtype=float)
    return p.c_rr * p.m * G * np.tanh(v / V_RR) + 0.5 * p.rho_air * p.cd_area * v * np.abs(v)


def drive_force_available(v: ArrayLike, p: VehicleParams) -> NDArray[np.float64]:
    """Drive force at γ = 1 and speed v [m/s] with static loads → [N]."""
    fz = _static_loads(p)
    v = np.asarray(v, dtype=float)
    drive, _ = wheel_torques(np.ones_like(v), v, list(fz), p)
    return np.sum(drive, axis=0) / p.R_w


def brake_force_available(p: VehicleParams) -> float:
    """Brake force at γ = −1 with static loads [N] (independent of speed)."""
    fz = _static_loads(p)
    _, brake = wheel_torques(-1.0, 0.0, list(fz), p)
    return float(np.sum(brake)) / p.R_w


def accel_from_gamma(gamma: ArrayLike, v: ArrayLike, p: VehicleParams) -> NDArray[np.float64]:
    """Quasi-static longitudinal acceleration [m/s²] of a car moving forward at v [m/s] under γ."""
    g = np.clip(np.asarray(gamma, dtype=float), -1.0, 1.0)
    v = np.asarray(v, dtype=float)
    force = (np.maximum(g, 0.0) * drive_force_available(v, p)
             + np.minimum(g, 0.0) * brake_force_available(p) - resistance_force(v, p))
    return force / p.m


def gamma_from_accel(a: ArrayLike, v: ArrayLike, p: VehicleParams) -> NDArray[np.float64]:
    """γ ∈ [−1, 1] that gives the desired acceleration a [m/s²] at speed v [m/s] (vectorised).

    Inverse of :func:`accel_from_gamma`; a beyond what the car can do saturates at ±1.
    """
    a = np.asarray(a, dtype=float)
    v = np.asarray(v, dtype=float)
    need = p.m * a + resistance_force(v, p)
    gamma = np.where(need >= 0.0, need / drive_force_available(v, p), need / brake_force_available(p))
    return np.clip(gamma, -1.0, 1.0)
