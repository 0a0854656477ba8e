"""Optional Gurobi backend (the paper's solver): the MIQP as it is, when gurobipy is importable.

gurobipy is imported lazily; :func:`available` says whether it can be. Note: the
pip licence refuses quadratic models above 200 variables.
"""

from __future__ import annotations

import time

import numpy as np

from twolevel.milp.model import MilpModel
from twolevel.milp.solution import Capabilities, Solution, Status

__all__ = ["CAPABILITIES", "available", "solve_gurobi"]

CAPABILITIES = Capabilities("gurobi", integer=True, quadratic=True)


def available() -> bool:
    """Whether gurobipy can be imported."""
    try:
        import gurobipy  # noqa: F401
    except Exception:
        return False
    return True


def solve_gurobi(model: MilpModel, *, time_limit: float | None = None, mip_gap: float = 1e-6) -> Solution:
    """Solve the MIQP (quadratic cost included) with Gurobi; ``time_limit`` [s]."""
    import gurobipy as gp  # lazy: optional
    import scipy.sparse as sp

    t0 = time.perf_counter()
    env = gp.Env(empty=True)
    env.setParam("OutputFlag", 0)
    env.start()
    m = gp.Model(env=env)
    vtype = np.where(model.integrality, "B", "C")
    lb = np.where(np.isfinite(model.lb), model.lb, -gp.GRB.INFINITY)
    ub = np.where(np.isfinite(model.ub), model.ub, gp.GRB.INFINITY)
    x = m.addMVar(model.n_cols, lb=lb, ub=ub, vtype=vtype)
    A = sp.csr_matrix(model.A)
    fin_hi = np.isfinite(model.row_hi)
    fin_lo = np.isfinite(model.row_lo)
    if fin_hi.any():
        m.addMConstr(A[fin_hi], x, "<", model.row_hi[fin_hi])
    if fin_lo.any():
        m.addMConstr(A[fin_lo], x, ">", model.row_lo[fin_lo])
    obj = model.q @ x + model.c0
    if model.P is not None:
        Pf = (model.P + sp.triu(model.P, 1).T).tocsr()
        obj = obj + 0.5 * (x @ Pf @ x)
    m.setObjective(obj)
    m.Params.MIPGap = mip_gap
    if time_limit is not None:
        m.Params.TimeLimit = time_limit
    t1 = time.perf_counter()
    m.optimize()
    t2 = time.perf_counter()
    status = _status(m.Status, gp)
    xv = np.asarray(x.X) if m.SolCount > 0 else None
    obj_v = float(m.ObjVal) if xv is not None else float("nan")
    return Solution(status, xv, obj_v, (t2 - t1) * 1e3, (t1 - t0) * 1e3, float(getattr(m, "MIPGap", np.nan)))


def _status(code: int, gp) -> Status:  # type: ignore[no-untyped-def]
    """Gurobi's model status → :class:`Status`."""
    return {gp.GRB.OPTIMAL: Status.OPTIMAL, gp.GRB.INFEASIBLE: Status.INFEASIBLE,
            gp.GRB.TIME_LIMIT: Status.TIME_LIMIT}.get(code, Status.ERROR)
