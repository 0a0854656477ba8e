"""Real-time disjunctive mode search over one fixed-pattern Clarabel QP (design.md, steps a–d).

Every binary of a :class:`~twolevel.milp.model.MilpModel` belongs to one
:class:`~twolevel.milp.model.Disjunction`. A *mode* picks one disjunct per disjunction: an int
array ``choice`` (D,), ``-1`` meaning undecided (its cover row disabled, its big-M rows off). With
the mode fixed the problem is the convex QP of :class:`~twolevel.milp.clarabel.FixedModeQP`; switching
mode rewrites values only, on the same solver object.

:meth:`ModeSearch.run`:

a. lower bound: the QP with every disjunction undecided;
b. the mode read off its trajectory (per disjunction the disjunct whose rows hold best: the
   slack of a big-M row with its binary at 1 is the predicate's margin; when the lower bound's
   point already satisfies that mode, it is the mode's optimum and no QP is solved); stop with
   a certificate when the cost is within ``gap`` (0.5 %) of the bound;
c. seeds given by the caller (choices, or trajectories to read modes off) and a descent that
   re-reads the mode off the incumbent's own trajectory;
d. best-first branch-and-bound over disjunctions within the remaining budget (node = partial
   mode, bound = its QP cost, branch on the most violated undecided disjunction); exact within
   ``bnb_gap`` when run to completion (``budget_ms=None``);
e. with whatever budget the branch-and-bound leaves (``bnb=False``, or a budget it did not use):
   late seeds, then per-disjunction flips ordered by the dual values of the chosen disjuncts' rows, then one more
   descent. (Measured on the closed-loop benchmark: run before the branch-and-bound under a QP
   cap, the flips spent the cap without finding the optimum the branch-and-bound then missed.)
"""

from __future__ import annotations

import heapq
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from twolevel.milp.clarabel import FixedModeQP
from twolevel.milp.solution import Status

__all__ = ["ModeResult", "ModeSearch"]

_FEAS = 1e-6  # [row units] a disjunct holds when its rows' slack is at least −_FEAS


@dataclass(frozen=True)
class ModeResult:
    """Outcome of a mode search. ``status``: ``optimal`` (certified within the gap or B&B
    finished), ``feasible`` (a mode found, not certified in time), ``infeasible`` (no mode can
    be feasible: proven), ``time_limit`` (no feasible mode found in time). ``mode``: choice per
    disjunction (−1 inactive); ``bound``: the best proven lower bound; ``gap`` = (cost − bound) /
    max(|cost|, 1e-9); ``timings_ms``: phase → ms (lower_bound, readoff, seeds, flips, descent, bnb)."""

    status: str
    cost: float
    x: np.ndarray | None
    mode: np.ndarray
    x_int: np.ndarray
    qps: int
    certified: bool
    gap: float
    bound: float
    nodes: int = 0
    timings_ms: dict[str, float] = field(default_factory=dict)


