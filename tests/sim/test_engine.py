"""Closed-loop runs on short scenarios: stop behaviours, safety with/without the monitor,
determinism, interruption, and the trace as `twolevel monitor` reads it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from helpers.world_files import load_world
from twolevel.monitor.tracefile import monitor_trace, read_trace
from twolevel.sim.engine import TIMING_COLUMNS, simulate_scenario
from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.low_level.decision import Action
from twolevel.control.nmpc.controller import NmpcController
from twolevel.sim.summary import LEVEL, LEVELS, StepDecision, StepInfo
from twolevel.sim.trace import read_run
from twolevel.stl.parser import parse

ROOT = Path(__file__).resolve().parents[2]
RULES = ROOT / "rules"

URBAN_MAP = """
kind: map
name: street
default_speed_limit: 10.0
roads:
  - id: street
    start: {x: 0, y: 0, heading: 0}
    segments: [{line: 200}]
    lanes:
      - {id: north, offset: -1.75, width: 3.5}
      - {id: south, offset: 1.75, width: 3.5, direction: backward}
stop_signs:
  - {id: stop_a, lane: north, s: 30, stop_time: 1.0}
traffic_lights:
  - id: light_a
    lane: north
    s: 70
    script: [{t: 0, state: red}, {t: 20, state: green}]
"""


def _urban(tmp_path: Path, duration: float = 25.0) -> Path:
    (tmp_path / "street.yaml").write_text(URBAN_MAP)
    path = tmp_path / "stops.yaml"
    path.write_text(f"""
kind: scenario
name: stops
map: street.yaml
ego: {{start: {{lane: north, s: 12}}, speed: 6.0}}
route: {{start: {{lane: north, s: 12}}, goal: {{lane: north, s: 190}}}}
participants:
  - {{id: oncoming, behaviour: idm, start: {{lane: south, s: 40}}, speed: 6.0}}
rules:
  - {RULES / 'speed_limit.stl'}
  - {RULES / 'stop_sign.stl'}
  - {RULES / 'red_light.stl'}
  - {RULES / 'safe_distance.stl'}
controller: {{time_limit: 30}}  # no wall-clock cut-off in the MPC: the same plan on any machine load
run: {{duration: {duration}, seed: 4}}
""")
    return path


def _stalled(tmp_path: Path) -> Path:
    path = tmp_path / "stalled.yaml"
    path.write_text(f"""
kind: scenario
name: stalled
map: {ROOT / 'maps' / 'highway.yaml'}
ego: {{start: {{lane: middle, s: 20}}, speed: 8.0, desired_speed: 8.0}}
route: {{start: {{lane: middle, s: 20}}, goal: {{lane: middle, s: 400}}, stop_at_goal: false}}
participants:
  - {{id: stalled, behaviour: stationary, start: {{lane: middle, s: 50}}}}
  - {{id: beside, behaviour: idm, start: {{lane: left, s: 10}}, speed: 9.0}}
