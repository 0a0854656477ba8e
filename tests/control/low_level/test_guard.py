"""The low level with its safety layer on (the default): what it applies when the plan verifies,
when it does not (the kept fail-safe, one step further each step, no sampling), without a
kept fail-safe, and how much it samples when the rules fail but the plan is safe."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.control.low_level.controller import LowLevelController
from twolevel.control.low_level.decision import Action
from twolevel.control.low_level.guard import DRIFT, Outcome
from twolevel.control.low_level.settings import LowLevelSettings
from twolevel.models import fourwheel as fw
from twolevel.models.rollout import rollout
from twolevel.world.sensing import Memory

from helpers.mpc_worlds import highway_world

SPEED = "input float v\ninput float v_max\nspeed = always[0:1] (v <= v_max + 0.5);\n"
KEEP = np.tile([0.0, 0.0], (10, 1))  # [δ, a]: hold the speed


def low(w, rs, **kw) -> LowLevelController:  # noqa: ANN001
    return LowLevelController.from_rulesets(w, [rs], settings=LowLevelSettings(seed=7, **kw))


def decide(ll: LowLevelController, w, x: np.ndarray, u: np.ndarray, k: int = 0, traffic=None):  # noqa: ANN001
    return ll.decide(x, u, k * w.settings.dt, traffic if traffic is not None else w.traffic0, Memory.fresh(w),
                     float(x[0]), None, step=k)


def stalled_ahead(tmp_path: Path, s: float, rules: str = SPEED):  # noqa: ANN201
    return highway_world(tmp_path, rules, f"{{id: stalled, behaviour: stationary, start: {{lane: middle, s: {s}}}}}")


def test_a_plan_that_verifies_runs_and_its_failsafe_is_kept(tmp_path: Path) -> None:
    w, rs = stalled_ahead(tmp_path, 200.0)
    ll = low(w, rs)
    x = fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, 15.0)
    d = decide(ll, w, x, KEEP)
    assert d.decision == Action.MPC and d.safety.outcome is Outcome.VERIFIED and d.safety.plan_first
    assert d.safety.failsafe == "brake 4" and d.candidates == 0 and "verify" in d.timings_ms
    kept = ll.guard.kept
    assert kept is not None and ll.guard.k == 0
    x1 = rollout(x, d.control[None, None, :], w.settings.dt, ll.params).states[0, 1]
    assert np.array_equal(x1, kept.states[0])  # it starts where the verified step ends


def test_a_plan_that_does_not_verify_runs_the_kept_failsafe_one_step_further_each_step(tmp_path: Path) -> None:
    """15 m/s towards a stalled car: the first plan verifies (the car is far enough); holding the
    speed stops verifying once full braking would no longer stop in time, and from then on the
    kept fail-safe's commands run in order, with nothing sampled (the plan satisfies the rules:
    only safety refutes it)."""
    w, rs = stalled_ahead(tmp_path, 20.0 + 4.22 + 1.0 + 15.0**2 / 8.0 + 3.0)  # brake 4 just fits
    ll = low(w, rs)
    x = fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, 15.0)
    first = decide(ll, w, x, KEEP)
    assert first.safety.outcome is Outcome.VERIFIED
    kept = ll.guard.kept
    x = rollout(x, first.control[None, None, :], w.settings.dt, ll.params).states[0, 1]
    ran: list[np.ndarray] = []
    for k in range(1, 40):
        if len(ran) == 4:
            break
        d = decide(ll, w, x, KEEP, k)
        if d.safety.outcome is Outcome.VERIFIED:
            kept = ll.guard.kept
            ran = []
        else:
            assert d.decision == Action.FAILSAFE and d.safety.outcome is Outcome.FAILSAFE
            assert d.candidates == 0 and d.safety.plan_first is False
            assert "stalled" in d.safety.refuted and d.safety.failsafe == f"{kept.name} @{len(ran)}"
            np.testing.assert_array_equal(d.control, kept.control_at(len(ran)))
            ran.append(d.control)
        x = rollout(x, d.control[None, None, :], w.settings.dt, ll.params).states[0, 1]
    assert ran, "holding 15 m/s this close must stop verifying"


def test_without_a_kept_failsafe_it_brakes_unverified(tmp_path: Path) -> None:
    """Too close to stop (no fail-safe at all) and nothing kept: full braking, recorded as
    unverified; :meth:`LowLevelController.start` reports the start as unsafe."""
    w, rs = stalled_ahead(tmp_path, 32.0)
    ll = low(w, rs)
    x = fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, 15.0)
    assert not ll.start(x, w.traffic0, 0.0, float(x[0])).verified
    d = decide(ll, w, x, KEEP)
    assert d.decision == Action.BRAKE and d.safety.outcome is Outcome.UNVERIFIED
    assert d.control[1] == -1.0 and d.candidates == 0


def test_a_state_off_the_kept_failsafe_drops_it(tmp_path: Path) -> None:
    w, rs = stalled_ahead(tmp_path, 60.0)
    ll = low(w, rs)
    x = fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, 15.0)
    decide(ll, w, x, KEEP)
    moved = rollout(x, np.array([[[0.0, 0.0]]]), w.settings.dt, ll.params).states[0, 1].copy()
    moved[0] += 10 * DRIFT  # not where the fail-safe was verified from
    u, check = ll.guard.fall_back(moved, None)
    assert u is None and check.outcome is Outcome.UNVERIFIED and ll.guard.kept is None


@pytest.mark.parametrize("safety, most", [(True, 32), (False, 200)])
def test_sampling_is_one_round_with_the_safety_layer(tmp_path: Path, safety: bool, most: int) -> None:
    """A plan that breaks the speed limit whatever the ball holds (u* accelerates hard above the
    limit) but is safe: with the safety layer one round is sampled before braking, the paper's
    whole budget without it."""
    w, rs = highway_world(tmp_path, SPEED)
    ll = low(w, rs, safety=safety)
    x = fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, 31.0)
    d = decide(ll, w, x, np.tile([0.0, 3.0], (10, 1)))
    assert d.violated == ("speed",) and d.decision == Action.BRAKE
    assert d.candidates == most
    assert d.safety.outcome is (Outcome.VERIFIED if safety else Outcome.OFF)


def test_the_paper_low_level_has_no_safety_layer(tmp_path: Path) -> None:
    w, rs = stalled_ahead(tmp_path, 32.0)
    ll = low(w, rs, safety=False)
    assert ll.guard is None and ll.start(np.zeros(12), w.traffic0, 0.0, 0.0) is None
    d = decide(ll, w, fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, 15.0), KEEP)
    assert d.decision == Action.MPC and d.safety.outcome is Outcome.OFF  # the rules hold: it drives on
