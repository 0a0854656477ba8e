"""Batched offline robustness: one rule over K candidate traces at once (the low level's monitor).

Same semantics as the oracle :func:`twolevel.monitor.robustness.robustness` (RTAMT 0.4.10's
offline discrete-time monitor, windows truncated at the ends of the trace) — the tests check
equality on random formulas — but every signal is a (K, T) array (candidates × samples, time
along the last axis) or a (T,) array shared by all candidates. The window kernels are the
oracle's own (:mod:`twolevel.monitor.windows`, which work along the last axis), so K candidates
cost one pass of numpy calls instead of K.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from twolevel.monitor.errors import MonitorError
from twolevel.monitor.robustness import DEFAULT_BUILTINS, Builtin
from twolevel.monitor.windows import Kind, future_window, past_window, since, until
from twolevel.stl import ast

__all__ = ["robustness_batch", "evaluate_rules_batch"]

_INF = np.inf


class _Batch:
    def __init__(self, signals: Mapping[str, np.ndarray], dt: float, consts: Mapping[str, float],
                 rules: Mapping[str, np.ndarray], builtins: Mapping[str, Builtin], K: int | None) -> None:
        shapes = {np.shape(v) for v in list(signals.values()) + list(rules.values())}
        T = {s[-1] for s in shapes if len(s) >= 1}
        if len(T) != 1:
            raise MonitorError("signals have different numbers of samples")
        self.T = T.pop()
        ks = {s[0] for s in shapes if len(s) == 2}
        if K is None:
            K = max(ks, default=1)
        if any(k != K for k in ks):
            raise MonitorError("signals have different numbers of candidates")
        self.K = K
        self.dt = float(dt)
        self.shape = (K, self.T)
        self.signals = {k: self.full(v) for k, v in signals.items()}
        self.rules = {k: self.full(v) for k, v in rules.items()}
        self.consts = consts
        self.builtins = builtins

    def full(self, v: np.ndarray | float) -> np.ndarray:
        return np.broadcast_to(np.asarray(v, dtype=np.float64), self.shape)

    def lookup(self, name: str) -> np.ndarray:
        if name in self.rules:
            return self.rules[name]
        if name in self.signals:
            return self.signals[name]
        if name in self.consts:
            return self.full(float(self.consts[name]))
        raise MonitorError(f"no signal, constant or earlier rule named '{name}'", name)

    def run(self, root: ast.Node) -> np.ndarray:
        return np.array(ast.fold(root, self.apply), dtype=np.float64)

    def apply(self, node: ast.Node, args: list[np.ndarray]) -> np.ndarray:  # noqa: C901 - dispatch
        if isinstance(node, ast.Num):
            return self.full(float(node.value))
        if isinstance(node, ast.Var):
            return self.lookup(node.name)
        if isinstance(node, ast.BoolConst):
            return self.full(_INF if node.value else -_INF)
        if isinstance(node, (ast.Neg, ast.Not)):
            return -args[0]
        if isinstance(node, ast.Abs):
            return np.abs(args[0])
        with np.errstate(all="ignore"):
            if isinstance(node, ast.Arith):
                left, right = args
                return {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.divide}[node.op](left, right)
            if isinstance(node, ast.Compare):
                left, right = args
                if node.op in ("<", "<="):
                    return right - left
                if node.op in (">", ">="):
                    return left - right
                return -np.abs(left - right) if node.op == "==" else np.abs(left - right)
            if isinstance(node, ast.Binary):
                left, right = args
                if node.op == "and":
                    return np.minimum(left, right)
                if node.op == "or":
                    return np.maximum(left, right)
                if node.op == "implies":
                    return np.maximum(-left, right)
                return -np.abs(left - right) if node.op == "iff" else np.abs(left - right)
        if isinstance(node, ast.Temporal):
            return self.temporal(node, np.ascontiguousarray(args[0]))
        if isinstance(node, ast.BinTemporal):
            left, right = (np.ascontiguousarray(a) for a in args)
            a, b = (0, None) if node.interval is None else node.interval.steps(self.dt)
            if node.op == "until":
                return until(left, right, a, b)
            if node.op == "since":
                return since(left, right, a, b)
            return np.maximum(future_window(left, 0, b, "min"), until(left, right, a, b))
        if isinstance(node, ast.Edge):
            x = args[0]
            edge = -_INF if node.op == "rise" else _INF
            prev = np.concatenate([np.full((self.K, 1), edge), x[:, :-1]], axis=1)
            return np.minimum(x, -prev) if node.op == "rise" else np.minimum(prev, -x)
        if isinstance(node, ast.Call):
            fn = self.builtins.get(node.name)
            if fn is None:
                raise MonitorError(f"unknown built-in predicate '{node.name}'", node.name)
            return self.full(np.asarray(fn(self.signals, *args), dtype=np.float64))
        raise MonitorError(f"cannot evaluate a {type(node).__name__} node", type(node).__name__)

    def temporal(self, node: ast.Temporal, x: np.ndarray) -> np.ndarray:
        if node.op in ("next", "prev"):
            pad = np.full((self.K, 1), _INF)
            return np.concatenate([x[:, 1:], pad], axis=1) if node.op == "next" else np.concatenate([pad, x[:, :-1]], axis=1)
        a, b = (0, None) if node.interval is None else node.interval.steps(self.dt)
        kind: Kind = "min" if node.op in ("always", "historically") else "max"
        if node.op in ("always", "eventually"):
            return future_window(x, a, b, kind)
        return past_window(x, a, b, kind)


def robustness_batch(
    formula: ast.Node, signals: Mapping[str, np.ndarray], dt: float, *, consts: Mapping[str, float] | None = None,
    rules: Mapping[str, np.ndarray] | None = None, builtins: Mapping[str, Builtin] | None = None,
    K: int | None = None,
) -> np.ndarray:
    """Robustness (K, T) of ``formula`` on K traces: ``signals`` map names to (K, T) or shared
    (T,) arrays sampled every ``dt`` [s]. Equal, row by row, to the offline oracle."""
    ev = _Batch(signals, dt, consts or {}, rules or {}, DEFAULT_BUILTINS if builtins is None else builtins, K)
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