rules: ["{RULES / 'collision.stl'}"]
controller: {{horizon_s: 1.0, rss: false}}  # the paper's MPC, which drives at the stalled car
run: {{duration: 6, seed: 1}}
""")
    return path


@pytest.fixture(scope="module")
def urban_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    tmp = tmp_path_factory.mktemp("urban")
    summary, diags = simulate_scenario(str(_urban(tmp)), str(tmp / "run"))
    assert summary is not None, [d.message for d in diags]
    return tmp, summary


@pytest.mark.slow
def test_stops_at_the_stop_sign_then_at_the_red_light_then_goes(urban_run) -> None:
    tmp, summary = urban_run
    assert summary.status == "complete" and summary.steps == 250
    assert summary.collisions == ()
    c = read_run(tmp / "run").columns
    t, v, s = c["t"], c["v"], c["s"]
    # stop sign at route s = 18: a standstill close before the line, never past it while moving
    at_sign = (v <= 0.1) & (c["d_stop"] >= 0) & (c["d_stop"] <= 3.0)
    assert at_sign.any()
    first_stop = t[np.argmax(at_sign)]
    assert np.all(s[t < first_stop] <= 18.0 + 1e-6)
    assert s.max() > 18.0 + 5.0  # and then drove on
    # red light at route s = 58 until 20 s: stands before the line while red, moves on at green
    red = t < 20.0
    assert np.all(s[red] <= 58.0 + 1e-6)
    assert np.any((v <= 0.1) & red & (s > 50.0))
    assert s[-1] > 58.0
    # no rule violated on the executed trace
    assert all(vi.steps == 0 for vi in summary.violations), summary.violations


@pytest.mark.slow
def test_trace_is_what_twolevel_monitor_reads(urban_run) -> None:
    tmp, _ = urban_run
    run = read_run(tmp / "run")
    trace, diags = read_trace(tmp / "run" / "trace.csv")
    assert trace is not None, [d.message for d in diags]
    for name in ("speed_limit", "stop_sign", "red_light", "safe_distance"):
        rf, _ = parse((RULES / f"{name}.stl").read_text(), name)
        report, d = monitor_trace(rf, {}, trace, series=True)
        assert not [x for x in d if x.is_error], [x.message for x in d]
        for verdict in report.rules:
            np.testing.assert_allclose(np.asarray(verdict.series, dtype=float), run.columns[f"rob_{verdict.name}"],
                                       rtol=0, atol=1e-9)
    meta = json.loads((tmp / "run" / "run.json").read_text())
    assert meta["status"] == "complete" and meta["rows"] == 250
    assert len(meta["rules"]) == 4 and all(len(r["sha256"]) == 64 for r in meta["rules"])
    assert {"numpy", "casadi", "highspy", "clarabel", "twolevel"} <= set(meta["versions"])
    assert meta["map_lines"] and meta["summary"]["steps"] == 250
    frames = (tmp / "run" / "frames.jsonl").read_text().splitlines()
    assert len(frames) == 250 and set(json.loads(frames[0])) == {"t", "ego", "plan", "others", "lights"}


@pytest.mark.slow
def test_same_seed_same_trace(urban_run, tmp_path: Path) -> None:
    tmp, _ = urban_run
    again, _ = simulate_scenario(str(_urban(tmp)), str(tmp_path / "again"))
    assert again is not None
    a, b = read_run(tmp / "run").columns, read_run(tmp_path / "again").columns
    assert list(a) == list(b)
    for name in a:
        if name in TIMING_COLUMNS:
            continue
        if isinstance(a[name], list):
            assert a[name] == b[name], name
        else:
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_interrupted_run_keeps_every_completed_row(tmp_path: Path) -> None:
    seen: list[StepInfo] = []

    def progress(info: StepInfo) -> None:
        seen.append(info)
        if info.step == 25:
            raise KeyboardInterrupt

    summary, diags = simulate_scenario(str(_urban(tmp_path)), str(tmp_path / "run"), progress=progress)
    assert summary is not None and summary.status == "interrupted" and summary.steps == 25
    assert any(d.code == "SIM612" for d in diags)
    run = read_run(tmp_path / "run")
    assert run.meta["status"] == "interrupted" and run.meta["rows"] == 25 and run.rows == 25
    assert np.all(np.isfinite(run.columns["rob_speed_limit"]))  # completed with truncated windows
    assert seen[-1].t == pytest.approx(2.5) and seen[-1].steps == 250 and seen[-1].rate_hz > 0


@pytest.mark.slow
def test_monitor_prevents_the_collision_the_mpc_alone_makes(tmp_path: Path) -> None:
    with_m, _ = simulate_scenario(str(_stalled(tmp_path)), str(tmp_path / "with"))
    without, diags = simulate_scenario(str(_stalled(tmp_path)), str(tmp_path / "without"), monitor=False)
    assert with_m is not None and without is not None
    to_stalled = {c.other: c.distance for c in with_m.closest}["stalled"]
    assert with_m.collisions == () and to_stalled > 4.22 and with_m.min_gap > 0
    assert with_m.decisions.get("brake", 0) + with_m.decisions.get("sampled", 0) > 0
    assert without.decisions == {"mpc": 60} or set(without.decisions) <= {"mpc", "fallback"}
    assert {c.other: c.distance for c in without.closest}["stalled"] < 4.22
    hit = without.collisions[0]
    assert hit.other == "stalled" and hit.gap < 0 and 20.0 < hit.x < 60.0
    assert any(d.code == "SIM614" for d in diags)
    run = read_run(tmp_path / "without")
    assert run.meta["summary"]["collisions"][0]["other"] == "stalled"
    assert np.nanmin(run.columns["min_gap"]) < 0


def test_bad_requests_are_diagnostics(tmp_path: Path) -> None:
    path = str(_stalled(tmp_path))
    assert simulate_scenario(path, str(tmp_path / "x"), controller="nope")[1][0].code == "SIM610"
    assert simulate_scenario(path, str(tmp_path / "x"), duration=-1.0)[1][0].code == "SIM611"
    s, d = simulate_scenario(str(tmp_path / "missing.yaml"), str(tmp_path / "x"))
    assert s is None and any(x.is_error for x in d)


@pytest.mark.slow
def test_trace_signals_equal_the_world_definitions(urban_run) -> None:
    """The engine's incremental sensing gives what world/signals.py's signals_along gives on
    the recorded trajectory (traffic replayed with the same ego boxes)."""
    from twolevel.world import traffic as tr
    from twolevel.world.signals import TrafficLog, signals_along

    tmp, _ = urban_run
    w = load_world(tmp / "stops.yaml")
    c = read_run(tmp / "run").columns
    states, state = [], w.traffic0
    for k in range(len(c["t"])):
        states.append(state)
        ego = tr.EgoBox(c["x"][k], c["y"][k], c["psi"][k], c["v"][k], w.ego.length)
        state = tr.step(state, w.settings.dt, lanes=w.lanes, parts=w.parts, limits=w.limits, lights=w.lights,
                        stops=w.stops, ego=ego, stop_speed=w.settings.stop_speed)
    ref = signals_along(w, TrafficLog.of(states, w.parts.length, w.parts.width),
                        {k: c[k] for k in ("x", "y", "psi", "v")})
    for name in ("s", "e", "v_max", "d_stop", "light_red", "d_light", "d_lead", "v_lead", "min_gap", "n_near"):
        np.testing.assert_allclose(c[name], ref[name], rtol=0, atol=1e-6, err_msg=name)


def test_run_ends_when_the_ego_has_stopped_at_the_goal(tmp_path: Path) -> None:
    # regression: the reference piled up at the route's end, the ego stopped metres past the goal
    # and the run idled to its full duration
    (tmp_path / "street.yaml").write_text(URBAN_MAP)
    path = tmp_path / "goal.yaml"
    path.write_text("""