class ModeSearch:
    """Mode search and branch-and-bound over the disjunctions of ``qp.model``."""

    def __init__(self, qp: FixedModeQP) -> None:
        self.qp = qp
        m = qp.model
        ds = m.disjunctions
        self.D = len(ds)
        pos_of = np.full(m.n_cols, -1, np.int64)
        pos_of[qp.ints] = np.arange(qp.ints.size)
        sizes = np.array([d.size for d in ds], np.int64)
        self.size = sizes
        self.gstart = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        G = int(self.gstart[-1])
        self.bin_col = np.concatenate([d.binaries for d in ds]).astype(np.int64) if G else np.zeros(0, np.int64)
        self.bin_pos = pos_of[self.bin_col]
        self.owner = np.repeat(np.arange(self.D), sizes)
        self.cover = np.array([d.cover_row for d in ds], np.int64)
        g_of_col = np.full(m.n_cols, -1, np.int64)
        g_of_col[self.bin_col] = np.arange(G)
        guards = np.array([d.guard for d in ds], np.int64)
        self.parent = np.where(guards >= 0, g_of_col[np.maximum(guards, 0)], -1)
        self.nested = np.flatnonzero(self.parent >= 0)
        self.top = np.flatnonzero(self.parent < 0)
        # rows of each disjunct, flattened; the A.data position of each row's guard entry
        rows = [r for d in ds for r in d.rows]
        self.row_cnt = np.array([r.size for r in rows], np.int64)
        self.row_flat = np.concatenate(rows).astype(np.int64) if rows else np.zeros(0, np.int64)
        self.row_g = np.repeat(np.arange(G), self.row_cnt)
        A = m.A
        # CSC entries sorted by (column, row): one search over column·m + row keys
        keys = np.repeat(np.arange(A.shape[1], dtype=np.int64), np.diff(A.indptr)) * A.shape[0] + A.indices
        self.guard_pos = np.searchsorted(keys, self.bin_col[self.row_g] * A.shape[0] + self.row_flat)
        self.cont_mask = ~m.integrality
        self._memo: dict[bytes, tuple[float, np.ndarray | None, np.ndarray | None]] = {}
        self.qps = 0

    # ------------------------------------------------------------------ modes
    def allowed(self) -> np.ndarray:
        """Bool per global disjunct: its binary may be 1 (upper bound ≥ 1)."""
        return self.qp.model.ub[self.bin_col] >= 0.5

    def _active(self, choice: np.ndarray) -> np.ndarray:
        act = self.parent < 0
        for d in self.nested:  # parents were created first
            p = self.parent[d]
            od = self.owner[p]
            act[d] = act[od] and choice[od] >= 0 and self.gstart[od] + choice[od] == p
        return act

    def to_int(self, choice: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x_int (in ``qp.ints`` order) and the rows to disable for a (partial) mode."""
        m = self.qp.model
        x_int = np.zeros(self.qp.ints.size)
        act = self._active(choice) if self.nested.size else np.ones(self.D, bool)
        dec = act & (choice >= 0)
        x_int[self.bin_pos[self.gstart[:-1][dec] + choice[dec]]] = 1.0
        disable = np.zeros(m.n_rows, bool)
        disable[self.cover[act & (choice < 0)]] = True
        return x_int, disable

    def values(self, x: np.ndarray) -> np.ndarray:
        """Per global disjunct: how well it holds on ``x`` (min slack of its rows with its binary at
        1; nested disjunctions count through their best disjunct; +inf without rows)."""
        m = self.qp.model
        G = int(self.gstart[-1])
        if G == 0:
            return np.zeros(0)
        xc = np.where(self.cont_mask, x, 0.0)
        ax = m.A @ xc
        r = self.row_flat
        slack = ax[r] + m.A.data[self.guard_pos] - m.row_lo[r]
        val = np.full(G, np.inf)
        np.minimum.at(val, self.row_g, slack)
        for d in self.nested[::-1]:
            s, e = self.gstart[d], self.gstart[d + 1]
            best = np.max(val[s:e])
            p = self.parent[d]
            val[p] = min(val[p], best)
        return val

    def read_off(self, x: np.ndarray, allowed: np.ndarray | None = None) -> np.ndarray:
        """The mode whose disjuncts hold best on ``x`` (one choice per disjunction)."""
        if self.D == 0:
            return np.zeros(0, np.int64)
        val = self.values(x)
        allowed = self.allowed() if allowed is None else allowed
        val = np.where(allowed, val, -np.inf)
        # argmax within each disjunction's segment
        order = np.lexsort((-val, self.owner))
        first = order[self.gstart[:-1]]
        return (first - self.gstart[:-1]).astype(np.int64)

    # ------------------------------------------------------------------ QPs
    def solve_mode(self, choice: np.ndarray) -> tuple[float, np.ndarray | None, np.ndarray | None]:
        """(cost, x, duals per model row) of a (partial) mode; cost +inf when infeasible."""
        key = choice.tobytes()
        hit = self._memo.get(key)
        if hit is not None:
            return hit
        x_int, disable = self.to_int(choice)
        sol = self.qp.solve(x_int, disable=disable)
        self.qps += 1
        if sol.status is Status.OPTIMAL and sol.x is not None:
            out = (float(sol.objective), sol.x, self.qp.row_duals(sol))
        else:
            out = (np.inf, None, None)
        self._memo[key] = out
        return out

    def _adopt(self, choice: np.ndarray, x: np.ndarray, duals: np.ndarray | None, tol: float = _FEAS) -> bool:
        """When ``x``, the optimum of a relaxation of ``choice``'s QP (fewer rows enforced),
        already satisfies that QP's rows and bounds (within ``tol``) with ``choice``'s binaries
        set, it is that QP's optimum too: memoise it instead of solving (saves the read-off QP
        whenever the lower bound's plan meets every rule). Not when the cost couples binaries
        and continuous columns (the continuous optimum would depend on the mode)."""
        ci = self.qp._Pf_ci
        if ci is not None and np.any(ci.data):
            return False
        x_int, _ = self.to_int(choice)
        xf = x.copy()
        xf[self.qp.ints] = x_int
        if self.qp.model.violation(xf) > tol:
            return False
        self._memo[choice.tobytes()] = (float(self.qp.model.objective(xf)), xf, duals)
        return True

    # ------------------------------------------------------------------ search
    def run(
        self, *, seeds: Sequence[np.ndarray] = (), seed_points: Sequence[np.ndarray] = (),
        budget_ms: float | None = 50.0, gap: float = 0.005, bnb_gap: float = 1e-4, abs_tol: float = 1e-6,
        max_flips: int = 6, bnb: bool = True, search_ms: float | None = None, max_flip_qps: int | None = None,
        search_qps: int | None = None, late_seed_points: Sequence[np.ndarray] = (),
    ) -> ModeResult:
        """Search a mode; see the module docstring. ``seeds``: choice arrays; ``seed_points``: full
        points x (unknown columns 0) to read modes off. ``budget_ms=None``: no time limit (the
        branch-and-bound runs to completion). ``search_ms``: a further cap on the optional phases
        (seeds, descent, flips, branch-and-bound) counted from the end of the read-off, within
        ``budget_ms``; ``search_qps``: the same cap counted in QPs (deterministic, unlike time);
        ``max_flip_qps``: at most that many QPs in the flips phase (the flips are tried in
        decreasing order of the dual weight of the chosen disjunct's rows). ``late_seed_points``:
        points read off only with the budget the branch-and-bound leaves (phase e)."""
        t_start = time.perf_counter()
        self._memo.clear()
        self.qps = 0
        tm: dict[str, float] = {}
        deadline = None if budget_ms is None else t_start + budget_ms / 1e3
        allowed = self.allowed()
        D = self.D

        qp_cap = [None]  # QPs allowed in total once the optional phases start

        def out_of_time() -> bool:
            if qp_cap[0] is not None and self.qps >= qp_cap[0]:
                return True
            return deadline is not None and time.perf_counter() > deadline

        def lap(name: str, t0: float) -> float:
            t1 = time.perf_counter()
            tm[name] = tm.get(name, 0.0) + (t1 - t0) * 1e3
            return t1

        undecided = np.full(D, -1, np.int64)
        lb, x_lb, z_lb = self.solve_mode(undecided)
        t = lap("lower_bound", t_start)
        if not np.isfinite(lb):
            return ModeResult("infeasible", np.inf, None, undecided, np.zeros(self.qp.ints.size), self.qps,
                              True, np.nan, np.inf, 0, tm)
        best = [np.inf, None, undecided, None]  # cost, x, choice, duals

        def consider(choice: np.ndarray) -> bool:
            c, x, z = self.solve_mode(choice)
            if c < best[0] - abs_tol:
                best[:] = [c, x, choice.copy(), z]
                return True
            return False

        def certified() -> bool:
            return best[0] <= lb + gap * max(abs(best[0]), 0.0) + abs_tol

        if D == 0:
            best[:] = [lb, x_lb, undecided, None]
        else:
            ch = self.read_off(x_lb, allowed)
            self._adopt(ch, x_lb, z_lb)
            consider(ch)
        t = lap("readoff", t)
        if search_ms is not None:  # the optional phases get at most search_ms from here
            cap = t + search_ms / 1e3
            deadline = cap if deadline is None else min(deadline, cap)
        if search_qps is not None:  # and at most search_qps QPs
            qp_cap[0] = self.qps + search_qps
        if D and not certified():
            for ch in list(seeds) + [self.read_off(p, allowed) for p in seed_points]:
                if out_of_time() or certified():
                    break
                ch = np.asarray(ch, np.int64)
                if ch.shape == (D,) and np.all(allowed[self.gstart[:-1] + np.maximum(ch, 0)] | (ch < 0)):
                    consider(np.maximum(ch, 0) if (ch < 0).any() else ch)
            t = lap("seeds", t)
            # descent: re-read the incumbent's own trajectory
            for _ in range(3):
                if best[1] is None or out_of_time() or certified():
                    break
                ch = self.read_off(best[1], allowed)
                if np.array_equal(ch, best[2]) or not consider(ch):
                    break
            t = lap("descent", t)
        cert = certified() if np.isfinite(best[0]) else False
        nodes = 0
        bound = lb
        if D and bnb and not cert and not out_of_time():
            finished, bound, nodes = self._bnb(lb, x_lb, best, allowed, bnb_gap, abs_tol, out_of_time)
            cert = finished
            t = lap("bnb", t)
        # the heuristic flips only with what the branch-and-bound leaves (it either finishes,
        # exact, or spends the cap: measured, it finds the optimum in fewer QPs than the flips)
        if D and not cert and not certified() and not out_of_time():
            for p in late_seed_points:
                if out_of_time() or certified():
                    break
                consider(self.read_off(p, allowed))
            t = lap("seeds", t)
            # flips ordered by the duals of the chosen disjuncts' rows
            improved = True
            rounds = 0
            q0 = self.qps
            flips_left = (lambda: True) if max_flip_qps is None else (lambda: self.qps - q0 < max_flip_qps)
            while improved and best[3] is not None and not certified() and not out_of_time() and rounds < 3 \
                    and flips_left():
                improved = False
                rounds += 1
                z = np.abs(best[3])
                ch0 = best[2]
                g_sel = self.gstart[:-1] + ch0
                w = np.zeros(int(self.gstart[-1]))
                np.add.at(w, self.row_g, z[self.row_flat])
                weight = w[g_sel]
                order = np.argsort(-weight)
                for d in order[:max_flips]:
                    if weight[d] <= 1e-9 or out_of_time() or not flips_left():
                        break
                    alts = [i for i in range(self.size[d]) if i != ch0[d] and allowed[self.gstart[d] + i]]
                    for i in alts:
                        if not flips_left() or out_of_time():
                            break
                        ch = ch0.copy()
                        ch[d] = i
                        if consider(ch):
                            improved = True
                    if improved:
                        break
            t = lap("flips", t)
            if best[1] is not None and not out_of_time() and not certified():
                ch = self.read_off(best[1], allowed)
                if not np.array_equal(ch, best[2]):
                    consider(ch)
                t = lap("descent", t)
            cert = certified()
        if cert and np.isfinite(best[0]):
            bound = max(bound, lb) if np.isfinite(bound) else lb
        x_int, _ = self.to_int(best[2]) if best[1] is not None else (np.zeros(self.qp.ints.size), None)
        if best[1] is None:
            status = "infeasible" if cert else "time_limit"
            return ModeResult(status, np.inf, None, best[2], x_int, self.qps, cert, np.nan, bound, nodes, tm)
        g = max(0.0, (best[0] - bound) / max(abs(best[0]), 1e-9))
        return ModeResult("optimal" if cert else "feasible", best[0], best[1], best[2], x_int, self.qps, cert,
                          g, bound, nodes, tm)

    def _bnb(self, lb: float, x_lb: np.ndarray, best: list, allowed: np.ndarray, bnb_gap: float,
             abs_tol: float, out_of_time) -> tuple[bool, float, int]:  # type: ignore[no-untyped-def]
        """Best-first B&B; updates ``best`` in place. Returns (finished, lowest open bound, nodes)."""
        D = self.D
        heap: list[tuple[float, int, np.ndarray, np.ndarray]] = [(lb, 0, np.full(D, -1, np.int64), x_lb)]
        counter = 1
        nodes = 0

        def prune_at() -> float:
            if not np.isfinite(best[0]):
                return np.inf
            return best[0] - max(bnb_gap * abs(best[0]), abs_tol)

        while heap:
            if out_of_time():
                return False, min(heap[0][0], best[0]), nodes
            bnd, _, ch, x = heapq.heappop(heap)
            if bnd >= prune_at():
                continue
            nodes += 1
            act = self._active(ch) if self.nested.size else np.ones(D, bool)
            open_d = np.flatnonzero(act & (ch < 0))
            val = np.where(allowed, self.values(x), -np.inf)
            seg_best = np.full(D, -np.inf)
            np.maximum.at(seg_best, self.owner, val)
            viol = seg_best[open_d]
            if open_d.size == 0 or np.all(viol >= -_FEAS):
                # the relaxation's point already satisfies every open disjunction: a full mode
                full = ch.copy()
                if open_d.size:
                    full[open_d] = self.read_off(x, allowed)[open_d]
                full[(~act) & (full < 0)] = 0
                if bnd < best[0] - abs_tol:
                    c, xf, z = self.solve_mode(full)
                    if c < best[0]:
                        best[:] = [c, xf, full, z]
                continue
            d = int(open_d[np.argmin(viol)])
            for i in range(self.size[d]):
                if not allowed[self.gstart[d] + i]:
                    continue
                child = ch.copy()
                child[d] = i
                c, xc, _ = self.solve_mode(child)
                if c < prune_at():
                    heapq.heappush(heap, (c, counter, child, xc))
                    counter += 1
                if out_of_time():
                    break
        return True, best[0], nodes
