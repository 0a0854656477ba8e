"""The low-level controller: the paper's runtime monitor on the detailed model.

Each step, given the MPC's optimal controls u* = [δ, a] over the horizon:

1. forward-simulate the detailed four-wheel Pacejka model (:mod:`twolevel.models.rollout`,
   compiled, batched) from the ego's current detailed state under u* (a → γ through the
   actuation map at the speed the car has at each step);
2. turn the predicted trajectory into the rules' signals (:mod:`twolevel.world.sensing`: the
   definitions of :mod:`twolevel.world.signals`, the other vehicles' constant-velocity
   predictions, ``collision_free`` as the oriented-box separation) and evaluate every rule with
   the batched offline monitor (:mod:`twolevel.monitor.batch`);
3. if every rule holds, apply u*_0 (decision ``mpc``); otherwise sample candidates in the ball of
   radius r around u* (decision ``sampled``: the best-cost candidate that satisfies every rule);
   if none of the sampling budget does, brake fully (decision ``brake``) — unless the car is
   (almost) standing (|v| < 1 m/s) and braking is worse: then, when the braking rollout's worst
   rule robustness is below that of u* or of a sampled candidate, that least-violating choice
   is applied (decision ``least_violation``). Braking a standing car cannot cure a violation
   the others cause (traffic passing within D_safe of a car stopped half across a lane
   marking); braking forever there is a deadlock, not safety. At speed the paper's full brake
   stands: it sheds the most energy.

**What "holds" means over a finite predicted window.** The trace a rule is judged on is the
recorded history (the last P samples the rule's past operators can reach, P = its past depth
/ dt) followed by the prediction k = 0..H (k = 0 is now). A rule *holds* for a candidate when
its robustness at k = 1 — time t + dt, the first sample the candidate's control changes — is
≥ 0, with every window truncated at the ends of that trace (RTAMT's offline semantics, as the
MPC's encoding uses). Consequences, by design:

* the current sample is not judged: nothing applied now can change it;
* a future window reaching beyond t + H·dt is cut at the horizon: ``always`` is judged on the
  part that is predicted, ``eventually`` must happen within it (``twolevel check`` warns about
  rules longer than the horizon);
* a rule the past has already decided (say ``historically`` over a violation) fails for every
  candidate, so the car brakes: the paper's rule, and what a safety monitor should do.

**The ball.** Candidates perturb u* by an offset held over the whole horizon (a consistent
correction of the plan; its first element is applied), drawn uniformly from the disc of radius
r in the normalised actuator space (δ/δ_max, γ), γ ∈ [−1, 1] the throttle/brake command (the
space of the paper's CARLA controls, where r = 0.3), clipped to the actuator limits. Sampling
is seeded per step from the run's seed (``numpy.random.default_rng((seed, step))``) and runs in
rounds (32, 64, then the rest of the budget) so the usual case costs one small batch.

**Screening on prefixes** (``screen``: cuts j, default one at 3 steps; exact). When every rule
is *prefix-bounded* — built from pointwise predicates, past operators, ``and``/``or``,
``always`` and ``next`` (no ``eventually``/``until``/``unless`` and no negation above a future
operator; :func:`prefix_bounded`) — its robustness at k = 1 on the trace cut after the predicted
sample j is an upper bound of its robustness on the whole prediction (``always`` over fewer
samples, each signal at k ≤ j the same: the rollout and the signals are causal). So each round
first rolls every candidate out over j steps only and drops those a rule already rejects there
(with more cuts, continues the survivors to the next cut and drops again; on scalability a
second cut at 6 did not pay for its extra judgement); the survivors are continued from their
state at the last cut (bit-identical to rolling out the whole horizon) and judged in full. The
step's later rounds are screened only while screening drops something. Which candidate is
chosen, its robustness and the count of candidates tried do not change; an intervention where
nothing satisfies (the full brake) costs about j / H of the rollouts instead of all of them,
for one more signals and monitor pass per cut.

When the car is (almost) standing and the least-violating choice is enabled, that choice needs
the exact worst robustness of the best candidate: a dropped candidate whose prefix bound beats
the best so far (strictly) and reaches the round's best judged one (on a tie only from a lower
index: argmax takes the first) is judged in full as well, best bound first in growing batches,
the threshold rising as they are judged (branch and bound; the others cannot be chosen); when
that judges more than half a round, the step's later rounds are not screened.

**Cost of a candidate** (lower is better): Σ_{k=1..H} ‖p_k − p̂_k‖² + (v_k − v̂_k)² — the
distance of its detailed trajectory from the MPC's planned one (p̂, v̂: ``target``; the plan
already trades tracking of the waypoints against the rules) — plus ‖offset‖² in the normalised
space. **Full brake**: γ = −1 with the MPC's steering.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from twolevel.world.sensing import Memory, Others, others_predicted, sense
from twolevel.models.actuation import accel_from_gamma, gamma_from_accel
from twolevel.models.params import VehicleParams
from twolevel.models.obb import box_corners
from twolevel.models.rollout import Backend, Rollout, rollout, rollout_accel
from twolevel.monitor.batch import evaluate_rules_batch
from twolevel.stl import analysis, ast
from twolevel.stl.typecheck import RuleSet
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["LowLevelSettings", "Decision", "LowLevelController", "RuleCheck", "MAX_PAST", "prefix_bounded"]

STANDING = 1.0
"""Below this speed [m/s] braking changes little, so a least-violating choice may replace it."""

MAX_PAST = 3000
"""Past samples kept for a rule with an unbounded past operator (``once`` without a bound)."""


@dataclass(frozen=True)
class LowLevelSettings:
    """``r``: radius of the sampling ball in (δ/δ_max, γ) [-]; ``samples``: the sampling budget
    [candidates per step]; ``rounds``: candidates per round (the last is repeated until the
    budget is spent); ``seed``: the run's seed; ``delta_max`` [rad]: steering limit;
    ``backend``: rollout backend (:mod:`twolevel.models.rollout`); ``least_violation``: when
    nothing satisfies, do not brake if braking violates the rules worse than u* or a sampled
    candidate (see the module docstring); False is the paper's plain rule; ``screen``: the cuts j
    [steps] of the prediction on whose prefixes candidates are screened, in turn, before their
    full rollout (empty: off; see the module docstring; it never changes the decision)."""

    r: float = 0.3
    samples: int = 200
    rounds: tuple[int, ...] = (32, 64)
    seed: int = 0
    delta_max: float = 0.5
    backend: Backend = "auto"
    least_violation: bool = True
    screen: tuple[int, ...] = (3,)

    def round_sizes(self) -> list[int]:
        """Candidates per round, summing to ``samples``."""
        out: list[int] = []
        left = self.samples
        i = 0
        while left > 0:
            k = min(self.rounds[min(i, len(self.rounds) - 1)] if self.rounds else left, left)
            if i >= len(self.rounds):
                k = left  # the rest in one batch
            out.append(k)
            left -= k
            i += 1
        return out


@dataclass(frozen=True, eq=False)
class RuleCheck:
    """One rule as the low level judges it: name, self-contained formula, past depth [samples]."""

    name: str
    formula: ast.Node
    past: int


@dataclass(frozen=True, eq=False)
class Decision:
    """The low level's answer for one step.

    ``decision``: ``mpc`` (u* holds), ``sampled``, ``brake`` or ``least_violation``; ``control`` = [δ rad, γ] applied
    now; ``accel`` [m/s²]: the acceleration that γ commands at the current speed (quasi-static);
    ``candidates``: sampled candidates evaluated (0 when u* held); ``robustness``: each rule's
    robustness at t + dt for the applied choice (for ``brake``: the braking rollout's);
    ``mpc_robustness``: u*'s; ``states`` (H+1, 12): the applied choice's predicted detailed
    trajectory; ``timings_ms``: rollout / signals / monitor / total."""

    decision: str
    control: np.ndarray
    accel: float
    candidates: int
    robustness: dict[str, float]
    mpc_robustness: dict[str, float]
    states: np.ndarray
    timings_ms: dict[str, float] = field(default_factory=dict)

    @property
    def violated(self) -> tuple[str, ...]:
        """Rules u* violated (why the low level intervened)."""
        return tuple(k for k, v in self.mpc_robustness.items() if not v >= 0)


def rule_checks(rulesets: Sequence[RuleSet], dt: float) -> tuple[list[RuleCheck], dict[str, float]]:
    """The rules of bound rule sets as :class:`RuleCheck` s (formulas self-contained, constants
    substituted), and the constants (for rules that name them)."""
    out: list[RuleCheck] = []
    consts: dict[str, float] = {}
    for rs in rulesets:
        consts.update({k: float(v) for k, v in rs.consts.items() if v is not None})
        for r in rs.rules:
            f = rs.formula(r.name)
            depth = analysis.past_depth(f, dt)
            past = int(math.ceil(depth / dt - 1e-9)) if math.isfinite(depth) else MAX_PAST
            out.append(RuleCheck(r.name, f, min(past, MAX_PAST)))
    return out, consts


class LowLevelController:
    """The paper's bottom level (see the module docstring)."""

    def __init__(self, world: World, rules: Sequence[RuleCheck], *, params: VehicleParams | None = None,
                 settings: LowLevelSettings | None = None, consts: Mapping[str, float] | None = None) -> None:
        self.world = world
        self.rules = list(rules)
        self.params = params or VehicleParams()
        self.settings = settings or LowLevelSettings(r=world.settings.r, samples=world.settings.samples,
                                                     seed=world.settings.seed)
        self.consts = dict(consts or {})
        self.H = world.settings.H
        self.dt = world.settings.dt
        self.past = max((r.past for r in self.rules), default=0)
        self._reads_a = any("a" in analysis.signals_read(r.formula) for r in self.rules)
        self._cuts = tuple(sorted({j for j in self.settings.screen if 0 < j < self.H}))
        self._screen = bool(self._cuts) and bool(self.rules) and all(prefix_bounded(r.formula) for r in self.rules)

    @classmethod
    def from_rulesets(cls, world: World, rulesets: Sequence[RuleSet], **kw: object) -> "LowLevelController":
        rules, consts = rule_checks(rulesets, world.settings.dt)
        return cls(world, rules, consts=consts, **kw)  # type: ignore[arg-type]

    def warm_up(self, x0: np.ndarray) -> None:
        """Build (and compile) the rollout functions for every batch size used, so the first
        intervention does not pay for it."""
        u = np.zeros((1, self.H, 2))
        rollout_accel(x0, u, self.dt, self.params, self.settings.backend)
        for k in set(self.settings.round_sizes()):
            rollout(x0, np.zeros((k, self.H, 2)), self.dt, self.params, self.settings.backend)
            if self._screen:
                rollout(x0, np.zeros((k, self._cuts[0], 2)), self.dt, self.params, self.settings.backend)

    # ------------------------------------------------------------------ evaluation
    def _signals(self, states: np.ndarray, accel: np.ndarray, delta: np.ndarray, t: float, memory: Memory,
                 others: Others, s0: float, history: Mapping[str, np.ndarray], P: int) -> dict[str, np.ndarray]:
        """History ⊕ prediction: (K, P + H + 1) arrays of every signal."""
        K, T, _ = states.shape
        X, Y, psi = states[..., 0], states[..., 1], states[..., 2]
        v = np.hypot(states[..., 3], states[..., 4]) * np.sign(states[..., 3])
        # each sample is projected near where its own path length puts it along the route
        step = np.hypot(np.diff(X, axis=1), np.diff(Y, axis=1))
        center = s0 + np.concatenate([np.zeros((K, 1)), np.cumsum(step, axis=1)], axis=1)
        pred = sense(self.world, t, self.dt, memory, others, X, Y, psi, v, accel, delta, s_center=center,
                     half_window=3.0)
        if P == 0:
            return pred
        out = {}
        for name, arr in pred.items():
            h = np.asarray(history[name], dtype=float)[-P:]
            out[name] = np.concatenate([np.broadcast_to(h, (K, P)), arr], axis=1)
        return out

    def evaluate(self, signals: Mapping[str, np.ndarray], P: int) -> dict[str, np.ndarray]:
        """Each rule's robustness (K,) at the first controlled sample (index P + 1)."""
        at = min(P + 1, next(iter(signals.values())).shape[1] - 1)
        full = evaluate_rules_batch([ast.Rule(r.name, r.formula) for r in self.rules], signals, self.dt,
                                    consts=self.consts)
        return {name: rob[:, at] for name, rob in full.items()}

    def _history_length(self, history: Mapping[str, np.ndarray] | None) -> int:
        if not history or self.past == 0:
            return 0
        return min([self.past] + [len(np.asarray(history.get(n, ()))) for n in _SIGNALS])

    def _accel(self, gamma: np.ndarray, states: np.ndarray) -> np.ndarray:
        """The acceleration signal (K, H) of candidates given as γ: what γ commands (the
        quasi-static actuation map) when a rule reads ``a``, else the realised rate of change
        of the predicted speed (cheaper, and no rule looks at it)."""
        if self._reads_a:
            return accel_from_gamma(gamma, np.maximum(states[:, :-1, 3], 0.0), self.params)
        return np.diff(states[..., 3], axis=1) / self.dt

    def _cost(self, states: np.ndarray, target: np.ndarray, offset: np.ndarray) -> np.ndarray:
        dp = states[:, 1:, :2] - target[None, 1:, :2]
        v = np.hypot(states[:, 1:, 3], states[:, 1:, 4])
        dv = v - target[None, 1:, 3]
        return (dp ** 2).sum(axis=(1, 2)) + (dv ** 2).sum(axis=1) + (offset ** 2).sum(axis=1)

    # ------------------------------------------------------------------ one step
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
        p, st, H, dt = self.params, self.settings, self.H, self.dt
        u_star = np.asarray(u_star, dtype=float).reshape(H, 2)
        x0 = np.asarray(x0, dtype=float)
        v_now = float(x0[3])
        others = others_predicted(self.world, traffic, float(x0[0]), float(x0[1]), s0, H, dt, now=now)
        P = self._history_length(history)
        hist = history or {}

        def judge(states: np.ndarray, accel: np.ndarray, delta: np.ndarray) -> dict[str, np.ndarray]:
            t1 = time.perf_counter()
            sig = self._signals(states, _extend(accel), _extend(delta), t, memory, others, s0, hist, P)
            t2 = time.perf_counter()
            rob = self.evaluate(sig, P)
            tm["signals"] = tm.get("signals", 0.0) + (t2 - t1) * 1e3
            tm["monitor"] = tm.get("monitor", 0.0) + (time.perf_counter() - t2) * 1e3
            return rob

        t0 = time.perf_counter()
        ro = rollout_accel(x0, u_star[None], dt, p, st.backend)
        tm["rollout"] = (time.perf_counter() - t0) * 1e3
        gamma_star = gamma_from_accel(u_star[:, 1], ro.states[0, :-1, 3], p)
        rob = judge(ro.states, u_star[None, :, 1], u_star[None, :, 0])
        mpc_rob = {k: float(v[0]) for k, v in rob.items()}
        if all(v >= 0 for v in mpc_rob.values()):
            return self._done("mpc", np.array([u_star[0, 0], gamma_star[0]]), float(u_star[0, 1]), 0, mpc_rob,
                              mpc_rob, ro.states[0], tm, t_start)

        target = ro.states[0][:, [0, 1, 2, 3]] if target is None else np.asarray(target, dtype=float)
        rng = np.random.default_rng((st.seed, step))
        tried = 0
        best: tuple[float, np.ndarray, float, dict[str, float], np.ndarray] | None = None
        if rob:
            best = (min(mpc_rob.values()), np.array([u_star[0, 0], gamma_star[0]]), float(u_star[0, 1]), mpc_rob,
                    ro.states[0])
        base = np.stack([u_star[:, 0] / st.delta_max, gamma_star], axis=1)  # (H, 2) normalised
        screen = self._screen
        exact_worst = st.least_violation and abs(v_now) < STANDING  # the least-violating choice needs it
        for k in st.round_sizes():
            radius = st.r * np.sqrt(rng.random(k))
            angle = 2 * np.pi * rng.random(k)
            offset = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)  # (k, 2)
            cand = base[None] + offset[:, None, :]
            cand[..., 0] = np.clip(cand[..., 0], -1.0, 1.0) * st.delta_max
            cand[..., 1] = np.clip(cand[..., 1], -1.0, 1.0)
            tried += k
            bound = None
            if screen:
                keep, screen, bound = self._screened(x0, cand, t, memory, others, s0, hist, P, tm)
                # (the next rounds of this step are screened while it prunes)
                idx = np.flatnonzero(keep)
                t0 = time.perf_counter()
                states = self._continued(cand[idx]).states if len(idx) else np.zeros((0, H + 1, x0.shape[0]))
                tm["rollout"] += (time.perf_counter() - t0) * 1e3
            else:
                idx = np.arange(k)
                t0 = time.perf_counter()
                states = rollout(x0, cand, dt, p, st.backend).states
                tm["rollout"] += (time.perf_counter() - t0) * 1e3
            rob = judge(states, self._accel(cand[idx, :, 1], states), cand[idx, :, 0]) if len(idx) else {}
            ok = np.all(np.stack([v >= 0 for v in rob.values()]), axis=0) if rob else np.zeros(len(idx), dtype=bool)
            if ok.any():
                cost = np.where(ok, self._cost(states, target, offset[idx]), np.inf)
                j = int(np.argmin(cost))
                c = idx[j]
                a0 = float(accel_from_gamma(cand[c, 0, 1], max(float(x0[3]), 0.0), p))
                return self._done("sampled", cand[c, 0].copy(), a0, tried,
                                  {n: float(v[j]) for n, v in rob.items()}, mpc_rob, states[j], tm, t_start)
            worst = np.min(np.stack(list(rob.values())), axis=0) if rob else np.zeros(0)
            if bound is not None and exact_worst:
                # a dropped candidate can replace the best only if its prefix bound (≥ its worst
                # robustness) beats the best's (strictly) and reaches the round's best judged
                # one (on a tie, only from a lower index): judge those in full too (NaN: judge)
                b = best[0] if best is not None else -np.inf
                pool = np.flatnonzero(~keep & ~(bound <= b))
                pool = pool[np.lexsort((pool, -np.nan_to_num(bound[pool], nan=np.inf)))]  # best bound first
                size, judged = 4, 0
                while len(pool):
                    valid = ~np.isnan(worst)
                    m = float(np.max(worst[valid], initial=-np.inf))
                    jm = int(idx[np.flatnonzero(valid & (worst == m))[0]]) if np.isfinite(m) else k
                    bp = bound[pool]
                    pool = pool[~(bp < m) & ~((bp == m) & (pool > jm))]
                    extra, pool = pool[:size], pool[size:]
                    if not len(extra):
                        break
                    size, judged = size * 4, judged + len(extra)
                    t0 = time.perf_counter()
                    more = rollout(x0, cand[extra], dt, p, st.backend).states
                    tm["rollout"] += (time.perf_counter() - t0) * 1e3
                    rob_e = judge(more, self._accel(cand[extra, :, 1], more), cand[extra, :, 0])
                    order = np.argsort(np.concatenate([idx, extra]), kind="stable")
                    idx = np.concatenate([idx, extra])[order]
                    states = np.concatenate([states, more])[order]
                    rob = {n: (np.concatenate([rob[n], v]) if rob else v)[order] for n, v in rob_e.items()}
                    worst = np.min(np.stack(list(rob.values())), axis=0)
                if 2 * judged > k:
                    screen = False  # the bounds are loose here: the next rounds are judged in full directly
            if len(idx) and (bound is None or exact_worst):
                j = int(np.argmax(worst))
                if best is None or worst[j] > best[0]:
                    c = idx[j]
                    a0 = float(accel_from_gamma(cand[c, 0, 1], max(float(x0[3]), 0.0), p))
                    best = (float(worst[j]), cand[c, 0].copy(), a0, {n: float(v[j]) for n, v in rob.items()}, states[j])

        brake = np.stack([u_star[:, 0], -np.ones(H)], axis=1)
        t0 = time.perf_counter()
        rb = rollout(x0, brake[None], dt, p, st.backend)
        tm["rollout"] += (time.perf_counter() - t0) * 1e3
        accel = self._accel(brake[None, :, 1], rb.states)
        rob = judge(rb.states, accel, brake[None, :, 0])
        a0 = float(accel_from_gamma(-1.0, max(float(x0[3]), 0.0), p))
        brake_rob = {n: float(v[0]) for n, v in rob.items()}
        standing = abs(v_now) < STANDING
        if st.least_violation and standing and best is not None and brake_rob and best[0] > min(brake_rob.values()) + 1e-9:
            return self._done("least_violation", best[1], best[2], tried, best[3], mpc_rob, best[4], tm, t_start)
        return self._done("brake", brake[0].copy(), a0, tried, brake_rob, mpc_rob, rb.states[0], tm, t_start)

    def _screened(self, x0: np.ndarray, cand: np.ndarray, t: float, memory: Memory, others: Others, s0: float,
                  hist: Mapping[str, np.ndarray], P: int,
                  tm: dict[str, float]) -> tuple[np.ndarray, bool, np.ndarray]:
        """Which candidates (K, H, 2) [δ rad, γ] no rule rejects on the prediction cut after
        each of the ``screen`` samples in turn (an upper bound of each rule's robustness; see
        the module docstring), whether any was dropped, and for each dropped one the bound of
        its worst rule robustness (K,) (+inf for the kept). Keeps the survivors' rollout up to
        the last cut for :meth:`_continued`."""
        p = self.params
        keep = np.ones(len(cand), dtype=bool)
        bound = np.full(len(cand), np.inf)
        states = np.asarray(x0, dtype=float)[None, None, :].repeat(len(cand), axis=0)  # (K, 1, 12)
        done = 0
        for j in self._cuts:
            live = np.flatnonzero(keep)
            t0 = time.perf_counter()
            more = rollout(states[:, -1], cand[live, done:j], self.dt, p, self.settings.backend).states
            states = np.concatenate([states, more[:, 1:]], axis=1)  # (live, j+1, 12)
            t1 = time.perf_counter()
            tm["rollout"] = tm.get("rollout", 0.0) + (t1 - t0) * 1e3
            # inputs per sample k = 0..j as the full judgement sees them (sample k carries the
            # input applied from k on)
            delta = cand[live, : j + 1, 0]
            if self._reads_a:
                accel = accel_from_gamma(cand[live, : j + 1, 1], np.maximum(states[:, :, 3], 0.0), p)
            else:
                accel = np.zeros_like(delta)  # no rule reads it
            sig = self._signals(states, accel, delta, t, memory, _cut(others, j + 1), s0, hist, P)
            t2 = time.perf_counter()
            rob = self.evaluate(sig, P)
            tm["signals"] = tm.get("signals", 0.0) + (t2 - t1) * 1e3
            tm["monitor"] = tm.get("monitor", 0.0) + (time.perf_counter() - t2) * 1e3
            table = np.stack(list(rob.values()))
            ok = ~np.any(table < 0, axis=0)
            keep[live[~ok]] = False
            bound[live[~ok]] = np.min(table[:, ~ok], axis=0)
            states, done = states[ok], j
            if not keep.any():
                break
        self._prefix, self._done_steps = states, done
        return keep, not keep.all(), bound

    def _continued(self, cand: np.ndarray) -> Rollout:
        """The full rollout of the screened candidates: their prefix continued from the last cut."""
        j, pre = self._done_steps, self._prefix
        rest = rollout(pre[:, -1], cand[:, j:], self.dt, self.params, self.settings.backend)
        states = np.concatenate([pre, rest.states[:, 1:]], axis=1)
        boxes = np.concatenate([box_corners(pre[..., 0], pre[..., 1], pre[..., 2], self.params.length,
                                            self.params.width), rest.boxes[:, 1:]], axis=1)
        return Rollout(states=states, boxes=boxes)

    def _done(self, decision: str, control: np.ndarray, accel: float, tried: int, rob: dict[str, float],
              mpc_rob: dict[str, float], states: np.ndarray, tm: dict[str, float], t_start: float) -> Decision:
        tm["total"] = (time.perf_counter() - t_start) * 1e3
        return Decision(decision, control, accel, tried, rob, mpc_rob, states, tm)


