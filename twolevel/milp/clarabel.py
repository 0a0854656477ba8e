"""Clarabel backend: the convex QP of a model with its integer columns fixed (a *mode*).

:class:`FixedModeQP` builds the Clarabel problem once per model pattern; a new mode or new model
values (same pattern) go in through Clarabel's in-place ``update`` (presolve off, structural
zeros kept), so the symbolic factorisation is reused. The pattern never depends on the mode: a
big-M row whose guard binary is 0 becomes ``0·x ≤ 1`` (its coefficients are zeroed, not removed).

Row layout handed to Clarabel (all from the model's continuous columns):
``[equalities (ZeroCone); a·x ≤ hi; −a·x ≤ −lo; x ≤ ub; −x ≤ −lb]`` (NonnegativeCone).
Rows with no continuous entry (e.g. the cover rows ``Σ b ≥ 1``) are checked in numpy instead.
clarabel is imported lazily.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from twolevel.milp.model import MilpModel, build_pattern
from twolevel.milp.solution import Capabilities, Solution, Status

__all__ = ["CAPABILITIES", "FixedModeQP"]

CAPABILITIES = Capabilities("clarabel", integer=False, quadratic=True, in_place_update=True)

_UNSET = object()


def _status(s: object) -> Status:
    name = str(s).split(".")[-1]
    if name in ("Solved", "AlmostSolved"):
        return Status.OPTIMAL
    if name in ("PrimalInfeasible", "AlmostPrimalInfeasible"):
        return Status.INFEASIBLE
    if name in ("DualInfeasible", "AlmostDualInfeasible"):
        return Status.UNBOUNDED
    if name in ("MaxTime", "MaxIterations"):
        return Status.TIME_LIMIT
    return Status.ERROR


def _hessian_parts(P: sp.spmatrix, cont: np.ndarray, ints: np.ndarray) -> tuple[sp.csr_matrix | None, sp.csc_matrix]:
    """The parts of the Hessian ``P`` (upper triangle, or both) a fixed-mode QP needs: the block
    coupling continuous and integer columns of the full symmetric matrix (None without integer
    columns) and the upper triangle of the continuous block."""
    Pf = (P + sp.triu(P, 1).T).tocsr()
    ci = Pf[cont][:, ints] if ints.size else None
    return ci, sp.triu(Pf[cont][:, cont]).tocsc()


@dataclass(frozen=True, eq=False)
class _HessianMoves:
    """Where each stored entry of :func:`_hessian_parts` comes from in ``P.data``, for Hessians
    with the same index arrays (the cost's weighed Hessian of each step has its shape's). Valid
    when such a P stores its upper triangle once per entry (then each part's entry is one of P's,
    moved) and no value is 0 (scipy's sum would drop it)."""

    indices: np.ndarray
    indptr: np.ndarray
    shape: tuple[int, int]
    ci: sp.csr_matrix | None  # the parts' patterns, with their entries' positions in P.data as data
    c: sp.csc_matrix

    @staticmethod
    def of(P: sp.spmatrix, cont: np.ndarray, ints: np.ndarray) -> "_HessianMoves | None":
        """The moves of ``P``'s pattern; None when it is not one the moves hold for."""
        if not isinstance(P, sp.csc_matrix):
            return None
        probe = sp.csc_matrix((np.arange(1.0, P.indices.size + 1.0), P.indices, P.indptr), shape=P.shape)
        cols = np.repeat(np.arange(P.shape[1]), np.diff(P.indptr))
        if not probe.has_canonical_format or np.any(P.indices > cols):  # duplicates, or a lower entry: sums
            return None
        ci, c = _hessian_parts(probe, cont, ints)
        return _HessianMoves(P.indices.copy(), P.indptr.copy(), P.shape, ci, c)

    def parts(self, P: sp.spmatrix) -> tuple[sp.csr_matrix | None, sp.csc_matrix] | None:
        """:func:`_hessian_parts` of ``P``, bit for bit, by moving its values; None when the moves
        do not hold for it (other index arrays, a zero value)."""
        if not isinstance(P, sp.csc_matrix) or P.shape != self.shape or not P.data.all() \
                or not np.array_equal(P.indptr, self.indptr) or not np.array_equal(P.indices, self.indices):
            return None
        ci = None if self.ci is None else sp.csr_matrix(
            (P.data[self.ci.data.astype(np.int64) - 1], self.ci.indices, self.ci.indptr), shape=self.ci.shape)
        c = sp.csc_matrix((P.data[self.c.data.astype(np.int64) - 1], self.c.indices, self.c.indptr), shape=self.c.shape)
        return ci, c


class FixedModeQP:
    """Clarabel QP of ``model`` with its integer columns fixed; reusable across modes."""

    def __init__(self, model: MilpModel, *, tol: float = 1e-8, time_limit: float | None = None) -> None:
        self.model = model
        self.tol = tol
        self.time_limit = time_limit
        self.ints = np.flatnonzero(model.integrality)
        self.cont = np.flatnonzero(~model.integrality)
        n, m = model.n_cols, model.n_rows
        self._pos = np.full(n, -1, np.int64)
        self._pos[self.cont] = np.arange(self.cont.size)
        A = model.A
        cols = np.repeat(np.arange(n), np.diff(A.indptr))
        rows = A.indices.astype(np.int64)
        is_c = self._pos[cols] >= 0
        self._tri_c = np.flatnonzero(is_c)  # A.data positions of continuous entries
        self._tri_i = np.flatnonzero(~is_c)
        rc, cc = rows[is_c], self._pos[cols[is_c]]
        has_c = np.zeros(m, bool)
        has_c[rc] = True
        lo, hi = model.row_lo, model.row_hi
        self._eq = np.flatnonzero(has_c & (lo == hi))
        self._up = np.flatnonzero(has_c & (lo != hi) & np.isfinite(hi))
        self._lo = np.flatnonzero(has_c & (lo != hi) & np.isfinite(lo))
        self._bin_rows = np.flatnonzero(~has_c)
        self._vub = np.flatnonzero(np.isfinite(model.ub[self.cont]))
        self._vlb = np.flatnonzero(np.isfinite(model.lb[self.cont]))
        # where each model row lands in Clarabel's rows (a row may land twice: up and lo)
        blocks = [self._eq, self._up, self._lo]
        out_r, out_c, src, sign = [], [], [], []
        off = 0
        for blk, sgn in zip(blocks, (1.0, 1.0, -1.0)):
            where = np.full(m, -1, np.int64)
            where[blk] = off + np.arange(blk.size)
            sel = where[rc] >= 0
            out_r.append(where[rc][sel]), out_c.append(cc[sel])
            src.append(self._tri_c[sel]), sign.append(np.full(int(sel.sum()), sgn))
            off += blk.size
        nb = off
        out_r.append(nb + np.arange(self._vub.size)), out_c.append(self._vub)
        out_r.append(nb + self._vub.size + np.arange(self._vlb.size)), out_c.append(self._vlb)
        self._n_eq = self._eq.size
        self._n_rows = nb + self._vub.size + self._vlb.size
        self._src = np.concatenate(src)
        self._sign = np.concatenate(sign)
        self._n_model_tri = self._src.size
        r_all = np.concatenate(out_r)
        c_all = np.concatenate(out_c)
        self._pat = build_pattern(r_all, c_all, (self._n_rows, self.cont.size))
        self._bound_vals = np.concatenate([np.ones(self._vub.size), -np.ones(self._vlb.size)])
        self._row_of_tri = np.concatenate(out_r[:3])  # Clarabel row of each model triplet
        self._tri_cols = np.repeat(np.arange(n), np.diff(A.indptr))
        self._src_rows = A.indices[self._src]
        self._P_src: object = _UNSET
        self._Pf_ci: sp.csr_matrix | None = None
        # guard binary of each model row (big-M rows)
        self._guard = np.full(m, -1, np.int64)
        for d in model.disjunctions:
            for bcol, rws in zip(d.binaries, d.rows):
                self._guard[rws] = bcol
        self._solver = None
        self._P_c: sp.csc_matrix | None = None
        self._moves: _HessianMoves | None = None
        self.setup_ms = 0.0

    @property
    def cost_couples_integers(self) -> bool:
        """Whether the Hessian of the last solve couples integer and continuous columns (then the
        continuous optimum depends on the mode, not only on the rows in force)."""
        return self._Pf_ci is not None and bool(np.any(self._Pf_ci.data))

    def disjunctive_rows(self) -> np.ndarray:
        """Bool per model row: every big-M and cover row of every disjunction — pass it as
        ``disable`` (with any ``x_int``) for the lower bound of the mode search
        (:mod:`twolevel.milp.modes`)."""
        mask = np.zeros(self.model.n_rows, bool)
        for d in self.model.disjunctions:
            mask[d.cover_row] = True
            for r in d.rows:
                mask[r] = True
        return mask

    # ------------------------------------------------------------------ data
    def _data(self, x_int: np.ndarray, disable: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        model = self.model
        full = np.zeros(model.n_cols)
        full[self.ints] = x_int
        off_rows = np.zeros(model.n_rows, bool)
        g = self._guard
        guarded = g >= 0
        off_rows[guarded] = full[g[guarded]] < 0.5
        if disable is not None:
            off_rows |= disable
        # shift by the fixed integer part
        A = model.A
        cols = self._tri_cols
        ti = self._tri_i
        shift = np.bincount(A.indices[ti], weights=A.data[ti] * full[cols[ti]], minlength=model.n_rows)
        # rows without continuous entries: check in numpy
        br = self._bin_rows[~off_rows[self._bin_rows]]
        ok = bool(np.all(shift[br] >= model.row_lo[br] - 1e-9) and np.all(shift[br] <= model.row_hi[br] + 1e-9))
        vals = A.data[self._src] * self._sign
        vals = np.where(off_rows[self._src_rows], 0.0, vals)
        data = self._pat.scatter(np.concatenate([vals, self._bound_vals]))
        b = np.concatenate([
            model.row_hi[self._eq] - shift[self._eq],
            np.where(off_rows[self._up], 1.0, model.row_hi[self._up] - shift[self._up]),
            np.where(off_rows[self._lo], 1.0, -(model.row_lo[self._lo] - shift[self._lo])),
            model.ub[self.cont][self._vub],
            -model.lb[self.cont][self._vlb],
        ])
        # cost of the continuous part: q_c + P_ci x_i
        q = model.q[self.cont].copy()
        if model.P is not self._P_src:  # the Hessian's parts, once per Hessian object
            self._P_src = model.P
            if model.P is not None:
                moved = None if self._moves is None else self._moves.parts(model.P)
                if moved is None:  # a new pattern: the sparse algebra, and the moves for the next Hessians
                    moved = _hessian_parts(model.P, self.cont, self.ints)
                    self._moves = _HessianMoves.of(model.P, self.cont, self.ints)
                self._Pf_ci, P_c = moved
                if self._P_c is not None and self._P_c.nnz == P_c.nnz and np.array_equal(
                        self._P_c.indices, P_c.indices) and np.array_equal(self._P_c.indptr, P_c.indptr):
                    self._P_c.data[:] = P_c.data  # same pattern: values only
                else:
                    self._P_c = P_c
            else:
                self._Pf_ci = None
                self._P_c = sp.csc_matrix((self.cont.size, self.cont.size))
        if self._Pf_ci is not None and self._Pf_ci.nnz:
            q += self._Pf_ci @ x_int
        return data, b, q, ok

    def row_duals(self, sol: Solution) -> np.ndarray:
        """The dual value of every model row (0 for rows Clarabel does not see), from a
        :meth:`solve` result: equality duals signed, inequality duals ≥ 0, a row with both
        bounds summed."""
        z = sol.info.get("z")
        out = np.zeros(self.model.n_rows)
        if z is None or np.size(z) == 0:
            return out
        z = np.asarray(z)
        ne, nu = self._eq.size, self._up.size
        out[self._eq] += z[:ne]
        out[self._up] += z[ne:ne + nu]
        out[self._lo] += z[ne + nu:ne + nu + self._lo.size]
        return out

    def solve(self, x_int: np.ndarray | None = None, *, disable: np.ndarray | None = None) -> Solution:
        """Solve with the integer columns at ``x_int`` (in ``model.integrality`` order; rounded).
        ``disable`` (bool per model row) switches further rows off, e.g. every disjunctive row
        for a lower bound."""
        import clarabel  # lazy: heavy

        model = self.model
        x_int = np.zeros(self.ints.size) if x_int is None else np.round(np.asarray(x_int, float))
        t0 = time.perf_counter()
        data, b, q, ok = self._data(x_int, disable)
        if not ok:
            return Solution(Status.INFEASIBLE, None, float("nan"), 0.0,
                            info={"reason": "integer-only rows violated"})
        P = self._P_c
        if self._solver is None:
            A = sp.csc_matrix((data, self._pat.indices, self._pat.indptr), shape=self._pat.shape)
            st = clarabel.DefaultSettings()
            st.verbose = False
            st.presolve_enable = False
            st.input_sparse_dropzeros = False
            st.tol_gap_abs = st.tol_gap_rel = st.tol_feas = self.tol
            if self.time_limit is not None:
                st.time_limit = self.time_limit
            cones = []
            if self._n_eq:
                cones.append(clarabel.ZeroConeT(self._n_eq))
            if self._n_rows - self._n_eq:
                cones.append(clarabel.NonnegativeConeT(self._n_rows - self._n_eq))
            self._solver = clarabel.DefaultSolver(P, q, A, b, cones, st)
        else:
            self._solver.update(P=P.data, q=q, A=data, b=b)
        t1 = time.perf_counter()
        sol = self._solver.solve()
        t2 = time.perf_counter()
        status = _status(sol.status)
        x = None
        obj = float("nan")
        if status is Status.OPTIMAL:
            x = np.zeros(model.n_cols)
            x[self.cont] = np.asarray(sol.x)
            x[self.ints] = x_int
            obj = model.objective(x)
        self.setup_ms = (t1 - t0) * 1e3
        return Solution(status, x, obj, (t2 - t1) * 1e3, self.setup_ms,
                        info={"z": np.asarray(sol.z), "iterations": int(sol.iterations)})
