"""Passing over the oncoming lane: where the MPC's lateral band may take in the oncoming lane, and
whether the oncoming lane is free for as long as a pass needs.

The pass itself is the RSS terminal's *passing on the left* disjunct
(:func:`twolevel.control.high_level.guards.rss_terminal`): a binary of the MILP, beside the
vehicle ahead from :data:`~twolevel.control.high_level.guards.BESIDE_FROM` on, carried from plan to
plan (:class:`~twolevel.control.high_level.guards.Pass`) until the ego is past it, then the
reference returns to the route's lane. This module makes that disjunct available over the
oncoming lane:

* :func:`oncoming_band` — the lateral offsets [m] the ego's reference point may take when the
  oncoming lane is open to it: the drivable area's outer bounds
  (:func:`twolevel.world.area.drivable_area`: the first lane running against the route, where
  the boundary is crossable from the route's lane — none, dashed, dashed_solid — and outside the
  no-overtaking zones), less half the ego's width and, beyond the oncoming lane, less
  :data:`EDGE_MARGIN` (the body keeps off the road's edge while it passes).
* :func:`pass_time` — how long the ego occupies the oncoming lane to pass the vehicle ahead and
  return in front of it: from its speed now, accelerating at the comfort acceleration up to the
  desired speed, until its rear is the vehicle's RSS distance (as a follower of the ego, the
  others' response) plus D_safe ahead of its front, plus the time of the lane change back.
* :func:`waiting_room`, :func:`room_to_pull_out` — where the ego **waits** behind the vehicle
  while the oncoming lane is not free (room to pull out from, judged from the waiting spot at the
  vehicle's pace), and whether a new pass may begin from where it is (the lane change out fits
  before the vehicle's rear).
* :func:`oncoming_free` — the **gap acceptance**: every vehicle sensed in the oncoming lane ahead
  must be farther than the ego travels in that time, plus what it travels (its speed, against the
  route) in that time, plus RSS's safe distance between cars driving towards each other
  (:func:`twolevel.world.assumptions.opposite_safe_distance`: the ego's response as the one out of
  its lane, the assumed response of the other); a vehicle standing in the oncoming lane within
  the stretch blocks it; and, since a vehicle beyond the sensing range is unknown, one just
  beyond it at the assumptions' speed bound must satisfy the same (so a pass needs a sensing
  range that covers it). The ego's speed during the pass is the desired speed.

The safety layer holds the claim while the ego is out of its lane: its fail-safes from there
steer back into the route's lane, by braking behind the vehicle or by completing the pass
(:mod:`twolevel.safety.failsafe`), verified against the oncoming traffic's occupancy.

Units: m, s, m/s, m/s².
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from twolevel.control.high_level.guards import BESIDE_FROM, Front, drivable_band
from twolevel.models.params import BicycleParams
from twolevel.world.area import drivable_area
from twolevel.world.assumptions import opposite_safe_distance, safe_distance
from twolevel.world.signals import HorizonConstants
from twolevel.world.world import World

__all__ = ["oncoming_band", "lateral_due", "lateral_share", "pass_lane", "pass_time", "oncoming_free",
           "sight_suffices", "waiting_room", "room_to_pull_out", "out_of_lane", "OUT_OF_LANE_MARGIN",
           "LANE_CHANGE_TIME", "EDGE_MARGIN"]

LANE_CHANGE_TIME = 2.0
"""[s] The time a lane change back into the route's lane takes (as :data:`BESIDE_FROM` allows for
the change out)."""

_TABLES: "weakref.WeakKeyDictionary[object, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]" = \
    weakref.WeakKeyDictionary()


def _table(world: World, spacing: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(s, lo, hi, oncoming) on a coarse grid along the route, once per world."""
    hit = _TABLES.get(world.route)
    if hit is not None:
        return hit
    s = np.arange(0.0, float(world.route.s[-1]) + spacing, spacing)
    area = drivable_area(world.lanes, world.route, s, oncoming=True)
    half = 0.5 * world.ego.width
    out = (s, _edge_bound(area.lo, area.same_lo, -1.0, half), _edge_bound(area.hi, area.same_hi, 1.0, half),
           area.oncoming)
    _TABLES[world.route] = out
    return out


