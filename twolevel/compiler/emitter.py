"""Robustness trees → rows of the model: min as rows, max as disjunctions with big-M from bounds.

The emission half of :class:`twolevel.compiler.encoder.Encoder` (a mixin over its state): new
variables, guarded rows, vectorised blocks, disjunctions, requiring a tree above a margin, and
the final flush of every emitted row into the builder's ``stl`` block.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from twolevel.compiler.types import MIL502, AffineSignal, EncodeError, Signal, _NOWHERE, _has_block
from twolevel.milp.model import Disjunction
from twolevel.compiler.tree import INF, Block, Lin, Op, Tree, bounds, negate

__all__ = ["RowEmitter"]


class RowEmitter:
    """Mixin: requires trees in the builder (state lives in the encoder)."""

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
