"""Each rule's robustness on a plan, by the offline monitor, with the MPC's own signals.

The plan is a point ``x`` of the step's model; its rule signals over the trace (past, now,
plan) are the model's affine signals evaluated there (:func:`plan_signals`), and
``collision_free(d)`` is the MPC's (the 1-norm diamond to every nearby vehicle's predicted
position), so the figures say what the MILCs required, checked by the oracle
(:func:`twolevel.monitor.robustness.robustness`).
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from twolevel.compiler.signals import AffineSignal
from twolevel.control.high_level.linearisation import StepData
from twolevel.control.high_level.problem import Assembled
from twolevel.control.high_level.rules import MpcRule
from twolevel.monitor.robustness import MonitorError, robustness

__all__ = ["plan_signals", "plan_robustness"]


def plan_signals(asm: Assembled, x: np.ndarray) -> dict[str, np.ndarray]:
    """The rule signals over the trace (past, now, plan) evaluated at the model point ``x``."""
    out: dict[str, np.ndarray] = {}
    for name, s in asm.signals.items():
        if isinstance(s, AffineSignal):
            out[name] = s.coef @ x[: s.coef.shape[1]] + s.offset
        else:
            out[name] = np.asarray(s, float)
    return out


def plan_robustness(rules: Sequence[MpcRule], step: StepData, asm: Assembled, x: np.ndarray, dt: float
                    ) -> dict[str, float]:
    """Each rule's robustness at the current step of the plan ``x`` (NaN when the monitor cannot
    evaluate it); ``dt`` [s]."""
    sig = plan_signals(asm, x)
    P = asm.layout.P
    others = step.hc.xy[:, :asm.layout.H + 1]  # (n, H+1, 2): the fine part the rules read

    def cf(signals: Mapping[str, np.ndarray], d: np.ndarray) -> np.ndarray:
        T = len(signals["x"])
        out = np.full(T, np.inf)
        if others.shape[0]:
            dist = np.abs(signals["x"][P:, None] - others[:, :, 0].T) + np.abs(signals["y"][P:, None] - others[:, :, 1].T)
            out[P:] = dist.min(axis=1)
        return out - d

    res: dict[str, float] = {}
    for r in rules:
        try:
            rho = robustness(r.formula, sig, dt, builtins={"collision_free": cf})
            res[r.name] = float(rho[P])
        except MonitorError:
            res[r.name] = float("nan")
    return res
