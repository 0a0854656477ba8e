"""The encoding agrees with the offline monitor (the oracle) on random formulas and trajectories."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twolevel.compiler.driver import encode
from twolevel.compiler.types import Requirement
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.highs import solve_highs
from twolevel.milp.solution import Status
from twolevel.monitor.robustness import robustness

from helpers.milp_systems import DT, H, PAST, T, double_integrator, random_formula, rollout

NOW = PAST  # trace index of the current sample
SEEDS = range(120)


def _case(seed: int):
    rng = np.random.default_rng(seed)
    f = random_formula(rng, depth=int(rng.integers(1, 4)))
    p_past = rng.uniform(-2, 2, PAST + 1)
    v_past = rng.uniform(-1, 1, PAST + 1)
    c = rng.uniform(-2, 2, T)
    times = (NOW,) if rng.random() < 0.7 else (NOW, NOW + 2)
    return rng, f, p_past, v_past, c, times


def _monitor(f, p, v, c, times):
    rho = robustness(f, {"p": p, "v": v, "c": c}, DT)
    return min(float(rho[t]) for t in times)


@pytest.mark.parametrize("seed", SEEDS)
def test_satisfaction_of_a_fixed_trajectory_matches_the_monitor(seed: int) -> None:
    rng, f, p_past, v_past, c, times = _case(seed)
    acc = rng.uniform(-2, 2, H)
    p_fut, v_fut = rollout(p_past[-1], v_past[-1], acc)
    if np.abs(p_fut).max() > 9.5:
        pytest.skip("trajectory leaves the bounds")
    p, v = np.concatenate([p_past, p_fut]), np.concatenate([v_past, v_fut])
    rho = _monitor(f, p, v, c, times)
    if abs(rho) < 1e-3 or math.isinf(rho):
        pytest.skip("too close to the boundary, or infinite")
    b = ModelBuilder()
    pb, vb, ab, sig = double_integrator(b, p_past, v_past)
    sig["c"] = c
    enc = encode(b, [Requirement("r", f, times)], sig, DT, mode="satisfaction")
    assert not enc.diagnostics or all(d.code == "MIL503" for d in enc.diagnostics)
    m = b.build()
    # fix the trajectory after building: big-M comes from the wide bounds, rows are exercised
    m.lb[ab.idx] = m.ub[ab.idx] = acc
    sol = solve_highs(m)
    assert sol.status in (Status.OPTIMAL, Status.INFEASIBLE)
    assert (sol.status is Status.OPTIMAL) == (rho >= 1e-4), (f, rho, sol.status)


@pytest.mark.parametrize("seed", SEEDS)
def test_optimal_robustness_equals_the_monitor_of_the_plan(seed: int) -> None:
    rng, f, p_past, v_past, c, times = _case(seed)
    b = ModelBuilder()
    pb, vb, ab, sig = double_integrator(b, p_past, v_past)
    sig["c"] = c
    enc = encode(b, [Requirement("r", f, times)], sig, DT, mode="robustness")
    m = b.build()
    sol = solve_highs(m, mip_gap=1e-9, options={"mip_abs_gap": 1e-9})
    if enc.infeasible:
        assert sol.status is Status.INFEASIBLE
        return
    assert sol.status is Status.OPTIMAL
    x = sol.x
    p = np.concatenate([p_past, x[pb.idx]])
    v = np.concatenate([v_past, x[vb.idx]])
    rho = _monitor(f, p, v, c, times)
    if math.isinf(rho):
        pytest.skip("infinite robustness (trivially true or false formula)")
    assert x[enc.rho] == pytest.approx(rho, abs=1e-6), f
    # the dynamics hold in the plan
    assert m.violation(x) < 1e-6
