"""Judging candidates: every rule's robustness on K predicted trajectories at once.

**What "holds" means over a finite predicted window.** The trace a rule is judged on is the
recorded history (the last P samples the rules' past operators can reach) followed by the
prediction k = 0..H (k = 0 is now). A rule *holds* for a candidate when its robustness at
k = 1 — time t + dt, the first sample the candidate's control changes — is ≥ 0, with every
window truncated at the ends of that trace (RTAMT's offline semantics, as the MPC's encoding
uses). Consequences, by design:

* the current sample is not judged: nothing applied now can change it;
* a future window reaching beyond t + H·dt is cut at the horizon: ``always`` is judged on the
  part that is predicted, ``eventually`` must happen within it (``twolevel check`` warns about
  rules longer than the horizon);
* a rule the past has already decided (say ``historically`` over a violation) fails for every
  candidate, so the car brakes: the paper's rule, and what a safety monitor should do.

The predicted trajectories become the rules' signals by the world's definitions
(:func:`twolevel.world.sensing.sense`: the other vehicles' predictions, constant velocity relative
to their lanes (:mod:`twolevel.world.motion`),
``collision_free`` as the oriented-box separation), evaluated by the batched offline monitor
(:func:`twolevel.monitor.batch.evaluate_rules_batch`).
"""

from __future__ import annotations

import time
from typing import Mapping, Sequence

import numpy as np

from twolevel.control.low_level.rules import RuleCheck
from twolevel.monitor.batch import evaluate_rules_batch
from twolevel.stl import ast
from twolevel.world.provided import ON_DEMAND_SIGNALS, SIGNALS
from twolevel.world.sensing import Memory, Others, sense
from twolevel.world.world import World

__all__ = ["Judge", "history_length", "extend", "cut"]


def history_length(history: Mapping[str, np.ndarray] | None, past: int) -> int:
    """Past samples every signal of ``history`` has, at most ``past``: every signal a run records,
    and the on-demand ones it holds (a run records those only when a rule reads them)."""
    if not history or past == 0:
        return 0
    names = SIGNALS + tuple(n for n in ON_DEMAND_SIGNALS if n in history)
    return min([past] + [len(np.asarray(history.get(n, ()))) for n in names])


def extend(u: np.ndarray) -> np.ndarray:
    """Inputs (K, H) → per-sample values (K, H+1): sample k carries the input applied from k on,
    the last sample repeats the last input."""
    u = np.atleast_2d(u)
    return np.concatenate([u, u[:, -1:]], axis=1)


def cut(others: Others, T: int) -> Others:
    """The other vehicles over the first T samples."""
    return Others(others.x[:, :T], others.y[:, :T], others.psi[:, :T], others.v[:, :T], others.s[:, :T],
                  others.e[:, :T], others.length, others.width, others.index)


class Judge:
    """Every rule's robustness at t + dt for candidate predictions of one step: the world at
    time ``t`` [s] (``memory`` before this step, the ``others`` predicted over k = 0..H), the
    ego's route position ``s0`` [m], the ``history`` of every signal (its last ``P`` samples
    precede the prediction). Adds its time to ``timings_ms`` (signals, monitor)."""

    def __init__(self, world: World, rules: Sequence[RuleCheck], consts: Mapping[str, float], dt: float, t: float,
                 memory: Memory, others: Others, s0: float, history: Mapping[str, np.ndarray], P: int,
                 timings_ms: dict[str, float]) -> None:
        self.world, self.rules, self.consts, self.dt, self.t = world, rules, consts, dt, t
        self.memory, self.others, self.s0, self.history, self.P = memory, others, s0, history, P
        self.timings_ms = timings_ms

    def signals(self, states: np.ndarray, accel: np.ndarray, delta: np.ndarray, others: Others
                ) -> dict[str, np.ndarray]:
        """History ⊕ prediction: (K, P + T) arrays of every signal for detailed states (K, T, 12)
        and per-sample inputs ``accel`` [m/s²], ``delta`` [rad] (K, T)."""
        K, T, _ = states.shape
        X, Y, psi = states[..., 0], states[..., 1], states[..., 2]
        v = np.hypot(states[..., 3], states[..., 4]) * np.sign(states[..., 3])
        # each sample is projected near where its own path length puts it along the route
        step = np.hypot(np.diff(X, axis=1), np.diff(Y, axis=1))
        center = self.s0 + np.concatenate([np.zeros((K, 1)), np.cumsum(step, axis=1)], axis=1)
        pred = sense(self.world, self.t, self.dt, self.memory, others, X, Y, psi, v, accel, delta, s_center=center,
                     half_window=3.0)
        P = self.P
        if P == 0:
            return pred
        out = {}
        for name, arr in pred.items():
            h = np.asarray(self.history[name], dtype=float)[-P:]
            out[name] = np.concatenate([np.broadcast_to(h, (K, P)), arr], axis=1)
        return out

    def evaluate(self, signals: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Each rule's robustness (K,) at the first controlled sample (index P + 1)."""
        at = min(self.P + 1, next(iter(signals.values())).shape[1] - 1)
        full = evaluate_rules_batch([ast.Rule(r.name, r.formula) for r in self.rules], signals, self.dt,
                                    consts=self.consts)
        return {name: rob[:, at] for name, rob in full.items()}

    def _timed(self, states: np.ndarray, accel: np.ndarray, delta: np.ndarray, others: Others
               ) -> dict[str, np.ndarray]:
        tm = self.timings_ms
        t1 = time.perf_counter()
        sig = self.signals(states, accel, delta, others)
        t2 = time.perf_counter()
        rob = self.evaluate(sig)
        tm["signals"] = tm.get("signals", 0.0) + (t2 - t1) * 1e3
        tm["monitor"] = tm.get("monitor", 0.0) + (time.perf_counter() - t2) * 1e3
        return rob

    def __call__(self, states: np.ndarray, accel: np.ndarray, delta: np.ndarray) -> dict[str, np.ndarray]:
        """Robustness (K,) per rule of whole predictions: states (K, H+1, 12), the inputs
        ``accel`` [m/s²] and ``delta`` [rad] applied at each step (K, H)."""
        return self._timed(states, extend(accel), extend(delta), self.others)

    def prefix(self, states: np.ndarray, accel: np.ndarray, delta: np.ndarray) -> dict[str, np.ndarray]:
        """Robustness (K,) per rule of predictions cut after sample j: states (K, j+1, 12) and the
        inputs per sample (K, j+1) (sample k carries the input applied from k on)."""
        return self._timed(states, accel, delta, cut(self.others, states.shape[1]))
