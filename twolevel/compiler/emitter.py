"""Stage 2 of the compiler: robustness trees → rows of the model.

:class:`RowEmitter` requires a tree above a margin (:meth:`RowEmitter.require`): a ``min`` needs
its children's rows only; a ``max`` over decision variables becomes a
:class:`~twolevel.milp.model.Disjunction`, one binary per disjunct, whose big-M rows get M from
the interval bounds of the row over the columns' bounds (never a blanket constant). A disjunct
that can never hold (upper bound below the margin) is dropped; one that always holds removes
its disjunction. A node with two or more parents (:class:`~twolevel.compiler.tree.Parents`) is
encoded once, through a variable ``z ≤ robustness``. Blocks emit themselves through the
:class:`~twolevel.compiler.sink.RowSink` this class implements. Rows are collected as arrays
and go into the builder as one block at :meth:`RowEmitter.flush`.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from twolevel.compiler.codes import MIL502, NOWHERE, EncodeError
from twolevel.compiler.tree import INF, Block, IntervalBounds, Lin, Op, Parents, Tree, negate
from twolevel.compiler.types import Emission, PendingDisjunction
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.model import Disjunction

__all__ = ["RowEmitter"]


class RowEmitter:
    """Requires robustness trees in ``builder`` (rows ``Σ v·x ≥ lo``); ``bounds`` and ``parents``
    are shared with stage 1; ``stable``: blocks at top level keep a value-independent structure
    and record it (:attr:`emissions`). ``label`` names the requirement being emitted (rule@step)
    on its disjunctions."""

    def __init__(self, builder: ModelBuilder, bounds: IntervalBounds, parents: Parents, *,
                 stable: bool = False) -> None:
        self._b = builder
        self._bounds = bounds
        self._parents = parents
        self.stable = stable
        self.label = ""
        self.emissions: list[Emission] = []
        self.infeasible = False  # a requirement fails by constants alone
        self.binaries = 0
        self.continuous = 0
        # emitted rows, concatenated once in :meth:`flush`
        self._r: list[np.ndarray] = []
        self._c: list[np.ndarray] = []
        self._v: list[np.ndarray] = []
        self._lo: list[float | np.ndarray] = []
        self._n = 0
        self._row0 = builder.n_rows
        self._disj: list[PendingDisjunction] = []
        self._rows_of_guard: dict[int, list[int]] = {}
        self._shared: dict[int, Lin] = {}  # id(tree) → its shared variable
        self._exact: dict[int, Lin] = {}   # id(tree) → a variable equal to it
        self._keep: list[object] = []      # trees whose identity keys the two tables above

    # ------------------------------------------------------------------ counts
    @property
    def rows(self) -> int:
        """Rows emitted so far."""
        return self._n

    @property
    def disjunctions(self) -> int:
        """Disjunctions emitted so far."""
        return len(self._disj)

    # ------------------------------------------------------------------ the row sink of blocks
    @property
    def lb(self) -> np.ndarray:
        return self._b.lb

    @property
    def ub(self) -> np.ndarray:
        return self._b.ub

    def add_continuous(self, name: str, lo: float, hi: float) -> int:
        """A new continuous column in [lo, hi]; its index."""
        blk = self._b.add_vars(name, 1, lo, hi)
        self.continuous += 1
        return blk.start

    def add_binaries(self, name: str, n: int) -> np.ndarray:
        blk = self._b.add_vars(name, n, 0.0, 1.0, integer=True)
        self.binaries += n
        return np.arange(blk.start, blk.stop)

    def _add_binary(self) -> int:
        blk = self._b.add_vars("b", 1, 0.0, 1.0, integer=True)
        self.binaries += 1
        return blk.start

    def tighten(self, cols: np.ndarray, lb: np.ndarray | float, ub: np.ndarray | float) -> None:
        self._b.tighten(cols, lb, ub)

    def fail(self, guard: int) -> None:
        """The current requirement cannot hold: forbid the guard, or mark the model infeasible."""
        if guard >= 0:
            self._b.tighten(np.array([guard]), 0.0, 0.0)
            return
        self.infeasible = True
        self._row((), (), 1.0, -1)  # 0 ≥ 1: the model is honestly infeasible

    def mark(self) -> tuple[int, int]:
        return int(sum(c.size for c in self._c)), self._n

    def record(self, kind: str, since: tuple[int, int], bins: np.ndarray, struct: tuple[np.ndarray, ...]) -> None:
        t1, r1 = self.mark()
        self.emissions.append(Emission(kind, slice(since[0], t1), slice(since[1], r1), bins, struct))

    def _guarded(self, rows: np.ndarray, guard: int) -> np.ndarray:
        if guard >= 0:
            self._rows_of_guard.setdefault(guard, []).extend(rows.tolist())
        return rows

    def emit_rows(self, cols: np.ndarray, vals: np.ndarray, lo: np.ndarray, guard: int = -1) -> np.ndarray:
        n, m = cols.shape
        first = self._n
        self._r.append(np.repeat(np.arange(first, first + n), m))
        self._c.append(cols.ravel().astype(np.int64))
        self._v.append(vals.ravel().astype(float))
        self._lo.append(np.asarray(lo, float))
        self._n += n
        return self._guarded(self._row0 + np.arange(first, first + n), guard)

    def emit_triplets(self, n: int, r: np.ndarray, c: np.ndarray, v: np.ndarray, lo: np.ndarray,
                      guard: int = -1) -> np.ndarray:
        first = self._n
        self._r.append(np.asarray(r, np.int64) + first)
        self._c.append(np.asarray(c, np.int64))
        self._v.append(np.asarray(v, float))
        self._lo.append(np.asarray(lo, float))
        self._n += n
        return self._guarded(self._row0 + np.arange(first, first + n), guard)

    def emit_covers(self, owner: np.ndarray, cols: np.ndarray, n_groups: int, *, extra_col: int = -1,
                    lo: float = 1.0) -> np.ndarray:
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
        base = len(self._b.disjunctions) + len(self._disj)
        st = starts.tolist()
        for j in range(len(st) - 1):
            a, b = st[j], st[j + 1]
            self._disj.append(PendingDisjunction(base + j, bins[a:b], int(covers[j]), guard, self.label, (),
                                                 tuple(rows[i:i + 1] for i in range(a, b))))

    # ------------------------------------------------------------------ trees
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

    def require(self, t: Tree, margin: Lin | float, guard: int = -1) -> None:
        """Add rows so that ``t ≥ margin`` holds whenever ``x[guard] = 1`` (always if −1)."""
        mlo, mhi = self._bounds(margin)
        tlo, thi = self._bounds(t)
        if tlo >= mhi and not (self.stable and guard < 0 and _has_block(t)):
            return  # always holds (stable mode still emits top-level blocks: a fixed structure)
        if thi < mlo:
            self.fail(guard)
            return
        if isinstance(t, float) or isinstance(t, Lin):
            self._leaf(t, margin, guard, mhi)
            return
        if isinstance(t, Block):
            if isinstance(margin, float):
                t.emit(self, margin, guard)
            else:
                self.require(t.expand(), margin, guard)
            return
        if self._parents.shared(t):
            z = self._shared.get(id(t))
            if z is None:
                zc = self.add_continuous("z", tlo, thi)
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
        mlo, mhi = self._bounds(margin)
        kids = []
        for k in t.kids:
            klo, khi = self._bounds(k)
            if klo >= mhi:
                return  # a disjunct always holds: no disjunction
            if khi >= mlo:
                kids.append(k)
        if not kids:
            self.fail(guard)
            return
        if len(kids) == 1:
            self.require(kids[0], margin, guard)
            return
        bins = [self._add_binary() for _ in kids]
        idx = bins + ([guard] if guard >= 0 else [])
        val = [1.0] * len(bins) + ([-1.0] if guard >= 0 else [])
        cover = self._row(idx, val, 0.0 if guard >= 0 else 1.0, -1)
        did = len(self._b.disjunctions) + len(self._disj)
        self._disj.append(PendingDisjunction(did, bins, cover, guard, self.label, tuple(kids)))
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
            tlo = self._bounds(t)[0]
            M = mhi - tlo
            if not math.isfinite(M):
                raise EncodeError(MIL502(
                    "a disjunct's expression is unbounded; give every variable finite bounds",
                    NOWHERE, hint="bound the states and inputs (reachable boxes)"))
            idx.append(guard)
            val.append(-M)
            self._row(idx, val, -M - const, guard)
        elif not idx:
            if const < 0:
                self.fail(-1)
        else:
            self._row(idx, val, -const, -1)

    def value(self, t: Tree) -> Tree:
        """A leaf equal to ``t`` exactly (a new ``z`` with two one-sided encodings)."""
        if isinstance(t, (float, Lin)):
            return t
        z = self._exact.get(id(t))
        if z is None:
            lo, hi = self._bounds(t)
            zc = self.add_continuous("zx", lo, hi)
            z = Lin((zc,), (1.0,), 0.0)
            nz = Lin((zc,), (-1.0,), 0.0)
            self._keep.extend([t, z, nz])
            self._exact[id(t)] = z
            self.require(t, z)            # z ≤ t
            self.require(negate(t), nz)   # −t ≥ −z
        return z

    # ------------------------------------------------------------------ output
    def flush(self, name: str) -> np.ndarray:
        """Add every emitted row to the builder as one block named ``name`` and register the
        disjunctions; returns the block's row indices."""
        rows = np.concatenate(self._r) if self._r else np.zeros(0, np.int64)
        cols = np.concatenate(self._c) if self._c else np.zeros(0, np.int64)
        vals = np.concatenate(self._v) if self._v else np.zeros(0)
        assert self._b.n_rows == self._row0, "rows added to the builder while encoding"
        if any(isinstance(v, np.ndarray) for v in self._lo):
            lo = np.concatenate([np.atleast_1d(np.asarray(v, float)) for v in self._lo]) if self._lo else np.zeros(0)
        else:
            lo = np.asarray(self._lo, float)
        out = self._b.add_rows(name, self._n, rows, cols, vals, lo, INF)
        for d in self._disj:
            self._b.add_disjunction(Disjunction(
                id=d.id, binaries=np.asarray(d.binaries, np.int64),
                rows=d.rows if d.rows is not None else
                tuple(np.asarray(self._rows_of_guard.get(bc, []), np.int64) for bc in d.binaries),
                cover_row=d.cover, guard=d.guard, label=d.label, sources=d.sources))
        return out


def _has_block(t: Tree) -> bool:
    """``t`` is a block or a ``min`` with a block child."""
    return isinstance(t, Block) or (isinstance(t, Op) and not t.is_max and any(isinstance(k, Block) for k in t.kids))
