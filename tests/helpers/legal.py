"""Random *legal* behaviour of one participant within the declared assumptions, for the
soundness tests of the occupancy prediction.

Lane-bound users (vehicles, cyclists) pick a path through the lane graph at random (a random
successor at every lane end) and, when they may change lanes, wander between the parallel lanes
of their road (at most 1.5 m/s sideways, the body always inside one lane or straddling two). Their
acceleration is piecewise constant, drawn at random (often an extreme: full braking or full
acceleration), within [−a_max, a_max·min(1, v_switch/v)] (the power limit taken at the speed
at the end of each small step, so the sample never exceeds it), never reversing, never faster
than max(v₀, min(v_max, speed_factor · the limit where they are)). Lines they are bound by at
the start (they obey the kind, the line is ahead and they can stop for it then) are kept: they
keep v²/(2·a_max) within the distance left, cross a light's line only while it is not red and a
stop sign's only after standing before it for its stop time.

Free users (pedestrians, anyone off the lanes) accelerate in random directions with |a| ≤
a_max, never faster than max(v₀, their speed bound), the box turned any way.

Maps with both lane changes and lines are left out (the sampler's lines follow the lane it is
on). Units: m, s, m/s, m/s².
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twolevel.models.obb import box_corners
from twolevel.world.assumptions import PEDESTRIAN, MotionBounds
from twolevel.safety.network import LIGHT, STOP_SIGN, Network
from twolevel.safety.polygons import lane_point
from twolevel.world.traffic import RED, TrafficState

DT = 0.02  # [s] the sampler's step


@dataclass(frozen=True)
class Track:
    """A sampled behaviour: times ``t`` (T,) [s] after the start and the body's ``corners`` (T, 4, 2) [m]."""

    t: np.ndarray
    corners: np.ndarray


def _accel(rng: np.random.Generator, lo: float, hi: float) -> float:
    u = rng.random()
    return lo if u < 0.3 else hi if u < 0.6 else float(rng.uniform(lo, hi))


def sample_free(net: Network, traffic: TrafficState, i: int, b: MotionBounds, rng: np.random.Generator,
                horizon: float, v_cap: float) -> Track:
    """Free motion of participant ``i`` (any heading) for ``horizon`` [s]."""
    w = net.world
    p = np.array([traffic.x[i], traffic.y[i]], dtype=float)
    vel = traffic.v[i] * np.array([math.cos(traffic.psi[i]), math.sin(traffic.psi[i])])
    cap = max(float(traffic.v[i]), v_cap)
    n = int(round(horizon / DT))
    ts, cs = [0.0], [box_corners(p[0], p[1], traffic.psi[i], w.parts.length[i], w.parts.width[i])]
    a = np.zeros(2)
    heading = float(traffic.psi[i])
    for k in range(1, n + 1):
        if k == 1 or rng.random() < DT / 0.4:
            ang = rng.uniform(0, 2 * math.pi)
            a = _accel(rng, 0.0, b.a_max) * np.array([math.cos(ang), math.sin(ang)])
        new = vel + a * DT
        speed = float(np.hypot(*new))
        if speed > cap:  # the speed bound: keep the direction, cut the length
            new = new * cap / speed
        p = p + 0.5 * (vel + new) * DT
        vel = new
        if rng.random() < 0.05:
            heading = rng.uniform(-math.pi, math.pi)
        ts.append(k * DT)
        cs.append(box_corners(p[0], p[1], heading, w.parts.length[i], w.parts.width[i]))
    return Track(np.asarray(ts), np.asarray(cs))


