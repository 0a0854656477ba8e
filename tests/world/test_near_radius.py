"""The default sensing radius ``r_near`` grows with the speed a scenario allows: 2 s of travel at
the fastest speed along the route (limit capped by the desired speed, at least the start speed),
never below the paper's 10 m nor beyond the sensing range; a radius given in the scenario is kept.
On the motorway (undertake_motorway, 30 m/s) the default reaches the slower car in the left lane
in time for no_passing_right to be judged on it (tests/world/test_passing_right.py runs it)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers.world_files import load_world
from twolevel.world.schema import R_NEAR_FLOOR, R_NEAR_HEADWAY

ROOT = Path(__file__).resolve().parents[2]
MAPS = ROOT / "maps"


def _scenario(tmp: Path, speed: float, desired: float | None = None, controller: str = "{}") -> Path:
    """The highway (limit 30 m/s) with the ego starting at ``speed`` [m/s]."""
    want = "" if desired is None else f"\n  desired_speed: {desired}"
    p = tmp / "s.yaml"
    p.write_text(f"""kind: scenario
name: radius
map: {MAPS / 'highway.yaml'}
ego:
  start: {{lane: middle, s: 20}}
  speed: {speed}{want}
route: {{start: {{lane: middle, s: 20}}, goal: {{lane: middle, s: 1400}}, stop_at_goal: false}}
controller: {controller}
expect: {{goal: false}}
""")
    return p


def test_the_motorway_scenario_senses_its_neighbour_without_a_hand_set_radius() -> None:
    w = load_world(ROOT / "scenarios" / "everyday" / "undertake_motorway.yaml")
    assert w.settings.r_near == pytest.approx(R_NEAR_HEADWAY * 30.0)  # 60 m at its 30 m/s; it once set 40 by hand
    assert R_NEAR_HEADWAY == 2.0 and R_NEAR_FLOOR == 10.0


@settings(max_examples=25, deadline=None)
@given(st.floats(0.0, 45.0), st.one_of(st.none(), st.floats(1.0, 40.0)))
def test_the_default_is_two_seconds_at_the_fastest_speed_allowed(tmp_path_factory: pytest.TempPathFactory,
                                                                speed: float, desired: float | None) -> None:
    w = load_world(_scenario(tmp_path_factory.mktemp("r"), speed, desired))
    fastest = max(min(30.0, desired if desired is not None else 30.0), speed)  # the highway's limit is 30 m/s
    want = min(max(10.0, 2.0 * fastest), w.settings.sensor_range)
    assert w.settings.r_near == pytest.approx(want)
    assert 10.0 <= w.settings.r_near <= w.settings.sensor_range


def test_a_given_radius_is_kept_and_the_default_stays_within_the_sensing_range(tmp_path: Path) -> None:
    assert load_world(_scenario(tmp_path, 30.0, controller="{r_near: 12}")).settings.r_near == 12.0
    assert load_world(_scenario(tmp_path, 30.0, controller="{sensor_range: 45}")).settings.r_near == 45.0
    assert load_world(_scenario(tmp_path, 0.0, desired=3.0)).settings.r_near == 10.0  # the floor
