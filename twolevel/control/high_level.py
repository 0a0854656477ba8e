"""The high-level controller: a receding-horizon MPC whose traffic rules are MILCs (the paper's top level).

Interface (stable; the low level and the simulation engine build on it)::

    ctrl = HighLevelController(world, rulesets, settings=MPCSettings(), params=BicycleParams())
    res  = ctrl.solve(ego_state, t, world_state, history)        # -> PlanResult
    ctrl.reset()                                                 # forget the previous plan

* ``world``: :class:`~twolevel.world.world.World` (static scenario); ``rulesets``: bound
  :class:`~twolevel.stl.typecheck.RuleSet` s (``lint.load_ruleset(path, consts)``); every rule of
  every set is required at the current step. ``HighLevelController.from_world(world)`` loads the
  scenario's own rule files and settings (returns ``(ctrl | None, diagnostics)``).
* ``MPCSettings(H=10, dt=0.1, weights=Weights(u=1, du=1, track=(1, 1, 1, 1)), solver="modes" |
  "highs" | "gurobi", time_limit=0.1 [s], gap=0.005, eps=1e-4)``.
* ``solve(ego_state, t, world_state, history)``: ``ego_state`` = (X [m], Y [m], ψ [rad], v [m/s]);
  ``t`` [s]; ``world_state``: the other traffic now — a
  :class:`~twolevel.world.traffic.TrafficState` or a :class:`Snapshot` (traffic + stop-sign
  memory), None for an empty road; ``history``: recorded past samples of the rule signals,
  ``{name: array}`` oldest first, *excluding* the current step (e.g. rows of
  :func:`twolevel.world.signals.signals_along` over the driven trajectory; may be None).
  ``history["delta"][-1]``, ``history["a"][-1]``, when present, are the control applied in the
  last step (for ‖u_0 − u_{−1}‖²).
* :class:`PlanResult`: ``status`` ('optimal' | 'feasible' | 'fallback' | 'infeasible' |
  'time_limit'), ``cost``, ``controls`` (H, 2) [δ rad, a m/s²], ``states`` (H+1, 4) (row 0 is the
  ego state), ``mode`` (choice per disjunction), ``binaries``, ``rows``, ``columns``, ``qps``,
  ``certified``, ``timings_ms`` (phase → ms: linearise, assembly, lower_bound, readoff, seeds,
  descent, flips, bnb, highs, polish, solve, total), ``rule_robustness`` ({rule: robustness at
  the current step of the plan, by the offline monitor with the high-level signals}),
  ``message``, ``diagnostics``. On 'fallback' the controls are the previous plan shifted by one
  step (or full braking when there is none) and ``message`` says why.

Model and signals: :mod:`twolevel.control.problem`; step data (linearisation about the shifted
previous plan, waypoints, bounds): :mod:`twolevel.control.horizon`; mode search:
:mod:`twolevel.milp.modes`. A model of an already seen shape reuses its Clarabel solver object
(values updated in place).
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Any, Mapping, Sequence

import numpy as np

from twolevel.compiler.types import Requirement
from twolevel.control.codes import MIL510, MIL511, MIL512
from twolevel.control.horizon import StepData, history_length, prepare_step
from twolevel.control.problem import Assembled, Weights, assemble, shape_key
from twolevel.control.template import TemplateCache, refresh, template_of
from twolevel.diagnostics import Diagnostic, Span
from twolevel.milp.clarabel import FixedModeQP
from twolevel.milp.model import PatternCache
from twolevel.milp.modes import ModeSearch
from twolevel.milp.solution import Status
from twolevel.models import bicycle
from twolevel.models.params import BicycleParams
from twolevel.stl import analysis
from twolevel.stl.typecheck import RuleSet
from twolevel.world.signals import StopMemory, update_stop_memory
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["MPCSettings", "Snapshot", "PlanResult", "HighLevelController", "Weights", "SOLVERS"]

SOLVERS = ("modes", "highs", "gurobi")
_MPC_SIGNALS = frozenset({"x", "y", "psi", "v", "a", "delta", "s", "e", "v_max", "d_stop", "light_red", "d_light",
                          "d_lead", "v_lead", "n_near"})


@dataclass(frozen=True)
class MPCSettings:
    """Horizon ``H`` [steps], period ``dt`` [s], cost ``weights``, ``solver``, ``time_limit`` per
    step [s] (None: no limit — the mode search's B&B runs to completion), certificate ``gap``
    (relative), satisfaction margin ``eps``, whether to evaluate ``rule_robustness``, and whether
    to re-linearise (about the reference, then about braking) when the step is infeasible;
    ``refresh`` (``modes`` solver): reuse a model of the same structure with new values (:mod:`twolevel.control.template`),
    keeping vehicle–step pairs within d + ``pad`` [m] so the structure lasts several steps;
    ``search_qps``: the mode search's optional phases (seeds, descent, flips, B&B) stop after that
    many QPs (deterministic; ~1 ms each at 18 vehicles), ``search_ms`` [ms] optionally after that
    long (time-dependent, so not deterministic), always within ``time_limit``; both ignored when
    ``time_limit`` is None; ``max_flip_qps``: at most that many QPs of dual-ordered flips;
    ``stop_decel`` [m/s²] and ``stop_margin`` [m]: the terminal can-still-stop condition before a
    stop line or red light a rule guards (:mod:`twolevel.control.guards`; the scenario's
    ``yellow_decel`` in :meth:`HighLevelController.from_world`); ``band``: keep the lateral offset
    within the lanes that run the route's way."""

    H: int = 10
    dt: float = 0.1
    weights: Weights = Weights()
    solver: str = "modes"
    time_limit: float | None = 0.1
    gap: float = 0.005
    eps: float = 1e-4
    monitor: bool = True
    relinearise: bool = True
    refresh: bool = True
    pad: float = 2.0
    search_ms: float | None = None
    search_qps: int | None = 16
    max_flip_qps: int | None = 8
    stop_decel: float = 3.0
    stop_margin: float = 0.3
    band: bool = True


@dataclass(frozen=True)
class Snapshot:
    """The world as the controller sees it now: other traffic and the stop-sign memory."""

    traffic: TrafficState
    memory: StopMemory | None = None


@dataclass(frozen=True, eq=False)
class PlanResult:
    """One MPC step's answer (see the module docstring)."""

    status: str
    cost: float
    controls: np.ndarray
    states: np.ndarray
    mode: np.ndarray
    binaries: int
    rows: int
    columns: int
    qps: int
    certified: bool
    timings_ms: dict[str, float]
    rule_robustness: dict[str, float]
    message: str = ""
    gap: float = float("nan")
    diagnostics: tuple[Diagnostic, ...] = ()
    solver: str = "modes"

    @property
    def ok(self) -> bool:
        """A plan that satisfies the rules (optimal or feasible)."""
        return self.status in ("optimal", "feasible")


@dataclass(frozen=True, eq=False)
class _Rule:
    name: str
    formula: object
    reads: frozenset[str]
    depth: int


def _empty_traffic() -> TrafficState:
    z = np.zeros(0)
    return TrafficState(0.0, z, z, z, z, np.zeros(0, int), z, z, np.zeros(0, bool), z, np.zeros(0, int))


class HighLevelController:
    """The MPC of design.md ("High-level controller"); see the module docstring."""

    def __init__(self, world: World, rulesets: Sequence[RuleSet], settings: MPCSettings | None = None, *,
                 params: BicycleParams | None = None) -> None:
        self.world = world
        self.settings = settings or MPCSettings(H=world.settings.H, dt=world.settings.dt)
        self.params = params or BicycleParams()
        if self.settings.solver not in SOLVERS:
            raise ValueError(f"unknown solver {self.settings.solver!r}; choose one of {', '.join(SOLVERS)}")
        if self.settings.solver == "gurobi":
            from twolevel.milp.gurobi import available

            if not available():
                raise ValueError("solver 'gurobi' needs gurobipy, which is not importable; use 'modes' or 'highs'")
        self.diagnostics: list[Diagnostic] = []
        self.rules: list[_Rule] = []
        dt = self.settings.dt
        for rs in rulesets:
            for r in rs.rules:
                f = rs.formula(r.name)
                reads = frozenset(n for n in analysis.signals_read(f) if n not in rs.consts)
                missing = sorted(reads - _MPC_SIGNALS)
                if missing:
                    self.diagnostics.append(MIL510(
                        f"rule '{r.name}' reads {', '.join(missing)}, which the MPC cannot predict; it is "
                        "left to the low level", r.span or Span(rs.file),
                        hint="at the high level use collision_free(d) instead of min_gap"))
                    continue
                depth = analysis.past_depth(f, dt)
                steps = int(round(depth / dt)) if math.isfinite(depth) else 10 ** 6
                self.rules.append(_Rule(r.name, f, reads, steps))
        reads_all = set().union(*(r.reads for r in self.rules)) if self.rules else set()
        self.stop_rules = ("d_stop" in reads_all, bool({"light_red", "d_light"} & reads_all))
        self._pattern_cache = PatternCache(capacity=16)
        self.templates = TemplateCache(capacity=4)
        self._qps: OrderedDict[tuple, tuple[FixedModeQP, ModeSearch]] = OrderedDict()
        self._prev: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None  # t, states, controls, mode
        self._s_hint: float | None = None
        self._recover_at: dict[str, float] = {}  # rule → time [s] from which a recovering plan meets it

    # ------------------------------------------------------------------ construction helpers
    @classmethod
    def from_world(cls, world: World, settings: MPCSettings | None = None, *, solver: str | None = None,
                   params: BicycleParams | None = None) -> tuple["HighLevelController | None", list[Diagnostic]]:
        """The controller of a scenario's world with its own rule files and settings."""
        st = settings or MPCSettings(H=world.settings.H, dt=world.settings.dt, solver=solver or world.settings.solver,
                                     time_limit=world.settings.time_limit, stop_decel=world.settings.yellow_decel)
        if solver is not None:
            st = MPCSettings(**{**st.__dict__, "solver": solver})
        return controller_of_world(cls, world, st, params)

    def reset(self) -> None:
        """Forget the previous plan (the next step linearises about the reference)."""
        self._prev = None
        self._s_hint = None
        self._recover_at = {}

    # ------------------------------------------------------------------ one step
    def requirements(self, drop: frozenset[str] = frozenset(), P: int = 0) -> list[Requirement]:
        return [Requirement(r.name, r.formula, (P,)) for r in self.rules if r.name not in drop]  # type: ignore[arg-type]

    def prepare(self, ego_state: Sequence[float], t: float, world_state: TrafficState | Snapshot | None,
                history: Mapping[str, np.ndarray] | None, about: str = "plan"
                ) -> tuple[StepData, dict[str, np.ndarray], int]:
        """Linearise and gather the step's constants; returns (step data, past samples, P)."""
        H, dt = self.settings.H, self.settings.dt
        traffic, memory = _unpack(world_state)
        hist = {k: np.asarray(v, float) for k, v in (history or {}).items()}
        memory = stop_memory_of(self.world, memory, hist, dt)
        prev = None
        if self._prev is not None and abs(t - self._prev[0] - dt) < 1e-6 and self._prev[2].shape[0] == H:
            prev = (self._prev[1], self._prev[2])
        u_prev = None
        if "delta" in hist and "a" in hist and len(hist["delta"]) and len(hist["a"]):
            u_prev = np.array([hist["delta"][-1], hist["a"][-1]])
        step = prepare_step(self.world, np.asarray(ego_state, float), t, traffic, H=H, dt=dt, params=self.params,
                            prev=prev, u_prev=u_prev, memory=memory, s_hint=self._s_hint, about=about,
                            stop_rules=self.stop_rules, stop_decel=self.settings.stop_decel,
                            stop_margin=self.settings.stop_margin, band=self.settings.band)
        names = set().union(*(r.reads for r in self.rules)) if self.rules else set()
        depth = max((r.depth for r in self.rules), default=0)
        P = history_length(hist, names, depth)
        return step, hist, P

    def build(self, step: StepData, past: Mapping[str, np.ndarray], P: int,
              drop: frozenset[str] = frozenset(), recover_after: Mapping[str, int] | None = None) -> Assembled:
        """The step's model with every rule not in ``drop``."""
        st = self.settings
        names = set().union(*(r.reads for r in self.rules if r.name not in drop)) if self.rules else set()
        reqs = self.requirements(drop, P)
        key = (P, tuple(r.name for r in reqs))
        use = st.refresh and st.solver == "modes" and not recover_after  # HiGHS: the minimal encoding
        if use:
            for tpl in self.templates.candidates(key):
                asm = refresh(tpl, step, reqs, past, names=names, dt=st.dt, eps=st.eps, weights=st.weights,
                              params=self.params, pad=st.pad)
                if asm is not None:
                    self.templates.touch(key, tpl)
                    self.templates.hits += 1
                    asm.template = tpl
                    return asm
            self.templates.misses += 1
        asm = assemble(step, reqs, H=st.H, dt=st.dt, params=self.params, weights=st.weights, past=past, P=P,
                       names=names, cache=self._pattern_cache, eps=st.eps, stable=use, pad=st.pad,
                       recover_after=recover_after)
        tpl = template_of(asm, st.eps) if use else None
        if tpl is not None:
            self.templates.add(key, tpl)
            asm.template = tpl
        return asm

    def _backend(self, asm: Assembled) -> tuple[FixedModeQP, ModeSearch]:
        tpl = asm.template
        if tpl is not None:
            if tpl.backend is None:  # type: ignore[attr-defined]
                qp = FixedModeQP(asm.model)
                tpl.backend = (qp, ModeSearch(qp))  # type: ignore[attr-defined]
            return tpl.backend  # type: ignore[attr-defined,return-value]
        key = shape_key(asm.model)
        hit = self._qps.get(key)
        if hit is not None:
            self._qps.move_to_end(key)
            hit[0].model = asm.model
            return hit
        qp = FixedModeQP(asm.model)
        ms = ModeSearch(qp)
        self._qps[key] = (qp, ms)
        while len(self._qps) > 8:
            self._qps.popitem(last=False)
        return qp, ms

    def _recover_later(self, res: PlanResult, asm: Assembled, step: StepData, past: Mapping[str, np.ndarray], P: int,
                       tm: dict[str, float], t0: float) -> tuple[PlanResult, Assembled]:
        """A rule violated now was required from a step the solver still finds infeasible: require
        it later. The extra shift j (the same for every recovering rule) is found by a binary
        search on the feasibility of the step's relaxation (every disjunction undecided, one QP
        per probe; requiring a rule later never adds constraints, so feasibility is monotone in
        j), then the full solve at the first relaxation-feasible j, then one step later at a time
        while the mode search still finds no plan (within the time limit)."""
        from twolevel.control.solve import solve_step

        lim = self.settings.time_limit
        if not res.ok and not asm.encoding.recovered and self._recover_at:
            # the hinted start did not help (the rule may no longer be violated): plain build
            self._recover_at = {}
        if res.ok or res.status == "time_limit" or not asm.encoding.recovered:
            return res, asm
        base = {n: t2 - t for n, t, t2 in asm.encoding.recovered}
        T = P + self.settings.H + 1  # trace length: a start step is at most T − 1
        j_max = min(T - 1 - t2 for _, _, t2 in asm.encoding.recovered)
        built: dict[int, Assembled] = {}
        probes = 0

        def in_time() -> bool:
            return lim is None or time.perf_counter() - t0 < lim

        def at(j: int) -> Assembled:  # search from start + j on (``after`` = offset + j − 1)
            if j not in built:
                built[j] = self.build(step, past, P, recover_after={n: b + j - 1 for n, b in base.items()})
            return built[j]

        def relaxed_feasible(j: int) -> bool:
            nonlocal probes
            a = at(j)
            if a.encoding.infeasible or any(d.is_error for d in a.diagnostics):
                return False
            qp, ms = self._backend(a)
            x_int, disable = ms.to_int(np.full(ms.D, -1, np.int64))
            probes += 1
            return qp.solve(x_int, disable=disable).status is Status.OPTIMAL

        lo, hi = 1, j_max + 1  # first relaxation-feasible j in [lo, hi); hi = none
        while lo < hi and in_time():
            mid = (lo + hi) // 2
            if relaxed_feasible(mid):
                hi = mid
            else:
                lo = mid + 1
        j = lo
        while j <= j_max and not res.ok and res.status != "time_limit" and in_time():
            asm = at(j)
            res = solve_step(self, step, asm, tm, t0)
            j += 1
        return (replace(res, qps=res.qps + probes) if probes else res), asm

    def solve(self, ego_state: Sequence[float], t: float, world_state: TrafficState | Snapshot | None = None,
              history: Mapping[str, np.ndarray] | None = None) -> PlanResult:
        """One MPC step (see the module docstring)."""
        from twolevel.control.solve import solve_step  # the two solve paths

        tm: dict[str, float] = {}
        t0 = time.perf_counter()
        step, past, P = self.prepare(ego_state, t, world_state, history)
        t1 = time.perf_counter()
        tm["linearise"] = (t1 - t0) * 1e3
        # a rule being recovered: start from the time the previous plan met it again (the same
        # absolute time; earlier starts were infeasible then), not from the first step
        dt = self.settings.dt
        hint = {n: int(round((ta - t) / dt)) - 1 for n, ta in self._recover_at.items()
                if int(round((ta - t) / dt)) >= 2}
        asm = self.build(step, past, P, recover_after=hint or None)
        t2 = time.perf_counter()
        tm["assembly"] = (t2 - t1) * 1e3
        res = solve_step(self, step, asm, tm, t0)
        res, asm = self._recover_later(res, asm, step, past, P, tm, t0)
        if res.ok and asm.encoding.recovered:
            self._recover_at = {n: t + (t2 - t1) * dt for n, t1, t2 in asm.encoding.recovered}
        elif res.ok:
            self._recover_at = {}
        # the linearisation about the previous plan can be far from a plan that now has to differ
        # (e.g. braking instead of swerving): re-linearise about the reference, then about braking
        for about in ("reference", "brake") if self.settings.relinearise else ():
            if res.ok or res.status == "time_limit" or (
                    self.settings.time_limit is not None and (time.perf_counter() - t0) > self.settings.time_limit):
                break
            t3 = time.perf_counter()
            step2, past2, P2 = self.prepare(ego_state, t, world_state, history, about=about)
            asm2 = self.build(step2, past2, P2)
            tm2: dict[str, float] = {}
            res2 = solve_step(self, step2, asm2, tm2, t3)
            for k, v in tm2.items():
                if k != "total":
                    tm[k] = tm.get(k, 0.0) + v
            tm["relinearise"] = tm.get("relinearise", 0.0) + tm2["total"]
            tm["total"] = (time.perf_counter() - t0) * 1e3
            if res2.ok:
                res = replace(res2, timings_ms=tm, qps=res.qps + res2.qps,
                              message=f"re-linearised about the {about}")
                step = step2
            else:
                res = replace(res, timings_ms=tm, qps=res.qps + res2.qps)
        if res.ok:
            self._prev = (t, res.states, res.controls, res.mode)
            self._s_hint = float(step.s_bar[1])
        elif res.status == "fallback":
            self._prev = (t, res.states, res.controls, res.mode)
        return res


def controller_of_world(cls: Any, world: World, settings: MPCSettings, params: BicycleParams | None,
                        **kw: object) -> tuple[Any, list[Diagnostic]]:
    """``cls(world, rulesets, settings, params=…, **kw)`` with the world's own rule files and, by
    default, the bicycle parameters of the world's ego; (None, diagnostics) when a rule file has
    an error or the constructor rejects its arguments (MIL512). Shared by the MPC and the NMPC."""
    from twolevel.world.world import load_rulesets

    sets, diags = load_rulesets(world)
    if any(d.is_error for d in diags):
        return None, diags
    if params is None:
        params = BicycleParams().with_overrides({k: v for k, v in world.ego.vehicle.items()
                                                 if k in BicycleParams.__dataclass_fields__})
    try:
        ctrl = cls(world, sets, settings, params=params, **kw)
    except ValueError as e:
        return None, diags + [MIL512(str(e), Span(world.name))]
    return ctrl, diags + ctrl.diagnostics


def stop_memory_of(world: World, memory: StopMemory | None, hist: Mapping[str, np.ndarray], dt: float
                   ) -> StopMemory | None:
    """``memory``, or when none was given the stop memory replayed from the history's ``s`` [m]
    and ``v`` [m/s] samples (None when the route has no stop line or the history lacks them)."""
    if memory is None and len(world.route_stops) and "s" in hist and "v" in hist:
        memory = StopMemory.fresh(world)
        for s, v in zip(hist["s"], hist["v"]):
            memory = update_stop_memory(memory, world, float(s), float(v), dt)
    return memory


def _unpack(world_state: TrafficState | Snapshot | None) -> tuple[TrafficState, StopMemory | None]:
    if world_state is None:
        return _empty_traffic(), None
    if isinstance(world_state, Snapshot):
        return world_state.traffic, world_state.memory
    return world_state, None


def fallback_plan(ctrl: HighLevelController, step: StepData) -> tuple[np.ndarray, np.ndarray, str]:
    """The paper's fallback: the previous plan shifted by one step (its last control repeated), or
    full braking with the wheel straight when there is no previous plan. States re-rolled from now."""
    H, dt = ctrl.settings.H, ctrl.settings.dt
    prev = ctrl._prev
    if prev is not None and prev[2].shape[0] == H:
        u = np.vstack([prev[2][1:], prev[2][-1:]])
        why = "previous plan shifted"
    else:
        u = np.tile([0.0, ctrl.params.a_min], (H, 1))
        why = "no previous plan: full braking"
    xs = bicycle.rollout(step.x0, u, dt, ctrl.params)
    stopped = np.maximum.accumulate(xs[:, 3] <= 0.0)
    if stopped.any():  # no reversing: hold at standstill
        xs[:, 3] = np.maximum(xs[:, 3], 0.0)
    return xs, u, why


__all__ += ["fallback_plan"]

