"""The NMPC baseline (casadi + IPOPT): closed loop on the kinematic model, the four-wheel variant,
warm start, determinism, failures. Worlds: the shipped ``comparison`` scenario and a small
straight street written to a temporary directory."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers.world_files import load_world
from twolevel.control.codes import MIL530
from twolevel.control.nmpc.controller import NmpcController, NmpcOptions
from twolevel.control.nmpc.nlp import bicycle_step_casadi
from twolevel.control.planner import Snapshot
from twolevel.models import bicycle
from twolevel.models import fourwheel as fw
from twolevel.models.obb import pose_separation
from twolevel.models.params import VehicleParams
from twolevel.models.rollout import rollout_accel
from twolevel.world.signals import StopMemory, update_stop_memory
from twolevel.world.world import World

REPO = Path(__file__).resolve().parents[3]
RULES = REPO / "rules"
DT = 0.1

STREET = """\
kind: map
name: street
default_speed_limit: 10
roads:
  - id: road
    start: {x: 0, y: 0, heading: 0}
    segments: [{line: 300}]
    lanes:
      - {id: a, offset: -1.75, width: 3.5}
      - {id: b, offset: 1.75, width: 3.5, direction: backward}
stop_signs:
  - {id: stop, lane: a, s: 40, stop_time: 1.0}
traffic_lights:
  - {id: tl, lane: a, s: 120, script: [{t: 0, state: red}, {t: 5, state: green}]}
