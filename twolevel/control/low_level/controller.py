"""The low-level controller: the paper's runtime monitor on the detailed model.

Each step, given the MPC's optimal controls u* = [δ, a] over the horizon:

1. forward-simulate the detailed four-wheel Pacejka model from the ego's current detailed
   state under u* (:mod:`twolevel.control.low_level.prediction`);
2. judge every rule on the predicted trajectory (:mod:`twolevel.control.low_level.judge`: the
   world's signal definitions and the batched offline monitor);
3. if every rule holds, apply u*_0 (decision ``mpc``); otherwise sample candidates in the ball
   of radius r around u* (:mod:`twolevel.control.low_level.sampling`, screened on prefixes by
   :mod:`twolevel.control.low_level.screening`; decision ``sampled``: the best-cost candidate
   that satisfies every rule); if none of the sampling budget does, brake fully (decision
   ``brake``) — or, for a standing car where braking is worse, apply the least-violating
   choice (decision ``least_violation``; :mod:`twolevel.control.low_level.brake`);
4. **the safety layer** (on by default, :mod:`twolevel.control.low_level.guard`): u*_0 is
   verified first; when it does not verify the plan is unsafe and the step is an emergency:
   the fail-safe verified earlier runs at once (decision ``failsafe``), nothing is sampled. When
   it verifies and the rules hold, it runs; when the rules chose another control (a candidate,
   the brake), that one is verified in turn, and runs if it verifies; else, for a candidate
   (a correction of u* within the ball), u*_0 — verified — runs when it breaks the rules no
   more than the fail-safe would over the horizon (decision ``mpc``, the rules it breaks on the
   prediction recorded), and otherwise, or for the brake, the fail-safe does.
   So a control runs only if a fail-safe after it was verified, whatever the planner and
   whichever rules the scenario lists. With the layer on, sampling is cut to its first round
   (``safety_rounds``; :mod:`twolevel.control.low_level.sampling`): no step spends the whole
   budget before it brakes.

The answer is a :class:`~twolevel.control.low_level.decision.Decision`; the rules as the low
level judges them are :class:`~twolevel.control.low_level.rules.RuleCheck` s.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Mapping, Sequence

import numpy as np

from twolevel.control.low_level.brake import STANDING, full_brake, prefer_least_violation
from twolevel.control.low_level.decision import Action, Choice, Decision
from twolevel.control.low_level.guard import OFF, Check, Guard
from twolevel.control.low_level.judge import Judge, history_length
from twolevel.control.low_level.prediction import Predictor
from twolevel.control.low_level.rules import RuleCheck, prefix_bounded, rule_checks
from twolevel.control.low_level.sampling import sample_ball
from twolevel.control.low_level.settings import LowLevelSettings
from twolevel.models.actuation import accel_from_gamma, gamma_from_accel
from twolevel.models.params import VehicleParams
from twolevel.safety.verify import Context, Verdict, context
from twolevel.stl import analysis
from twolevel.stl.typecheck import RuleSet
from twolevel.world.sensing import Memory, Others, others_predicted
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["LowLevelController"]


class LowLevelController:
    """The paper's bottom level (see the module docstring)."""

    def __init__(self, world: World, rules: Sequence[RuleCheck], *, params: VehicleParams | None = None,
                 settings: LowLevelSettings | None = None, consts: Mapping[str, float] | None = None,
                 safety: Context | None = None) -> None:
        self.world = world
        self.rules = list(rules)
        self.params = params or VehicleParams()
        self.settings = settings or LowLevelSettings.of(world.settings)
        self.consts = dict(consts or {})
        self.H = world.settings.H
        self.dt = world.settings.dt
        self.past = max((r.past for r in self.rules), default=0)
        reads_a = any("a" in analysis.signals_read(r.formula) for r in self.rules)
        self.predictor = Predictor(self.params, self.H, self.dt, self.settings.backend, reads_a)
        self.cuts = tuple(sorted({j for j in self.settings.screen if 0 < j < self.H}))
        self._screens = bool(self.cuts) and bool(self.rules) and all(prefix_bounded(r.formula) for r in self.rules)
        self.guard = Guard(safety or context(world, self.params)) if self.settings.safety else None

    @classmethod
    def from_rulesets(cls, world: World, rulesets: Sequence[RuleSet], **kw: object) -> "LowLevelController":
        rules, consts = rule_checks(rulesets, world.settings.dt)
        return cls(world, rules, consts=consts, **kw)  # type: ignore[arg-type]

    @property
    def screens(self) -> bool:
        """Whether candidates are screened on prefixes (cuts set and every rule prefix-bounded)."""
        return self._screens

    def warm_up(self, x0: np.ndarray) -> None:
        """Build (and compile) the rollout functions for every batch size used, so the first
        intervention does not pay for it."""
        self.predictor.warm_up(x0, set(self.settings.round_sizes()), self.cuts[0] if self._screens else None)

    def decide(self, x0: np.ndarray, u_star: np.ndarray, t: float, traffic: TrafficState, memory: Memory, s0: float,
               history: Mapping[str, np.ndarray] | None = None, *, target: np.ndarray | None = None,
               step: int = 0, now: Others | None = None) -> Decision:
        """The control to apply now from the detailed state ``x0`` (12,), the MPC's controls
        ``u_star`` (H, 2) [δ rad, a m/s²], time ``t`` [s], the traffic now, the sensing memory
        before this step, the ego's route position ``s0`` [m], the recorded ``history`` of every
        signal (oldest first, excluding now), the plan's states ``target`` (H+1, 4) [X, Y, ψ, v]
        and the step number (seeds the sampling); ``now``: the vehicles sensed now
        (:func:`~twolevel.world.sensing.others_now` at x0, s0), when the caller has them."""
        tm: dict[str, float] = {}
        t_start = time.perf_counter()
        st, H, dt = self.settings, self.H, self.dt
        u_star = np.asarray(u_star, dtype=float).reshape(H, 2)
        x0 = np.asarray(x0, dtype=float)
        v_now = float(x0[3])
        others = others_predicted(self.world, traffic, float(x0[0]), float(x0[1]), s0, H, dt, now=now)
        P = history_length(history, self.past)
        judge = Judge(self.world, self.rules, self.consts, dt, t, memory, others, s0, history or {}, P, tm)

        ro = self.predictor.plan(x0, u_star, tm)
        gamma_star = gamma_from_accel(u_star[:, 1], ro.states[0, :-1, 3], self.params)
        intended = np.stack([u_star[:, 0], gamma_star], axis=1)
        rob = judge(ro.states, u_star[None, :, 1], u_star[None, :, 0])
        mpc_rob = {k: float(v[0]) for k, v in rob.items()}
        mpc = Choice(min(mpc_rob.values()) if mpc_rob else np.inf, intended[0].copy(),
                     float(u_star[0, 1]), mpc_rob, ro.states[0])
        guard = self.guard
        first = self._verify(x0, mpc.control, traffic, t, s0, tm) if guard is not None else None
        if first is not None and not first.verified:  # the plan is unsafe: no sampling, the fail-safe now
            return self._fall_back(x0, u_star, mpc, first, 0, mpc_rob, intended, tm, t_start, first)
        if all(v >= 0 for v in mpc_rob.values()):
            safety = self._first(guard.commit(first), first) if guard is not None and first is not None else OFF
            return self._done(Action.MPC, mpc, 0, mpc_rob, intended, safety, tm, t_start)

        target = ro.states[0][:, [0, 1, 2, 3]] if target is None else np.asarray(target, dtype=float)
        rng = np.random.default_rng((st.seed, step))
        exact_worst = st.least_violation and abs(v_now) < STANDING  # the least-violating choice needs it
        sampled = sample_ball(x0, u_star, gamma_star, target, mpc if rob else None, st, rng, self.predictor, judge,
                              self.cuts, self._screens, exact_worst, tm, st.safety_rounds if guard is not None else None)
        if sampled.found is not None:
            action, choice = Action.SAMPLED, sampled.found
        else:
            braking = full_brake(x0, u_star, self.predictor, judge, tm)
            if prefer_least_violation(sampled.best, braking, v_now, st.least_violation):
                assert sampled.best is not None
                action, choice = Action.LEAST_VIOLATION, sampled.best
            else:
                action, choice = Action.BRAKE, braking
        if guard is None or first is None:
            return self._done(action, choice, sampled.tried, mpc_rob, intended, OFF, tm, t_start)
        again = first if np.array_equal(choice.control, mpc.control) else self._verify(x0, choice.control, traffic,
                                                                                      t, s0, tm)
        if not again.verified and action is not Action.BRAKE and self._plan_no_worse(x0, mpc, judge):
            # a correction of u* that does not verify: u*'s own first command verified, and it
            # breaks the rules no more than the kept fail-safe would (which, keeping its speed in
            # a junction, broke clear_junction at once while u* was still speeding up to leave)
            why = str(again.refuted_by) if again.refuted_by is not None else ""
            return self._done(Action.MPC, mpc, sampled.tried, mpc_rob, intended,
                              self._first(replace(guard.commit(first), refuted=why), first), tm, t_start)
        if not again.verified:
            return self._fall_back(x0, u_star, choice, again, sampled.tried, mpc_rob, intended, tm, t_start, first)
        return self._done(action, choice, sampled.tried, mpc_rob, intended, self._first(guard.commit(again), first), tm,
                          t_start)

    def start(self, x0: np.ndarray, traffic: TrafficState, t: float, s0: float) -> Verdict | None:
        """Check the initial state (:meth:`Guard.start`); None when the safety layer is off."""
        return self.guard.start(x0, traffic, t, s0) if self.guard is not None else None

    def _verify(self, x0: np.ndarray, control: np.ndarray, traffic: TrafficState, t: float, s0: float,
                tm: dict[str, float]) -> Verdict:
        assert self.guard is not None
        t0 = time.perf_counter()
        v = self.guard.verify(x0, control, traffic, t, s0)
        tm["verify"] = tm.get("verify", 0.0) + (time.perf_counter() - t0) * 1e3
        return v

    def _fall_back(self, x0: np.ndarray, u_star: np.ndarray, choice: Choice, refuted: Verdict, tried: int,
                   mpc_rob: dict[str, float], intended: np.ndarray, tm: dict[str, float], t_start: float,
                   first: Verdict) -> Decision:
        """The kept fail-safe's command (decision ``failsafe``); without one, full braking with the
        plan's steering, unverified (decision ``brake``). ``refuted``: the verdict on the rules'
        choice; ``first``: on u*'s first command."""
        assert self.guard is not None
        u, safety = self.guard.fall_back(x0, refuted)
        safety = self._first(safety, first)
        if u is None:
            brake = Choice(choice.worst, np.array([u_star[0, 0], -1.0]), self._accel(-1.0, x0), choice.robustness,
                           choice.states)
            return self._done(Action.BRAKE, brake, tried, mpc_rob, intended, safety, tm, t_start)
        run = Choice(choice.worst, u, self._accel(float(u[1]), x0), choice.robustness, choice.states)
        return self._done(Action.FAILSAFE, run, tried, mpc_rob, intended, safety, tm, t_start)

    def _plan_no_worse(self, x0: np.ndarray, mpc: Choice, judge: Judge) -> bool:
        """Whether u* (verified) breaks the rules no more on the detailed prediction (its worst
        robustness is at least as high) than the fail-safe the guard would run from ``x0``
        over the next H steps (its own states: replayed, it reproduces them; standing after its
        end); True when there is none to run."""
        assert self.guard is not None
        fs, k = self.guard.kept, self.guard.k
        if fs is None or not self.guard.on_track(x0):
            return True
        states = fs.states[np.minimum(np.arange(k, k + self.H + 1), fs.steps)]
        u = np.array([fs.control_at(k + j) for j in range(self.H)])  # H commands, the held brake after its end
        accel = accel_from_gamma(u[:, 1], np.maximum(states[:-1, 3], 0.0), self.params)
        rob = judge(states[None], accel[None], u[None, :, 0])
        return mpc.worst >= min((float(v[0]) for v in rob.values()), default=np.inf)

    def _accel(self, gamma: float, x0: np.ndarray) -> float:
        """The acceleration [m/s²] γ commands at the car's speed (quasi-static)."""
        return float(accel_from_gamma(gamma, max(float(x0[3]), 0.0), self.params))

    def _done(self, action: Action, choice: Choice, tried: int, mpc_rob: dict[str, float], intended: np.ndarray,
              safety: Check, tm: dict[str, float], t_start: float) -> Decision:
        tm["total"] = (time.perf_counter() - t_start) * 1e3
        return Decision(action, choice.control, choice.accel, tried, choice.robustness, mpc_rob, choice.states, tm,
                        safety, intended)

    def _first(self, check: Check, first: Verdict) -> Check:
        """``check`` recording whether u*'s first command verified."""
        return replace(check, plan_first=first.verified)
