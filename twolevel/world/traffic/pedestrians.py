"""Pedestrians: walking across the road, at a crosswalk or anywhere, waiting for a gap or not.

A walk (:class:`twolevel.world.schema.Walk`) is a straight path: across the road at a point of a
lane (from just outside the road on one side — where the lanes there end — to just outside the
other), or a given distance on from a free pose. Its pedestrian stands until its trigger (as a
manoeuvre's, :mod:`twolevel.world.traffic.triggers`), then waits at the kerb until no vehicle
(the ego included) stands on its path or would reach the crossing of a lane sooner than ``gap``
[s] after the pedestrian has walked past that lane (``gap`` 0: it steps out without looking),
then walks at its speed to the far side — and leaves the scene there (a walk of a distance stands
at its end instead); once walking it does not stop. Its speed changes within the assumptions about
pedestrians (:mod:`twolevel.world.assumptions`: at most 0.6 m/s², 2 m/s by default), so it takes
a couple of seconds to reach walking pace.

Vehicles (IDM) stop before a crossing while a pedestrian is on the lane or about to step onto it
(:data:`ENTERING` m before its edge), and — at a marked ``crosswalk`` — for a pedestrian waiting
at the kerb or on its way across to their lane, if they can stop at their comfortable
deceleration (when they cannot, they pass first).
"""

from __future__ import annotations

import numpy as np

from twolevel.world.geometry import LaneSet
from twolevel.world.traffic.state import Memory, Walks
from twolevel.world.traffic.triggers import fires

__all__ = ["KERB", "ENTERING", "STOP_SHORT", "crossing_path", "rows_of", "walks_of", "walking_time", "clear_to_walk",
           "walk", "crossing_lines"]

KERB = 0.75
"""[m] How far outside the road a crossing pedestrian waits (and ends)."""
ENTERING = 2.0
"""[m] A vehicle stops for a walking pedestrian this close to its lane's edge (or on it)."""
STOP_SHORT = 1.5
"""[m] How far before the crossing's centre line a vehicle's front stops."""
_SAMPLE = 0.05  # [m] spacing of the points a path is looked up at


def crossing_path(lanes: LaneSet, lane: int, s: float, from_right: bool) -> tuple[np.ndarray, float, float]:
    """The path across the road at (``lane``, ``s`` [m]), perpendicular to the lane: start point
    (2,) [m], heading [rad] and length [m] (from :data:`KERB` outside the last lane on the start
    side to as far outside on the other; lanes the line meets within half a lane of each other
    belong to the road)."""
    p, h = lanes.pose(np.array([lane]), np.array([s]))
    normal = np.array([-np.sin(h[0]), np.cos(h[0])])  # to the lane's left
    u = np.arange(-60.0, 60.0 + 1e-9, _SAMPLE)
    hit, _, _ = lanes.lookup(p[0] + u[:, None] * normal)
    at = u[hit >= 0]
    groups = np.split(at, np.flatnonzero(np.diff(at) > 0.5 * float(lanes.width.max())) + 1)
    road = next((g for g in groups if g[0] <= 0.0 <= g[-1]), np.array([-0.5, 0.5]))
    lo, hi = float(road[0]), float(road[-1])
    a, b = lo - KERB, hi + KERB
    if not from_right:
        normal, a, b = -normal, -b, -a
    return p[0] + a * normal, float(np.arctan2(normal[1], normal[0])), float(b - a)


