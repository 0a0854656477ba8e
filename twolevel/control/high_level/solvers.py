"""The solve paths of one MPC step: one strategy per solver, behind one interface.

Each path takes the assembled step, the solver objects built on its model
(:class:`~twolevel.control.high_level.backend.Backend`) and the time left, and returns an
:class:`Attempt` — the point of the model it found (or none) and how it got there:

* :class:`ModeSearchPath` (``modes``): :class:`~twolevel.milp.modes.ModeSearch` on the cached
  Clarabel QP, seeded with the previous plan shifted, then (after the branch-and-bound, or
  first when there is no previous plan) the reference, the reference shifted one lane left and
  right, and "stay behind" the vehicle ahead (:func:`seed_points`).
* :class:`HighsPath` (``highs``): the L1 counterpart of the model in HiGHS picks the binaries
  (time limit), then Clarabel with those binaries fixed restores the exact quadratic cost.
* :class:`GurobiPath` (``gurobi``): the MIQP in Gurobi (when gurobipy is importable).

:func:`solve_path` picks the path of the settings.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from twolevel.control.high_level.backend import Backend
from twolevel.control.high_level.linearisation import StepData
from twolevel.control.high_level.problem import Assembled
from twolevel.control.high_level.settings import SOLVERS, MPCSettings
from twolevel.control.planner import PlanStatus
from twolevel.milp.gurobi import available as gurobi_available
from twolevel.milp.gurobi import solve_gurobi
from twolevel.milp.highs import solve_highs
from twolevel.milp.l1_surrogate import l1_surrogate
from twolevel.milp.solution import Status
from twolevel.world.geometry import Route

__all__ = ["Attempt", "SolvePath", "ModeSearchPath", "HighsPath", "GurobiPath", "solve_path", "seed_points"]


@dataclass(frozen=True, eq=False)
class Attempt:
    """What a solve path found: ``x`` (the model point; None when no plan), its ``cost``, the
    ``mode`` (choice per disjunction), QPs solved, whether the status is ``certified``, the
    relative ``gap`` and the path's phases [ms]."""

    status: PlanStatus = PlanStatus.INFEASIBLE
    cost: float = float("inf")
    x: np.ndarray | None = None
    mode: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    qps: int = 0
    certified: bool = False
    gap: float = float("nan")
    timings_ms: dict[str, float] = field(default_factory=dict)


class SolvePath(Protocol):
    """One way to solve an assembled step."""

    def solve(self, asm: Assembled, step: StepData, backend: Backend, budget_ms: float | None,
              warm: bool) -> Attempt:
        """Solve ``asm`` within ``budget_ms`` [ms] (None: no limit); ``warm``: the step is
        linearised about a previous plan of the same horizon."""


def _point(asm: Assembled, states: np.ndarray, controls: np.ndarray | None = None) -> np.ndarray:
    """A full model point with the states (N, 4) for k = 1..N (and controls) filled in, the rest 0."""
    x = np.zeros(asm.model.n_cols)
    x[asm.layout.x.ravel()] = states.ravel()
    if controls is not None:
        x[asm.layout.u.ravel()] = controls.ravel()
    return x


def seed_points(step: StepData, asm: Assembled, route: Route, warm: bool) -> list[np.ndarray]:
    """Trajectories to read modes off: the previous plan shifted (``warm``: the linearisation
    point is that plan), the reference, the reference shifted one lane left and right, and a
    stay-behind reference for the vehicle ahead."""
    pts = []
    H, N = step.H, step.N
    if warm:
        pts.append(_point(asm, step.xs_bar[1:], step.us_bar))
    om = step.omega
    pts.append(_point(asm, om))
    normal = np.stack([-np.sin(om[:, 2]), np.cos(om[:, 2])], axis=1)
    for side in (1.0, -1.0):
        shifted = om.copy()
        ramp = np.minimum(1.0, np.arange(1, N + 1) / max(H / 2, 1))[:, None]
        shifted[:, :2] += side * step.lane_width * ramp * normal
        pts.append(_point(asm, shifted))
    hc = step.hc
    if hc.lead >= 0:
        gap = hc.lead_offset + 2.0
        s_cap = np.minimum(step.s_ref[1:], np.maximum(hc.s_lead[1:] - gap, step.s_bar[0]))
        behind = om.copy()
        behind[:, :2] = route.position(s_cap)
        behind[:, 3] = np.minimum(om[:, 3], np.maximum(np.diff(np.concatenate([[step.s_bar[0]], s_cap])) / step.steps,
                                                       0))
        pts.append(_point(asm, behind))
    return pts


