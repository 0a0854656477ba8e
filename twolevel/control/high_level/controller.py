"""The high-level controller: a receding-horizon MPC whose traffic rules are MILCs (the paper's top level).

It implements :class:`~twolevel.control.planner.Planner`::

    ctrl = HighLevelController(world, rulesets, settings=MPCSettings(), params=BicycleParams())
    res  = ctrl.solve(ego, t, world_state, history)        # -> PlanResult
    ctrl.reset()                                           # forget the previous plan

* ``world``: :class:`~twolevel.world.world.World` (static scenario); ``rulesets``: bound
  :class:`~twolevel.stl.typecheck.RuleSet` s (``lint.load_ruleset(path, consts)``); every rule of
  every set the MPC can predict is required at the current step
  (:mod:`twolevel.control.high_level.rules`). ``HighLevelController.from_world(world)`` loads the
  scenario's own rule files and settings (returns ``(ctrl | None, diagnostics)``).
* ``settings``: :class:`~twolevel.control.high_level.settings.MPCSettings`.
* ``solve``: see :mod:`twolevel.control.planner`; the MPC plans from the ego's pose. On
  'fallback' the controls are the previous plan shifted by one step (or full braking when there
  is none, :mod:`twolevel.control.high_level.fallback`) and ``message`` says why.

One step: the step data (:mod:`twolevel.control.high_level.linearisation`: reference,
linearisation about the shifted previous plan, bounds, guards), the model
(:mod:`twolevel.control.high_level.problem`; a model of an already seen structure is refreshed
in place, :mod:`twolevel.control.high_level.template`), the solve path
(:mod:`twolevel.control.high_level.solvers`) on solver objects kept from step to step
(:mod:`twolevel.control.high_level.backend`), then the plan's rule robustness
(:mod:`twolevel.control.high_level.robustness`). A rule already violated now is required from a
later step (recovery, ``MIL517``); an infeasible step is re-linearised about the reference, then
about braking. What one step hands the next is :attr:`HighLevelController.carry`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Mapping, Sequence

import numpy as np

from twolevel.compiler.types import Requirement
from twolevel.control.codes import MIL515
from twolevel.control.high_level.backend import Backend, BackendCache
from twolevel.control.high_level.fallback import fallback_plan
from twolevel.control.high_level.overtaking import pass_lane
from twolevel.control.high_level.guards import Pass, stop_lines_read
from twolevel.control.high_level.linearisation import StepData, history_length, prepare_step
from twolevel.control.high_level.problem import Assembled, StepRules, assemble
from twolevel.control.high_level.robustness import plan_robustness
from twolevel.control.high_level.rules import MpcRule, mpc_rules
from twolevel.control.high_level.right_of_way import gap_rule
from twolevel.control.high_level.settings import MPCSettings
from twolevel.control.high_level.solvers import Attempt, solve_path
from twolevel.control.high_level.template import TemplateCache, refresh, template_of
from twolevel.control.planner import (EgoState, LookAhead, PlanResult, PlanStatus, PreviousPlan, Snapshot,
                                      WorldState, planner_of_world, stop_memory_of)
from twolevel.diagnostics import Diagnostic, Span
from twolevel.milp.model import PatternCache
from twolevel.milp.solution import Status
from twolevel.models.params import BicycleParams
from twolevel.stl.typecheck import RuleSet
from twolevel.world.world import World

__all__ = ["HighLevelController", "Carry"]

_OWN_PHASES = ("linearise", "assembly", "solve", "total", "relinearise", "unmargined")
"""Timing entries that are not phases of the solve (the rest sum to ``solve``)."""


@dataclass(frozen=True)
class Carry:
    """What one MPC step hands the next."""

    previous: PreviousPlan | None = None
    """The last plan (optimal, feasible or the fallback): linearisation point, seed, fallback."""
    s_hint: float | None = None
    """[m] Where on the route the ego is expected at the next step (narrows its projection)."""
    recover_at: Mapping[str, float] = field(default_factory=dict)
    """Rule being recovered → time [s] from which the last plan met it again."""
    passing: Pass | None = None
    """While the plans pass the vehicle ahead: when they are due beside it and on which side (set
    by the first plan that chose to pass, :data:`~twolevel.control.high_level.guards.BESIDE_FROM`
    later)."""


class HighLevelController:
    """The paper's MPC; see the module docstring."""

    label = "mpc"

    def __init__(self, world: World, rulesets: Sequence[RuleSet], settings: MPCSettings | None = None, *,
                 params: BicycleParams | None = None) -> None:
        self.world = world
        self.settings = settings or MPCSettings.of_world(world.settings)
        self.params = params or BicycleParams()
        self.path = solve_path(self.settings, world.route)
        self.rules: list[MpcRule]
        self.rules, diags = mpc_rules(rulesets, self.settings.dt)
        self.diagnostics: list[Diagnostic] = diags
        reads_all = set().union(*(r.reads for r in self.rules)) if self.rules else set()
        self.stop_rules = stop_lines_read(reads_all)
        self.gap = gap_rule(rulesets)
        self.templates = TemplateCache(capacity=4)
        self.carry = Carry()
        self._pattern_cache = PatternCache(capacity=16)
        self._backends = BackendCache(capacity=8)

    @classmethod
    def from_world(cls, world: World, settings: MPCSettings | None = None, *, solver: str | None = None,
                   params: BicycleParams | None = None) -> tuple["HighLevelController | None", list[Diagnostic]]:
        """The controller of a scenario's world with its own rule files and settings."""
        st = settings or MPCSettings.of_world(world.settings, solver=solver or world.settings.solver,
                                              time_limit=world.settings.time_limit, stop_decel=world.settings.yellow_decel)
        if solver is not None:
            st = replace(st, solver=solver)
        return planner_of_world(cls, world, st, params)

    @property
    def history_depth(self) -> int:
        """Past samples [steps] the rules' past operators reach."""
        return max((r.depth for r in self.rules), default=0)

    def reset(self) -> None:
        """Forget the previous plan (the next step linearises about the reference)."""
        self.carry = Carry()

    # ------------------------------------------------------------------ the step's model
    def requirements(self, drop: frozenset[str] = frozenset(), P: int = 0) -> list[Requirement]:
        """Every rule not in ``drop``, required at trace index ``P`` (now)."""
        return [Requirement(r.name, r.formula, (P,)) for r in self.rules if r.name not in drop]

    def step_rules(self, past: Mapping[str, np.ndarray], P: int, drop: frozenset[str] = frozenset(),
                   recover_after: Mapping[str, int] | None = None) -> StepRules:
        """What the rules not in ``drop`` ask of a step with ``P`` past samples of ``past``."""
        names = frozenset().union(*(r.reads for r in self.rules if r.name not in drop)) if self.rules else frozenset()
        return StepRules(tuple(self.requirements(drop, P)), names, past, P, recover_after)

    def prepare(self, ego: EgoState | Sequence[float], t: float, world_state: WorldState,
                history: Mapping[str, np.ndarray] | None, about: str = "plan"
                ) -> tuple[StepData, dict[str, np.ndarray], int]:
        """Linearise and gather the step's constants; returns (step data, past samples, P)."""
        dt = self.settings.dt
        snap = Snapshot.of(world_state)
        hist = {k: np.asarray(v, float) for k, v in (history or {}).items()}
        memory = stop_memory_of(self.world, snap.memory, hist, dt)
        prev = self.carry.previous
        if prev is not None and not prev.precedes(t, dt, self.settings.periods):
            prev = None
        u_prev = None
        if "delta" in hist and "a" in hist and len(hist["delta"]) and len(hist["a"]):
            u_prev = np.array([hist["delta"][-1], hist["a"][-1]])
        step = prepare_step(self.world, EgoState.of(ego).pose, t, snap.traffic, self.settings, self.params,
                            prev=prev, u_prev=u_prev, memory=memory, s_hint=self.carry.s_hint, about=about,
                            stop_rules=self.stop_rules, passing=self.carry.passing, gap=self.gap)
        names = set().union(*(r.reads for r in self.rules)) if self.rules else set()
        depth = max((r.depth for r in self.rules), default=0)
        P = history_length(hist, names, depth)
        return step, hist, P

    def build(self, step: StepData, past: Mapping[str, np.ndarray], P: int,
              drop: frozenset[str] = frozenset(), recover_after: Mapping[str, int] | None = None,
              margins: bool = True) -> Assembled:
        """The step's model with every rule not in ``drop`` (``margins`` False: each on its bound,
        without the settings' margins)."""
        st = self.settings if margins else replace(self.settings, margins=())
        rules = self.step_rules(past, P, drop, recover_after)
        key = (P, tuple(r.name for r in rules.requirements))
        use = st.refresh and st.solver == "modes" and not recover_after  # HiGHS: the minimal encoding
        if use:
            for tpl in self.templates.candidates(key):
                asm = refresh(tpl, step, rules, st, self.params)
                if asm is not None:
                    self.templates.touch(key, tpl)
                    self.templates.hits += 1
                    return asm
            self.templates.misses += 1
        asm = assemble(step, rules, st, self.params, cache=self._pattern_cache, stable=use)
        tpl = template_of(asm, st.eps) if use else None
        if tpl is not None:
            self.templates.add(key, tpl)
        return asm

    def backend(self, asm: Assembled) -> Backend:
        """The solver objects for ``asm``'s model: its template's own, or one of its shape."""
        tpl = self.templates.holding(asm)
        if tpl is None:
            return self._backends.get(asm)
        if tpl.backend is None:
            tpl.backend = Backend.of(asm)
        return tpl.backend

    # ------------------------------------------------------------------ one step
    def _warm(self) -> bool:
        """Whether the previous plan seeds the mode search (it spans the horizon)."""
        prev = self.carry.previous
        return prev is not None and prev.spans(self.settings.periods)

    def _solve_built(self, step: StepData, asm: Assembled, tm: dict[str, float], t0: float) -> PlanResult:
        """Solve the assembled step with the solve path; the fallback when nothing works."""
        st = self.settings
        model = asm.model
        diags = list(asm.diagnostics)
        att, msg = Attempt(), ""
        encode_error = any(d.is_error for d in asm.diagnostics)
        if encode_error:
            msg = "; ".join(d.message for d in asm.diagnostics if d.is_error)
        elif asm.encoding.infeasible:
            att, msg = Attempt(certified=True), "a rule is violated by signals known at solve time"
        else:
            t1 = time.perf_counter()
            backend = self.backend(asm)
            tm["backend"] = (time.perf_counter() - t1) * 1e3
            left = None if st.time_limit is None else max(st.time_limit * 1e3 - (time.perf_counter() - t0) * 1e3, 1.0)
            att = self.path.solve(asm, step, backend, left, self._warm())
            tm.update(att.timings_ms)
            if att.x is None:
                msg = ("no mode satisfies every rule" if att.status is PlanStatus.INFEASIBLE
                       else "no plan found within the time limit")
        tm["solve"] = sum(v for k, v in tm.items() if k not in _OWN_PHASES)
        tm["total"] = (time.perf_counter() - t0) * 1e3
        nb, nr, nc = model.n_binaries, model.n_rows, model.n_cols
        mode = np.asarray(att.mode)
        periods = np.asarray(st.periods)
        if att.x is None:
            states, controls, why = fallback_plan(self.carry.previous, step.x0, periods, st.dt, self.params)
            diags.append(MIL515(f"t = {step.t:.2f} s: {msg}; fallback: {why}", Span(self.world.name)))
            return PlanResult(PlanStatus.FALLBACK, float("nan"), controls[:st.H], states[:st.H + 1], mode, nb, nr, nc,
                              att.qps, att.certified, tm, {}, f"{att.status.value}: {msg}; fallback: {why}", att.gap,
                              tuple(diags), st.solver, None if encode_error else att.status,
                              look_ahead=self._look_ahead(states, controls))
        x = att.x
        states = np.vstack([step.x0[None], x[asm.layout.x]])
        controls = x[asm.layout.u]
        rob: dict[str, float] = {}
        if st.monitor:
            t4 = time.perf_counter()
            rob = plan_robustness(self.rules, step, asm, x, st.dt)
            tm["monitor"] = (time.perf_counter() - t4) * 1e3
        if asm.encoding.recovered:
            msg = "recovering: " + "; ".join(f"rule '{n}' violated now, required from k = {t2 - t}"
                                             for n, t, t2 in asm.encoding.recovered)
        return PlanResult(att.status, float(att.cost), controls[:st.H], states[:st.H + 1], mode, nb, nr, nc, att.qps,
                          bool(att.certified), tm, rob, msg, float(att.gap), tuple(diags), st.solver,
                          look_ahead=self._look_ahead(states, controls))

    def _look_ahead(self, states: np.ndarray, controls: np.ndarray) -> LookAhead | None:
        """The whole plan when the look-ahead is longer than the fine part (else None)."""
        st = self.settings
        return LookAhead(np.asarray(st.periods), st.dt, states, controls) if st.N > st.H else None

    def _recover_later(self, res: PlanResult, asm: Assembled, step: StepData, past: Mapping[str, np.ndarray], P: int,
                       tm: dict[str, float], t0: float) -> tuple[PlanResult, Assembled]:
        """A rule violated now was required from a step the solver still finds infeasible: require
        it later. The extra shift j (the same for every recovering rule) is found by a binary
        search on the feasibility of the step's relaxation (every disjunction undecided, one QP
        per probe; requiring a rule later never adds constraints, so feasibility is monotone in
        j), then the full solve at the first relaxation-feasible j, then one step later at a time
        while the mode search still finds no plan (within the time limit)."""
        lim = self.settings.time_limit
        if not res.ok and not asm.encoding.recovered and self.carry.recover_at:
            # the hinted start did not help (the rule may no longer be violated): plain build
            self.carry = replace(self.carry, recover_at={})
        if res.ok or res.status is PlanStatus.TIME_LIMIT or not asm.encoding.recovered:
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
            be = self.backend(a)
            x_int, disable = be.search.to_int(np.full(be.search.D, -1, np.int64))
            probes += 1
            return be.qp.solve(x_int, disable=disable).status is Status.OPTIMAL

        lo, hi = 1, j_max + 1  # first relaxation-feasible j in [lo, hi); hi = none
        while lo < hi and in_time():
            mid = (lo + hi) // 2
            if relaxed_feasible(mid):
                hi = mid
            else:
                lo = mid + 1
        j = lo
        while j <= j_max and not res.ok and res.status is not PlanStatus.TIME_LIMIT and in_time():
            asm = at(j)
            res = self._solve_built(step, asm, tm, t0)
            j += 1
        return (replace(res, qps=res.qps + probes) if probes else res), asm

    def solve(self, ego: EgoState | Sequence[float], t: float, world_state: WorldState = None,
              history: Mapping[str, np.ndarray] | None = None) -> PlanResult:
        """One MPC step (see :mod:`twolevel.control.planner`)."""
        tm: dict[str, float] = {}
        t0 = time.perf_counter()
        step, past, P = self.prepare(ego, t, world_state, history)
        t1 = time.perf_counter()
        tm["linearise"] = (t1 - t0) * 1e3
        # a rule being recovered: start from the time the previous plan met it again (the same
        # absolute time; earlier starts were infeasible then), not from the first step
        dt = self.settings.dt
        hint = {n: int(round((ta - t) / dt)) - 1 for n, ta in self.carry.recover_at.items()
                if int(round((ta - t) / dt)) >= 2}
        asm = self.build(step, past, P, recover_after=hint or None)
        t2 = time.perf_counter()
        tm["assembly"] = (t2 - t1) * 1e3
        res = self._solve_built(step, asm, tm, t0)
        res, asm = self._recover_later(res, asm, step, past, P, tm, t0)
        if res.ok and asm.encoding.recovered:
            self.carry = replace(self.carry, recover_at={n: t + (k2 - k1) * dt for n, k1, k2 in asm.encoding.recovered})
        elif res.ok:
            self.carry = replace(self.carry, recover_at={})
        # the linearisation about the previous plan can be far from a plan that now has to differ
        # (e.g. braking instead of swerving): re-linearise about the reference, then about braking
        for about in ("reference", "brake") if self.settings.relinearise else ():
            if res.ok or res.status is PlanStatus.TIME_LIMIT or (
                    self.settings.time_limit is not None and (time.perf_counter() - t0) > self.settings.time_limit):
                break
            t3 = time.perf_counter()
            step2, past2, P2 = self.prepare(ego, t, world_state, history, about=about)
            asm2 = self.build(step2, past2, P2)
            tm2: dict[str, float] = {}
            res2 = self._solve_built(step2, asm2, tm2, t3)
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
        res = self._unmargined(res, step, past, P, tm, t0)
        if res.ok:
            self.carry = replace(self.carry, previous=PreviousPlan.of(t, res), s_hint=float(step.s_bar[1]),
                                 passing=self._passing(step, res, t))
        elif res.status is PlanStatus.FALLBACK:
            self.carry = replace(self.carry, previous=PreviousPlan.of(t, res), passing=None)
        return res

    def _unmargined(self, res: PlanResult, step: StepData, past: Mapping[str, np.ndarray], P: int,
                    tm: dict[str, float], t0: float) -> PlanResult:
        """When no plan keeps the rules with their margins (``MPCSettings.margins``: proven
        infeasible, within the time limit) the step is planned with every rule on its bound
        (robustness ≥ eps): a margin is room for what the detailed car realises less well, never
        a reason to fall back. The encoder already drops a margin at a step whose known values
        leave no room for it (:func:`~twolevel.compiler.driver.margin_at`); this covers the
        dynamics leaving none."""
        st = self.settings
        lim = st.time_limit
        names = {r.name for r in self.rules}
        if res.ok or res.cause is not PlanStatus.INFEASIBLE or not any(n in names for n, m in st.margins if m > 0) \
                or (lim is not None and time.perf_counter() - t0 > lim):
            return res
        t1 = time.perf_counter()
        asm = self.build(step, past, P, margins=False)
        tm2: dict[str, float] = {}
        res2 = self._solve_built(step, asm, tm2, t1)
        tm["unmargined"] = tm2["total"]
        tm["total"] = (time.perf_counter() - t0) * 1e3
        if not res2.ok:
            return replace(res, timings_ms=tm, qps=res.qps + res2.qps)
        return replace(res2, timings_ms=tm, qps=res.qps + res2.qps, message="every rule on its bound (no plan keeps "
                       "the margins)" + (f"; {res2.message}" if res2.message else ""))

    def _passing(self, step: StepData, res: PlanResult, t: float) -> Pass | None:
        """The pass of the vehicle ahead under way after a plan made at ``t`` [s]: kept while the
        plans pass the same vehicle (the RSS terminal's disjunction, the model's first, chose a
        side), begun by the first that did, in the next lane on that side."""
        rss = step.rss
        if rss is None or not rss.active or not any(rss.sides) or not len(res.mode) or res.mode[0] == 0:
            return None
        p = self.carry.passing
        if p is not None and p.vehicle == rss.front:
            return p
        side = int(res.mode[0])
        e_front = (rss.left[-1] + rss.right[-1]) / 2  # the passed vehicle's lateral offset
        lane = pass_lane(self.world, float(step.s_bar[-1]), (rss.left[-1], rss.right[-1])[side - 1],
                         e_front + (step.lane_width if side == 1 else -step.lane_width))
        return Pass(t + rss.due, side, rss.front, lane)
