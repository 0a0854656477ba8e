"""Model assembly, pattern cache, HiGHS/Clarabel backends, the L1 surrogate and model export."""

from __future__ import annotations


import numpy as np
import pytest

from twolevel.compiler.driver import encode
from twolevel.compiler.types import Requirement
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.clarabel import CAPABILITIES as CLARABEL, FixedModeQP
from twolevel.milp.highs import CAPABILITIES as HIGHS, solve_highs, write_model
from twolevel.milp.l1_surrogate import l1_surrogate
from twolevel.milp.model import PatternCache
from twolevel.milp.solution import Status
from twolevel.stl import ast

from helpers.milp_systems import DT, H, PAST, double_integrator

NOW = PAST
P = ast.Var("p")
# be at p >= 0.45 or at p <= 0.05 at some step in [0.3, 0.6] s; always |v| <= 3
RULE = ast.Binary("and",
    ast.Temporal("eventually", ast.Interval(0.3, 0.6), ast.Binary(
        "or", ast.Compare(">=", P, ast.Num(0.45)), ast.Compare("<=", P, ast.Num(0.05)))),
    ast.Temporal("always", None, ast.Compare("<=", ast.Abs(ast.Var("v")), ast.Num(3.0))))


def _mpc(p0: float = 0.3, ref: float = 0.3, cache: PatternCache | None = None):
    b = ModelBuilder()
    pb, vb, ab, sig = double_integrator(b, np.full(PAST + 1, p0), np.zeros(PAST + 1))
    import scipy.sparse as sp
    n = b.n_cols
    # cost: sum (p_k - ref)^2 + 0.1 a_k^2
    F = sp.vstack([sp.csr_matrix((np.ones(H), (np.arange(H), pb.idx)), shape=(H, n)),
                   sp.csr_matrix((np.ones(H), (np.arange(H), ab.idx)), shape=(H, n))])
    b.add_residuals(F, np.concatenate([np.full(H, ref), np.zeros(H)]),
                    np.concatenate([np.ones(H), 0.1 * np.ones(H)]))
    enc = encode(b, [Requirement("r", RULE, (NOW,))], sig, DT)
    return b.build(cache), (pb, vb, ab), enc


def _reference_qp(model, x_int):
    """The fixed-mode QP solved by HiGHS's QP solver (binaries fixed by bounds)."""
    import highspy
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    lb, ub = model.lb.copy(), model.ub.copy()
    ints = np.flatnonzero(model.integrality)
    lb[ints] = ub[ints] = x_int
    A = model.A
    h.passModel(model.n_cols, model.n_rows, A.nnz, 1, 1, model.c0, model.q, lb, ub,
                model.row_lo, model.row_hi, A.indptr, A.indices, A.data,
                np.zeros(model.n_cols, np.int32))
    Pl = model.P.T.tocsc()  # HiGHS wants the lower triangle column-wise
    h.passHessian(model.n_cols, Pl.nnz, 1, Pl.indptr, Pl.indices, Pl.data)
    h.run()
    if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
        return None
    return h.getInfo().objective_function_value


def _one_hot_modes(model, qp: FixedModeQP, disjunctions=None) -> list[np.ndarray]:  # noqa: ANN001
    """The integer vectors (over ``qp.ints``) that switch on one disjunct each, over every
    disjunct of ``disjunctions`` (default: all of the model's)."""
    modes = []
    for d in model.disjunctions if disjunctions is None else disjunctions:
        for i in range(d.size):
            xi = np.zeros(qp.ints.size)
            xi[np.searchsorted(qp.ints, d.binaries[i])] = 1
            modes.append(xi)
    return modes


def test_exact_path_l1_mode_then_clarabel_polish() -> None:
    model, (pb, vb, ab), enc = _mpc()
    assert enc.binaries > 0 and model.P is not None
    lin = l1_surrogate(model)
    assert lin.P is None and lin.n_cols == model.n_cols + 2 * H
    s = solve_highs(lin, time_limit=10.0)
    assert s.status is Status.OPTIMAL
    qp = FixedModeQP(model)
    x_int = s.x[: model.n_cols][qp.ints]
    pol = qp.solve(x_int)
    assert pol.status is Status.OPTIMAL
    assert model.violation(pol.x) < 1e-6
    ref = _reference_qp(model, x_int)
    assert pol.objective == pytest.approx(ref, rel=1e-5, abs=1e-6)
    # the best of all modes is no better than... enumerate the modes of the one disjunction
    best = np.inf
    for xi in _one_hot_modes(model, qp):
        r = qp.solve(xi)
        if r.ok:
            best = min(best, r.objective)
            ref = _reference_qp(model, xi)
            assert r.objective == pytest.approx(ref, rel=1e-5, abs=1e-6)
    assert pol.objective >= best - 1e-6


