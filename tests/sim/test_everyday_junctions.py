"""The everyday suite's junctions (scenarios/everyday/: unprotected_left, stop_sign_crossing,
merge_platoon) in the closed loop with the real controller and safety layer: each map describes
its junction (who has priority, the conflicts), each scenario loads rules/right_of_way.stl, and
each run is judged against its own ``expect:`` (goal, no collision at fault, speed_limit,
give_way, clear_junction, stop_sign where there is one, peak deceleration ≤ 4 m/s²), the
monitor agreeing with the run. Read back from the trace: the ego waited before the junction
while cars with priority passed, went in after them, never stood inside its conflict area nor
on any lane its route conflicts with, and never braked harder than 4 m/s² (these scenarios used
to meet their hazards with the fail-safes' full braking, ~9 m/s²)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers.junction_runs import check_gaps, junction_run, standing_in_conflicting_lanes

EVERYDAY = Path(__file__).resolve().parents[2] / "scenarios" / "everyday"
COMFORT = 4.0  # [m/s²] peak deceleration without a sudden hazard

# each scenario, and the participants with priority that come before the ego may go: it goes in
# only once each has passed its conflict area (t_reach +inf)
CASES = {
    "unprotected_left": ("oncoming_1", "oncoming_2", "oncoming_3", "oncoming_4"),
    "stop_sign_crossing": ("north_1", "north_2", "north_3", "south_1", "south_2", "south_3"),
    "merge_platoon": ("car_1", "car_2", "car_3", "car_4", "car_5", "car_6"),
}


def _decel(c: dict[str, np.ndarray]) -> float:
    """Peak deceleration [m/s²] of the executed speed (finite differences of v over t)."""
    return float(-np.min(np.diff(c["v"]) / np.diff(c["t"])))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_everyday_junction_waits_for_priority_traffic_and_brakes_gently(tmp_path: Path, name: str) -> None:
    path = EVERYDAY / f"{name}.yaml"
    c = junction_run(path, tmp_path / name)  # goal, no collision at fault, the rules, max_decel
    inside, waiting = check_gaps(c)
    assert waiting.sum() >= 10 and inside.any()
    first_in = int(np.flatnonzero(inside)[0])
    assert np.flatnonzero(waiting)[-1] < first_in  # it waited, then went
    for pid in CASES[name]:  # in after every car with priority had passed
        assert c[f"t_reach[{pid}]"][first_in] == np.inf, pid
    assert not standing_in_conflicting_lanes(path, c).any()
    assert _decel(c) <= COMFORT


def test_the_lane_check_sees_a_car_standing_across_the_crossing() -> None:
    """The oracle above: at the crossroads' stop line the ego's box is on no lane its route
    conflicts with; standing in the middle of the crossing (x = 100 m), or its front 1 m into the
    southbound crossing lane (x from 96.5 m), it is; driving through, it does not stand."""
    x = np.array([90.1, 100.0, 96.5 - 2.11 + 1.0, 100.0])
    c = {"x": x, "y": np.full(4, -1.75), "psi": np.zeros(4), "v": np.array([0.0, 0.0, 0.1, 5.0])}
    assert standing_in_conflicting_lanes(EVERYDAY / "stop_sign_crossing.yaml", c).tolist() == [False, True, True, False]