_SIGNALS = ("x", "y", "psi", "v", "a", "delta", "s", "e", "v_max", "d_stop", "light_red", "d_light", "d_lead",
            "v_lead", "min_gap", "n_near")


_POINTWISE_CALLS = frozenset({"collision_free"})
"""Built-in predicates whose value at a sample depends on the signals at that sample only."""


def _causal(node: ast.Node) -> bool:
    """No future operator and no built-in that could look beyond the sample: the value at k
    depends on samples ≤ k only."""
    for n in node.walk():
        if isinstance(n, ast.Temporal) and n.op in ("always", "eventually", "next"):
            return False
        if isinstance(n, ast.BinTemporal) and n.op != "since":
            return False
        if isinstance(n, ast.Call) and n.name not in _POINTWISE_CALLS:
            return False
    return True


def prefix_bounded(node: ast.Node) -> bool:
    """Whether a formula's robustness at any sample of a trace cut short is ≥ its robustness on
    the whole trace (windows truncated at the end, RTAMT's offline semantics): causal formulas,
    and ``and``/``or``/``always``/``next``/past operators over prefix-bounded operands
    (``implies`` with a causal antecedent). Conservative: False when unsure."""
    if _causal(node):
        return True
    if isinstance(node, ast.Binary):
        if node.op in ("and", "or"):
            return prefix_bounded(node.left) and prefix_bounded(node.right)
        if node.op == "implies":
            return _causal(node.left) and prefix_bounded(node.right)
        return False
    if isinstance(node, ast.Temporal):
        return node.op in ("always", "next", "historically", "once", "prev") and prefix_bounded(node.operand)
    if isinstance(node, ast.BinTemporal):
        return node.op == "since" and prefix_bounded(node.left) and prefix_bounded(node.right)
    return False


def _cut(others: Others, T: int) -> Others:
    """The other vehicles over the first T samples."""
    return Others(others.x[:, :T], others.y[:, :T], others.psi[:, :T], others.v[:, :T], others.s[:, :T],
                  others.e[:, :T], others.length, others.width, others.index)


def _extend(u: np.ndarray) -> np.ndarray:
    """Inputs (K, H) → per-sample values (K, H+1): sample k carries the input applied from k on,
    the last sample repeats the last input."""
    u = np.atleast_2d(u)
    return np.concatenate([u, u[:, -1:]], axis=1)
