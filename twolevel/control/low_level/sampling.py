"""Sampling the ball around u* for a control that satisfies every rule.

**The ball.** Candidates perturb u* by an offset held over the whole horizon (a consistent
correction of the plan; its first element is applied), drawn uniformly from the disc of radius
r in the normalised actuator space (δ/δ_max, γ), γ ∈ [−1, 1] the throttle/brake command (the
space of the paper's CARLA controls, where r = 0.3), clipped to the actuator limits. Sampling
is seeded per step from the run's seed (``numpy.random.default_rng((seed, step))``) and runs in
rounds (32, 64, then the rest of the budget) so the usual case costs one small batch.

**With the safety layer on** only the first ``rounds`` rounds are sampled
(``LowLevelSettings.safety_rounds``, one by default): the first round finds the correction in
most steps that have one (about 95 % on the paper's scenarios), and a step without one brakes
(or takes the least-violating choice) at once instead of spending the paper's whole budget
(100–250 ms when nothing satisfies) — the safety layer, not the budget, keeps the car safe.

**Cost of a candidate** (lower is better): Σ_{k=1..H} ‖p_k − p̂_k‖² + (v_k − v̂_k)² — the
distance of its detailed trajectory from the MPC's planned one (p̂, v̂: ``target``; the plan
already trades tracking of the waypoints against the rules) — plus ‖offset‖² in the normalised
space. The best-cost candidate that satisfies every rule is the answer.

**Screening** (:mod:`twolevel.control.low_level.screening`): a round's candidates are first
judged on prefixes; the step's later rounds are screened only while screening drops something.
Which candidate is chosen, its robustness and the count of candidates tried do not change.
When the car is (almost) standing and the least-violating choice is enabled
(:mod:`twolevel.control.low_level.brake`), that choice needs the exact worst robustness of the
best candidate: a dropped candidate whose prefix bound beats the best so far (strictly) and
reaches the round's best judged one (on a tie only from a lower index: argmax takes the first)
is judged in full as well, best bound first in growing batches, the threshold rising as they
are judged (branch and bound; the others cannot be chosen); when that judges more than half a
round, the step's later rounds are not screened.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from twolevel.control.low_level.decision import Choice
from twolevel.control.low_level.judge import Judge
from twolevel.control.low_level.prediction import Predictor
from twolevel.control.low_level.screening import continued, screen
from twolevel.control.low_level.settings import LowLevelSettings
from twolevel.models.actuation import accel_from_gamma

__all__ = ["Sampled", "sample_ball", "candidate_cost"]


@dataclass(frozen=True, eq=False)
class Sampled:
    """What sampling found: a candidate that satisfies every rule (``found``, None when none
    did), how many candidates it ``tried``, and the least-violating choice so far (``best``:
    u* or a judged candidate; None without rules)."""

    found: Choice | None
    tried: int
    best: Choice | None


def candidate_cost(states: np.ndarray, target: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """The cost (K,) of candidates' detailed trajectories (K, H+1, 12) against the plan
    ``target`` (H+1, 4) [X, Y, ψ, v], with their normalised ``offset`` (K, 2) (see the module
    docstring)."""
    dp = states[:, 1:, :2] - target[None, 1:, :2]
    v = np.hypot(states[:, 1:, 3], states[:, 1:, 4])
    dv = v - target[None, 1:, 3]
    return (dp ** 2).sum(axis=(1, 2)) + (dv ** 2).sum(axis=1) + (offset ** 2).sum(axis=1)


def _choice(cand: np.ndarray, c: int, j: int, worst: float, rob: dict[str, np.ndarray], states: np.ndarray,
            v0: float, predictor: Predictor) -> Choice:
    """Candidate ``c`` (row ``j`` of the judged ones) as a choice."""
    a0 = float(accel_from_gamma(cand[c, 0, 1], max(v0, 0.0), predictor.params))
    return Choice(worst, cand[c, 0].copy(), a0, {n: float(v[j]) for n, v in rob.items()}, states[j])


def sample_ball(x0: np.ndarray, u_star: np.ndarray, gamma_star: np.ndarray, target: np.ndarray,
                mpc: Choice | None, settings: LowLevelSettings, rng: np.random.Generator, predictor: Predictor,
                judge: Judge, cuts: Sequence[int], screening: bool, exact_worst: bool,
                tm: dict[str, float], rounds: int | None = None) -> Sampled:
    """Sample the ball around the plan ``u_star`` (H, 2) [δ rad, a m/s²] (γ: ``gamma_star`` (H,))
    from the detailed state ``x0`` in rounds, with ``rng``; ``target``: the plan's states;
    ``mpc``: u* as a choice; ``screening`` on the prefixes ``cuts``; ``exact_worst``: track the
    least-violating choice exactly; ``rounds``: sample at most that many rounds (None: the whole
    budget; see the module docstring)."""
    st = settings
    H = u_star.shape[0]
    tried = 0
    best = mpc
    base = np.stack([u_star[:, 0] / st.delta_max, gamma_star], axis=1)  # (H, 2) normalised
    v0 = float(x0[3])
    for k in st.round_sizes()[:rounds]:
        radius = st.r * np.sqrt(rng.random(k))
        angle = 2 * np.pi * rng.random(k)
        offset = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)  # (k, 2)
        cand = base[None] + offset[:, None, :]
        cand[..., 0] = np.clip(cand[..., 0], -1.0, 1.0) * st.delta_max
        cand[..., 1] = np.clip(cand[..., 1], -1.0, 1.0)
        tried += k
        bound = None
        if screening:
            scr = screen(predictor, judge, x0, cand, cuts, tm)
            keep, bound = scr.keep, scr.bound
            screening = scr.pruned  # (the next rounds of this step are screened while it prunes)
            idx = np.flatnonzero(keep)
            states = (continued(predictor, scr, cand[idx], tm).states if len(idx)
                      else np.zeros((0, H + 1, x0.shape[0])))
        else:
            idx = np.arange(k)
            states = predictor.candidates(x0, cand, tm).states
        rob = judge(states, predictor.accel(cand[idx, :, 1], states), cand[idx, :, 0]) if len(idx) else {}
        ok = np.all(np.stack([v >= 0 for v in rob.values()]), axis=0) if rob else np.zeros(len(idx), dtype=bool)
        if ok.any():
            cost = np.where(ok, candidate_cost(states, target, offset[idx]), np.inf)
            j = int(np.argmin(cost))
            return Sampled(_choice(cand, idx[j], j, float(np.min([v[j] for v in rob.values()])), rob, states, v0,
                                   predictor), tried, best)
        worst = np.min(np.stack(list(rob.values())), axis=0) if rob else np.zeros(0)
        if bound is not None and exact_worst:
            # a dropped candidate can replace the best only if its prefix bound (≥ its worst
            # robustness) beats the best's (strictly) and reaches the round's best judged
            # one (on a tie, only from a lower index): judge those in full too (NaN: judge)
            b = best.worst if best is not None else -np.inf
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
                more = predictor.candidates(x0, cand[extra], tm).states
                rob_e = judge(more, predictor.accel(cand[extra, :, 1], more), cand[extra, :, 0])
                order = np.argsort(np.concatenate([idx, extra]), kind="stable")
                idx = np.concatenate([idx, extra])[order]
                states = np.concatenate([states, more])[order]
                rob = {n: (np.concatenate([rob[n], v]) if rob else v)[order] for n, v in rob_e.items()}
                worst = np.min(np.stack(list(rob.values())), axis=0)
            if 2 * judged > k:
                screening = False  # the bounds are loose here: the next rounds are judged in full directly
        if len(idx) and (bound is None or exact_worst):
            j = int(np.argmax(worst))
            if best is None or worst[j] > best.worst:
                best = _choice(cand, idx[j], j, float(worst[j]), rob, states, v0, predictor)
    return Sampled(None, tried, best)
