"""The look-ahead beyond the paper's 1 s: non-uniform steps, RSS's distance to the vehicle ahead at
its end, and the speed bound from the sensing range — in closed loop on the kinematic bicycle
(the MPC's own model) and checked on the plans with the offline monitor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers.mpc_worlds import advance, closed_loop, controller, make_world, rules
from twolevel.control.high_level.linearisation import shifted
from twolevel.control.planner import PreviousPlan
from twolevel.models import bicycle
from twolevel.models.params import BicycleParams
from twolevel.monitor.robustness import robustness
from twolevel.world.assumptions import safe_distance, stopping_speed
from twolevel.world.signals import TrafficLog, signals_along

ONE_LANE = """kind: map
name: one_lane
default_speed_limit: 20.0
roads:
  - id: road
    start: {x: 0, y: 0, heading: 0}
    segments:
      - line: 600
    lanes:
      - {id: lane, offset: 0.0, width: 3.5}
"""
EGO = "{start: {lane: lane, s: 20}, speed: 15.0, desired_speed: 15.0}"
ROUTE = "{start: {lane: lane, s: 20}, goal: {lane: lane, s: 590}, stop_at_goal: false}"
STALLED_AT = 150.0
STALLED = "[{id: stalled, behaviour: stationary, start: {lane: lane, s: %g}}]" % STALLED_AT
COLLISION = "no_collision = always[0:1] collision_free(1.0);\n"
RSS_RULE = "input float rss_gap\nrss = (rss_gap >= 1.0);\n"


def _stalled_world(tmp_path: Path, extra: str = ""):
    (tmp_path / "lane.yaml").write_text(ONE_LANE)
    return make_world(tmp_path, str(tmp_path / "lane.yaml"), EGO, ROUTE, STALLED, extra=extra)


def _approach(tmp_path: Path, **settings):
    """15 m/s towards a stalled car 126 m ahead on a one-lane road, with the paper's collision
    rule alone: (states, results, gap to the stalled car's bumper [m] per step)."""
    w = _stalled_world(tmp_path)
    ctrl = controller(w, [rules(tmp_path, COLLISION)], time_limit=0.1, **settings)
    xs, res, _ = closed_loop(ctrl, w, 150)
    gap = STALLED_AT - xs[:, 0] - w.ego.length
    return w, xs, res, gap


def test_the_look_ahead_slows_down_early_for_a_stalled_car_and_stops_behind_it(tmp_path) -> None:
    w, xs, res, gap = _approach(tmp_path)
    a = np.diff(xs[:, 3]) / w.settings.dt
    slowing = np.flatnonzero(a < -0.5)
    assert all(r.ok for r in res)
    assert slowing.size and gap[slowing[0]] > 40.0   # slows 3 s (45 m) out, not at the last moment
    assert -a.min() <= 4.5                             # RSS's comfortable braking, not the tyres' 9 m/s²
    assert xs[-1, 3] < 0.05 and 0.5 <= gap.min()       # stands behind it, D_safe and a little away
    # never closer than RSS's distance (the world's rss_gap ≥ 0): the plans end it and D_safe
    # behind the car, in between they may brake harder than RSS's 4 m/s² and use the margin
    ego = {"x": xs[:, 0], "y": xs[:, 1], "psi": xs[:, 2], "v": xs[:, 3]}
    sig = signals_along(w, _log(w, len(xs)), ego)
    assert np.isfinite(sig["rss_gap"]).any() and np.all(sig["rss_gap"] >= 0.0)
    assert sig["rss_gap"][-1] >= w.settings.D_safe - 0.01  # and stands with the margin
    # the paper's horizon (1 s, no terminal distance) does none of this: it drives into the car
    # (the 1-norm diamond of the high level is no obstacle to a car at 15 m/s)
    _, xs_old, _, gap_old = _approach(tmp_path, horizon_s=1.0, rss=False)
    assert gap_old.min() < 0.0 and not np.any(np.diff(xs_old[:, 3]) / w.settings.dt < -0.5)


def _log(w, T: int) -> TrafficLog:
    """The (stationary) traffic of a world over T samples."""
    tr = w.traffic0
    rep = lambda a: np.repeat(a[None], T, axis=0)  # noqa: E731
    return TrafficLog(rep(tr.x), rep(tr.y), rep(tr.psi), rep(tr.v), rep(tr.active), w.parts.length, w.parts.width)


def test_the_terminal_rss_distance_holds_on_every_plan_by_the_monitor(tmp_path) -> None:
    w, xs, res, gap = _approach(tmp_path)
    rule = rules(tmp_path, RSS_RULE, name="rss").formula("rss")
    w_params = BicycleParams()
    sensed = np.hypot(STALLED_AT - xs[:-1, 0], xs[:-1, 1]) <= w.settings.sensor_range
    for r, seen in zip(res, sensed):
        la = r.look_ahead
        assert la is not None and np.allclose(np.diff(la.times), [0.1] * 10 + [0.5] * 8)
        # the planned trajectory: the plan's controls on the bicycle (exactly; the plan's own
        # states are its linearised model's), at its sample times; the stalled car where it stands
        T = len(la.times)
        xs_plan = bicycle.rollout(la.states[0], la.controls, la.dt * la.periods, w_params)
        plan = {"x": xs_plan[:, 0], "y": xs_plan[:, 1], "psi": xs_plan[:, 2], "v": xs_plan[:, 3]}
        sig = signals_along(w, _log(w, T), plan)
        rho = robustness(rule, sig, 0.1)  # no temporal operator: the sample times do not matter
        if seen:  # RSS's distance plus D_safe at the plan's end (the chords lie above RSS's distance;
            # up to the solver's tolerance)
            assert rho[-1] >= -1e-4, (r.message, sig["rss_gap"][-1])
        else:  # the car beyond the sensing range is unknown to the plan, which keeps going
            assert la.states[-1, 3] == pytest.approx(15.0, abs=0.1)
    assert sensed.sum() > 100 and not sensed.all()


def test_the_rss_rule_is_encoded_conservatively_on_the_fine_part(tmp_path) -> None:
    # rules/rss_distance.stl at the high level: its rss_gap is the chord of RSS's distance over
    # the speeds each step can reach, above the distance itself; the world's rss_gap on the plan
    # is never below what the model required
    w = _stalled_world(tmp_path)
    rss = rules(tmp_path, "input float rss_gap\nrss_distance = always[0:1] (rss_gap >= 1.0);\n", name="rd")
    ctrl = controller(w, [rules(tmp_path, COLLISION), rss], time_limit=0.1)
    formula = rss.formula("rss_distance")
    xs, res, _ = closed_loop(ctrl, w, 90)
    encoded = 0
    for x, r in zip(xs, res):
        assert r.ok and r.rule_robustness["rss_distance"] >= -1e-6
        if not np.isfinite(r.rule_robustness["rss_distance"]):
            assert np.hypot(STALLED_AT - x[0], x[1]) > w.settings.sensor_range  # not sensed when planned
            continue
        plan = {"x": r.states[:, 0], "y": r.states[:, 1], "psi": r.states[:, 2], "v": r.states[:, 3]}
        true = robustness(formula, signals_along(w, _log(w, len(r.states)), plan), 0.1)[0]
        assert true >= r.rule_robustness["rss_distance"] - 1e-6
        encoded += 1
    assert encoded > 50


def test_rss_is_kept_behind_a_moving_vehicle_and_beside_counts_only_where_the_lane_is_free(tmp_path) -> None:
    # a slower car 30 m ahead in the middle lane and the left lane busy beside the ego: the plan
    # ends RSS's distance behind it or in the free right lane, never in the busy left one
    parts = ("[{id: slow, behaviour: constant_velocity, start: {lane: middle, s: 50}, speed: 8.0},"
             " {id: l1, behaviour: constant_velocity, start: {lane: left, s: 20}, speed: 12.0},"
             " {id: l2, behaviour: constant_velocity, start: {lane: left, s: 45}, speed: 12.0}]")
    w = make_world(tmp_path, "highway.yaml", "{start: {lane: middle, s: 20}, speed: 12.0, desired_speed: 14.0}",
                   "{start: {lane: middle, s: 20}, goal: {lane: middle, s: 900}, stop_at_goal: false}", parts,
                   extra="controller: {r_near: 40}")
    ctrl = controller(w, [rules(tmp_path, "input float e\non_road = always[0:1] ((e <= 4.5) and (e >= -4.5));\n")])
    step, past, P = ctrl.prepare(np.array([w.ego.x, w.ego.y, w.ego.psi, w.ego.v]), 0.0, w.traffic0, None)
    assert step.rss is not None and step.rss.active and step.rss.sides == (False, True)
    res = ctrl.solve(np.array([w.ego.x, w.ego.y, w.ego.psi, w.ego.v]), 0.0, w.traffic0)
    la = res.look_ahead
    s_N, e_N = w.route.local_coordinates(la.states[-1:, :2])
    T = la.times[-1]
    gap = 50.0 + 8.0 * T - s_N[0] - w.ego.length
    behind = gap >= float(safe_distance(la.states[-1, 3], 8.0, w.settings.response)) + w.settings.D_safe - 0.05
    assert res.ok and (behind or e_N[0] <= -2.0)
    assert e_N[0] < 1.0  # not beside it on the left, where l1 and l2 drive


def test_never_faster_than_it_can_stop_within_its_sensing_range(tmp_path) -> None:
    w = make_world(tmp_path, "highway.yaml", "{start: {lane: middle, s: 20}, speed: 10.0, desired_speed: 25.0}",
                   "{start: {lane: middle, s: 20}, goal: {lane: middle, s: 1400}, stop_at_goal: false}",
                   extra="controller: {sensor_range: 40}")
    v_sense = stopping_speed(40.0 - w.ego.length - w.settings.D_safe, w.settings.response)
    assert w.settings.v_sense == pytest.approx(v_sense) and 15.0 < v_sense < 17.0
    xs, res, _ = closed_loop(controller(w, []), w, 80)
    assert all(r.ok for r in res)
    assert xs[:, 3].max() <= v_sense + 1e-3 and xs[-1, 3] > v_sense - 0.5  # up to it, never above
    # a car already faster slows down to it about as hard as RSS's braking (which the bound
    # allows for), not at once
    xs2, res2, _ = closed_loop(controller(w, []), w, 30, x0=[w.ego.x, w.ego.y, w.ego.psi, 20.0])
    a = np.diff(xs2[:, 3]) / w.settings.dt
    assert all(r.ok for r in res2) and xs2[-1, 3] <= v_sense + 0.05 and a.min() >= -5.0


def test_the_previous_plan_shifted_onto_a_coarse_grid_is_the_bicycle_under_its_controls() -> None:
    # shifting by one period lands on the previous plan's own samples over the fine part and,
    # between coarse samples, on the state its held control leads to (exactly)
    p = BicycleParams()
    periods = np.array([1] * 10 + [5] * 8)
    rng = np.random.default_rng(3)
    u = np.column_stack([rng.uniform(-0.05, 0.05, 18), rng.uniform(-2, 2, 18)])
    x0 = np.array([0.0, 0.0, 0.1, 12.0])
    states = bicycle.rollout(x0, u, 0.1 * periods, p)
    prev = PreviousPlan(0.0, states, u, np.zeros(0, np.int64), periods)
    x1 = states[1]
    xs, us = shifted(prev, x1, periods, 0.1, p)
    fine = np.repeat(u, periods, axis=0)  # the previous controls on the period grid
    dense = bicycle.rollout(x0, np.vstack([fine, fine[-1:]]), 0.1, p)  # ... and one period past its end
    ticks = np.concatenate([[0], np.cumsum(periods)])
    np.testing.assert_allclose(xs[1:], dense[ticks[1:] + 1], atol=1e-9)
    np.testing.assert_array_equal(us, fine[np.minimum(ticks[:-1] + 1, len(fine) - 1)])
    assert prev.spans(periods) and not prev.spans(10) and prev.precedes(0.1, 0.1, periods)


def test_the_uniform_look_ahead_keeps_the_papers_plan_shape(tmp_path) -> None:
    w = make_world(tmp_path, "highway.yaml", "{start: {lane: middle, s: 20}, speed: 10.0}",
                   "{start: {lane: middle, s: 20}, goal: {lane: middle, s: 900}, stop_at_goal: false}")
    res = controller(w, [], horizon_s=1.0).solve(np.array([w.ego.x, w.ego.y, w.ego.psi, w.ego.v]), 0.0, w.traffic0)
    assert res.ok and res.look_ahead is None and res.states.shape == (11, 4) and res.controls.shape == (10, 2)
    res5 = controller(w, []).solve(np.array([w.ego.x, w.ego.y, w.ego.psi, w.ego.v]), 0.0, advance(w.traffic0, 0.0))
    assert res5.controls.shape == (10, 2) and res5.look_ahead is not None and res5.look_ahead.controls.shape == (18, 2)
