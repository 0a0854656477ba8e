"""What one MPC step knows before it builds a model: the linearisation point and the bounds.

:func:`prepare_step` turns (ego state, time, traffic, history, previous plan) into a
:class:`StepData`: the reference (:mod:`twolevel.control.high_level.reference`: waypoints ω_k
and the solve-time constants), the linearisation point (the previous plan shifted by one step,
a rollout of the reference's controls, or full braking), the Jacobians of the kinematic bicycle
along it (:func:`twolevel.models.bicycle.linearize`, vectorised), the state and steering bounds
(reachable boxes) and the guards (:mod:`twolevel.control.high_level.guards`: the drivable band,
the terminal can-still-stop condition). Units: m, rad, m/s, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from twolevel.control.high_level.guards import TerminalStop, drivable_band, stop_lines, terminal_stop
from twolevel.control.high_level.reference import reference, reference_controls, wrap_to
from twolevel.control.high_level.settings import MPCSettings
from twolevel.control.planner import PreviousPlan
from twolevel.models import bicycle
from twolevel.models.params import BicycleParams
from twolevel.world.signals import HorizonConstants, StopMemory
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["StepData", "prepare_step", "direction_box", "steering_bound", "history_length"]


@dataclass(frozen=True, eq=False)
class StepData:
    """One step's known quantities (k = 0..H; index 0 is now).

    ``xs_bar`` (H+1, 4) / ``us_bar`` (H, 2): linearisation point; ``A`` (H, 4, 4), ``B`` (H, 4, 2),
    ``c`` (H, 4): x_{k+1} ≈ A_k x_k + B_k u_k + c_k; ``omega`` (H, 4): waypoints for k = 1..H;
    ``s_ref`` (H+1,) [m] route positions of the waypoints; ``s_bar``/``h_bar``/``p_bar``: route
    position, tangent heading and route point of the linearisation point's projection (k = 0..H),
    for s_k ≈ s̄_k + t̄_kᵀ(p_k − p̄_k); ``lo``/``hi`` (H, 4): state bounds for k = 1..H;
    ``e_lo``/``e_hi`` (H,) [m]: bounds on the lateral offset e_k ≈ n̄_kᵀ(p_k − p̄_k) for k = 1..H
    (:func:`twolevel.control.high_level.guards.drivable_band`, widened to include where the ego and the
    linearisation point already are); ``term``: the can-still-stop terminal condition
    (:func:`twolevel.control.high_level.guards.terminal_stop`, inactive when no line applies); ``delta_hi``
    (H,) [rad]: the steering bound per step (:func:`steering_bound`; None: the steering limit)."""

    t: float
    x0: np.ndarray
    u_prev: np.ndarray
    xs_bar: np.ndarray
    us_bar: np.ndarray
    A: np.ndarray
    B: np.ndarray
    c: np.ndarray
    omega: np.ndarray
    s_ref: np.ndarray
    s_bar: np.ndarray
    h_bar: np.ndarray
    p_bar: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    hc: HorizonConstants
    lane_width: float
    e_lo: np.ndarray
    e_hi: np.ndarray
    term: TerminalStop = TerminalStop()
    delta_hi: np.ndarray | None = None


def _cos_range(lo: np.ndarray, hi: np.ndarray, phase: float) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of cos(θ − phase) over θ ∈ [lo, hi] (vectorised)."""
    a, b = lo - phase, hi - phase
    ca, cb = np.cos(a), np.cos(b)
    mn, mx = np.minimum(ca, cb), np.maximum(ca, cb)
    has_max = np.floor(b / (2 * math.pi)) >= np.ceil(a / (2 * math.pi))
    has_min = np.floor((b - math.pi) / (2 * math.pi)) >= np.ceil((a - math.pi) / (2 * math.pi))
    return np.where(has_min, -1.0, mn), np.where(has_max, 1.0, mx)


