"""The paper's fallback when the MPC finds no plan: the previous plan shifted, or full braking."""

from __future__ import annotations

import numpy as np

from twolevel.control.high_level.linearisation import shifted
from twolevel.control.planner import PreviousPlan
from twolevel.models import bicycle
from twolevel.models.params import BicycleParams

__all__ = ["fallback_plan"]


def fallback_plan(previous: PreviousPlan | None, x0: np.ndarray, periods: np.ndarray, dt: float,
                  params: BicycleParams) -> tuple[np.ndarray, np.ndarray, str]:
    """States (N+1, 4), controls (N, 2) [δ rad, a m/s²] and why, over the look-ahead of
    ``periods`` (N,) [periods dt of each step; dt in s]: the previous plan's controls shifted by
    one period (:func:`~twolevel.control.high_level.linearisation.shifted`: its last control
    repeated), or full braking with the wheel straight when there is none; states rolled out on
    the kinematic bicycle from ``x0`` (X, Y, ψ, v), held at standstill once stopped (no reversing)."""
    periods = np.asarray(periods)
    if previous is not None and previous.spans(periods):
        u = shifted(previous, np.asarray(x0, dtype=float)[:4], periods, dt, params)[1]
        why = "previous plan shifted"
    else:
        u = np.tile([0.0, params.a_min], (len(periods), 1))
        why = "no previous plan: full braking"
    xs = bicycle.rollout(x0, u, dt * periods, params)
    stopped = np.maximum.accumulate(xs[:, 3] <= 0.0)
    if stopped.any():  # no reversing: hold at standstill
        xs[:, 3] = np.maximum(xs[:, 3], 0.0)
    return xs, u, why
