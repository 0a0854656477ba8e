"""The built-in world predicate ``collision_free(d)`` at the high level, its block, and reachable boxes.

``collision_free(d)`` is ``|x − x_i| + |y − y_i| ≥ d`` for every nearby vehicle i (a 1-norm
diamond around its constant-velocity prediction). Vehicle–step pairs whose least 1-norm distance
from the ego's position box is at least d, and faces that can never hold, are removed exactly by
the compiler's interval pruning, given the ego's position bounds (reachable boxes). Where the
ego's position is one column per coordinate, the pairs of a trace are one
:class:`CollisionBlock` (a :class:`~twolevel.compiler.tree.Block`), emitted by a few array
operations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twolevel.compiler.sink import RowSink
from twolevel.compiler.codes import MIL501, MIL504, EncodeError, span_of
from twolevel.compiler.signals import TraceSignals
from twolevel.compiler.tree import INF, Block, Lin, Op, Tree, add, lin, mk, scale
from twolevel.compiler.types import Builtin, BuiltinContext
from twolevel.stl import ast

__all__ = ["collision_free_builtin", "reachable_box", "CollisionBlock"]


def collision_free_builtin(x: str, y: str, others: np.ndarray, *, ids: np.ndarray | None = None,
                           pad: float = 0.0, keep: np.ndarray | None = None) -> Builtin:
    """``collision_free(d)`` at the high level: ``|x − x_i| + |y − y_i| ≥ d`` for every other
    vehicle i — robustness ``min_i max_faces(σ₁(x − x_i) + σ₂(y − y_i)) − d``.

    ``others`` has shape (N, T, 2): each vehicle's predicted position per trace step [m] (NaN
    where absent). Pairs that cannot come within reach and faces that can never hold are
    removed by the compiler's interval pruning, exactly, given the ego's position bounds.

    Stable encoding (the compiler's ``stable`` mode): each kept pair is a disjunction of all four
    faces (faces that can never hold have their binary's upper bound set to 0), and the kept
    pairs are those that can come within ``d + pad`` [m] (``pad`` ≥ 0: a margin so that the same
    structure serves the next steps), or, when ``keep`` is given, the pairs whose code is in
    ``keep`` plus every pair that can come within d. A pair's code is ``step·2³² + ids[i]`` (``ids``: a stable
    identity per vehicle, default its row); pairs are emitted in code order."""
    others = np.asarray(others, dtype=float)
    vid = np.arange(others.shape[0], dtype=np.int64) if ids is None else np.asarray(ids, np.int64)
    opts = (float(pad), None if keep is None else np.asarray(keep, np.int64))
    faces = ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0))
    tables: dict[int, tuple[BuiltinContext, _PairTable]] = {}  # one pair table per evaluation

    def fn(ctx: BuiltinContext, args: tuple[ast.Term, ...], t: int, s: float, node: ast.Call) -> Tree:
        if len(args) != 1:
            raise EncodeError(MIL504("collision_free takes one argument (the distance d [m])",
                                     span_of(node)))
        d = ctx.term(args[0], t)
        if not isinstance(d, float):
            raise EncodeError(MIL501("collision_free(d): d must be known at solve time", span_of(node)))
        tb = tables.get(id(ctx))
        if s > 0 and tb is not None and tb[0] is ctx and tb[1].ok_t[t]:  # fast: the pair table knows step t
            idx = np.arange(tb[1].start[t], tb[1].start[t + 1])
            return CollisionBlock(tb[1], idx, np.full(idx.size, d)) if idx.size else INF
        o = others[:, t]
        ok = np.isfinite(o).all(axis=1)
        if not ok.any():
            return s * INF
        ex, ey = ctx.signals.at(x, t), ctx.signals.at(y, t)
        if isinstance(ex, float) and isinstance(ey, float):
            return s * (float(np.min(np.abs(ex - o[ok, 0]) + np.abs(ey - o[ok, 1]))) - d)
        if s > 0 and isinstance(ex, Lin) and isinstance(ey, Lin) and len(ex.idx) == 1 and len(ey.idx) == 1:
            tb = tables.get(id(ctx))
            if tb is None or tb[0] is not ctx:
                tb = (ctx, _PairTable.of(ctx.signals, x, y, others, vid, opts))
                tables.clear()
                tables[id(ctx)] = tb
            idx = tb[1].at(t)
            if idx is not None:
                return CollisionBlock(tb[1], idx, np.full(idx.size, d))
        pairs: list[Tree] = []
        for i in range(others.shape[0]):
            ox, oy = others[i, t]
            if not (math.isfinite(ox) and math.isfinite(oy)):
                continue
            dx, dy = add(ex, -ox), add(ey, -oy)
            pair = mk(True, [add(add(scale(dx, a), scale(dy, b)), -d) for a, b in faces])
            if isinstance(pair, Op) and s > 0:
                # exact: the least 1-norm distance from the ego's box to the vehicle, minus d
                (xlo, xhi), (ylo, yhi) = ctx.bounds(dx), ctx.bounds(dy)
                pair.lo_hint = max(xlo, -xhi, 0.0) + max(ylo, -yhi, 0.0) - d
            pairs.append(pair)
        return scale(mk(False, pairs), s) if pairs else s * INF

    return fn


def reachable_box(p0: float, v_lo: float, v_hi: float, dt: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of a coordinate over ``steps`` samples when its rate stays in [v_lo, v_hi] [m/s]:
    ``p0 + k·dt·v_lo ≤ p_k ≤ p0 + k·dt·v_hi`` for k = 1..steps [m]."""
    k = np.arange(1, steps + 1) * dt
    return p0 + k * v_lo, p0 + k * v_hi


_FA = np.array([1.0, 1.0, -1.0, -1.0])  # face signs on dx
_FB = np.array([1.0, -1.0, 1.0, -1.0])  # face signs on dy


class _PairTable:
    """Every vehicle–step pair of a trace whose ego position is one column per coordinate, in
    arrays sorted by step: ego ``xa·x[xc]``, offset ``xo`` = ego offset − vehicle position (same
    for y); ``step``, ``veh``; ``start[t]:start[t+1]`` are the pairs of step t."""

    __slots__ = ("xc", "xa", "xo", "yc", "ya", "yo", "step", "veh", "start", "ok_t", "code", "opts")

    @classmethod
    def of(cls, signals: TraceSignals, x: str, y: str, others: np.ndarray, ids: np.ndarray | None = None,
           opts: tuple = (0.0, None)) -> "_PairTable":
        tb = cls()
        tb.opts = opts
        sx, sy = signals.get(x), signals.get(y)
        T = signals.length
        if not (hasattr(sx, "coef") and hasattr(sy, "coef")):
            tb.ok_t = np.zeros(T, bool)
            tb.start = np.zeros(T + 1, np.int64)
            return tb
        cx, cy = sx.coef, sy.coef  # type: ignore[union-attr]
        nx, ny = np.diff(cx.indptr), np.diff(cy.indptr)
        tb.ok_t = (nx == 1) & (ny == 1)
        fin = np.isfinite(others).all(axis=2)[:, :T] & tb.ok_t[None, :]  # (N, T)
        t_idx, v_idx = np.nonzero(fin.T)
        px, py = cx.indptr[t_idx], cy.indptr[t_idx]
        tb.xc, tb.xa = cx.indices[px].astype(np.int64), cx.data[px].astype(float)
        tb.yc, tb.ya = cy.indices[py].astype(np.int64), cy.data[py].astype(float)
        tb.xo = sx.offset[t_idx] - others[v_idx, t_idx, 0]  # type: ignore[union-attr]
        tb.yo = sy.offset[t_idx] - others[v_idx, t_idx, 1]  # type: ignore[union-attr]
        tb.step, tb.veh = t_idx, v_idx
        tb.code = t_idx.astype(np.int64) * (1 << 32) + (v_idx if ids is None else ids[v_idx])
        tb.start = np.searchsorted(t_idx, np.arange(T + 1))
        return tb

    def at(self, t: int) -> np.ndarray | None:
        if not self.ok_t[t]:
            return None
        return np.arange(self.start[t], self.start[t + 1])


class CollisionBlock(Block):
    """``min`` over vehicle–step pairs (rows ``idx`` of a :class:`_PairTable`) of the 1-norm
    diamond robustness: dx = xa·x[xc] + xo, dy = ya·x[yc] + yo (ego minus vehicle), value
    |dx| + |dy| − d. Several blocks under one ``min`` merge into one, so a whole
    ``always[..] collision_free(d)`` is emitted by one vectorised call: pairs that always hold are
    dropped, faces that can never hold are dropped, one face left gives a plain row, two or more a
    disjunction (one binary per face, big-M from the bounds)."""

    __slots__ = ("tb", "idx", "d", "_cache")
    kind = "collision"

    def __init__(self, tb: _PairTable, idx: np.ndarray, d: np.ndarray) -> None:
        self.tb, self.idx, self.d = tb, idx, d
        self._cache: tuple | None = None

    def arrays(self) -> tuple[np.ndarray, ...]:
        """Per pair: ego x column, x coefficient, x offset, the same for y, step, vehicle row."""
        if self._cache is None:
            tb, i = self.tb, self.idx
            self._cache = (tb.xc[i], tb.xa[i], tb.xo[i], tb.yc[i], tb.ya[i], tb.yo[i], tb.step[i], tb.veh[i])
        return self._cache

    @classmethod
    def merge(cls, blocks: list["Block"]) -> "CollisionBlock":
        tbs = {id(b.tb) for b in blocks}  # type: ignore[attr-defined]
        if len(tbs) != 1:
            return _merge_tables(blocks)
        return cls(blocks[0].tb, np.concatenate([b.idx for b in blocks]),  # type: ignore[attr-defined]
                   np.concatenate([b.d for b in blocks]))  # type: ignore[attr-defined]

    def _ranges(self, lb: np.ndarray, ub: np.ndarray) -> tuple[np.ndarray, ...]:
        xc, xa, xo, yc, ya, yo, _, _ = self.arrays()
        a1, a2 = xa * lb[xc], xa * ub[xc]
        b1, b2 = ya * lb[yc], ya * ub[yc]
        return (np.minimum(a1, a2) + xo, np.maximum(a1, a2) + xo,
                np.minimum(b1, b2) + yo, np.maximum(b1, b2) + yo)

    def bounds(self, lb: np.ndarray, ub: np.ndarray) -> tuple[float, float]:
        xlo, xhi, ylo, yhi = self._ranges(lb, ub)
        lo = np.maximum(np.maximum(xlo, -xhi), 0.0) + np.maximum(np.maximum(ylo, -yhi), 0.0)
        hi = np.maximum(np.abs(xlo), np.abs(xhi)) + np.maximum(np.abs(ylo), np.abs(yhi))
        return float(np.min(lo - self.d)), float(np.min(hi - self.d))

    def expand(self) -> Tree:
        xc, xa, xo, yc, ya, yo, _, _ = self.arrays()
        pairs: list[Tree] = []
        for i in range(xc.size):
            dx = lin((int(xc[i]),), (float(xa[i]),), float(xo[i]))
            dy = lin((int(yc[i]),), (float(ya[i]),), float(yo[i]))
            pairs.append(mk(True, [add(add(scale(dx, a), scale(dy, b)), -float(self.d[i]))
                                   for a, b in zip(_FA, _FB)]))
        return mk(False, pairs)

    def stable_layout(self, lb: np.ndarray, ub: np.ndarray, margin: float, keep: np.ndarray | None = None
                      ) -> "StableLayout | None":
        """The stable encoding of ``self ≥ margin`` at top level (see :func:`collision_free_builtin`);
        ``keep``: the codes to emit (besides every pair that can come within d); default the
        table's own. None when a pair can never be kept clear (no face can hold) or when the
        block has no unique pair codes (then the plain emission applies)."""
        code = getattr(self.tb, "code", None)
        if code is None:
            return None
        codes = code[self.idx]
        if np.unique(codes).size != codes.size:
            return None
        pad, keep0 = self.tb.opts
        keep = keep0 if keep is None else keep
        xc, xa, xo, yc, ya, yo, _, _ = self.arrays()
        xlo, xhi, ylo, yhi = self._ranges(lb, ub)
        d = self.d[:, None]
        f_hi = np.where(_FA > 0, xhi[:, None], -xlo[:, None]) + np.where(_FB > 0, yhi[:, None], -ylo[:, None]) - d
        f_lo = np.where(_FA > 0, xlo[:, None], -xhi[:, None]) + np.where(_FB > 0, ylo[:, None], -yhi[:, None]) - d
        pair_lo = (np.maximum(np.maximum(xlo, -xhi), 0.0) + np.maximum(np.maximum(ylo, -yhi), 0.0) - self.d)
        live = pair_lo < margin
        possible = f_hi >= margin
        if np.any(live & ~possible.any(axis=1)):
            return StableLayout(None, 0, 0, (), np.zeros(0), np.zeros(0), np.zeros(0), failed=True)
        padded = pair_lo < margin + pad
        sel = live | (padded if keep is None else np.isin(codes, keep))
        p = np.flatnonzero(sel)
        p = p[np.argsort(codes[p], kind="stable")]
        M = np.maximum(margin - f_lo[p], 0.0)
        cst = _FA[None] * xo[p, None] + _FB[None] * yo[p, None] - d[p] - margin
        n = p.size
        cols = (np.repeat(xc[p], 4), np.repeat(yc[p], 4))
        vals = np.stack([(_FA[None] * xa[p, None]).ravel(), (_FB[None] * ya[p, None]).ravel(), -M.ravel()], 1)
        lo = np.concatenate([(-cst - M).ravel(), np.ones(n)])
        tvals = np.concatenate([vals.ravel(), np.ones(4 * n)])
        return StableLayout(codes[p], n, int(padded.sum()), cols, tvals, lo, possible[p].ravel().astype(float))

    def emit(self, sink: RowSink, margin: float, guard: int) -> None:
        """Rows for ``self ≥ margin`` (whenever ``x[guard] = 1``), vectorised."""
        if sink.stable and guard < 0:
            lay = self.stable_layout(sink.lb, sink.ub, margin)
            if lay is not None and lay.failed:
                sink.fail(guard)
                return
            if lay is not None:
                self._emit_stable(sink, lay)
                return
        xc, xa, xo, yc, ya, yo, step, veh = self.arrays()
        xlo, xhi, ylo, yhi = self._ranges(sink.lb, sink.ub)
        d = self.d[:, None]
        # face f: a·dx + b·dy − d; its bounds over the box
        f_hi = np.where(_FA > 0, xhi[:, None], -xlo[:, None]) + np.where(_FB > 0, yhi[:, None], -ylo[:, None]) - d
        f_lo = np.where(_FA > 0, xlo[:, None], -xhi[:, None]) + np.where(_FB > 0, ylo[:, None], -yhi[:, None]) - d
        pair_lo = (np.maximum(np.maximum(xlo, -xhi), 0.0) + np.maximum(np.maximum(ylo, -yhi), 0.0) - self.d)
        live = pair_lo < margin
        keep = (f_hi >= margin) & live[:, None]
        nk = keep.sum(axis=1)
        if np.any(live & (nk == 0)):
            sink.fail(guard)
        # constant part of each face: a·xo + b·yo − d − margin moves to the right-hand side
        cst = _FA[None] * xo[:, None] + _FB[None] * yo[:, None] - d - margin
        ca = _FA[None] * xa[:, None]
        cb = _FB[None] * ya[:, None]
        single = live & (nk == 1)
        multi = live & (nk >= 2)
        pi, fi = np.nonzero(keep & single[:, None])  # plain rows (one face left)
        n1 = pi.size
        if n1:
            if guard >= 0:
                M = margin - f_lo[pi, fi]
                cols = np.stack([xc[pi], yc[pi], np.full(n1, guard)], 1)
                vals = np.stack([ca[pi, fi], cb[pi, fi], -M], 1)
                lo = -cst[pi, fi] - M
            else:
                cols = np.stack([xc[pi], yc[pi]], 1)
                vals = np.stack([ca[pi, fi], cb[pi, fi]], 1)
                lo = -cst[pi, fi]
            sink.emit_rows(cols, vals, lo, guard)
        mp = np.flatnonzero(multi)  # disjunctions (two or more faces): one binary per kept face
        if mp.size:
            pi, fi = np.nonzero(keep[mp])
            pi = mp[pi]
            nb = pi.size
            bcols = sink.add_binaries("cf", nb)
            M = margin - f_lo[pi, fi]
            rows = sink.emit_rows(np.stack([xc[pi], yc[pi], bcols], 1),
                                  np.stack([ca[pi, fi], cb[pi, fi], -M], 1), -cst[pi, fi] - M)
            starts = np.concatenate([[0], np.cumsum(nk[mp])])
            owner = np.repeat(np.arange(mp.size), nk[mp])
            covers = sink.emit_covers(owner, bcols, mp.size, extra_col=guard, lo=0.0 if guard >= 0 else 1.0)
            # one disjunction per pair: its binaries, each enabling one face row (rows[i])
            sink.add_disjunctions(bcols, rows, covers, starts, guard)

    def _emit_stable(self, sink: RowSink, lay: "StableLayout") -> None:
        n, nb = lay.n, 4 * lay.n  # n = 0 still records an (empty) emission: the structure
        bcols = sink.add_binaries("cf", nb)
        sink.tighten(bcols, 0.0, lay.bin_ub)
        since = sink.mark()
        v = lay.tvals[: 3 * nb].reshape(nb, 3)
        rows = sink.emit_rows(np.stack([lay.cols[0], lay.cols[1], bcols], 1), v, lay.lo[:nb])
        covers = sink.emit_covers(np.repeat(np.arange(n), 4), bcols, n, lo=1.0)
        sink.add_disjunctions(bcols, rows, covers, np.arange(0, nb + 1, 4), -1)
        sink.record(self.kind, since, bcols, (lay.codes,))


@dataclass(frozen=True, slots=True)
class StableLayout:
    """The values of a stable collision emission: pair ``codes`` (n,), the ego columns of each
    face row (x, y), every triplet value in emission order (face rows x, y, binary; then the
    cover rows' ones), every row's lower bound (face rows, then covers), each binary's upper
    bound; ``n_padded``: how many pairs can come within d + pad now; ``failed``: a pair can never
    be kept clear (no face can hold)."""

    codes: np.ndarray | None
    n: int
    n_padded: int
    cols: tuple[np.ndarray, ...]
    tvals: np.ndarray
    lo: np.ndarray
    bin_ub: np.ndarray
    failed: bool = False


def _merge_tables(blocks: list[Block]) -> CollisionBlock:
    """Blocks from different tables (two collision_free calls): one table of their pairs."""
    tb = _PairTable()
    parts = [b.arrays() for b in blocks]  # type: ignore[attr-defined]
    for k, name in enumerate(("xc", "xa", "xo", "yc", "ya", "yo", "step", "veh")):
        setattr(tb, name, np.concatenate([p[k] for p in parts]))
    tb.ok_t = np.zeros(0, bool)
    tb.start = np.zeros(1, np.int64)
    d = np.concatenate([b.d for b in blocks])  # type: ignore[attr-defined]
    return CollisionBlock(tb, np.arange(d.size), d)