EDGE_MARGIN = 0.5
"""[m] How far inside the road's edge beyond the oncoming lane the ego's body keeps while it
passes over that lane (a driver keeps off the edge line; the detailed car's tracking and its
heading in the lane change take some of it), at most what keeps the oncoming lane's centre line
within the band."""


def _edge_bound(edge: np.ndarray, same: np.ndarray, sign: float, half: float) -> np.ndarray:
    """The bound [m] of the ego's reference point on one side (``sign`` +1 left, −1 right) whose
    drivable area reaches the road's ``edge`` [m] and, without the oncoming lane, ``same`` [m]:
    the body :data:`EDGE_MARGIN` inside the edge where an oncoming lane is taken in on that side
    (never short of the oncoming lane's centre), else touching it."""
    reach = sign * (edge - same)  # the oncoming lane's width where it is taken in on this side, else 0
    margin = np.where(reach > 1e-9, np.minimum(EDGE_MARGIN, np.maximum(0.5 * reach - half, 0.0)), 0.0)
    return edge - sign * (half + margin)


def oncoming_band(world: World, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lateral bounds (lo, hi) [m] (+ left) of the ego's reference point at route positions ``s``
    [m] with the oncoming lane where passing over it is allowed (the tighter of the two
    neighbouring grid points; elsewhere :func:`drivable_band`'s), and whether the oncoming lane
    is open there (both points)."""
    grid, lo, hi, onc = _table(world)
    i = np.clip(np.searchsorted(grid, np.asarray(s, float)), 1, len(grid) - 1)
    open_ = onc[i - 1] & onc[i]
    b_lo, b_hi = drivable_band(world, s)
    return (np.where(open_, np.maximum(lo[i - 1], lo[i]), b_lo), np.where(open_, np.minimum(hi[i - 1], hi[i]), b_hi),
            open_)


def lateral_share(world: World, v0: float, due: float, t: float) -> float:
    """The share [-] of a lane change begun now at speed ``v0`` [m/s] and due complete in ``due``
    [s] that is done after ``t`` [s]: the smooth step (3u² − 2u³) of the way travelled at the
    comfort acceleration (u = x(t)/x(due)) — from rest, little of it in the first second."""
    a = world.settings.comfort.accel
    u = min(1.0, (v0 * t + 0.5 * a * t * t) / max(v0 * due + 0.5 * a * due * due, 1e-9))
    return 3.0 * u * u - 2.0 * u**3


OUT_OF_LANE_MARGIN = 0.35
"""[m] How far the ego's body keeps beyond the route lane's edge while it passes over the oncoming
lane: the safety layer's box margin (0.1 m), tracking, and D_safe (1 m) to what it passes. The
safety layer predicts a vehicle on its lane anywhere across the lane
(:mod:`twolevel.safety.occupancy`), so a pass that left part of the ego's body in that lane could
never be verified."""


def out_of_lane(world: World, s: float) -> float:
    """[m] The least lateral offset of the ego's reference point (+ left) at route position ``s``
    [m] at which its body is out of the route's lane by :data:`OUT_OF_LANE_MARGIN`."""
    return 0.5 * float(world.route.width_at(s)) + 0.5 * world.ego.width + OUT_OF_LANE_MARGIN


def pass_lane(world: World, s: float, beside: float, next_lane: float) -> float:
    """The lateral offset [m] the reference runs at while the ego passes a vehicle, beside it at
    ``beside`` [m]: the centre of the next lane
    ``next_lane`` [m], within the band the pass is in — the same-direction band when ``beside``
    lies in it (a pass within the lane, or into a lane running the route's way), else the band
    with the oncoming lane — at route position ``s`` [m]. (A reference in a lane the band leaves
    out pulls the plan against the band's edge.)"""
    lo, hi = (float(b[0]) for b in drivable_band(world, np.array([s])))
    if not lo <= beside <= hi:
        lo, hi, _ = (float(b[0]) for b in oncoming_band(world, np.array([s])))
    lo, hi = min(lo, beside), max(hi, beside)
    return min(max(next_lane, lo), hi)


def lateral_due(world: World, params: BicycleParams, v0: float, shift: float) -> float:
    """[s] When a pass that starts now at speed ``v0`` [m/s] can be beside the vehicle ahead,
    ``shift`` [m] to the side: at least :data:`BESIDE_FROM`, and the time to travel, at the comfort
    acceleration from v0, the length of a smooth lane change (3u² − 2u³) of that width whose
    curvature keeps within 80 % of the steering limit and, at v0, the comfort lateral
    acceleration. From standstill a lane change needs room and time the 2 s of a pass at speed
    do not give."""
    length = _lane_change_length(world, params, v0, shift)
    a = world.settings.comfort.accel
    t = (-v0 + math.sqrt(v0 * v0 + 2.0 * a * length)) / a
    return max(BESIDE_FROM, t)


def room_to_pull_out(world: World, params: BicycleParams, front: Front, s0: float, v0: float, shift: float) -> bool:
    """Whether the ego at route position ``s0`` [m] and speed ``v0`` [m/s] is far enough behind
    ``front`` to begin a pass over the oncoming lane now: the lane change ``shift`` [m] out of its
    lane (:func:`_lane_change_length`, as :func:`lateral_due` plans it) fits into the gap to the
    front's rear less D_safe. The front's own travel is not counted: the safety layer assumes it
    may brake (only not speed up) while it is passed, so a pull-out that needs it to drive on
    cannot be verified. Closer, the ego would be half out of its lane behind the vehicle, where
    no fail-safe verifies (it can neither steer back while it brakes nor get out past a front
    that brakes), so it keeps to its waiting room (:func:`waiting_room`) first."""
    gap = float(front.s[0]) - front.offset - s0 - world.settings.D_safe
    return _lane_change_length(world, params, v0, shift) <= gap


def pass_time(world: World, front: Front, s0: float, v0: float) -> tuple[float, float, float]:
    """(T [s], distance [m], speed [m/s]): how long the ego at route position ``s0`` [m] and speed
    ``v0`` [m/s] is out of its lane to pass ``front`` (module docstring), how far it travels
    meanwhile and its speed at the end; T = inf when it cannot get past within 60 s."""
    a = world.settings.comfort.accel
    v_des = float(world.route.desired_speed_at(s0))
    t = np.arange(0.0, 60.0, 0.1)
    t_top = max(v_des - v0, 0.0) / a
    v = np.where(t < t_top, v0 + a * t, max(v_des, v0))
    x = np.where(t < t_top, v0 * t + 0.5 * a * t**2, v0 * t_top + 0.5 * a * t_top**2 + max(v_des, v0) * (t - t_top))
    ahead = safe_distance(front.v, v, world.assumptions.response) + world.settings.D_safe
    need = front.s[0] - s0 + 2.0 * front.offset + ahead + front.v * t
    done = np.flatnonzero(x >= need)
    if not len(done):
        return math.inf, math.inf, float(v[-1])
    k = int(done[0])
    T = float(t[k]) + LANE_CHANGE_TIME
    return T, float(x[k] + v[k] * LANE_CHANGE_TIME), float(v[k])


def oncoming_free(world: World, hc: HorizonConstants, front: Front, s0: float, v0: float) -> bool:
    """Whether the oncoming lane is free for the pass of ``front`` from route position ``s0`` [m]
    at speed ``v0`` [m/s] (module docstring: sensed vehicles, standing ones, and one unseen just
    beyond the sensing range)."""
    T, travel, v_pass = pass_time(world, front, s0, v0)
    if not math.isfinite(T):
        return False
    st = world.settings
    width = float(world.route.width_at(s0))
    ego_resp, other_resp = st.response, world.assumptions.response
    lane = (hc.seen_e > width / 2) & (hc.seen_e < 1.5 * width) & (hc.seen != front.index)
    dist = hc.seen_s[lane] - s0 - (world.ego.length + world.parts.length[hc.seen[lane]]) / 2
    speed = np.maximum(-hc.seen_v[lane], 0.0)  # towards the ego [m/s]
    moving = speed > 0.1
    need = travel + speed * T + opposite_safe_distance(v_pass, speed, ego_resp, other_resp)
    if np.any(moving & (dist > -world.ego.length) & (dist < need)):
        return False
    if np.any(~moving & (dist > -world.ego.length) & (dist < travel + st.D_safe)):
        return False
    return sight_suffices(world, s0, T, travel, v_pass)


def sight_suffices(world: World, s0: float, T: float, travel: float, v_pass: float) -> bool:
    """Whether an oncoming vehicle just beyond the sensing range, at the assumptions' speed bound
    for the limit at route position ``s0`` [m], leaves a pass of ``T`` [s] over ``travel`` [m]
    ending at ``v_pass`` [m/s] RSS's opposite-direction distance."""
    st = world.settings
    cap = world.assumptions.vehicle.speed_cap(float(world.route.limit_at(s0)))
    unseen = travel + cap * T + float(opposite_safe_distance(v_pass, cap, st.response, world.assumptions.response))
    return unseen <= max(st.sensor_range, st.r_near)


WAIT_ROOM_FACTOR = 1.5
"""[-] The waiting room is this many lane changes at the steering limit long (room to track it)."""


def waiting_room(world: World, params: BicycleParams, front: Front, s0: float, e0: float, lateral: float) -> float:
    """[m] How much farther back than D_safe the ego waits behind ``front`` when it could pass it
    over the oncoming lane but the oncoming traffic does not let it now: the length of a lane
    change from rest to beside it (:func:`lateral_due`'s), so that it can pull out when the gap
    comes; 0 where no pass over the oncoming lane could be taken (the lane is not open beside
    it, or the sensing range could never show a gap long enough from where it would wait: the
    pass is judged from there at the front's speed — from rest behind a standing vehicle, at a
    tractor's pace behind one —, not from ``s0``: the ego may still be far back, and a room that
    came and went with the ego's own position would make it surge and brake behind the vehicle)."""
    s_at = front.s[0] + np.array([-front.offset, 0.0, front.offset])
    if not oncoming_band(world, s_at)[2].all():
        return 0.0
    room = WAIT_ROOM_FACTOR * _pull_out(params, max(front.e + lateral, out_of_lane(world, s0)) - e0)
    s_wait = float(front.s[0]) - front.offset - world.settings.D_safe - room
    T, travel, v_pass = pass_time(world, front, s_wait, max(front.v, 0.0))
    if not (math.isfinite(T) and sight_suffices(world, s_wait, T, travel, v_pass)):
        return 0.0
    return room


def _lane_change_length(world: World, params: BicycleParams, v0: float, shift: float) -> float:
    """[m] The length of a smooth lane change (3u² − 2u³) ``shift`` [m] wide begun at ``v0``
    [m/s]: within 80 % of the steering limit (:func:`_pull_out`) and, at v0, the comfort lateral
    acceleration."""
    return max(_pull_out(params, shift), v0 * math.sqrt(6.0 * abs(shift) / world.settings.comfort.lat_accel))


def _pull_out(params: BicycleParams, shift: float) -> float:
    """[m] The length of a smooth lane change (3u² − 2u³) ``shift`` [m] wide whose curvature keeps
    within 80 % of the steering limit (the yaw-rate law ψ̇ = v/l_f·tan δ)."""
    kappa = math.tan(0.8 * params.delta_max) / params.l_f
    return math.sqrt(6.0 * abs(shift) / kappa)
