"""The MPC's drivable band: the route's lane and the usable lanes beside it that run the same
way — never a parking lane (regression: on a street whose parking lanes were plain driving lanes
in the map, and the band took any lane found beside the route, the MPC overtook a queue through
the parking lane, the safety layer's fail-safes then stood on it beside parked cars, and the car
stood for 48 s within D_safe of one: a deadlock, goal missed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers.world_files import write
from twolevel.control.high_level.guards import drivable_band
from twolevel.sim.engine import simulate_scenario
from twolevel.sim.trace import read_run
from twolevel.world.loader import load_scenario
from twolevel.world.world import build_world

ROOT = Path(__file__).resolve().parents[3]

STREET = """\
kind: map
name: street
roads:
  - id: street
    start: {{x: 0, y: 0, heading: 0}}
    segments: [{{line: 200}}]
    lanes:
      - {{id: east, offset: -1.75, width: 3.5}}
      - {{id: west, offset: 1.75, width: 3.5, direction: backward}}
      - {{id: park_e, offset: -4.75, width: 2.5, type: {kind}{usable}}}
"""

SCENARIO = """\
kind: scenario
map: map.yaml
ego: {start: {lane: east, s: 10}, speed: 8}
route: {start: {lane: east, s: 10}, goal: {lane: east, s: 190}}
"""


def _band(tmp_path: Path, kind: str, usable: str = "") -> tuple[np.ndarray, np.ndarray, float]:
    write(tmp_path, "map.yaml", STREET.format(kind=kind, usable=usable))
    world = build_world(load_scenario(write(tmp_path, "s.yaml", SCENARIO))[0])
    lo, hi = drivable_band(world, np.linspace(0.0, 170.0, 35))
    return lo, hi, 0.5 * world.ego.width


@pytest.mark.parametrize("kind, usable, extends", [("parking", "", False), ("shoulder", "", False),
                                                    ("shoulder", ", usable: true", True), ("driving", "", True)])
def test_the_band_takes_a_lane_beside_the_route_only_when_it_is_usable(tmp_path: Path, kind: str, usable: str,
                                                                       extends: bool) -> None:
    lo, hi, half = _band(tmp_path, kind, usable)
    np.testing.assert_allclose(hi, 1.75 - half)  # the oncoming lane is never in the band
    # with the lane beside: one more lane width (the route lane's, 3.5 m); else the route lane's own edge
    np.testing.assert_allclose(lo, (-1.75 - 3.5 if extends else -1.75) + half)


@pytest.mark.slow
def test_regression_the_queue_is_followed_not_overtaken_through_the_parking_lane(tmp_path: Path) -> None:
    """The everyday suite's dense street: the car follows the queue in its lane past the parked
    cars and reaches the goal (it stood 48 s beside a parked car after passing through the
    parking lane)."""
    out = tmp_path / "run"
    summary, diags = simulate_scenario(str(ROOT / "scenarios/everyday/urban_dense.yaml"), str(out), frames=False)
    assert summary is not None and summary.status == "complete", [d.message for d in diags]
    assert summary.goal_reached_t is not None
    e = np.asarray(read_run(out).columns["e"], float)
    assert np.abs(e).max() < 0.9  # within the ego's own lane (3.5 m wide, the car 1.8 m)
    assert not [c for c in summary.collisions if c.at_fault]
