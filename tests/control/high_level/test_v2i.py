"""What the planner knows of a light: its state now (default) or, with ``v2i: true``, its
program. Without V2I a green light half a second before it turns yellow is green all over the
look-ahead, so the car does not brake before the yellow shows (it did: the planner read the
program)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers.mpc_worlds import controller, make_world
from twolevel.world.signals import horizon_constants
from twolevel.world.world import World, load_rulesets

REPO = Path(__file__).resolve().parents[3]
T_YELLOW = 7.0  # [s] signalised.yaml: light_east turns yellow at 7 s, red at 10 s (line at s = 92 m)


def _world(tmp: Path, v2i: bool) -> World:
    return make_world(tmp, "signalised.yaml", "{start: {lane: east, s: 72}, speed: 10.0}",
                      "{start: {lane: east, s: 72}, goal: {lane: east, s: 190}, stop_at_goal: false}",
                      extra=f"rules: [{REPO / 'rules' / 'red_light.stl'}]\ncontroller: {{r_near: 60, v2i: {str(v2i).lower()}}}",
                      name=f"v2i_{v2i}")


def _x0(w: World) -> np.ndarray:
    return np.array([w.ego.x, w.ego.y, w.ego.psi, w.ego.v])


@pytest.mark.parametrize("v2i", [False, True])
def test_the_light_over_the_look_ahead_is_its_state_now_unless_v2i(tmp_path: Path, v2i: bool) -> None:
    w = _world(tmp_path, v2i)
    assert w.settings.v2i is v2i
    ticks = np.arange(51)
    hc = horizon_constants(w, w.traffic0, T_YELLOW - 0.5, _x0(w), dt=0.1, ticks=ticks,
                           s_pred=10.0 * 0.1 * ticks)
    assert hc.s_light == pytest.approx(92.0 - 72.0)  # route positions start at the route's start
    if v2i:  # the program: yellow (the ego can stop) from 7 s on
        np.testing.assert_array_equal(hc.light_red, (hc.t >= T_YELLOW - 1e-9).astype(float))
    else:  # green now, so green all along
        assert not hc.light_red.any()
    # once it shows yellow, both know
    hc = horizon_constants(w, w.traffic0, T_YELLOW + 0.1, _x0(w), dt=0.1, ticks=ticks, s_pred=1.0 * ticks)
    assert hc.light_red.all()


def test_without_v2i_the_plan_does_not_brake_before_the_yellow_shows(tmp_path: Path) -> None:
    plans = {}
    for v2i in (False, True):
        w = _world(tmp_path, v2i)
        sets, diags = load_rulesets(w)
        assert not [d for d in diags if d.is_error]
        plans[v2i] = controller(w, sets).solve(_x0(w), T_YELLOW - 0.5, w.traffic0)
        assert plans[v2i].ok
    now, known = plans[False], plans[True]
    # only now: no braking for a light that is green (the reference keeps its speed)
    assert now.controls[0, 1] > -0.3 and now.states[-1, 3] > 9.0
    # V2I: the plan slows for the yellow it knows is coming, 20 m ahead
    assert known.controls[0, 1] < -0.5 and known.states[-1, 3] < now.states[-1, 3] - 1.0
