"""Other traffic: lights' states over time and every participant stepped by its behaviour.

Array-based (HighwayEnv's act-then-step, over all participants at once; the order of one step:
:mod:`twolevel.world.traffic.step`). Behaviours:

* ``stationary``; ``constant_velocity`` (along its lane when placed on one, else straight on);
* ``idm`` — Treiber's Intelligent Driver Model along its lane (:mod:`~twolevel.world.traffic.idm`),
  following the body ahead that is in its way (a car parked beside its path is not,
  :mod:`~twolevel.world.traffic.neighbours`) — the ego included, on its lane and on a lane it
  reaches into — stopping at red lights, at yellow ones it can stop for, at stop signs (standing
  there ``stop_time``, then waiting for an acceptable gap in priority traffic,
  :mod:`~twolevel.world.traffic.junctions`) and for pedestrians crossing; letting a merging ego
  in within its politeness (:mod:`~twolevel.world.traffic.ego`); changing lanes by MOBIL when
  enabled (:mod:`~twolevel.world.traffic.mobil`, :mod:`~twolevel.world.traffic.lanechange`);
* ``scripted`` — waypoints linear in time, or manoeuvre primitives along its lane
  (:mod:`~twolevel.world.traffic.manoeuvres`);
* a pedestrian's walk (:mod:`~twolevel.world.traffic.pedestrians`).

Every behaviour but waypoints stays within the assumptions the safety layer makes about its kind
of road user (:mod:`twolevel.world.assumptions`; the envelope of
:mod:`~twolevel.world.traffic.idm`: IDM's braking is capped at the kind's a_max). A lane-following
participant that runs off the end of a lane continues on the lane's first successor, or leaves
the map (``active`` false).
"""

from twolevel.world.traffic.state import (
    BIG, CONSTANT_VELOCITY, GREEN, IDM, MANOEUVRES, RED, SCRIPTED, STATIONARY, WALK, YELLOW, Conflicts, EgoBox,
    Lights, Memory, Participants, Plans, SpeedLimits, StopLines, TrafficState, Walks, nearby,
)
from twolevel.world.traffic.step import step

__all__ = ["GREEN", "YELLOW", "RED", "Lights", "StopLines", "Conflicts", "SpeedLimits", "Participants", "Plans", "Walks",
           "Memory", "TrafficState", "EgoBox", "step", "nearby", "STATIONARY", "CONSTANT_VELOCITY", "IDM", "SCRIPTED",
           "MANOEUVRES", "WALK", "BIG"]
