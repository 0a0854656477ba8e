"""Assembly and solve times of one horizon-10 MILC model (2-D double integrator ego, N nearby
vehicles with collision_free, a speed rule, least-squares tracking cost). Prints figures."""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from twolevel.compiler.collision import collision_free_builtin, reachable_box
from twolevel.compiler.driver import encode
from twolevel.compiler.signals import AffineSignal
from twolevel.compiler.types import Requirement
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.clarabel import FixedModeQP
from twolevel.milp.highs import solve_highs
from twolevel.milp.l1_surrogate import l1_surrogate
from twolevel.milp.model import PatternCache
from twolevel.stl import ast

H, DT, VMAX = 10, 0.1, 15.0
CF = ast.Temporal("always", None, ast.Call("collision_free", (ast.Num(5.0),)))
SPEED = ast.Temporal("always", None, ast.Compare("<=", ast.Var("vx"), ast.Var("vmax")))


def build(others: np.ndarray, x0: np.ndarray, cache: PatternCache | None):
    b = ModelBuilder()
    p = b.add_vars("pos", 2 * H, -1e3, 1e3)   # x_k, y_k interleaved, k = 1..H
    v = b.add_vars("vel", 2 * H, -VMAX, VMAX)
    u = b.add_vars("acc", 2 * H, -4.0, 4.0)
    xi, yi = p.start + 2 * np.arange(H), p.start + 2 * np.arange(H) + 1
    for c, i in ((xi, 0), (yi, 1)):
        lo, hi = reachable_box(x0[i], -VMAX, VMAX, DT, H)
        b.tighten(c, lo, hi)
    # dynamics, vectorised: p_k - p_{k-1} - dt v_{k-1} = 0, v_k - v_{k-1} - dt u_{k-1} = 0
    k = np.arange(2 * H)
    prev = k - 2
    r = np.concatenate([k, k[2:], k[2:], 2 * H + k, 2 * H + k[2:], 2 * H + k])
    c = np.concatenate([p.start + k, p.start + prev[2:], v.start + prev[2:], v.start + k,
                        v.start + prev[2:], u.start + k])
    val = np.concatenate([np.ones(2 * H), -np.ones(2 * H - 2), -DT * np.ones(2 * H - 2),
                          np.ones(2 * H), -np.ones(2 * H - 2), -DT * np.ones(2 * H)])
    rhs = np.zeros(4 * H)
    rhs[:2] = x0[:2] + DT * x0[2:]
    rhs[2 * H: 2 * H + 2] = x0[2:]
    b.add_rows("dyn", 4 * H, r, c, val, rhs, rhs)
    n = b.n_cols
    ref = np.stack([x0[0] + 10.0 * DT * np.arange(1, H + 1), np.zeros(H)], 1).ravel()
    F = sp.vstack([sp.csr_matrix((np.ones(2 * H), (k, p.start + k)), shape=(2 * H, n)),
                   sp.csr_matrix((np.ones(2 * H), (k, u.start + k)), shape=(2 * H, n))])
    b.add_residuals(F, np.concatenate([ref, np.zeros(2 * H)]), np.concatenate([np.ones(2 * H), 0.1 * np.ones(2 * H)]))
    sig = {"x": AffineSignal.of_columns(xi, n, past=[x0[0]]), "y": AffineSignal.of_columns(yi, n, past=[x0[1]]),
           "vx": AffineSignal.of_columns(v.start + 2 * np.arange(H), n, past=[x0[2]]),
           "vmax": np.full(H + 1, 12.0)}
    enc = encode(b, [Requirement("cf", CF, (0,)), Requirement("speed", SPEED, (0,))], sig, DT,
                 builtins={"collision_free": collision_free_builtin("x", "y", others)})
    return b.build(cache), enc


def main() -> None:
    rng = np.random.default_rng(0)
    for N in (0, 6, 18):
        others = np.zeros((N, H + 1, 2))
        pos = np.stack([rng.uniform(5, 60, N), rng.choice([-3.5, 0.0, 3.5], N)], 1)
        vel = np.stack([rng.uniform(0, 8, N), np.zeros(N)], 1)
        for i in range(N):
            others[i] = pos[i] + vel[i] * DT * np.arange(H + 1)[:, None]
        x0 = np.array([0.0, 0.0, 10.0, 0.0])
        cache = PatternCache()
        build(others, x0, cache)
        ts = []
        for _ in range(20):
            t0 = time.perf_counter()
            m, enc = build(others, x0, cache)
            ts.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        lin = l1_surrogate(m)
        t_l1 = time.perf_counter() - t0
        s = solve_highs(lin, time_limit=5.0)
        qp = FixedModeQP(m)
        xi = s.x[: m.n_cols][qp.ints] if s.x is not None else np.zeros(qp.ints.size)
        r1 = qp.solve(xi)
        r2 = qp.solve(xi)  # same object: in-place update path
        print(f"N={N:2d} rows={m.n_rows} cols={m.n_cols} binaries={enc.binaries} "
              f"disjunctions={enc.disjunctions} | encode+build median {np.median(ts)*1e3:.2f} ms "
              f"(cache hits {cache.hits}) | L1 transform {t_l1*1e3:.2f} ms | HiGHS {s.status.value} "
              f"{s.setup_ms + s.solve_ms:.1f} ms | Clarabel first {r1.setup_ms + r1.solve_ms:.2f} ms, "
              f"updated {r2.setup_ms + r2.solve_ms:.2f} ms ({r2.status.value}, cost {r2.objective:.3f})")


if __name__ == "__main__":
    main()
