"""Other traffic: lights' states over time and every participant stepped by its behaviour.

Array-based (HighwayEnv's act-then-step, over all vehicles at once). Behaviours:
``stationary``; ``constant_velocity`` (along its lane when placed on one, else straight on);
``idm`` (Treiber's Intelligent Driver Model along its lane, reacting to the vehicle ahead — the
ego included — to red lights, to yellow lights it can stop for, and to stop signs, which it
serves by standing still for the sign's ``stop_time``); ``scripted`` (waypoints, linear in time).
A lane-following vehicle that runs off the end of a lane continues on the lane's first
successor, or leaves the map (``active`` false).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from twolevel.world.geometry import LaneSet

__all__ = ["GREEN", "YELLOW", "RED", "Lights", "StopLines", "SpeedLimits", "Participants", "TrafficState",
           "EgoBox", "step", "nearby", "STATIONARY", "CONSTANT_VELOCITY", "IDM", "SCRIPTED"]

GREEN, YELLOW, RED = 0, 1, 2
STATIONARY, CONSTANT_VELOCITY, IDM, SCRIPTED = 0, 1, 2, 3
_BIG = 1e7  # [m] separates lanes in sort keys


@dataclass(frozen=True, eq=False)
class Lights:
    """Traffic lights: stop line (lane index, s [m]) and program. Each light's program is phase
    start times ``times`` (n, P) [s] (padded with +inf) and ``states`` (n, P), repeating with
    ``period`` (n,) [s] (+inf for a script), shifted by ``offset`` (n,) [s]: the state at time t
    is the phase in force at u = (t + offset) mod period."""

    ids: tuple[str, ...]
    lane: np.ndarray
    s: np.ndarray
    times: np.ndarray
    states: np.ndarray
    period: np.ndarray
    offset: np.ndarray

    def state_at(self, t: np.ndarray | float) -> np.ndarray:
        """States (..., n) in {GREEN, YELLOW, RED} at times ``t`` (...) [s]."""
        t = np.asarray(t, dtype=float)[..., None]
        u = np.where(np.isfinite(self.period), np.mod(t + self.offset, np.where(np.isfinite(self.period), self.period, 1.0)),
                     t + self.offset)
        phase = (self.times <= u[..., None]).sum(-1) - 1
        phase = np.clip(phase, 0, self.times.shape[1] - 1)
        return np.take_along_axis(np.broadcast_to(self.states, phase.shape + (self.states.shape[1],)),
                                  phase[..., None], axis=-1)[..., 0]


@dataclass(frozen=True, eq=False)
class StopLines:
    """Stop signs: stop line (lane index, s [m]) and required standstill ``stop_time`` [s]."""

    ids: tuple[str, ...]
    lane: np.ndarray
    s: np.ndarray
    stop_time: np.ndarray


@dataclass(frozen=True, eq=False)
class SpeedLimits:
    """Speed limit by (lane, s): breakpoints with global keys ``base[lane] + s`` (sorted) and values [m/s]."""

    key: np.ndarray
    value: np.ndarray
    base: np.ndarray

    def at(self, lane: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Limit [m/s] in force at (lane index, s [m])."""
        j = np.clip(np.searchsorted(self.key, self.base[lane] + s, side="right") - 1, 0, len(self.key) - 1)
        return self.value[j]


@dataclass(frozen=True, eq=False)
class Participants:
    """What does not change: ids, behaviour kind (N,), boxes (N,) [m], IDM parameters (N, 6) as
    v0 [m/s] (NaN: min(120 km/h, lane limit)), T [s], s0 [m], a [m/s²], b [m/s²], delta, and
    scripted waypoints ``script_t`` (N, W) [s] / ``script_xy`` (N, W, 2) [m] padded with the last."""

    ids: tuple[str, ...]
    kind: np.ndarray
    length: np.ndarray
    width: np.ndarray
    idm: np.ndarray
    script_t: np.ndarray
    script_xy: np.ndarray


@dataclass(frozen=True, eq=False)
class TrafficState:
    """Every participant at time ``t`` [s]: pose x, y [m], psi [rad], speed v [m/s]; lane index
    (−1 off-lane), s and lateral [m] on it; ``active`` (false once off the map); IDM stop-sign
    memory: ``stop_timer`` [s] of standstill at a stop line and ``served`` (index of the last stop
    sign served, −1)."""

    t: float
    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    v: np.ndarray
    lane: np.ndarray
    s: np.ndarray
    lateral: np.ndarray
    active: np.ndarray
    stop_timer: np.ndarray
    served: np.ndarray

    @property
    def xy(self) -> np.ndarray:
        """Positions (N, 2) [m]."""
        return np.stack([self.x, self.y], axis=1)


