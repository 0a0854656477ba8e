"""The affine block: ``always[a,b]`` over a conjunction of linear predicates, vectorised.

``always[0:1] (v <= v_max + tol)`` at one step is the ``min`` over the window of affine
expressions of the decision variables: one dense row per (predicate, step) over the signals'
columns, built with array arithmetic instead of one tree leaf per step. :class:`AffineBlock` is a
:class:`~twolevel.compiler.tree.Block`: rows always true are dropped and rows false by constants
fail the requirement exactly as the generic path does; under a guard each row gets its big-M
from the variable bounds. :func:`vector_always` is stage 1's fast path: anything else (other
operators, non-linear terms, negation) returns ``None`` and the generic evaluation takes over.
"""

from __future__ import annotations

import numpy as np

from twolevel.compiler.sink import RowSink
from twolevel.compiler.signals import TraceSignals
from twolevel.compiler.tree import Block, Tree, lin, mk
from twolevel.stl import ast

__all__ = ["AffineBlock", "vector_always"]


class AffineBlock(Block):
    """``min_i (C[i] @ x[:n] + off[i])`` over the first ``n = C.shape[1]`` columns; ``S`` (same
    shape, bool) is the structural pattern (an entry may be structurally present and zero now)."""

    __slots__ = ("C", "off", "S")
    kind = "affine"

    def __init__(self, C: np.ndarray, off: np.ndarray, S: np.ndarray | None = None) -> None:
        self.C, self.off = C, off
        self.S = C != 0 if S is None else S

    @classmethod
    def merge(cls, blocks: list[Block]) -> "AffineBlock":
        n = max(b.C.shape[1] for b in blocks)  # type: ignore[attr-defined]
        Cs = [np.pad(b.C, ((0, 0), (0, n - b.C.shape[1]))) for b in blocks]  # type: ignore[attr-defined]
        Ss = [np.pad(b.S, ((0, 0), (0, n - b.S.shape[1]))) for b in blocks]  # type: ignore[attr-defined]
        return cls(np.vstack(Cs), np.concatenate([b.off for b in blocks]), np.vstack(Ss))  # type: ignore[attr-defined]

    def _range(self, lb: np.ndarray, ub: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = self.C.shape[1]
        a, b = self.C * lb[None, :n], self.C * ub[None, :n]
        with np.errstate(invalid="ignore"):
            lo = np.where(self.C == 0, 0.0, np.minimum(a, b)).sum(axis=1) + self.off
            hi = np.where(self.C == 0, 0.0, np.maximum(a, b)).sum(axis=1) + self.off
        return lo, hi

    def bounds(self, lb: np.ndarray, ub: np.ndarray) -> tuple[float, float]:
        lo, hi = self._range(lb, ub)
        return float(lo.min()), float(hi.min())

    def expand(self) -> Tree:
        rows = []
        for i in range(self.C.shape[0]):
            nz = np.flatnonzero(self.C[i])
            rows.append(lin(tuple(int(j) for j in nz), tuple(float(v) for v in self.C[i, nz]), float(self.off[i])))
        return mk(False, rows)

    def layout(self, lb: np.ndarray, ub: np.ndarray, margin: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """Stable emission at top level: every row kept (redundant ones too), entries from the
        structural pattern. (r, c, vals, lo) of the rows ``C x ≥ margin − off``; None when a row
        can never hold."""
        lo, hi = self._range(lb, ub)
        if np.any(hi < margin):
            return None
        r, c = np.nonzero(self.S)
        return r, c, self.C[r, c], margin - self.off

    def emit(self, sink: RowSink, margin: float, guard: int) -> None:
        if sink.stable and guard < 0:
            out = self.layout(sink.lb, sink.ub, margin)
            if out is None:
                sink.fail(guard)
                return
            r, c, vals, rhs = out
            since = sink.mark()
            sink.emit_triplets(self.C.shape[0], r, c, vals, rhs)
            sink.record(self.kind, since, np.zeros(0, np.int64), (self.S,))
            return
        lo, hi = self._range(sink.lb, sink.ub)
        if np.any(hi < margin):
            sink.fail(guard)
        live = (lo < margin) & (hi >= margin)
        if not live.any():
            return
        C = self.C[live]
        rhs = margin - self.off[live]
        r, c = np.nonzero(C)
        vals = C[r, c]
        if guard >= 0:
            M = margin - lo[live]
            k = C.shape[0]
            r = np.concatenate([r, np.arange(k)])
            c = np.concatenate([c, np.full(k, guard)])
            vals = np.concatenate([vals, -M])
            rhs = rhs - M
        sink.emit_triplets(C.shape[0], r, c, vals, rhs, guard)


Term = tuple[np.ndarray, np.ndarray, np.ndarray]


def _term(sig: TraceSignals, node: ast.Node, steps: np.ndarray, n: int) -> Term | None:
    """A term over ``steps``: (C (K, n), off (K,), structural pattern S (K, n)), or None when
    not affine with known factors."""
    K = steps.size
    if isinstance(node, ast.Num):
        return np.zeros((K, n)), np.full(K, float(node.value)), np.zeros((K, n), bool)
    if isinstance(node, ast.Var):
        c = sig.const(node.name)
        if c is not None:
            return np.zeros((K, n)), np.full(K, c), np.zeros((K, n), bool)
        dense = sig.dense(node.name, n)
        if dense is None:
            return None
        C, off = dense
        return C[steps], off[steps], sig.pattern(node.name, n)[steps]
    if isinstance(node, ast.Neg):
        a = _term(sig, node.operand, steps, n)
        return None if a is None else (-a[0], -a[1], a[2])
    if isinstance(node, ast.Arith):
        a, b = _term(sig, node.left, steps, n), _term(sig, node.right, steps, n)
        if a is None or b is None:
            return None
        if node.op == "+":
            return a[0] + b[0], a[1] + b[1], a[2] | b[2]
        if node.op == "-":
            return a[0] - b[0], a[1] - b[1], a[2] | b[2]
        a_const, b_const = not a[2].any(), not b[2].any()
        if node.op == "*":
            if a_const:
                return b[0] * a[1][:, None], b[1] * a[1], b[2] & (a[1] != 0)[:, None]
            if b_const:
                return a[0] * b[1][:, None], a[1] * b[1], a[2] & (b[1] != 0)[:, None]
            return None
        if node.op == "/" and b_const and np.all(b[1] != 0):
            return a[0] / b[1][:, None], a[1] / b[1], a[2]
    return None


def _conjuncts(node: ast.Node, out: list[ast.Compare]) -> bool:
    if isinstance(node, ast.Compare) and node.op in ("<", "<=", ">", ">="):
        out.append(node)
        return True
    if isinstance(node, ast.Binary) and node.op == "and":
        return _conjuncts(node.left, out) and _conjuncts(node.right, out)
    return False


def vector_always(sig: TraceSignals, node: ast.Temporal, steps: range, stable: bool = False) -> Tree | None:
    """The robustness tree of ``always`` over ``steps`` of a conjunction of linear predicates,
    as an :class:`AffineBlock` (constants folded first); None when the fast path does not apply.
    ``stable``: a row is constant only when it has no structural entry (see
    :class:`~twolevel.compiler.types.Emission`)."""
    preds: list[ast.Compare] = []
    if not _conjuncts(node.operand, preds) or len(steps) == 0:
        return None
    n = sig.dense_width()
    if n is None:
        return None
    st = np.arange(steps.start, steps.stop)
    Cs, offs, Ss = [], [], []
    for p in preds:
        l, r = _term(sig, p.left, st, n), _term(sig, p.right, st, n)
        if l is None or r is None:
            return None
        if p.op in ("<", "<="):
            Cs.append(r[0] - l[0]), offs.append(r[1] - l[1])
        else:
            Cs.append(l[0] - r[0]), offs.append(l[1] - r[1])
        Ss.append(l[2] | r[2])
    C, off, S = np.vstack(Cs), np.concatenate(offs), np.vstack(Ss)
    if not np.all(np.isfinite(C)):
        return None
    # stable: a row is constant only when it has no structural entry (not when its values are 0)
    const = ~S.any(axis=1) if stable else ~C.any(axis=1)
    with np.errstate(invalid="ignore"):
        c_min = float(np.min(off[const])) if const.any() else np.inf
    if np.isnan(c_min):
        return None
    keep = ~const & np.isfinite(off)
    if np.any(~const & (off == -np.inf)):
        return -np.inf
    if not keep.any():
        return c_min
    blk = AffineBlock(C[keep], off[keep], S[keep] if stable else None)
    return mk(False, [blk, c_min]) if np.isfinite(c_min) else blk
