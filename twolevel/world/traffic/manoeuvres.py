"""Manoeuvre primitives: scripted participants that drive along their lane by a chain of actions.

A chain (``manoeuvres:`` in a scenario, :class:`twolevel.world.schema.Manoeuvre`) is run in
order, one action started per step at most: an action is armed once the one before it has
started, and starts when its trigger holds (:mod:`twolevel.world.traffic.triggers`; default:
right after the previous one ended). Actions:

* ``lane_change: left | right | <lane id>`` over ``duration`` [s] (default 4): the lateral
  motion of :mod:`twolevel.world.traffic.lanechange`; a side without a lane there is skipped;
* ``brake_to: v`` / ``accelerate_to: v`` / ``follow_lane: v`` [m/s]: the speed moves to v at
  ``decel`` (default 3 m/s²) going down and ``accel`` (default 1.5 m/s²) going up, and stays;
  ``follow_lane`` lasts at least ``hold`` [s];
* ``speed_profile: [[x, v], …]``: v over time (``along: time``) or distance (``along:
  distance``) since it started, linear between the points, held after the last;
* ``stop``: brake to a standstill at ``decel`` and stand (at least ``hold`` [s]).

A speed action and a lane change run side by side (a cut-in that brakes while it changes lanes:
start the braking with ``after_start`` or an ego trigger). Before its first speed action the
participant keeps its initial speed. It ignores other traffic — it does what it is told, as an
OpenSCENARIO action does — but stays within the assumptions about its kind (the envelope of
:mod:`twolevel.world.traffic.idm`): a deceleration asked beyond them is limited (``check`` warns).
An action ends when its speed is reached (or cannot rise further), its profile or duration has
run out, and its ``hold`` has passed.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from twolevel.world.traffic.state import Memory, Plans
from twolevel.world.traffic.triggers import AFTER, TRIGGERS, fires

__all__ = ["ACTIONS", "LANE_CHANGE", "BRAKE_TO", "ACCELERATE_TO", "SPEED_PROFILE", "FOLLOW_LANE", "STOP",
           "DEFAULT_DECEL", "DEFAULT_ACCEL", "DEFAULT_DURATION", "plans_of", "drive"]

LANE_CHANGE, BRAKE_TO, ACCELERATE_TO, SPEED_PROFILE, FOLLOW_LANE, STOP = 1, 2, 3, 4, 5, 6
ACTIONS = {"lane_change": LANE_CHANGE, "brake_to": BRAKE_TO, "accelerate_to": ACCELERATE_TO,
           "speed_profile": SPEED_PROFILE, "follow_lane": FOLLOW_LANE, "stop": STOP}
DEFAULT_DECEL = 3.0  # [m/s²] firm, well within any vehicle's assumed 8 m/s²
DEFAULT_ACCEL = 1.5  # [m/s²]
DEFAULT_DURATION = 4.0  # [s] a lane change (twolevel.world.traffic.lanechange)


def plans_of(chains: Sequence[Sequence[Any] | None], lane_index: dict[str, int]) -> Plans:
    """The table of every participant's chain (schema :class:`~twolevel.world.schema.Manoeuvre`
    items; None or empty: none), lanes named by id looked up in ``lane_index``."""
    n = len(chains)
    P = max([len(c or ()) for c in chains] + [1])
    K = max([len(m.speed_profile or ()) for c in chains for m in c or ()] + [2])
    plans = Plans.empty(n)
    count = np.array([len(c or ()) for c in chains], dtype=int)
    if not count.any():
        return plans
    i_ = lambda: np.zeros((n, P), dtype=int)  # noqa: E731
    f_ = lambda: np.zeros((n, P))  # noqa: E731
    action, trigger, side, lane = i_(), i_(), i_(), i_() - 1
    when, speed, accel, decel, duration, hold = f_(), f_(), f_(), f_(), f_(), f_()
    px, pv, along, end = np.zeros((n, P, K)), np.zeros((n, P, K)), np.zeros((n, P), dtype=bool), f_()
    for i, chain in enumerate(chains):
        for k, m in enumerate(chain or ()):
            name = m.action
            action[i, k] = ACTIONS[name]
            trig = next((key for key in TRIGGERS if getattr(m, key, None) is not None), None)
            trigger[i, k] = AFTER if trig is None else TRIGGERS[trig]
            when[i, k] = 0.0 if trig is None else float(getattr(m, trig))
            accel[i, k] = m.accel if m.accel is not None else DEFAULT_ACCEL
            decel[i, k] = m.decel if m.decel is not None else DEFAULT_DECEL
            duration[i, k] = m.duration if m.duration is not None else DEFAULT_DURATION
            hold[i, k] = m.hold or 0.0
            if name == "lane_change":
                side[i, k] = {"left": 1, "right": -1}.get(m.lane_change, 0)
                lane[i, k] = lane_index.get(m.lane_change, -1)
            elif name == "speed_profile":
                pts = np.asarray(m.speed_profile, dtype=float)
                px[i, k, : len(pts)], pv[i, k, : len(pts)] = pts[:, 0], pts[:, 1]
                px[i, k, len(pts):] = pts[-1, 0] + np.arange(1, K - len(pts) + 1)
                pv[i, k, len(pts):] = pts[-1, 1]
                along[i, k] = m.along == "distance"
                end[i, k] = pts[-1, 0]
                speed[i, k] = pts[-1, 1]
            elif name != "stop":
                speed[i, k] = float(getattr(m, name))
    return Plans(count, action, trigger, when, speed, accel, decel, duration, hold, side, lane, px, pv, along, end)


def _profile(plans: Plans, who: np.ndarray, k: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Speed [m/s] of the profiles (who, k) at ``x`` [s or m since they started]."""
    px, pv = plans.profile_x[who, k], plans.profile_v[who, k]  # (M, K)
    j = np.clip((px <= x[:, None]).sum(1) - 1, 0, px.shape[1] - 2)
    r = np.arange(len(who))
    x0, x1 = px[r, j], px[r, j + 1]
    u = np.clip((x - x0) / (x1 - x0), 0.0, 1.0)
    return np.where(x < px[:, 0], pv[:, 0], pv[r, j] + u * (pv[r, j + 1] - pv[r, j]))


