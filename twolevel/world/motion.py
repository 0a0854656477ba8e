"""How the ego expects the other participants to move over its look-ahead (both levels).

**Constant velocity relative to the lane.** A participant the traffic moves along a lane (IDM,
constant-velocity and manoeuvring vehicles on a lane: the simulator's lane followers) keeps its
speed and its heading *relative to the lane*: its arc length advances by v·cos(ψ − θ) and its
lateral offset by v·sin(ψ − θ) per second (θ the lane's heading where it is; a lane change under
way keeps moving sideways), onto the lane's successor at its end (the first, the one the traffic
takes; extrapolated straight past the end of a lane without one). In a bend the prediction
follows the bend; on a straight lane it is the straight line. Everybody else (pedestrians,
scripted waypoints, free movers) is predicted in a straight line at constant velocity.

Why not the straight line for everybody: an oncoming car in a bend of radius R, predicted on its
tangent, drifts L²/(2R) towards the outside of the bend after L metres — 1.7 m after 10 m on a
30 m bend, the whole clearance between two 1.8 m cars in neighbouring 3.5 m lanes — so every car
meeting the ego in a left-hand bend looked like a head-on collision one second ahead, and the low
level braked fully for traffic keeping its lane.

Where a participant's lane is straight over the stretch it is predicted on, the straight-line
formula is kept (the same motion, computed exactly as before). Units: m, rad, m/s, s.
"""

from __future__ import annotations

import numpy as np

from twolevel.world.traffic.state import CONSTANT_VELOCITY, IDM, MANOEUVRES, TrafficState
from twolevel.world.world import World

__all__ = ["predicted_poses", "LANE_FOLLOWERS", "STRAIGHT"]

LANE_FOLLOWERS = (CONSTANT_VELOCITY, IDM, MANOEUVRES)
"""The behaviours the traffic moves along their lanes (:mod:`twolevel.world.traffic.step`)."""
STRAIGHT = 1e-9
"""[rad] A lane whose heading turns by no more than this over a predicted stretch is straight there."""
_HOPS = 16  # successors followed at most within one look-ahead


def predicted_poses(world: World, traffic: TrafficState, idx: np.ndarray, tau: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres ``x``, ``y`` (n, T) [m] and headings ``psi`` (n, T) [rad] of the participants
    ``idx`` (n,) at the times ``tau`` (T,) [s] from now (see the module docstring)."""
    idx = np.asarray(idx, dtype=int)
    tau = np.asarray(tau, dtype=float)
    v, psi0 = traffic.v[idx], traffic.psi[idx]
    x = traffic.x[idx, None] + (v * np.cos(psi0))[:, None] * tau[None]
    y = traffic.y[idx, None] + (v * np.sin(psi0))[:, None] * tau[None]
    psi = np.repeat(psi0[:, None], len(tau), axis=1)
    follow = traffic.active[idx] & (traffic.lane[idx] >= 0) & np.isin(world.parts.kind[idx], LANE_FOLLOWERS)
    if not follow.any() or not len(tau):
        return x, y, psi
    j = np.flatnonzero(follow)
    lanes = world.lanes
    lane0, s0 = traffic.lane[idx[j]].astype(int), traffic.s[idx[j]]
    _, h0 = lanes.pose(lane0, s0)
    rel = np.arctan2(np.sin(psi0[j] - h0), np.cos(psi0[j] - h0))  # heading relative to the lane
    s = s0[:, None] + (v[j] * np.cos(rel))[:, None] * tau[None]
    lat = traffic.lateral[idx[j], None] + (v[j] * np.sin(rel))[:, None] * tau[None]
    lane = np.repeat(lane0[:, None], len(tau), axis=1)
    for _ in range(_HOPS):  # onto the successor past a lane's end (the traffic's own choice)
        over = (s > lanes.length[lane]) & (lanes.successor[lane] >= 0)
        if not over.any():
            break
        s = np.where(over, s - lanes.length[lane], s)
        lane = np.where(over, lanes.successor[lane], lane)
    p, h = lanes.pose(lane.ravel(), s.ravel(), lat.ravel())
    h = h.reshape(s.shape)
    turn = np.abs(np.arctan2(np.sin(h - h0[:, None]), np.cos(h - h0[:, None])))
    bends = np.flatnonzero(np.any(turn > STRAIGHT, axis=1))
    if not len(bends):
        return x, y, psi
    rows = j[bends]
    x[rows] = p[:, 0].reshape(s.shape)[bends]
    y[rows] = p[:, 1].reshape(s.shape)[bends]
    psi[rows] = h[bends] + rel[bends, None]
    return x, y, psi
