"""Screening candidates on prefixes of their prediction (exact: it never changes the decision).

When every rule is prefix-bounded (:func:`twolevel.control.low_level.rules.prefix_bounded`), a
rule's robustness at k = 1 on the prediction cut after sample j is an upper bound of its
robustness on the whole prediction. So each round first rolls every candidate out over j steps
only and drops those a rule already rejects there (with more cuts, continues the survivors to
the next cut and drops again; on ``scalability`` a second cut at 6 did not pay for its extra
judgement); the survivors are continued from their state at the last cut (bit-identical to
rolling out the whole horizon) and judged in full. An intervention where nothing satisfies
(the full brake) costs about j / H of the rollouts instead of all of them, for one more
signals and monitor pass per cut.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from twolevel.control.low_level.judge import Judge
from twolevel.control.low_level.prediction import Predictor
from twolevel.models.actuation import accel_from_gamma
from twolevel.models.rollout import Rollout

__all__ = ["Screened", "screen", "continued"]


@dataclass(frozen=True, eq=False)
class Screened:
    """Which candidates survive the cuts (``keep`` (K,)), whether any was dropped (``pruned``),
    for each dropped one the bound of its worst rule robustness (``bound`` (K,), +inf for the
    kept), and the survivors' rollout up to the last cut (``prefix`` (n, done+1, 12))."""

    keep: np.ndarray
    pruned: bool
    bound: np.ndarray
    prefix: np.ndarray
    done: int


def screen(predictor: Predictor, judge: Judge, x0: np.ndarray, cand: np.ndarray, cuts: Sequence[int],
           tm: dict[str, float]) -> Screened:
    """Screen candidates (K, H, 2) [δ rad, γ] from the detailed state ``x0`` on the prediction
    cut after each of ``cuts`` in turn (see the module docstring)."""
    p = predictor.params
    keep = np.ones(len(cand), dtype=bool)
    bound = np.full(len(cand), np.inf)
    states = np.asarray(x0, dtype=float)[None, None, :].repeat(len(cand), axis=0)  # (K, 1, 12)
    done = 0
    for j in cuts:
        live = np.flatnonzero(keep)
        more = predictor.candidates(states[:, -1], cand[live, done:j], tm).states
        states = np.concatenate([states, more[:, 1:]], axis=1)  # (live, j+1, 12)
        # inputs per sample k = 0..j as the full judgement sees them (sample k carries the
        # input applied from k on)
        delta = cand[live, : j + 1, 0]
        if predictor.reads_a:
            accel = accel_from_gamma(cand[live, : j + 1, 1], np.maximum(states[:, :, 3], 0.0), p)
        else:
            accel = np.zeros_like(delta)  # no rule reads it
        rob = judge.prefix(states, accel, delta)
        table = np.stack(list(rob.values()))
        ok = ~np.any(table < 0, axis=0)
        keep[live[~ok]] = False
        bound[live[~ok]] = np.min(table[:, ~ok], axis=0)
        states, done = states[ok], j
        if not keep.any():
            break
    return Screened(keep, not keep.all(), bound, states, done)


def continued(predictor: Predictor, screened: Screened, cand: np.ndarray, tm: dict[str, float]) -> Rollout:
    """The full rollout of the survivors (their candidates ``cand``): the prefix continued from
    the last cut."""
    p = predictor.params
    j, pre = screened.done, screened.prefix
    rest = predictor.candidates(pre[:, -1], cand[:, j:], tm)
    return Rollout(np.concatenate([pre, rest.states[:, 1:]], axis=1), p.length, p.width)