def drive(plans: Plans, mem: Memory, who: np.ndarray, t: float, dt: float, v: np.ndarray, cap: np.ndarray,
          ego_dist: np.ndarray, ego_speed: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, Memory]:
    """One step of the chains of participants ``who`` at time ``t`` [s]: their speed ``v`` and
    speed bound ``cap`` [m/s], the ego's distance to them [m] and its speed [m/s]. Returns the
    acceleration [m/s²] of each of ``who`` (before the envelope), the lane changes to begin
    (indices into ``who``, and per change the side (+1 left, −1 right, 0: the lane) and lane
    index and duration stacked as (3, C)) and the memory."""
    nxt, started, ended = mem.next[who], mem.started[who], mem.ended[who]
    lon, lon_t0, lon_odo0, odo = mem.lon[who], mem.lon_t0[who], mem.lon_odo0[who], mem.odo[who]
    last = np.maximum(nxt - 1, 0)
    act = plans.action[who, last]
    target = np.minimum(np.where(act == STOP, 0.0, plans.speed[who, last]), cap)
    elapsed = t - started
    reach = np.abs(v - target) < 1e-6
    run_out = np.where(plans.along_distance[who, last], odo - lon_odo0, t - lon_t0) >= plans.profile_end[who, last]
    done = np.select([act == LANE_CHANGE, act == SPEED_PROFILE], [mem.lc_from[who] < 0, run_out],
                     reach & (elapsed >= plans.hold[who, last] - 1e-9))
    ended = np.where((nxt > 0) & ~np.isfinite(ended) & done, t, ended)
    # the next action of each chain, if its trigger holds
    k = np.minimum(nxt, plans.action.shape[1] - 1)
    go = (nxt < plans.count[who]) & fires(plans.trigger[who, k], plans.when[who, k], t, started, ended, ego_dist, ego_speed)
    a_k = plans.action[who, k]
    is_lon = go & (a_k != LANE_CHANGE)
    lon = np.where(is_lon, k, lon)
    lon_t0 = np.where(is_lon, t, lon_t0)
    lon_odo0 = np.where(is_lon, odo, lon_odo0)
    started = np.where(go, t, started)
    ended = np.where(go, np.inf, ended)
    nxt = np.where(go, nxt + 1, nxt)
    change = np.flatnonzero(go & (a_k == LANE_CHANGE))
    requests = np.stack([plans.side[who[change], k[change]].astype(float), plans.lane[who[change], k[change]].astype(float),
                         plans.duration[who[change], k[change]]])
    # the acceleration the active speed action asks for
    li = np.maximum(lon, 0)
    la = plans.action[who, li]
    goal = np.minimum(np.where(la == STOP, 0.0, plans.speed[who, li]), cap)
    prof = la == SPEED_PROFILE
    if prof.any():
        x_next = np.where(plans.along_distance[who, li], odo + v * dt - lon_odo0, t + dt - lon_t0)
        goal = np.where(prof, np.minimum(_profile(plans, who, li, x_next), cap), goal)
    up = np.where(prof, np.inf, plans.accel[who, li])
    down = np.where(prof, np.inf, plans.decel[who, li])
    acc = np.where(lon >= 0, np.clip((goal - v) / dt, -down, up), 0.0)
    mem = mem.but(next=_put(mem.next, who, nxt), started=_put(mem.started, who, started),
                  ended=_put(mem.ended, who, ended), lon=_put(mem.lon, who, lon), lon_t0=_put(mem.lon_t0, who, lon_t0),
                  lon_odo0=_put(mem.lon_odo0, who, lon_odo0))
    return acc, change, requests, mem


def _put(full: np.ndarray, who: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = full.copy()
    out[who] = values
    return out

