"""What one MPC step knows before it builds a model: the linearisation point and the bounds.

:func:`prepare_step` turns (ego state, time, traffic, history, previous plan) into a
:class:`StepData`: the reference (:mod:`twolevel.control.high_level.reference`: waypoints ω_k
and the solve-time constants), the linearisation point (the previous plan shifted by one period,
:func:`shifted`; a rollout of the reference's controls; or full braking), the Jacobians of the
kinematic bicycle along it (:func:`twolevel.models.bicycle.linearize`, vectorised, each step for
its own length), the state and steering bounds (reachable boxes; the speed the ego can stop from
within its sensing range) and the guards (:mod:`twolevel.control.high_level.guards`: the
drivable band, the terminal can-still-stop condition, RSS's distance to the vehicle ahead).
Everything spans the whole look-ahead of :class:`~twolevel.control.high_level.settings.MPCSettings`
(N steps, the first H of one period dt). Units: m, rad, m/s, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from twolevel.control.high_level.overtaking import oncoming_band
from twolevel.control.high_level.guards import (Pass, RssTerminal, TerminalStop, drivable_band, rss_terminal,
                                                stop_lines, terminal_stop)
from twolevel.control.high_level.neighbours import NEIGHBOUR_SIGNALS, NeighbourConstants, neighbour_constants
from twolevel.control.high_level.right_of_way import GapRule, ZoneConstants, give_way_line
from twolevel.control.high_level.reference import reference, reference_controls, wrap_to
from twolevel.control.high_level.settings import MPCSettings
from twolevel.control.high_level.steering import heading_weight, steering_bound, steering_reference, steering_weight
from twolevel.control.planner import PreviousPlan
from twolevel.models import bicycle
from twolevel.models.params import BicycleParams
from twolevel.stl.analysis import split_participant_key
from twolevel.world.signals import HorizonConstants, StopMemory
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["StepData", "prepare_step", "direction_box", "steering_bound", "history_length", "shifted", "sensing_bound"]


@dataclass(frozen=True, eq=False)
class StepData:
    """One step's known quantities over the look-ahead (k = 0..N; index 0 is now; the first H
    steps last one period, ``steps`` (N,) [s] are all the lengths).

    ``xs_bar`` (N+1, 4) / ``us_bar`` (N, 2): linearisation point; ``A`` (N, 4, 4), ``B`` (N, 4, 2),
    ``c`` (N, 4): x_{k+1} ≈ A_k x_k + B_k u_k + c_k; ``omega`` (N, 4): waypoints for k = 1..N;
    ``s_ref`` (N+1,) [m] route positions of the waypoints; ``s_bar``/``h_bar``/``p_bar``: route
    position, tangent heading and route point of the linearisation point's projection (k = 0..N),
    for s_k ≈ s̄_k + t̄_kᵀ(p_k − p̄_k); ``lo``/``hi`` (N, 4): state bounds for k = 1..N;
    ``e_lo``/``e_hi`` (N,) [m]: bounds on the lateral offset e_k ≈ n̄_kᵀ(p_k − p̄_k) for k = 1..N
    (:func:`twolevel.control.high_level.guards.drivable_band`, widened to include where the ego and the
    linearisation point already are); ``term``: the can-still-stop terminal condition at step N
    (:func:`twolevel.control.high_level.guards.terminal_stop`, inactive when no line applies); ``delta_hi``
    (N,) [rad]: the steering bound per step (:func:`steering_bound`; None: the steering limit);
    ``rss``: RSS's distance to the vehicle ahead at step N (:func:`twolevel.control.high_level.guards.rss_terminal`;
    None when the settings do not ask for it); ``steer_ref`` (N,) [rad]: the steering that follows
    the route's curvature, ``steer_weight`` (N,) [-]: the factor on the steering terms' weights at
    the linearisation point's speeds (:mod:`twolevel.control.high_level.steering`; None: the
    paper's cost, δ weighed in rad about 0); ``head_weight`` (N,) [-]: the factor on the heading's
    tracking weight while the ego passes over the oncoming lane
    (:func:`~twolevel.control.high_level.steering.heading_weight`; None: the paper's, ψ in rad)."""

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
    steps: np.ndarray = field(default_factory=lambda: np.zeros(0))
    H: int = 0
    rss: RssTerminal | None = None
    steer_ref: np.ndarray | None = None
    steer_weight: np.ndarray | None = None
    zones: ZoneConstants | None = None
    neighbours: NeighbourConstants | None = None
    head_weight: np.ndarray | None = None

    @property
    def N(self) -> int:
        """Steps of the look-ahead."""
        return int(self.A.shape[0])


def _cos_range(lo: np.ndarray, hi: np.ndarray, phase: float) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of cos(θ − phase) over θ ∈ [lo, hi] (vectorised)."""
    a, b = lo - phase, hi - phase
    ca, cb = np.cos(a), np.cos(b)
    mn, mx = np.minimum(ca, cb), np.maximum(ca, cb)
    has_max = np.floor(b / (2 * math.pi)) >= np.ceil(a / (2 * math.pi))
    has_min = np.floor((b - math.pi) / (2 * math.pi)) >= np.ceil((a - math.pi) / (2 * math.pi))
    return np.where(has_min, -1.0, mn), np.where(has_max, 1.0, mx)


def direction_box(x0: np.ndarray, ticks: np.ndarray, dt: float, params: BicycleParams, v_cap: float,
                  margin: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """State bounds (N, 4) for k = 1..N at the times dt·``ticks`` [s] (``ticks`` (N+1,), whole
    periods from now): speed in [0, min(v0 + a_max·t_k, v_cap)], heading within the yaw the
    steering limit allows, and X/Y within the sum of per-step displacement boxes (distance ≤
    v·h_k in any direction of the reachable heading cone), widened by ``margin`` [m]."""
    X, Y, psi, v = (float(a) for a in x0[:4])
    k = np.asarray(ticks)[1:]
    H = len(k)
    h = dt * np.diff(ticks)
    v_hi = np.minimum(v + params.a_max * k * dt, v_cap)
    step = h * np.concatenate([[v], v_hi[:-1]]) + 0.5 * params.a_max * h * h
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


def shifted(prev: PreviousPlan, x0: np.ndarray, periods: np.ndarray, dt: float, params: BicycleParams
            ) -> tuple[np.ndarray, np.ndarray]:
    """The previous plan one period ``dt`` [s] later, on this step's grid of ``periods`` (N,)
    [periods per step]: states (N+1, 4) — ``x0`` now, then the previous plan's state at each
    step's time (its own sample when the grids meet, as over the fine part; else advanced from
    the sample before by the control it held, exactly: the bicycle under a held control) — and
    controls (N, 2), the previous plan's control in force at each step's start (its last one
    beyond its end)."""
    ticks = np.concatenate([[0], np.cumsum(periods)])
    prev_ticks = np.concatenate([[0], np.cumsum(prev.periods)])
    q = ticks[1:] + 1  # this step's sample times in the previous plan's periods
    j = np.clip(np.searchsorted(prev_ticks, q, side="right") - 1, 0, len(prev_ticks) - 1)
    u_j = prev.controls[np.minimum(j, len(prev.controls) - 1)]
    xs = np.vstack([x0[None], bicycle.step(prev.states[j], u_j, dt * (q - prev_ticks[j]), params)])
    xs[:, 2] = wrap_to(xs[:, 2], float(x0[2]))
    jc = np.clip(np.searchsorted(prev_ticks, ticks[:-1] + 1, side="right") - 1, 0, len(prev.controls) - 1)
    return xs, prev.controls[jc]


def sensing_bound(v0: float, ticks: np.ndarray, dt: float, v_sense: float, brake: float) -> np.ndarray:
    """The speed bound [m/s] at the times dt·``ticks[1:]`` [s] from what the ego can see:
    ``v_sense`` [m/s] (it stops within its sensing range from there,
    :class:`~twolevel.world.loader.Sensing`), or, for an ego already faster (``v0`` [m/s]),
    braking at ``brake`` [m/s²] down to it."""
    return np.maximum(v_sense, v0 - brake * dt * np.asarray(ticks[1:]))


def prepare_step(
    world: World, x0: np.ndarray, t: float, traffic: TrafficState, settings: MPCSettings, params: BicycleParams,
    *, prev: PreviousPlan | None = None, u_prev: np.ndarray | None = None, memory: StopMemory | None = None,
    s_hint: float | None = None, about: str = "plan", stop_rules: tuple[bool, bool, bool] = (False, False, False),
    passing: Pass | None = None, gap: GapRule = GapRule(),
) -> StepData:
    """Everything known at time ``t`` [s] for ego state ``x0`` = (X, Y, ψ, v), over the
    look-ahead of ``settings``.

    ``prev``: the previous plan, made one period ago; shifted by one period (:func:`shifted`) it
    gives the linearisation point (``about="plan"``); ``about="reference"`` linearises about a
    rollout of the reference's controls, ``"brake"`` about full braking. ``u_prev`` [δ, a] is the
    control applied during the last step (for the ‖u_0 − u_{−1}‖² term; default the previous
    plan's first). ``stop_rules`` = (a rule reads d_stop, a rule reads light_red/d_light, a rule reads
    xwalk_busy/d_xwalk): which
    lines the terminal can-still-stop condition guards, with ``settings.stop_decel`` [m/s²] and
    ``settings.stop_margin`` [m] before the line; ``settings.band``: bound the lateral offset to
    the drivable band; ``gap``: the gap the right-of-way rule asks for (the give-way line,
    :mod:`~twolevel.control.high_level.right_of_way`); ``settings.rss``: keep RSS's distance behind the vehicle ahead, or pass it
    (``passing``: a pass under way, :class:`~twolevel.control.high_level.guards.Pass`). The speed
    is bounded by what the ego can see (:func:`sensing_bound`, the world's
    ``settings.v_sense``). ``memory``, ``s_hint``: see
    :func:`~twolevel.control.high_level.reference.reference`."""
    H, N, dt = settings.H, settings.N, settings.dt
    periods = np.asarray(settings.periods)
    ticks = np.asarray(settings.ticks)
    steps = dt * periods
    stop_decel, stop_margin = settings.stop_decel, settings.stop_margin
    route = world.route
    ws = world.settings
    x0 = np.asarray(x0, dtype=float)[:4].copy()
    ref = reference(world, x0, t, traffic, settings, params, memory=memory, s_hint=s_hint, stop_rules=stop_rules,
                    passing=passing, gap=gap if "priority" in world.participant_signals else None)
    s0, s_ref, v_ref, omega, hc = ref.s0, ref.s_ref, ref.v_ref, ref.omega, ref.hc
    if about == "brake":  # a braking rollout with the wheel straight (to standstill, no reversing)
        us_bar = np.zeros((N, 2))
        v = float(x0[3])
        for k in range(N):
            us_bar[k, 1] = max(params.a_min, -v / steps[k])
            v = max(v + us_bar[k, 1] * steps[k], 0.0)
        xs_bar = bicycle.rollout(x0, us_bar, steps, params)
        if u_prev is None and prev is not None:
            u_prev = prev.controls[0]
    elif prev is not None and about == "plan" and not (ref.oncoming and passing is None and x0[3] < PASS_FROM_REST):
        xs_bar, us_bar = shifted(prev, x0, periods, dt, params)
        if u_prev is None:
            u_prev = prev.controls[0]
    else:
        us_bar = reference_controls(route.curvature_at(s_ref[:-1]), v_ref, steps, params)
        xs_bar = bicycle.rollout(x0, us_bar, steps, params)
    if u_prev is None:
        u_prev = np.zeros(2)
    A, B, c = bicycle.linearize(xs_bar[:-1], us_bar, steps, params)
    v_guess = max(x0[3], 1.0)
    T = float(ticks[-1] * dt)
    s_bar, _ = route.project_near(xs_bar[:, :2], np.full(N + 1, s0) + ticks * dt * v_guess,
                                  T * (v_guess + params.a_max * ticks[-1] * dt) + 10.0)
    h_bar = route.heading_at(s_bar)
    p_bar = route.position(s_bar)
    v_cap = max(float(route.limit_v.max()) * 1.5, float(x0[3]) + 1.0, params.v_max)
    lo, hi = direction_box(x0, ticks, dt, params, min(v_cap, params.v_max) if x0[3] <= params.v_max else v_cap)
    if math.isfinite(ws.v_sense):
        hi[:, 3] = np.minimum(hi[:, 3], sensing_bound(float(x0[3]), ticks, dt, ws.v_sense, ws.response.brake_min))
    width = float(route.width_at(s0))
    # lateral offsets: the drivable band (never narrower than where the ego / the linearisation are)
    n_bar = np.stack([-np.sin(h_bar), np.cos(h_bar)], axis=1)
    e_bar = np.einsum("kj,kj->k", n_bar, xs_bar[:, :2] - p_bar)
    if settings.band:  # never narrower than where the ego already is (so the step stays feasible)
        b_lo, b_hi = drivable_band(world, s_bar[1:])
        if ref.oncoming:  # a pass over the oncoming lane (its gap accepted by the reference)
            b_lo, b_hi, _ = oncoming_band(world, s_bar[1:])
        e_lo = np.minimum(b_lo, e_bar[0] - 0.05)
        e_hi = np.maximum(b_hi, e_bar[0] + 0.05)
    else:
        e_lo, e_hi = np.full(N, -1e4), np.full(N, 1e4)
    term = TerminalStop()
    s_line = math.inf
    if any(stop_rules):
        s_line = float(stop_lines(hc, stop=stop_rules[0], light=stop_rules[1], xwalk=stop_rules[2])[-1])
    zones = ref.zones
    s_line = min(s_line, give_way_line(zones))
    if route.v_des.size and route.v_des[-1] <= 1e-9:  # the route stops at its goal
        s_line = min(s_line, float(route.s[-1]) + stop_margin)
    if math.isfinite(s_line):
        reach = min(max(s_line - stop_margin - s0, 0.5), ws.r_near)
        term = terminal_stop(s_line, s0 + ref.d_brake, ref.v_brake, decel=stop_decel, reach=reach, margin=stop_margin)
    rss = None
    if settings.rss:
        v_lo = np.maximum(float(x0[3]) + params.a_min * dt * ticks[1:], 0.0)
        rss = rss_terminal(hc, ref.front, ws.response, s0=s0, v0=float(x0[3]), steps=steps, H=H, v_lo=v_lo, v_hi=hi[:, 3],
                           v_bar=xs_bar[1:, 3], margin=ws.D_safe, a_min=params.a_min, lateral=ref.lateral,
                           sides=ref.sides, beside=ref.beside, e0=ref.e0, due=ref.due, early=ref.early)
    kappa = route.curvature_at(s_ref[:-1])
    v_bar = np.maximum(xs_bar[:-1, 3], x0[3])
    steer_weight = steering_weight(v_bar, params.l_f) if settings.lateral_weight else None
    # over the oncoming lane the lateral velocity is damped too (the car arrives there fast)
    head_weight = heading_weight(np.maximum(xs_bar[1:, 3], 0.0)) if settings.lateral_weight and ref.oncoming else None
    return StepData(t, x0, np.asarray(u_prev, float), xs_bar, us_bar, A, B, c, omega, s_ref, s_bar, h_bar, p_bar,
                    lo, hi, hc, width, e_lo, e_hi, term, steering_bound(v_bar, kappa, params), steps, H, rss,
                    steering_reference(kappa, params) if settings.lateral_weight else None, steer_weight, zones,
                    neighbour_constants(world, hc, s_bar, H) if set(NEIGHBOUR_SIGNALS) & set(world.participant_signals)
                    else None, head_weight)


PASS_FROM_REST = 3.0
"""[m/s] Below this speed a pass over the oncoming lane that begins now is linearised about the
reference, which drives off, not about the previous plan, which stood (about a standing plan the
linear model cannot move sideways, and the pass is never chosen)."""


def history_length(history: Mapping[str, np.ndarray] | None, names: set[str], depth: int) -> int:
    """How many past samples every signal in ``names`` has (at most ``depth``); participants'
    signals (``NAME[*]``) do not limit it."""
    if depth <= 0 or not history:
        return 0
    n = depth
    for name in names:
        if split_participant_key(name) is not None:  # a participant's signals: absent before it was sensed
            continue
        h = history.get(name)
        n = min(n, 0 if h is None else len(h))
    return max(n, 0)
