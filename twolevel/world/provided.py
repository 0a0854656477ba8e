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
d_lead        m      bumper-to-bumper gap to the nearest vehicle ahead in the ego's lane (+inf if none)
v_lead        m/s    that vehicle's speed along the route (= v if none)
min_gap       m      oriented-box separation to the nearest vehicle within r_near (+inf if none)
n_near        -      number of vehicles within r_near
rss_gap       m      gap to the nearest vehicle ahead in the ego's lane within the sensing range,
                     beyond RSS's safe distance behind it (+inf if none)
============  =====  ===============================================================

Timing convention (the one place it is stated): sample k of a trace is the state at time k·dt
and the control applied from k·dt on (held until (k+1)·dt). The simulator's trace and history
rows, the low level's predictions (sample k = u*_k, the last held) and the MPC's signals (now =
its decision u_0, the last recorded sample = u_{-1}, the control applied during the last step,
which is also the u_{-1} of the cost term ‖u_0 − u_{-1}‖²) all follow it.
"""

from __future__ import annotations

SIGNALS: tuple[str, ...] = ("x", "y", "psi", "v", "a", "delta", "s", "e", "v_max", "d_stop", "light_red",
                            "d_light", "d_lead", "v_lead", "min_gap", "n_near", "rss_gap")
"""Every signal the world provides, in the order of the table above (the one list of their names:
the simulator's history and trace columns follow this order)."""

PROVIDED_SIGNALS: frozenset[str] = frozenset(SIGNALS)
"""The same names as a set (what the type checker accepts as a rule's inputs)."""

__all__ = ["SIGNALS", "PROVIDED_SIGNALS"]
