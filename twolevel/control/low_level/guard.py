"""The safety layer of the low level: every control it applies is verified, or it is the
fail-safe verified earlier (online verification, :mod:`twolevel.safety`; its guarantee, what it
rests on and its limits are stated in ``twolevel/safety/__init__.py``).

Each step the low level asks the :class:`Guard` about the control the rules chose (u*'s first
control of any planner, a sampled correction, the brake):

* :meth:`Guard.verify` — :func:`~twolevel.safety.verify.verify_step`: after that step, does a
  fail-safe exist that avoids every place the others may legally be until the car stands, and
  stands where nobody may legally come?
* verified → :meth:`Guard.commit`: the control runs and its fail-safe is **kept** (its commands
  start at the state after this step);
* not verified → :meth:`Guard.fall_back`: the kept fail-safe runs, one step further each step
  (``control_at(k)``, k steps after the step that verified it). By induction one is always at
  hand: the first comes from the initial state (:meth:`Guard.start`).

Outcomes per step (the trace's ``verification`` column, :class:`Outcome`): ``verified``,
``failsafe`` (the kept fail-safe ran), ``unverified`` (nothing was kept — the start was unsafe
and no control has verified since, or the car is not where the kept fail-safe put it; the low
level then brakes fully, unverified) and ``off`` (the layer is switched off).

A fail-safe is executed only from the state it was verified for: the plant is the model it was
rolled out on, so the car is exactly where the fail-safe says; if it is not (a plant that
differs, a state set from outside), the fail-safe is dropped and the step is ``unverified``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twolevel.milp.solution import ValueEnum
from twolevel.safety.failsafe import FailSafe
from twolevel.safety.verify import Context, Verdict, verify_initial_state, verify_step
from twolevel.world.traffic import TrafficState

__all__ = ["Outcome", "Check", "OFF", "Guard", "DRIFT"]

DRIFT = 1e-6
"""[m, rad, m/s] Largest difference between the car's state and the kept fail-safe's state for
that step (pose and speed) with which the fail-safe is still executed."""


class Outcome(ValueEnum):
    """What the safety layer did in one step (see the module docstring)."""

    VERIFIED = "verified"
    FAILSAFE = "failsafe"
    UNVERIFIED = "unverified"
    OFF = "off"


@dataclass(frozen=True)
class Check:
    """The safety layer's record of one step: the ``outcome``; the fail-safe in force after it
    (``failsafe``: its manoeuvre, and for an executed one the step into it, e.g. ``brake 4 @3``);
    why the control the rules chose did not verify (``refuted``: the last fail-safe's
    refutation, empty when it verified); whether the plan's own first command (u*_0) verified
    (``plan_first``; None: not checked)."""

    outcome: Outcome
    failsafe: str = ""
    refuted: str = ""
    plan_first: bool | None = None


OFF = Check(Outcome.OFF)


class Guard:
    """The kept fail-safe of one run and the verification context ``ctx`` of its world (see the
    module docstring)."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        self.kept: FailSafe | None = None
        self.k = 0
        """The step into the kept fail-safe whose command runs when it is next executed."""

    def reset(self) -> None:
        """Forget the kept fail-safe."""
        self.kept, self.k = None, 0

    def start(self, x0: np.ndarray, traffic: TrafficState, t: float, s0: float | None = None) -> Verdict:
        """Check the initial state ``x0`` (12,) at ``t`` [s] (route position ``s0`` [m]) and keep its
        fail-safe (from ``x0`` itself: its first command runs now if the first control does not
        verify). A refuted verdict: the run starts unsafe."""
        v = verify_initial_state(self.ctx, x0, traffic, t, s0)
        self.kept, self.k = v.failsafe, 0
        return v

    def verify(self, x0: np.ndarray, control: np.ndarray, traffic: TrafficState, t: float,
               s0: float | None = None) -> Verdict:
        """Whether the command ``control`` [δ rad, γ] from ``x0`` keeps a fail-safe
        (:func:`~twolevel.safety.verify.verify_step`)."""
        return verify_step(self.ctx, x0, control, traffic, t, s0)

    def commit(self, v: Verdict) -> Check:
        """The verified control runs: keep its fail-safe (from the state after this step)."""
        assert v.verified and v.failsafe is not None
        self.kept, self.k = v.failsafe, 0
        return Check(Outcome.VERIFIED, v.failsafe.name)

    def on_track(self, x0: np.ndarray) -> bool:
        """Whether the kept fail-safe can run from ``x0`` now: there is one, and ``x0`` is its
        state for this step within :data:`DRIFT` (or it has ended: it holds the brake)."""
        fs = self.kept
        if fs is None:
            return False
        if self.k > fs.steps:
            return True
        return bool(np.all(np.abs(np.asarray(x0[:4], dtype=float) - fs.states[self.k, :4]) <= DRIFT))

    def fall_back(self, x0: np.ndarray, refuted: Verdict | None) -> tuple[np.ndarray | None, Check]:
        """The kept fail-safe's command for now (and the step moves on), or None when there is
        none for the state ``x0`` (:data:`DRIFT`); ``refuted``: the verdict that failed."""
        why = str(refuted.refuted_by) if refuted is not None and refuted.refuted_by is not None else ""
        if not self.on_track(x0):
            self.kept = None
        fs = self.kept
        if fs is None:
            return None, Check(Outcome.UNVERIFIED, "", why)
        u = fs.control_at(self.k)
        check = Check(Outcome.FAILSAFE, f"{fs.name} @{self.k}", why)
        self.k += 1
        return u, check
