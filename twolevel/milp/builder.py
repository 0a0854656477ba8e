"""Assembling a :class:`~twolevel.milp.model.MilpModel` from whole arrays.

Variables and constraints are added in named blocks of arrays (COO triplets with block-local row
numbers); :meth:`ModelBuilder.build` concatenates every block once and makes the CSC matrix,
with its pattern taken from a :class:`~twolevel.milp.model.PatternCache` when the same shape was
built before. Nothing is ever added row by row to a solver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from twolevel.milp.model import Disjunction, MilpModel, PatternCache, Residuals, csc_from_coo

__all__ = ["ModelBuilder", "VarBlock"]

INF = np.inf


@dataclass(frozen=True)
class VarBlock:
    """A contiguous range of columns."""

    name: str
    start: int
    stop: int

    @property
    def idx(self) -> np.ndarray:
        return np.arange(self.start, self.stop)

    def __len__(self) -> int:
        return self.stop - self.start


class ModelBuilder:
    """Collects variable and constraint blocks; :meth:`build` assembles the model once."""

    def __init__(self) -> None:
        self._lb: list[np.ndarray] = []
        self._ub: list[np.ndarray] = []
        self._int: list[np.ndarray] = []
        self._col_names: list[str] = []
        self.n_cols = 0
        self.n_rows = 0
        self._rows: list[np.ndarray] = []
        self._cols: list[np.ndarray] = []
        self._vals: list[np.ndarray] = []
        self._rlo: list[np.ndarray] = []
        self._rhi: list[np.ndarray] = []
        self._row_blocks: dict[str, tuple[slice, slice]] = {}
        self._col_blocks: dict[str, slice] = {}
        self._n_trip = 0
        self._q: dict[int, float] = {}
        self._q_arrays: list[tuple[np.ndarray, np.ndarray]] = []
        self._res: list[tuple[sp.csr_matrix, np.ndarray, np.ndarray]] = []
        self.c0 = 0.0
        self.disjunctions: list[Disjunction] = []
        # fast access to current bounds (for big-M by interval arithmetic while encoding)
        self._cap = 0
        self._lb_buf: np.ndarray = np.zeros(0)
        self._ub_buf: np.ndarray = np.zeros(0)

    # ------------------------------------------------------------------ variables
    def add_vars(
        self, name: str, n: int, lb: np.ndarray | float = -INF, ub: np.ndarray | float = INF,
        integer: bool = False,
    ) -> VarBlock:
        """Add ``n`` columns named ``name[i]``; bounds broadcast."""
        if name in self._col_blocks:
            name = f"{name}#{len(self._col_blocks)}"
        lo = np.broadcast_to(np.asarray(lb, dtype=float), (n,)).copy()
        hi = np.broadcast_to(np.asarray(ub, dtype=float), (n,)).copy()
        self._lb.append(lo)
        self._ub.append(hi)
        self._int.append(np.full(n, integer))
        blk = VarBlock(name, self.n_cols, self.n_cols + n)
        self._col_blocks[name] = slice(blk.start, blk.stop)
        self._col_names.extend(f"{name}[{i}]" for i in range(n))
        self.n_cols += n
        if self.n_cols > self._cap:
            self._cap = max(2 * self._cap, self.n_cols, 64)
            for attr in ("_lb_buf", "_ub_buf"):
                old = getattr(self, attr)
                new = np.empty(self._cap)
                new[: old.size] = old
                setattr(self, attr, new)
        self._lb_buf[blk.start : blk.stop] = lo
        self._ub_buf[blk.start : blk.stop] = hi
        return blk

    @property
    def lb(self) -> np.ndarray:
        """Current lower bounds of every column (a view; write through :meth:`tighten`)."""
        return self._lb_buf[: self.n_cols]

    @property
    def ub(self) -> np.ndarray:
        return self._ub_buf[: self.n_cols]

    def tighten(self, cols: np.ndarray, lb: np.ndarray | float, ub: np.ndarray | float) -> None:
        """Intersect the bounds of ``cols`` with [lb, ub] (e.g. reachable boxes)."""
        cols = np.asarray(cols)
        self._lb_buf[cols] = np.maximum(self._lb_buf[cols], lb)
        self._ub_buf[cols] = np.minimum(self._ub_buf[cols], ub)

    # ------------------------------------------------------------------ constraints
    def add_rows(
        self, name: str, n_rows: int, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray,
        lo: np.ndarray | float, hi: np.ndarray | float,
    ) -> np.ndarray:
        """Add ``n_rows`` rows ``lo ≤ A_blk x ≤ hi``; ``rows`` are block-local (0..n_rows-1).
        Returns the global row indices. Zero values are kept as structural entries."""
        if name in self._row_blocks:
            name = f"{name}#{len(self._row_blocks)}"
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.asarray(cols, dtype=np.int64)
        vals = np.asarray(vals, dtype=float)
        if rows.size and (rows.min() < 0 or rows.max() >= n_rows):
            raise ValueError(f"block {name}: row index out of range")
        if cols.size and (cols.min() < 0 or cols.max() >= self.n_cols):
            raise ValueError(f"block {name}: column index out of range")
        self._rows.append(rows + self.n_rows)
        self._cols.append(cols)
        self._vals.append(vals)
        self._rlo.append(np.broadcast_to(np.asarray(lo, dtype=float), (n_rows,)).copy())
        self._rhi.append(np.broadcast_to(np.asarray(hi, dtype=float), (n_rows,)).copy())
        self._row_blocks[name] = (
            slice(self._n_trip, self._n_trip + rows.size), slice(self.n_rows, self.n_rows + n_rows)
        )
        self._n_trip += rows.size
        out = np.arange(self.n_rows, self.n_rows + n_rows)
        self.n_rows += n_rows
        return out

    def add_disjunction(self, d: Disjunction) -> None:
        self.disjunctions.append(d)

    # ------------------------------------------------------------------ costs
    def add_linear_cost(self, cols: np.ndarray, vals: np.ndarray | float) -> None:
        cols = np.asarray(cols, dtype=np.int64)
        self._q_arrays.append((cols, np.broadcast_to(np.asarray(vals, float), cols.shape).copy()))

    def add_residuals(self, F: sp.spmatrix, g: np.ndarray, w: np.ndarray | float) -> None:
        """Add ``Σ_i w_i (F_i x − g_i)²`` (F has ``n_cols`` columns at build time or fewer)."""
        F = sp.csr_matrix(F)
        g = np.asarray(g, dtype=float)
        self._res.append((F, g, np.broadcast_to(np.asarray(w, float), g.shape).copy()))

    # ------------------------------------------------------------------ assembly
    def build(self, cache: PatternCache | None = None) -> MilpModel:
        """Concatenate every block once and assemble the model."""
        n = self.n_cols
        rows = np.concatenate(self._rows) if self._rows else np.zeros(0, np.int64)
        cols = np.concatenate(self._cols) if self._cols else np.zeros(0, np.int64)
        vals = np.concatenate(self._vals) if self._vals else np.zeros(0)
        A, pat = csc_from_coo(rows, cols, vals, (self.n_rows, n), cache)
        q = np.zeros(n)
        for c, v in self._q_arrays:
            np.add.at(q, c, v)
        residuals = None
        P = None
        pr: list[np.ndarray] = []
        pc: list[np.ndarray] = []
        pv: list[np.ndarray] = []
        c0 = self.c0
        if self._res:
            F = sp.vstack([sp.csr_matrix((f.data, f.indices, f.indptr), shape=(f.shape[0], n))
                           for f, _, _ in self._res]).tocsr()
            g = np.concatenate([r[1] for r in self._res])
            w = np.concatenate([r[2] for r in self._res])
            residuals = Residuals(F, g, w)
            H = (F.T @ sp.diags(2.0 * w) @ F).tocoo()
            pr.append(H.row), pc.append(H.col), pv.append(H.data)
            q += -2.0 * (F.T @ (w * g))
            c0 += float(w @ (g * g))
        if pr:
            r, c, v = np.concatenate(pr), np.concatenate(pc), np.concatenate(pv)
            up = r <= c
            P = sp.csc_matrix((v[up], (r[up], c[up])), shape=(n, n))
            P.sum_duplicates()
        rlo = np.concatenate(self._rlo) if self._rlo else np.zeros(0)
        rhi = np.concatenate(self._rhi) if self._rhi else np.zeros(0)
        row_names: list[str] = []
        for name, (_, rs) in self._row_blocks.items():
            row_names.extend(f"{name}[{i}]" for i in range(rs.stop - rs.start))
        return MilpModel(
            A=A, row_lo=rlo, row_hi=rhi, lb=self.lb.copy(), ub=self.ub.copy(),
            integrality=np.concatenate(self._int) if self._int else np.zeros(0, bool),
            q=q, P=P, c0=c0, residuals=residuals, col_names=tuple(self._col_names),
            row_names=tuple(row_names), disjunctions=tuple(self.disjunctions), pattern=pat,
            row_blocks=dict(self._row_blocks), col_blocks=dict(self._col_blocks),
            triplet_values=vals.copy(),
        )
