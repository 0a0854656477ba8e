"""The NMPC baseline the paper compares against: one nonlinear program per step, casadi + IPOPT.

It implements :class:`~twolevel.control.planner.Planner`, as the MPC does, so the simulation
engine can swap it in::

    ctrl = NmpcController(world, rulesets, settings=MPCSettings(), model="kinematic" | "fourwheel")
    ctrl, diags = NmpcController.from_world(world, model="fourwheel")   # the scenario's rule files
    res  = ctrl.solve(ego, t, world_state, history)                     # -> PlanResult
    ctrl.reset()

Same fine horizon H, period dt, waypoints ω (:func:`twolevel.control.high_level.linearisation.prepare_step`,
the high level's own) and cost with the weights of ``settings.weights``: the baseline plans over
H steps of dt, as the paper's does, not over the MPC's longer look-ahead
(``settings.uniform()``). The speed the ego can stop from within its sensing range bounds every
step (as the MPC's, :func:`~twolevel.control.high_level.linearisation.sensing_bound`). The rules
that can be written smoothly become constraints, chosen from what the rule sets read:

* a rule reading ``v_max``: v_k ≤ v_max,k (the limit at the predicted positions), relaxed to
  what full braking allows when the ego is already too fast (v_0 + a_min·k·dt);
* ``collision_free(d)`` in a rule: for each nearby vehicle's constant-velocity prediction an
  order-4 superellipse in its frame with semi-axes (L_i + L_ego)/2 + d and (W_i + W_ego)/2 + d
  (:mod:`twolevel.control.nmpc.nlp`), at most ``NmpcOptions.max_obstacles`` vehicles (the nearest;
  the rest of the slots are far-away dummies);
* a rule reading ``d_stop``: while a stop line applies (not yet served, within r_near), the ego
  stays behind the line: t_lineᵀ(p_k − p_line) ≤ 0 (t_line the route's tangent at the line), and
  at the last step it can still stop before it: t_lineᵀ(p_H − p_line) + v_H²/(2·D) ≤ 0,
  D = ``NmpcOptions.stop_decel``. A position bound alone lets the plan reach the line at speed
  at the end of the horizon, and the next step is infeasible; the terminal braking-distance
  term keeps it feasible from step to step. (The term at every step instead makes the rows
  nearly dependent and IPOPT crawls: 200 iterations instead of 12, measured.)
* a rule reading ``light_red`` or ``d_light``: the same at every step k where the light is red;
  a rule reading ``xwalk_busy`` or ``d_xwalk``: the same while the crosswalk ahead is busy.
* a rule reading the right-of-way signals (``d_zone``, ``t_reach(o)``, …): the same at the
  high level's give-way line (:func:`~twolevel.control.high_level.right_of_way.give_way_line`)
  while it holds — the baseline waits before a conflict area, it does not encode the gap rule —
  and, once the line lets it go, from its waiting place until it is out of the area, an
  acceleration of at least ``CLEAR_ACCEL`` while slower than the rule's v_go: the clearing the
  line (and the safety layer's verifier) let it go for; the paper's cost alone launches at
  ≈ 0.86 m/s² and fell behind it inside the area.
* the route's goal, when the route stops there, is one more such line.

Every such line is also a speed bound (:meth:`NmpcController._line_speeds`: a profile braking
at ``settings.stop_decel``, or harder when stopping from where the ego is needs it, to a stop
``settings.stop_margin`` before the line). With the paper's unit weights a 1 m/s² harder braking
over the horizon costs far more than a few tenths of a radian of steering, so a bound on the
positions alone was met by steering away from the route: at the 4-way stop the plan turned
across its lane (0.58 m off, 0.1 rad askew) and the safety layer found no fail-safe to move
off with. A line the ego's point has passed by at most ``NmpcOptions.stop_slack`` is kept
where full braking stops it (standing millimetres past its line, the ego still waits).

Anything else (e.g. ``keep_gap`` on d_lead, past operators) is not expressed; each such rule
gets an ``MIL530`` warning at construction. The NLP is built once (:class:`NmpcProblem`) and
warm-started each step from the previous solution shifted by one step, primal and dual.

``ego``: the kinematic model plans from the pose (X, Y, ψ, v); the four-wheel model from the
detailed state (:mod:`twolevel.models.fourwheel`) when the :class:`~twolevel.control.planner.EgoState`
carries one, else from steady straight running at v. Either plans from its model's state: the
step data reads its first four components, and ``PlanResult.states`` is (H+1, 4) = [X, Y, ψ, v]
in both (vx for the four-wheel model). Fields of the MILP controller that do not apply: ``mode`` empty,
``binaries`` 0, ``certified`` False, ``gap`` NaN, ``rule_robustness`` {}; ``qps`` holds IPOPT's
iteration count, ``rows``/``columns`` the NLP's constraints/variables, ``solver`` "nmpc-<model>".
``timings_ms``: prepare, parameters, solve (IPOPT's wall time), total. An IPOPT failure gives
'fallback': the previous plan shifted (or full braking) with IPOPT's status in ``message``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import numpy as np

from twolevel.control.codes import MIL515, MIL530
from twolevel.control.high_level.guards import stop_lines, stop_lines_read
from twolevel.control.high_level.right_of_way import CLEAR_ACCEL, MPC_ZONE_PATTERNS, RUN_UP, gap_rule, give_way_line
from twolevel.control.high_level.linearisation import StepData, prepare_step, sensing_bound
from twolevel.control.high_level.settings import MPCSettings
from twolevel.control.high_level.steering import steering_reference
from twolevel.control.nmpc.nlp import MODELS, NlpSolution, NmpcProblem
from twolevel.control.planner import (EgoState, PlanResult, PlanStatus, Snapshot, WorldState, planner_of_world,
                                      stop_memory_of)
from twolevel.diagnostics import Diagnostic, Span
from twolevel.models import fourwheel as fw
from twolevel.models.params import BicycleParams, VehicleParams
from twolevel.stl import analysis, ast
from twolevel.stl.typecheck import RuleSet
from twolevel.world.world import World

__all__ = ["NmpcOptions", "NmpcController", "LastSolution", "MODELS"]

_FAR = 1.0e3  # [m] offset of the dummy obstacles
#: the lines a plan stops at (:meth:`NmpcController._lines`): the steps, route positions [m], rows
Lines = tuple[np.ndarray, np.ndarray, np.ndarray]


@dataclass(frozen=True)
class NmpcOptions:
    """``max_obstacles``: obstacle slots in the NLP (fixed; nearest vehicles first) [-];
    ``max_iter``/``tol``: IPOPT's (exact Hessian); ``retry``: after a failure, solve again with the
    L-BFGS Hessian, then with the exact one (``retry_max_iter`` iterations each) before falling back; ``max_cpu_time`` [s] per solve (None: no limit); ``warm_start``:
    start from the previous solution shifted, with its duals (``"primal"``: without duals, IPOPT's
    cold initialisation of the multipliers); ``substeps``: internal steps per dt of the
    four-wheel model (None: its own h_int); ``expand``: build the NLP as one SX graph (None:
    kinematic yes, four-wheel no — expanding it takes ≈ 6 s to build, solves ≈ 2× faster);
    ``stop_margin`` [m]: how far before a stop line the ego's point must stay; ``stop_decel``
    [m/s²]: the deceleration in the can-still-stop term of the stop-line bound (None: the
    bicycle's |a_min|); ``stop_slack`` [m]: a line the ego's point has passed is still kept
    (moved to where full braking stops it) while that is at most this far past it."""

    max_obstacles: int = 6
    max_iter: int = 30
    retry_max_iter: int = 100
    retry: bool = True
    tol: float = 1e-6
    max_cpu_time: float | None = None
    warm_start: bool | str = True
    substeps: int | None = None
    expand: bool | None = None
    stop_margin: float = 0.0
    stop_decel: float | None = None
    stop_slack: float = 0.5


@dataclass(frozen=True, eq=False)
class LastSolution:
    """The NLP's last solution (primal and dual), made at ``t`` [s]: the next step's warm start,
    and the controls the fallback shifts."""

    t: float
    solution: NlpSolution


def _calls(node: ast.Node, name: str) -> list[ast.Call]:
    return [n for n in node.walk() if isinstance(n, ast.Call) and n.name == name]


class NmpcController:
    """The paper's NMPC baseline (see the module docstring)."""

    label = "nmpc"

    def __init__(self, world: World, rulesets: Sequence[RuleSet], settings: MPCSettings | None = None, *,
                 model: str = "kinematic", params: BicycleParams | None = None,
                 vehicle: VehicleParams | None = None, options: NmpcOptions | None = None) -> None:
        if model not in MODELS:
            raise ValueError(f"unknown NMPC model {model!r}; choose one of {', '.join(MODELS)}")
        self.world = world
        self.settings = replace((settings or MPCSettings.of_world(world.settings)).uniform(), rss=False)
        self.model = model
        self.params = params or BicycleParams()
        self.vehicle = vehicle or VehicleParams().with_overrides(
            {k: v for k, v in world.ego.vehicle.items() if k in VehicleParams.__dataclass_fields__})
        self.options = options or NmpcOptions()
        self.diagnostics: list[Diagnostic] = []
        self.speed = self.stop = self.light = self.xwalk = self.give_way = False
        self.d_collision: float | None = None
        self.gap = gap_rule(rulesets)
        for rs in rulesets:
            for r in rs.rules:
                f = rs.formula(r.name)
                reads = {n for n in analysis.signals_read(f) if n not in rs.consts}
                used = False
                if "v_max" in reads:
                    self.speed = used = True
                stop, light, xwalk = stop_lines_read(reads)
                self.stop, self.light, self.xwalk = self.stop or stop, self.light or light, self.xwalk or xwalk
                used = used or stop or light or xwalk
                if reads & ({"d_zone", "d_zone_out"} | MPC_ZONE_PATTERNS):
                    self.give_way = used = True
                for c in _calls(f, "collision_free"):
                    d = analysis.fold_term(c.args[0]) if len(c.args) == 1 else None
                    if isinstance(d, ast.Num):
                        self.d_collision = max(self.d_collision or 0.0, float(d.value))
                        used = True
                if not used:
                    self.diagnostics.append(MIL530(
                        f"rule '{r.name}' is not a speed limit, stop line, red light, crosswalk or collision_free rule; "
                        "the NMPC baseline ignores it", r.span or Span(rs.file),
                        hint="the NMPC expresses v_max, d_stop, light_red/d_light, xwalk_busy/d_xwalk, the give-way line and "
                        "collision_free(d) only"))
        st = self.settings
        o = self.options
        self.problem = NmpcProblem(model, H=st.H, dt=st.dt, weights=st.weights, bicycle=self.params,
                                   vehicle=self.vehicle, n_obstacles=o.max_obstacles if self.d_collision is not None else 0,
                                   substeps=o.substeps, max_iter=o.max_iter, tol=o.tol, max_cpu_time=o.max_cpu_time,
                                   expand=o.expand, retry_max_iter=o.retry_max_iter)
        self.previous: LastSolution | None = None
        self._s_hint: float | None = None
        self.last: NlpSolution | None = None

    @classmethod
    def from_world(cls, world: World, settings: MPCSettings | None = None, *, model: str = "kinematic",
                   params: BicycleParams | None = None, options: NmpcOptions | None = None
                   ) -> tuple["NmpcController | None", list[Diagnostic]]:
        """The NMPC of a scenario's world with its own rule files and settings."""
        st = settings or MPCSettings.of_world(world.settings, time_limit=world.settings.time_limit)
        return planner_of_world(cls, world, st, params, model=model, options=options)

    @property
    def history_depth(self) -> int:
        """Past samples [steps] the NMPC reads: none (no past operator is expressed)."""
        return 0

    def reset(self) -> None:
        """Forget the previous solution (the next step starts cold from the reference)."""
        self.previous = None
        self._s_hint = None

    # ------------------------------------------------------------------ step data
    def _prepare(self, x0: np.ndarray, t: float, world_state: WorldState,
                 history: Mapping[str, np.ndarray] | None) -> StepData:
        """The high level's step data from the model state ``x0`` (its first four components)."""
        st = self.settings
        snap = Snapshot.of(world_state)
        hist = {k: np.asarray(v, float) for k, v in (history or {}).items()}
        memory = stop_memory_of(self.world, snap.memory, hist, st.dt)
        u_prev = None
        if len(hist.get("delta", ())) and len(hist.get("a", ())):
            u_prev = np.array([hist["delta"][-1], hist["a"][-1]])
        elif self.previous is not None:
            u_prev = self.problem.unpack_w(self.previous.solution.w)[1][0]
        return prepare_step(self.world, x0[:4], t, snap.traffic, st, self.params, u_prev=u_prev, memory=memory,
                            s_hint=self._s_hint, gap=self.gap)

    def _x0(self, ego: EgoState) -> np.ndarray:
        """The model's state now: the pose (kinematic), the detailed state (four-wheel), or
        steady straight running at the pose's speed when there is no detailed state."""
        if self.model == "kinematic":
            return ego.pose[:4].copy()
        if ego.detailed is not None and ego.detailed.size == fw.NX:
            return ego.detailed.copy()
        return fw.initial_state(*(float(c) for c in ego.pose[:4]), p=self.vehicle)

    def parameters(self, step: StepData, x0: np.ndarray, lines: Lines | None = None) -> np.ndarray:
        """The NLP's parameter vector for this step (see :mod:`twolevel.control.nmpc.nlp`);
        ``lines``: the step's :meth:`_lines` when already known."""
        H, dt = self.settings.H, self.settings.dt
        hc = step.hc
        route = self.world.route
        k = np.arange(1, H + 1)
        vb = np.full(H, 1e3)
        if self.speed:
            vb = np.maximum(hc.v_max[1:], float(x0[3]) + self.params.a_min * dt * k + 0.05)
        ws = self.world.settings  # what the ego can stop from within its sensing range
        vb = np.minimum(vb, sensing_bound(float(x0[3]), np.arange(H + 1), dt, ws.v_sense, ws.response.brake_min))
        stop = np.tile([0.0, 0.0, 1.0, 0.0], (H, 1))
        kept, s_stop, rows = self._lines(step, x0) if lines is None else lines
        if kept.size:
            stop[kept] = rows
            # aimed where the reference stops (settings.stop_margin before the line), the
            # position bound at the line itself is never pressed
            s_stop = float(np.min(s_stop)) - self.settings.stop_margin
            vb[kept] = np.minimum(vb[kept], self._line_speeds(float(step.s_ref[0]), float(x0[3]), s_stop)[kept])
        N = self.problem.N
        centres = np.tile(x0[:2] + _FAR, (N, H, 1))
        shapes = np.tile([1.0, 0.0, 1.0, 1.0], (N, 1))
        m = len(hc.index)
        if N and m:
            order = np.argsort(np.hypot(*(hc.xy[:, 0, :] - x0[:2]).T), kind="stable")[:N]
            q = len(order)
            d = float(self.d_collision or 0.0)
            centres[:q] = hc.xy[order, 1:, :]
            psi = hc.psi[order, 0]
            A = 0.5 * (hc.length[order] + self.world.ego.length) + d
            B = 0.5 * (hc.width[order] + self.world.ego.width) + d
            shapes[:q] = np.column_stack([np.cos(psi), np.sin(psi), 1.0 / A, 1.0 / B])
        steer = None
        if step.steer_weight is not None:  # the steering in the lateral acceleration it causes
            before = steering_reference(route.curvature_at(np.array([step.s_ref[0] - float(x0[3]) * dt])), self.params)
            ref = step.steer_ref[:H]
            steer = np.column_stack([ref, np.concatenate([before, ref[:-1]]), step.steer_weight[:H]])
        return self.problem.layout.pack(x0, step.u_prev, step.omega, vb, stop, centres, shapes, steer)

    def _lines(self, step: StepData, x0: np.ndarray) -> Lines:
        """The lines the plan stops at: the steps (0-based indices into 1..H) where one applies
        (the nearest stop line, red light, give-way line or the goal) and is kept (the ego's
        point is behind it, or passed it by at most ``options.stop_slack`` where full braking
        stops it), the route position [m] the plan must stay behind at each (the line less
        ``options.stop_margin``, or where the ego stops), and the stop block's rows
        (n_x, n_y, b, c) there (see :mod:`twolevel.control.nmpc.nlp`)."""
        H = self.settings.H
        route = self.world.route
        # stop lines: the nearest line that applies at step k (inf: none)
        s_line = stop_lines(step.hc, stop=self.stop, light=self.light, xwalk=self.xwalk)[1:]  # the high level's
        if self.give_way:  # right of way: wait where the high level's give-way line is, while it holds
            s_line = np.minimum(s_line, give_way_line(step.zones))
        if route.v_des.size and route.v_des[-1] <= 1e-9:  # the route stops at its goal
            s_line = np.minimum(s_line, float(route.s[-1]))
        act = np.flatnonzero(np.isfinite(s_line))
        sl = s_line[act]
        h = route.heading_at(sl)
        n = np.stack([np.cos(h), np.sin(h)], axis=1).reshape(-1, 2)
        b = np.einsum("ij,ij->i", n, route.position(sl).reshape(-1, 2)) - self.options.stop_margin
        # where full braking stops the ego's point: the model's speed cannot go below 0 within a
        # period, so it still rolls up to v·dt/2 more than v²/(2·|a_min|)
        v0 = max(float(x0[3]), 0.0)
        ahead = n @ x0[:2]
        over = np.maximum(ahead + 0.5 * v0 * (v0 / abs(self.params.a_min) + self.settings.dt) - b, 0.0)
        # a line already passed cannot be kept, unless the ego stops within options.stop_slack
        # of it; a line it can stop no nearer to than that moves to where it stops (standing a
        # few millimetres past it, the ego still waits there instead of driving into the
        # junction, and the plan stays feasible)
        near = over <= self.options.stop_slack
        kept = (ahead <= b + 1e-9) | near
        over = np.where(near, over, 0.0)
        b = b + over
        decel = self.options.stop_decel or abs(self.params.a_min)
        c = np.where(act == H - 1, 0.5 / decel, 0.0)  # terminal: can still stop
        rows = np.column_stack([n, b, c])[kept]
        return act[kept], (sl - self.options.stop_margin + over)[kept], rows

    def _launch(self, step: StepData, x0: np.ndarray, lines: Lines) -> np.ndarray | None:
        """(H,) [m/s²] The least acceleration at each step when the ego moves off into a conflict
        area (None: no bound): :data:`~twolevel.control.high_level.right_of_way.CLEAR_ACCEL`
        while the speed it gives stays below the rule's least speed inside (``GapRule.speed``,
        v_go), once the give-way line has let the ego go, from its waiting place until its rear
        has left the area, and no line before the area's exit stops it.

        The give-way line lets the ego go when it can clear the area at CLEAR_ACCEL before any
        vehicle with priority could arrive (the safety layer's clearing fail-safe); the paper's
        cost launches at ~0.86 m/s² (a² weighs as much as the speed's tracking error), so the
        ego fell behind that schedule inside the area, the verifier refuted clearing and braked
        it to a stop in the junction (rules/right_of_way.stl's clear_junction: v ≥ v_go or
        a ≥ a_go there)."""
        zc = step.zones
        if not self.give_way or zc is None or not math.isfinite(zc.s_in) or zc.waiting():
            return None
        half = 0.5 * zc.length
        if not zc.s_in - half - 2.0 * RUN_UP <= zc.s0 < zc.s_out + half:
            return None  # not at its waiting place, or out of the area
        if np.any(lines[1] < zc.s_out + half):
            return None  # a line stops it before it is through
        H, dt = self.settings.H, self.settings.dt
        slow = float(x0[3]) + CLEAR_ACCEL * dt * np.arange(H) < zc.gap.speed
        if not slow.any():
            return None
        return np.where(slow, CLEAR_ACCEL, self.params.a_min)

    def _line_speeds(self, s0: float, v0: float, s_stop: float) -> np.ndarray:
        """(H,) [m/s] The speed bound at steps 1..H of a line the plan stops at, ``s_stop`` [m]
        (route position), from the ego at (``s0`` [m], ``v0`` [m/s]): the speeds of a profile
        that accelerates at the bicycle's a_max while it can still stop before ``s_stop``
        braking at D, then brakes at D (each step's end speed w such that
        s + (v + w)·dt/2 + w²/(2·D) ≤ s_stop, the exact distances of constant accelerations),
        never below what full braking allows. D is the larger of ``settings.stop_decel`` and what
        stopping from (``s0``, ``v0``) needs, at most the bicycle's |a_min|. A plan never faster
        than the profile is never ahead of it, so the bound needs no guess of the plan's
        positions. A line is a speed limit falling to 0 at it, which steering cannot meet, as it
        met the bound on the positions alone (the module docstring)."""
        H, dt = self.settings.H, self.settings.dt
        a_min, a_max = abs(self.params.a_min), self.params.a_max
        room = s_stop - s0
        decel = min(max(self.settings.stop_decel, v0 * v0 / (2.0 * room) if room > 1e-3 else a_min), a_min)
        out = np.empty(H)
        s, v = s0, max(v0, 0.0)
        for k in range(H):  # H scalar steps
            r = s_stop - s - 0.5 * v * dt
            w = math.sqrt((0.5 * decel * dt) ** 2 + 2.0 * decel * r) - 0.5 * decel * dt if r > 0.0 else 0.0
            w = max(min(w, v + a_max * dt), v - a_min * dt, 0.0)
            s += 0.5 * (v + w) * dt
            out[k] = v = w
        return np.maximum(out, v0 - a_min * dt * np.arange(1, H + 1) + 0.05)

    def _initial_guess(self, t: float, step: StepData, x0: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, str]:
        pr = self.problem
        H, m, nx = pr.H, pr.m, pr.nx
        warm = self.options.warm_start
        if warm and self.previous is not None and abs(t - self.previous.t - self.settings.dt) < 1e-6:
            sol = self.previous.solution
            X, U = pr.unpack_w(sol.w)
            U = np.vstack([U[1:], U[-1:]])
            X = np.vstack([X[1:], np.asarray(pr.F(X[-1], U[-1]), float).ravel()[None]])
            w0 = pr.pack_w(X, U)
            if warm == "primal":
                return w0, None, None, "warm-primal"
            lg = sol.lam_g.reshape(H, m)
            lg = np.vstack([lg[1:], lg[-1:]]).ravel()
            lx_x, lx_u = sol.lam_x[: H * nx].reshape(H, nx), sol.lam_x[H * nx:].reshape(H, 2)
            lx = np.concatenate([np.vstack([lx_x[1:], lx_x[-1:]]).ravel(), np.vstack([lx_u[1:], lx_u[-1:]]).ravel()])
            return w0, lg, lx, "warm"
        U = step.us_bar
        X = pr.roll(x0, U)[1:]
        return pr.pack_w(X, U), None, None, "cold"

    # ------------------------------------------------------------------ one step
    def solve(self, ego: EgoState | Sequence[float], t: float, world_state: WorldState = None,
              history: Mapping[str, np.ndarray] | None = None) -> PlanResult:
        """One NMPC step (see the module docstring); numerical failures give 'fallback'."""
        tm: dict[str, float] = {}
        t0 = time.perf_counter()
        x0 = self._x0(EgoState.of(ego))
        if not np.all(np.isfinite(x0)):
            return self._fail(x0, t, "non-finite ego state", 0, tm, t0)
        step = self._prepare(x0, t, world_state, history)
        t1 = time.perf_counter()
        tm["prepare"] = (t1 - t0) * 1e3
        lines = self._lines(step, x0)
        p = self.parameters(step, x0, lines)
        w0, lg, lx, how = self._initial_guess(t, step, x0)
        a_low = self._launch(step, x0, lines)
        tm["parameters"] = (time.perf_counter() - t1) * 1e3
        sol = self.problem.solve(w0, p, lg, lx, retry=self.options.retry, a_low=a_low)
        self.last = sol
        tm["solve"] = sol.solve_ms
        pr = self.problem
        name = f"nmpc-{self.model}"
        retried = len(sol.attempts) > 1
        tried = " → ".join(sol.attempts) if retried else sol.status
        msg = f"ipopt: {tried}, {sol.iterations} iterations ({how} start{', retried' if retried else ''})"
        if sol.success:
            X, U = pr.unpack_w(sol.w)
            states = np.vstack([x0[None, :4], X[:, :4]])
            self.previous = LastSolution(t, sol)
            self._s_hint = float(step.s_ref[1])
            status = PlanStatus.OPTIMAL if sol.status == "Solve_Succeeded" else PlanStatus.FEASIBLE
            tm["total"] = (time.perf_counter() - t0) * 1e3
            return PlanResult(status, sol.cost, U, states, np.zeros(0, np.int64), 0, pr.n_g, pr.n_w, sol.iterations,
                              False, tm, {}, msg, float("nan"), (), name)
        return self._fail(x0, t, msg, sol.iterations, tm, t0)

    def _fail(self, x0: np.ndarray, t: float, msg: str, iterations: int, tm: dict[str, float], t0: float
              ) -> PlanResult:
        """The fallback plan: the previous plan shifted, or full braking (rolled from ``x0``)."""
        pr = self.problem
        U, why = self._fallback_controls()
        X = self._roll_forward(x0, U) if np.all(np.isfinite(x0)) else np.full((pr.H, pr.nx), np.nan)
        if self.previous is not None:  # keep shifting the last good solution (duals dropped)
            self.previous = LastSolution(t, NlpSolution(pr.pack_w(X, U), np.zeros(pr.n_g), np.zeros(pr.n_w),
                                                        float("nan"), "fallback", 0, 0.0, True))
        tm["total"] = (time.perf_counter() - t0) * 1e3
        diag = MIL515(f"t = {t:.2f} s: NMPC {msg}; fallback: {why}", Span(self.world.name))
        return PlanResult(PlanStatus.FALLBACK, float("nan"), U, np.vstack([x0[None, :4], X[:, :4]]), np.zeros(0, np.int64), 0,
                          pr.n_g, pr.n_w, iterations, False, tm, {}, f"{msg}; fallback: {why}", float("nan"),
                          (diag,), f"nmpc-{self.model}")

    def _roll_forward(self, x0: np.ndarray, U: np.ndarray) -> np.ndarray:
        """States k = 1..H under U (H, 2), which is edited in place so the kinematic model's
        speed stops at 0 instead of reversing."""
        dt = self.settings.dt
        x = x0
        out = []
        for k in range(U.shape[0]):  # H scalar steps, fallback only
            if self.model == "kinematic":
                U[k, 1] = max(U[k, 1], -float(x[3]) / dt)
            x = np.asarray(self.problem.F(x, U[k]), float).ravel()
            out.append(x)
        return np.array(out)

    def _fallback_controls(self) -> tuple[np.ndarray, str]:
        H = self.settings.H
        if self.previous is not None:
            U = self.problem.unpack_w(self.previous.solution.w)[1]
            return np.vstack([U[1:], U[-1:]]), "previous plan shifted"
        return np.tile([0.0, self.params.a_min], (H, 1)), "no previous plan: full braking"

