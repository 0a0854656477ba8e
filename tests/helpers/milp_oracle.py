"""The two checks that hold an MILC encoding to the offline monitor (the oracle) on the double
integrator of :mod:`helpers.milp_systems`, shared by the encoding's random-formula tests.

``signals(builder)`` adds the system and returns ``(p_block, v_block, a_block, signals)``;
``monitor(p, v)`` is the oracle's robustness of the formula at the required times on the whole
trace (past, now, plan)."""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import pytest

from twolevel.compiler.driver import encode
from twolevel.compiler.types import Requirement
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.highs import solve_highs
from twolevel.milp.solution import Status
from twolevel.stl import ast

from helpers.milp_systems import DT, H, rollout

Signals = Callable[[ModelBuilder], tuple]
Monitor = Callable[[np.ndarray, np.ndarray], float]


def check_satisfaction_of_a_fixed_trajectory(rng: np.random.Generator, f: ast.Node, times: tuple[int, ...],
                                             p_past: np.ndarray, v_past: np.ndarray, signals: Signals,
                                             monitor: Monitor) -> None:
    """A random plan fixed in the model: the satisfaction encoding is feasible exactly when the
    monitor says the formula holds (skips plans that leave the bounds or come within 1e-3 of the
    boundary)."""
    acc = rng.uniform(-2, 2, H)
    p_fut, v_fut = rollout(p_past[-1], v_past[-1], acc)
    if np.abs(p_fut).max() > 9.5:
        pytest.skip("trajectory leaves the bounds")
    rho = monitor(np.concatenate([p_past, p_fut]), np.concatenate([v_past, v_fut]))
    if abs(rho) < 1e-3 or math.isinf(rho):
        pytest.skip("too close to the boundary, or infinite")
    b = ModelBuilder()
    _, _, ab, sig = signals(b)
    enc = encode(b, [Requirement("r", f, times)], sig, DT, mode="satisfaction")
    assert not enc.diagnostics or all(d.code == "MIL503" for d in enc.diagnostics)
    m = b.build()
    # fix the trajectory after building: big-M comes from the wide bounds, rows are exercised
    m.lb[ab.idx] = m.ub[ab.idx] = acc
    sol = solve_highs(m)
    assert sol.status in (Status.OPTIMAL, Status.INFEASIBLE)
    assert (sol.status is Status.OPTIMAL) == (rho >= 1e-4), (f, rho, sol.status)


def check_optimal_robustness(f: ast.Node, times: tuple[int, ...], p_past: np.ndarray, v_past: np.ndarray,
                             signals: Signals, monitor: Monitor) -> None:
    """The robustness encoding's optimum equals the monitor's robustness of the optimal plan,
    and the plan keeps the dynamics (infeasible exactly when the encoding says so)."""
    b = ModelBuilder()
    pb, vb, _, sig = signals(b)
    enc = encode(b, [Requirement("r", f, times)], sig, DT, mode="robustness")
    m = b.build()
    sol = solve_highs(m, mip_gap=1e-9, options={"mip_abs_gap": 1e-9})
    if enc.infeasible:
        assert sol.status is Status.INFEASIBLE
        return
    assert sol.status is Status.OPTIMAL
    x = sol.x
    rho = monitor(np.concatenate([p_past, x[pb.idx]]), np.concatenate([v_past, x[vb.idx]]))
    if math.isinf(rho):
        pytest.skip("infinite robustness (trivially true or false formula)")
    assert x[enc.rho] == pytest.approx(rho, abs=1e-6), f
    assert m.violation(x) < 1e-6  # the dynamics hold in the plan
