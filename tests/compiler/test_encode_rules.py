"""Folding, big-M from bounds, collision_free pruning and geometry."""

from __future__ import annotations

import numpy as np
import pytest

from twolevel.compiler.collision import collision_free_builtin, reachable_box
from twolevel.compiler.driver import encode
from twolevel.compiler.signals import AffineSignal
from twolevel.compiler.types import Requirement
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.highs import solve_highs
from twolevel.milp.solution import Status
from twolevel.stl import ast

from helpers.milp_systems import DT, H, PAST, T, double_integrator, random_formula

NOW = PAST
P, V = ast.Var("p"), ast.Var("v")


def _num(x: float) -> ast.Num:
    return ast.Num(x)


def _di(light: np.ndarray | None = None):
    b = ModelBuilder()
    pb, vb, ab, sig = double_integrator(b, np.zeros(PAST + 1), np.zeros(PAST + 1))
    if light is not None:
        sig["light"] = light
    return b, sig


def test_rule_with_a_known_false_activation_adds_nothing() -> None:
    # (light > 0) -> eventually[0,0.5] (p >= 1): light is known and off
    f = ast.Binary("implies", ast.Compare(">", ast.Var("light"), _num(0.0)),
                   ast.Temporal("eventually", ast.Interval(0.0, 0.5), ast.Compare(">=", P, _num(1.0))))
    b, sig = _di(np.full(T, -1.0))
    rows0, cols0 = b.n_rows, b.n_cols
    enc = encode(b, [Requirement("stop", f, tuple(range(NOW, T)))], sig, DT)
    assert (enc.rows, enc.binaries, enc.continuous) == (0, 0, 0)
    assert (b.n_cols, b.n_rows) == (cols0, rows0 + 0)
    # the same rule with the light on needs a disjunction
    b2, sig2 = _di(np.full(T, 1.0))
    enc2 = encode(b2, [Requirement("stop", f, (NOW,))], sig2, DT)
    assert enc2.binaries > 0 and enc2.disjunctions == 1


def test_trivially_true_disjunct_removes_the_disjunction() -> None:
    f = ast.Binary("or", ast.Compare(">", ast.Var("light"), _num(0.0)), ast.Compare(">=", P, _num(1.0)))
    b, sig = _di(np.full(T, 2.0))
    enc = encode(b, [Requirement("r", f, tuple(range(NOW, T)))], sig, DT)
    assert enc.binaries == 0 and enc.rows == 0


def test_a_conjunction_needs_no_binaries_in_satisfaction_mode() -> None:
    f = ast.Temporal("always", ast.Interval(0.0, 0.8), ast.Binary(
        "and", ast.Compare("<=", P, _num(3.0)), ast.Compare("<=", ast.Abs(V), _num(2.0))))
    b, sig = _di()
    enc = encode(b, [Requirement("r", f, (NOW,))], sig, DT)
    assert enc.binaries == 0 and enc.rows > 0


def test_constant_violation_is_reported_and_infeasible() -> None:
    f = ast.Compare(">", ast.Var("light"), _num(0.0))
    b, sig = _di(np.full(T, -1.0))
    enc = encode(b, [Requirement("r", f, (NOW,))], sig, DT)
    assert enc.infeasible and [d.code for d in enc.diagnostics] == ["MIL503"]
    assert solve_highs(b.build()).status is Status.INFEASIBLE


def test_nonlinear_predicate_is_a_diagnostic() -> None:
    f = ast.Compare("<=", ast.Arith("*", P, V), _num(1.0))
    b, sig = _di()
    enc = encode(b, [Requirement("r", f, (NOW + 1,))], sig, DT)
    assert [d.code for d in enc.diagnostics] == ["MIL501"]


@pytest.mark.parametrize("seed", range(40))
def test_big_m_is_finite_and_derived_from_bounds(seed: int) -> None:
    rng = np.random.default_rng(1000 + seed)
    f = random_formula(rng, depth=3)
    b, sig = _di()
    sig["c"] = rng.uniform(-2, 2, T)
    for mode in ("satisfaction", "robustness"):
        enc = encode(b, [Requirement("r", f, (NOW,))], sig, DT, mode=mode)
    m = b.build()
    A = m.A.tocsc()
    ints = np.flatnonzero(m.integrality)
    coefs = np.abs(A[:, ints].data) if ints.size else np.zeros(0)
    cont = ~m.integrality
    ranges = (m.ub - m.lb)[cont]
    assert np.all(np.isfinite(coefs))
    # every |M| is below 10x the largest variable range (20 m for p) times the largest coefficient
    assert coefs.size == 0 or coefs.max() <= 10 * ranges[np.isfinite(ranges)].max() * 2.5


