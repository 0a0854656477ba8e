"""Kinematic bicycle: exact discretisation and analytic Jacobians."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from twolevel.models import bicycle
from twolevel.models.params import BicycleParams

finite = st.floats(-1.0, 1.0)


def _states_inputs(H: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    xs = np.c_[rng.uniform(-50, 50, (H, 2)), rng.uniform(-np.pi, np.pi, H), rng.uniform(-2, 25, H)]
    us = np.c_[rng.uniform(-0.5, 0.5, H), rng.uniform(-9, 3, H)]
    return xs, us


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from([0.05, 0.1, 0.2]))
def test_jacobians_agree_with_finite_differences(seed: int, dt: float) -> None:
    xs, us = _states_inputs(10, seed)
    A, B, c = bicycle.linearize(xs, us, dt)
    eps = 1e-6
    for k in range(len(xs)):
        for j in range(4):
            e = np.eye(4)[j] * eps
            fd = (bicycle.step(xs[k] + e, us[k], dt) - bicycle.step(xs[k] - e, us[k], dt)) / (2 * eps)
            np.testing.assert_allclose(A[k, :, j], fd, atol=1e-6)
        for j in range(2):
            e = np.eye(2)[j] * eps
            fd = (bicycle.step(xs[k], us[k] + e, dt) - bicycle.step(xs[k], us[k] - e, dt)) / (2 * eps)
            np.testing.assert_allclose(B[k, :, j], fd, atol=1e-6)
    # the affine model is exact at the linearisation point
    lin = np.einsum("kij,kj->ki", A, xs) + np.einsum("kij,kj->ki", B, us) + c
    np.testing.assert_allclose(lin, bicycle.step(xs, us, dt), atol=1e-9)


def test_straight_and_tiny_steer_limits_are_smooth() -> None:
    x = np.array([[0.0, 0.0, 0.3, 10.0]] * 3)
    u = np.array([[0.0, 1.0], [1e-9, 1.0], [-1e-9, 1.0]])
    out = bicycle.step(x, u, 0.1)
    s = 10 * 0.1 + 0.5 * 0.01
    np.testing.assert_allclose(out[0], [s * np.cos(0.3), s * np.sin(0.3), 0.3, 10.1], atol=1e-12)
    np.testing.assert_allclose(out[1], out[0], atol=1e-8)
    A, B, _ = bicycle.linearize(x, u, 0.1)
    assert np.all(np.isfinite(A)) and np.all(np.isfinite(B))
    np.testing.assert_allclose(A[1], A[0], atol=1e-7)


@settings(max_examples=30, deadline=None)
@given(arrays(float, 2, elements=st.floats(-0.5, 0.5)), st.floats(0.0, 25.0), st.floats(-8.0, 3.0))
def test_step_is_exact_for_held_input(u0: np.ndarray, v: float, a: float) -> None:
    # compare with a fine RK4 integration of the continuous dynamics
    x0 = np.array([1.0, -2.0, 0.4, v])
    u = np.array([u0[0], a])
    x, n, dt = x0.copy(), 400, 0.2
    h = dt / n
    for _ in range(n):
        k1 = bicycle.f(x, u)
        k2 = bicycle.f(x + h / 2 * k1, u)
        k3 = bicycle.f(x + h / 2 * k2, u)
        k4 = bicycle.f(x + h * k3, u)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    np.testing.assert_allclose(bicycle.step(x0, u, dt), x, atol=1e-9)


def test_paper_yaw_rate_uses_l_f() -> None:
    p = BicycleParams()
    assert p.l_f == 2.11
    d = bicycle.f([0, 0, 0, 10.0], [0.1, 0.0], p)
    assert np.isclose(d[2], 10.0 / 2.11 * np.tan(0.1))


def test_rollout_matches_repeated_steps_and_batches() -> None:
    xs, us = _states_inputs(10, 3)
    traj = bicycle.rollout(xs[0], us, 0.1)
    x = xs[0]
    for k in range(10):
        x = bicycle.step(x, us[k], 0.1)
        np.testing.assert_allclose(traj[k + 1], x)
    batch = bicycle.rollout(np.stack([xs[0], xs[1]]), np.stack([us, us]), 0.1)
    np.testing.assert_allclose(batch[0], traj)
