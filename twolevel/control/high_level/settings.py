"""The MPC's settings: horizon, cost weights, the solve path and its limits, the guards.

Passed whole to the functions of one step (:func:`~twolevel.control.high_level.linearisation.prepare_step`,
:func:`~twolevel.control.high_level.problem.assemble`, :func:`~twolevel.control.high_level.template.refresh`
and the solve paths of :mod:`twolevel.control.high_level.solvers`). The NMPC baseline reads
the horizon, the period and the weights.
"""

from __future__ import annotations

from dataclasses import dataclass

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
    """Horizon [steps]."""
    dt: float = 0.1
    """Period [s]."""
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