kind: scenario
name: goal
map: street.yaml
ego: {start: {lane: north, s: 100}, speed: 6.0}
route: {start: {lane: north, s: 100}, goal: {lane: north, s: 130}}
rules: []
controller: {time_limit: 30}
run: {duration: 30, seed: 0}
""")
    summary, diags = simulate_scenario(str(path), str(tmp_path / "run"), monitor=False)
    assert summary is not None, [d.message for d in diags]
    assert summary.status == "complete"
    assert summary.goal_reached_t is not None and summary.goal_reached_t < 15.0
    assert summary.steps == round(summary.goal_reached_t / 0.1) + 1          # ended there
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    assert meta["summary"]["goal_reached_t"] == summary.goal_reached_t
    import csv

    with open(tmp_path / "run" / "trace.csv", newline="") as f:
        last = list(csv.DictReader(f))[-1]
    assert abs(float(last["s"]) - 30.0) <= 1.0 and float(last["v"]) <= 0.1   # at the goal, not past it


def test_a_full_disk_is_a_diagnostic_and_keeps_what_was_written(tmp_path, monkeypatch) -> None:
    """ENOSPC while writing used to end in 'internal error' and a stray temporary (review)."""
    import errno

    from twolevel.sim import trace as trace_mod
    from twolevel.sim.engine import simulate_scenario

    real_write = trace_mod.TraceWriter.write

    def write(self, row):  # noqa: ANN001
        if self.rows >= 5:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_write(self, row)

    monkeypatch.setattr(trace_mod.TraceWriter, "write", write)
    scenario = str(Path(__file__).resolve().parents[2] / "scenarios" / "traffic_rules.yaml")
    summary, diags = simulate_scenario(scenario, str(tmp_path / "run"), duration=2.0)
    assert summary is not None and summary.status == "crashed"
    assert any(d.code == "SIM615" and "No space left" in d.message for d in diags)
    assert (tmp_path / "run" / "trace.csv").read_text().count("\n") == 1 + 5
    assert not list((tmp_path / "run").glob(".*tmp"))


def test_nan_robustness_does_not_count_as_holding() -> None:
    import numpy as np

    from twolevel.sim.summary import summarise

    s = summarise(scenario="s", run_dir="d", status="complete", monitor=True, controller="twolevel", seed=0, dt=0.1,
                  wall_time_s=1.0, step_ms=[1, 1, 1], high_ms=[1, 1, 1], low_ms=[0, 0, 0], tracking=[0, 0, 0],
                  over_limit=[0, 0, 0], min_dist=[9, 9, 9], min_gap=[5, 5, 5], decisions=["mpc"] * 3, collisions=[],
                  robustness={"r": np.array([1.0, np.nan, 2.0])})
    [v] = s.violations
    assert v.steps == 1 and v.first_t == 0.1


def test_dense_traffic_needs_no_braking_from_the_monitor(tmp_path: Path) -> None:
    # regression: at 13 m/s the MPC's linearised model could steer at full lock (a lateral
    # acceleration of ~35 m/s², no tyre gives that), its plan swerved toward the next lane, the
    # low level braked with that steering and the car came to rest across the lane marking, with
    # traffic passing within D_safe (no_collision violated for ~10 s). The steering bound of the
    # lateral-acceleration limit keeps the plan one the detailed model follows.
    text = (ROOT / "scenarios" / "scalability.yaml").read_text()
    text = text.replace("../maps/", f"{ROOT / 'maps'}/").replace("../rules/", f"{ROOT / 'rules'}/")
    text = text.replace("controller: {r_near: 40}", "controller: {r_near: 40, time_limit: 30}")
    path = tmp_path / "dense.yaml"
    path.write_text(text)
    summary, diags = simulate_scenario(str(path), str(tmp_path / "run"), duration=4.0)
    assert summary is not None, [d.message for d in diags]
    assert summary.collisions == () and summary.min_gap > 0
    assert summary.decisions.get("brake", 0) == 0 and summary.decisions.get("least_violation", 0) == 0
    assert not any(v.rule == "no_collision" and v.steps for v in summary.violations)
    run = read_run(tmp_path / "run")
    assert np.all(run.columns["rob_no_collision"] >= 0)


def test_every_action_and_planner_label_is_a_trace_decision_with_a_level() -> None:
    """The trace's decisions are one vocabulary: the low level's actions, the planners' labels
    (unchecked steps without the monitor) and the fallback, each at one level of the report."""
    values = {d.value for d in StepDecision}
    assert {a.value for a in Action} <= values
    assert {HighLevelController.label, NmpcController.label} <= values
    assert set(LEVEL) == values and set(LEVEL.values()) == set(LEVELS)
    assert StepDecision(Action.BRAKE).level == "low" and StepDecision("fallback").level == "high"
