"""Every shipped map and scenario loads cleanly, builds a world, and checks with its rules."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.world.loader import check_world_file, load_map, load_scenario
from twolevel.world.signals import horizon_constants
from twolevel.world.traffic import nearby
from twolevel.world.world import build_world

ROOT = Path(__file__).resolve().parents[2]
MAPS = sorted((ROOT / "maps").glob("*.yaml")) + [ROOT / "examples/scenario/map.yaml"]
SCENARIOS = sorted((ROOT / "scenarios").rglob("*.yaml")) + [ROOT / "examples/scenario/scenario.yaml"]


@pytest.mark.parametrize("path", MAPS, ids=lambda p: p.name)
def test_map_loads(path: Path) -> None:
    m, diags = load_map(path)
    assert m is not None and diags == []


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_scenario_loads_builds_and_checks(path: Path) -> None:
    scn, diags = load_scenario(path)
    assert scn is not None and diags == []
    assert check_world_file(path) == []  # includes the rule files, linted at the scenario's dt and H
    w = build_world(scn)
    hc = horizon_constants(w, w.traffic0, 0.0, (w.ego.x, w.ego.y, w.ego.psi, w.ego.v))
    assert hc.v_max.shape == (w.settings.H + 1,)


def test_paper_scenarios_have_their_structure() -> None:
    worlds = {p.stem: build_world(load_scenario(p)[0]) for p in SCENARIOS if p.parent.name == "scenarios"}
    assert set(worlds) == {"comparison", "traffic_rules", "safety", "scalability"}
    assert len(worlds["comparison"].route.limit_s) >= 4
    assert np.any(worlds["comparison"].route.kappa != 0)
    tr = worlds["traffic_rules"]
    assert len(tr.route_stops) == 1 and len(tr.route_lights) == 1 and tr.route_stops[0] < tr.route_lights[0]
    assert len(worlds["safety"].parts.ids) == 160
    safety = worlds["safety"]
    still = safety.parts.kind == 0
    assert still.sum() == 1 and safety.traffic0.lane[still][0] == safety.route.pieces[0][0]
    sc = worlds["scalability"]
    assert len(sc.parts.ids) == 121 and sc.settings.r_near == 40
    assert 12 <= nearby(sc.traffic0, sc.ego.x, sc.ego.y, 40).sum() <= 24


def test_rule_file_reading_an_unprovided_signal_fails_check(tmp_path: Path) -> None:
    (tmp_path / "r.stl").write_text("input float v\ninput float warp\nfast = always[0:1] (v <= warp);\n")
    (tmp_path / "q.stl").write_text("input float v\nslow = always[0:1] (v >= 0);\n")
    text = (ROOT / "examples/scenario/scenario.yaml").read_text()
    text = text.replace("map: map.yaml", f"map: {ROOT / 'examples/scenario/map.yaml'}")
    text = text.replace("  - ../../rules/speed_limit.stl", "  - r.stl")
    text = text.replace("  - file: ../../rules/red_light.stl", "  - {file: q.stl, constants: {nope: 1}}")
    (tmp_path / "s.yaml").write_text(text)
    diags = check_world_file(tmp_path / "s.yaml")
    assert any(d.is_error and Path(d.span.file).name == "r.stl" and "warp" in d.message for d in diags), diags


def test_binding_an_undeclared_constant_points_at_the_scenario(tmp_path: Path) -> None:
    text = (ROOT / "examples/scenario/scenario.yaml").read_text()
    text = text.replace("map: map.yaml", f"map: {ROOT / 'examples/scenario/map.yaml'}")
    text = text.replace("  - ../../rules/speed_limit.stl", f"  - {{file: {ROOT / 'rules/speed_limit.stl'}, constants: {{tol: 0.2}}}}")
    text = text.replace("  - file: ../../rules/red_light.stl", f"  - {{file: {ROOT / 'rules/red_light.stl'}, constants: {{nope: 1}}}}")
    (tmp_path / "s.yaml").write_text(text)
    diags = check_world_file(tmp_path / "s.yaml")
    assert [(d.code, Path(d.span.file).name, d.span.line) for d in diags] == [("STL219", "s.yaml", 14)]
