"""A deliberately reckless high level: it drives the route as fast as the route allows and
ignores everything else — other traffic, stop signs, lights and every rule.

Each step it plans H steps of the kinematic bicycle (:mod:`twolevel.models.bicycle`) that track
the route: the speed goes to the route's desired speed (the limit in force, lowered for bends,
ahead of a lower limit and of the goal when the route stops there, :mod:`twolevel.world.speed_profile`)
at the bicycle's acceleration bounds; the steering follows the route's curvature (δ = atan(l_f·κ))
with Stanley's correction of the heading and lateral errors, within the steering limit and the
lateral-acceleration bound |tan δ| ≤ a_lat_max·l_f/v². It never looks at the traffic it is given.

It exists to show what the low level's safety layer guarantees (:mod:`twolevel.control.low_level.guard`):
whatever a planner asks for, a control runs only if a fail-safe after it was verified, so even
this one is never at fault in a collision (it still breaks traffic rules the low level cannot
correct). Select it with ``twolevel simulate --controller reckless``. Units: m, s, rad, m/s, m/s².
"""

from __future__ import annotations

import math
import time
from typing import Mapping, Sequence

import numpy as np

from twolevel.control.planner import EgoState, PlanResult, PlanStatus, WorldState, planner_of_world
from twolevel.diagnostics import Diagnostic
from twolevel.models import bicycle
from twolevel.models.params import BicycleParams
from twolevel.stl.typecheck import RuleSet
from twolevel.world.world import World

__all__ = ["RecklessPlanner", "K_HEADING", "K_LATERAL"]

K_HEADING = 1.0
"""Stanley's heading gain [-]."""
K_LATERAL = 1.5
"""Stanley's lateral gain [1/s] (over the speed + 1 m/s)."""


class RecklessPlanner:
    """The reckless high level (see the module docstring); a :class:`~twolevel.control.planner.Planner`."""

    label = "reckless"

    def __init__(self, world: World, rulesets: Sequence[RuleSet] = (), settings: object = None, *,
                 params: BicycleParams | None = None) -> None:
        self.world = world
        self.params = params or BicycleParams()
        self.H, self.dt = world.settings.H, world.settings.dt
        self._s: float | None = None  # the route position found last step [m]
        self.diagnostics: list[Diagnostic] = []

    @classmethod
    def from_world(cls, world: World, params: BicycleParams | None = None
                   ) -> tuple["RecklessPlanner | None", list[Diagnostic]]:
        """The planner of a scenario's world (its rule files are read, as every planner's, and
        then ignored)."""
        return planner_of_world(cls, world, None, params)

    @property
    def history_depth(self) -> int:
        """Past samples it reads: none."""
        return 0

    def reset(self) -> None:
        self._s = None

    def solve(self, ego: EgoState | Sequence[float] | np.ndarray, t: float, world_state: WorldState = None,
              history: Mapping[str, np.ndarray] | None = None) -> PlanResult:
        """H steps along the route (``t``, ``world_state`` and ``history`` are ignored)."""
        t0 = time.perf_counter()
        p, route, dt = self.params, self.world.route, self.dt
        x = np.asarray(EgoState.of(ego).pose, dtype=float)
        states, controls = [x], []
        s_hint = self._s
        for k in range(self.H):  # a handful of steps: each needs the route where the car is then
            if s_hint is None:
                s_arr, e_arr = route.local_coordinates(x[None, :2])
            else:
                s_arr, e_arr = route.project_near(x[None, :2], np.array([s_hint]), 15.0 + abs(x[3]) * dt)
            s, e = float(s_arr[0]), float(e_arr[0])
            if k == 0:
                self._s = s
            s_hint = s
            v = float(x[3])
            v_ref = float(route.desired_speed_at(s + max(v, 0.0) * dt))
            a = float(np.clip((v_ref - v) / dt, p.a_min, p.a_max))
            e_psi = (x[2] - float(route.heading_at(s)) + math.pi) % (2 * math.pi) - math.pi
            delta = math.atan(p.l_f * float(route.curvature_at(s))) - K_HEADING * e_psi \
                - math.atan2(K_LATERAL * e, max(v, 0.0) + 1.0)
            bound = min(p.delta_max, math.atan(p.a_lat_max * p.l_f / max(v * v, 1e-6)))
            u = np.array([float(np.clip(delta, -bound, bound)), a])
            x = bicycle.step(x, u, dt, p)
            controls.append(u)
            states.append(x)
        ms = (time.perf_counter() - t0) * 1e3
        return PlanResult(PlanStatus.UNCHECKED, math.nan, np.asarray(controls), np.asarray(states),
                          np.zeros(0, dtype=int), 0, 0, 0, 0, False, {"total": ms}, {}, solver="reckless")
