"""The two solve paths of one MPC step, the seeds of the mode search, the fallback, the monitor.

* ``modes``: :class:`~twolevel.milp.modes.ModeSearch` on the cached Clarabel QP, seeded with the
  previous plan shifted, then (after the branch-and-bound, or first when there is no previous
  plan) the reference, the reference shifted one lane left and right, and "stay behind" the
  vehicle ahead.
* ``highs``: the L1 counterpart of the model in HiGHS picks the binaries (time limit), then
  Clarabel with those binaries fixed restores the exact quadratic cost.
* ``gurobi``: the MIQP in Gurobi (when gurobipy is importable).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from twolevel.compiler.signals import AffineSignal
from twolevel.control.horizon import StepData
from twolevel.control.problem import Assembled
from twolevel.diagnostics import Span
from twolevel.milp.highs import solve_highs
from twolevel.milp.l1_surrogate import l1_surrogate
from twolevel.milp.solution import Status

if TYPE_CHECKING:
    from twolevel.control.high_level import HighLevelController, PlanResult

__all__ = ["solve_step", "seed_points", "plan_signals", "monitor_rules"]


def _point(asm: Assembled, states: np.ndarray, controls: np.ndarray | None = None) -> np.ndarray:
    """A full model point with the states (H, 4) for k = 1..H (and controls) filled in, the rest 0."""
    x = np.zeros(asm.model.n_cols)
    x[asm.layout.x.ravel()] = states.ravel()
    if controls is not None:
        x[asm.layout.u.ravel()] = controls.ravel()
    return x


def seed_points(ctrl: "HighLevelController", step: StepData, asm: Assembled) -> list[np.ndarray]:
    """Trajectories to read modes off: previous plan shifted, the reference, the reference shifted
    one lane left and right, and a stay-behind reference for the vehicle ahead."""
    pts = []
    H = ctrl.settings.H
    if ctrl._prev is not None and ctrl._prev[1].shape[0] == H + 1:
        pts.append(_point(asm, step.xs_bar[1:], step.us_bar))
    om = step.omega
    pts.append(_point(asm, om))
    normal = np.stack([-np.sin(om[:, 2]), np.cos(om[:, 2])], axis=1)
    for side in (1.0, -1.0):
        shifted = om.copy()
        ramp = np.minimum(1.0, np.arange(1, H + 1) / max(H / 2, 1))[:, None]
        shifted[:, :2] += side * step.lane_width * ramp * normal
        pts.append(_point(asm, shifted))
    hc = step.hc
    if hc.lead >= 0:
        route = ctrl.world.route
        gap = hc.lead_offset + 2.0
        s_cap = np.minimum(step.s_ref[1:], np.maximum(hc.s_lead[1:] - gap, step.s_bar[0]))
        behind = om.copy()
        behind[:, :2] = route.position(s_cap)
        behind[:, 3] = np.minimum(om[:, 3], np.maximum(np.diff(np.concatenate([[step.s_bar[0]], s_cap])) / ctrl.settings.dt, 0))
        pts.append(_point(asm, behind))
    return pts


def plan_signals(asm: Assembled, x: np.ndarray) -> dict[str, np.ndarray]:
    """The rule signals over the trace (past, now, plan) evaluated at the model point ``x``."""
    out: dict[str, np.ndarray] = {}
    for name, s in asm.signals.items():
        if isinstance(s, AffineSignal):
            out[name] = s.coef @ x[: s.coef.shape[1]] + s.offset
        else:
            out[name] = np.asarray(s, float)
    return out


def monitor_rules(ctrl: "HighLevelController", step: StepData, asm: Assembled, x: np.ndarray) -> dict[str, float]:
    """Each rule's robustness at the current step of the plan, by the offline monitor, with the
    high-level ``collision_free`` (the 1-norm diamond to every nearby vehicle's prediction)."""
    from twolevel.monitor.robustness import MonitorError, robustness

    sig = plan_signals(asm, x)
    P = asm.layout.P
    others = step.hc.xy  # (n, H+1, 2)

    def cf(signals, d):  # type: ignore[no-untyped-def]
        T = len(signals["x"])
        out = np.full(T, np.inf)
        if others.shape[0]:
            dist = np.abs(signals["x"][P:, None] - others[:, :, 0].T) + np.abs(signals["y"][P:, None] - others[:, :, 1].T)
            out[P:] = dist.min(axis=1)
        return out - d

    res: dict[str, float] = {}
    for r in ctrl.rules:
        try:
            rho = robustness(r.formula, sig, ctrl.settings.dt, builtins={"collision_free": cf})  # type: ignore[arg-type]
            res[r.name] = float(rho[P])
        except MonitorError:
            res[r.name] = float("nan")
    return res


def solve_step(ctrl: "HighLevelController", step: StepData, asm: Assembled, tm: dict[str, float],
               t0: float) -> "PlanResult":
    """Solve the assembled step with the controller's solver; the fallback when nothing works."""
    from twolevel.control.codes import MIL515
    from twolevel.control.high_level import PlanResult, fallback_plan

    st = ctrl.settings
    model = asm.model
    H = st.H
    diags = list(asm.diagnostics)
    status, cost, x, mode, qps, cert, gap, msg = "infeasible", float("inf"), None, np.zeros(0, np.int64), 0, False, float("nan"), ""
    if any(d.is_error for d in asm.diagnostics):
        msg = "; ".join(d.message for d in asm.diagnostics if d.is_error)
    elif asm.encoding.infeasible:
        msg = "a rule is violated by signals known at solve time"
        cert = True
    else:
        t1 = time.perf_counter()
        qp, ms = ctrl._backend(asm)
        tm["backend"] = (time.perf_counter() - t1) * 1e3
        left = None if st.time_limit is None else max(st.time_limit * 1e3 - (time.perf_counter() - t0) * 1e3, 1.0)
        if st.solver == "modes":
            capped = st.time_limit is not None
            pts = seed_points(ctrl, step, asm)
            # with a previous plan, its shifted modes are the warm start; the reference-based
            # seeds come after the branch-and-bound (measured: under the QP cap the B&B reaches
            # the optimum in fewer QPs than they spend), and first when there is no previous plan
            early, late = (pts[:1], pts[1:]) if ctrl._prev is not None and ctrl._prev[1].shape[0] == H + 1 else (pts, [])
            r = ms.run(seed_points=early, late_seed_points=late, budget_ms=left, gap=st.gap,
                       search_ms=st.search_ms if capped else None, max_flip_qps=st.max_flip_qps if capped else None,
                       search_qps=st.search_qps if capped else None)
            tm.update({k: v for k, v in r.timings_ms.items()})
            status, cost, x, mode, qps, cert, gap = r.status, r.cost, r.x, r.mode, r.qps, r.certified, r.gap
        elif st.solver == "highs":
            t2 = time.perf_counter()
            lin = l1_surrogate(model)
            sol = solve_highs(lin, time_limit=None if left is None else left / 1e3)
            t3 = time.perf_counter()
            tm["highs"] = (t3 - t2) * 1e3
            if sol.x is not None:
                xi = np.round(sol.x[: model.n_cols][qp.ints])
                pol = qp.solve(xi)
                qps = 1
                tm["polish"] = (time.perf_counter() - t3) * 1e3
                if pol.status is Status.OPTIMAL:
                    x, cost = pol.x, pol.objective
                    status = "optimal" if sol.status is Status.OPTIMAL else "feasible"
                    cert = sol.status is Status.OPTIMAL
                    mode = ms.read_off(x) if ms.D else np.zeros(0, np.int64)
                    gap = float(sol.gap)
                    # the L1 cost can pick a mode that is not the quadratic optimum's: descend
                    # over the modes read off the polished plan (a few QPs on the same object)
                    for _ in range(3 if ms.D else 0):
                        c2, x2, _ = ms.solve_mode(ms.read_off(x))
                        qps += 1
                        if not c2 < cost - 1e-9:
                            break
                        cost, x = c2, x2
                        mode = ms.read_off(x)
                    tm["polish"] = (time.perf_counter() - t3) * 1e3
            else:
                status = {Status.INFEASIBLE: "infeasible", Status.TIME_LIMIT: "time_limit"}.get(sol.status, "infeasible")
                cert = sol.status is Status.INFEASIBLE
        else:
            from twolevel.milp.gurobi import solve_gurobi

            sol = solve_gurobi(model, time_limit=None if left is None else left / 1e3)
            tm["gurobi"] = sol.solve_ms
            if sol.x is not None:
                x, cost = sol.x, sol.objective
                status = "optimal" if sol.status is Status.OPTIMAL else "feasible"
                cert = sol.status is Status.OPTIMAL
                mode = ms.read_off(x) if ms.D else np.zeros(0, np.int64)
            else:
                status = "infeasible" if sol.status is Status.INFEASIBLE else "time_limit"
        if x is None:
            msg = "no mode satisfies every rule" if status == "infeasible" else "no plan found within the time limit"
    tm["solve"] = sum(v for k, v in tm.items() if k not in ("linearise", "assembly", "solve", "total", "relinearise"))
    tm["total"] = (time.perf_counter() - t0) * 1e3
    nb, nr, nc = model.n_binaries, model.n_rows, model.n_cols
    if x is None:
        states, controls, why = fallback_plan(ctrl, step)
        diags.append(MIL515(f"t = {step.t:.2f} s: {msg}; fallback: {why}", Span(ctrl.world.name)))
        return PlanResult("fallback", float("nan"), controls, states, np.asarray(mode), nb, nr, nc, qps, cert, tm, {},
                          f"{status}: {msg}; fallback: {why}", gap, tuple(diags), st.solver)
    states = np.vstack([step.x0[None], x[asm.layout.x]])
    controls = x[asm.layout.u]
    rob: dict[str, float] = {}
    if st.monitor:
        t4 = time.perf_counter()
        rob = monitor_rules(ctrl, step, asm, x)
        tm["monitor"] = (time.perf_counter() - t4) * 1e3
    if asm.encoding.recovered:
        msg = "recovering: " + "; ".join(f"rule '{n}' violated now, required from k = {t2 - t}"
                                         for n, t, t2 in asm.encoding.recovered)
    return PlanResult(status, float(cost), controls, states, np.asarray(mode), nb, nr, nc, qps, bool(cert), tm, rob,
                      msg, float(gap), tuple(diags), st.solver)
