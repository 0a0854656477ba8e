"""The paper's kinematic bicycle, its exact zero-order-hold discretisation and Jacobians.

State x = [X, Y, ψ, v] (position [m], heading [rad], speed [m/s]); input u = [δ, a]
(steering angle [rad], acceleration [m/s²]). Continuous dynamics, as in the paper
(Aasi, Vasile, Belta, arXiv 2105.02759)::

    Ẋ = v cos ψ,   Ẏ = v sin ψ,   ψ̇ = v/l_f · tan δ,   v̇ = a

with l_f = 2.11 m (the paper's constant standing where a wheelbase usually is).

Discretisation: **exact for an input held constant over dt** (zero-order hold). With δ held,
the path curvature κ = tan δ / l_f is constant whatever the speed, so the car travels the
arc length s = v·dt + a·dt²/2 on a circle of curvature κ:
ψ⁺ = ψ + κs, v⁺ = v + a·dt and the position moves by the chord s·sinc(κs/2) at the mid-arc
heading ψ + κs/2. This is exact also when v changes sign (s is then the signed arc length).
:func:`step_columns` writes this map once, for numpy (:func:`step`, :func:`rollout`) and for
casadi (the NMPC's shooting, :mod:`twolevel.control.nmpc.nlp`); :func:`linearize` differentiates
it analytically for a whole horizon at once.

The numpy functions take the step length ``dt`` [s] as a number or, for a horizon whose steps
differ in length (fine near, coarse far), as one length per step: each step is discretised
exactly for its own length.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twolevel.models.ops import NP
from twolevel.models.params import BicycleParams

__all__ = ["f", "step", "step_columns", "rollout", "linearize", "NX", "NU"]

NX = 4
NU = 2
_DEFAULT = BicycleParams()
_EYE = np.eye(NX)
_SMALL = 1e-4  # |θ| below which sinc and its derivative use their Taylor series


def f(x: ArrayLike, u: ArrayLike, params: BicycleParams = _DEFAULT) -> NDArray[np.float64]:
    """Continuous dynamics ẋ = f(x, u); x (..., 4), u (..., 2) → (..., 4) [SI units/s]."""
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float)
    psi, v = x[..., 2], x[..., 3]
    return np.stack(
        [v * np.cos(psi), v * np.sin(psi), v / params.l_f * np.tan(u[..., 0]), u[..., 1] + 0 * v],
        axis=-1,
    )


def _sinc(theta: Any, xp: Any) -> Any:
    """sin(θ)/θ, its series near θ = 0, in the operations of ``xp``."""
    small = xp.fabs(theta) < _SMALL
    th = xp.where(small, 1.0, theta)
    return xp.where(small, 1.0 - theta**2 / 6.0, xp.sin(th) / th)


def _sinc_and_derivative(theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """sin(θ)/θ and its derivative (θcosθ − sinθ)/θ², series near θ = 0 (numpy)."""
    small = np.abs(theta) < _SMALL
    th = np.where(small, 1.0, theta)
    s, c = np.sin(th), np.cos(th)
    sinc = np.where(small, 1.0 - theta**2 / 6.0, s / th)  # = _sinc(theta, NP), sharing sin(th)
    dsinc = np.where(small, -theta / 3.0 + theta**3 / 30.0, (th * c - s) / th**2)
    return sinc, dsinc


def step_columns(X: Any, Y: Any, psi: Any, v: Any, delta: Any, a: Any, dt: Any, l_f: float,
                 xp: Any = NP) -> tuple[Any, Any, Any, Any]:
    """The exact zero-order-hold step on columns (one array or symbol per component): state X, Y
    [m], ψ [rad], v [m/s], input δ [rad], a [m/s²], period ``dt`` [s] (with numpy, also an array
    broadcast against the columns), ``l_f`` [m] → X⁺, Y⁺, ψ⁺, v⁺. Written once in the operations
    of ``xp``: numpy's (:data:`~twolevel.models.ops.NP`) for :func:`step`, casadi's
    (:func:`~twolevel.models.ops.casadi_ops`) for the NMPC's shooting."""
    kappa = xp.tan(delta) / l_f
    s = v * dt + 0.5 * a * dt * dt
    theta = 0.5 * kappa * s
    g = s * _sinc(theta, xp)
    phi = psi + theta
    return X + g * xp.cos(phi), Y + g * xp.sin(phi), psi + 2.0 * theta, v + a * dt