def direction_box(x0: np.ndarray, H: int, dt: float, params: BicycleParams, v_cap: float,
                  margin: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """State bounds (H, 4) for k = 1..H: speed in [0, min(v0 + a_max·k·dt, v_cap)], heading within
    the yaw the steering limit allows, and X/Y within the sum of per-step displacement boxes
    (distance ≤ v·dt in any direction of the reachable heading cone), widened by ``margin`` [m]."""
    X, Y, psi, v = (float(a) for a in x0[:4])
    k = np.arange(1, H + 1)
    v_hi = np.minimum(v + params.a_max * k * dt, v_cap)
    step = dt * np.concatenate([[v], v_hi[:-1]]) + 0.5 * params.a_max * dt * dt
    step = np.maximum(step, 0.0)
    yaw = np.cumsum(step * math.tan(params.delta_max) / params.l_f)
    yaw = np.minimum(yaw, math.pi)
    yaw_prev = np.concatenate([[0.0], yaw[:-1]])
    # step j moves by at most step_j in a direction within psi ± yaw_j (the heading after it)
    cmin, cmax = _cos_range(psi - yaw, psi + yaw, 0.0)
    smin, smax = _cos_range(psi - yaw, psi + yaw, math.pi / 2)
    del yaw_prev
    dx_lo = np.cumsum(step * np.minimum(cmin, 0.0)) - margin
    dx_hi = np.cumsum(step * np.maximum(cmax, 0.0)) + margin
    dy_lo = np.cumsum(step * np.minimum(smin, 0.0)) - margin
    dy_hi = np.cumsum(step * np.maximum(smax, 0.0)) + margin
    lo = np.stack([X + dx_lo, Y + dy_lo, psi - yaw - 0.05, np.zeros(H)], axis=1)
    hi = np.stack([X + dx_hi, Y + dy_hi, psi + yaw + 0.05, v_hi + 0.1], axis=1)
    return lo, hi


def steering_bound(v: np.ndarray, kappa: np.ndarray, params: BicycleParams) -> np.ndarray:
    """|δ_k| bound [rad] per step at speeds ``v`` (H,) [m/s] (the linearisation point's, at least
    the current speed, so a plan that brakes less than the last one is still bounded): the steering limit,
    or at speed the steering of ``params.a_lat_max`` lateral acceleration (|tan δ| ≤
    a_lat_max·l_f/v²), never below what the route's curvature ``kappa`` (H,) [1/m] needs plus a
    margin for corrections. The plan's own speeds may exceed ``v`` (accelerating more than the
    last plan did), so its lateral acceleration may exceed the limit by (v_plan/v)²."""
    v2 = np.maximum(np.asarray(v, float) ** 2, 1e-9)
    lat = np.arctan(params.a_lat_max * params.l_f / v2)
    need = np.abs(np.arctan(params.l_f * np.asarray(kappa, float))) + 0.02
    return np.minimum(params.delta_max, np.maximum(lat, need))


def prepare_step(
    world: World, x0: np.ndarray, t: float, traffic: TrafficState, settings: MPCSettings, params: BicycleParams,
    *, prev: PreviousPlan | None = None, u_prev: np.ndarray | None = None, memory: StopMemory | None = None,
    s_hint: float | None = None, about: str = "plan", stop_rules: tuple[bool, bool] = (False, False),
) -> StepData:
    """Everything known at time ``t`` [s] for ego state ``x0`` = (X, Y, ψ, v), over the horizon
    and period of ``settings``.

    ``prev``: the previous plan, made one step ago; it is shifted by one step to give the
    linearisation point (``about="plan"``); ``about="reference"`` linearises about a rollout of
    the reference's controls, ``"brake"`` about full braking. ``u_prev`` [δ, a] is the control
    applied during the last step (for the ‖u_0 − u_{−1}‖² term; default the previous plan's
    first). ``stop_rules`` = (a rule reads d_stop, a rule reads light_red/d_light): which lines
    the terminal can-still-stop condition guards, with ``settings.stop_decel`` [m/s²] and
    ``settings.stop_margin`` [m] before the line; ``settings.band``: bound the lateral offset to
    the drivable band. ``memory``, ``s_hint``: see :func:`~twolevel.control.high_level.reference.reference`."""
    H, dt = settings.H, settings.dt
    stop_decel, stop_margin = settings.stop_decel, settings.stop_margin
    route = world.route
    x0 = np.asarray(x0, dtype=float)[:4].copy()
    ref = reference(world, x0, t, traffic, settings, params, memory=memory, s_hint=s_hint, stop_rules=stop_rules)
    s0, s_ref, v_ref, omega, hc = ref.s0, ref.s_ref, ref.v_ref, ref.omega, ref.hc
    if about == "brake":  # a braking rollout with the wheel straight (to standstill, no reversing)
        us_bar = np.zeros((H, 2))
        v = float(x0[3])
        for k in range(H):
            us_bar[k, 1] = max(params.a_min, -v / dt)
            v = max(v + us_bar[k, 1] * dt, 0.0)
        xs_bar = bicycle.rollout(x0, us_bar, dt, params)
        if u_prev is None and prev is not None:
            u_prev = prev.controls[0]
    elif prev is not None and about == "plan":
        ps, pu = prev.states, prev.controls
        us_bar = np.vstack([pu[1:], pu[-1:]])
        xs_bar = np.vstack([x0[None], ps[2:], bicycle.step(ps[-1], pu[-1], dt, params)[None]])
        xs_bar[:, 2] = wrap_to(xs_bar[:, 2], float(x0[2]))
        if u_prev is None:
            u_prev = pu[0]
    else:
        us_bar = reference_controls(route.curvature_at(s_ref[:-1]), v_ref, dt, params)
        xs_bar = bicycle.rollout(x0, us_bar, dt, params)
    if u_prev is None:
        u_prev = np.zeros(2)
    A, B, c = bicycle.linearize(xs_bar[:-1], us_bar, dt, params)
    s_bar, _ = route.project_near(xs_bar[:, :2], np.full(H + 1, s0) + np.arange(H + 1) * dt * max(x0[3], 1.0),
                                  H * dt * (max(x0[3], 1.0) + params.a_max * H * dt) + 10.0)
    h_bar = route.heading_at(s_bar)
    p_bar = route.position(s_bar)
    v_cap = max(float(route.limit_v.max()) * 1.5, float(x0[3]) + 1.0, params.v_max)
    lo, hi = direction_box(x0, H, dt, params, min(v_cap, params.v_max) if x0[3] <= params.v_max else v_cap)
    width = float(route.width_at(s0))
    # lateral offsets: the drivable band (never narrower than where the ego / the linearisation are)
    n_bar = np.stack([-np.sin(h_bar), np.cos(h_bar)], axis=1)
    e_bar = np.einsum("kj,kj->k", n_bar, xs_bar[:, :2] - p_bar)
    if settings.band:  # never narrower than where the ego already is (so the step stays feasible)
        b_lo, b_hi = drivable_band(world, s_bar[1:])
        e_lo = np.minimum(b_lo, e_bar[0] - 0.05)
        e_hi = np.maximum(b_hi, e_bar[0] + 0.05)
    else:
        e_lo, e_hi = np.full(H, -1e4), np.full(H, 1e4)
    term = TerminalStop()
    s_line = math.inf
    if any(stop_rules):
        s_line = float(stop_lines(hc, stop=stop_rules[0], light=stop_rules[1])[-1])
    if route.v_des.size and route.v_des[-1] <= 1e-9:  # the route stops at its goal
        s_line = min(s_line, float(route.s[-1]) + stop_margin)
    if math.isfinite(s_line):
        reach = min(max(s_line - stop_margin - s0, 0.5), world.settings.r_near)
        term = terminal_stop(s_line, s0 + ref.d_brake, ref.v_brake, decel=stop_decel, reach=reach, margin=stop_margin)
    return StepData(t, x0, np.asarray(u_prev, float), xs_bar, us_bar, A, B, c, omega, s_ref, s_bar, h_bar, p_bar,
                    lo, hi, hc, width, e_lo, e_hi, term, steering_bound(np.maximum(xs_bar[:-1, 3], x0[3]),
                                                                        route.curvature_at(s_ref[:-1]),
                                                                        params))


def history_length(history: Mapping[str, np.ndarray] | None, names: set[str], depth: int) -> int:
    """How many past samples every signal in ``names`` has (at most ``depth``)."""
    if depth <= 0 or not history:
        return 0
    n = depth
    for name in names:
        h = history.get(name)
        n = min(n, 0 if h is None else len(h))
    return max(n, 0)
