"""The MPC's settings: horizon, cost weights, the solve path and its limits, the guards.

Passed whole to the functions of one step (:func:`~twolevel.control.high_level.linearisation.prepare_step`,
:func:`~twolevel.control.high_level.problem.assemble`, :func:`~twolevel.control.high_level.template.refresh`
and the solve paths of :mod:`twolevel.control.high_level.solvers`). The NMPC baseline reads
the fine part of the horizon, the period and the weights.

**The look-ahead** (:func:`~twolevel.world.look_ahead.look_ahead_periods`): H steps of the period dt (the *fine part*, the
paper's H = 10 at dt = 0.1 s), then *coarse* steps up to ``horizon_s`` (default
:data:`DEFAULT_HORIZON_S`; coarse steps of :data:`COARSE_PERIODS` periods, the last one shorter
when the rest is not a multiple, or an explicit list ``coarse_steps``). Every step is a whole
number of periods, so each coarse step boundary is a sample time of the rules' grid. The rules
are judged on the fine part only (their STL semantics count steps of dt; a formula looking
further than H·dt is reported by ``twolevel check``); the coarse part carries the dynamics (each
step discretised exactly for its length), the drivable band, the speed bounds (the limit in
force when a rule reads ``v_max``, and what the car can see) and RSS's distance to the vehicle
ahead (:mod:`twolevel.control.high_level.guards`). ``horizon_s`` = H·dt is the paper's uniform
horizon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

from twolevel.world.look_ahead import COARSE_PERIODS, DEFAULT_HORIZON_S, MAX_COARSE_STEPS, look_ahead_periods

__all__ = ["Weights", "MPCSettings", "SOLVERS"]

SOLVERS = ("modes", "highs", "gurobi")
"""The solve paths (:mod:`twolevel.control.high_level.solvers`)."""

@dataclass(frozen=True)
class Weights:
    """The paper's cost weights (all 1 in the paper)."""

    u: float = 1.0
    """Weight on ‖u_k‖² (δ [rad], a [m/s²])."""
    du: float = 1.0
    """Weight on ‖u_k − u_{k−1}‖²."""
    track: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    """Weights on (ζ_k − ω_k)² per state component X, Y, ψ, v (plan minus waypoint)."""


