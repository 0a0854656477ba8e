"""Real-time disjunctive mode search over one fixed-pattern Clarabel QP.

Every binary of a :class:`~twolevel.milp.model.MilpModel` belongs to one
:class:`~twolevel.milp.model.Disjunction`. A *mode* picks one disjunct per disjunction: an int
array ``choice`` (D,), ``-1`` meaning undecided (its cover row disabled, its big-M rows off). With
the mode fixed the problem is the convex QP of :class:`~twolevel.milp.clarabel.FixedModeQP`;
switching mode rewrites values only, on the same solver object.

:meth:`ModeSearch.run` goes through these phases, each a method of the run's state (``_Run``):

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
   late seeds, then per-disjunction flips ordered by the dual values of the chosen disjuncts'
   rows, then one more descent. (Measured on the closed-loop benchmark: run before the branch-and-bound under a QP
   cap, the flips spent the cap without finding the optimum the branch-and-bound then missed.)
"""

from __future__ import annotations

import heapq
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from twolevel.milp.clarabel import FixedModeQP
from twolevel.milp.solution import Status, ValueEnum

__all__ = ["ModeStatus", "ModeResult", "ModeSearch"]

_FEAS = 1e-6  # [row units] a disjunct holds when its rows' slack is at least −_FEAS


class ModeStatus(ValueEnum):
    """Outcome of a mode search."""

    OPTIMAL = "optimal"        # certified within the gap, or the branch-and-bound finished
    FEASIBLE = "feasible"      # a mode found, not certified in time
    INFEASIBLE = "infeasible"  # no mode can be feasible (proven)
    TIME_LIMIT = "time_limit"  # no feasible mode found in time


@dataclass(frozen=True)
class ModeResult:
    """Outcome of a mode search (``status``: see :class:`ModeStatus`). ``mode``: choice per
    disjunction (−1 inactive); ``bound``: the best proven lower bound; ``gap`` = (cost − bound) /
    max(|cost|, 1e-9); ``timings_ms``: phase → ms (lower_bound, readoff, seeds, flips, descent, bnb)."""

    status: ModeStatus
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

    def reset(self) -> None:
        """Forget the QPs solved so far (the memo of modes) and their count."""
        self._memo.clear()
        self.qps = 0

    def active(self, choice: np.ndarray) -> np.ndarray:
        """Bool per disjunction: it is in force under the (partial) mode ``choice`` (top-level
        ones always; a nested one when its enclosing disjunct is chosen)."""
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
        act = self.active(choice) if self.nested.size else np.ones(self.D, bool)
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

    def adopt(self, choice: np.ndarray, x: np.ndarray, duals: np.ndarray | None, tol: float = _FEAS) -> bool:
        """When ``x``, the optimum of a relaxation of ``choice``'s QP (fewer rows enforced),
        already satisfies that QP's rows and bounds (within ``tol``) with ``choice``'s binaries
        set, it is that QP's optimum too: memoise it instead of solving (saves the read-off QP
        whenever the lower bound's plan meets every rule). Not when the cost couples binaries
        and continuous columns (the continuous optimum would depend on the mode)."""
        if self.qp.cost_couples_integers:
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
        self.reset()
        run = _Run(self, budget_ms=budget_ms, gap=gap, abs_tol=abs_tol)
        if not run.lower_bound():
            return run.infeasible()
        run.read_off()
        run.cap(search_ms, search_qps)
        if self.D and not run.certified():
            run.seeds(seeds, seed_points)
            run.descent()
        cert = run.certified() if np.isfinite(run.best.cost) else False
        if self.D and bnb and not cert and not run.out_of_time():
            cert = run.branch_and_bound(bnb_gap)
        # the heuristic flips only with what the branch-and-bound leaves (it either finishes,
        # exact, or spends the cap: measured, it finds the optimum in fewer QPs than the flips)
        if self.D and not cert and not run.certified() and not run.out_of_time():
            run.late_seeds(late_seed_points)
            run.flips(max_flips, max_flip_qps)
            run.final_descent()
            cert = run.certified()
        return run.result(cert)


@dataclass
class _Incumbent:
    """The best mode found so far: its cost, point, choice per disjunction and row duals."""

    cost: float
    x: np.ndarray | None
    choice: np.ndarray
    duals: np.ndarray | None


