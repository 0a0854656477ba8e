"""The names of the signals the world provides to rules (no numpy: ``twolevel check`` reads it).

Meaning and units (computed in :mod:`twolevel.world.signals`):

============  =====  ===============================================================
x, y          m      ego reference point
psi           rad    ego heading
v             m/s    ego speed
a             m/s²   ego acceleration input
delta         rad    ego steering angle
s             m      progress along the route (projection on the reference path)
e             m      lateral offset from the route, + left
v_max         m/s    speed limit in force at the ego's route position
d_stop        m      route distance to the next stop line that applies (+inf if none within r_near)
light_red     1/0    1 when the next light within r_near is red, or yellow and the ego can stop
d_light       m      route distance to that light's stop line (+inf if none within r_near)
d_lead        m      bumper-to-bumper gap to the nearest vehicle ahead in the ego's lane heading its way (+inf if none)
v_lead        m/s    that vehicle's speed along the route (= v if none)
min_gap       m      oriented-box separation to the nearest vehicle within r_near (+inf if none)
n_near        -      number of vehicles within r_near
rss_gap       m      gap to the nearest vehicle ahead in the ego's lane within the sensing range,
                     beyond RSS's safe distance behind it (+inf if none)
d_zone        m      route distance from the ego's front to the entry of its next conflict area at a
                     junction (≤ 0 once in; +inf if none within r_near)
d_zone_out    m      route distance the ego's rear still has to the exit of that area (> 0 until it
                     has left; −inf if none): inside while d_zone ≤ 0 < d_zone_out
t_zone        s      time to reach that area at the current speed (0 inside, +inf standing or none)
t_zone_out    s      time to clear it at the current speed (+inf standing in or before it, 0 if none)
over_centre   m      how far the ego's body reaches over the centre line (the boundary to the first
                     lane left of the route running against it) into the oncoming lane: e + W/2
                     − the line's offset (< 0 inside; −inf where no oncoming lane lies to the left)
solid_left    1/0    1 when that centre line is solid at the ego's route position (may not be crossed
                     from the ego's side)
no_overtaking 1/0    1 inside a no-overtaking zone of the route's lane
xwalk_busy    1/0    1 while a marked crosswalk ahead on the route has a pedestrian waiting at its
                     kerb or walking on it, not yet past the ego's lane (a waiting one only while
                     the ego can stop before the line at 4 m/s²); else 0
d_xwalk       m      route distance to the line before that crosswalk (where the ego's front stands
                     STOP_SHORT before its centre, as other traffic stops; negative once past it,
                     up to PASS_MARGIN; +inf if none within r_near)
============  =====  ===============================================================

``xwalk_busy`` and ``d_xwalk`` (:mod:`twolevel.world.crosswalks`) are *on demand*
(:data:`ON_DEMAND_SIGNALS`): the reference definition (``signals_along``) always gives them, but
a run senses them and records them in its trace and history only when a loaded rule reads them
(so a run without such a rule keeps its columns and its cost).

**Participant signals** relate one other participant o to the ego; a rule reads them inside a
quantifier (``forall o in vehicles: d_lon(o) > 0``). Both are projected on the ego's route: route
position s and lateral offset e (+ left), heading θ relative to the route there, half-extents of
the box along the route l = (L|cos θ| + W|sin θ|)/2 and across it h = (L|sin θ| + W|cos θ|)/2.
The lanes are bands of the route lane's width w parallel to it (band j: |e − j·w| ≤ w/2); a body
*occupies* the bands its lateral extent [e − h, e + h] overlaps. Computed in
:mod:`twolevel.world.relations`.

============  =====  ========  =====================================================================
name          unit   absent    meaning
============  =====  ========  =====================================================================
v             m/s    0         o's speed along the route, v_o·cos θ_o
a             m/s²   0         change of v(o) over the last sample / dt (0 where o was absent at the
                               previous sample; 0 in constant-velocity predictions)
d_lon         m      +inf      o's rear minus the ego's front along the route, (s_o − l_o) − (s + l):
                               > 0 when o is in front of the ego (CommonRoad's in_front_of)
d_lat         m      +inf      e_o − e: o's lateral offset from the ego, + left
in_same_lane  m      −inf      > 0 when o and the ego occupy a common lane: the overlap of o's body with
                               the ego's lanes or of the ego's with o's, the smaller; < 0: the gap
cut_in        m      −inf      > 0 while o cuts into the ego's lane (CommonRoad's cut_in(o, ego)): the
                               least of in_same_lane(o), how far o's body crosses a lane boundary,
                               and how far it moves towards the ego's side in 1 s
precedes      m      −inf      > 0 when o is the vehicle directly ahead in the ego's lane (CommonRoad's
                               precedes): the least of in_same_lane(o), d_lon(o) and, for each other
                               vehicle q in that lane ahead of the ego, how far q's front is behind
                               o's rear
t_reach       s      +inf      time for o to reach the ego's next conflict area at o's speed, along its
                               lane (0 while in it; +inf when past it, standing, or on no lane
                               that conflicts with the ego's)
t_clear       s      0         time for o to clear that area at its speed (+inf standing in or before it)
priority      1/0    0         1 when o goes before the ego there (arm priorities, a left turn gives
                               way to oncoming traffic, lights)
d_exit        m      −inf      how far the ego's rear has to go along the route to leave its zone of
                               the conflict with o's way (< 0 once left)
d_behind      m      +inf      the ego's rear minus o's front along the route, (s − L/2) − (s_o + l_o):
                               > 0 when o is behind the ego (d_lon(o)'s mirror); o is *beside* the
                               ego while d_lon(o) ≤ 0 and d_behind(o) ≤ 0
left_of       m      −inf      how far o's body lies left of the ego's, (e_o − h_o) − (e + W/2): > 0
                               when o is wholly to the ego's left; −inf when o does not run the
                               route's way (heading within 45°: oncoming traffic is never left_of)
============  =====  ========  =====================================================================

In ``d_behind`` and ``left_of`` the ego's box is taken along the route (L, W its length and width;
its heading relative to the route left out, as for ``over_centre``: affine in s and e, as the MPC
encodes them).

t_reach … d_exit (and the ego's d_zone … t_zone_out) are :mod:`twolevel.world.right_of_way`'s.

A participant is *present* at a sample when it is active and within ``r_near`` of the ego; the
signal ``present[ID]`` (:data:`twolevel.stl.analysis.PRESENT`) is then +inf, else −inf, and its
other signals take the *absent* values above (so that a rule's body, read where o is absent,
neither needs nor invents a value: o is far away, not in the lane, not cutting in). In a trace
participant ID's signal NAME is the column ``NAME[ID]``.

Timing convention (the one place it is stated): sample k of a trace is the state at time k·dt
and the control applied from k·dt on (held until (k+1)·dt). The simulator's trace and history
rows, the low level's predictions (sample k = u*_k, the last held) and the MPC's signals (now =
its decision u_0, the last recorded sample = u_{-1}, the control applied during the last step,
which is also the u_{-1} of the cost term ‖u_0 − u_{-1}‖²) all follow it.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Mapping

SIGNALS: tuple[str, ...] = ("x", "y", "psi", "v", "a", "delta", "s", "e", "v_max", "d_stop", "light_red",
                            "d_light", "d_lead", "v_lead", "min_gap", "n_near", "rss_gap", "d_zone", "d_zone_out",
                            "t_zone", "t_zone_out", "over_centre", "solid_left", "no_overtaking")
"""Every signal the world provides and a run always records, in the order of the table above (the
one list of their names: the simulator's history and trace columns follow this order)."""

ON_DEMAND_SIGNALS: tuple[str, ...] = ("xwalk_busy", "d_xwalk")
"""Signals the world provides that a run records only when a loaded rule reads them (after
:data:`SIGNALS` in the table above)."""

PROVIDED_SIGNALS: frozenset[str] = frozenset(SIGNALS + ON_DEMAND_SIGNALS)
"""Every name a rule may read as an input (what the type checker accepts)."""

PARTICIPANT_SIGNALS: tuple[str, ...] = ("v", "a", "d_lon", "d_lat", "in_same_lane", "cut_in", "precedes", "t_reach",
                                        "t_clear", "priority", "d_exit", "d_behind", "left_of")
"""Every participant signal the world provides, in the order of the table above."""

PROVIDED_PARTICIPANT_SIGNALS: frozenset[str] = frozenset(PARTICIPANT_SIGNALS)
"""The same names as a set (what the type checker accepts as participant signals)."""

PARTICIPANT_ABSENT: Mapping[str, float] = MappingProxyType({
    "v": 0.0, "a": 0.0, "d_lon": math.inf, "d_lat": math.inf, "in_same_lane": -math.inf, "cut_in": -math.inf,
    "precedes": -math.inf, "t_reach": math.inf, "t_clear": 0.0, "priority": 0.0,
    "d_exit": -math.inf, "d_behind": math.inf, "left_of": -math.inf})
"""Each participant signal's value where its participant is absent."""

__all__ = ["SIGNALS", "ON_DEMAND_SIGNALS", "PROVIDED_SIGNALS", "PARTICIPANT_SIGNALS", "PROVIDED_PARTICIPANT_SIGNALS",
           "PARTICIPANT_ABSENT"]
