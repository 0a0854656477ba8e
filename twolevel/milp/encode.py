"""STL formulas over an MPC horizon → mixed-integer linear constraints (MILCs).

Signals have two faces (design.md, "World"): at trace step ``k`` a signal is a constant (known at
solve time, including every past sample) or an affine expression of the decision variables.
:class:`AffineSignal` holds the latter as a sparse matrix (one row per step) plus an offset; a
plain array holds the former.

A formula at step ``t`` is first evaluated into a robustness tree (:mod:`twolevel.milp.robtree`):
min/max over affine leaves, with every constant folded, so an inactive rule or a trivially true
disjunct vanishes before a variable is created. Then the tree is *required*:

* satisfaction mode: ``robustness ≥ ε`` (ε = 1e-4, above the solver tolerances);
* robustness mode: ``robustness ≥ ρ`` for one margin variable ρ whose maximum is the robustness
  (ρ ≤ min(a, b) ⇔ ρ ≤ a ∧ ρ ≤ b; ρ ≤ max(a, b) ⇔ ρ ≤ a ∨ ρ ≤ b — exact at the optimum).

A ``min`` needs nothing but its children's rows; a ``max`` over decision variables becomes a
:class:`~twolevel.milp.model.Disjunction` with one binary per disjunct and big-M rows whose M is
the interval bound of the row over the variables' bounds (never a blanket constant). Disjuncts
that can never hold (upper bound below the margin) are removed, a disjunct that always holds
removes its disjunction: this is how vehicle–step pairs out of reach and impossible faces of
``collision_free`` vanish, exactly, once the ego's position bounds are its reachable boxes.
A subtree shared by several parents gets one variable ``z ≤ robustness`` instead of being
encoded once per parent. ``iff``/``xor`` (robustness ∓|a − b|, RTAMT's) need the exact values of
both sides: two-sided encodings ``z = robustness``.

Semantics are those of the offline monitor (RTAMT's discrete-time offline semantics): windows
truncated at the ends of the trace, empty ``always``/``historically`` windows +inf, empty
``eventually``/``once`` windows −inf, ``next`` past the end and ``prev`` before the start +inf.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterable, Literal, Mapping, Sequence, Union

import numpy as np
import scipy.sparse as sp

from twolevel.diagnostics import Code, Diagnostic, Severity, Span
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.model import Disjunction
from twolevel.milp.robtree import INF, Block, Lin, Op, Tree, add, bounds, lin, mk, negate, scale
from twolevel.stl import ast

__all__ = [
    "AffineSignal",
    "Signal",
    "Requirement",
    "Encoding",
    "Emission",
    "EncodeError",
    "Encoder",
    "encode",
    "collision_free_builtin",
    "reachable_box",
    "MIL501",
    "MIL502",
    "MIL503",
    "MIL504",
]

MIL501 = Code("MIL501", "nonlinear-predicate", Severity.ERROR,
              "A predicate is not linear in the decision variables and cannot be encoded.")
MIL502 = Code("MIL502", "unbounded-big-m", Severity.ERROR,
              "A disjunction involves an unbounded variable: no finite big-M exists.")
MIL503 = Code("MIL503", "rule-violated-by-constants", Severity.WARNING,
              "A rule is violated by signals known at solve time; no plan can satisfy it.")
MIL504 = Code("MIL504", "unknown-name", Severity.ERROR,
              "A formula names a signal, constant, rule or built-in the encoder was not given.")

_NOWHERE = Span("<rules>")


@dataclass(frozen=True)
class AffineSignal:
    """A signal affine in the decision variables: value at step k = ``coef[k] @ x + offset[k]``.

    ``coef`` is CSR with one row per trace step (a row without entries is a constant step, e.g.
    a past sample); ``offset`` has the same length."""

    coef: sp.csr_matrix
    offset: np.ndarray

    @classmethod
    def of_columns(cls, cols: Sequence[int] | np.ndarray, n_cols: int,
                   past: Sequence[float] = (), scale: float = 1.0,
                   offset: float | np.ndarray = 0.0) -> "AffineSignal":
        """``scale·x[cols[k]] + offset`` after ``len(past)`` constant past samples."""
        cols = np.asarray(cols, dtype=np.int64)
        P, H = len(past), cols.size
        T = P + H
        indptr = np.concatenate([np.zeros(P + 1, np.int64), np.arange(1, H + 1)])
        C = sp.csr_matrix((np.full(H, scale), cols, indptr), shape=(T, n_cols))
        off = np.concatenate([np.asarray(past, float), np.broadcast_to(offset, (H,))])
        return cls(C, off)

    def __len__(self) -> int:
        return int(self.offset.size)


Signal = Union[AffineSignal, np.ndarray, float]
Builtin = Callable[["Encoder", tuple[ast.Term, ...], int, float, ast.Call], Tree]


class EncodeError(Exception):
    """Raised inside the encoder with the diagnostic to report."""

    def __init__(self, diagnostic: Diagnostic) -> None:
        super().__init__(diagnostic.message)
        self.diagnostic = diagnostic


@dataclass(frozen=True)
class Requirement:
    """Require ``formula`` at the trace steps ``times`` (``name`` labels rows and diagnostics)."""

    name: str
    formula: ast.Node
    times: tuple[int, ...]


@dataclass
class Encoding:
    """What :func:`encode` added to a builder."""

    mode: str
    rho: int = -1  # column of the margin variable in robustness mode
    rows: int = 0
    binaries: int = 0
    continuous: int = 0
    disjunctions: int = 0
    infeasible: bool = False  # a requirement is false by constants alone
    diagnostics: list[Diagnostic] = field(default_factory=list)
    # stable mode: each requirement's folded tree (name, step, tree) and every block emission
    # (:class:`Emission`), for refreshing the values of a model of the same structure
    trees: list[tuple[str, int, object]] = field(default_factory=list)
    emissions: list["Emission"] = field(default_factory=list)
    recovered: list[tuple[str, int, int]] = field(default_factory=list)


@dataclass(frozen=True, eq=False)
class Emission:
    """Where one vectorised block put its rows (stable mode): triplets ``tri`` and rows ``rows``
    (encoder-local, i.e. relative to the start of the ``stl`` block), its binary columns
    ``bins`` (global) and its structure ``struct`` (arrays that must match for a refresh)."""

    kind: str
    tri: slice
    rows: slice
    bins: np.ndarray
    struct: tuple[np.ndarray, ...]


def _has_block(t: Tree) -> bool:
    return isinstance(t, Block) or (isinstance(t, Op) and not t.is_max and any(isinstance(k, Block) for k in t.kids))


def _span(node: ast.Node | None) -> Span:
    return node.span if node is not None and node.span is not None else _NOWHERE


class Encoder:
    """Evaluates formulas into robustness trees and requires them in a :class:`ModelBuilder`."""

    def __init__(
        self, builder: ModelBuilder, signals: Mapping[str, Signal], dt: float, *,
        consts: Mapping[str, float] | None = None,
        rules: Mapping[str, ast.Node] | None = None,
        builtins: Mapping[str, Builtin] | None = None,
        length: int | None = None,
        stable: bool = False,
    ) -> None:
        self.b = builder
        # stable: vectorised blocks keep redundant rows, faces and pairs so that a model's
        # structure depends only on the formulas and the kept vehicle–step pairs (see Emission)
        self.stable = stable
        self.emissions: list[Emission] = []
        self.signals = signals
        self.dt = dt
        self.consts = dict(consts or {})
        self.rules = dict(rules or {})
        self.builtins = dict(builtins or {})
        if length is None:
            lens = [len(s) for s in signals.values()
                    if isinstance(s, AffineSignal) or np.ndim(s) > 0]
            if not lens:
                raise ValueError("give the trace length: no signal has one")
            length = max(lens)
        self.T = int(length)
        self._rob: dict[tuple[int, int, float], Tree] = {}
        self._sig: dict[tuple[str, int], Tree] = {}
        self._dense: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._bnd: dict[int, tuple[float, float, object]] = {}
        self._refs: dict[int, int] = {}
        self._shared: dict[int, Tree] = {}
        self._keep: list[object] = []
        # emitted rows, concatenated once in :meth:`flush`
        self._r: list[np.ndarray] = []
        self._c: list[np.ndarray] = []
        self._v: list[np.ndarray] = []
        self._lo: list[float] = []
        self._n = 0
        self._row0 = builder.n_rows
        self._disj: list[dict] = []
        self._rows_of_guard: dict[int, list[int]] = {}
        self.infeasible = False
        self.diagnostics: list[Diagnostic] = []
        self.n_bin = 0
        self.n_cont = 0
        self._label = ""

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
                from twolevel.milp.affine_block import vector_always

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

    # ------------------------------------------------------------------ rows
    def bounds(self, t: Tree) -> tuple[float, float]:
        return bounds(t, self.b.lb, self.b.ub, self._bnd)

    def _new_var(self, name: str, lo: float, hi: float, binary: bool = False) -> int:
        blk = self.b.add_vars(name, 1, lo, hi, integer=binary)
        if binary:
            self.n_bin += 1
        else:
            self.n_cont += 1
        return blk.start

    def _row(self, idx: Sequence[int], val: Sequence[float], lo: float, guard: int) -> int:
        """Emit ``Σ val·x[idx] ≥ lo``; returns the global row index."""
        r = self._row0 + self._n
        self._r.append(np.full(len(idx), self._n, np.int64))
        self._c.append(np.asarray(idx, np.int64))
        self._v.append(np.asarray(val, float))
        self._lo.append(lo)
        self._n += 1
        if guard >= 0:
            self._rows_of_guard.setdefault(guard, []).append(r)
        return r

    def n_triplets(self) -> int:
        """Triplets emitted so far (encoder-local)."""
        return int(sum(c.size for c in self._c))

    def emit_rows(self, cols: np.ndarray, vals: np.ndarray, lo: np.ndarray) -> np.ndarray:
        """Emit rows ``Σ_j vals[i, j]·x[cols[i, j]] ≥ lo[i]`` at once (unguarded bookkeeping is
        the caller's); returns their global row indices."""
        n, m = cols.shape
        first = self._n
        self._r.append(np.repeat(np.arange(first, first + n), m))
        self._c.append(cols.ravel().astype(np.int64))
        self._v.append(vals.ravel().astype(float))
        self._lo.append(np.asarray(lo, float))
        self._n += n
        return self._row0 + np.arange(first, first + n)

    def emit_triplets(self, n: int, r: np.ndarray, c: np.ndarray, v: np.ndarray, lo: np.ndarray) -> np.ndarray:
        """Emit ``n`` rows ``Σ v·x[c] ≥ lo`` from triplets with block-local rows ``r``."""
        first = self._n
        self._r.append(np.asarray(r, np.int64) + first)
        self._c.append(np.asarray(c, np.int64))
        self._v.append(np.asarray(v, float))
        self._lo.append(np.asarray(lo, float))
        self._n += n
        return self._row0 + np.arange(first, first + n)

    def dense_width(self) -> int | None:
        """The column count every affine signal is expressed over (None if they differ)."""
        ws = {s.coef.shape[1] for s in self.signals.values() if isinstance(s, AffineSignal)}
        return ws.pop() if len(ws) == 1 else (0 if not ws else None)

    def dense_signal(self, name: str, n: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Signal ``name`` as dense rows over the trace: (C (T, n), offset (T,)), cached."""
        hit = self._dense.get(name)
        if hit is not None:
            return hit
        s = self.signals.get(name)
        if s is None:
            return None
        if isinstance(s, AffineSignal):
            rows = np.repeat(np.arange(self.T), np.diff(s.coef.indptr))
            flat = rows * n + np.asarray(s.coef.indices)
            C = np.bincount(flat, weights=np.asarray(s.coef.data, float), minlength=self.T * n).reshape(self.T, n)
            out = (C, np.asarray(s.offset, float))
        else:
            out = (np.zeros((self.T, n)), np.broadcast_to(np.asarray(s, float), (self.T,)).astype(float))
        self._dense[name] = out
        return out

    def emit_grouped(self, owner: np.ndarray, cols: np.ndarray, n_groups: int, *, extra_col: int = -1,
                     lo: float = 1.0) -> np.ndarray:
        """One row per group ``g``: ``Σ_{owner[i] = g} x[cols[i]] (− x[extra_col]) ≥ lo`` (cover rows)."""
        first = self._n
        r = first + owner
        c = cols
        v = np.ones(cols.size)
        if extra_col >= 0:
            r = np.concatenate([r, first + np.arange(n_groups)])
            c = np.concatenate([c, np.full(n_groups, extra_col)])
            v = np.concatenate([v, -np.ones(n_groups)])
        self._r.append(r.astype(np.int64))
        self._c.append(np.asarray(c, np.int64))
        self._v.append(v)
        self._lo.append(np.full(n_groups, float(lo)))
        self._n += n_groups
        return self._row0 + np.arange(first, first + n_groups)

    def add_disjunctions(self, bins: np.ndarray, rows: np.ndarray, covers: np.ndarray, starts: np.ndarray,
                         guard: int) -> None:
        """Record many disjunctions at once: disjunction j has binaries ``bins[starts[j]:starts[j+1]]``,
        binary i enabling the single row ``rows[i]``, and cover row ``covers[j]`` (vectorised
        built-ins; label: the current requirement)."""
        base = len(self.b.disjunctions) + len(self._disj)
        st = starts.tolist()
        for j in range(len(st) - 1):
            a, b = st[j], st[j + 1]
            self._disj.append(dict(id=base + j, binaries=bins[a:b], cover=int(covers[j]), guard=guard,
                                   label=self._label, sources=(), rows=tuple(rows[i:i + 1] for i in range(a, b))))

    def add_disjunction(self, binaries: list[int], cover: int, guard: int, label: str = "",
                        sources: tuple[object, ...] = ()) -> None:
        """Record a disjunction whose rows were emitted (``_rows_of_guard`` filled by the caller)."""
        did = len(self.b.disjunctions) + len(self._disj)
        self._disj.append(dict(id=did, binaries=binaries, cover=cover, guard=guard,
                               label=label or self._label, sources=sources))

    def _fail(self, guard: int) -> None:
        """The current requirement cannot hold: forbid the guard, or mark the model infeasible."""
        if guard >= 0:
            self.b.tighten(np.array([guard]), 0.0, 0.0)
            return
        self.infeasible = True
        self._row((), (), 1.0, -1)  # 0 ≥ 1: the model is honestly infeasible

    def require(self, t: Tree, margin: Lin | float, guard: int = -1) -> None:
        """Add rows so that ``t ≥ margin`` holds whenever ``x[guard] = 1`` (always if −1)."""
        mlo, mhi = self.bounds(margin)
        tlo, thi = self.bounds(t)
        if tlo >= mhi and not (self.stable and guard < 0 and _has_block(t)):
            return  # always holds (stable mode still emits top-level blocks: a fixed structure)
        if thi < mlo:
            self._fail(guard)
            return
        if isinstance(t, float) or isinstance(t, Lin):
            self._leaf(t, margin, guard, mhi)
            return
        if isinstance(t, Block):
            if isinstance(margin, float):
                t.emit(self, margin, guard)  # type: ignore[attr-defined]
            else:
                self.require(t.expand(), margin, guard)
            return
        if self._refs.get(id(t), 0) >= 2:
            z = self._shared.get(id(t))
            if z is None:
                zc = self._new_var("z", tlo, thi)
                z = Lin((zc,), (1.0,), 0.0)
                self._shared[id(t)] = z
                self._keep.append(z)
                self._require_op(t, z, -1)
            self._leaf(z, margin, guard, mhi)
            return
        self._require_op(t, margin, guard)

    def _require_op(self, t: Op, margin: Lin | float, guard: int) -> None:
        if not t.is_max:
            for k in t.kids:
                self.require(k, margin, guard)
            return
        mlo, mhi = self.bounds(margin)
        kids = []
        for k in t.kids:
            klo, khi = self.bounds(k)
            if klo >= mhi:
                return  # a disjunct always holds: no disjunction
            if khi >= mlo:
                kids.append(k)
        if not kids:
            self._fail(guard)
            return
        if len(kids) == 1:
            self.require(kids[0], margin, guard)
            return
        bins = [self._new_var("b", 0.0, 1.0, binary=True) for _ in kids]
        idx = bins + ([guard] if guard >= 0 else [])
        val = [1.0] * len(bins) + ([-1.0] if guard >= 0 else [])
        cover = self._row(idx, val, 0.0 if guard >= 0 else 1.0, -1)
        did = len(self.b.disjunctions) + len(self._disj)
        self._disj.append(dict(id=did, binaries=bins, cover=cover, guard=guard,
                               label=self._label, sources=tuple(kids)))
        for bcol, k in zip(bins, kids):
            self.require(k, margin, bcol)

    def _leaf(self, t: Lin | float, margin: Lin | float, guard: int, mhi: float) -> None:
        # row: t - margin (+ M (1 - g)) >= 0
        idx: list[int] = []
        val: list[float] = []
        const = 0.0
        for x in (t, margin):
            sgn = 1.0 if x is t else -1.0
            if isinstance(x, float):
                const += sgn * x
            else:
                idx.extend(x.idx)
                val.extend(v * sgn for v in x.val)
                const += sgn * x.c
        if guard >= 0:
            tlo = self.bounds(t)[0]
            M = mhi - tlo
            if not math.isfinite(M):
                raise EncodeError(MIL502(
                    "a disjunct's expression is unbounded; give every variable finite bounds",
                    _NOWHERE, hint="bound the states and inputs (reachable boxes)"))
            idx.append(guard)
            val.append(-M)
            self._row(idx, val, -M - const, guard)
        elif not idx:
            if const < 0:
                self._fail(-1)
        else:
            self._row(idx, val, -const, -1)

    def value(self, t: Tree) -> Tree:
        """A leaf equal to ``t`` exactly (a new ``z`` with two one-sided encodings)."""
        if isinstance(t, (float, Lin)):
            return t
        z = self._shared.get(-id(t))
        if z is None:
            lo, hi = self.bounds(t)
            zc = self._new_var("zx", lo, hi)
            z = Lin((zc,), (1.0,), 0.0)
            nz = Lin((zc,), (-1.0,), 0.0)
            self._keep.extend([t, z, nz])
            self._shared[-id(t)] = z
            self.require(t, z)            # z ≤ t
            self.require(negate(t), nz)   # −t ≥ −z
        return z

    # ------------------------------------------------------------------ output
    def flush(self, name: str) -> np.ndarray:
        """Add every emitted row to the builder as one block and register the disjunctions."""
        rows = np.concatenate(self._r) if self._r else np.zeros(0, np.int64)
        cols = np.concatenate(self._c) if self._c else np.zeros(0, np.int64)
        vals = np.concatenate(self._v) if self._v else np.zeros(0)
        assert self.b.n_rows == self._row0, "rows added to the builder while encoding"
        if any(isinstance(v, np.ndarray) for v in self._lo):
            lo = np.concatenate([np.atleast_1d(np.asarray(v, float)) for v in self._lo]) if self._lo else np.zeros(0)
        else:
            lo = np.asarray(self._lo, float)
        out = self.b.add_rows(name, self._n, rows, cols, vals, lo, INF)
        for d in self._disj:
            rws = d.get("rows")
            self.b.add_disjunction(Disjunction(
                id=d["id"], binaries=np.asarray(d["binaries"], np.int64),
                rows=rws if rws is not None else
                tuple(np.asarray(self._rows_of_guard.get(bc, []), np.int64) for bc in d["binaries"]),
                cover_row=d["cover"], guard=d["guard"], label=d["label"], sources=d["sources"]))
        return out


def encode(
    builder: ModelBuilder,
    requirements: Iterable[Requirement],
    signals: Mapping[str, Signal],
    dt: float,
    *,
    mode: Literal["satisfaction", "robustness"] = "satisfaction",
    eps: float = 1e-4,
    consts: Mapping[str, float] | None = None,
    rules: Mapping[str, ast.Node] | None = None,
    builtins: Mapping[str, Builtin] | None = None,
    length: int | None = None,
    rho_weight: float = 1.0,
    rho_bounds: tuple[float, float] | None = None,
    stable: bool = False,
    recover: bool = False,
    recover_after: Mapping[str, int] | None = None,
) -> Encoding:
    """Encode ``requirements`` into ``builder`` (rows in one block named ``"stl"``).

    Satisfaction: every requirement's robustness ≥ ``eps``. Robustness: a margin variable ρ,
    ρ ≤ every requirement's robustness, cost ``−rho_weight·ρ``; ρ is bounded by the interval
    bounds of the requirements (or ``rho_bounds``). Encoding problems (non-linear predicates,
    unknown names, unbounded big-M) come back as diagnostics, never as exceptions. ``stable``:
    vectorised blocks keep redundant rows (structure independent of the current values; see
    :class:`Emission`) and the result lists the trees and emissions. ``recover`` (satisfaction
    mode): a requirement already false at its step by what is known at solve time is required
    instead from the first later step at which it can hold given the variables' bounds (the
    first step whose value the plan can still change); each such shift is listed in
    ``Encoding.recovered`` as (name, step, new step). ``recover_after`` {name: k}: search from step
    + k + 1 on (after a recovery that the solver found infeasible)."""
    enc = Encoder(builder, signals, dt, consts=consts, rules=rules, builtins=builtins, length=length,
                  stable=stable)
    out = Encoding(mode=mode)
    requirements = list(requirements)
    try:
        trees: list[tuple[str, int, Tree]] = []
        for req in requirements:
            for t in req.times:
                tree = enc.rob(req.formula, t, 1.0)
                if isinstance(tree, Op):
                    enc._refs[id(tree)] = enc._refs.get(id(tree), 0) + 1
                trees.append((req.name, t, tree))
        if mode == "robustness":
            top = mk(False, [tr for _, _, tr in trees]) if trees else INF
            lo, hi = enc.bounds(top)
            if rho_bounds is not None:
                lo, hi = max(lo, rho_bounds[0]), min(hi, rho_bounds[1])
            if not math.isfinite(hi):
                hi = rho_bounds[1] if rho_bounds is not None else 1e3
            if not math.isfinite(lo):
                lo = min(hi, rho_bounds[0] if rho_bounds is not None else -1e3)
            out.rho = enc._new_var("rho", lo, hi)
            builder.add_linear_cost(np.array([out.rho]), -rho_weight)
            margin: Lin | float = Lin((out.rho,), (1.0,), 0.0)
        else:
            margin = float(eps)
        if recover and mode == "satisfaction":
            trees = _recover(enc, trees, list(requirements), float(eps), out, dict(recover_after or {}))
        for name, t, tree in trees:
            enc._label = f"{name}@{t}"
            before = enc.infeasible
            enc.require(tree, margin)
            if enc.infeasible and not before:
                enc.diagnostics.append(MIL503(
                    f"rule '{name}' cannot hold at step {t} given the known signals", _NOWHERE))
        enc.flush("stl")
    except EncodeError as e:
        out.diagnostics.append(e.diagnostic)
        out.infeasible = True
        return out
    out.rows = enc._n
    out.binaries = enc.n_bin
    out.continuous = enc.n_cont
    out.disjunctions = len(enc._disj)
    out.infeasible = enc.infeasible
    out.diagnostics.extend(enc.diagnostics)
    if stable:
        out.trees = trees
        out.emissions = enc.emissions
    return out


def _recover(enc: Encoder, trees: list[tuple[str, int, Tree]], reqs: list[Requirement], eps: float,
             out: Encoding, after: dict[str, int]) -> list[tuple[str, int, Tree]]:
    """Shift each requirement that folds to false (upper bound below ε) to its first later step
    at which it can hold; see :func:`encode`."""
    formulas = [r.formula for r in reqs for _ in r.times]
    res = []
    for (name, t, tree), f in zip(trees, formulas):
        if enc.bounds(tree)[1] >= eps:
            res.append((name, t, tree))
            continue
        for t2 in range(t + 1 + after.get(name, 0), enc.T):
            tree2 = enc.rob(f, t2, 1.0)
            if enc.bounds(tree2)[1] >= eps:
                if isinstance(tree2, Op):
                    enc._refs[id(tree2)] = enc._refs.get(id(tree2), 0) + 1
                out.recovered.append((name, t, t2))
                res.append((name, t2, tree2))
                break
        else:
            res.append((name, t, tree))
    return res


# ---------------------------------------------------------------------------- built-ins
# (in their own module; re-exported here for existing callers)
def __getattr__(name: str) -> object:
    if name in ("collision_free_builtin", "reachable_box"):
        from twolevel.milp import collision

        return getattr(collision, name)
    raise AttributeError(name)
