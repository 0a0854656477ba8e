"""The lateral clearance the ego keeps to a road user it passes: what may be passed, and how wide.

One definition for everyone who lays out a pass: the MPC's reference (how far beside the vehicle
ahead its pass runs, :mod:`twolevel.control.high_level.reference`) and the safety layer's
fail-safes that complete a pass (:mod:`twolevel.safety.verify`). A pass whose clearance does not
fit beside the road user within the lanes running the route's way goes over the oncoming lane
(where the markings open it and the oncoming traffic leaves it free for the pass,
:mod:`twolevel.control.high_level.overtaking`), or the ego follows.

* a **vehicle** (and a parked car): :data:`VEHICLE_CLEARANCE` between the bodies;
* a **cyclist** or a **pedestrian** (:data:`twolevel.world.assumptions.CYCLIST`, ``PEDESTRIAN``):
  1.5 m where the speed limit is urban (at most :data:`URBAN_LIMIT`, 50 km/h), 2 m above it —
  German StVO §5(4) sentence 3 (since 2020: "innerorts mindestens 1,5 m und außerorts mindestens
  2 m"; read here by the limit in force, since the map has no town signs), and the Highway Code
  for Great Britain's rule 163 (at least 1.5 m to cyclists at up to 30 mph). A cyclist may use
  the whole of its lane, so in a lane of ordinary width this clearance takes the ego's body over
  the centre line: such a pass is a pass over the oncoming lane.

Units: m, m/s.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from twolevel.world.assumptions import VEHICLE

__all__ = ["VEHICLE_CLEARANCE", "VULNERABLE_URBAN", "VULNERABLE_RURAL", "URBAN_LIMIT", "passing_clearance"]

VEHICLE_CLEARANCE = 0.5
"""[m] Between the bodies of the ego and a vehicle it passes."""

VULNERABLE_URBAN = 1.5
"""[m] Between the ego's body and a cyclist's or pedestrian's it passes where the limit is urban."""

VULNERABLE_RURAL = 2.0
"""[m] The same above the urban limit."""

URBAN_LIMIT = 13.89
"""[m/s] The highest speed limit that counts as urban (50 km/h)."""


def passing_clearance(user: Any, limit: Any) -> Any:
    """[m] The lateral clearance between the bodies for passing road users of kind ``user``
    (:data:`~twolevel.world.assumptions.VEHICLE`, ``CYCLIST``, ``PEDESTRIAN``; an int or an
    array) where the speed limit is ``limit`` [m/s] (a float or an array broadcasting with it)
    (module docstring)."""
    vulnerable = np.where(np.asarray(limit, dtype=float) <= URBAN_LIMIT + 1e-6, VULNERABLE_URBAN, VULNERABLE_RURAL)
    out = np.where(np.asarray(user) == VEHICLE, VEHICLE_CLEARANCE, vulnerable)
    return float(out) if out.ndim == 0 else out