def step(x: ArrayLike, u: ArrayLike, dt: ArrayLike, params: BicycleParams = _DEFAULT) -> NDArray[np.float64]:
    """Exact zero-order-hold step: x (..., 4), u (..., 2), dt [s] (a number, or broadcast against
    x's leading dimensions) → x⁺ (..., 4)."""
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float)
    return np.stack(step_columns(x[..., 0], x[..., 1], x[..., 2], x[..., 3], u[..., 0], u[..., 1],
                                 np.asarray(dt, dtype=float), params.l_f), axis=-1)


def rollout(x0: ArrayLike, us: ArrayLike, dt: ArrayLike, params: BicycleParams = _DEFAULT) -> NDArray[np.float64]:
    """States over a horizon: x0 (..., 4), us (..., H, 2), dt [s] (a number or (H,) step lengths)
    → (..., H+1, 4), xs[..., 0, :] = x0.

    Loops over the H steps (the recursion is sequential); everything else is batched.
    """
    us = np.asarray(us, dtype=float)
    x = np.broadcast_to(np.asarray(x0, dtype=float), us.shape[:-2] + (NX,))
    h = np.broadcast_to(np.asarray(dt, dtype=float), (us.shape[-2],))
    out = [x]
    for k in range(us.shape[-2]):
        x = step(x, us[..., k, :], float(h[k]), params)
        out.append(x)
    return np.stack(out, axis=-2)


def linearize(
    xs: ArrayLike, us: ArrayLike, dt: ArrayLike, params: BicycleParams = _DEFAULT
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Jacobians of :func:`step` about (x̄_k, ū_k) for every k at once.

    xs (H, 4), us (H, 2), dt [s] (a number or (H,) step lengths) → A (H, 4, 4), B (H, 4, 2),
    c (H, 4) with step(x, u) ≈ A_k x + B_k u + c_k near (x̄_k, ū_k), exactly at it. Any leading
    batch dimensions are allowed. No Python loop.
    """
    xs = np.asarray(xs, dtype=float)
    us = np.asarray(us, dtype=float)
    dt = np.asarray(dt, dtype=float)
    psi, v = xs[..., 2], xs[..., 3]
    delta, a = us[..., 0], us[..., 1]
    tan_d = np.tan(delta)
    kappa = tan_d / params.l_f
    dkappa_ddelta = (1.0 + tan_d * tan_d) / params.l_f
    s = v * dt + 0.5 * a * dt * dt
    theta = 0.5 * kappa * s
    sinc, dsinc = _sinc_and_derivative(theta)
    g = s * sinc
    phi = psi + theta
    cphi, sphi, cth = np.cos(phi), np.sin(phi), np.cos(theta)
    dg_dkappa = 0.5 * s * s * dsinc  # ∂g/∂s = cos θ

    # partials of X⁺, Y⁺, ψ⁺ with respect to ψ, s and κ
    dX_dpsi, dY_dpsi = -g * sphi, g * cphi
    dX_ds = cth * cphi - g * sphi * 0.5 * kappa
    dY_ds = cth * sphi + g * cphi * 0.5 * kappa
    dX_dk = dg_dkappa * cphi - g * sphi * 0.5 * s
    dY_dk = dg_dkappa * sphi + g * cphi * 0.5 * s

    shape = xs.shape[:-1]
    A = np.empty(shape + (NX, NX))
    A[...] = _EYE
    A[..., 0, 2] = dX_dpsi
    A[..., 1, 2] = dY_dpsi
    A[..., 0, 3] = dX_ds * dt
    A[..., 1, 3] = dY_ds * dt
    A[..., 2, 3] = kappa * dt

    half_dt2 = 0.5 * dt * dt
    B = np.empty(shape + (NX, NU))
    B[..., 0, 0] = dX_dk * dkappa_ddelta
    B[..., 1, 0] = dY_dk * dkappa_ddelta
    B[..., 2, 0] = s * dkappa_ddelta
    B[..., 3, 0] = 0.0
    B[..., 0, 1] = dX_ds * half_dt2
    B[..., 1, 1] = dY_ds * half_dt2
    B[..., 2, 1] = kappa * half_dt2
    B[..., 3, 1] = dt

    # c = step(x̄, ū) − A x̄ − B ū, written out (X, Y, ψ, v enter A as identity)
    c = np.empty(shape + (NX,))
    c[..., 0] = g * cphi - dX_dpsi * psi - B[..., 0, 0] * delta - dX_ds * s
    c[..., 1] = g * sphi - dY_dpsi * psi - B[..., 1, 0] * delta - dY_ds * s
    c[..., 2] = 2.0 * theta - kappa * s - B[..., 2, 0] * delta
    c[..., 3] = 0.0
    return A, B, c
