"""Physics of the detailed four-wheel model (numpy reference integrator)."""

from __future__ import annotations

import numpy as np
import pytest

from twolevel.models import bicycle, fourwheel as fw
from twolevel.models.params import G, BicycleParams, VehicleParams
from twolevel.models.actuation import gamma_from_accel
from twolevel.models.rollout import rollout_accel

P = VehicleParams()


def test_low_speed_small_steering_tracks_kinematic_bicycle() -> None:
    # 3 m/s, δ = 0.05 rad for 5 s: tyre slip is negligible, so the rear axle follows the
    # kinematic bicycle (wheelbase a + b, referenced at the rear axle) within 5 cm and 0.002 rad.
    v, H, dt = 3.0, 50, 0.1
    u = np.tile([0.05, 0.0], (H, 1))
    s = rollout_accel(fw.initial_state(v=v), u[None], dt, P, backend="numpy").states[0]
    rear = np.c_[s[:, 0] - P.b * np.cos(s[:, 2]), s[:, 1] - P.b * np.sin(s[:, 2])]
    acc = np.diff(s[:, 3]) / dt  # the same speed profile for the bicycle
    kin = bicycle.rollout([-P.b, 0.0, 0.0, v], np.c_[u[:, 0], acc], dt, BicycleParams(l_f=P.wheelbase))
    assert np.abs(rear - kin[:, :2]).max() < 0.05
    assert np.abs(s[:, 2] - kin[:, 2]).max() < 0.002
    assert s[-1, 2] > 0.25  # it did turn (≈ 0.29 rad)


def test_full_braking_stops_like_mu_g_and_stays_stopped() -> None:
    v0 = 15.0
    s = fw.simulate(fw.initial_state(v=v0), np.tile([0.0, -1.0], (60, 1)), 0.1, P)
    assert np.all(np.isfinite(s))
    dist = s[-1, 0]
    ideal = v0**2 / (2 * P.mu * G)  # 11.5 m: every tyre at its peak all the way
    assert ideal < dist < ideal / 0.85  # brakes use 95 % of the peak, plus the build-up
    stopped = s[30:]  # stopped within 3 s (ideal 1.53 s)
    assert np.abs(stopped[:, 3]).max() < 1e-9
    assert np.ptp(stopped[:, 0]) < 1e-9 and np.abs(stopped[:, 1]).max() < 1e-9
    assert s[:, 3].min() >= 0.0  # never rolls backwards
    assert np.abs(stopped[:, 6:10]).max() == 0.0  # wheels locked by the holding brake


def test_standstill_is_finite_and_at_rest() -> None:
    x0 = fw.initial_state(v=0.0)
    for u in ([0.4, 0.0], [-0.4, -1.0], [0.0, -0.3]):
        s = fw.simulate(x0, np.tile(u, (20, 1)), 0.1, P)
        assert np.all(np.isfinite(s))
        assert np.abs(s[:, :6]).max() < 1e-12  # no creep in any direction


def test_start_from_rest_is_smooth_and_forward() -> None:
    s = fw.simulate(fw.initial_state(v=0.0), np.tile([0.1, 0.5], (30, 1)), 0.1, P)
    assert np.all(np.isfinite(s))
    assert np.all(np.diff(s[:, 3]) > 0)  # accelerates monotonically through the low-speed blend
    assert 1.5 < s[-1, 3] / 3.0 < 2.5  # ≈ half the grip-limited 4.4 m/s²


def _steady_state(v: float, delta: float, seconds: float = 5.0) -> np.ndarray:
    """State after holding the steer with the speed held at v by a P controller on a."""
    x = fw.initial_state(v=v)
    for _ in range(int(seconds / 0.1)):
        a = 2.0 * (v - np.hypot(x[3], x[4]))
        x = fw.step(x, [delta, float(gamma_from_accel(a, x[3], P))], 0.1, P)
    return x


def test_linear_range_understeers() -> None:
    # steady state at 15 m/s, speed held: the yaw rate stays below the kinematic (neutral) one
    # and falls further behind as steering grows (positive understeer gradient)
    deltas = np.array([0.01, 0.02, 0.04, 0.08])
    ss = np.array([_steady_state(15.0, d) for d in deltas])
    speed = np.hypot(ss[:, 3], ss[:, 4])
    assert np.abs(speed - 15.0).max() < 0.5  # P control: small steady-state error
    ratio = ss[:, 5] / (speed * np.tan(deltas) / P.wheelbase)
    assert np.all(ratio < 1.0) and np.all(np.diff(ratio) < 0)


