"""The low level's last resort: full braking, or the least-violating choice of a standing car.

**Full brake**: γ = −1 with the MPC's steering — the paper's rule when nothing in the sampling
budget satisfies every rule; at speed it sheds the most energy. Unless the car is (almost)
standing (|v| < :data:`STANDING`) and braking is worse: then, when the braking rollout's worst
rule robustness is below that of u* or of a sampled candidate, that least-violating choice is
applied. Braking a standing car cannot cure a violation the others cause (traffic passing
within D_safe of a car stopped half across a lane marking); braking forever there is a
deadlock, not safety.
"""

from __future__ import annotations

import numpy as np

from twolevel.control.low_level.decision import Choice
from twolevel.control.low_level.judge import Judge
from twolevel.control.low_level.prediction import Predictor
from twolevel.models.actuation import accel_from_gamma

__all__ = ["STANDING", "full_brake", "prefer_least_violation"]

STANDING = 1.0
"""Below this speed [m/s] braking changes little, so a least-violating choice may replace it."""


def full_brake(x0: np.ndarray, u_star: np.ndarray, predictor: Predictor, judge: Judge, tm: dict[str, float]
               ) -> Choice:
    """Full braking (γ = −1) with the plan's steering ``u_star[:, 0]`` [rad] from the detailed
    state ``x0``, predicted and judged."""
    H = u_star.shape[0]
    brake = np.stack([u_star[:, 0], -np.ones(H)], axis=1)
    rb = predictor.candidates(x0, brake[None], tm)
    accel = predictor.accel(brake[None, :, 1], rb.states)
    rob = judge(rb.states, accel, brake[None, :, 0])
    a0 = float(accel_from_gamma(-1.0, max(float(x0[3]), 0.0), predictor.params))
    brake_rob = {n: float(v[0]) for n, v in rob.items()}
    worst = min(brake_rob.values()) if brake_rob else np.inf
    return Choice(worst, brake[0].copy(), a0, brake_rob, rb.states[0])


def prefer_least_violation(best: Choice | None, braking: Choice, v_now: float, enabled: bool) -> bool:
    """Whether the least-violating choice ``best`` replaces ``braking`` at speed ``v_now``
    [m/s] (see the module docstring); ``enabled``: the setting allows it."""
    standing = abs(v_now) < STANDING
    return (enabled and standing and best is not None and bool(braking.robustness)
            and best.worst > braking.worst + 1e-9)