@dataclass(frozen=True)
class EgoBox:
    """The ego as other traffic sees it: position [m], heading [rad], speed [m/s], length [m]."""

    x: float
    y: float
    psi: float
    v: float
    length: float = 4.22


def nearby(state: TrafficState, x: float, y: float, r_near: float) -> np.ndarray:
    """Mask (N,) of active participants whose centre is within ``r_near`` [m] of (x, y)."""
    return state.active & (np.hypot(state.x - x, state.y - y) <= r_near)


def _idm_accel(v: np.ndarray, v0: np.ndarray, gap: np.ndarray, dv: np.ndarray, p: np.ndarray) -> np.ndarray:
    T, s0, a, b, delta = p[:, 1], p[:, 2], p[:, 3], p[:, 4], p[:, 5]
    s_star = s0 + np.maximum(0.0, v * T + v * dv / (2 * np.sqrt(a * b)))
    return a * (1 - (v / v0) ** delta - (s_star / np.maximum(gap, 0.01)) ** 2)


def step(
    state: TrafficState, dt: float, *, lanes: LaneSet, parts: Participants, limits: SpeedLimits,
    lights: Lights, stops: StopLines, ego: EgoBox | None = None, stop_speed: float = 0.1,
) -> TrafficState:
    """Advance every participant by ``dt`` [s]; vectorised over participants."""
    with np.errstate(invalid="ignore"):
        return _step(state, dt, lanes, parts, limits, lights, stops, ego, stop_speed)