# ----------------------------------------------------------------------------- collision_free


def _ego(b: ModelBuilder, x0: float, y0: float, vmax: float):
    xs = b.add_vars("x", H, -1e3, 1e3)
    ys = b.add_vars("y", H, -1e3, 1e3)
    lo, hi = reachable_box(x0, -vmax, vmax, DT, H)
    b.tighten(xs.idx, lo, hi)
    lo, hi = reachable_box(y0, -vmax, vmax, DT, H)
    b.tighten(ys.idx, lo, hi)
    n = b.n_cols
    sig = {"x": AffineSignal.of_columns(xs.idx, n, past=[x0]),
           "y": AffineSignal.of_columns(ys.idx, n, past=[y0])}
    return xs, ys, sig


CF = ast.Call("collision_free", (ast.Num(2.0),))


def test_vehicle_step_pairs_out_of_reach_are_dropped() -> None:
    b = ModelBuilder()
    xs, ys, sig = _ego(b, 0.0, 0.0, vmax=10.0)  # reach after k steps: 1·k m per axis
    others = np.full((3, H + 1, 2), np.nan)
    others[0] = (100.0, 0.0)               # never within reach
    others[1] = (4.0, 0.0)                 # ego reaches x ≥ 2 from step 3 on (1-norm ≤ 2 needs x ≥ 2)
    others[2, :, 0] = np.linspace(50, 5, H + 1)  # approaching along x
    others[2, :, 1] = 30.0
    enc = encode(b, [Requirement("cf", CF, tuple(range(1, H + 1)))], sig, DT,
                 builtins={"collision_free": collision_free_builtin("x", "y", others)})
    assert not enc.diagnostics
    # only vehicle 1, from step 2 on: the least 1-norm distance from the ego's box [-k, k]² to
    # (4, 0) is 4 - k, which is below d + eps = 2 + 1e-4 from k = 2; faces that can never hold
    # are removed too (at k = 2 only the two faces looking back at the ego remain)
    m = b.build()
    kept = [d for d in m.disjunctions]
    steps = sorted(int(d.label.split("@")[1]) for d in kept)
    assert steps == list(range(2, H + 1))
    assert kept[0].size == 2 and kept[-1].size == 4
    assert all(2 <= d.size <= 4 for d in kept)
    # nothing from vehicles 0 and 2
    assert enc.binaries == sum(d.size for d in kept)


def _plan_through(y_offset: float) -> Status:
    b = ModelBuilder()
    xs, ys, sig = _ego(b, 0.0, y_offset, vmax=60.0)
    others = np.zeros((1, H + 1, 2))
    others[0, :, 0] = 2.0 + 0.0 * np.arange(H + 1)  # stationary at (2, 0)
    encode(b, [Requirement("cf", CF, tuple(range(1, H + 1)))], sig, DT,
           builtins={"collision_free": collision_free_builtin("x", "y", others)})
    m = b.build()
    path = np.linspace(0.0, 4.0, H + 1)[1:]
    m.lb[xs.idx] = m.ub[xs.idx] = path
    m.lb[ys.idx] = m.ub[ys.idx] = y_offset
    return solve_highs(m).status


def test_a_plan_through_a_vehicle_is_infeasible_and_around_it_feasible() -> None:
    assert _plan_through(0.0) is Status.INFEASIBLE
    assert _plan_through(0.5) is Status.INFEASIBLE  # |dy| + |dx| = 0.5 at x = 2
    assert _plan_through(2.5) is Status.OPTIMAL