@dataclass(frozen=True)
class MPCSettings:
    """Everything one MPC step is configured by (one docstring per field)."""

    H: int = 10
    """The fine part of the horizon [steps of dt], where the rules are judged."""
    dt: float = 0.1
    """Period [s]."""
    horizon_s: float | None = None
    """[s] The whole look-ahead (:func:`~twolevel.world.look_ahead.look_ahead_periods`; None: its default); H·dt: the paper's
    uniform horizon."""
    coarse_dt: float | None = None
    """[s] Length of the coarse steps (None: :data:`COARSE_PERIODS` periods)."""
    coarse_steps: tuple[float, ...] | None = None
    """[s] The coarse steps' lengths, explicitly (instead of ``coarse_dt``)."""
    weights: Weights = Weights()
    """Cost weights."""
    solver: str = "modes"
    """The solve path, one of :data:`SOLVERS`."""
    time_limit: float | None = 0.1
    """Wall time per step [s]; None: no limit (the mode search's branch-and-bound runs to completion)."""
    gap: float = 0.005
    """Relative optimality gap at which the mode search certifies a plan."""
    eps: float = 1e-4
    """Satisfaction margin: a rule is required with robustness ≥ eps."""
    margins: tuple[tuple[str, float], ...] = (("clear_junction", 0.2),)
    """(rule name, margin) pairs: that rule is required with robustness ≥ eps + margin, a margin
    inside its bound for what the detailed car realises less well than the plan's model. The
    right-of-way rule pack's clear_junction (rules/right_of_way.stl: a ≥ a_go until v ≥ v_go):
    moving off in a tight turn the steered front tyres drag and the detailed car gains about 13 %
    less speed than the plan, so a plan on the bound breaks it on the low level's prediction
    (which then samples a correction); measured on right_turn_stream and merge_cyclist, 0.15 still let
    the low level sample (the shortfall adds up over the look-ahead), 0.2 [m/s², m/s] does not."""
    monitor: bool = True
    """Evaluate ``rule_robustness`` of the plan by the offline monitor."""
    relinearise: bool = True
    """When the step is infeasible, re-linearise about the reference, then about braking."""
    refresh: bool = True
    """(``modes``) Reuse a model of the same structure with new values
    (:mod:`twolevel.control.high_level.template`)."""
    pad: float = 2.0
    """[m] Vehicle–step pairs within d + pad are kept in a refreshable model, so its structure
    lasts several steps."""
    search_ms: float | None = None
    """[ms] The mode search's optional phases (seeds, descent, flips, B&B) stop after that long
    (time-dependent, so not deterministic); ignored when ``time_limit`` is None."""
    search_qps: int | None = 16
    """The mode search's optional phases stop after that many QPs (deterministic; ~1 ms each at
    18 vehicles); always within ``time_limit``; ignored when ``time_limit`` is None."""
    max_flip_qps: int | None = 8
    """At most that many QPs of dual-ordered flips; ignored when ``time_limit`` is None."""
    stop_decel: float = 3.0
    """[m/s²] Deceleration of the terminal can-still-stop condition before a stop line or red
    light a rule guards (:mod:`twolevel.control.high_level.guards`; the scenario's
    ``yellow_decel`` in :meth:`~twolevel.control.high_level.controller.HighLevelController.from_world`)."""
    stop_margin: float = 0.3
    """[m] How far before such a line the plan stops."""
    band: bool = True
    """Keep the lateral offset within the lanes that run the route's way."""
    lateral_weight: bool = True
    """Weigh the steering terms of the cost by the lateral acceleration they cause, about the
    steering that follows the route (:mod:`twolevel.control.high_level.steering`); False: the
    paper's cost (δ in rad about 0), which weaves at motorway speed."""
    rss: bool = True
    """Keep RSS's safe distance (plus the world's D_safe) behind the vehicle ahead within the
    sensing range from the last fine step to the end of the look-ahead (conservative linear rows,
    :func:`twolevel.control.high_level.guards.rss_guard`)."""
    periods: tuple[int, ...] = field(init=False, repr=False, compare=False)
    """The steps of the whole look-ahead in periods dt (:func:`~twolevel.world.look_ahead.look_ahead_periods`; the first H are 1)."""

    def __post_init__(self) -> None:
        if self.H < 1 or not (self.dt > 0 and math.isfinite(self.dt)):
            raise ValueError(f"the horizon needs H ≥ 1 and dt > 0 (H = {self.H}, dt = {self.dt:g} s)")
        cs = None if self.coarse_steps is None else tuple(float(c) for c in self.coarse_steps)
        object.__setattr__(self, "coarse_steps", cs)
        object.__setattr__(self, "periods", look_ahead_periods(self.H, self.dt, self.horizon_s, self.coarse_dt, cs))

    @property
    def N(self) -> int:
        """Steps of the whole look-ahead (H fine, then the coarse ones)."""
        return len(self.periods)

    @property
    def steps(self) -> tuple[float, ...]:
        """[s] The step lengths of the whole look-ahead (n·dt for a step of n periods)."""
        return tuple(n * self.dt for n in self.periods)

    @property
    def ticks(self) -> tuple[int, ...]:
        """The sample times k = 0..N of the look-ahead in periods from now (0 first)."""
        out = [0]
        for n in self.periods:
            out.append(out[-1] + n)
        return tuple(out)

    @property
    def look_ahead(self) -> float:
        """[s] The whole look-ahead."""
        return self.ticks[-1] * self.dt

    @classmethod
    def of_world(cls, ws: Any, **fields: Any) -> "MPCSettings":
        """Settings with a world's horizon (H, dt and the look-ahead), RSS switch, cost weights and rule
        margins (where the scenario gives them), from its :class:`~twolevel.world.world.Settings`
        ``ws``; ``fields`` set the others."""
        u, du, track = ws.weights
        fields.setdefault("weights", Weights(float(u), float(du), tuple(float(w) for w in track)))  # type: ignore[arg-type]
        if ws.margins is not None:
            fields.setdefault("margins", tuple((str(n), float(m)) for n, m in ws.margins))
        return cls(H=ws.H, dt=ws.dt, horizon_s=ws.horizon_s, coarse_dt=ws.coarse_dt, coarse_steps=ws.coarse_steps,
                   rss=ws.rss, **fields)

    def uniform(self) -> "MPCSettings":
        """The same settings over the fine part only (the paper's H steps of dt)."""
        return replace(self, horizon_s=self.H * self.dt, coarse_dt=None, coarse_steps=None)
