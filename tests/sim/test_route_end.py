"""A route that does not stop at its goal (``stop_at_goal: false``): the car drives on at its
desired speed and the run ends where the route does — no emergency stop in a live lane (it
braked at −9 m/s² at the route's end and stood there). And the ride's figures a judged run
records (twolevel/verdict/ride.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.sim.engine import simulate_scenario
from twolevel.sim.trace import read_run
from twolevel.verdict.judge import judge_run, recorded_ride
from twolevel.verdict.motion import motion_of

MAPS = Path(__file__).resolve().parents[2] / "maps"


def _scenario(tmp: Path, stop: bool) -> Path:
    p = tmp / f"end_{stop}.yaml"
    p.write_text(f"""kind: scenario
name: route_end
map: {MAPS / 'one_lane.yaml'}
ego: {{start: {{lane: lane, s: 10}}, speed: 11.0}}
route: {{start: {{lane: lane, s: 10}}, goal: {{lane: lane, s: 70}}, stop_at_goal: {str(stop).lower()}}}
run: {{duration: 20, seed: 0}}
expect: {{max_decel: 4.0}}
""")
    return p


@pytest.mark.slow
def test_a_route_that_does_not_stop_ends_the_run_at_its_end_without_braking(tmp_path: Path) -> None:
    summary, diags = simulate_scenario(str(_scenario(tmp_path, False)), str(tmp_path / "run"), frames=False)
    assert summary is not None, [d.message for d in diags]
    run = read_run(tmp_path / "run")
    t, s, v = (np.asarray(run.columns[k], float) for k in ("t", "s", "v"))
    length = 60.0
    # it reaches the goal, drives past the route's end at its speed, and the run ends there
    assert summary.goal_reached_t is not None and s[-1] >= length - 1e-6 > s[-2]
    assert t[-1] < 8.0 and v.min() > 10.0
    assert motion_of(t, v, np.asarray(run.columns["psi"], float)).peak_decel[0] < 1.0
    verdict, _ = judge_run(tmp_path / "run")
    assert verdict is not None and verdict.passed, [c.detail for c in verdict.failed]
    ride = recorded_ride(read_run(tmp_path / "run").meta)
    assert ride is not None and ride.goal_t == pytest.approx(summary.goal_reached_t) and ride.stopped == 0.0
    assert ride.lane_offset < 0.3 and ride.decel < 1.0


@pytest.mark.slow
def test_a_route_that_stops_still_stops_at_its_goal(tmp_path: Path) -> None:
    summary, _ = simulate_scenario(str(_scenario(tmp_path, True)), str(tmp_path / "run"), frames=False)
    assert summary is not None and summary.goal_reached_t is not None
    run = read_run(tmp_path / "run")
    s, v = (np.asarray(run.columns[k], float) for k in ("s", "v"))
    assert abs(v[-1]) <= 0.1 and 59.0 <= s[-1] <= 60.5
    verdict, _ = judge_run(tmp_path / "run")
    ride = recorded_ride(read_run(tmp_path / "run").meta)
    # the final standstill is arriving, not time spent stopped; braking comfortable
    assert verdict is not None and verdict.passed and ride is not None and ride.stopped == 0.0
    assert 0.5 < ride.decel <= 4.0


def test_the_ride_of_a_known_trace() -> None:
    from twolevel.verdict.ride import Ride, ride_of
    from twolevel.world.loader import load_scenario
    from twolevel.world.world import build_world

    w = build_world(load_scenario(Path(__file__).resolve().parents[2] / "scenarios/everyday/fast_bend.yaml")[0])
    t = 0.1 * np.arange(101)
    v = np.concatenate([np.full(20, 9.0), 9.0 - 3.0 * 0.1 * np.arange(1, 31), np.zeros(25), 0.1 * np.arange(1, 27)])
    x = 10.0 + np.concatenate([[0.0], np.cumsum(v[:-1] * 0.1)])
    y = np.full_like(t, -1.75 + 0.4)  # 0.4 m left of the east lane's centre
    ride = ride_of(w, {"t": t, "x": x, "y": y, "psi": np.zeros_like(t), "v": v}, None, 0.1)
    assert ride.lane_offset == pytest.approx(0.4)
    assert ride.decel == pytest.approx(3.0) and ride.stopped == pytest.approx(2.7)  # 27 samples at ≤ 0.1 m/s
    assert ride.jerk == pytest.approx(30.0)  # 3 m/s² from one sample to the next (0.1 s)
    assert Ride.from_json(ride.to_json()) == ride
    # standing at the end of a run that reached its goal is arriving
    still = ride_of(w, {"t": t[:75], "x": x[:75], "y": y[:75], "psi": np.zeros(75), "v": v[:75]}, 7.0, 0.1)
    assert still.stopped == 0.0 and ride_of(w, {"t": t[:75], "x": x[:75], "y": y[:75], "psi": np.zeros(75),
                                                "v": v[:75]}, None, 0.1).stopped == pytest.approx(2.6)