def test_collision_free_robustness_matches_the_diamond() -> None:
    b = ModelBuilder()
    xs, ys, sig = _ego(b, 0.0, 0.0, vmax=20.0)
    others = np.zeros((2, H + 1, 2))
    others[0] = (3.0, 1.0)
    others[1] = (-2.0, -2.0)
    f = ast.Temporal("always", None, CF)
    enc = encode(b, [Requirement("cf", f, (0,))], sig, DT, mode="robustness",
                 builtins={"collision_free": collision_free_builtin("x", "y", others)})
    m = b.build()
    sol = solve_highs(m, mip_gap=1e-9)
    assert sol.status is Status.OPTIMAL
    x = np.concatenate([[0.0], sol.x[xs.idx]])
    y = np.concatenate([[0.0], sol.x[ys.idx]])
    d1 = np.abs(x[:, None] - others[:, :, 0].T) + np.abs(y[:, None] - others[:, :, 1].T)
    assert sol.x[enc.rho] == pytest.approx(float(d1.min() - 2.0), abs=1e-6)


@pytest.mark.parametrize("margin", [0.0, 0.02, 0.05])
def test_a_rule_with_a_margin_holds_that_far_inside_its_bound(margin: float) -> None:
    """``margins`` {name: m}: that rule is required with robustness ≥ eps + m, the others with eps."""
    b = ModelBuilder()
    pb, vb, ab, sig = double_integrator(b, np.zeros(PAST + 1), np.zeros(PAST + 1))
    b.add_linear_cost(np.array([pb.start + 4]), -1.0)  # push p_5 as far as the rules let it
    b.add_linear_cost(np.array([vb.start + 7]), -1.0)  # and v_8
    reqs = [Requirement("near", ast.Compare("<=", P, _num(0.1)), (NOW + 5,)),
            Requirement("slow", ast.Compare("<=", V, _num(0.5)), (NOW + 8,))]
    eps = 1e-4
    enc = encode(b, reqs, sig, DT, eps=eps, margins={"near": margin})
    assert not enc.infeasible
    sol = solve_highs(b.build())
    assert sol.status is Status.OPTIMAL
    assert sol.x[pb.start + 4] == pytest.approx(0.1 - eps - margin, abs=1e-6)
    assert sol.x[vb.start + 7] == pytest.approx(0.5 - eps, abs=1e-6)


@pytest.mark.parametrize("margin", [0.02, 0.05, 0.12, 0.15])
def test_a_margin_is_dropped_only_at_a_step_whose_known_value_leaves_no_room_for_it(margin: float) -> None:
    """``near`` (p ≤ 0.1) at the step now, where p = 0 is known, has robustness 0.1: a margin
    that fits is required, one beyond it falls back to the plain eps at that step (listed in
    ``unmargined``) instead of making the encoding infeasible, and later steps keep it."""
    b = ModelBuilder()
    pb, vb, ab, sig = double_integrator(b, np.zeros(PAST + 1), np.zeros(PAST + 1))
    b.add_linear_cost(np.array([pb.start + 4]), -1.0)
    near = ast.Compare("<=", P, _num(0.1))
    eps = 1e-4
    enc = encode(b, [Requirement("near", near, (NOW, NOW + 5))], sig, DT, eps=eps, margins={"near": margin})
    assert not enc.infeasible
    assert enc.unmargined == ([] if eps + margin <= 0.1 else [("near", NOW)])
    sol = solve_highs(b.build())
    assert sol.status is Status.OPTIMAL
    assert sol.x[pb.start + 4] == pytest.approx(0.1 - eps - margin, abs=1e-6)


def test_a_margin_in_robustness_mode_shifts_the_maximised_robustness() -> None:
    """In robustness mode ρ ≤ robustness − m for a rule with margin m: the maximised ρ is the
    plan's robustness of that rule less its margin."""
    b = ModelBuilder()
    pb, vb, ab, sig = double_integrator(b, np.zeros(PAST + 1), np.zeros(PAST + 1))
    reqs = [Requirement("near", ast.Compare("<=", P, _num(0.1)), (NOW + 5,))]
    enc = encode(b, reqs, sig, DT, mode="robustness", margins={"near": 0.05}, rho_bounds=(-10.0, 10.0))
    sol = solve_highs(b.build())
    assert sol.status is Status.OPTIMAL
    assert sol.x[enc.rho] == pytest.approx(0.1 - sol.x[pb.start + 4] - 0.05, abs=1e-6)
