"""Fail-safe trajectories of the ego on the detailed four-wheel model: brake to standstill along
the route, or clear a conflict zone first, then brake.

A fail-safe is a sequence of actuator commands [δ [rad], γ [-]] per control step from a given
detailed state, with the states the detailed model (:mod:`twolevel.models.rollout`, the plant's
own equations and parameters) goes through under it, until the car stands (speed ≤
``v_stop``). Replayed from the same state with the same parameters it reproduces these states,
so what is executed is what was verified; after its last command the car holds the brake
(:meth:`FailSafe.control_at`).

**Manoeuvres** (:func:`manoeuvres`), in the order the verifier tries them:

* ``brake`` at a few deceleration levels, the gentlest first: RSS's ``brake_min`` (4 m/s², what
  a follower may expect of the car ahead; no fail-safe brakes more gently, so a car that cuts in
  leaving RSS's distance is always one the fail-safe stops for), a firmer level, then full
  braking (γ = −1, ≈ 9.3 m/s² on dry tarmac, the tyres' limit);
* ``clear`` when a conflict zone (a stretch of the route that crosses or merges with another
  lane, :attr:`~twolevel.safety.network.Network.zones`) lies within the braking distance or the
  car is in one: keep the speed (or gain some, from standstill too) until the car's centre is
  past the zone's end by ``clear_margin``, then brake. A car already inside a junction leaves it.

* **returning** ones when the car is out of the route's lane (passing over the oncoming lane, or
  its box over the line): brake while steering back into the lane (behind what it passes), creep
  back, or complete the pass — out beside what it passes, past it, back into the lane, then
  brake (:func:`manoeuvres`' ``back``; the lateral path is :func:`return_path`, tracked in
  half-second closed-loop segments).

**Steering** follows the route: the curvature along the manoeuvre's speed profile as feed-
forward (δ = atan(wheelbase · κ)), plus a correction of the heading and lateral errors at the
start (Stanley's law, faded out over a second), bounded by a lateral acceleration ``a_lat_max``
at speed. The whole fail-safe is one deterministic function of the start state.

Batched over manoeuvres (one compiled rollout per chunk for all of them). Units: m, s, m/s,
m/s², rad.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from twolevel.models.actuation import accel_from_gamma, gamma_from_accel
from twolevel.models.params import VehicleParams
from twolevel.models.rollout import Backend, rollout
from twolevel.world.geometry import Route

__all__ = ["FailSafeSettings", "Manoeuvre", "FailSafe", "manoeuvres", "roll", "brake_rate", "return_path",
           "catch_up", "MIN_GAIN", "FULL"]

FULL = math.inf
"""Deceleration level meaning full braking (γ = −1)."""


@dataclass(frozen=True)
class FailSafeSettings:
    """``decels`` [m/s²]: braking levels, gentlest first (:data:`FULL`: γ = −1); ``clear_accels``
    [m/s²]: accelerations while clearing a zone (0 keeps the speed); ``clear_brakes`` [m/s²]: the
    braking after clearing; ``clear_margin`` [m]; ``v_stop`` [m/s]: standing; ``max_time`` [s]: a fail-safe that has not stopped by then
    fails; Stanley gains ``k_heading`` [-] and ``k_lateral`` [1/s] (over speed); ``a_lat_max``
    [m/s²] bounds the steering at speed; ``delta_max`` [rad]."""

    decels: tuple[float, ...] = (4.0, 6.0, FULL)
    clear_accels: tuple[float, ...] = (0.0, 1.5)
    clear_brakes: tuple[float, ...] = (4.0, FULL)
    clear_margin: float = 1.0
    v_stop: float = 0.05
    max_time: float = 30.0
    k_heading: float = 1.0
    k_lateral: float = 1.5
    a_lat_max: float = 4.0
    delta_max: float = 0.5


@dataclass(frozen=True)
class Manoeuvre:
    """One fail-safe to try: ``decel`` [m/s²] braking level (:data:`FULL`), and for a clearing
    one the acceleration ``clear_accel`` [m/s²] held until the centre passes route position
    ``s_clear`` [m] (None: brake from the start). A **returning** one (``e_goal`` finite) steers
    back into the route's lane: its lateral offset follows a smooth step from where it starts to
    ``e_goal`` [m] between route positions ``s_return`` and ``s_return`` + ``d_return`` [m]
    — after first moving out to ``e_out`` [m] (beside what it passes; NaN: not) between
    ``s_out`` and ``s_out`` + ``d_out`` [m] (:func:`return_path`)."""

    decel: float
    clear_accel: float | None = None
    s_clear: float = -math.inf
    e_goal: float = math.nan
    s_return: float = -math.inf
    d_return: float = 0.0
    e_out: float = math.nan
    s_out: float = -math.inf
    d_out: float = 0.0

    @property
    def name(self) -> str:
        """A short label: ``brake 4``, ``brake full``, ``clear +1.5 to 84.0 m, brake 4``, with
        ``, back in lane`` for a returning one."""
        b = "full" if math.isinf(self.decel) else f"{self.decel:g}"
        back = "" if math.isnan(self.e_goal) else ", back in lane"
        if self.clear_accel is None:
            return f"brake {b}{back}"
        return f"clear {self.clear_accel:+g} to {self.s_clear:.1f} m, brake {b}{back}"


@dataclass(frozen=True, eq=False)
class FailSafe:
    """A fail-safe: ``controls`` (N, 2) [δ rad, γ] per step of ``dt`` [s] from ``states[0]``,
    ``states`` (N+1, 12) of the detailed model, whether it ``stopped`` (speed ≤ v_stop at the end)
    and the manoeuvre it executes."""

    manoeuvre: Manoeuvre
    controls: np.ndarray
    states: np.ndarray
    dt: float
    stopped: bool
    hold: np.ndarray = field(default_factory=lambda: np.array([0.0, -1.0]))

    @property
    def name(self) -> str:
        return self.manoeuvre.name

    @property
    def steps(self) -> int:
        """Number of commands N."""
        return len(self.controls)

    @property
    def t_stop(self) -> float:
        """Time from the start to standstill [s] (N · dt)."""
        return self.steps * self.dt

    def control_at(self, k: int) -> np.ndarray:
        """The command [δ, γ] at step k ≥ 0 from the start; after the last, the held brake."""
        return self.controls[k].copy() if k < self.steps else self.hold.copy()


def manoeuvres(settings: FailSafeSettings, zones: np.ndarray, s0: float, v0: float, brake_full: float,
               back: tuple[float, ...] | None = None) -> list[Manoeuvre]:
    """The manoeuvres to try from route position ``s0`` [m] at speed ``v0`` [m/s], in order:
    each braking level, then clearing the first conflict zone (``zones`` (Z, 2) [m] of the centre)
    that the car is in or cannot be sure to stop before (its gentlest braking distance reaches
    it), with ``brake_full`` [m/s²] the full-braking deceleration. ``back`` = (e_goal [m],
    s_past [m], e_beside [m][, v_past [m/s][, e_now [m]]]): the car is out of the route's lane
    (on the oncoming lane, passing): every braking level steers back to lateral offset e_goal
    while it brakes (behind what it passes), a creep at 1 m/s² steers back over the length the
    steering limit needs, and, when s_past is finite (the route position its centre must pass
    now to be ahead of what it passes, which drives on at up to v_past along the route, 0 when
    omitted), it also completes the pass: keeps its speed (or gains some) while it moves from
    e_now out to e_beside (beside what it passes) and past where it catches up with s_past
    (:func:`catch_up`), steers back over the distance a lateral acceleration of
    ``settings.a_lat_max``/2 needs at the speed it has there, then brakes (:func:`_returning`)."""
    if back is not None:
        return _returning(settings, s0, v0, brake_full, *back)
    out = [Manoeuvre(d) for d in settings.decels]
    gentle = min(settings.decels) if settings.decels else brake_full
    reach = s0 + v0**2 / (2 * min(gentle, brake_full)) + 1.0
    ahead = [z for z in np.asarray(zones).reshape(-1, 2) if z[1] >= s0 and z[0] <= reach]
    if ahead:
        s_clear = float(ahead[0][1]) + settings.clear_margin
        out += [Manoeuvre(b, a, s_clear) for b in settings.clear_brakes for a in settings.clear_accels
                if _moves(a, v0, s_clear - s0, settings.max_time)]
    return out


KEEP_MIN = 0.5
"""[m/s] Below this speed, keeping it clears nothing: a manoeuvre that clears a zone or completes a
pass from a (near) standstill gains speed."""


PASS_PACE = 3.0
"""[m/s] The slowest speed the path of a completed pass is laid out for (its way back into the
lane is as long as at this speed): a slower car keeps its speed along it (from :data:`KEEP_MIN`,
:func:`_moves`) or gains speed."""


def _moves(accel: float, v0: float, distance: float, max_time: float) -> bool:
    """Whether holding ``accel`` [m/s²] from speed ``v0`` [m/s] gets to a point ``distance`` [m]
    ahead within ``max_time`` [s]: keeping a speed below :data:`KEEP_MIN` does not count, nor one too
    slow for the distance (the manoeuvre would not brake before its time is up: its rollout, in
    half-second segments when it returns to the lane, would run to ``max_time`` and fail)."""
    return accel > 0 or (v0 >= KEEP_MIN and distance <= v0 * max_time)


def catch_up(s0: float, v0: float, accel: float, s_past: float, v_past: float) -> float:
    """[m] Where a car at route position ``s0`` [m] and speed ``v0`` [m/s], holding ``accel``
    [m/s²] (≥ 0), draws level with a point now at ``s_past`` [m] that moves on at ``v_past``
    [m/s] (a vehicle being passed, which does not speed up: ahead of it by as much as s_past is
    ahead of it now); ``s_past`` itself when it stands or the car is already there; +inf when the
    car never gets there (no faster than the point, gaining no speed)."""
    gap = s_past - s0
    if gap <= 0.0 or v_past <= 0.0:
        return max(s_past, s0)
    dv = v0 - v_past
    if accel > 0.0:
        t = (-dv + math.sqrt(dv * dv + 2.0 * accel * gap)) / accel
    elif dv > 0.0:
        t = gap / dv
    else:
        return math.inf
    return s_past + v_past * t


MIN_GAIN = 0.2
"""[m/s²] The least acceleration a completing pass gains speed at: below it, it keeps its speed."""


def _step_length(v: float, accel: float, k: float) -> float:
    """[m] The length d of a smooth lateral step (3u² − 2u³) begun at speed ``v`` [m/s] and driven
    at ``accel`` [m/s²] whose peak lateral acceleration, at the speed it ends with, stays within
    the bound ``k`` [m] states: (v² + 2·accel·d)·k ≤ d² (k = 6·rise / bound)."""
    return accel * k + math.sqrt(accel * accel * k * k + v * v * k)


def _accel_within(v: float, d: float, k: float) -> float:
    """[m/s²] The largest acceleration from speed ``v`` [m/s] at which a smooth lateral step of
    length ``d`` [m] keeps within the bound ``k`` [m] (:func:`_step_length`'s); +inf when there is
    no step (k = 0), negative when even the speed v is too fast for it."""
    if k <= 0.0:
        return math.inf
    return (d * d - v * v * k) / (2.0 * k * max(d, 1e-6))


def _returning(settings: FailSafeSettings, s0: float, v0: float, brake_full: float, e_goal: float,
               s_past: float, e_beside: float, v_past: float = 0.0, e_now: float | None = None) -> list[Manoeuvre]:
    """:func:`manoeuvres` for a car out of the route's lane (its ``back``): the gentlest and the
    full braking level, the creep, and completing the pass at the speed it has (at
    :data:`KEEP_MIN` or more, when that gets it there in time: :func:`_moves`) or gaining 1.5
    m/s² — less where the way out beside what it passes (from ``e_now`` [m], where it is; e_goal
    when not given) would take more lateral acceleration at the speed gained than a_lat_max/2
    (:func:`_accel_within`) —, returning where it has caught up with what it passes (``v_past``
    [m/s] its speed, :func:`catch_up`) over a way back laid out for the speed it then has
    (:func:`_step_length`), braking gently after — completing first when the car is already out
    beside what it passes (the likeliest to pass verification, tried alone first; few
    manoeuvres, since each is rolled out in half-second closed-loop segments)."""
    e_now = e_goal if e_now is None else e_now
    levels = sorted({min(settings.decels), max(settings.decels)}) if settings.decels else [brake_full]
    out = [Manoeuvre(d, e_goal=e_goal, s_return=s0,
                     d_return=max(v0**2 / (2 * min(brake_full, d)), 0.5)) for d in levels]
    # slow or standing: creep back, over the distance the steering limit needs for the step
    d_min = math.sqrt(6.0 * 3.5 * 2.7 / math.tan(0.8 * settings.delta_max))  # a lane's width, wheelbase ~2.7 m
    out.append(Manoeuvre(levels[0], 1.0, s0 + d_min, e_goal, s0, d_min))
    if math.isfinite(s_past):
        # a smooth step of rise R over d peaks at lateral acceleration v²·6R/d²: within a_lat_max/2
        k_ret = 6.0 * 3.5 / (0.5 * settings.a_lat_max)  # [m] a lane's width back
        k_out = 6.0 * abs(e_beside - e_now) / (0.5 * settings.a_lat_max)  # out beside it
        room = max(0.6 * (max(s_past, s0) - s0), 0.5)  # out beside it before its rear
        d_out = min(_step_length(max(v0, PASS_PACE), 0.0, k_ret), room)
        gain = min(max(settings.clear_accels, default=0.0), _accel_within(v0, d_out, k_out))
        brake = min(settings.clear_brakes) if settings.clear_brakes else levels[0]
        complete = []
        for a in sorted({0.0, gain if gain >= MIN_GAIN else 0.0}):
            start = catch_up(s0, v0, a, s_past, v_past)
            if not math.isfinite(start):
                continue
            v_ret = math.sqrt(v0 * v0 + 2.0 * a * max(start - s0, 0.0))  # at the start of the way back
            d_ret = _step_length(max(v_ret, PASS_PACE), a, k_ret)
            if _moves(a, v0, start + d_ret - s0, settings.max_time):
                complete.append(Manoeuvre(brake, a, start + d_ret, e_goal, start, d_ret, e_beside, s0, d_out))
        out = complete + out if abs(e_beside - e_goal) > 0 and v0 > 1.0 else out + complete
    return out


def _smooth_step(s: np.ndarray, start: np.ndarray, length: np.ndarray, rise: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``rise`` · (3u² − 2u³), u = (s − start)/length clipped to [0, 1], with its first and second
    derivatives along s."""
    d = np.maximum(length, 1e-3)
    u = np.minimum(np.maximum((s - start) / d, 0.0), 1.0)  # np.clip's, without its wrapper's overhead
    inside = (u > 0.0) & (u < 1.0)
    return (rise * (3 * u**2 - 2 * u**3), np.where(inside, rise * 6 * u * (1 - u) / d, 0.0),
            np.where(inside, rise * (6 - 12 * u) / d**2, 0.0))


def return_path(e_from: np.ndarray, path: tuple[np.ndarray, ...], s: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lateral offset [m] a returning fail-safe follows at route positions ``s`` [m] (rows
    broadcast with ``e_from`` [m], where it starts, and the arrays of ``path`` = (e_out, s_out,
    d_out, e_goal, s_return, d_return), each of the manoeuvres' fields): a smooth step out to
    e_out over [s_out, s_out + d_out] (none where e_out is NaN), then one to ``e_goal`` over
    [s_return, s_return + d_return]; with its slope [-] and curvature [1/m] along s. NaN goals give
    the route's centre line (0, 0, 0)."""
    return _path_at(e_from, _path_steps(e_from, path), s)


_Steps = tuple[tuple[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _path_steps(e_from: np.ndarray, path: tuple[np.ndarray, ...]) -> _Steps:
    """:func:`return_path`'s two smooth steps, (start [m], length [m], rise [m]) each, and where
    there is no goal: what does not depend on s (a rollout computes it once)."""
    e_out, s_out, d_out, e_goal, s_ret, d_ret = path
    out = ~np.isnan(e_out)
    mid = np.where(out, e_out, e_from)
    return ((s_out, d_out, np.where(out, e_out - e_from, 0.0)), (s_ret, d_ret, np.nan_to_num(e_goal - mid)),
            np.isnan(e_goal))


def _path_at(e_from: np.ndarray, steps: _Steps, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`return_path` at ``s`` [m] from its steps (:func:`_path_steps`)."""
    first, second, none = steps
    e1, g1, c1 = _smooth_step(s, *first)
    e2, g2, c2 = _smooth_step(s, *second)
    return (np.where(none, 0.0, e_from + e1 + e2), np.where(none, 0.0, g1 + g2), np.where(none, 0.0, c1 + c2))


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


@functools.lru_cache(maxsize=16)
def brake_rate(params: VehicleParams) -> float:
    """Full braking's deceleration [m/s²] (γ = −1, quasi-static, at low speed)."""
    return float(-accel_from_gamma(-1.0, 0.0, params))


def _roll_live(x: np.ndarray, u: np.ndarray, live: np.ndarray, dt: float, params: VehicleParams,
               backend: Backend) -> np.ndarray:
    """The states (K, n+1, 12) of the rows ``live`` (K,) of the rollout of commands ``u`` (K, n, 2)
    from ``x`` (K, 12); the other rows (fail-safes that have stopped: their states after the stop
    are never read) stand at their ``x`` — only the live rows are simulated."""
    if live.all():
        return rollout(x, u, dt, params, backend).states
    ro = np.repeat(x[:, None, :], u.shape[1] + 1, axis=1)
    if live.any():
        ro[live] = rollout(x[live], u[live], dt, params, backend).states
    return ro


def roll(x0: np.ndarray, plan: list[Manoeuvre], route: Route, s0: float, dt: float, params: VehicleParams,
         settings: FailSafeSettings = FailSafeSettings(), backend: Backend = "auto") -> list[FailSafe]:
    """The fail-safes of the manoeuvres ``plan`` from the detailed state ``x0`` (12,) (or one
    state per manoeuvre, (K, 12)), the ego's centre being near route position ``s0`` [m] (or
    (K,)), where its projection is searched.

    All manoeuvres are rolled out together in segments: each segment's commands are planned from
    its start state (the speed and route position profile of the manoeuvre, steering from the
    curvature along it and the errors at the start), as long as the manoeuvre needs to stop by
    that profile (rounded up to whole seconds, so that few compiled rollouts serve all lengths);
    a manoeuvre that has not stopped by the end of a segment gets another one."""
    K = len(plan)
    if K == 0:
        return []
    st = settings
    full = brake_rate(params)
    decel = np.array([full if math.isinf(m.decel) else m.decel for m in plan])
    is_full = np.array([math.isinf(m.decel) for m in plan])
    clear_a = np.array([np.nan if m.clear_accel is None else m.clear_accel for m in plan])
    s_clear = np.array([m.s_clear for m in plan])
    path = tuple(np.array([getattr(m, f) for m in plan])
                 for f in ("e_out", "s_out", "d_out", "e_goal", "s_return", "d_return"))
    returning = ~np.isnan(path[3])
    path_end = path[4] + path[5]
    path_rows = tuple(p[:, None] for p in path)
    has_clear = ~np.isnan(clear_a)
    ca = np.where(has_clear, clear_a, 0.0)  # np.nan_to_num's, without its wrapper
    ca_col, decel_col, full_col = ca[:, None], decel[:, None], is_full[:, None]
    s_last = float(route.s[-1])
    e_from: np.ndarray | None = None
    L = params.wheelbase
    n_max = int(math.ceil(st.max_time / dt))
    bucket = max(1, int(round(1.0 / dt)))
    x = np.array(np.broadcast_to(np.asarray(x0, dtype=float), (K, 12)))
    states, controls = [x[:, None, :]], []
    s_hint = np.array(np.broadcast_to(np.asarray(s0, dtype=float), (K,)))
    stop_at = np.full(K, -1)
    done = 0
    along: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # per segment length: its times [s] and Stanley's fade
    # a segment's planning is a few hundred operations on (K, n) arrays of a handful of rows, so each
    # is written as the cheapest numpy call that gives the same bits (np.minimum(np.maximum) for
    # np.clip, one errstate for the whole loop, the times and fade of a segment length computed once)
    with np.errstate(divide="ignore", invalid="ignore"):
        while done < n_max and (stop_at < 0).any():
            v = np.maximum(x[:, 3], 0.0)
            s, e = route.project_near(x[:, :2], s_hint, 5.0 + float(v.max()) * dt)
            e_psi = _wrap(x[:, 2] - route.heading_at(s))
            if e_from is None:
                e_from = e.copy()[:, None]
                steps = _path_steps(e_from, path_rows)
            # the profile: clear (hold clear_a until s_clear), then brake at decel to standstill
            clearing = has_clear & (s < s_clear)
            t_c = np.where(clearing, np.where(np.abs(ca) > 1e-9,
                                              (-v + np.sqrt(np.maximum(v**2 + 2 * ca * (s_clear - s), 0.0))) / ca,
                                              (s_clear - s) / np.maximum(v, 1e-3)), 0.0)
            # NaN and +inf (no time to clear) → max_time; never −inf: a time to clear is ≥ 0
            t_c = np.minimum(np.where(np.isnan(t_c), st.max_time, t_c), st.max_time)
            v_c = v + ca * t_c * clearing
            need = t_c + v_c / decel + 2 * dt
            n = int(min(n_max - done, bucket * math.ceil(float(need[stop_at < 0].max()) / (bucket * dt) + 1e-9)))
            n = max(n, 1)
            if (returning & (stop_at < 0) & (s < path_end)).any():  # on a path: closed loop twice a second
                n = min(n, max(1, bucket // 2))
            if n not in along:
                tk_n = dt * np.arange(n)[None, :]
                along[n] = tk_n, np.minimum(np.maximum(1.0 - tk_n / 1.0, 0.0), 1.0)
            tk, fade = along[n]
            in_clear = clearing[:, None] & (tk < t_c[:, None])
            tb = np.maximum(tk - t_c[:, None], 0.0)
            v_pred = np.where(in_clear, v[:, None] + ca_col * tk, np.maximum(v_c[:, None] - decel_col * tb, 0.0))
            s_c = s + v * t_c + 0.5 * ca * clearing * t_c**2
            tb_stop = np.minimum(tb, v_c[:, None] / decel_col)
            s_pred = np.where(in_clear, s[:, None] + v[:, None] * tk + 0.5 * ca_col * tk**2,
                              s_c[:, None] + v_c[:, None] * tb_stop - 0.5 * decel_col * tb_stop**2)
            u = np.empty((K, n, 2))  # (K, n, 2): [δ, γ]
            held = full_col & ~in_clear
            if held.all():  # full braking throughout: γ = −1 (the inverse map's value is not read)
                u[..., 1] = -1.0
            else:
                a_k = np.where(in_clear, ca_col, -decel_col)
                u[..., 1] = np.where(held, -1.0, gamma_from_accel(a_k, v_pred, params))
            # steering: curvature along the profile + Stanley's correction, faded out over a second;
            # the lateral path at the start (column 0: the errors) and along the profile (its curvature) at once
            e_path, slope, path_curv = _path_at(e_from, steps, np.concatenate([s[:, None], s_pred], axis=1))
            e_path, slope, path_curv = e_path[:, 0], slope[:, 0], path_curv[:, 1:]
            ff = np.arctan(L * (route.curvature_at(np.minimum(s_pred, s_last)) + path_curv))
            fb = -(st.k_heading * (e_psi - np.arctan(slope)) + np.arctan2(st.k_lateral * (e - e_path), v + 1.0))
            bound = np.minimum(st.delta_max, np.arctan(st.a_lat_max * L / np.maximum(v_pred**2, 1e-6)))
            u[..., 0] = np.minimum(np.maximum(ff + fb[:, None] * fade, -bound), bound)
            ro = _roll_live(x, u, stop_at < 0, dt, params, backend)  # (K, n+1, 12)
            controls.append(u)
            states.append(ro[:, 1:])
            stopped = ro[:, 1:, 3] <= st.v_stop
            first = np.where(stopped.any(axis=1), stopped.argmax(axis=1), -1)
            new = (stop_at < 0) & (first >= 0)
            stop_at = np.where(new, done + first + 1, stop_at)
            x = ro[:, -1]
            s_hint = s_pred[:, -1]
            done += n
    U = np.concatenate(controls, axis=1)
    X = np.concatenate(states, axis=1)
    out = []
    for k, m in enumerate(plan):  # a handful of manoeuvres
        n = int(stop_at[k]) if stop_at[k] >= 0 else done
        out.append(FailSafe(m, U[k, :n].copy(), X[k, : n + 1].copy(), dt, bool(stop_at[k] >= 0)))
    return out
