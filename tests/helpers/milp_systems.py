"""Shared fixtures for the MILC tests: a 1-D double integrator and random formulas."""

from __future__ import annotations

import numpy as np

from twolevel.compiler.signals import AffineSignal
from twolevel.milp.builder import ModelBuilder
from twolevel.stl import ast

DT = 0.1
PAST = 3   # constant past samples
H = 8      # horizon steps
T = PAST + H + 1  # trace: past, now (constant), H decision steps
P_BOUND, V_BOUND, A_BOUND = 10.0, 4.0, 2.0


def double_integrator(builder: ModelBuilder, p_past: np.ndarray, v_past: np.ndarray):
    """Decision variables p_1..p_H, v_1..v_H, a_0..a_{H-1} with exact Euler dynamics; the trace
    signals p, v are the past (PAST samples + now, constant) followed by the decision steps."""
    p = builder.add_vars("p", H, -P_BOUND, P_BOUND)
    v = builder.add_vars("v", H, -V_BOUND, V_BOUND)
    a = builder.add_vars("a", H, -A_BOUND, A_BOUND)
    # p_{k+1} = p_k + dt v_k ; v_{k+1} = v_k + dt a_k, k = 0..H-1 (p_0, v_0 known)
    lo = np.zeros(2 * H)
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    for k in range(H):
        # position row k
        rows.append(k), cols.append(p.start + k), vals.append(1.0)
        if k > 0:
            rows += [k, k]
            cols += [p.start + k - 1, v.start + k - 1]
            vals += [-1.0, -DT]
        else:
            lo[k] = p_past[-1] + DT * v_past[-1]
        # velocity row H + k
        rows.append(H + k), cols.append(v.start + k), vals.append(1.0)
        rows.append(H + k), cols.append(a.start + k), vals.append(-DT)
        if k > 0:
            rows.append(H + k), cols.append(v.start + k - 1), vals.append(-1.0)
        else:
            lo[H + k] = v_past[-1]
    builder.add_rows("dyn", 2 * H, np.array(rows), np.array(cols), np.array(vals), lo, lo)
    n = builder.n_cols
    sig = {
        "p": AffineSignal.of_columns(p.idx, n, past=p_past),
        "v": AffineSignal.of_columns(v.idx, n, past=v_past),
    }
    return p, v, a, sig


def with_known(p_past: np.ndarray, v_past: np.ndarray, c: np.ndarray):
    """The :func:`double_integrator` with a signal ``c`` known over the whole trace, as the
    oracle checks of :mod:`helpers.milp_oracle` take it (``builder`` → blocks and signals)."""
    def add(builder: ModelBuilder):
        pb, vb, ab, sig = double_integrator(builder, p_past, v_past)
        sig["c"] = c
        return pb, vb, ab, sig
    return add


def rollout(p0: float, v0: float, acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p, v = [p0], [v0]
    for a in acc:
        p.append(p[-1] + DT * v[-1])
        v.append(v[-1] + DT * a)
    return np.array(p[1:]), np.array(v[1:])


def _iv(rng: np.random.Generator) -> ast.Interval:
    a = int(rng.integers(0, 3))
    b = a + int(rng.integers(0, 4))
    return ast.Interval(a * DT, b * DT)


def _term(rng: np.random.Generator) -> ast.Node:
    kind = rng.integers(0, 5)
    if kind == 0:
        return ast.Var("p")
    if kind == 1:
        return ast.Var("v")
    if kind == 2:
        return ast.Arith("+", ast.Var("p"), ast.Arith("*", ast.Num(round(float(rng.uniform(-1, 1)), 2)), ast.Var("v")))
    if kind == 3:
        return ast.Arith("-", ast.Var("p"), ast.Var("c"))
    return ast.Abs(ast.Arith("-", ast.Var("v"), ast.Num(round(float(rng.uniform(-1, 1)), 2))))


def random_formula(rng: np.random.Generator, depth: int = 3) -> ast.Node:
    """A random formula of the language over p, v (decision-dependent) and c (known)."""
    if depth == 0 or rng.random() < 0.25:
        op = ["<", "<=", ">", ">=", "==", "!=="][int(rng.choice(6, p=[.25, .2, .25, .2, .05, .05]))]
        return ast.Compare(op, _term(rng), ast.Num(round(float(rng.uniform(-3, 3)), 2)))
    k = int(rng.integers(0, 17))
    sub = lambda: random_formula(rng, depth - 1)  # noqa: E731
    if k == 0:
        return ast.Not(sub())
    if k in (1, 2, 3):
        return ast.Binary(["and", "or", "implies"][k - 1], sub(), sub())
    if k == 4:
        return ast.Binary(["iff", "xor"][int(rng.integers(0, 2))], sub(), sub())
    if k in (5, 6, 7, 8):
        op = ["always", "eventually", "historically", "once"][k - 5]
        return ast.Temporal(op, _iv(rng) if rng.random() < 0.8 else None, sub())
    if k in (9, 10):
        return ast.Temporal(["next", "prev"][k - 9], None, sub())
    if k in (11, 12):
        return ast.Edge(["rise", "fall"][k - 11], sub())
    if k == 13:
        return ast.BoolConst(bool(rng.integers(0, 2))) if rng.random() < 0.3 else ast.Binary("or", sub(), sub())
    op = ["until", "since", "unless"][k - 14]
    return ast.BinTemporal(op, _iv(rng) if rng.random() < 0.8 else None, sub(), sub())