def _step(state: TrafficState, dt: float, lanes: LaneSet, parts: Participants, limits: SpeedLimits,
          lights: Lights, stops: StopLines, ego: EgoBox | None, stop_speed: float) -> TrafficState:
    n = len(state.x)
    kind = parts.kind
    on_lane = state.active & (state.lane >= 0)
    lane = np.maximum(state.lane, 0)
    t1 = state.t + dt

    # --- leaders: vehicles on the same lane (sorted by lane, s), plus the ego -----------
    keys = [np.where(on_lane, state.lane * _BIG + state.s, np.inf)]
    half = [parts.length / 2]
    speed = [state.v]
    if ego is not None:
        el, es, _ = lanes.lookup(np.array([[ego.x, ego.y]]), heading=np.array([ego.psi]))
        if el[0] >= 0:
            keys.append(el * _BIG + es)
            half.append(np.array([ego.length / 2]))
            speed.append(np.array([ego.v * np.cos(ego.psi - lanes.pose(el, es)[1][0])]))
    key = np.concatenate(keys)
    hl = np.concatenate(half)
    vv = np.concatenate(speed)
    order = np.argsort(key, kind="stable")
    sk = key[order]
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    nxt = np.minimum(rank[:n] + 1, len(order) - 1)
    lead = order[nxt]
    same = (nxt > rank[:n]) & (np.floor(sk[nxt] / _BIG) == lane) & np.isfinite(sk[nxt])
    gap = np.where(same, key[lead] - key[:n] - hl[lead] - hl[:n], np.inf)
    v_lead = np.where(same, vv[lead], state.v)
    # one lane ahead: the last vehicle on the successor lane
    succ = lanes.successor[lane]
    has_succ = ~same & (succ >= 0)
    if has_succ.any():
        j = np.minimum(np.searchsorted(sk, succ * _BIG, side="left"), len(sk) - 1)
        ok = has_succ & (np.floor(sk[j] / _BIG) == succ) & np.isfinite(sk[j])
        first = order[j]
        g2 = lanes.length[lane] - state.s + (sk[j] - succ * _BIG) - hl[first] - hl[:n]
        gap = np.where(ok, g2, gap)
        v_lead = np.where(ok, vv[first], v_lead)

    # --- stop lines: next light or stop sign ahead on the lane -------------------------
    line_lane = np.concatenate([lights.lane, stops.lane])
    line_key = np.concatenate([lights.lane * _BIG + lights.s, stops.lane * _BIG + stops.s])
    if len(line_key):
        lorder = np.argsort(line_key)
        lk = line_key[lorder]
        front = np.where(on_lane, state.lane * _BIG + state.s + parts.length / 2 - 0.5, np.inf)
        j = np.minimum(np.searchsorted(lk, front, side="left"), len(lk) - 1)
        li = lorder[j]
        found = on_lane & (line_lane[li] == state.lane) & (lk[j] >= front)
        d_line = np.where(found, lk[j] - (state.lane * _BIG + state.s + parts.length / 2), np.inf)
        n_lights = len(lights.ids)
        is_light = li < n_lights
        light_state = lights.state_at(state.t)[np.minimum(li, max(n_lights - 1, 0))] if n_lights else np.zeros(n, int)
        b = parts.idm[:, 4]
        can_stop = d_line >= state.v**2 / (2 * b)
        stop_idx = li - n_lights
        blocks = found & np.where(
            is_light,
            (light_state == RED) | ((light_state == YELLOW) & can_stop),
            state.served != stop_idx,
        )
        d_line = np.where(blocks, d_line, np.inf)
        # stop-sign standstill memory
        at_sign = found & ~is_light & blocks & (d_line < 3.0) & (state.v <= stop_speed)
        timer = np.where(at_sign, state.stop_timer + dt, 0.0)
        need = stops.stop_time[np.clip(stop_idx, 0, max(len(stops.ids) - 1, 0))] if len(stops.ids) else np.zeros(n)
        done = at_sign & (timer >= need)
        served = np.where(done, stop_idx, state.served)
        timer = np.where(done, 0.0, timer)
        use_line = d_line < gap
        gap = np.where(use_line, d_line, gap)
        v_lead = np.where(use_line, 0.0, v_lead)
    else:
        served, timer = state.served, state.stop_timer

    # --- IDM acceleration and integration along lanes ---------------------------------
    v0 = np.where(np.isnan(parts.idm[:, 0]), np.minimum(120 / 3.6, limits.at(lane, state.s)), parts.idm[:, 0])
    acc = np.where((kind == IDM) & on_lane, _idm_accel(state.v, v0, gap, state.v - v_lead, parts.idm), 0.0)
    v_new = state.v + acc * dt
    stopping = v_new < 0  # stops within the step: travel exactly to standstill
    ds = np.where(stopping, -state.v**2 / (2 * np.where(acc < 0, acc, -1.0)), state.v * dt + 0.5 * acc * dt**2)
    v_new = np.maximum(v_new, 0.0)
    moves = state.active & ((kind == IDM) | (kind == CONSTANT_VELOCITY))
    follow = moves & on_lane
    s_new = np.where(follow, state.s + ds, state.s)
    lane_new = state.lane.copy()
    active = state.active.copy()
    over = follow & (s_new > lanes.length[lane])
    if over.any():
        nxt_lane = lanes.successor[lane]
        s_new = np.where(over, s_new - lanes.length[lane], s_new)
        lane_new = np.where(over, nxt_lane, lane_new)
        active = active & ~(over & (nxt_lane < 0))
    keep = follow & active
    p, h = lanes.pose(np.maximum(lane_new, 0), s_new, state.lateral)
    x = np.where(keep, p[:, 0], state.x)
    y = np.where(keep, p[:, 1], state.y)
    psi = np.where(keep, h, state.psi)
    # free constant velocity: straight on
    free = moves & ~on_lane
    x = np.where(free, x + state.v * np.cos(state.psi) * dt, x)
    y = np.where(free, y + state.v * np.sin(state.psi) * dt, y)
    v_out = np.where(follow, v_new, state.v)
    # scripted: interpolate waypoints at t1
    scripted = kind == SCRIPTED
    if scripted.any():
        st, sxy = parts.script_t, parts.script_xy
        k = np.clip((st <= t1).sum(1) - 1, 0, st.shape[1] - 2)
        r = np.arange(n)
        t0w, t1w = st[r, k], st[r, k + 1]
        frac = np.clip((t1 - t0w) / np.maximum(t1w - t0w, 1e-9), 0, 1)
        seg = sxy[r, k + 1] - sxy[r, k]
        pos = sxy[r, k] + frac[:, None] * seg
        vel = np.hypot(seg[:, 0], seg[:, 1]) / np.maximum(t1w - t0w, 1e-9)
        moving = (frac < 1) & (vel > 0)
        x = np.where(scripted, pos[:, 0], x)
        y = np.where(scripted, pos[:, 1], y)
        psi = np.where(scripted & moving, np.arctan2(seg[:, 1], seg[:, 0]), psi)
        v_out = np.where(scripted, np.where(moving, vel, 0.0), v_out)
    return replace(state, t=t1, x=x, y=y, psi=psi, v=v_out, lane=np.where(active, lane_new, -1), s=s_new,
                   active=active, stop_timer=timer, served=served)
