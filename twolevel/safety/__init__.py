"""Online verification: the ego never causes a collision, whatever the planner above the low level.

**The guarantee.** A command is executed only if, after it, a *fail-safe* exists — a manoeuvre
on the detailed vehicle model that avoids every place the other road users may legally be until
the ego stands still, and stands where nobody may legally come. If the next command does not
verify, the ego executes the fail-safe verified one step earlier, which exists by induction
(the first one is checked at the start: :func:`~twolevel.safety.verify.verify_initial_state`).
So the ego is never in a collision *that is its fault*: while it moves, it is never where a
participant that keeps the assumptions may be; once it stands, it stands outside every lane but
its own (Pek, Manzinger, Koschi, Althoff, Nature Machine Intelligence 2020; Pek & Althoff's
invariably safe states).

**What it rests on** (each written down where it is used):

* the declared **assumptions about others** (:mod:`twolevel.world.assumptions`; SPOT's and
  RSS's published defaults, the scenario's ``assumptions:`` section may change them and
  ``twolevel check`` warns when it makes them tighter): bounded speed (a factor over the limit)
  and acceleration, no reversing, staying on their lanes (changing to parallel ones when allowed),
  stopping at stop signs and red lights they can stop for; pedestrians anywhere within speed and
  acceleration bounds;
* **responsibilities left to others** (RSS): a follower on the ego's lane keeps its distance; a
  participant changing into the ego's lane leaves it RSS's distance (every braking fail-safe
  brakes at least at RSS's brake_min from the next step, so it stops for such a cut-in; a
  clearing one keeps its speed through the zone first); anyone who hits a standing ego outside
  their lane is at fault — :mod:`twolevel.safety.verify` states when each applies (the ego inside its route
  lane);
* **the ego's model**: fail-safes are rolled out on the plant's own four-wheel model and
  parameters, and replayed step by step they reproduce the verified states exactly; a plant that
  differs from the model (a real car) needs the model error in ``VerifySettings.margin``;
* **perception**: the traffic state given to the verifier is what is there (no occlusion, no
  sensing error, every participant known) and the map is right.

**Limits** (what it does not do):

* participants that break the assumptions can hit the ego; :mod:`twolevel.safety.responsibility`
  then classifies the collision as not the ego's fault (the other left its predicted occupancy);
* a lane that is parallel to another and also branches (maps with lines on lane groups), stop
  lines on lanes a participant may change into, and map corners sharper than 90° are handled
  conservatively but were not sampled by the soundness tests;
* standing is invariably safe only outside other lanes; a route whose goal lies inside a
  junction cannot be ended there;
* the prediction horizon is the fail-safe's: beyond its standstill nothing is checked but the
  place it stands (others' occupancies after that are theirs to mind);
* the evasive fail-safe (swerving within the drivable area) is not implemented: braking, and
  clearing a conflict zone first, are.

**Public API** (the names below are importable from ``twolevel.safety``)::

    context(world, params=None, settings=None) -> Context                      # verify.py
    verify_step(ctx, x0, control, traffic, t, s_hint=None) -> Verdict
    verify_initial_state(ctx, x0, traffic, t=0.0, s_hint=None) -> Verdict
    time_to_react(ctx, x0, plan, traffic, t, s_hint=None, known=-1) -> TimeToReact
    predict(net, traffic, t, intervals, assumptions, kinds, include=None, roi=None) -> Occupancy  # occupancy.py
    network_of(world) -> Network                                                # network.py
    roll(x0, plan, route, s0, dt, params, settings=FailSafeSettings(), backend="auto") -> list[FailSafe]  # failsafe.py
    classify(t, ego, other, ego_box, other_box, *, other_inside=None, ego_lane=None, other_lane=None,
             stop_speed=0.1, response_time=2.0, standing_in=None, brake_min=4.0,
             brake_max=8.0) -> Responsibility                                   # responsibility.py
    stayed_within(ctx, traffic_states, i) -> np.ndarray

Records: :class:`Verdict` (``verified``, ``failsafe``, ``refutations``, ``horizon``,
``participants``, ``timings_ms``), :class:`FailSafe` (``controls`` (N, 2) [δ rad, γ] from the
state after the intended step, ``states``, ``control_at(k)``), :class:`Refutation`,
:class:`TimeToReact`, :class:`Responsibility`; the assumptions are the world's
(:class:`~twolevel.world.assumptions.Assumptions`). Importing this package imports numpy:
``twolevel check`` never imports it.
"""

from twolevel.safety.failsafe import FailSafe, FailSafeSettings, Manoeuvre, roll
from twolevel.safety.network import Network, network_of
from twolevel.safety.occupancy import Intervals, Occupancy, predict
from twolevel.safety.responsibility import Responsibility, classify, stayed_within
from twolevel.safety.verify import (
    Context, Refutation, TimeToReact, Verdict, VerifySettings, context, time_to_react, verify_initial_state, verify_step,
)

__all__ = [
    "Context", "FailSafe", "FailSafeSettings", "Intervals", "Manoeuvre", "Network", "Occupancy", "Refutation",
    "Responsibility", "TimeToReact", "Verdict", "VerifySettings", "classify", "context", "network_of", "predict",
    "roll", "stayed_within", "time_to_react", "verify_initial_state", "verify_step",
]
