"""The paper's fallback when the MPC finds no plan: the previous plan shifted, or full braking."""

from __future__ import annotations

import numpy as np

from twolevel.control.planner import PreviousPlan
from twolevel.models import bicycle
from twolevel.models.params import BicycleParams

__all__ = ["fallback_plan"]


def fallback_plan(previous: PreviousPlan | None, x0: np.ndarray, H: int, dt: float, params: BicycleParams
                  ) -> tuple[np.ndarray, np.ndarray, str]:
    """States (H+1, 4), controls (H, 2) [δ rad, a m/s²] and why: the previous plan's controls
    shifted by one step (its last control repeated), or full braking with the wheel straight
    when there is none; states rolled out on the kinematic bicycle from ``x0`` (X, Y, ψ, v) over
    ``H`` steps of ``dt`` [s], held at standstill once stopped (no reversing)."""
    if previous is not None and previous.spans(H):
        u = np.vstack([previous.controls[1:], previous.controls[-1:]])
        why = "previous plan shifted"
    else:
        u = np.tile([0.0, params.a_min], (H, 1))
        why = "no previous plan: full braking"
    xs = bicycle.rollout(x0, u, dt, params)
    stopped = np.maximum.accumulate(xs[:, 3] <= 0.0)
    if stopped.any():  # no reversing: hold at standstill
        xs[:, 3] = np.maximum(xs[:, 3], 0.0)
    return xs, u, why
