"""The NMPC baseline's nonlinear program: one parametric casadi NLP per (model, shape), IPOPT.

Decision vector ``w`` = [X_1 … X_H (``nx`` each, k-major), U_0 … U_{H−1} ([δ, a] each)];
multiple shooting: X_{k+1} = F(X_k, U_k) with X_0 the parameter ``x0``.

Models (``F`` over one control period dt [s], input held):

* ``"kinematic"`` (nx = 4, [X, Y, ψ, v]): the exact zero-order-hold step of
  :func:`twolevel.models.bicycle.step`, the same equations
  (:func:`~twolevel.models.bicycle.step_columns`) through the casadi ops.
* ``"fourwheel"`` (nx = 12, :mod:`twolevel.models.fourwheel`): the detailed model's own
  integrator (:func:`~twolevel.models.fourwheel.substep`, through the casadi ops), ``n``
  internal steps per dt (default the model's ``h_int``, 20 at dt = 0.1 s), a → γ by
  :func:`~twolevel.models.actuation.gamma_from_accel` at the start of the step as
  :func:`twolevel.models.rollout.rollout_accel` does. Cost and rules read [X, Y, ψ, vx].

Parameter vector ``p`` (:class:`ParamLayout`): x0 (nx), u_prev (2), ω (H, 4), speed bound (H,),
stop bound (H, 4) = (n_x, n_y, b, c) for nᵀp_k + c·v_k² ≤ b, obstacle centres (N, H, 2) and shapes
(N, 4) = (cos ψ_i, sin ψ_i, 1/A_i, 1/B_i), the steering (H, 3) = (δ_ref,k, δ_ref,k−1, weight
factor_k) (δ_ref,−1: the route's steering one period ago).

Constraints ``g``, per step k = 1..H in this order (so duals shift with the plan):
dynamics (nx, = 0); v_k ≤ vbound_k; nᵀp_k + c_k·v_k² ≤ b_k (behind a stop line
and able to stop before it: c = 1/(2·deceleration); n = 0, b = 1, c = 0 when no line applies); for each obstacle the order-4 superellipse
((ξ/A)⁴ + (η/B)⁴ + ε)^¼ ≥ 1 in the obstacle's frame (ξ along its heading), which contains the
Minkowski sum of the two boxes grown by the distance d, scales like a distance, and is smooth.

Cost (the paper's, as :mod:`twolevel.control.high_level.problem`): Σ_k w_u‖u_k‖² + w_du‖u_k − u_{k−1}‖²
+ Σ_{k=1..H} Σ_i w_i (ζ_{k,i} − ω_{k,i})², with δ_k − δ_ref,k (the steering that follows the
route) and the steering's rate about the route's, (δ_k − δ_{k−1}) − (δ_ref,k − δ_ref,k−1), weighed
by the step's factor (:mod:`twolevel.control.high_level.steering`: the lateral jerk it causes;
a bend's onset costs nothing, else the plan entered a bend late: 5 cm off at 8 m/s; δ_ref = 0
and factor 1 give the paper's cost). Unlike the MPC's 5 s look-ahead, the baseline's 1 s horizon does not
weigh the lateral acceleration itself: within 1 s an offset's correction hardly pays, so the
plan would hardly steer and the offset would swing slowly (±5 cm after 30 s at 15 m/s).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from twolevel.control.high_level.settings import Weights
from twolevel.models import bicycle
from twolevel.models import fourwheel as fw
from twolevel.models.actuation import gamma_from_accel
from twolevel.models.ops import casadi_ops
from twolevel.models.params import BicycleParams, VehicleParams

__all__ = ["MODELS", "LADDER", "ParamLayout", "NlpSolution", "NmpcProblem", "bicycle_step_casadi"]

MODELS = ("kinematic", "fourwheel")
_EPS_SUPER = 1e-8  # keeps the ¼ power smooth at the obstacle's centre
SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")

LADDER: tuple[tuple[bool, bool], ...] = ((False, False), (True, True), (False, True))
"""The IPOPT attempts of one solve, each from the same point until one succeeds (the later ones
only with ``retry``, :meth:`NmpcProblem.solve`): (L-BFGS Hessian, the retry's iteration
budget) — the exact Hessian, then L-BFGS, then the exact Hessian for longer."""


def bicycle_step_casadi(x: Any, u: Any, dt: float, l_f: float) -> Any:
    """:func:`twolevel.models.bicycle.step` in casadi symbols: x (4,), u (2,) → x⁺ (4,) (the same
    equations, :func:`~twolevel.models.bicycle.step_columns`, through the casadi ops)."""
    import casadi as ca

    return ca.vertcat(*bicycle.step_columns(x[0], x[1], x[2], x[3], u[0], u[1], dt, l_f, casadi_ops()))


def _fourwheel_step_casadi(x: Any, u: Any, dt: float, p: VehicleParams, n: int) -> Any:
    import casadi as ca

    ops = casadi_ops()
    gamma = gamma_from_accel(u[1], x[3], p, ops)
    cols = [x[i] for i in range(fw.NX)]
    h = dt / n
    for _ in range(n):
        cols = fw.substep(cols, u[0], gamma, h, p, ops)
    return ca.vertcat(*cols)


@dataclass(frozen=True)
class ParamLayout:
    """Offsets of the parameter blocks in ``p`` (see the module docstring)."""

    nx: int
    H: int
    N: int

    @property
    def size(self) -> int:
        return self.nx + 2 + 4 * self.H + self.H + 4 * self.H + 2 * self.N * self.H + 4 * self.N + 3 * self.H

    def pack(self, x0: np.ndarray, u_prev: np.ndarray, omega: np.ndarray, vbound: np.ndarray, stop: np.ndarray,
             centres: np.ndarray, shapes: np.ndarray, steer: np.ndarray | None = None) -> np.ndarray:
        """One parameter vector from its blocks (shapes as in the module docstring; ``steer``
        None: the paper's steering terms, δ_ref = 0 and factor 1)."""
        if steer is None:
            steer = np.tile([0.0, 0.0, 1.0], (self.H, 1))
        return np.concatenate([np.ravel(x0), np.ravel(u_prev), np.ravel(omega), np.ravel(vbound), np.ravel(stop),
                               np.ravel(centres), np.ravel(shapes), np.ravel(steer)]).astype(float)


@dataclass(frozen=True, eq=False)
class NlpSolution:
    """IPOPT's answer: primal ``w``, duals ``lam_g``/``lam_x``, objective, IPOPT status, iterations,
    solver wall time [ms], whether it counts as solved, and the status of each attempt (the rungs
    of :data:`LADDER` tried)."""

    w: np.ndarray
    lam_g: np.ndarray
    lam_x: np.ndarray
    cost: float
    status: str
    iterations: int
    solve_ms: float
    success: bool
    attempts: tuple[str, ...] = ()


class NmpcProblem:
    """The NLP for one model and shape (H, N obstacles), built once; :meth:`solve` per step."""

    def __init__(self, model: str, *, H: int, dt: float, weights: Weights, bicycle: BicycleParams,
                 vehicle: VehicleParams, n_obstacles: int, substeps: int | None = None, max_iter: int = 30,
                 tol: float = 1e-6, max_cpu_time: float | None = None, expand: bool | None = None,
                 retry_max_iter: int = 100) -> None:
        import casadi as ca

        if model not in MODELS:
            raise ValueError(f"unknown NMPC model {model!r}; choose one of {', '.join(MODELS)}")
        self.model, self.H, self.dt, self.N = model, H, dt, n_obstacles
        self.nx = 4 if model == "kinematic" else fw.NX
        self.substeps = 1 if model == "kinematic" else (substeps or fw.substeps_per_step(dt, vehicle))
        nx, N = self.nx, n_obstacles
        self.layout = ParamLayout(nx, H, N)
        self.n_w = H * nx + 2 * H
        self.m = nx + 2 + N  # constraints per step

        xs = ca.SX.sym("x", nx)
        us = ca.SX.sym("u", 2)
        if model == "kinematic":
            nxt = bicycle_step_casadi(xs, us, dt, bicycle.l_f)
        else:
            nxt = _fourwheel_step_casadi(xs, us, dt, vehicle, self.substeps)
        self.F = ca.Function("shoot", [xs, us], [nxt])
        self._roll = self.F.mapaccum("roll", H)

        L = self.layout
        P = ca.MX.sym("p", L.size)
        o = 0

        def take(n: int) -> Any:
            nonlocal o
            blk = P[o:o + n]
            o += n
            return blk

        x0, u_prev = take(nx), take(2)
        omega = ca.reshape(take(4 * H), 4, H)  # column k = ω_{k+1}
        vb = take(H)
        stop = ca.reshape(take(4 * H), 4, H)
        cen = take(2 * N * H)  # (N, H, 2) row-major
        shp = ca.reshape(take(4 * N), 4, N)
        steer = ca.reshape(take(3 * H), 3, H)  # column k = (δ_ref,k, δ_ref,k−1, weight factor_k)

        W = ca.MX.sym("w", self.n_w)
        X = ca.reshape(W[: H * nx], nx, H)
        U = ca.reshape(W[H * nx:], 2, H)
        w_track = ca.DM(np.asarray(weights.track, float))
        J = 0
        g = []
        # the shooting function is called, not inlined: keeps the four-wheel graph small
        Xn = self.F.map(H)(ca.horzcat(x0, X[:, :-1]), U)
        for k in range(H):
            uk = U[:, k]
            du = uk - (u_prev if k == 0 else U[:, k - 1])
            zeta = ca.vertcat(X[0, k], X[1, k], X[2, k], X[3, k])
            e = zeta - omega[:, k]
            turn = du[0] - (steer[0, k] - steer[1, k])  # the steering's rate about the route's
            J += (weights.u * ((uk[0] - steer[0, k]) ** 2 + uk[1] ** 2)
                  + weights.du * (turn ** 2 * steer[2, k] + du[1] ** 2) + ca.dot(w_track, e * e))
            gk = [Xn[:, k] - X[:, k], vb[k] - X[3, k], stop[2, k] - stop[0, k] * X[0, k] - stop[1, k] * X[1, k] - stop[3, k] * X[3, k] ** 2]
            for i in range(N):
                base = 2 * (i * H + k)
                dx, dy = X[0, k] - cen[base], X[1, k] - cen[base + 1]
                c, s, ia, ib = shp[0, i], shp[1, i], shp[2, i], shp[3, i]
                xi = (c * dx + s * dy) * ia
                eta = (-s * dx + c * dy) * ib
                gk.append((xi**4 + eta**4 + _EPS_SUPER) ** 0.25 - 1.0)
            g.append(ca.vertcat(*gk))
        G = ca.vertcat(*g)
        self._nlp = {"x": W, "p": P, "f": J, "g": G}
        self._opts_base: dict[str, Any] = {
            "print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.max_iter": max_iter,
            "expand": (model == "kinematic") if expand is None else expand, "ipopt.tol": tol, "ipopt.acceptable_tol": max(tol * 100, 1e-4), "ipopt.acceptable_iter": 5,
        }
        if max_cpu_time is not None:
            self._opts_base["ipopt.max_cpu_time"] = max_cpu_time
        self.retry_max_iter = retry_max_iter
        self._solvers: dict[tuple[bool, bool, bool], Any] = {}

        # bounds
        lo_x = np.full((H, nx), -np.inf)
        hi_x = np.full((H, nx), np.inf)
        if model == "kinematic":
            lo_x[:, 3], hi_x[:, 3] = 0.0, bicycle.v_max
        else:
            lo_x[:, 3] = -0.5
        lo_u = np.tile([-bicycle.delta_max, bicycle.a_min], (H, 1))
        hi_u = np.tile([bicycle.delta_max, bicycle.a_max], (H, 1))
        self.lbx = np.concatenate([lo_x.ravel(), lo_u.ravel()])
        self.ubx = np.concatenate([hi_x.ravel(), hi_u.ravel()])
        lg = np.zeros((H, self.m))
        ug = np.full((H, self.m), np.inf)
        ug[:, :nx] = 0.0
        self.lbg, self.ubg = lg.ravel(), ug.ravel()

    @property
    def n_g(self) -> int:
        return self.H * self.m

    def _solver(self, warm: bool, lbfgs: bool = False, long: bool = False) -> Any:
        """IPOPT for a warm or cold start, with the L-BFGS Hessian or the exact one, with the
        retry's iteration budget (``long``) or the first attempt's (one rung of :data:`LADDER`)."""
        s = self._solvers.get((warm, lbfgs, long))
        if s is None:
            import casadi as ca

            opts = dict(self._opts_base)
            if lbfgs:
                opts["ipopt.hessian_approximation"] = "limited-memory"
            if long:
                opts["ipopt.max_iter"] = self.retry_max_iter
            if warm:
                opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.warm_start_bound_push": 1e-6,
                             "ipopt.warm_start_mult_bound_push": 1e-6, "ipopt.warm_start_slack_bound_push": 1e-6,
                             "ipopt.mu_init": 1e-4})
            s = ca.nlpsol(f"nmpc_{self.model}", "ipopt", self._nlp, opts)
            self._solvers[(warm, lbfgs, long)] = s
        return s

    def roll(self, x0: np.ndarray, U: np.ndarray) -> np.ndarray:
        """States (H+1, nx) under controls U (H, 2) [δ, a] from x0 (nx,)."""
        out = np.asarray(self._roll(np.asarray(x0, float), np.asarray(U, float).T)).T
        return np.vstack([np.asarray(x0, float)[None], out])

    def pack_w(self, X: np.ndarray, U: np.ndarray) -> np.ndarray:
        """Decision vector from states (H, nx) for k = 1..H and controls (H, 2)."""
        return np.concatenate([np.ravel(X), np.ravel(U)])

    def unpack_w(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(states (H, nx) for k = 1..H, controls (H, 2)) of a decision vector."""
        H, nx = self.H, self.nx
        return w[: H * nx].reshape(H, nx), w[H * nx:].reshape(H, 2)

    def solve(self, w0: np.ndarray, p: np.ndarray, lam_g0: np.ndarray | None = None,
              lam_x0: np.ndarray | None = None, retry: bool = True, a_low: np.ndarray | None = None) -> NlpSolution:
        """One IPOPT solve from ``w0``; with duals given, IPOPT's warm-start initialisation is used.
        ``a_low`` (H,) [m/s²]: the least acceleration at each step, this solve only (None: the
        bicycle's a_min).
        With the exact Hessian first; if that fails and ``retry``, again from the same point with
        the limited-memory (L-BFGS) Hessian, which gets through the saddle-like points the exact
        Hessian crawls at (a stop line ahead with the tracking cost pulling forward), and if that
        fails too, with the exact Hessian and L-BFGS's iteration budget: with the steering's rate
        weighed by the lateral jerk the cost is ill-conditioned at speed, L-BFGS stalls and a
        sudden swerve (a stopped vehicle entering the 1 s horizon) takes the exact Hessian ≈ 35
        iterations. Iterations and time add up. Numerical failures come back as an unsuccessful :class:`NlpSolution`,
        never raised."""
        lbx = self.lbx
        if a_low is not None:
            lbx = lbx.copy()
            lbx[self.H * self.nx + 1::2] = np.maximum(lbx[self.H * self.nx + 1::2], a_low)
        tries = [self._attempt(w0, p, lam_g0, lam_x0, *LADDER[0], lbx=lbx)]
        for rung in LADDER[1:] if retry else ():
            if tries[-1].success:
                break
            tries.append(self._attempt(w0, p, lam_g0, lam_x0, *rung, lbx=lbx))
        if len(tries) == 1:
            return tries[0]
        last = tries[-1]
        return NlpSolution(last.w, last.lam_g, last.lam_x, last.cost, last.status,
                           sum(a.iterations for a in tries), sum(a.solve_ms for a in tries), last.success,
                           tuple(a.status for a in tries))

    def _attempt(self, w0: np.ndarray, p: np.ndarray, lam_g0: np.ndarray | None, lam_x0: np.ndarray | None,
                 lbfgs: bool, long: bool = False, lbx: np.ndarray | None = None) -> NlpSolution:
        warm = lam_g0 is not None and lam_x0 is not None
        args: dict[str, Any] = {"x0": w0, "p": p, "lbx": self.lbx if lbx is None else lbx, "ubx": self.ubx,
                                "lbg": self.lbg, "ubg": self.ubg}
        if warm:
            args.update({"lam_g0": lam_g0, "lam_x0": lam_x0})
        t0 = time.perf_counter()
        try:
            solver = self._solver(warm, lbfgs, long)
            sol = solver(**args)
            stats = solver.stats()
        except Exception as exc:  # casadi raises on evaluation errors (NaN/Inf in a function)
            ms = (time.perf_counter() - t0) * 1e3
            n = np.full(self.n_w, np.nan)
            why = f"exception: {type(exc).__name__}: {exc}".splitlines()[0][:200]
            return NlpSolution(n, np.zeros(self.n_g), np.zeros(self.n_w), float("nan"), why, 0, ms, False, (why,))
        ms = (time.perf_counter() - t0) * 1e3
        w = np.asarray(sol["x"], float).ravel()
        status = str(stats.get("return_status", "unknown"))
        ok = status in SUCCESS and bool(np.all(np.isfinite(w)))
        return NlpSolution(w, np.asarray(sol["lam_g"], float).ravel(), np.asarray(sol["lam_x"], float).ravel(),
                           float(sol["f"]), status, int(stats.get("iter_count", 0)), ms, ok, (status,))
