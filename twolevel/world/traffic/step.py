"""One step of all traffic: every participant advanced by its behaviour, vectorised over them.

The order within a step (HighwayEnv's act-then-step: every decision reads the state at its
start, then everybody moves):

1. **the lanes** — the lane table of every body on a lane (participants, the lane a participant
   changing lanes leaves, the ego; :mod:`~twolevel.world.traffic.neighbours`) and the body ahead
   of each IDM driver;
2. **lines** — the next traffic light or stop sign on its lane (red, or yellow it can stop for;
   a stop sign until it has stood ``stop_time`` there and the gap in priority traffic is
   acceptable, :mod:`~twolevel.world.traffic.junctions`) and pedestrians' crossings
   (:mod:`~twolevel.world.traffic.pedestrians`) become standing leaders;
3. **IDM** — accelerations (:mod:`~twolevel.world.traffic.idm`); followers of a lane the ego
   signals it moves into slow down to let it in when that needs no more braking than politeness
   · b_safe (:mod:`~twolevel.world.traffic.ego`); MOBIL drivers decide lane changes
   (:mod:`~twolevel.world.traffic.mobil`);
4. **scripts** — manoeuvre chains (:mod:`~twolevel.world.traffic.manoeuvres`) and walks;
5. **motion** — every acceleration within the envelope of its kind, lane followers integrated
   along their lanes (onto a successor at a lane's end, or off the map), lane changes moved on
   sideways (:mod:`~twolevel.world.traffic.lanechange`), free constant-velocity participants
   straight on, waypoints interpolated.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from twolevel.world.geometry import LaneSet
from twolevel.world.traffic import junctions, lanechange, manoeuvres, mobil, pedestrians
from twolevel.world.traffic.ego import EgoView, view
from twolevel.world.traffic.idm import envelope, idm_accel, speed_bound
from twolevel.world.traffic.neighbours import Found, LaneTable, transfer
from twolevel.world.traffic.state import (
    BIG, CONSTANT_VELOCITY, IDM, MANOEUVRES, RED, SCRIPTED, WALK, YELLOW, EgoBox, Lights, Memory, Participants,
    SpeedLimits, StopLines, TrafficState,
)

__all__ = ["step", "EGO_IDM"]

EGO_IDM = np.array([np.nan, 1.6, 2.0, 0.73, 1.67, 4.0])
"""IDM parameters others assume of the ego (the schema's defaults; v0: the limit) [m/s, s, m, m/s², m/s², -]."""
_SIGN_ZONE = 3.0  # [m] a vehicle this close to a stop line stands "at" it
_MOVING_OFF = 20.0  # [m] a vehicle within this distance past the line it served is still moving off


def step(
    state: TrafficState, dt: float, *, lanes: LaneSet, parts: Participants, limits: SpeedLimits,
    lights: Lights, stops: StopLines, ego: EgoBox | None = None, stop_speed: float = 0.1,
) -> TrafficState:
    """Advance every participant by ``dt`` [s]; vectorised over participants. ``ego``: the ego
    as others see it (a leader, a merging car, priority traffic, a trigger); ``stop_speed``
    [m/s]: counted as standing still at a stop line."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return _step(state, dt, lanes, parts, limits, lights, stops, ego, stop_speed)


def _entries(state: TrafficState, mem: Memory, lanes: LaneSet, parts: Participants, on_lane: np.ndarray,
             eg: EgoView | None) -> tuple[LaneTable, np.ndarray, np.ndarray, np.ndarray]:
    """The lane table, and for participants changing lanes: who, and their (s, lateral) on the
    lane they leave."""
    n = len(state.x)
    idx = np.flatnonzero(on_lane)
    lane, s, lat = [state.lane[idx]], [state.s[idx]], [state.lateral[idx]]
    hl, hw, v, owner = [parts.length[idx] / 2], [parts.width[idx] / 2], [state.v[idx]], [idx]
    ch = np.flatnonzero(on_lane & (mem.lc_from >= 0))
    s_from, lat_from, _ = transfer(lanes, state.lane[ch], state.s[ch], state.lateral[ch], mem.lc_from[ch])
    inside = np.abs(lat_from) < lanes.width[mem.lc_from[ch]] / 2 + parts.width[ch] / 2
    keep = ch[inside]
    lane.append(mem.lc_from[keep]), s.append(s_from[inside]), lat.append(lat_from[inside])
    hl.append(parts.length[keep] / 2), hw.append(parts.width[keep] / 2), v.append(state.v[keep]), owner.append(keep)
    if eg is not None and eg.lane >= 0:
        bl, bs, blat, bv = eg.body
        lane.append(bl), s.append(bs), lat.append(blat), v.append(bv)
        hl.append(np.full(len(bl), eg.hl)), hw.append(np.full(len(bl), eg.hw)), owner.append(np.full(len(bl), n))
    cat = np.concatenate
    table = LaneTable.of(cat(lane).astype(int), cat(s), cat(hl), cat(lat), cat(hw), cat(v), cat(owner).astype(int))
    return table, ch, s_from, lat_from


def _step(state: TrafficState, dt: float, lanes: LaneSet, parts: Participants, limits: SpeedLimits,
          lights: Lights, stops: StopLines, ego: EgoBox | None, stop_speed: float) -> TrafficState:
    n = len(state.x)
    kind = parts.kind
    mem = state.remembered
    on_lane = state.active & (state.lane >= 0)
    lane = np.maximum(state.lane, 0)
    t1 = state.t + dt
    eg = view(lanes, ego) if ego is not None else None
    hl, hw = parts.length / 2, parts.width / 2

    # --- 1. the lanes: the body ahead of each IDM driver ----------------------------------------
    table, ch, s_from, lat_from = _entries(state, mem, lanes, parts, on_lane, eg)
    drivers = np.flatnonzero(on_lane & (kind == IDM))
    found = table.ahead(lanes, state.lane[drivers], state.s[drivers], hl[drivers], state.lateral[drivers],
                        hw[drivers], drivers, state.v[drivers])
    gap = np.full(n, np.inf)
    v_lead = state.v.copy()
    gap[drivers], v_lead[drivers] = found.gap, found.v
    follow_gap, follow_v = gap.copy(), v_lead.copy()  # car following alone (MOBIL compares these)

    # --- 2. lines: lights, stop signs (with give way), pedestrians' crossings -------------------
    served, timer, held = state.served, state.stop_timer, np.full(n, np.inf)
    b = parts.idm[:, 4]
    line_lane = np.concatenate([lights.lane, stops.lane])
    line_key = np.concatenate([lights.lane * BIG + lights.s, stops.lane * BIG + stops.s])
    if len(line_key):
        lorder = np.argsort(line_key)
        lk = line_key[lorder]
        front = np.where(on_lane, state.lane * BIG + state.s + parts.length / 2 - 0.5, np.inf)
        j = np.minimum(np.searchsorted(lk, front, side="left"), len(lk) - 1)
        li = lorder[j]
        found_line = on_lane & (line_lane[li] == state.lane) & (lk[j] >= front)
        d_line = np.where(found_line, lk[j] - (state.lane * BIG + state.s + parts.length / 2), np.inf)
        n_lights = len(lights.ids)
        is_light = li < n_lights
        light_state = lights.state_at(state.t)[np.minimum(li, max(n_lights - 1, 0))] if n_lights else np.zeros(n, int)
        can_stop = d_line >= state.v**2 / (2 * b)
        stop_idx = li - n_lights
        blocks = found_line & np.where(
            is_light,
            (light_state == RED) | ((light_state == YELLOW) & can_stop),
            state.served != stop_idx,
        )
        d_line = np.where(blocks, d_line, np.inf)
        held = np.where(blocks, state.s + d_line + parts.length / 2, np.inf)
        served, timer = _give_way(state, parts, stops, eg, dt, stop_speed, found_line & ~is_light & blocks,
                                  np.minimum(np.maximum(stop_idx, 0), max(len(stops.ids) - 1, 0)), d_line, held, on_lane)
        use_line = d_line < gap
        gap = np.where(use_line, d_line, gap)
        v_lead = np.where(use_line, 0.0, v_lead)
    gap, v_lead = _crossings(state, mem, parts, on_lane, gap, v_lead)

    # --- 3. IDM, letting a merging ego in, MOBIL ------------------------------------------------
    limit = limits.at(lane, state.s)
    v0 = np.where(np.isnan(parts.idm[:, 0]), np.minimum(120 / 3.6, limit), parts.idm[:, 0])
    acc = np.where((kind == IDM) & on_lane, idm_accel(state.v, v0, gap, state.v - v_lead, parts.idm), 0.0)
    if len(ch):  # a driver changing lanes also keeps its distance on the lane it leaves
        acc = _keep_behind_old(table, lanes, state, parts, mem, ch, s_from, lat_from, v0, acc)
    if eg is not None and len(eg.merging[0]):
        acc = _let_in(eg, state, parts, on_lane, v0, acc)
    new_lane, new_s, new_lat = state.lane, state.s, state.lateral
    cand = np.flatnonzero(on_lane & (kind == IDM) & parts.changes & (mem.lc_from < 0)
                          & (state.t - mem.lc_done >= lanechange.SETTLE)
                          & ((lanes.left[lane] >= 0) | (lanes.right[lane] >= 0)))
    if len(cand):
        new_lane, new_s, new_lat, mem = _mobil(table, lanes, state, parts, mem, eg, v0, cand, follow_gap, follow_v)

    # --- 4. scripts: manoeuvre chains and walks -------------------------------------------------
    bound = speed_bound(state.v, limit, parts.bounds)
    ego_dist = np.full(n, np.inf) if ego is None else np.hypot(state.x - ego.x, state.y - ego.y)
    ego_speed = 0.0 if ego is None else abs(ego.v)
    scripted = np.flatnonzero(state.active & (kind == MANOEUVRES))
    if len(scripted):
        a_s, change, req, mem = manoeuvres.drive(parts.plans, mem, scripted, state.t, dt, state.v[scripted],
                                                 bound[scripted], ego_dist[scripted], ego_speed)
        acc[scripted] = a_s
        who = scripted[change]
        side, to = req[0].astype(int), req[1].astype(int)
        target = np.select([side > 0, side < 0], [lanes.left[lane[who]], lanes.right[lane[who]]], to)
        ok = (target >= 0) & (target != state.lane[who]) & on_lane[who] & (
            (target == lanes.left[lane[who]]) | (target == lanes.right[lane[who]]))
        who, target, dur = who[ok], target[ok], req[2][ok]
        home = lanechange.home_lateral(lanes, target, parts.width[who], parts.keep_right[who], np.zeros(len(who)))
        new_lane, new_s, new_lat, mem = lanechange.begin(lanes, mem, who, new_lane, new_s, new_lat, target, home, dur)

    # --- 5. motion ------------------------------------------------------------------------------
    bounded = (kind == IDM) | (kind == MANOEUVRES)
    acc = np.where(bounded, envelope(acc, state.v, parts.bounds), acc)
    v_new = state.v + acc * dt
    stopping = v_new < 0  # stops within the step: travel exactly to standstill
    ds = np.where(stopping, -state.v**2 / (2 * np.where(acc < 0, acc, -1.0)), state.v * dt + 0.5 * acc * dt**2)
    v_new = np.maximum(v_new, 0.0)
    capped = bounded & (v_new > bound)
    if capped.any():
        v_new = np.where(capped, bound, v_new)
        ds = np.where(capped, 0.5 * (state.v + v_new) * dt, ds)
    moves = state.active & ((kind == IDM) | (kind == CONSTANT_VELOCITY) | (kind == MANOEUVRES))
    follow = moves & on_lane
    lane_now = np.maximum(new_lane, 0)
    s_new = np.where(follow, new_s + ds, new_s)
    lane_new = new_lane.copy()
    active = state.active.copy()
    lc_from = mem.lc_from
    over = follow & (s_new > lanes.length[lane_now])
    if over.any():
        nxt_lane = lanes.successor[lane_now]
        s_new = np.where(over, s_new - lanes.length[lane_now], s_new)
        lane_new = np.where(over, nxt_lane, lane_new)
        active = active & ~(over & (nxt_lane < 0))
        old_next = lanes.successor[np.maximum(lc_from, 0)]
        lc_from = np.where(over & (lc_from >= 0), np.where(old_next >= 0, old_next, np.maximum(nxt_lane, 0)), lc_from)
    lateral, v_lat, mem = lanechange.advance(mem.but(lc_from=lc_from), new_lat, dt, t1)
    keep = follow & active
    p, h = lanes.pose(np.maximum(lane_new, 0), s_new, lateral)
    x = np.where(keep, p[:, 0], state.x)
    y = np.where(keep, p[:, 1], state.y)
    psi = np.where(keep, h + np.arctan2(v_lat, np.maximum(v_new, 1.0)), state.psi) if v_lat.any() else \
        np.where(keep, h, state.psi)
    # free constant velocity: straight on
    free = moves & ~on_lane
    x = np.where(free, x + state.v * np.cos(state.psi) * dt, x)
    y = np.where(free, y + state.v * np.sin(state.psi) * dt, y)
    v_out = np.where(follow, v_new, state.v)
    odo = mem.odo + np.where(follow, ds, 0.0)
    phase = mem.phase
    walkers = np.flatnonzero(state.active & (kind == WALK))
    if len(walkers):
        x, y, psi, v_out, acc, odo, phase = _walk(state, mem, parts, eg, walkers, dt, ego_dist, ego_speed, x, y, psi,
                                                  v_out, acc, odo, phase)
        active = active & ~((kind == WALK) & (phase == 3) & parts.walks.leaves)
    scripted_wp = kind == SCRIPTED
    if scripted_wp.any():
        x, y, psi, v_out = _waypoints(parts, t1, scripted_wp, x, y, psi, v_out)
    return replace(state, t=t1, x=x, y=y, psi=psi, v=v_out, lane=np.where(active, lane_new, -1), s=s_new,
                   lateral=lateral, active=active, stop_timer=timer, served=served,
                   memory=mem.but(odo=odo, phase=phase, accel=np.where(follow | (kind == WALK), acc, 0.0)))


def _give_way(state: TrafficState, parts: Participants, stops: StopLines, eg: EgoView | None, dt: float,
              stop_speed: float, at_stop: np.ndarray, sign: np.ndarray, d_line: np.ndarray, held: np.ndarray,
              on_lane: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stop signs served: a vehicle stands at one for its ``stop_time`` (yield lines: comes within
    braking distance) and then, where the line has conflicts, waits for an acceptable gap.
    Returns (served, stop timer)."""
    n = len(state.x)
    if not len(stops.ids):
        return state.served, np.zeros(n)
    must = stops.stopping[sign]
    standing = at_stop & must & (d_line < _SIGN_ZONE) & (state.v <= stop_speed)
    timer = np.where(standing, state.stop_timer + dt, 0.0)
    ready = np.where(must, standing & (timer >= stops.stop_time[sign]),
                     at_stop & (d_line < state.v**2 / (2 * parts.idm[:, 4]) + 5.0))
    go = ready.copy()
    conf = stops.conflicts
    decide = np.flatnonzero(ready & np.isin(sign, conf.line))
    if len(decide):
        lane, s, hl, v, body = _bodies(state, parts, eg)
        held_all, waiting = held, ready & must
        sv = np.maximum(state.served, 0)  # moving off from a line served just now: accelerating
        off = (state.served >= 0) & (stops.lane[sv] == state.lane) & (state.s - stops.s[sv] < _MOVING_OFF)
        accel = np.where(off & (parts.kind == IDM), parts.idm[:, 3], 0.0)
        if eg is not None:
            held_all, waiting, accel = np.append(held, np.inf), np.append(waiting, False), np.append(accel, 0.0)
        go[decide] = junctions.clear_to_go(conf, sign[decide], decide, parts.critical_gap[decide], lane, s, hl, v,
                                           accel, held_all, waiting, body)
    served = np.where(go, sign, state.served)
    return served, np.where(go, 0.0, timer)


def _bodies(state: TrafficState, parts: Participants, eg: EgoView | None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every body on a lane that others give way to, participants then the ego: lane, s [m],
    half length [m], speed along the lane [m/s] (≥ 0) and whether it is one (on a lane, not a
    pedestrian)."""
    body = state.active & (state.lane >= 0) & (parts.kind != WALK)
    lane, s, hl, v = state.lane, state.s, parts.length / 2, state.v
    if eg is None:
        return lane, s, hl, v, body
    return (np.append(lane, eg.lane), np.append(s, eg.s), np.append(hl, eg.hl), np.append(v, max(eg.v, 0.0)),
            np.append(body, eg.lane >= 0))


def _crossings(state: TrafficState, mem: Memory, parts: Participants, on_lane: np.ndarray, gap: np.ndarray,
               v_lead: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pedestrians' crossings ahead on each vehicle's lane as standing leaders (a crosswalk's
    waiting pedestrian only for a vehicle that can stop comfortably)."""
    c_lane, c_s, courtesy = pedestrians.crossing_lines(parts.walks, mem, state.active)
    if not len(c_lane):
        return gap, v_lead
    key = c_lane * BIG + c_s
    order = np.argsort(key)
    ck = key[order]
    front = state.lane * BIG + state.s + parts.length / 2
    j = np.minimum(np.searchsorted(ck, front - 0.5, side="left"), len(ck) - 1)
    line = order[j]
    d = np.where(on_lane & (c_lane[line] == state.lane) & (ck[j] >= front - 0.5), ck[j] - front, np.inf)
    comfortable = d >= state.v**2 / (2 * parts.idm[:, 4])
    d = np.where(courtesy[line] & ~comfortable, np.inf, d)
    use = d < gap
    return np.where(use, d, gap), np.where(use, 0.0, v_lead)


def _keep_behind_old(table: LaneTable, lanes: LaneSet, state: TrafficState, parts: Participants, mem: Memory,
                     ch: np.ndarray, s_from: np.ndarray, lat_from: np.ndarray, v0: np.ndarray, acc: np.ndarray
                     ) -> np.ndarray:
    """IDM drivers changing lanes also follow the body ahead on the lane they leave while their
    body is still in it."""
    drv = (parts.kind[ch] == IDM) & (np.abs(lat_from) < lanes.width[mem.lc_from[ch]] / 2 + parts.width[ch] / 2)
    c = ch[drv]
    if not len(c):
        return acc
    f = table.ahead(lanes, mem.lc_from[c], s_from[drv], parts.length[c] / 2, lat_from[drv], parts.width[c] / 2, c,
                    state.v[c])
    a = idm_accel(state.v[c], v0[c], f.gap, state.v[c] - f.v, parts.idm[c])
    out = acc.copy()
    out[c] = np.minimum(acc[c], a)
    return out


def _let_in(eg: EgoView, state: TrafficState, parts: Participants, on_lane: np.ndarray, v0: np.ndarray,
            acc: np.ndarray) -> np.ndarray:
    """IDM drivers behind the ego on a lane it signals it moves into brake for it, as for a
    leader, when that needs no more than politeness · b_safe."""
    out = acc
    for to, s_to, v_to in zip(*eg.merging):
        behind = on_lane & (parts.kind == IDM) & (state.lane == to) & (state.s < s_to)
        gap = s_to - state.s - eg.hl - parts.length / 2
        a = idm_accel(state.v, v0, gap, state.v - v_to, parts.idm)
        polite = a >= -parts.mobil[:, 0] * parts.mobil[:, 2]
        out = np.where(behind & polite & (gap > 0), np.minimum(out, a), out)
    return out


def _mobil(table: LaneTable, lanes: LaneSet, state: TrafficState, parts: Participants, mem: Memory,
           eg: EgoView | None, v0: np.ndarray, cand: np.ndarray, follow_gap: np.ndarray, follow_v: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Memory]:
    """MOBIL's decisions for the drivers ``cand`` and the lane changes they begin."""
    n = len(state.x)
    ego_v = 0.0 if eg is None else float(eg.v)
    ego_v0 = 120 / 3.6
    p = np.vstack([parts.idm, EGO_IDM[None, :]])
    drivers = mobil.Drivers(np.append(state.v, ego_v), np.append(v0, ego_v0), p,
                            np.append(parts.length / 2, 0.0 if eg is None else eg.hl), n)
    c = cand
    a_c = idm_accel(state.v[c], v0[c], follow_gap[c], state.v[c] - follow_v[c], parts.idm[c])
    now = Found(np.zeros(len(c), dtype=int), follow_gap[c], follow_v[c])
    home = lanechange.home_lateral(lanes, state.lane[c], parts.width[c], parts.keep_right[c], state.lateral[c])
    pick, target = mobil.decide(table, lanes, drivers, c, state.lane[c], state.s[c], state.lateral[c], home,
                                parts.width[c] / 2, now, a_c, parts.mobil[c], parts.response)
    who = c[pick]
    home_t = lanechange.home_lateral(lanes, target, parts.width[who], parts.keep_right[who], np.zeros(len(who)))
    return lanechange.begin(lanes, mem, who, state.lane, state.s, state.lateral, target, home_t, parts.mobil[who, 4])


def _walk(state: TrafficState, mem: Memory, parts: Participants, eg: EgoView | None, walkers: np.ndarray, dt: float,
          ego_dist: np.ndarray, ego_speed: float, x: np.ndarray, y: np.ndarray, psi: np.ndarray, v: np.ndarray,
          acc: np.ndarray, odo: np.ndarray, phase: np.ndarray) -> tuple[np.ndarray, ...]:
    """One step of the pedestrians ``walkers`` (the vehicles read at the step's start)."""
    waiting = walkers[mem.phase[walkers] <= 1]  # waiting, or setting off this step
    clear = np.ones(len(walkers), dtype=bool)
    if len(waiting):
        ok = pedestrians.clear_to_walk(parts.walks, waiting, parts.bounds[:, 2], *_bodies(state, parts, eg))
        clear[np.searchsorted(walkers, waiting)] = ok
    pos, v_w, a_w, ph = pedestrians.walk(parts.walks, mem, walkers, state.t, dt, state.v[walkers],
                                         parts.bounds[walkers, 2], ego_dist[walkers], ego_speed, clear)
    x, y, psi, v, acc, odo, phase = x.copy(), y.copy(), psi.copy(), v.copy(), acc.copy(), odo.copy(), phase.copy()
    x[walkers], y[walkers], v[walkers], acc[walkers] = pos[:, 0], pos[:, 1], v_w, a_w
    psi[walkers] = parts.walks.heading[walkers]
    phase[walkers], odo[walkers] = ph[:, 0].astype(int), ph[:, 1]
    return x, y, psi, v, acc, odo, phase


def _waypoints(parts: Participants, t1: float, scripted: np.ndarray, x: np.ndarray, y: np.ndarray, psi: np.ndarray,
               v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Waypoint participants interpolated at ``t1`` [s] (linear in time, positions as given)."""
    n = len(x)
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
    v = np.where(scripted, np.where(moving, vel, 0.0), v)
    return x, y, psi, v
