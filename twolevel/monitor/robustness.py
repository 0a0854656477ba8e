"""The offline discrete-time robustness monitor: the reference oracle.

It gives RTAMT 0.4.10's offline discrete-time semantics (``StlDiscreteTimeSpecification.
evaluate``) for every operator of the rule language, over whole numpy arrays:

* ``a <= b``/``a < b``: ``b - a``; ``>``/``>=``: ``a - b``; ``==``: ``-|a - b|``; ``!==``: ``|a - b|``;
* ``not``: negation; ``and``/``or``: min/max; ``implies``: ``max(-l, r)``; ``iff``: ``-|l - r|``;
  ``xor``: ``|l - r|``; ``true``/``false``: ``+inf``/``-inf``;
* ``always[a,b]``/``eventually[a,b]`` at ``i``: min/max over samples ``i+a .. i+b`` truncated at
  the end of the trace, ``+inf``/``-inf`` when the window is empty; unbounded: to the end;
* ``historically``/``once``: the same over ``i-b .. i-a`` truncated at the start;
* ``l until[a,b] r``: ``max_{m in [a,b]} min(r[i+m], min l[i .. i+m-1])``; beyond the trace
  ``r = -inf``, ``l = +inf``; ``since`` mirrored (``l`` over ``i-m+1 .. i``);
* ``l unless[a,b] r`` = ``always[0,b] l or (l until[a,b] r)`` (RTAMT's rewriting);
* ``next``: ``x[i+1]``, ``+inf`` at the last sample; ``prev``: ``x[i-1]``, ``+inf`` at the first;
* ``rise``: ``min(x[i], -x[i-1])`` with ``x[-1] = -inf``; ``fall``: ``min(-x[i], x[i-1])`` with
  ``x[-1] = +inf``;
* ``forall o in vehicles: body`` at ``i``: the minimum over the participants p present at ``i``
  (``present[p] > 0``) of the body's robustness at ``i`` with ``d_lon(o)`` read from the signal
  ``d_lon[p]``, +inf when none is present; ``exists``: the maximum, -inf when none is — exactly
  :func:`twolevel.stl.analysis.expand_quantifiers`. The participants are those whose presence
  ``present[p]`` the trace holds; the body is evaluated for all of them at once, over arrays
  with a participant axis before time.

Intervals are in seconds and cover the samples ``round(a/dt) .. round(b/dt)``.
"""

from __future__ import annotations

from typing import Callable, Iterator, Mapping, Sequence

import numpy as np

from twolevel.monitor import windows
from twolevel.monitor.errors import MonitorError
from twolevel.stl import ast
from twolevel.stl.analysis import PRESENT, participant_key, participants_in

__all__ = [
    "Builtin",
    "DEFAULT_BUILTINS",
    "MonitorError",
    "collision_free",
    "robustness",
    "evaluate_rules",
    "TraceEvaluator",
    "ArrayEvaluator",
]

Builtin = Callable[..., np.ndarray]
"""A world predicate: ``builtin(signals, *args) -> robustness array``; ``args`` are the evaluated
argument terms (arrays of the trace length), ``signals`` the trace's named signals."""


def collision_free(signals: Mapping[str, np.ndarray], d: np.ndarray) -> np.ndarray:
    """Low-level ``collision_free(d)``: the signal ``min_gap`` (signed separation of the ego's and
    the nearest vehicle's bounding boxes [m]) minus the required distance ``d`` [m]."""
    gap = signals.get("min_gap")
    if gap is None:
        raise MonitorError("collision_free(d) needs the signal 'min_gap' (bounding-box separation [m])", "min_gap")
    return np.asarray(gap, dtype=np.float64) - d


DEFAULT_BUILTINS: Mapping[str, Builtin] = {"collision_free": collision_free}

_INF = np.inf


def _trace_length(signals: Mapping[str, np.ndarray], rules: Mapping[str, np.ndarray]) -> int:
    n: int | None = None
    first = ""
    for group in (signals, rules):
        for name, arr in group.items():
            arr = np.asarray(arr)
            if arr.ndim != 1:
                raise MonitorError(f"signal '{name}' is not one-dimensional (shape {arr.shape})", name)
            if n is None:
                n, first = arr.shape[0], name
            elif arr.shape[0] != n:
                raise MonitorError(
                    f"signal '{name}' has {arr.shape[0]} samples but '{first}' has {n}", name
                )
    if n is None:
        raise MonitorError("cannot tell the trace length: no signals given")
    return n


