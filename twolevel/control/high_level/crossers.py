"""Pedestrians and cyclists crossing the ego's lane ahead: where the MPC's reference waits for them.

A driver who sees someone walking or riding towards the road ahead slows down and lets them
cross, seconds before collision avoidance would have to. Away from a crosswalk the person
crossing must give way (StVO § 25(3)), so no rule binds the ego here; but a driver must still
not run them down (§ 1(2), § 3(2a)), and braking at the tyre limit when they step into the lane
is what a competent driver avoids. This module is that foresight, for the reference only: where
it waits is a cost the plan tracks; what is lawful stays with the rules and what is safe with the
safety layer.

Definitions, from what the ego senses now (participants active and within the sensing range;
pedestrians, and cyclists off any lane — a cyclist on a lane is traffic, handled by the lane
logic and right of way):

* each is projected onto the route (s_i, e_i) [m] and moves on in a straight line at its speed
  now: sideways at ė = v·sin(ψ − route heading), along at ṡ = v·cos(…) [m/s];
* the *band* is what the ego's body sweeps: the route's lane, widened to the ego's own lateral
  extent where it is off the centre, plus the person's half width and :data:`MARGIN`;
* a person *crosses* when it moves sideways at :data:`CROSS_SPEED` or more and across the road
  (|sin| ≥ :data:`CROSS_SINE`), and is in the band or heading into it: it is in the band from
  ``t_in`` (0 when there already) to ``t_out`` [s], where it enters the band at route position
  s_c (the nearer of where it enters and leaves it, less its radius);
* the ego *goes first* when, accelerating at the comfort acceleration up to the desired speed,
  its rear is :data:`MARGIN` past s_c :data:`TIME_GAP` before ``t_in``; the person has *crossed
  first* when the ego's front, so accelerating, reaches s_c no earlier than :data:`TIME_GAP`
  after ``t_out``;
* otherwise the ego waits: :func:`crossing_halt` is the route position of the ego's centre when
  its front stands :data:`~twolevel.world.traffic.pedestrians.STOP_SHORT` before s_c (the
  nearest over all who cross), +inf when none binds.

At a marked crosswalk the rule decides (``rules/crosswalk.stl``), but it sees pedestrians only
within ``r_near``, which may be shorter than the comfortable stopping distance.
:func:`crosswalk_halt` is the rule's own busy crosswalk (:mod:`twolevel.world.crosswalks`) with
the pedestrians sensed within the sensing range instead, so the reference stops for it from
further away.

Units: m, m/s, m/s², s.
"""

from __future__ import annotations

import math

import numpy as np

from twolevel.safety.occupancy import time_to_travel
from twolevel.world.assumptions import CYCLIST, PEDESTRIAN
from twolevel.world.signals import crosswalks_seen, sensing_window
from twolevel.world.traffic import TrafficState
from twolevel.world.traffic.pedestrians import STOP_SHORT
from twolevel.world.world import World

__all__ = ["CROSS_SPEED", "CROSS_SINE", "MARGIN", "TIME_GAP", "crossing_halt", "crosswalk_halt"]

CROSS_SPEED = 0.3
"""[m/s] Slower sideways than this, a person is not crossing (standing, or walking along)."""
CROSS_SINE = 0.3
"""Below this |sin| of the angle to the road, a person walks along it, not across (17°)."""
MARGIN = 0.5
"""[m] Kept to a crossing person, beside and before/behind the ego's body."""
TIME_GAP = 1.5
"""[s] Kept between the ego and a crossing person at the point they share."""


def crossing_halt(world: World, traffic: TrafficState, xy: tuple[float, float], s0: float, e0: float,
                  v0: float) -> float:
    """[m] Where the ego at ``xy`` [m] — route position ``s0`` and offset ``e0`` [m] —, at speed
    ``v0`` [m/s], waits for the pedestrians and cyclists crossing its lane ahead (the module
    docstring); +inf when none binds."""
    parts, route, ego = world.parts, world.route, world.ego
    user = parts.user
    kind = (user == PEDESTRIAN) | ((user == CYCLIST) & (traffic.lane < 0))
    near = traffic.active & kind & (np.hypot(traffic.x - xy[0], traffic.y - xy[1]) <= world.settings.sensor_range)
    idx = np.flatnonzero(near)
    if not len(idx):
        return math.inf
    s, e = route.project_near(traffic.xy[idx], np.full(len(idx), s0), sensing_window(world))
    rel = traffic.psi[idx] - route.heading_at(s)
    e_dot = traffic.v[idx] * np.sin(rel)
    moving = (np.abs(e_dot) >= CROSS_SPEED) & (np.abs(np.sin(rel)) >= CROSS_SINE)
    if not moving.any():
        return math.inf
    idx, s, e, rel, e_dot = idx[moving], s[moving], e[moving], rel[moving], e_dot[moving]
    s_dot = traffic.v[idx] * np.cos(rel)
    radius = 0.5 * np.hypot(parts.length[idx], parts.width[idx])
    half = 0.5 * route.width_at(s)
    lo = np.minimum(-half, e0 - 0.5 * ego.width) - 0.5 * parts.width[idx] - MARGIN
    hi = np.maximum(half, e0 + 0.5 * ego.width) + 0.5 * parts.width[idx] + MARGIN
    t_in = np.maximum((np.where(e_dot > 0, lo, hi) - e) / e_dot, 0.0)
    t_out = (np.where(e_dot > 0, hi, lo) - e) / e_dot
    s_c = s + np.minimum(s_dot * t_in, s_dot * t_out) - radius  # where it enters the band, or leaves it nearer
    n = len(idx)  # the ego accelerating at comfort up to its desired speed (no engine limit)
    v = np.full(n, max(v0, 0.0))
    ramp = (v, np.maximum(v, float(route.desired_speed_at(s0))), np.full(n, world.settings.comfort.accel),
            np.full(n, np.inf))
    clear = time_to_travel(*ramp, np.maximum(s_c + 2.0 * radius + MARGIN + 0.5 * ego.length - s0, 0.0))
    arrive = time_to_travel(*ramp, np.maximum(s_c - MARGIN - 0.5 * ego.length - s0, 0.0))
    waits = ((t_out > 0) & (s_c > s0 + 0.5 * ego.length)  # crossing ahead of the ego's front
             & (clear + TIME_GAP > t_in) & (arrive < t_out + TIME_GAP))  # neither goes first
    if not waits.any():
        return math.inf
    return float((s_c[waits] - STOP_SHORT - 0.5 * ego.length).min())


def crosswalk_halt(world: World, traffic: TrafficState, xy: tuple[float, float], s0: float, v0: float) -> float:
    """[m] The line of the nearest busy crosswalk on the route (``xwalk_busy``'s definition, with
    the pedestrians active within the sensing range of the ego at ``xy`` [m] instead of
    ``r_near``), for the ego at route position ``s0`` [m] and speed ``v0`` [m/s]; +inf when none
    is busy."""
    if world.crosswalks.n == 0:
        return math.inf
    idx = np.flatnonzero(traffic.active & (np.hypot(traffic.x - xy[0], traffic.y - xy[1]) <= world.settings.sensor_range))
    busy, d = crosswalks_seen(world, np.array(s0), np.array(v0), idx, traffic.x[idx], traffic.y[idx],
                              np.ones(len(idx), dtype=bool), reach=world.settings.sensor_range)
    return s0 + float(d) if float(busy) > 0.5 else math.inf