"""


def street(tmp: Path, ego_s: float, speed: float, rules: list[str], participants: str = "[]") -> World:
    (tmp / "street.yaml").write_text(STREET)
    rl = ", ".join(str(RULES / r) for r in rules)
    (tmp / "scn.yaml").write_text(
        f"kind: scenario\nname: street\nmap: street.yaml\nego: {{start: {{lane: a, s: {ego_s}}}, speed: {speed}}}\n"
        f"route: {{start: {{lane: a, s: 0}}, goal: {{lane: a, s: 290}}}}\nparticipants: {participants}\n"
        f"rules: [{rl}]\nrun: {{duration: 30, seed: 0}}\n")
    return load_world(tmp / "scn.yaml")


@pytest.fixture(scope="module")
def comparison() -> World:
    return load_world(REPO / "scenarios" / "comparison.yaml")


def make(world: World, **kw) -> NmpcController:
    ctrl, diags = NmpcController.from_world(world, **kw)
    assert ctrl is not None, [d.message for d in diags]
    return ctrl


def closed_loop(ctrl: NmpcController, world: World, steps: int, x0: np.ndarray | None = None):
    """Kinematic plant, stationary/constant traffic as given, stop-sign memory kept; returns
    (states (steps+1, 4), results)."""
    e = world.ego
    x = np.array([e.x, e.y, e.psi, e.v]) if x0 is None else np.asarray(x0, float)
    mem = StopMemory.fresh(world)
    xs, res = [x], []
    for k in range(steps):
        r = ctrl.solve(x, k * DT, Snapshot(world.traffic0, mem), None)
        res.append(r)
        x = bicycle.step(x, r.controls[0], DT, ctrl.params)
        s = float(world.route.local_coordinates(x[None, :2])[0][0])
        mem = update_stop_memory(mem, world, s, float(x[3]), DT)
        xs.append(x)
    return np.array(xs), res


# ------------------------------------------------------------------ model and construction
@settings(max_examples=200, deadline=None)
@given(st.floats(-3.2, 3.2), st.floats(0.0, 30.0), st.floats(-0.5, 0.5), st.floats(-9.0, 3.0),
       st.sampled_from([0.0, 1e-7, -3e-5, 1e-3]))
def test_casadi_bicycle_is_the_numpy_step(psi: float, v: float, delta: float, a: float, tiny: float) -> None:
    import casadi as ca

    x = np.array([3.0, -2.0, psi, v])
    for d in (delta, tiny):  # tiny steering exercises the sinc series branch
        u = np.array([d, a])
        got = np.asarray(ca.evalf(bicycle_step_casadi(ca.DM(x), ca.DM(u), DT, 2.11))).ravel()
        np.testing.assert_allclose(got, bicycle.step(x, u, DT), rtol=1e-12, atol=1e-12)


def test_rules_become_constraints_and_the_rest_is_reported(comparison: World) -> None:
    ctrl, diags = NmpcController.from_world(comparison)
    assert ctrl is not None
    assert ctrl.speed and ctrl.d_collision == 1.0 and not ctrl.stop and not ctrl.light
    codes = [(d.code, d.message) for d in diags]
    assert any(c == MIL530.id and "keep_gap" in m for c, m in codes), codes
    with pytest.raises(ValueError, match="unknown NMPC model"):
        NmpcController(comparison, [], model="bogus")


# ------------------------------------------------------------------ closed loop, kinematic
def test_tracks_the_curved_road_within_the_limits(comparison: World) -> None:
    """Both bends of the comparison road (s = 0…~200 m): lateral error < 5 cm (measured 1.5 cm),
    v never above the limit in force, every step solved by IPOPT."""
    ctrl = make(comparison)
    xs, res = closed_loop(ctrl, comparison, 250)
    s, e = comparison.route.local_coordinates(xs[:, :2])
    assert s[-1] > 150.0  # through the left bend (60–139 m) into the right one
    assert np.max(np.abs(e)) < 0.05, np.max(np.abs(e))
    over = xs[:, 3] - comparison.route.limit_at(s)
    assert np.max(over) <= 1e-3, np.max(over)
    assert all(r.status == "optimal" for r in res)
    r = res[-1]
    assert r.controls.shape == (10, 2) and r.states.shape == (11, 4) and r.binaries == 0 and not r.certified
    assert r.solver == "nmpc-kinematic" and r.timings_ms["solve"] > 0 and r.timings_ms["total"] >= r.timings_ms["solve"]
    assert "Solve_Succeeded" in r.message


def test_stops_before_an_active_stop_line_then_goes_on(tmp_path: Path) -> None:
    w = street(tmp_path, 10.0, 8.0, ["speed_limit.stl", "stop_sign.stl"])
    ctrl = make(w)
    assert ctrl.stop
    xs, res = closed_loop(ctrl, w, 110)
    s, _ = w.route.local_coordinates(xs[:, :2])
    first_past = int(np.argmax(s > 40.0)) if (s > 40.0).any() else len(s)
    assert first_past < len(s), "never went on after the stop"
    before = slice(0, first_past)
    assert np.min(xs[before, 3][s[before] > 37.0]) <= 0.1  # stood still close to the line
    stopped = np.flatnonzero(xs[:, 3] <= 0.1)
    assert np.max(s[stopped]) <= 40.0 + 1e-6 and np.min(s[stopped]) >= 37.0
    assert len(stopped) * DT >= 1.0 - 1e-9  # the sign's stop_time
    assert all(r.ok for r in res)


def test_brakes_for_a_stop_line_seen_from_afar_at_the_stop_deceleration(tmp_path: Path) -> None:
    """A line the plan must stop at bounds its speeds (a profile braking at the settings'
    stop_decel), so the 1 s plan, whose cost weighs a² against little tracking error, no longer
    brakes only when the can-still-stop term at the line binds (5.9 m/s² from 10 m/s before)."""
    (tmp_path / "street.yaml").write_text(STREET.replace("default_speed_limit: 10", "default_speed_limit: 14"))
    rl = ", ".join(str(RULES / r) for r in ["speed_limit.stl", "stop_sign.stl"])
    (tmp_path / "scn.yaml").write_text(
        "kind: scenario\nname: street\nmap: street.yaml\nego: {start: {lane: a, s: 0}, speed: 10}\n"
        "route: {start: {lane: a, s: 0}, goal: {lane: a, s: 290}}\ncontroller: {r_near: 60}\n"
        f"rules: [{rl}]\nrun: {{duration: 30, seed: 0}}\n")
    w = load_world(tmp_path / "scn.yaml")
    ctrl = make(w)
    xs, res = closed_loop(ctrl, w, 80)
    s, e = w.route.local_coordinates(xs[:, :2])
    decel = -np.diff(xs[:, 3]) / DT
    assert np.max(decel) <= ctrl.settings.stop_decel + 0.25, np.max(decel)
    stopped = np.flatnonzero(xs[:, 3] <= 0.1)
    assert stopped.size and 37.0 <= np.min(s[stopped]) and np.max(s[stopped]) <= 40.0
    assert np.max(np.abs(e)) < 1e-3 and all(r.ok for r in res)


def test_waits_at_a_red_light_and_goes_on_green(tmp_path: Path) -> None:
    w = street(tmp_path, 100.0, 8.0, ["speed_limit.stl", "red_light.stl"])
    ctrl = make(w)
    assert ctrl.light
    xs, res = closed_loop(ctrl, w, 90)
    s, _ = w.route.local_coordinates(xs[:, :2])
    t = DT * np.arange(len(s))
    assert np.all(s[t < 5.0] <= 120.0 + 1e-6)  # red until 5 s
    assert s[-1] > 125.0  # then on
    assert all(r.ok for r in res)


def test_keeps_its_distance_to_a_stopped_vehicle(tmp_path: Path) -> None:
    w = street(tmp_path, 0.0, 8.0, ["speed_limit.stl", "safe_distance.stl"],
               "[{id: parked, behaviour: stationary, start: {lane: a, s: 45}}]")
    ctrl = make(w)
    xs, res = closed_loop(ctrl, w, 80)
    o = w.traffic0
    dx, dy = xs[:, 0] - o.x[0], xs[:, 1] - o.y[0]
    c, s_ = np.cos(o.psi[0]), np.sin(o.psi[0])
    A = 0.5 * (w.parts.length[0] + w.ego.length) + 1.0
    B = 0.5 * (w.parts.width[0] + w.ego.width) + 1.0
    measure = (((c * dx + s_ * dy) / A) ** 4 + ((-s_ * dx + c * dy) / B) ** 4) ** 0.25
    assert np.min(measure) >= 1.0 - 1e-5, np.min(measure)  # the smooth distance held at every step
    sep = pose_separation(xs[:, 0], xs[:, 1], xs[:, 2], w.ego.length, w.ego.width,
                          o.x[0], o.y[0], o.psi[0], w.parts.length[0], w.parts.width[0])
    assert np.min(sep) > 0.5  # no contact
    assert xs[-1, 3] < 0.5 or np.max(np.abs(dy)) > 2.0  # stopped behind it, or went around
    assert all(r.ok for r in res)


# ------------------------------------------------------------------ warm start, determinism, failures
def test_warm_start_reduces_iterations(comparison: World) -> None:
    its = {}
    for mode in (True, False):
        ctrl = make(comparison, options=NmpcOptions(warm_start=mode))
        _, res = closed_loop(ctrl, comparison, 60)
        its[mode] = [r.qps for r in res[1:]]
    assert np.mean(its[True]) < 0.75 * np.mean(its[False]), its  # measured: 4.4 vs 9.2 on average


def test_same_inputs_same_plan(comparison: World) -> None:
    a, b = make(comparison), make(comparison)
    xa, ra = closed_loop(a, comparison, 20)
    xb, rb = closed_loop(b, comparison, 20)
    np.testing.assert_array_equal(xa, xb)
    for p, q in zip(ra, rb):
        np.testing.assert_array_equal(p.controls, q.controls)
        np.testing.assert_array_equal(p.states, q.states)


def test_ipopt_failure_falls_back_to_the_shifted_plan(comparison: World) -> None:
    ctrl = make(comparison)
    x = np.array([comparison.ego.x, comparison.ego.y, comparison.ego.psi, comparison.ego.v])
    good = ctrl.solve(x, 0.0, comparison.traffic0)
    assert good.status == "optimal"
    x1 = bicycle.step(x, good.controls[0], DT)
    ctrl.problem._opts_base["ipopt.max_iter"] = 0  # IPOPT stops at once: Maximum_Iterations_Exceeded
    ctrl.problem.retry_max_iter = 0
    ctrl.problem._solvers.clear()
    bad = ctrl.solve(x1, DT, comparison.traffic0)
    assert bad.status == "fallback" and "Maximum_Iterations_Exceeded" in bad.message
    np.testing.assert_allclose(bad.controls[:-1], good.controls[1:])
    assert bad.diagnostics and bad.diagnostics[0].code == "MIL515"
    # a non-finite state is a numerical failure too: no exception, braking without a plan
    ctrl.reset()
    nan = ctrl.solve(np.array([np.nan, 0.0, 0.0, 5.0]), 0.0, comparison.traffic0)
    assert nan.status == "fallback" and np.all(nan.controls[:, 1] <= 0) and "non-finite" in nan.message


# ------------------------------------------------------------------ four-wheel model
def test_fourwheel_plan_is_feasible_on_one_step(comparison: World) -> None:
    """One step of the NMPC on the detailed model (≈ 2 s with the build): the plan solves,
    obeys the speed limit and agrees with the detailed model's own rollout of its controls."""
    ctrl = make(comparison, model="fourwheel")
    x0 = fw.initial_state(comparison.ego.x, comparison.ego.y, comparison.ego.psi, comparison.ego.v)
    r = ctrl.solve(x0, 0.0, comparison.traffic0)
    assert r.ok, r.message
    assert r.solver == "nmpc-fourwheel" and r.states.shape == (11, 4) and r.controls.shape == (10, 2)
    vp = ctrl.vehicle
    roll = rollout_accel(x0, r.controls[None], DT, vp, backend="casadi-vm").states[0]
    np.testing.assert_allclose(roll[:, :4], r.states, atol=1e-5)
    s = comparison.route.local_coordinates(r.states[:, :2])[0]
    assert np.all(r.states[:, 3] <= comparison.route.limit_at(s) + 1e-3)
    assert np.all(np.abs(r.controls[:, 0]) <= ctrl.params.delta_max + 1e-9)
    assert isinstance(vp, VehicleParams) and ctrl.problem.substeps == fw.substeps_per_step(DT, vp)


