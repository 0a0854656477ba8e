"""The mode search's branch-and-bound is exact: on random formulas over a double integrator it
reaches HiGHS's MILP optimum (linear cost) and the best of every mode enumerated (quadratic cost)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from helpers.milp_systems import DT, H, T, double_integrator, random_formula
from twolevel.compiler.driver import encode
from twolevel.compiler.types import Requirement
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.clarabel import FixedModeQP
from twolevel.milp.highs import solve_highs
from twolevel.milp.modes import ModeSearch, ModeStatus
from twolevel.milp.solution import Status


def _model(seed: int, quadratic: bool, depth: int = 3):
    rng = np.random.default_rng(seed)
    b = ModelBuilder()
    p_past = rng.uniform(-2, 2, 4)
    v_past = rng.uniform(-1, 1, 4)
    p, v, a, sig = double_integrator(b, p_past, v_past)
    sig["c"] = rng.uniform(-2, 2, T)
    reqs = [Requirement(f"r{i}", random_formula(rng, depth), (3,)) for i in range(2)]
    enc = encode(b, reqs, sig, DT)
    if quadratic:
        import scipy.sparse as sp
        F = sp.csr_matrix((np.ones(2 * H), (np.arange(2 * H), np.concatenate([p.idx, a.idx]))), shape=(2 * H, b.n_cols))
        b.add_residuals(F, np.concatenate([rng.uniform(-3, 3, H), np.zeros(H)]), 1.0)
    else:
        b.add_linear_cost(np.concatenate([p.idx, a.idx]), rng.uniform(-1, 1, 2 * H))
    return b.build(), enc


@pytest.mark.parametrize("seed", range(40))
def test_bnb_to_completion_matches_highs_on_linear_costs(seed: int) -> None:
    m, enc = _model(seed, quadratic=False)
    if enc.diagnostics and any(d.is_error for d in enc.diagnostics):
        pytest.skip("formula not encodable")
    ref = solve_highs(m, mip_gap=1e-9)
    ms = ModeSearch(FixedModeQP(m))
    r = ms.run(budget_ms=None, bnb_gap=1e-9)
    if ref.status is Status.INFEASIBLE:
        assert r.status == "infeasible" and r.certified
        return
    assert ref.status is Status.OPTIMAL
    assert r.status is ModeStatus.OPTIMAL and r.certified
    assert r.cost == pytest.approx(ref.objective, rel=1e-5, abs=1e-5)
    assert m.violation(r.x) < 1e-5


@pytest.mark.parametrize("seed", range(100))
def test_bnb_to_completion_is_the_best_mode_on_quadratic_costs(seed: int) -> None:
    m, enc = _model(seed, quadratic=True, depth=2)  # depth 2: every mode can be enumerated
    qp = FixedModeQP(m)
    ms = ModeSearch(qp)
    if enc.infeasible:  # false by the constants: the search must say so, not invent a plan
        assert ms.run(budget_ms=None, bnb_gap=1e-9).status == "infeasible"
        return
    if np.prod(ms.size) > 4096 or ms.nested.size:
        pytest.skip("too many modes to enumerate, or nested disjunctions (not a plain product)")
    best = np.inf
    allowed = ms.allowed()
    for combo in itertools.product(*[range(k) for k in ms.size]):
        ch = np.array(combo, dtype=np.int64)
        if not allowed[ms.gstart[:-1] + ch].all():
            continue
        best = min(best, ms.solve_mode(ch)[0])
    r = ms.run(budget_ms=None, bnb_gap=1e-9)
    if not np.isfinite(best):
        assert r.status == "infeasible"
        return
    assert r.status == "optimal"
    assert r.cost == pytest.approx(best, rel=1e-6, abs=1e-6)
    # the heuristic phase alone (no B&B) finds a feasible mode whenever one exists
    assert np.isfinite(ms.run(budget_ms=None, bnb=False).cost) or r.nodes > 0


def test_adopted_readoff_is_that_modes_optimum() -> None:
    """When the lower bound's point already satisfies the read-off mode, the search takes it
    without a second QP: it must be what solving that mode gives, and feasible."""
    adopted = 0
    for seed in range(120):
        m, enc = _model(seed, quadratic=True, depth=2)
        if enc.infeasible or any(d.is_error for d in enc.diagnostics):
            continue
        ms = ModeSearch(FixedModeQP(m))
        r = ms.run(budget_ms=None, bnb=False)
        if ms.D == 0 or r.x is None or r.qps != 1:
            continue
        adopted += 1
        ms.reset()
        c, _, _ = ms.solve_mode(r.mode)
        assert r.cost == pytest.approx(c, rel=1e-6, abs=1e-6)
        assert m.violation(r.x) <= 1e-6
    assert adopted >= 3  # 7 of these 120 seeds


def test_statuses_read_as_the_strings_they_replace() -> None:
    """Statuses are enums that print, serialise and look up as their values (the trace, run.json
    and the plan's JSON write them)."""
    import json

    for st in (*ModeStatus, *Status):
        assert st == st.value and f"{st}" == str(st) == st.value
        assert json.dumps({st: st}) == json.dumps({st.value: st.value})
        assert {st.value: 1}[st] == 1
