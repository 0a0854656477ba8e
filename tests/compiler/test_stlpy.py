"""Differential test against stlpy's benchmark problems (Kurtz & Lin; 2-D double integrator).

stlpy's own MICP solvers need Gurobi or Drake, neither available here, so its encoding cannot be
solved: we maximise robustness with *our* encoding (HiGHS) and check that stlpy's independent
``robustness()`` of our optimal trajectory equals our ρ*, which certifies ρ* is attained by a
real plan under stlpy's semantics. The specs come in two forms: stlpy's own formula trees
translated node for node into our AST (and/or with time shifts), and, for reach-avoid and the
door puzzle, written by hand with our temporal operators.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

stlpy = pytest.importorskip("stlpy")
from stlpy.STL import LinearPredicate, STLTree  # noqa: E402
from stlpy import benchmarks as bm  # noqa: E402

from twolevel.compiler.driver import encode  # noqa: E402
from twolevel.compiler.signals import AffineSignal  # noqa: E402
from twolevel.compiler.types import Requirement  # noqa: E402
from twolevel.milp.builder import ModelBuilder  # noqa: E402
from twolevel.milp.highs import solve_highs  # noqa: E402
from twolevel.milp.solution import Status  # noqa: E402
from twolevel.stl import ast  # noqa: E402

X_MIN, X_MAX = np.array([0.0, 0.0, -1.0, -1.0]), np.array([10.0, 10.0, 1.0, 1.0])
U_MAX = 0.5


def translate(f) -> ast.Node:  # type: ignore[no-untyped-def]
    """stlpy formula → our AST over signals y0..y5 (sample period 1)."""
    if isinstance(f, LinearPredicate):
        a = f.a.ravel()
        terms = [ast.Arith("*", ast.Num(float(a[i])), ast.Var(f"y{i}")) for i in np.flatnonzero(a)]
        lhs = terms[0]
        for t in terms[1:]:
            lhs = ast.Arith("+", lhs, t)
        return ast.Compare(">=", lhs, ast.Num(float(f.b[0])))
    assert isinstance(f, STLTree)
    kids = []
    for sub, k in zip(f.subformula_list, f.timesteps):
        g = translate(sub)
        kids.append(g if k == 0 else ast.Temporal("eventually", ast.Interval(float(k), float(k)), g))
    out = kids[0]
    for k in kids[1:]:
        out = ast.Binary(f.combination_type, out, k)
    return out


def plan(formula: ast.Node, x0: np.ndarray, T: int, time_limit: float = 60.0):
    """Maximise robustness at t = 0 over a T-step double-integrator plan; y = [x; u]."""
    b = ModelBuilder()
    xs = b.add_vars("x", 4 * T, np.tile(X_MIN, T), np.tile(X_MAX, T))  # x_1..x_T
    us = b.add_vars("u", 2 * (T + 1), -U_MAX, U_MAX)                  # u_0..u_T
    # x_{t+1} = A x_t + B u_t with A = [[I, I], [0, I]], B = [[0], [I]]
    rows, cols, vals, rhs = [], [], [], np.zeros(4 * T)
    for t in range(T):
        for i in range(4):
            r = 4 * t + i
            rows.append(r), cols.append(xs.start + r), vals.append(1.0)
            prev = [(i, 1.0)] + ([(i + 2, 1.0)] if i < 2 else [])
            for j, c in prev:
                if t == 0:
                    rhs[r] += c * x0[j]
                else:
                    rows.append(r), cols.append(xs.start + 4 * (t - 1) + j), vals.append(-c)
            if i >= 2:
                rows.append(r), cols.append(us.start + 2 * t + i - 2), vals.append(-1.0)
    b.add_rows("dyn", 4 * T, np.array(rows), np.array(cols), np.array(vals), rhs, rhs)
    n = b.n_cols
    sig = {f"y{i}": AffineSignal.of_columns(xs.start + 4 * np.arange(T) + i, n, past=[x0[i]])
           for i in range(4)}
    for i in range(2):
        sig[f"y{4 + i}"] = AffineSignal.of_columns(us.start + 2 * np.arange(T + 1) + i, n)
    t0 = time.perf_counter()
    enc = encode(b, [Requirement("spec", formula, (0,))], sig, 1.0, mode="robustness")
    m = b.build()
    t1 = time.perf_counter()
    sol = solve_highs(m, time_limit=time_limit, mip_gap=1e-9, options={"mip_abs_gap": 1e-9})
    assert sol.status is Status.OPTIMAL, sol.status
    x = sol.x
    X = np.vstack([x0, x[xs.idx].reshape(T, 4)])
    U = x[us.idx].reshape(T + 1, 2)
    y = np.hstack([X, U]).T  # stlpy's (d, T+1)
    return float(x[enc.rho]), y, enc, (t1 - t0, sol.solve_ms / 1e3)


def _check(spec, ours: ast.Node, x0, T) -> None:  # type: ignore[no-untyped-def]
    rho, y, enc, _ = plan(ours, np.asarray(x0, float), T)
    assert enc.binaries > 0
    assert spec.robustness(y, 0)[0] == pytest.approx(rho, abs=1e-6)
    # and stlpy's tree translated gives the same optimum
    rho2, y2, _, _ = plan(translate(spec), np.asarray(x0, float), T)
    assert rho2 == pytest.approx(rho, abs=1e-6)
    assert spec.robustness(y2, 0)[0] == pytest.approx(rho2, abs=1e-6)


def _inside(bounds) -> ast.Node:  # type: ignore[no-untyped-def]
    x0, x1, y0, y1 = (float(v) for v in bounds)
    px, py = ast.Var("y0"), ast.Var("y1")
    return ast.Binary("and", ast.Binary("and", ast.Compare(">=", px, ast.Num(x0)), ast.Compare("<=", px, ast.Num(x1))),
                      ast.Binary("and", ast.Compare(">=", py, ast.Num(y0)), ast.Compare("<=", py, ast.Num(y1))))


def test_reach_avoid_written_in_our_language() -> None:
    T = 15
    sc = bm.ReachAvoid(goal_bounds=(7, 8, 8, 9), obstacle_bounds=(3, 5, 4, 6), T=T)
    iv = ast.Interval(0.0, float(T))
    ours = ast.Binary("and", ast.Temporal("always", iv, ast.Not(_inside(sc.obstacle_bounds))),
                      ast.Temporal("eventually", iv, _inside(sc.goal_bounds)))
    _check(sc.GetSpecification(), ours, [1.0, 2.0, 0.0, 0.0], T)


@pytest.mark.slow
def test_door_puzzle_written_in_our_language() -> None:
    T = 20
    sc = bm.DoorPuzzle(T=T, N=1)
    iv = ast.Interval(0.0, float(T))
    obstacles = [sc.obs1_bounds, sc.obs2_bounds, sc.obs3_bounds, sc.obs4_bounds, sc.obs5_bounds]
    avoid = ast.Not(_inside(obstacles[0]))
    for o in obstacles[1:]:
        avoid = ast.Binary("and", avoid, ast.Not(_inside(o)))
    ours = ast.Binary("and", ast.Binary(
        "and", ast.Temporal("always", iv, avoid),
        ast.BinTemporal("until", iv, ast.Not(_inside(sc.door1_bounds)), _inside(sc.key1_bounds))),
        ast.Temporal("eventually", iv, _inside(sc.goal_bounds)))
    _check(sc.GetSpecification(), ours, [6.0, 1.0, 0.0, 0.0], T)


@pytest.mark.parametrize("name", [
    "either_or",
    pytest.param("narrow_passage", marks=pytest.mark.slow),
    pytest.param("stepping_stones", marks=pytest.mark.slow),
])
def test_stlpy_benchmark_trees(name: str) -> None:
    if name == "either_or":
        T = 15
        sc = bm.EitherOr(goal=(7, 8, 8, 9), target_one=(1, 2, 6, 7), target_two=(7, 8, 4.5, 5.5),
                         obstacle=(3, 5, 4, 6), T=T, T_dwell=4)
        x0 = [2.0, 2.0, 0.0, 0.0]
    elif name == "narrow_passage":
        T = 20
        sc = bm.NarrowPassage(T=T)
        x0 = [2.0, 2.0, 0.0, 0.0]
    else:
        T = 12
        sc = bm.SteppingStones(num_stones=10, T=T, seed=1)
        x0 = [2.0, 2.0, 0.0, 0.0]
    spec = sc.GetSpecification()
    rho, y, enc, _ = plan(translate(spec), np.asarray(x0), T)
    assert enc.binaries > 0
    assert spec.robustness(y, 0)[0] == pytest.approx(rho, abs=1e-6)
