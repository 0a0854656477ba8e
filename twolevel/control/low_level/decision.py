"""The low level's answer for one step: which choice it applied, and why."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twolevel.control.low_level.guard import OFF, Check
from twolevel.milp.solution import ValueEnum

__all__ = ["Action", "Choice", "Decision"]


class Action(ValueEnum):
    """Which control the low level applied (the trace's ``decision``)."""

    MPC = "mpc"
    """u*, the MPC's first control: every rule holds on the detailed prediction — or, with the
    safety layer, the candidate the rules chose instead did not verify while u*_0 did, and u*
    breaks the rules no more than the kept fail-safe would."""
    SAMPLED = "sampled"
    """The best-cost candidate of the ball around u* that satisfies every rule."""
    BRAKE = "brake"
    """Full braking: nothing in the sampling budget satisfies every rule."""
    LEAST_VIOLATION = "least_violation"
    """The least-violating choice (u* or a candidate) of a standing car, where braking is worse."""
    FAILSAFE = "failsafe"
    """The fail-safe verified at an earlier step, one step further: u* did not verify, or the
    control the rules chose did not and u* breaks the rules more than the fail-safe
    (:mod:`twolevel.control.low_level.guard`)."""


@dataclass(frozen=True, eq=False)
class Choice:
    """A control the low level can apply: the ``control`` now [δ rad, γ], the ``accel`` [m/s²]
    γ commands at the current speed, each rule's ``robustness`` at t + dt, the ``worst`` of them,
    and the predicted detailed trajectory ``states`` (H+1, 12)."""

    worst: float
    control: np.ndarray
    accel: float
    robustness: dict[str, float]
    states: np.ndarray


@dataclass(frozen=True, eq=False)
class Decision:
    """The low level's answer for one step.

    ``decision``: the :class:`Action`; ``control`` = [δ rad, γ] applied now; ``accel``
    [m/s²]: the acceleration that γ commands at the current speed (quasi-static);
    ``candidates``: sampled candidates evaluated (0 when u* held); ``robustness``: each rule's
    robustness at t + dt for the choice the rules made (for ``brake``: the braking rollout's);
    ``mpc_robustness``: u*'s; ``states`` (H+1, 12): that choice's predicted detailed
    trajectory; ``timings_ms``: rollout / signals / monitor / verify / total; ``safety``: what
    the safety layer did (:class:`~twolevel.control.low_level.guard.Check`; ``off`` when it is
    off); ``intended`` (H, 2) [δ rad, γ]: u* as actuator commands (for the time to react)."""

    decision: Action
    control: np.ndarray
    accel: float
    candidates: int
    robustness: dict[str, float]
    mpc_robustness: dict[str, float]
    states: np.ndarray
    timings_ms: dict[str, float] = field(default_factory=dict)
    safety: Check = OFF
    intended: np.ndarray | None = None

    @property
    def violated(self) -> tuple[str, ...]:
        """Rules u* violated (why the low level intervened)."""
        return tuple(k for k, v in self.mpc_robustness.items() if not v >= 0)
