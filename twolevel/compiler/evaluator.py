"""Formulas → robustness trees (:mod:`twolevel.compiler.tree`) over the trace, constants folded.

The evaluation half of :class:`twolevel.compiler.encoder.Encoder` (a mixin over its state): signals
at a step, arithmetic terms, every operator of the language with the offline monitor's
semantics (see :mod:`twolevel.compiler.driver`).
"""

from __future__ import annotations

import numpy as np

from twolevel.compiler.types import MIL501, MIL504, AffineSignal, EncodeError, _span
from twolevel.compiler.tree import INF, Op, Tree, add, lin, mk, negate, scale
from twolevel.stl import ast

__all__ = ["TreeEvaluator"]


class TreeEvaluator:
    """Mixin: evaluates formulas into robustness trees (state lives in the encoder)."""

    # ------------------------------------------------------------------ terms
    def signal_at(self, name: str, k: int, node: ast.Node | None = None) -> Tree:
        """The value of signal ``name`` at trace step ``k`` as a tree leaf."""
        key = (name, k)
        hit = self._sig.get(key)
        if hit is not None:
            return hit
        s = self.signals.get(name)
        if s is None:
            if name in self.consts:
                return float(self.consts[name])
            raise EncodeError(MIL504(f"unknown signal or constant '{name}'", _span(node),
                                     hint="pass it in signals= or consts="))
        if isinstance(s, AffineSignal):
            C = s.coef
            a, b = C.indptr[k], C.indptr[k + 1]
            out = lin(tuple(int(i) for i in C.indices[a:b]),
                      tuple(float(v) for v in C.data[a:b]), float(s.offset[k]))
        elif np.ndim(s) == 0:
            out = float(s)
        else:
            out = float(np.asarray(s)[k])
        self._sig[key] = out
        return out

    def term(self, node: ast.Node, t: int) -> Tree:
        """A term at step ``t``: constant, affine, or min/max of affine pieces (``abs``)."""
        if isinstance(node, ast.Num):
            return float(node.value)
        if isinstance(node, ast.Var):
            if node.name in self.consts and node.name not in self.signals:
                return float(self.consts[node.name])
            return self.signal_at(node.name, t, node)
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
                raise EncodeError(MIL501("product of two decision-dependent terms", _span(node),
                                         hint="one factor must be known at solve time"))
            if node.op == "/":
                if isinstance(b, float) and b != 0.0:
                    return scale(a, 1.0 / b)
                raise EncodeError(MIL501("division by a decision-dependent term or by zero",
                                         _span(node), hint="divide by a known non-zero value"))
        raise EncodeError(MIL504(f"cannot encode term {type(node).__name__}", _span(node)))

    # ------------------------------------------------------------------ formulas
    def rob(self, node: ast.Node, t: int, s: float = 1.0) -> Tree:
        """``s ·`` robustness of ``node`` at trace step ``t`` (s = ±1) as a folded tree."""
        key = (id(node), t, s)
        hit = self._rob.get(key)
        if hit is not None:
            return hit
        out = self._rob_new(node, t, s)
        if isinstance(out, Op):
            for k in out.kids:
                if isinstance(k, Op):
                    self._refs[id(k)] = self._refs.get(id(k), 0) + 1
        self._rob[key] = out
        self._keep.append(node)
        return out

    def _comb(self, is_max: bool, kids: list[Tree], s: float) -> Tree:
        return mk(is_max if s > 0 else not is_max, kids)

    def _window(self, t: int, iv: ast.Interval | None, past: bool) -> range:
        T = self.T
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
            za = self.value(self.rob(n.left, t, 1.0))
            zb = self.value(self.rob(n.right, t, 1.0))
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
                return self.rob(n.operand, k, s) if 0 <= k < self.T else s * INF
            past = op in ("historically", "once")
            w = self._window(t, n.interval, past)
            if op == "always" and s > 0:
                from twolevel.compiler.affine_block import vector_always

                fast = vector_always(self, n, w)
                if fast is not None:
                    return fast
            is_max = op in ("eventually", "once")
            return self._comb(is_max, [self.rob(n.operand, k, s) for k in w], s)
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
                raise EncodeError(MIL504(f"unknown built-in '{n.name}'", _span(n)))
            return fn(self, n.args, t, s, n)
        if isinstance(n, ast.Rule):
            return self.rob(n.formula, t, s)
        raise EncodeError(MIL504(f"cannot encode {type(n).__name__}", _span(n)))

    def _until(self, n: ast.BinTemporal, t: int, s: float) -> Tree:
        kids = []
        for k in self._window(t, n.interval, False):
            parts = [self.rob(n.right, k, s)] + [self.rob(n.left, j, s) for j in range(t, k)]
            kids.append(self._comb(False, parts, s))
        return self._comb(True, kids, s)

