"""The low level's decision logic on real worlds, rules, rollouts and monitors (the paper's low level:
the safety layer off; tests/control/low_level/test_guard.py has it on)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from twolevel.control.low_level.controller import LowLevelController
from twolevel.control.low_level.settings import LowLevelSettings
from twolevel.models import fourwheel as fw
from twolevel.world.sensing import Memory

from helpers.mpc_worlds import highway_world


def _decide(w, rs, v: float, u: np.ndarray, *, samples: int = 200, step: int = 0, least: bool = True):
    ll = LowLevelController.from_rulesets(w, [rs], settings=LowLevelSettings(samples=samples, seed=7, safety=False,
                                                                             least_violation=least))
    x0 = fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, v)
    return ll.decide(x0, u, 0.0, w.traffic0, Memory.fresh(w), 20.0, None, step=step)


SPEED = "input float v\ninput float v_max\nspeed = always[0:1] (v <= v_max + 0.5);\n"


def test_holding_plan_is_applied(tmp_path: Path) -> None:
    w, rs = highway_world(tmp_path, SPEED)
    d = _decide(w, rs, 29.0, np.tile([0.0, 0.0], (10, 1)))
    assert d.decision == "mpc" and d.candidates == 0
    assert d.robustness["speed"] > 0 and d.control[0] == 0.0
    assert d.states.shape == (11, fw.NX)


def test_violating_plan_is_replaced_by_a_sampled_control_that_satisfies(tmp_path: Path) -> None:
    # at 30.3 m/s (limit 30 + 0.5) accelerating at 1 m/s² breaks the limit within the second;
    # candidates with γ up to 0.3 lower brake a little and keep it
    w, rs = highway_world(tmp_path, SPEED)
    u = np.tile([0.0, 1.0], (10, 1))
    d = _decide(w, rs, 30.3, u)
    assert d.mpc_robustness["speed"] < 0 and d.violated == ("speed",)
    assert d.decision == "sampled" and 0 < d.candidates <= 200
    assert d.robustness["speed"] >= 0
    v = np.hypot(d.states[1:, 3], d.states[1:, 4])
    assert v.max() <= 30.5 + 1e-9  # the applied choice's own prediction satisfies the rule
    assert abs(d.control[0]) <= 0.3 * 0.5 + 1e-12  # within the ball (δ_max = 0.5 rad)
    # deterministic for (seed, step)
    again = _decide(w, rs, 30.3, u)
    np.testing.assert_array_equal(again.control, d.control)


def test_impossible_situation_brakes(tmp_path: Path) -> None:
    # a stopped car 8 m ahead (centres) at 15 m/s: no control can keep the boxes 1 m apart
    rules = "input float min_gap\nsafe = always[0:1] collision_free(1.0);\n"
    w, rs = highway_world(tmp_path, rules, "{id: stalled, behaviour: stationary, start: {lane: middle, s: 28}}")
    d = _decide(w, rs, 15.0, np.tile([0.0, -2.0], (10, 1)), samples=40, least=False)
    assert d.decision == "brake" and d.candidates == 40
    assert d.control[1] == -1.0 and d.accel < -8.0
    assert d.robustness["safe"] < 0  # recorded honestly: braking does not save it either


def test_a_standing_car_that_braking_cannot_help_takes_the_least_violating_choice(tmp_path: Path) -> None:
    # stopped half across the lane marking while the next lane's traffic closes in from behind:
    # braking keeps it there; moving back towards its lane violates less
    rules = "input float min_gap\nsafe = always[0:1] collision_free(1.0);\n"
    w, rs = highway_world(tmp_path, rules, "{id: passing, behaviour: constant_velocity, start: {lane: left, s: 14}, speed: 14}")
    ll = LowLevelController.from_rulesets(w, [rs], settings=LowLevelSettings(samples=40, seed=7, safety=False))
    x0 = fw.initial_state(w.ego.x, w.ego.y + 1.5, 0.15, 0.0)
    u = np.tile([-0.4, 2.0], (10, 1))
    d = ll.decide(x0, u, 0.0, w.traffic0, Memory.fresh(w), 20.0, None)
    plain = LowLevelController.from_rulesets(w, [rs], settings=LowLevelSettings(samples=40, seed=7, least_violation=False,
                                                                                safety=False))
    b = plain.decide(x0, u, 0.0, w.traffic0, Memory.fresh(w), 20.0, None)
    assert b.decision == "brake" and b.robustness["safe"] < 0
    assert d.decision == "least_violation" and d.robustness["safe"] > b.robustness["safe"]
    # at speed the paper's full brake stands even with least_violation on
    w2, rs2 = highway_world(tmp_path, rules, "{id: stalled, behaviour: stationary, start: {lane: middle, s: 28}}")
    assert _decide(w2, rs2, 15.0, np.tile([0.0, -2.0], (10, 1)), samples=40).decision == "brake"


def test_current_sample_is_not_judged(tmp_path: Path) -> None:
    # now v = 30.3 breaks 'v <= 30.2', but under braking every controlled sample keeps it
    w, rs = highway_world(tmp_path, "input float v\nnow_or_later = v <= 30.2;\n")
    d = _decide(w, rs, 30.3, np.tile([0.0, -3.0], (10, 1)))
    assert d.decision == "mpc" and d.robustness["now_or_later"] >= 0


def test_round_sizes_spend_the_budget() -> None:
    assert LowLevelSettings(samples=200).round_sizes() == [32, 64, 104]
    assert LowLevelSettings(samples=10).round_sizes() == [10]
    assert LowLevelSettings(samples=0).round_sizes() == []
    assert sum(LowLevelSettings(samples=50).round_sizes()) == 50
