"""Predictions of the detailed model for the low level: compiled, batched rollouts.

The four-wheel Pacejka model (:mod:`twolevel.models.rollout`) is rolled out from the ego's
detailed state under u* (accelerations, a → γ through the actuation map at the speed the car
has at each step) or under candidates given as [δ, γ]; :meth:`Predictor.accel` gives the
acceleration signal the rules read. Each rollout adds its time to the step's ``rollout`` [ms].
"""

from __future__ import annotations

import time

import numpy as np

from twolevel.models.actuation import accel_from_gamma
from twolevel.models.params import VehicleParams
from twolevel.models.rollout import Backend, Rollout, rollout, rollout_accel

__all__ = ["Predictor"]


class Predictor:
    """Rollouts over ``H`` steps of ``dt`` [s] of the detailed model ``params`` with ``backend``;
    ``reads_a``: some rule reads the acceleration ``a``."""

    def __init__(self, params: VehicleParams, H: int, dt: float, backend: Backend, reads_a: bool) -> None:
        self.params, self.H, self.dt, self.backend, self.reads_a = params, H, dt, backend, reads_a

    def plan(self, x0: np.ndarray, u_star: np.ndarray, tm: dict[str, float]) -> Rollout:
        """The rollout (1 trajectory) of the plan's controls ``u_star`` (H, 2) [δ rad, a m/s²]."""
        t0 = time.perf_counter()
        ro = rollout_accel(x0, u_star[None], self.dt, self.params, self.backend)
        tm["rollout"] = tm.get("rollout", 0.0) + (time.perf_counter() - t0) * 1e3
        return ro

    def candidates(self, x0: np.ndarray, cand: np.ndarray, tm: dict[str, float]) -> Rollout:
        """The rollouts of candidates (K, n, 2) [δ rad, γ] over n steps from ``x0`` (12,) or one
        state per candidate (K, 12)."""
        t0 = time.perf_counter()
        ro = rollout(x0, cand, self.dt, self.params, self.backend)
        tm["rollout"] = tm.get("rollout", 0.0) + (time.perf_counter() - t0) * 1e3
        return ro

    def accel(self, gamma: np.ndarray, states: np.ndarray) -> np.ndarray:
        """The acceleration signal (K, H) [m/s²] of candidates given as γ (K, H): what γ commands
        (the quasi-static actuation map) when a rule reads ``a``, else the realised rate of
        change of the predicted speed (cheaper, and no rule looks at it)."""
        if self.reads_a:
            return accel_from_gamma(gamma, np.maximum(states[:, :-1, 3], 0.0), self.params)
        return np.diff(states[..., 3], axis=1) / self.dt

    def warm_up(self, x0: np.ndarray, sizes: set[int], first_cut: int | None) -> None:
        """Build (and compile) the rollout functions for every batch size used (``sizes``
        candidates over the horizon, and over ``first_cut`` steps when screening)."""
        u = np.zeros((1, self.H, 2))
        rollout_accel(x0, u, self.dt, self.params, self.backend)
        for k in sizes:
            rollout(x0, np.zeros((k, self.H, 2)), self.dt, self.params, self.backend)
            if first_cut is not None:
                rollout(x0, np.zeros((k, first_cut, 2)), self.dt, self.params, self.backend)