def rows_of(lanes: LaneSet, owner: int, origin: np.ndarray, heading: float, length: float
            ) -> list[tuple[int, int, float, float, float]]:
    """Where a straight path crosses lanes: (owner, lane, s on the lane [m], distance walked
    where it enters and leaves the lane [m]) per lane met, in walking order."""
    d = np.arange(0.0, length + 1e-9, _SAMPLE)
    pts = origin[None, :] + d[:, None] * np.array([np.cos(heading), np.sin(heading)])[None, :]
    lane, s, _ = lanes.lookup(pts)
    out = []
    for k in np.unique(lane[lane >= 0]):
        at = np.flatnonzero(lane == k)
        out.append((owner, int(k), float(s[at[len(at) // 2]]), float(d[at[0]]), float(d[at[-1]] + _SAMPLE)))
    return sorted(out, key=lambda r: r[3])


def walks_of(n: int, specs: list[tuple[int, np.ndarray, float, float, float, int, float, float, bool, bool]],
             lanes: LaneSet) -> Walks:
    """The walks table: ``specs`` per walker (index, origin (2,), heading [rad], length [m],
    speed [m/s], trigger code, trigger value, gap [s], crosswalk, leaves once across)."""
    w = Walks.empty(n)
    if not specs:
        return w
    origin, heading, length, speed = w.origin.copy(), w.heading.copy(), w.length.copy(), w.speed.copy()
    trigger, when, gap, crosswalk, leaves = w.trigger.copy(), w.when.copy(), w.gap.copy(), w.crosswalk.copy(), w.leaves.copy()
    rows: list[tuple[int, int, float, float, float]] = []
    for i, o, h, ln, sp, tk, tv, g, cw, lv in specs:
        origin[i], heading[i], length[i], speed[i] = o, h, ln, sp
        trigger[i], when[i], gap[i], crosswalk[i], leaves[i] = tk, tv, g, cw, lv
        rows += rows_of(lanes, i, o, h, ln)
    r = np.array(rows, dtype=float).reshape(-1, 5)
    return Walks(origin, heading, length, speed, trigger, when, gap, crosswalk, leaves, r[:, 0].astype(int), r[:, 1].astype(int),
                 r[:, 2], r[:, 3], r[:, 4])


def walking_time(d: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Time [s] to walk ``d`` [m] from standing, speeding up at ``a`` [m/s²] to ``v`` [m/s]."""
    ramp = v**2 / (2 * a)
    return np.where(d <= ramp, np.sqrt(2 * np.maximum(d, 0.0) / a), v / a + (d - ramp) / v)


def clear_to_walk(walks: Walks, who: np.ndarray, a_max: np.ndarray, lane: np.ndarray, s: np.ndarray, hl: np.ndarray,
                  v: np.ndarray, vehicle: np.ndarray) -> np.ndarray:
    """Whether each waiting pedestrian ``who`` (speeding up at ``a_max`` (N,) [m/s²]) may step
    out: no ``vehicle`` body (lane, s, half length [m], speed along its lane [m/s]; the ego
    included) stands on its path or reaches a crossing of it sooner than the pedestrian's ``gap``
    [s] after the pedestrian would have walked past that lane."""
    rows = np.flatnonzero(np.isin(walks.row_owner, who))
    if not len(rows):
        return np.ones(len(who), dtype=bool)
    o = walks.row_owner[rows]
    rl, rs = walks.row_lane[rows], walks.row_s[rows]
    on = vehicle[None, :] & (lane[None, :] == rl[:, None])
    dist = rs[:, None] - s[None, :] - hl[None, :]
    inside = on & (np.abs(rs[:, None] - s[None, :]) < hl[None, :] + 1.0)
    tta = np.where(inside, 0.0, np.where(on & (dist >= 0), dist / np.maximum(v[None, :], 0.1), np.inf))
    need = walks.gap[o] + walking_time(walks.row_leave[rows], walks.speed[o], a_max[o])
    blocked = np.zeros(len(walks.gap), dtype=bool)
    np.logical_or.at(blocked, o, tta.min(axis=1) < need)
    return ~blocked[who] | (walks.gap[who] <= 0)


def walk(walks: Walks, mem: Memory, who: np.ndarray, t: float, dt: float, v: np.ndarray, a_max: np.ndarray,
         ego_dist: np.ndarray, ego_speed: float, clear: np.ndarray
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One step of the walkers ``who``: (position (M, 2) [m], speed [m/s], acceleration [m/s²],
    phase) after ``dt`` [s], from their speed ``v``, acceleration bound ``a_max`` [m/s²], the ego's
    distance [m] and speed [m/s] (triggers) and whether the way is ``clear`` (M,)."""
    phase = mem.phase[who]
    odo = mem.odo[who]
    zero = np.zeros(len(who))
    start = (phase == 0) & fires(walks.trigger[who], walks.when[who], t, zero, zero, ego_dist, ego_speed)
    phase = np.where(start, 1, phase)
    phase = np.where((phase == 1) & clear, 2, phase)
    left = np.maximum(walks.length[who] - odo, 0.0)
    goal = np.where(phase == 2, np.minimum(walks.speed[who], np.sqrt(2 * a_max * left)), 0.0)  # 0: standing or across
    acc = np.clip((goal - v) / dt, -a_max, a_max)
    v_new = np.maximum(v + acc * dt, 0.0)
    odo = np.minimum(odo + 0.5 * (v + v_new) * dt, walks.length[who])
    phase = np.where((phase == 2) & (walks.length[who] - odo < 1e-3), 3, phase)  # then it slows to a stop there
    h = walks.heading[who]
    pos = walks.origin[who] + odo[:, None] * np.stack([np.cos(h), np.sin(h)], axis=1)
    return pos, v_new, acc, np.stack([phase, odo]).T


def crossing_lines(walks: Walks, mem: Memory, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where vehicles must stop for pedestrians now: (lane, s of the stop point [m], courtesy)
    per line; ``courtesy`` lines (a pedestrian waiting at a crosswalk) bind only a vehicle that
    can stop comfortably."""
    if not len(walks.row_owner):
        z = np.zeros(0)
        return z.astype(int), z, z.astype(bool)
    o = walks.row_owner
    phase, odo = mem.phase[o], mem.odo[o]
    near = (phase == 2) & (odo >= walks.row_enter - ENTERING) & (odo <= walks.row_leave + 0.5)
    yielded = walks.crosswalk[o] & ((phase == 1) | ((phase == 2) & (odo <= walks.row_leave + 0.5)))
    on = active[o] & (near | yielded)
    return walks.row_lane[on], walks.row_s[on] - STOP_SHORT, yielded[on] & ~near[on]