@pytest.mark.parametrize("delta", [0.15, 0.3])
def test_limit_cornering_respects_friction_and_understeers(delta: float) -> None:
    # 15 m/s into a large step steer, coasting: the tyres saturate; sample every 10 ms
    dt = 0.01
    s = fw.simulate(fw.initial_state(v=15.0), np.tile([delta, 0.0], (300, 1)), dt, P)
    assert np.all(np.isfinite(s))
    vy_dot = np.diff(s[:, 4]) / dt
    lat_acc = vy_dot + 0.5 * (s[1:, 5] * s[1:, 3] + s[:-1, 5] * s[:-1, 3])  # a_y = v̇y + r·vx
    assert np.abs(lat_acc).max() <= P.mu * G * 1.02  # never beyond μ·g (2 % numerical margin)
    assert np.abs(lat_acc).max() > 0.85 * P.mu * G  # and it does reach the limit
    # understeer at the limit: curvature below the kinematic one, front slipping more than rear,
    # no spin (small body slip angle)
    mid = s[100:]
    curvature = mid[:, 5] / np.hypot(mid[:, 3], mid[:, 4])
    assert np.all(curvature < np.tan(delta) / P.wheelbase)
    r, vx, vy = mid[:, 5], mid[:, 3], mid[:, 4]
    alpha_front = delta - np.arctan((vy + P.a * r) / vx)
    alpha_rear = -np.arctan((vy - P.b * r) / vx)
    assert np.all(alpha_front > alpha_rear)
    assert np.abs(np.arctan2(vy, vx)).max() < 0.1


@pytest.mark.parametrize("h", [0.005])
def test_halving_the_internal_step_changes_an_aggressive_manoeuvre_little(h: float) -> None:
    # 15 m/s, full throttle into a 0.3 rad step steer, then full braking in the turn: 2 s
    u = np.r_[np.tile([0.3, 1.0], (10, 1)), np.tile([0.3, -1.0], (10, 1))]
    ends = [fw.simulate(fw.initial_state(v=15.0), u, 0.1, P.with_overrides({"h_int": hh}))[-1]
            for hh in (h, h / 2, h / 4)]
    d1 = np.abs(ends[0] - ends[1])
    d2 = np.abs(ends[1] - ends[2])
    # stated tolerance at h = 5 ms: 10 cm in position, 0.01 rad in heading, 0.1 m/s in speed
    assert d1[:2].max() < 0.10 and d1[2] < 0.01 and d1[3:5].max() < 0.1
    # and the change shrinks with the step (first-order convergence: about halves)
    assert np.hypot(*d2[:2]) < 0.7 * np.hypot(*d1[:2])


def test_agrees_with_commonroad_single_track_on_a_gentle_manoeuvre() -> None:
    vm = pytest.importorskip("vehiclemodels.vehicle_dynamics_st")
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2

    cr = parameters_vehicle2()
    t = cr.tire
    # match the tyres' linear range (ST's cornering stiffness μ·C_S = −p_ky1 per unit load),
    # switch off what ST does not model (drag, rolling resistance), same mass/geometry
    p = P.with_overrides({
        "m": cr.m, "a": cr.a, "b": cr.b, "I_z": cr.I_z, "h_cg": cr.h_s, "mu": 1.0,
        "D_y": t.p_dy1, "C_y": t.p_cy1, "B_y": -t.p_ky1 / (t.p_dy1 * t.p_cy1), "E_y": t.p_ey1,
        "c_rr": 0.0, "cd_area": 0.0, "load_sensitivity": 0.0,
    })
    v0, amp, period, T, dt = 15.0, 0.03, 4.0, 4.0, 0.01
    w = 2 * np.pi / period
    times = np.arange(0.0, T, dt)
    delta_mid = amp * np.sin(w * (times + dt / 2))  # ZOH steer at the interval midpoints
    s = fw.simulate(fw.initial_state(v=v0, p=p), np.c_[delta_mid, np.zeros_like(times)], dt, p)

    def st_rhs(tt: float, x: np.ndarray) -> np.ndarray:
        return np.array(vm.vehicle_dynamics_st(list(x), [amp * w * np.cos(w * tt), 0.0], cr))

    x = np.array([0.0, 0.0, 0.0, v0, 0.0, 0.0, 0.0])  # [X, Y, δ, v, ψ, ψ̇, β]
    ref = [x]
    for tt in times:  # RK4 with 2 substeps per 10 ms
        for k in range(2):
            h, t0 = dt / 2, tt + k * dt / 2
            k1 = st_rhs(t0, x)
            k2 = st_rhs(t0 + h / 2, x + h / 2 * k1)
            k3 = st_rhs(t0 + h / 2, x + h / 2 * k2)
            k4 = st_rhs(t0 + h, x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        ref.append(x)
    ref = np.array(ref)
    # stated tolerance: lateral position 5 cm over 60 m, 5 mrad in heading, 5 % of the peak yaw
    # rate; along the road 20 cm (ST holds v̇ = a exactly, ignoring the drag of steered tyres)
    assert np.abs(s[:, 1] - ref[:, 1]).max() < 0.05
    assert np.abs(s[:, 0] - ref[:, 0]).max() < 0.20
    assert np.abs(s[:, 2] - ref[:, 4]).max() < 0.005
    assert np.abs(s[:, 5] - ref[:, 5]).max() < 0.05 * np.abs(ref[:, 5]).max()
    assert np.abs(ref[:, 1]).max() > 1.0  # the manoeuvre is not trivial