def sample_lane(net: Network, traffic: TrafficState, i: int, t_abs: float, b: MotionBounds, rng: np.random.Generator,
                horizon: float) -> Track:
    """Lane-bound motion of participant ``i`` (on a lane now) for ``horizon`` [s] from absolute
    time ``t_abs`` [s]."""
    w = net.world
    lanes = w.lanes.lanes
    L, W = float(w.parts.length[i]), float(w.parts.width[i])
    lane, s, v = int(traffic.lane[i]), float(traffic.s[i]), float(traffic.v[i])
    lat = float(traffic.lateral[i])
    change = b.lane_changes and (net.group == net.group[lane]).sum() > 1
    # the path ahead (lanes in order, each one's offset along the path)
    path, offs = [lane], [0.0]
    while offs[-1] + lanes[path[-1]].length < s + 400.0 and lanes[path[-1]].successors:
        nxt = lanes[path[-1]].successors
        offs.append(offs[-1] + lanes[path[-1]].length)
        path.append(int(nxt[rng.integers(len(nxt))]))
    # the lines it is bound by, in path coordinates
    lines = []
    if not change:
        front0 = s + L / 2
        for lane_k, off in zip(path, offs):
            for q in np.flatnonzero(net.line_lane == lane_k):
                x = off + float(net.line_s[q])
                d = x - front0
                kind = int(net.line_kind[q])
                obey = b.stop_lines if kind == STOP_SIGN else b.red_lights
                standing = kind == STOP_SIGN and v <= 0.5 and d <= 3.0
                if d >= 0 and obey and v**2 / (2 * b.a_max) <= d and not standing:
                    lines.append([x, kind, int(net.line_index[q]), 0.0])  # last: time stood at it
        lines.sort()
    x = s  # path coordinate of the centre
    k_lane = 0
    n = int(round(horizon / DT))
    wide = max(abs(lat), (w.lanes.width[lane] - W) / 2)  # how far off centre it may be on its lane
    target = lat
    members = np.flatnonzero(net.group == net.group[lane]) if change else np.array([lane])
    ts, cs = [0.0], []
    a = 0.0

    def corners() -> np.ndarray:
        p, h = lane_point(w.lanes, np.array([path[k_lane]]), np.array([x - offs[k_lane]]), np.array([lat]))
        return box_corners(p[0, 0], p[0, 1], h[0], L, W)

    cs.append(corners())
    for k in range(1, n + 1):
        t = k * DT
        s_here = min(max(x - offs[k_lane], 0.0), lanes[path[k_lane]].length)  # past a map's end: its last limit
        limit = float(w.limits.at(np.array([path[k_lane]]), np.array([s_here]))[0])
        cap = max(float(traffic.v[i]), min(b.v_max, b.speed_factor * limit))
        if k == 1 or rng.random() < DT / 0.5:
            hi = b.a_max * min(1.0, b.v_switch / max(v + b.a_max * DT, 1e-9))
            a = _accel(rng, -b.a_max, hi)
        a_k = min(a, b.a_max * min(1.0, b.v_switch / max(v + max(a, 0) * DT, 1e-9)))
        v_new = min(max(v + a_k * DT, 0.0), cap)
        # keep to the nearest line it is bound by: always able to stop before it (a light may
        # turn red), across only when it may (a light not red; a stop sign served)
        for line in lines:
            x_line, kind, idx, stood = line
            front = x + L / 2
            if front > x_line + 1e-9 or (kind == STOP_SIGN and stood >= w.stops.stop_time[idx] - 1e-9):
                continue  # passed, or served
            if v_new**2 / (2 * b.a_max) > x_line - front - 0.5 * (v + v_new) * DT - 1e-6:
                v_new = max(v - b.a_max * DT, 0.0)  # brake fully: keeps it able to stop in time
            red = kind == LIGHT and int(w.lights.state_at(t_abs + t)[idx]) == RED
            if front + 0.5 * (v + v_new) * DT > x_line and (kind == STOP_SIGN or red):
                v_new = -1.0  # at the line (it is slow enough to stop there): it stops on it
            if kind == STOP_SIGN and v_new <= 1e-9 and v <= 1e-9:
                line[3] = stood + DT
            if v_new < 0:
                x, v_new = x_line - L / 2 - 0.5 * (v + 0.0) * DT, 0.0
            break
        x += 0.5 * (v + v_new) * DT
        v = v_new
        # sideways: wander between the group's lanes (not near the lane's end)
        if change:
            near_end = offs[k_lane] + lanes[path[k_lane]].length - x < 60.0
            if near_end:
                dl = net.dlat[members] - net.dlat[path[k_lane]]
                target = float(dl[np.argmin(np.abs(dl - lat))])
            elif rng.random() < DT / 1.5:
                m = int(rng.choice(members))
                room = (w.lanes.width[m] - W) / 2
                target = float(net.dlat[m] - net.dlat[path[k_lane]] + rng.uniform(-room, room))
            lat += float(np.clip(target - lat, -1.5 * DT, 1.5 * DT))
        else:
            lat = float(np.clip(lat, -wide, wide))
        # next lane at the end (from the member lane the body is on)
        while k_lane + 1 < len(path) and x > offs[k_lane + 1]:
            if change:
                dl = net.dlat[members] - net.dlat[path[k_lane]]
                m = int(members[np.argmin(np.abs(dl - lat))])
                succ = lanes[m].successors
                if succ:
                    q = int(succ[rng.integers(len(succ))])
                    path[k_lane + 1:] = [q]
                    offs[k_lane + 1:] = [offs[k_lane] + lanes[path[k_lane]].length]
                    lat -= float(net.dlat[m] - net.dlat[path[k_lane]])
                    members = np.flatnonzero(net.group == net.group[q])
                    while offs[-1] + lanes[path[-1]].length < x + 400.0 and lanes[path[-1]].successors:
                        nxt = lanes[path[-1]].successors
                        offs.append(offs[-1] + lanes[path[-1]].length)
                        path.append(int(nxt[rng.integers(len(nxt))]))
            k_lane += 1
            wide = (w.lanes.width[path[k_lane]] - W) / 2
            if not change:
                lat = float(np.clip(lat, -wide, wide))
        ts.append(t)
        cs.append(corners())
    return Track(np.asarray(ts), np.asarray(cs))


def sample(net: Network, traffic: TrafficState, i: int, t_abs: float, kind: int, b: MotionBounds,
           rng: np.random.Generator, horizon: float) -> Track:
    """Legal behaviour of participant ``i`` of ``kind`` under ``b`` for ``horizon`` [s]."""
    if b.lane_bound and traffic.lane[i] >= 0:
        return sample_lane(net, traffic, i, t_abs, b, rng, horizon)
    limit = float(net.world.limits.value.max())
    cap = b.v_max if kind == PEDESTRIAN else b.speed_cap(limit)
    return sample_free(net, traffic, i, b, rng, horizon, cap)