class ModeSearchPath:
    """``modes``: the real-time disjunctive mode search (see the module docstring)."""

    def __init__(self, settings: MPCSettings, route: Route) -> None:
        self.settings = settings
        self.route = route

    def solve(self, asm: Assembled, step: StepData, backend: Backend, budget_ms: float | None,
              warm: bool) -> Attempt:
        st = self.settings
        capped = st.time_limit is not None
        pts = seed_points(step, asm, self.route, warm)
        # with a previous plan, its shifted modes are the warm start; the reference-based
        # seeds come after the branch-and-bound (measured: under the QP cap the B&B reaches
        # the optimum in fewer QPs than they spend), and first when there is no previous plan
        early, late = (pts[:1], pts[1:]) if warm else (pts, [])
        r = backend.search.run(seed_points=early, late_seed_points=late, budget_ms=budget_ms, gap=st.gap,
                               search_ms=st.search_ms if capped else None,
                               max_flip_qps=st.max_flip_qps if capped else None,
                               search_qps=st.search_qps if capped else None)
        return Attempt(PlanStatus(r.status), r.cost, r.x, r.mode, r.qps, r.certified, r.gap, dict(r.timings_ms))


class HighsPath:
    """``highs``: HiGHS picks the modes on the L1 model, Clarabel polishes (see the module docstring)."""

    def solve(self, asm: Assembled, step: StepData, backend: Backend, budget_ms: float | None,
              warm: bool) -> Attempt:
        model, qp, ms = asm.model, backend.qp, backend.search
        tm: dict[str, float] = {}
        t2 = time.perf_counter()
        lin = l1_surrogate(model)
        sol = solve_highs(lin, time_limit=None if budget_ms is None else budget_ms / 1e3)
        t3 = time.perf_counter()
        tm["highs"] = (t3 - t2) * 1e3
        if sol.x is None:
            status = PlanStatus.TIME_LIMIT if sol.status is Status.TIME_LIMIT else PlanStatus.INFEASIBLE
            return Attempt(status, certified=sol.status is Status.INFEASIBLE, timings_ms=tm)
        xi = np.round(sol.x[: model.n_cols][qp.ints])
        pol = qp.solve(xi)
        qps = 1
        tm["polish"] = (time.perf_counter() - t3) * 1e3
        if pol.status is not Status.OPTIMAL:
            return Attempt(qps=qps, timings_ms=tm)
        x, cost = pol.x, pol.objective
        mode = ms.read_off(x) if ms.D else np.zeros(0, np.int64)
        # the L1 cost can pick a mode that is not the quadratic optimum's: descend over the
        # modes read off the polished plan (a few QPs on the same object)
        for _ in range(3 if ms.D else 0):
            c2, x2, _ = ms.solve_mode(ms.read_off(x))
            qps += 1
            if not c2 < cost - 1e-9:
                break
            cost, x = c2, x2
            mode = ms.read_off(x)
        tm["polish"] = (time.perf_counter() - t3) * 1e3
        status = PlanStatus.OPTIMAL if sol.status is Status.OPTIMAL else PlanStatus.FEASIBLE
        return Attempt(status, cost, x, mode, qps, sol.status is Status.OPTIMAL, float(sol.gap), tm)


class GurobiPath:
    """``gurobi``: the MIQP in Gurobi."""

    def solve(self, asm: Assembled, step: StepData, backend: Backend, budget_ms: float | None,
              warm: bool) -> Attempt:
        ms = backend.search
        sol = solve_gurobi(asm.model, time_limit=None if budget_ms is None else budget_ms / 1e3)
        tm = {"gurobi": sol.solve_ms}
        if sol.x is None:
            status = PlanStatus.INFEASIBLE if sol.status is Status.INFEASIBLE else PlanStatus.TIME_LIMIT
            return Attempt(status, timings_ms=tm)
        mode = ms.read_off(sol.x) if ms.D else np.zeros(0, np.int64)
        status = PlanStatus.OPTIMAL if sol.status is Status.OPTIMAL else PlanStatus.FEASIBLE
        return Attempt(status, sol.objective, sol.x, mode, 0, sol.status is Status.OPTIMAL, timings_ms=tm)


def solve_path(settings: MPCSettings, route: Route) -> SolvePath:
    """The solve path ``settings.solver`` names. Raises ValueError for an unknown solver or
    Gurobi without gurobipy."""
    if settings.solver == "modes":
        return ModeSearchPath(settings, route)
    if settings.solver == "highs":
        return HighsPath()
    if settings.solver == "gurobi":
        if not gurobi_available():
            raise ValueError("solver 'gurobi' needs gurobipy, which is not importable; use 'modes' or 'highs'")
        return GurobiPath()
    raise ValueError(f"unknown solver {settings.solver!r}; choose one of {', '.join(SOLVERS)}")
