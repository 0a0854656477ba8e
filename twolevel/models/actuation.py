"""Throttle/brake γ ∈ [−1, 1] → wheel torques, and desired acceleration → γ.

γ > 0 drives: each driven wheel's force is γ·min(s_i·F_e(v), μ·D_x·Fz_i) with the engine map
F_e(v) = min(F_max, P_max / v) [N] and s_i the wheel's share (``rear_drive_share`` between the
axles, left and right equal): full throttle is capped at the tyre's grip (traction control),
and drive, like brake, is proportional to γ.
γ < 0 brakes: each wheel's brake torque is |γ|·min(T_b,max, η·μ·D_x·Fz·R_w) (η =
``brake_friction_use``), i.e. an ideal, load-proportional distribution just below the tyre's
peak, so full braking decelerates at ≈ η·μ·g without locking the wheels.

Every function takes an ``xp`` namespace (:mod:`twolevel.models.ops`; numpy by default) so it
runs on numpy arrays and on casadi SX expressions alike. The quasi-static maps (:func:`accel_from_gamma`, :func:`gamma_from_accel`) use the
static axle loads, the road resistances and the wheels' spin inertia (effective mass
m + 4·I_w/R_w²); they are exact inverses of each other inside the
actuator range and are what the high-level MPC's acceleration a is turned into.
"""

from __future__ import annotations

import functools
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twolevel.models.params import G, VehicleParams

__all__ = [
    "engine_force",
    "tyre_grip",
    "wheel_torques",
    "resistance_force",
    "effective_mass",
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


def tyre_grip(fz: Any, p: VehicleParams) -> Any:
    """Load-sensitive effective load Fz·(1 − ε·(Fz − Fz0)/Fz0) [N], Fz0 = m·g/4: the tyre's peak
    force is μ·D·tyre_grip(Fz) (ε = ``load_sensitivity``)."""
    fz0 = 0.25 * p.m * G
    return fz * (1.0 - p.load_sensitivity * (fz - fz0) / fz0)


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
    f_engine = engine_force(vx, p, xp)
    shares = (0.5 * (1.0 - p.rear_drive_share),) * 2 + (0.5 * p.rear_drive_share,) * 2
    grip = [p.mu * p.D_x * tyre_grip(xp.fmax(fz_i, 0.0), p) for fz_i in fz]
    drive = [throttle * xp.fmin(share * f_engine, grip_i) * p.R_w for share, grip_i in zip(shares, grip)]
    brake_t = [
        brake * xp.fmin(p.brake_torque_max, p.brake_friction_use * grip_i * p.R_w) for grip_i in grip
    ]
    return drive, brake_t


def _loads(p: VehicleParams, ax: Any = 0.0) -> tuple[Any, Any, Any, Any]:
    """Normal load per wheel FL, FR, RL, RR [N] at longitudinal acceleration ax [m/s²]."""
    front = 0.5 * p.m * (G * p.b - ax * p.h_cg) / p.wheelbase
    rear = 0.5 * p.m * (G * p.a + ax * p.h_cg) / p.wheelbase
    return (front, front, rear, rear)


def effective_mass(p: VehicleParams) -> float:
    """Mass [kg] the longitudinal force accelerates: the car plus its four wheels' spin inertia."""
    return p.m + 4.0 * p.I_w / p.R_w**2


def resistance_force(v: Any, p: VehicleParams, xp: Any = np) -> Any:
    """Rolling resistance plus aerodynamic drag opposing the motion at speed v [m/s] → [N]."""
    return p.c_rr * p.m * G * xp.tanh(v / V_RR) + 0.5 * p.rho_air * p.cd_area * v * xp.fabs(v)


def drive_force_available(v: Any, p: VehicleParams, xp: Any = np, ax: Any = 0.0) -> Any:
    """Drive force at γ = 1 and speed v [m/s] → [N], with the axle loads at acceleration ax [m/s²]."""
    drive, _ = wheel_torques(1.0, v, _loads(p, ax), p, xp)
    return (drive[0] + drive[1] + drive[2] + drive[3]) / p.R_w


@functools.lru_cache(maxsize=16)
def brake_force_available(p: VehicleParams) -> float:
    """Brake force at γ = −1 [N] (independent of speed; with the ideal load-proportional brake
    distribution it does not depend on the load transfer either); computed once per parameter set."""
    _, brake = wheel_torques(-1.0, 0.0, _loads(p), p, np)
    return float(np.sum(brake)) / p.R_w


def accel_from_gamma(gamma: Any, v: Any, p: VehicleParams, xp: Any = np) -> Any:
    """Quasi-static longitudinal acceleration [m/s²] of a car moving forward at v [m/s] under γ
    (the drive's grip limit depends on the load transfer of the acceleration itself: solved by
    fixed-point iteration, a contraction with rate ≈ μ·h_cg/L ≈ 0.2)."""
    g = xp.fmin(xp.fmax(gamma, -1.0), 1.0)
    brake = xp.fmin(g, 0.0) * brake_force_available(p) - resistance_force(v, p, xp)
    a = brake / effective_mass(p)
    for _ in range(25):
        nxt = (xp.fmax(g, 0.0) * drive_force_available(v, p, xp, a) + brake) / effective_mass(p)
        if xp is np and np.array_equal(nxt, a):  # a fixed point, bit for bit: the rest would repeat it
            return nxt
        a = nxt
    return a


def gamma_from_accel(a: Any, v: Any, p: VehicleParams, xp: Any = np) -> Any:
    """γ ∈ [−1, 1] that gives the desired acceleration a [m/s²] at speed v [m/s] (vectorised).

    Inverse of :func:`accel_from_gamma`; a beyond what the car can do saturates at ±1.
    """
    need = effective_mass(p) * a + resistance_force(v, p, xp)
    if xp is np and not np.any(need >= 0.0):  # braking throughout (a fail-safe): the drive is not needed
        return np.fmin(np.fmax(need / brake_force_available(p), -1.0), 1.0)
    drive = drive_force_available(v, p, xp, xp.fmin(xp.fmax(a, -10.0), 10.0))  # loads at a feasible a
    gamma = xp.where(need >= 0.0, need / drive, need / brake_force_available(p))
    return xp.fmin(xp.fmax(gamma, -1.0), 1.0)
