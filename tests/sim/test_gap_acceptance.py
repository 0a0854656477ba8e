"""Gap acceptance at a junction in the closed loop: the ego, standing at its line, goes in a gap of
about 7–8 s before a car with priority coming at the speed limit, and lets a gap of 3 s go —
turning left across oncoming traffic on the priority road, and turning left out of a side road
at a yield sign and at a stop sign. The gap is the car's constant-velocity time to the ego's
conflict area when the run starts (the trace's ``t_reach``). The ego needs rules/right_of_way.stl's
gap at the car's speed and, at the car's worst under the declared assumptions, to be out of its way
before it could arrive (:mod:`twolevel.control.high_level.right_of_way`); the safety layer checks
the same (:mod:`twolevel.safety.verify`). Each run is judged against its ``expect:``: no
collision at fault, the rules held."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.monitor.tracefile import read_trace

from helpers.judged_runs import judged_run

ROOT = Path(__file__).resolve().parents[2]
LIMIT = 13.89  # [m/s] the map's limit; the car with priority drives at it
STOP_READY = 3.2  # [s] when the ego has served its stop sign (it creeps to the line, then stands 1 s)

MAP = """kind: map
name: long_tee
default_speed_limit: {limit}
roads:
  - id: west
    start: {{x: -200, y: 0, heading: 0}}
    segments: [{{line: 190}}]
    lanes: [{{id: west_in, offset: -1.75}}, {{id: west_out, offset: 1.75, direction: backward}}]
  - id: east
    start: {{x: 160, y: 0, heading: 180}}
    segments: [{{line: 150}}]
    lanes: [{{id: east_in, offset: -1.75}}, {{id: east_out, offset: 1.75, direction: backward}}]
  - id: south
    start: {{x: 0, y: -160, heading: 90}}
    segments: [{{line: 150}}]
    lanes: [{{id: south_in, offset: -1.75}}, {{id: south_out, offset: 1.75, direction: backward}}]
junctions:
  - id: tee
    arms:
      - {{road: west, end: end, priority: priority}}
      - {{road: east, end: end, priority: priority}}
      - {{road: south, end: end, priority: {side}}}
"""

SCENARIO = """kind: scenario
name: gap_{case}_{gap}
map: long_tee.yaml
ego:
  start: {{lane: {ego_lane}, s: {ego_s}}}
  speed: 0.0
route:
  start: {{lane: {ego_lane}, s: {ego_s}}}
  goal: {{lane: {goal_lane}, s: 40}}
participants:
  - {{id: car, behaviour: constant_velocity, start: {{lane: west_in, s: {car_s}}}, speed: {limit}}}
controller: {{r_near: 150}}
rules:
  - {rules}/speed_limit.stl
  - {{file: {rules}/right_of_way.stl, constants: {constants}}}{stop}
run: {{duration: 14, seed: 0}}
expect: {{goal: false, rules: [give_way, clear_junction{stop_rule}]}}
"""

# the ego's lane and where it stands on it (at its waiting place, a metre or so before the
# conflict area, at the stop sign 1.6 m before its line), the lane of its goal, the side road's
# sign, and where on west_in the car is when its time to the area is 0 (the recorded t_reach when
# the ego may go — at once, or at the stop sign once it has stood its second — is the gap named)
CASES = {
    "left_turn": ("east_in", 147.0, "south_out", "yield", 194.9),
    "yield": ("south_in", 147.4, "west_out", "yield", 188.6),
    "stop": ("south_in", 147.4, "west_out", "stop", 188.6),
}


def _run(tmp_path: Path, case: str, gap: float, constants: str = "{}") -> tuple[dict[str, np.ndarray], np.ndarray, int]:
    """The run's trace columns, times, and the sample from which the ego may go."""
    ego_lane, ego_s, goal_lane, side, at_area = CASES[case]
    (tmp_path / "long_tee.yaml").write_text(MAP.format(limit=LIMIT, side=side))
    car_s = at_area - (gap + (STOP_READY if side == "stop" else 0.0)) * LIMIT
    stop = side == "stop"
    path = tmp_path / f"{case}.yaml"
    path.write_text(SCENARIO.format(case=case, gap=int(gap), ego_lane=ego_lane, ego_s=ego_s, goal_lane=goal_lane, car_s=car_s,
                                    limit=LIMIT, rules=ROOT / "rules",
                                    stop=f"\n  - {ROOT / 'rules'}/stop_sign.stl" if stop else "",
                                    stop_rule=", stop_sign" if stop else "", constants=constants))
    trace, _ = read_trace(str(judged_run(path, tmp_path / "run") / "trace.csv"))
    assert trace is not None
    c = {k: np.asarray(v, float) for k, v in trace.columns.items()}
    t = np.asarray(trace.t, float)
    ready = int(np.flatnonzero(~np.isfinite(c["d_stop"]))[0]) if case == "stop" else 0  # its stop served
    return c, t, ready


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_a_gap_of_8_s_is_taken(tmp_path: Path, case: str) -> None:
    c, t, ready = _run(tmp_path, case, 8.0)
    assert c["t_reach[car]"][ready] == pytest.approx(8.0, abs=0.15) and c["priority[car]"][ready] == 1.0
    inside = (c["d_zone"] <= 0) & (c["d_zone_out"] > 0)
    first_in = int(np.flatnonzero(inside)[0])
    # in before the car, gone from its way before it arrives, never standing inside
    assert t[first_in] < t[ready] + 2.0 and np.isfinite(c["t_reach[car]"][first_in])
    assert not (inside & (c["v"] < 0.3) & (c["a"] < 0.5)).any()
    out_of_its_way = np.flatnonzero(c["d_exit[car]"] <= 0)
    assert len(out_of_its_way) and t[out_of_its_way[0]] < t[ready] + 8.0


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_a_gap_of_3_s_is_let_go(tmp_path: Path, case: str) -> None:
    c, t, ready = _run(tmp_path, case, 3.0)
    assert c["t_reach[car]"][ready] == pytest.approx(3.0, abs=0.15)
    inside = (c["d_zone"] <= 0) & (c["d_zone_out"] > 0)
    assert inside.any()
    first_in = int(np.flatnonzero(inside)[0])
    assert t[first_in] > t[ready] + 3.0 and c["t_reach[car]"][first_in] == np.inf  # after the car had passed


@pytest.mark.slow
def test_the_line_reads_the_scenario_s_margin(tmp_path: Path) -> None:
    """The give-way line keeps the loaded rule's gap: with t_margin = 3 s the 8 s gap at the yield
    sign (7.3 s needed with the rule's 1.5 s, 8.8 s with 3 s) is let go."""
    c, t, _ = _run(tmp_path, "yield", 8.0, "{t_margin: 3.0}")
    inside = (c["d_zone"] <= 0) & (c["d_zone_out"] > 0)
    first_in = int(np.flatnonzero(inside)[0])
    assert t[first_in] > 8.0 and c["t_reach[car]"][first_in] == np.inf
    standing = (c["v"] < 0.3) & (c["d_zone"] > 0) & (t < t[first_in])
    assert standing.sum() * (t[1] - t[0]) > 5.0  # it stood at its line while the car came
