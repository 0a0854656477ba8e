"""Stage 1 of the compiler: a formula at one trace step → its robustness tree.

:class:`Evaluator` evaluates terms and every operator of the language with the offline
monitor's semantics (RTAMT's discrete-time offline semantics: windows truncated at the ends of
the trace, empty ``always``/``historically`` windows +inf, empty ``eventually``/``once`` windows
−inf, ``next`` past the end and ``prev`` before the start +inf) into the tree of
:mod:`twolevel.compiler.tree`, every constant folded. ``always`` over a conjunction of linear
predicates becomes one :class:`~twolevel.compiler.affine_block.AffineBlock`; a call
``name(args)`` goes to the built-in of that name (e.g.
:func:`~twolevel.compiler.collision.collision_free_builtin`). ``iff``/``xor`` need the exact
values of both sides: those come from the ``exact`` hook (stage 2's
:meth:`~twolevel.compiler.emitter.RowEmitter.value`).

**The recorded past in one constant.** A past operator's window (``once``, ``historically``)
reaching back over the trace's *settled prefix* — the leading samples every signal its operand
reads has known at solve time: the recorded history — does not become one leaf per sample
(``once[0:15]`` at 10 Hz reads 150 recorded samples at each step of the horizon). The operand's
robustness over that prefix is computed once per encoding by the offline monitor itself
(:func:`twolevel.monitor.robustness.robustness`, numpy over the prefix's arrays: the oracle judges
the recorded past), and each window takes the max (min) of its part of it as one constant; the
samples after the prefix are trees as before. The value is the same as the leaf-by-leaf tree
(the monitor's semantics are the evaluator's), up to the rounding of a division (the monitor
divides, the tree scales by the inverse). The prefix of an operand that reads ahead (``once
eventually[0:1] …``) stops that far before the first unknown sample; an operand calling a
built-in or naming another rule is evaluated leaf by leaf.
"""

from __future__ import annotations

import math
from typing import Callable, Mapping

import numpy as np

from twolevel.compiler.affine_block import vector_always
from twolevel.compiler.codes import MIL501, MIL504, MIL505, EncodeError, span_of
from twolevel.compiler.signals import TraceSignals
from twolevel.compiler.tree import INF, IntervalBounds, Op, Parents, Tree, add, mk, negate, scale
from twolevel.compiler.types import Builtin
from twolevel.monitor.robustness import robustness
from twolevel.stl import ast
from twolevel.stl.analysis import future_horizon, signals_read

__all__ = ["Evaluator"]


