"""``check`` warns (YML432) where a route's bend cannot be driven at its speed limit within the
comfort lateral acceleration, at the sign, the lane's own limit or the bend; the comfort, V2I
and weight settings are validated at their line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.pipeline.checking import check
from twolevel.world.loader import check_world_file, load_scenario

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()

MAP = """kind: map
name: bend
default_speed_limit: {default}
roads:
  - id: road
    start: {{x: 0, y: 0, heading: 0}}
    segments:
      - line: 100
      - arc: {{radius: 50, angle: -90}}
      - line: 100
    lanes:
      - {{id: east, offset: -1.75{own}}}
      - {{id: west, offset: 1.75, direction: backward}}
speed_limits: {signs}
"""


def world(tmp: Path, *, default: float = 20.0, own: str = "", signs: str = "[]", controller: str = "{}",
          desired: str = "") -> Path:
    """A map with a 50 m right bend (the east lane's radius 48.25 m) and a scenario driving it;
    the scenario's ``controller:`` is on line 9."""
    (tmp / "map.yaml").write_text(MAP.format(default=default, own=own, signs=signs))
    (tmp / "s.yaml").write_text(f"""kind: scenario
name: bend
map: map.yaml
ego:
  start: {{lane: east, s: 5}}
  speed: 10{desired}
route: {{start: {{lane: east, s: 5}}, goal: {{lane: east, s: 250}}}}
run: {{duration: 60}}
controller: {controller}
""")
    return tmp / "s.yaml"


def warnings(p: Path) -> list:
    return [d for d in check([str(p)]).diagnostics if d.code == "YML432"]


def test_a_bend_too_tight_for_the_default_limit_is_warned_at_the_bend(tmp_path: Path) -> None:
    d = warnings(world(tmp_path))
    assert [(x.span.file.endswith("map.yaml"), x.span.line) for x in d] == [(True, 9)]
    radius = 50 - 1.75
    assert f"{radius:.1f} m bend of lane 'east'" in d[0].message and "limit 20 m/s" in d[0].message
    assert f"{400 / radius:.1f} m/s² of lateral acceleration" in d[0].message
    assert f"slow to {math.sqrt(2.0 * radius):.1f} m/s" in d[0].message  # the default comfort, 2 m/s²
    assert d[0].severity.value == "warning" and load_scenario(tmp_path / "s.yaml")[0] is not None


def test_the_sign_in_force_is_where_the_warning_points(tmp_path: Path) -> None:
    # a 15 m/s sign before the bend sets the limit there: the warning is at its value
    d = warnings(world(tmp_path, default=8.0, signs="[{id: fast, lane: east, s: 60, value: 15.0}]"))
    column = (tmp_path / "map.yaml").read_text().splitlines()[13].index("15.0") + 1
    assert [(x.span.line, x.span.column) for x in d] == [(14, column)] and "limit 15 m/s" in d[0].message
    # a sign within the bend counts too
    d = warnings(world(tmp_path, default=8.0, signs="[{id: fast, lane: east, s: 130, value: 15.0}]"))
    assert [x.span.line for x in d] == [14]


def test_the_lanes_own_limit_is_where_the_warning_points(tmp_path: Path) -> None:
    d = warnings(world(tmp_path, default=8.0, own=", speed_limit: 16"))
    assert [x.span.line for x in d] == [12] and "limit 16 m/s" in d[0].message


@pytest.mark.parametrize("kwargs", [
    dict(default=9.8),                                     # 9.8² / 48.25 = 1.99 m/s²: comfortable
    dict(controller="{comfort_lat_accel: 8.5}"),            # allowed more lateral acceleration
    dict(desired="\n  desired_speed: 9.5"),                 # the ego never drives the limit
    dict(default=8.0, signs="[{id: later, lane: east, s: 200, value: 20.0}]"),  # past the bend
])
def test_no_warning_where_the_bend_can_be_driven(tmp_path: Path, kwargs: dict) -> None:
    assert warnings(world(tmp_path, **kwargs)) == []


def test_the_paper_scenarios_have_no_bend_warning() -> None:
    for p in sorted((ROOT / "scenarios").glob("*.yaml")):
        assert warnings(p) == [], p


def test_the_cli_reports_the_everyday_bend_scenarios(tmp_path: Path) -> None:
    res = runner.invoke(app, ["check", str(ROOT / "scenarios/everyday/fast_bend.yaml"), "-f", "json"],
                        env={"GITHUB_ACTIONS": ""})
    out = json.loads(res.stdout)
    assert res.exit_code == 0
    assert [(d["code"], Path(d["file"]).name, d["line"]) for d in out["diagnostics"]] == [("YML432", "fast_bend.yaml", 12)]


@pytest.mark.parametrize("controller, code, key", [
    ("{comfort_decel: 0}", "YML414", "comfort_decel"),
    ("{comfort_accel: -1.0}", "YML414", "comfort_accel"),
    ("{comfort_jerk: .inf}", "YML414", "comfort_jerk"),
    ("{comfort_lat_accel: .nan}", "YML414", "comfort_lat_accel"),
    ("{comfort_lat_accel: 20}", "YML414", "comfort_lat_accel"),
    ("{v2i: 1}", "YML413", "v2i"),
    ("{weights: {u: -1}}", "YML414", "u"),
    ("{weights: {track: [1, 1, 1]}}", None, "track"),
    ("{weights: {speed: 1}}", "YML411", "speed"),
])
def test_bad_comfort_v2i_and_weights_are_errors_at_their_line(tmp_path: Path, controller: str, code: str | None,
                                                              key: str) -> None:
    p = world(tmp_path, controller=controller)
    errors = [d for d in check_world_file(p) if d.is_error]
    assert len(errors) == 1 and errors[0].span.line == 9, [(d.code, d.span.line, d.message) for d in errors]
    line = (tmp_path / "s.yaml").read_text().splitlines()[8]
    assert line.index(key) + 1 <= errors[0].span.column  # at the key or its value
    if code is not None:
        assert errors[0].code == code
    assert load_scenario(p)[0] is None