class ArrayEvaluator:
    """One evaluation: signals, constants, rule results and a memo of evaluated nodes.

    Shape-generic: every value is an array of :attr:`shape` with time along the last axis, so
    the batched monitor (:class:`twolevel.monitor.batch.BatchEvaluator`, shape (K, T)) extends
    it, setting up its signals differently (``__init__`` and :meth:`full`) and reusing the whole
    evaluation (:meth:`run`, :meth:`apply`)."""

    def __init__(
        self,
        signals: Mapping[str, np.ndarray],
        dt: float,
        consts: Mapping[str, float],
        rules: Mapping[str, np.ndarray],
        builtins: Mapping[str, Builtin] | None,
    ) -> None:
        if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
            raise MonitorError(f"the sampling period dt must be a positive number of seconds, got {dt!r}", "dt")
        self.n = _trace_length(signals, rules)
        self.shape: tuple[int, ...] = (self.n,)
        self.dt = float(dt)
        self.signals = {k: np.asarray(v, dtype=np.float64) for k, v in signals.items()}
        self.consts = consts
        self.rules = {k: np.asarray(v, dtype=np.float64) for k, v in rules.items()}
        self.builtins = DEFAULT_BUILTINS if builtins is None else builtins

    def full(self, value: float) -> np.ndarray:
        """``value`` at every sample."""
        return np.full(self.shape, value)

    def _pad(self, x: np.ndarray, value: float) -> np.ndarray:
        """One sample of ``value`` to put before or after ``x`` along time."""
        return np.full(x.shape[:-1] + (1,), value)

    # -- names --------------------------------------------------------------------------------
    def lookup(self, name: str) -> np.ndarray:
        if name in self.rules:
            return self.rules[name]
        if name in self.signals:
            return self.signals[name]
        if name in self.consts:
            return self.full(float(self.consts[name]))
        raise MonitorError(f"no signal, constant or earlier rule named '{name}'", name)

    def steps(self, interval: ast.Interval | None) -> tuple[int, int | None]:
        if interval is None:
            return 0, None
        return interval.steps(self.dt)

    # -- evaluation (iterative post-order: deep formulas do not hit the recursion limit) ------
    def run(self, root: ast.Node) -> np.ndarray:
        return ast.fold(root, self.apply, leaves=(ast.Quantifier,))

    def quantify(self, node: ast.Quantifier) -> np.ndarray:
        """``forall``/``exists`` over the participants whose ``present[p]`` the signals hold: the
        body evaluated once over arrays with a participant axis before time (see the module
        docstring), then the minimum or maximum over it where each participant is present."""
        forall = node.op == "forall"
        pids = participants_in(self.signals)
        if not pids:
            return self.full(np.inf if forall else -np.inf)
        inner = _Bound(self, node.var, pids)
        body = np.asarray(inner.run(node.body), dtype=np.float64)
        with np.errstate(invalid="ignore"):
            present = np.where(inner.stacked(PRESENT) > 0, np.inf, -np.inf)
            if forall:
                return np.min(np.maximum(-present, body), axis=-2)
            return np.max(np.minimum(present, body), axis=-2)

    def apply(self, node: ast.Node, args: list[np.ndarray]) -> np.ndarray:  # noqa: C901 - a dispatch table
        if isinstance(node, ast.Num):
            return self.full(float(node.value))
        if isinstance(node, ast.Var):
            return self.lookup(node.name)
        if isinstance(node, ast.BoolConst):
            return self.full(_INF if node.value else -_INF)
        if isinstance(node, ast.Neg):
            return -args[0]
        if isinstance(node, ast.Abs):
            return np.abs(args[0])
        if isinstance(node, ast.Arith):
            left, right = args
            with np.errstate(all="ignore"):
                if node.op == "+":
                    return left + right
                if node.op == "-":
                    return left - right
                if node.op == "*":
                    return left * right
                return left / right
        if isinstance(node, ast.Compare):
            left, right = args
            with np.errstate(invalid="ignore"):
                if node.op in ("<", "<="):
                    return right - left
                if node.op in (">", ">="):
                    return left - right
                if node.op == "==":
                    return -np.abs(left - right)
                return np.abs(left - right)
        if isinstance(node, ast.Not):
            return -args[0]
        if isinstance(node, ast.Binary):
            left, right = args
            with np.errstate(invalid="ignore"):
                if node.op == "and":
                    return np.minimum(left, right)
                if node.op == "or":
                    return np.maximum(left, right)
                if node.op == "implies":
                    return np.maximum(-left, right)
                if node.op == "iff":
                    return -np.abs(left - right)
                return np.abs(left - right)
        if isinstance(node, ast.Temporal):
            return self.temporal(node, args[0])
        if isinstance(node, ast.BinTemporal):
            return self.bin_temporal(node, args[0], args[1])
        if isinstance(node, ast.Edge):
            x = args[0]
            if node.op == "rise":
                prev = np.concatenate((self._pad(x, -_INF), x[..., :-1]), axis=-1)
                return np.minimum(x, -prev)
            prev = np.concatenate((self._pad(x, _INF), x[..., :-1]), axis=-1)
            return np.minimum(prev, -x)
        if isinstance(node, ast.Call):
            fn = self.builtins.get(node.name)
            if fn is None:
                raise MonitorError(f"unknown built-in predicate '{node.name}'", node.name)
            out = np.asarray(fn(self.signals, *args), dtype=np.float64)
            return np.broadcast_to(out, self.shape).copy()
        if isinstance(node, ast.Quantifier):
            return self.quantify(node)
        if isinstance(node, ast.ParticipantSignal):
            return self.participant_signal(node)
        raise MonitorError(f"cannot evaluate a {type(node).__name__} node", type(node).__name__)

    def participant_signal(self, node: ast.ParticipantSignal) -> np.ndarray:
        raise MonitorError(f"'{node.name}({node.var})' is read outside a quantifier that binds '{node.var}'", node.var)

    def temporal(self, node: ast.Temporal, x: np.ndarray) -> np.ndarray:
        op = node.op
        if op == "next":
            return np.concatenate((x[..., 1:], self._pad(x, _INF)), axis=-1)[..., : self.n]
        if op == "prev":
            return np.concatenate((self._pad(x, _INF), x[..., :-1]), axis=-1)[..., : self.n]
        a, b = self.steps(node.interval)
        if op == "always":
            return windows.future_window(x, a, b, "min")
        if op == "eventually":
            return windows.future_window(x, a, b, "max")
        if op == "historically":
            return windows.past_window(x, a, b, "min")
        return windows.past_window(x, a, b, "max")  # once

    def bin_temporal(self, node: ast.BinTemporal, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        a, b = self.steps(node.interval)
        if node.op == "until":
            return windows.until(left, right, a, b)
        if node.op == "since":
            return windows.since(left, right, a, b)
        held = windows.future_window(left, 0, b, "min")  # unless
        return np.maximum(held, windows.until(left, right, a, b))


class _Broadcast(Mapping[str, np.ndarray]):
    """Signals each seen through ``view`` (a broadcast) when read, since a formula reads a few of
    the many: an evaluator's from inside a quantifier (:class:`_Bound`: an axis for the
    participants inserted before time), or as (K, T) in the batched monitor
    (:class:`twolevel.monitor.batch.BatchEvaluator`)."""

    def __init__(self, signals: Mapping[str, np.ndarray], view: Callable[[np.ndarray], np.ndarray]) -> None:
        self._signals, self._view = signals, view

    def __getitem__(self, name: str) -> np.ndarray:
        return self._view(self._signals[name])

    def __contains__(self, name: object) -> bool:
        return name in self._signals

    def __iter__(self) -> Iterator[str]:
        return iter(self._signals)

    def __len__(self) -> int:
        return len(self._signals)


class _Bound(ArrayEvaluator):
    """The evaluation of a quantifier's body: every value has the outer evaluator's shape with
    the participants ``pids`` as an axis before time; ``var(o)``'s signals are the stacked
    columns ``name[p]``, everything else is the outer evaluator's, broadcast."""

    def __init__(self, outer: ArrayEvaluator, var: str, pids: Sequence[str]) -> None:
        self.outer, self.var, self.pids = outer, var, tuple(pids)
        self.n, self.dt = outer.n, outer.dt
        self.shape = outer.shape[:-1] + (len(self.pids), outer.shape[-1])
        self.signals = _Broadcast(outer.signals, self._inserted)
        self.rules = _Broadcast(outer.rules, self._inserted)
        self.consts, self.builtins = outer.consts, outer.builtins
        self._stacks: dict[str, np.ndarray] = {}

    def _inserted(self, v: np.ndarray) -> np.ndarray:
        """An outer value with an axis for the participants inserted before time (length 1, broadcast)."""
        return np.broadcast_to(np.asarray(v)[..., None, :], self.shape)

    def full(self, value: float) -> np.ndarray:
        return np.full(self.shape, value)

    def stacked(self, name: str) -> np.ndarray:
        """Participant signal ``name`` of every participant, stacked along the participant axis."""
        hit = self._stacks.get(name)
        if hit is None:
            try:
                cols = [np.broadcast_to(np.asarray(self.outer.signals[participant_key(name, p)], dtype=np.float64),
                                        self.outer.shape) for p in self.pids]
            except KeyError as exc:
                raise MonitorError(f"no signal '{exc.args[0]}': every participant present needs its "
                                   f"'{name}' column", str(exc.args[0])) from None
            hit = self._stacks[name] = np.stack(cols, axis=-2)
        return hit

    def participant_signal(self, node: ast.ParticipantSignal) -> np.ndarray:
        if node.var != self.var:
            return super().participant_signal(node)
        return self.stacked(node.name)

    def quantify(self, node: ast.Quantifier) -> np.ndarray:
        raise MonitorError(f"a quantifier over '{node.var}' inside the quantifier over '{self.var}' is not supported",
                           node.var)


def robustness(
    formula: ast.Node,
    signals: Mapping[str, np.ndarray],
    dt: float,
    *,
    consts: Mapping[str, float] | None = None,
    rules: Mapping[str, np.ndarray] | None = None,
    builtins: Mapping[str, Builtin] | None = None,
) -> np.ndarray:
    """The robustness of ``formula`` at every sample of the trace (float64; ``±inf`` for
    ``true``/``false`` and empty windows, as RTAMT).

    ``signals`` maps names to equally long 1-D arrays sampled every ``dt`` [s]; ``consts`` maps
    declared constants to numbers; ``rules`` maps names of already evaluated rules to their
    robustness; ``builtins`` replaces :data:`DEFAULT_BUILTINS`. Raises :class:`MonitorError` for
    a missing name, unequal lengths or a bad ``dt``.
    """
    ev = ArrayEvaluator(signals, dt, consts or {}, rules or {}, builtins)
    return np.asarray(ev.run(formula), dtype=np.float64).copy()


class TraceEvaluator:
    """Rules evaluated one after another over one trace: the signals are checked and converted
    once, and each finished rule is added once, so ``R`` rules cost ``O(R)`` set-up, not the
    ``O(R²)`` of calling :func:`robustness` with a growing ``rules`` mapping.

    Raises :class:`MonitorError` as :func:`robustness` does (bad ``dt``, unequal lengths, no
    signals to tell the trace length).
    """

    def __init__(
        self,
        signals: Mapping[str, np.ndarray],
        dt: float,
        *,
        consts: Mapping[str, float] | None = None,
        builtins: Mapping[str, Builtin] | None = None,
    ) -> None:
        self._ev = ArrayEvaluator(signals, dt, consts or {}, {}, builtins)

    def evaluate(self, formula: ast.Node) -> np.ndarray:
        """The robustness of ``formula`` at every sample (names may be rules already added)."""
        return np.asarray(self._ev.run(formula), dtype=np.float64).copy()

    def add(self, name: str, values: np.ndarray) -> None:
        """Make ``values`` (a rule's robustness, one per sample) readable as ``name``."""
        arr = np.asarray(values, dtype=np.float64)
        if arr.shape != (self._ev.n,):
            raise MonitorError(f"rule '{name}' has shape {arr.shape} but the trace has {self._ev.n} samples", name)
        self._ev.rules[name] = arr


def evaluate_rules(
    rules: Sequence[ast.Rule],
    signals: Mapping[str, np.ndarray],
    dt: float,
    *,
    consts: Mapping[str, float] | None = None,
    builtins: Mapping[str, Builtin] | None = None,
) -> dict[str, np.ndarray]:
    """The robustness signal of every rule, in order; a later rule may name an earlier one."""
    done: dict[str, np.ndarray] = {}
    if not rules:
        return done
    ev = TraceEvaluator(signals, dt, consts=consts, builtins=builtins)
    for rule in rules:
        done[rule.name] = ev.evaluate(rule.formula)
        ev.add(rule.name, done[rule.name])
    return done