class Evaluator:
    """Evaluates formulas over ``signals`` (sample period ``dt`` [s]) into folded robustness
    trees, memoised per (formula node, step, sign). ``rules``: named rules a formula may refer
    to; ``builtins``: built-in predicates by name; ``bounds``: the interval bounds shared with
    stage 2; ``parents``: where the parents of each node are counted (for stage 2's sharing);
    ``exact``: a tree → a leaf equal to it (for ``iff``/``xor``); ``stable``: blocks keep rows
    that are constant now (see :class:`~twolevel.compiler.types.Emission`)."""

    def __init__(
        self, signals: TraceSignals, dt: float, bounds: IntervalBounds, *,
        rules: Mapping[str, ast.Node] | None = None,
        builtins: Mapping[str, Builtin] | None = None,
        parents: Parents | None = None,
        exact: Callable[[Tree], Tree] | None = None,
        stable: bool = False,
    ) -> None:
        self.signals = signals
        self.dt = dt
        self._bounds = bounds
        self.rules = dict(rules or {})
        self.builtins = dict(builtins or {})
        self.parents = Parents() if parents is None else parents
        self._exact = exact
        self.stable = stable
        self._memo: dict[tuple[int, int, float], Tree] = {}
        self._keep: list[object] = []  # formula nodes whose identity keys the memo
        self._recorded: dict[int, tuple[ast.Node, np.ndarray | None]] = {}

    @property
    def length(self) -> int:
        """Steps of the trace [samples]."""
        return self.signals.length

    def bounds(self, t: Tree) -> tuple[float, float]:
        """Interval bounds of ``t`` over the current column bounds."""
        return self._bounds(t)

    # ------------------------------------------------------------------ terms
    def term(self, node: ast.Node, t: int) -> Tree:
        """A term at step ``t``: constant, affine, or min/max of affine pieces (``abs``)."""
        if isinstance(node, ast.Num):
            return float(node.value)
        if isinstance(node, ast.Var):
            c = self.signals.const(node.name)
            if c is not None:
                return c
            return self.signals.at(node.name, t, node)
        if isinstance(node, ast.Neg):
            return negate(self.term(node.operand, t))
        if isinstance(node, ast.Abs):
            v = self.term(node.operand, t)
            if isinstance(v, float):
                return abs(v)
            return mk(True, [v, negate(v)])
        if isinstance(node, ast.Arith):
            a, b = self.term(node.left, t), self.term(node.right, t)
            if node.op == "+":
                return add(a, b)
            if node.op == "-":
                return add(a, negate(b))
            if node.op == "*":
                if isinstance(a, float):
                    return scale(b, a)
                if isinstance(b, float):
                    return scale(a, b)
                raise EncodeError(MIL501("product of two decision-dependent terms", span_of(node),
                                         hint="one factor must be known at solve time"))
            if node.op == "/":
                if isinstance(b, float) and b != 0.0:
                    return scale(a, 1.0 / b)
                raise EncodeError(MIL501("division by a decision-dependent term or by zero",
                                         span_of(node), hint="divide by a known non-zero value"))
        raise EncodeError(MIL504(f"cannot encode term {type(node).__name__}", span_of(node)))

    # ------------------------------------------------------------------ formulas
    def rob(self, node: ast.Node, t: int, s: float = 1.0) -> Tree:
        """``s ·`` robustness of ``node`` at trace step ``t`` (s = ±1) as a folded tree."""
        key = (id(node), t, s)
        hit = self._memo.get(key)
        if hit is not None:
            return hit
        out = self._rob_new(node, t, s)
        if isinstance(out, float) and math.isnan(out):  # the oracle's NaN: no tree, no bound, no verdict
            raise EncodeError(MIL505(
                f"the robustness of this formula at step {t} is undefined: a term is inf - inf (iff/xor of two "
                "sides both infinite, or an infinite signal less itself)", span_of(node),
                hint="the offline monitor finds it undefined too (SIM607); rewrite the formula so that no two "
                     "infinite values are subtracted (e.g. iff/xor of 'true' or of 'next' at the horizon's end)"))
        if isinstance(out, Op):
            for k in out.kids:
                self.parents.add(k)
        self._memo[key] = out
        self._keep.append(node)
        return out

    def _value(self, t: Tree) -> Tree:
        if self._exact is None:
            raise ValueError("iff/xor need exact values: give the evaluator an exact= hook (stage 2)")
        return self._exact(t)

    def _comb(self, is_max: bool, kids: list[Tree], s: float) -> Tree:
        return mk(is_max if s > 0 else not is_max, kids)

    def _window(self, t: int, iv: ast.Interval | None, past: bool) -> range:
        T = self.signals.length
        if iv is None:
            return range(0, t + 1) if past else range(t, T)
        a, b = iv.steps(self.dt)
        if past:
            lo = 0 if b is None else max(t - b, 0)
            return range(lo, t - a + 1) if t - a >= 0 else range(0)
        hi = T - 1 if b is None else min(t + b, T - 1)
        return range(t + a, hi + 1)

    def _rob_new(self, n: ast.Node, t: int, s: float) -> Tree:
        if isinstance(n, ast.Compare):
            l, r = self.term(n.left, t), self.term(n.right, t)
            if n.op in ("<", "<="):
                v = add(r, negate(l))
            elif n.op in (">", ">="):
                v = add(l, negate(r))
            else:
                d = add(l, negate(r))
                v = mk(n.op == "!==", [d, negate(d)]) if not isinstance(d, float) else (
                    abs(d) if n.op == "!==" else -abs(d))
            return scale(v, s)
        if isinstance(n, ast.BoolConst):
            return s * (INF if n.value else -INF)
        if isinstance(n, ast.Not):
            return self.rob(n.operand, t, -s)
        if isinstance(n, ast.Binary):
            if n.op in ("and", "or"):
                return self._comb(n.op == "or", [self.rob(n.left, t, s), self.rob(n.right, t, s)], s)
            if n.op == "implies":
                return self._comb(True, [self.rob(n.left, t, -s), self.rob(n.right, t, s)], s)
            za = self._value(self.rob(n.left, t, 1.0))
            zb = self._value(self.rob(n.right, t, 1.0))
            d = add(za, negate(zb))
            if isinstance(d, float):
                v: Tree = abs(d) if n.op == "xor" else -abs(d)
            else:
                v = mk(n.op == "xor", [d, negate(d)])
            return scale(v, s)
        if isinstance(n, ast.Temporal):
            op = n.op
            if op in ("next", "prev"):
                k = t + 1 if op == "next" else t - 1
                return self.rob(n.operand, k, s) if 0 <= k < self.signals.length else s * INF
            past = op in ast.PAST_OPS
            w = self._window(t, n.interval, past)
            if op == "always" and s > 0:
                fast = vector_always(self.signals, n, w, self.stable)
                if fast is not None:
                    return fast
            is_max = op in ("eventually", "once")
            return self._comb(is_max, self._window_kids(n, w, s, is_max == (s > 0)), s)
        if isinstance(n, ast.BinTemporal):
            if n.op == "unless":
                # RTAMT: phi unless[a,b] psi = always[0,b] phi or phi until[a,b] psi
                alw_iv = None if n.interval is None else ast.Interval(0.0, n.interval.hi)
                g = self._comb(False, [self.rob(n.left, k, s)
                                       for k in self._window(t, alw_iv, False)], s)
                return self._comb(True, [g, self._until(n, t, s)], s)
            if n.op == "until":
                return self._until(n, t, s)
            # since: max over t' in window of min(psi[t'], phi over (t', t])
            kids = []
            for k in self._window(t, n.interval, True):
                parts = [self.rob(n.right, k, s)] + [self.rob(n.left, j, s) for j in range(k + 1, t + 1)]
                kids.append(self._comb(False, parts, s))
            return self._comb(True, kids, s)
        if isinstance(n, ast.Edge):
            if n.op == "rise":
                prev = self.rob(n.operand, t - 1, -s) if t >= 1 else s * INF
                return self._comb(False, [self.rob(n.operand, t, s), prev], s)
            prev = self.rob(n.operand, t - 1, s) if t >= 1 else s * INF
            return self._comb(False, [self.rob(n.operand, t, -s), prev], s)
        if isinstance(n, ast.Var):
            if n.name in self.rules:
                return self.rob(self.rules[n.name], t, s)
            return scale(self.term(n, t), s)
        if isinstance(n, ast.Call):
            fn = self.builtins.get(n.name)
            if fn is None:
                raise EncodeError(MIL504(f"unknown built-in '{n.name}'", span_of(n)))
            return fn(self, n.args, t, s, n)
        if isinstance(n, ast.Rule):
            return self.rob(n.formula, t, s)
        raise EncodeError(MIL504(f"cannot encode {type(n).__name__}", span_of(n)))

    def _window_kids(self, n: ast.Temporal, w: range, s: float, take_max: bool) -> list[Tree]:
        """``s`` · the operand's robustness over the window ``w``: a past operator's samples in
        the settled prefix (:meth:`recorded`) as one constant (their max if ``take_max``, else
        their min), the others as trees."""
        start = w.start
        kids: list[Tree] = []
        if n.op in ast.PAST_OPS and len(w):
            done = self.recorded(n.operand)
            if done is not None and len(done) > w.start:
                start = min(w.stop, len(done))
                part = s * done[w.start:start]
                kids.append(float(part.max() if take_max else part.min()))
        kids += [self.rob(n.operand, k, s) for k in range(start, w.stop)]
        return kids

    def recorded(self, node: ast.Node) -> np.ndarray | None:
        """The robustness of ``node`` at each sample of the settled prefix of the trace that it
        can be judged on (the samples whose whole reach is known at solve time), by the offline
        monitor in one pass; None when there is none or ``node`` holds what the monitor cannot
        evaluate here (a built-in, another rule's name, a participant quantifier). Memoised per
        node for the encoding."""
        hit = self._recorded.get(id(node))
        if hit is not None:
            return hit[1]
        out = self._recorded_new(node)
        self._recorded[id(node)] = (node, out)
        return out

    def _recorded_new(self, node: ast.Node) -> np.ndarray | None:
        if any(isinstance(m, (ast.Call, ast.Quantifier, ast.ParticipantSignal)) for m in node.walk()):
            return None
        names = {m for m in signals_read(node) if self.signals.const(m) is None}
        if not names or names & self.rules.keys() or any(self.signals.get(m) is None for m in names):
            return None
        reach = future_horizon(node, self.dt)
        if not math.isfinite(reach):
            return None
        k = min(self.signals.settled(m) for m in names)
        known = k - math.ceil(reach / self.dt - 1e-9)
        if known <= 0:
            return None
        rho = robustness(node, {m: self.signals.prefix(m, k) for m in names}, self.dt,
                         consts=self.signals.consts)
        return rho[:known]

    def _until(self, n: ast.BinTemporal, t: int, s: float) -> Tree:
        kids = []
        for k in self._window(t, n.interval, False):
            parts = [self.rob(n.right, k, s)] + [self.rob(n.left, j, s) for j in range(t, k)]
            kids.append(self._comb(False, parts, s))
        return self._comb(True, kids, s)