def test_clarabel_update_in_place_equals_a_fresh_solver() -> None:
    cache = PatternCache()
    m1, _, _ = _mpc(p0=0.3, ref=0.5, cache=cache)
    m2, _, _ = _mpc(p0=0.25, ref=0.2, cache=cache)
    assert cache.hits == 1 and cache.misses == 1
    assert np.array_equal(m1.A.indptr, m2.A.indptr) and np.array_equal(m1.A.indices, m2.A.indices)
    qp = FixedModeQP(m1)
    modes = _one_hot_modes(m1, qp, m1.disjunctions[:1])
    first = [qp.solve(xi) for xi in modes]  # one solver object, updated per mode
    # switch the same object to the second model's values (same pattern)
    qp.model = m2
    second = [qp.solve(xi) for xi in modes]
    for xi, a, b in zip(modes, first, second):
        fa, fb = FixedModeQP(m1).solve(xi), FixedModeQP(m2).solve(xi)
        assert a.status == fa.status and b.status == fb.status
        if a.ok:
            assert a.objective == pytest.approx(fa.objective, rel=1e-6, abs=1e-7)
        if b.ok:
            assert b.objective == pytest.approx(fb.objective, rel=1e-6, abs=1e-7)
    assert sum(r.ok for r in first) >= 1


def test_lower_bound_with_every_disjunctive_row_disabled() -> None:
    model, _, _ = _mpc()
    qp = FixedModeQP(model)
    lb = qp.solve(np.zeros(qp.ints.size), disable=qp.disjunctive_rows())
    assert lb.ok
    # every feasible mode costs at least the bound
    for xi in _one_hot_modes(model, qp):
        r = qp.solve(xi)
        if r.ok:
            assert r.objective >= lb.objective - 1e-7


def test_infeasible_mode_is_reported() -> None:
    model, _, _ = _mpc()
    qp = FixedModeQP(model)
    r = qp.solve(np.zeros(qp.ints.size))  # no disjunct chosen: the cover row fails
    assert r.status is Status.INFEASIBLE


@pytest.mark.parametrize("suffix", ["mps", "lp"])
def test_written_model_reads_back_with_the_same_optimum(tmp_path, suffix: str) -> None:
    import highspy
    model, _, _ = _mpc()
    lin = l1_surrogate(model)
    path = tmp_path / f"model.{suffix}"
    write_model(lin, path)
    assert path.stat().st_size > 0
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.readModel(str(path))
    h.run()
    ours = solve_highs(lin)
    assert h.getInfo().objective_function_value == pytest.approx(ours.objective, rel=1e-6, abs=1e-6)


def test_block_update_in_place_changes_only_values() -> None:
    model, (pb, vb, ab), _ = _mpc()
    data_before = model.A.data.copy()
    tri, rows = model.row_blocks["dyn"]
    vals = model.triplet_values[tri].copy()
    model.set_block_values("dyn", vals * 2.0)
    assert not np.array_equal(model.A.data, data_before)
    model.set_block_values("dyn", vals)
    assert np.array_equal(model.A.data, data_before)
    model.set_row_bounds("dyn", 1.0, 1.0)
    assert np.all(model.row_lo[rows] == 1.0)


def test_highs_does_what_it_declares() -> None:
    """HiGHS branches on the binaries and minimises only the linear part of the cost."""
    assert HIGHS.integer and not HIGHS.quadratic
    model, _, _ = _mpc()
    assert model.P is not None and model.P.nnz
    s = solve_highs(model)
    assert s.ok
    ints = s.x[model.integrality]
    assert ints.size and np.allclose(ints, np.round(ints))
    assert s.objective == pytest.approx(float(model.q @ s.x) + model.c0, rel=1e-7, abs=1e-7)


def test_clarabel_does_what_it_declares() -> None:
    """Clarabel keeps the integer columns where the mode puts them and minimises the whole
    quadratic cost."""
    assert CLARABEL.quadratic and not CLARABEL.integer and CLARABEL.in_place_update
    model, _, _ = _mpc()
    qp = FixedModeQP(model)
    solved = [(xi, qp.solve(xi)) for xi in _one_hot_modes(model, qp)]
    solved = [(xi, r) for xi, r in solved if r.ok]
    assert solved
    for xi, r in solved:
        assert np.array_equal(r.x[qp.ints], xi)
        assert r.objective == pytest.approx(model.objective(r.x), rel=1e-9, abs=1e-9)
