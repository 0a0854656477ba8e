"""Batched offline robustness: one rule over K candidate traces at once (the low level's monitor).

Same semantics as the oracle :func:`twolevel.monitor.robustness.robustness` (RTAMT 0.4.10's
offline discrete-time monitor, windows truncated at the ends of the trace) — the tests check
equality on random formulas — but every signal is a (K, T) array (candidates × samples, time
along the last axis) or a (T,) array shared by all candidates. The evaluation is the oracle's
own (its evaluator and window kernels work along the last axis); only the set-up of the
signals differs, so K candidates cost one pass of numpy calls instead of K.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from twolevel.monitor.errors import MonitorError
from twolevel.monitor.robustness import DEFAULT_BUILTINS, ArrayEvaluator, Builtin, _Broadcast
from twolevel.stl import ast

__all__ = ["BatchEvaluator", "robustness_batch", "evaluate_rules_batch"]


class BatchEvaluator(ArrayEvaluator):
    """The oracle's evaluation over (K, T) arrays: only the set-up of the signals differs."""

    def __init__(self, signals: Mapping[str, np.ndarray], dt: float, consts: Mapping[str, float],
                 rules: Mapping[str, np.ndarray], builtins: Mapping[str, Builtin], K: int | None) -> None:
        shapes = {np.shape(v) for v in list(signals.values()) + list(rules.values())}
        T = {s[-1] for s in shapes if len(s) >= 1}
        if len(T) != 1:
            raise MonitorError("signals have different numbers of samples")
        self.T = self.n = T.pop()
        ks = {s[0] for s in shapes if len(s) == 2}
        if K is None:
            K = max(ks, default=1)
        if any(k != K for k in ks):
            raise MonitorError("signals have different numbers of candidates")
        self.K = K
        self.dt = float(dt)
        self.shape = (K, self.T)
        if any(len(s) > 2 for s in shapes):
            raise MonitorError("signals must be (K, T) or (T,) arrays")
        # as (K, T) views when the formula reads them (a rule reads a few of the many signals)
        self.signals = _Broadcast(signals, self.full)
        self.rules = _Broadcast(rules, self.full)
        self.consts = consts
        self.builtins = builtins

    def full(self, v: np.ndarray | float) -> np.ndarray:  # type: ignore[override]
        """``v`` (a number, a shared (T,) or a (K, T) array) as a read-only (K, T) view."""
        return np.broadcast_to(np.asarray(v, dtype=np.float64), self.shape)

    def run(self, root: ast.Node) -> np.ndarray:
        with np.errstate(all="ignore"):  # a candidate's overflow is a value, not a warning
            return np.array(super().run(root), dtype=np.float64)


def robustness_batch(
    formula: ast.Node, signals: Mapping[str, np.ndarray], dt: float, *, consts: Mapping[str, float] | None = None,
    rules: Mapping[str, np.ndarray] | None = None, builtins: Mapping[str, Builtin] | None = None,
    K: int | None = None,
) -> np.ndarray:
    """Robustness (K, T) of ``formula`` on K traces: ``signals`` map names to (K, T) or shared
    (T,) arrays sampled every ``dt`` [s]. Equal, row by row, to the offline oracle."""
    ev = BatchEvaluator(signals, dt, consts or {}, rules or {}, DEFAULT_BUILTINS if builtins is None else builtins, K)
    return ev.run(formula)


def evaluate_rules_batch(
    rules: Sequence[ast.Rule], signals: Mapping[str, np.ndarray], dt: float, *,
    consts: Mapping[str, float] | None = None, builtins: Mapping[str, Builtin] | None = None, K: int | None = None,
) -> dict[str, np.ndarray]:
    """Every rule's robustness (K, T), in order; a later rule may name an earlier one."""
    done: dict[str, np.ndarray] = {}
    for rule in rules:
        done[rule.name] = robustness_batch(rule.formula, signals, dt, consts=consts, rules=done, builtins=builtins, K=K)
    return done
