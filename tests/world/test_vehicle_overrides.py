"""Ego vehicle-parameter overrides are validated against the models' parameter sets at check time."""

from __future__ import annotations

from pathlib import Path

from helpers.world_files import MAP, SCENARIO, write
from twolevel.world.loader import check_world_file, load_scenario


def _scenario(tmp_path: Path, vehicle_yaml: str) -> Path:
    write(tmp_path, "map.yaml", MAP)
    text = SCENARIO.replace("  speed: 5\n", "  speed: 5\n  vehicle:\n" + vehicle_yaml)
    return write(tmp_path, "scenario.yaml", text)


def test_known_overrides_of_either_model_are_accepted(tmp_path: Path) -> None:
    path = _scenario(tmp_path, "    l_f: 1.9\n    mu: 0.8\n")
    scenario, diags = load_scenario(path)
    assert scenario is not None and [d.code for d in diags if d.is_error] == []


def test_unknown_override_points_at_its_key_with_a_suggestion(tmp_path: Path) -> None:
    path = _scenario(tmp_path, "    l_f: 1.9\n    muu: 0.8\n")
    diags = [d for d in check_world_file(str(path)) if d.code == "YML411"]
    assert len(diags) == 1
    d = diags[0]
    assert d.span.line == 8 and "muu" in d.message and d.hint is not None and "'mu'" in d.hint


def test_physically_invalid_override_is_out_of_range(tmp_path: Path) -> None:
    path = _scenario(tmp_path, "    l_f: -2.0\n")
    diags = [d for d in check_world_file(str(path)) if d.code == "YML414"]
    assert len(diags) == 1 and diags[0].span.line == 7 and "l_f" in diags[0].message


def test_lateral_acceleration_limit_is_a_bicycle_parameter(tmp_path: Path) -> None:
    from twolevel.control.high_level.controller import HighLevelController
    from twolevel.control.high_level.settings import MPCSettings
    from twolevel.world.world import build_world

    path = _scenario(tmp_path, "    a_lat_max: 6.5\n")
    scenario, diags = load_scenario(path)
    assert scenario is not None and [d.code for d in diags if d.is_error] == []
    ctrl, _ = HighLevelController.from_world(build_world(scenario), MPCSettings())
    assert ctrl is not None and ctrl.params.a_lat_max == 6.5   # the MPC plans with the override
    bad = [d for d in check_world_file(str(_scenario(tmp_path, "    a_lat_max: 0\n"))) if d.code == "YML414"]
    assert len(bad) == 1 and "a_lat_max" in bad[0].message
