"""The declared assumptions: defaults, the scenario's ``assumptions:`` section, its diagnostics."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.world.assumptions import (
    CYCLIST, PEDESTRIAN, RSS_BOUNDS, VEHICLE, VEHICLE_BOUNDS, CYCLIST_BOUNDS, PEDESTRIAN_BOUNDS, kinds_of,
    safe_distance,
)
from twolevel.world.loader import check_world_file, load_scenario
from twolevel.world.schema import AssumptionsSpec, PedestrianBoundsSpec, ResponseSpec, UserBoundsSpec
from twolevel.world.world import build_world

MAPS = Path(__file__).resolve().parents[2] / "maps"


def scenario(tmp: Path, section: str, extra: str = "") -> Path:
    text = f"""\
kind: scenario
map: {MAPS / 'highway.yaml'}
ego: {{start: {{lane: middle, s: 10}}, speed: 10}}
route: {{start: {{lane: middle, s: 10}}, goal: {{lane: middle, s: 500}}}}
participants:
  - {{id: walker, behaviour: stationary, start: {{x: 50, y: 8, heading: 0}}}}
  - {{id: bike, behaviour: constant_velocity, start: {{lane: right, s: 40}}, speed: 5}}
populations:
  - {{id: crowd, count: 3, lanes: [left], s_range: [100, 200]}}
{extra}assumptions:
{textwrap.indent(textwrap.dedent(section), '  ')}"""
    p = tmp / "scn.yaml"
    p.write_text(text)
    return p


def test_the_section_overrides_the_defaults_and_names_road_users(tmp_path):
    p = scenario(tmp_path, """\
        vehicle: {a_max: 9.5, lane_changes: false}
        pedestrian: {v_max: 3.0}
        response: {time: 2.5}
        road_users: {walker: pedestrian, bike: cyclist, crowd: pedestrian}
        """)
    scn, diags = load_scenario(p)
    assert scn is not None and [d.code for d in diags] == ["YML423"]  # keeping lanes is tighter
    a = build_world(scn).assumptions
    assert a.vehicle.a_max == 9.5 and not a.vehicle.lane_changes and a.vehicle.v_switch == VEHICLE_BOUNDS.v_switch
    assert a.pedestrian.v_max == 3.0 and a.pedestrian.a_max == PEDESTRIAN_BOUNDS.a_max
    assert a.response.time == 2.5 and a.response.brake_min == RSS_BOUNDS.brake_min
    ids = build_world(scn).parts.ids
    assert dict(zip(ids, kinds_of(ids, a))) == {"walker": PEDESTRIAN, "bike": CYCLIST, "crowd-0": PEDESTRIAN,
                                                "crowd-1": PEDESTRIAN, "crowd-2": PEDESTRIAN}


def test_without_the_section_everyone_is_a_vehicle_under_the_defaults(tmp_path):
    p = scenario(tmp_path, "{}\n")
    w = build_world(load_scenario(p)[0])
    assert w.assumptions.vehicle == VEHICLE_BOUNDS and w.assumptions.cyclist == CYCLIST_BOUNDS
    assert set(kinds_of(w.parts.ids, w.assumptions)) == {VEHICLE}


@pytest.mark.parametrize("section, code, line, text", [
    ("road_users: {walker: pedestrian, walkr: cyclist}\n", "YML416", 11, "no participant or population 'walkr'"),
    ("road_users: {walker: truck}\n", "YML415", 11, "'vehicle', 'cyclist' or 'pedestrian'"),
    ("vehicle: {a_max: .inf}\n", "YML414", 11, "finite"),
    ("vehicle: {a_max: -2}\n", "YML414", 11, "> 0"),
    ("pedestrian: {lane_changes: true}\n", "YML411", 11, "unknown key 'lane_changes'"),
    ("vehicle: {a_max: 4.0}\n", "YML423", 11, "tighter than the default 8.0"),
    ("response: {brake_min: 6}\n", "YML423", 11, "'response.brake_min' = 6.0 is tighter"),
    ("cyclist:\n  stop_lines: false\n  speed_factor: 1.5\n", "YML423", 13, "'cyclist.speed_factor'"),
])
def test_check_reports_bad_assumptions_at_their_line(tmp_path, section, code, line, text):
    diags = check_world_file(scenario(tmp_path, section))
    hits = [d for d in diags if d.code == code]
    assert hits, [(d.code, d.message) for d in diags]
    assert hits[0].span.line == line and text in hits[0].message


def test_the_cli_warns_about_tighter_assumptions_and_fails_under_strict(tmp_path):
    p = scenario(tmp_path, "vehicle: {speed_factor: 1.0}\n")
    ok = CliRunner().invoke(app, ["check", str(p), "-f", "concise"])
    assert ok.exit_code == 0 and "YML423" in ok.output
    strict = CliRunner().invoke(app, ["check", str(p), "-f", "concise", "--strict"])
    assert strict.exit_code == 1


def test_check_of_a_scenario_with_assumptions_imports_no_numpy(tmp_path):
    p = scenario(tmp_path, "vehicle: {a_max: 4.0}\nroad_users: {walker: pedestrian}\n")
    code = ("import sys\nfrom twolevel.world.loader import check_world_file\n"
            f"check_world_file({str(p)!r})\nprint('numpy' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_the_schema_documents_the_library_defaults():
    """Every default the schema's descriptions quote is the library's."""
    fields = UserBoundsSpec.model_fields
    quoted = {
        ("v_max", "vehicle"): VEHICLE_BOUNDS.v_max, ("v_max", "cyclist"): CYCLIST_BOUNDS.v_max,
        ("a_max", "vehicle"): VEHICLE_BOUNDS.a_max, ("a_max", "cyclist"): CYCLIST_BOUNDS.a_max,
        ("speed_factor", "vehicle"): VEHICLE_BOUNDS.speed_factor, ("v_switch", "default"): VEHICLE_BOUNDS.v_switch,
        ("v_switch", "cyclist"): CYCLIST_BOUNDS.v_switch,
    }
    for (name, who), value in quoted.items():
        text = fields[name].description
        assert re.search(rf"{who} {value:g}\b", text), (name, text)
    assert f"default {PEDESTRIAN_BOUNDS.v_max:g}" in PedestrianBoundsSpec.model_fields["v_max"].description
    assert f"default {PEDESTRIAN_BOUNDS.a_max:g}" in PedestrianBoundsSpec.model_fields["a_max"].description
    for name in ("time", "accel_max", "brake_min", "brake_max"):
        assert f"default {getattr(RSS_BOUNDS, name):g}" in ResponseSpec.model_fields[name].description
    assert AssumptionsSpec.model_fields["road_users"].description


def test_rss_safe_distance():
    """Shalev-Shwartz et al.'s gap: grows with the rear car's speed, shrinks with the front's,
    and is what the rear car needs to stop behind the front one braking at brake_max."""
    assert safe_distance(20.0, 20.0) > safe_distance(10.0, 20.0) >= 0.0
    assert safe_distance(20.0, 30.0) < safe_distance(20.0, 20.0)
    r = RSS_BOUNDS
    v, d = 15.0, safe_distance(15.0, 0.0)
    v_resp = v + r.time * r.accel_max
    assert d == pytest.approx(v * r.time + 0.5 * r.accel_max * r.time**2 + v_resp**2 / (2 * r.brake_min))