class _Run:
    """One :meth:`ModeSearch.run`: the budget (deadline [s], QP cap), the lower bound, the
    incumbent, the phase timings [ms]; each phase of the module docstring is a method."""

    def __init__(self, search: ModeSearch, *, budget_ms: float | None, gap: float, abs_tol: float) -> None:
        self.s = search
        self.t = time.perf_counter()  # start of the current phase
        self.deadline = None if budget_ms is None else self.t + budget_ms / 1e3
        self.qp_cap: int | None = None  # QPs allowed in total once the optional phases start
        self.gap, self.abs_tol = gap, abs_tol
        self.tm: dict[str, float] = {}
        self.allowed = search.allowed()
        self.undecided = np.full(search.D, -1, np.int64)
        self.lb, self.x_lb, self.z_lb = np.inf, None, None
        self.best = _Incumbent(np.inf, None, self.undecided, None)
        self.bound = np.inf
        self.nodes = 0

    # ------------------------------------------------------------------ bookkeeping
    def out_of_time(self) -> bool:
        if self.qp_cap is not None and self.s.qps >= self.qp_cap:
            return True
        return self.deadline is not None and time.perf_counter() > self.deadline

    def lap(self, phase: str) -> None:
        """Close the current phase: add its time to ``phase``."""
        t1 = time.perf_counter()
        self.tm[phase] = self.tm.get(phase, 0.0) + (t1 - self.t) * 1e3
        self.t = t1

    def consider(self, choice: np.ndarray) -> bool:
        """Solve ``choice``; keep it when it beats the incumbent by more than ``abs_tol``."""
        c, x, z = self.s.solve_mode(choice)
        if c < self.best.cost - self.abs_tol:
            self.best = _Incumbent(c, x, choice.copy(), z)
            return True
        return False

    def certified(self) -> bool:
        """The incumbent is within ``gap`` of the lower bound."""
        return self.best.cost <= self.lb + self.gap * max(abs(self.best.cost), 0.0) + self.abs_tol

    def cap(self, search_ms: float | None, search_qps: int | None) -> None:
        """Cap the optional phases, from now on, at ``search_ms`` [ms] and ``search_qps`` QPs."""
        if search_ms is not None:
            cap = self.t + search_ms / 1e3
            self.deadline = cap if self.deadline is None else min(self.deadline, cap)
        if search_qps is not None:
            self.qp_cap = self.s.qps + search_qps

    # ------------------------------------------------------------------ phases
    def lower_bound(self) -> bool:
        """a. The QP with every disjunction undecided; False when even that is infeasible."""
        self.lb, self.x_lb, self.z_lb = self.s.solve_mode(self.undecided)
        self.bound = self.lb
        self.lap("lower_bound")
        return bool(np.isfinite(self.lb))

    def read_off(self) -> None:
        """b. The mode read off the lower bound's point (adopted without a QP when it holds)."""
        if self.s.D == 0:
            self.best = _Incumbent(self.lb, self.x_lb, self.undecided, None)
        else:
            ch = self.s.read_off(self.x_lb, self.allowed)
            self.s.adopt(ch, self.x_lb, self.z_lb)
            self.consider(ch)
        self.lap("readoff")

    def seeds(self, seeds: Sequence[np.ndarray], points: Sequence[np.ndarray]) -> None:
        """c. The caller's choices and the modes read off its points."""
        D, allowed, gstart = self.s.D, self.allowed, self.s.gstart
        for ch in list(seeds) + [self.s.read_off(p, allowed) for p in points]:
            if self.out_of_time() or self.certified():
                break
            ch = np.asarray(ch, np.int64)
            if ch.shape == (D,) and np.all(allowed[gstart[:-1] + np.maximum(ch, 0)] | (ch < 0)):
                self.consider(np.maximum(ch, 0) if (ch < 0).any() else ch)
        self.lap("seeds")

    def descent(self, rounds: int = 3) -> None:
        """c. Re-read the mode off the incumbent's own point while that improves it."""
        for _ in range(rounds):
            if self.best.x is None or self.out_of_time() or self.certified():
                break
            ch = self.s.read_off(self.best.x, self.allowed)
            if np.array_equal(ch, self.best.choice) or not self.consider(ch):
                break
        self.lap("descent")

    def branch_and_bound(self, bnb_gap: float) -> bool:
        """d. Best-first branch-and-bound over the disjunctions (node = partial mode, bound =
        its QP cost, branch on the most violated open disjunction); True when it finished."""
        s, D, allowed = self.s, self.s.D, self.allowed
        heap: list[tuple[float, int, np.ndarray, np.ndarray]] = [(self.lb, 0, self.undecided.copy(), self.x_lb)]
        counter = 1
        finished = True
        while heap:
            if self.out_of_time():
                finished = False
                self.bound = min(heap[0][0], self.best.cost)
                break
            bnd, _, ch, x = heapq.heappop(heap)
            if bnd >= self._prune_at(bnb_gap):
                continue
            self.nodes += 1
            act = s.active(ch) if s.nested.size else np.ones(D, bool)
            open_d = np.flatnonzero(act & (ch < 0))
            val = np.where(allowed, s.values(x), -np.inf)
            seg_best = np.full(D, -np.inf)
            np.maximum.at(seg_best, s.owner, val)
            viol = seg_best[open_d]
            if open_d.size == 0 or np.all(viol >= -_FEAS):
                # the relaxation's point already satisfies every open disjunction: a full mode
                full = ch.copy()
                if open_d.size:
                    full[open_d] = s.read_off(x, allowed)[open_d]
                full[(~act) & (full < 0)] = 0
                if bnd < self.best.cost - self.abs_tol:
                    c, xf, z = s.solve_mode(full)
                    if c < self.best.cost:
                        self.best = _Incumbent(c, xf, full, z)
                continue
            d = int(open_d[np.argmin(viol)])
            for i in range(s.size[d]):
                if not allowed[s.gstart[d] + i]:
                    continue
                child = ch.copy()
                child[d] = i
                c, xc, _ = s.solve_mode(child)
                if c < self._prune_at(bnb_gap):
                    heapq.heappush(heap, (c, counter, child, xc))
                    counter += 1
                if self.out_of_time():
                    break
        if finished:
            self.bound = self.best.cost
        self.lap("bnb")
        return finished

    def _prune_at(self, bnb_gap: float) -> float:
        if not np.isfinite(self.best.cost):
            return np.inf
        return self.best.cost - max(bnb_gap * abs(self.best.cost), self.abs_tol)

    def late_seeds(self, points: Sequence[np.ndarray]) -> None:
        """e. The modes read off points kept for the budget the branch-and-bound leaves."""
        for p in points:
            if self.out_of_time() or self.certified():
                break
            self.consider(self.s.read_off(p, self.allowed))
        self.lap("seeds")

    def flips(self, max_flips: int, max_flip_qps: int | None) -> None:
        """e. Flip single disjunctions, in decreasing order of the dual weight of the chosen
        disjuncts' rows, for at most three improving rounds and ``max_flip_qps`` QPs."""
        s, allowed = self.s, self.allowed
        q0 = s.qps

        def flips_left() -> bool:
            return max_flip_qps is None or s.qps - q0 < max_flip_qps

        improved = True
        rounds = 0
        while improved and self.best.duals is not None and not self.certified() and not self.out_of_time() \
                and rounds < 3 and flips_left():
            improved = False
            rounds += 1
            z = np.abs(self.best.duals)
            ch0 = self.best.choice
            g_sel = s.gstart[:-1] + ch0
            w = np.zeros(int(s.gstart[-1]))
            np.add.at(w, s.row_g, z[s.row_flat])
            weight = w[g_sel]
            order = np.argsort(-weight)
            for d in order[:max_flips]:
                if weight[d] <= 1e-9 or self.out_of_time() or not flips_left():
                    break
                alts = [i for i in range(s.size[d]) if i != ch0[d] and allowed[s.gstart[d] + i]]
                for i in alts:
                    if not flips_left() or self.out_of_time():
                        break
                    ch = ch0.copy()
                    ch[d] = i
                    if self.consider(ch):
                        improved = True
                if improved:
                    break
        self.lap("flips")

    def final_descent(self) -> None:
        """e. One more read-off of the incumbent's point."""
        if self.best.x is not None and not self.out_of_time() and not self.certified():
            ch = self.s.read_off(self.best.x, self.allowed)
            if not np.array_equal(ch, self.best.choice):
                self.consider(ch)
            self.lap("descent")

    # ------------------------------------------------------------------ outcome
    def infeasible(self) -> ModeResult:
        """The lower bound is infeasible: so is every mode (proven)."""
        return ModeResult(ModeStatus.INFEASIBLE, np.inf, None, self.undecided, np.zeros(self.s.qp.ints.size),
                          self.s.qps, True, np.nan, np.inf, 0, self.tm)

    def result(self, cert: bool) -> ModeResult:
        best = self.best
        bound = self.bound
        if cert and np.isfinite(best.cost):
            bound = max(bound, self.lb) if np.isfinite(bound) else self.lb
        x_int = self.s.to_int(best.choice)[0] if best.x is not None else np.zeros(self.s.qp.ints.size)
        if best.x is None:
            status = ModeStatus.INFEASIBLE if cert else ModeStatus.TIME_LIMIT
            return ModeResult(status, np.inf, None, best.choice, x_int, self.s.qps, cert, np.nan, bound,
                              self.nodes, self.tm)
        g = max(0.0, (best.cost - bound) / max(abs(best.cost), 1e-9))
        return ModeResult(ModeStatus.OPTIMAL if cert else ModeStatus.FEASIBLE, best.cost, best.x, best.choice,
                          x_int, self.s.qps, cert, g, bound, self.nodes, self.tm)