def test_options_are_frozen() -> None:
    o = NmpcOptions()
    with pytest.raises(Exception):
        o.max_iter = 3  # type: ignore[misc]
    assert replace(o, warm_start="primal").warm_start == "primal"


def test_plans_the_papers_horizon_within_the_sensing_speed_bound(tmp_path: Path) -> None:
    # the MPC's settings look 5 s ahead; the baseline keeps H = 10 steps of dt, and the speed from
    # which the ego stops within its sensing range (40 m here: ~16 m/s) bounds it as the MPC
    (tmp_path / "scn.yaml").write_text(
        f"kind: scenario\nname: sense\nmap: {REPO / 'maps' / 'highway.yaml'}\n"
        "ego: {start: {lane: middle, s: 20}, speed: 12.0, desired_speed: 25.0}\n"
        "route: {start: {lane: middle, s: 20}, goal: {lane: middle, s: 1400}, stop_at_goal: false}\n"
        f"rules: [{RULES / 'speed_limit.stl'}]\ncontroller: {{sensor_range: 40}}\nrun: {{duration: 10, seed: 0}}\n")
    w = load_world(tmp_path / "scn.yaml")
    ctrl = make(w)
    assert ctrl.settings.N == ctrl.settings.H == 10 and not ctrl.settings.rss
    xs, res = closed_loop(ctrl, w, 60)
    assert all(r.ok for r in res) and res[0].controls.shape == (10, 2) and res[0].look_ahead is None
    assert xs[:, 3].max() <= w.settings.v_sense + 1e-3 and xs[-1, 3] > w.settings.v_sense - 0.5
