"""CommonRoad import and export on scenarios written by commonroad-io's own writer (straight,
curved, merging, signalised and stop-sign intersections; every obstacle type; every goal form):
what converts into what, the findings at the XML element's line, lights that agree with
commonroad-io's own state at every step, the CLI, and the round trip import → simulate → export
→ import, read back by commonroad-io."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

pytest.importorskip("commonroad", reason="commonroad-io is not installed (pip install 'twolevel[commonroad]')")

from twolevel.cli import app  # noqa: E402
from twolevel.interop.commonroad import import_commonroad  # noqa: E402
from twolevel.interop.commonroad_samples import SAMPLES, grid_network, write_samples  # noqa: E402
from twolevel.interop.output import write_imported  # noqa: E402
from twolevel.world.loader import check_world_file, load_scenario  # noqa: E402
from twolevel.world.world import build_world  # noqa: E402

runner = CliRunner()


@pytest.fixture(scope="module")
def samples(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return {p.stem.split("_")[1].split("-")[0]: p for p in write_samples(tmp_path_factory.mktemp("cr"))}


def _imported(path: Path, out: Path):  # noqa: ANN202
    imp, diags = import_commonroad(path, out_dir=out)
    assert imp is not None, diags
    write_imported(imp, out)
    return imp, diags


def _line_of(path: Path, pattern: str) -> int:
    for k, line in enumerate(path.read_text().splitlines(), 1):
        if re.search(pattern, line):
            return k
    raise AssertionError(pattern)


@pytest.mark.parametrize("name", [stem.split("_")[1].split("-")[0] for stem in SAMPLES])
def test_every_sample_imports_into_files_that_check_and_build(samples: dict[str, Path], tmp_path: Path, name: str) -> None:
    imp, diags = _imported(samples[name], tmp_path)
    assert all(d.severity.value == "warning" and d.code in ("IMP710", "IMP714") for d in diags), diags
    found = check_world_file(tmp_path / "scenario.yaml")
    assert not [d for d in found if d.is_error], found
    scn, _ = load_scenario(tmp_path / "scenario.yaml")
    world = build_world(scn)
    assert len(world.lanes.lanes) == len(imp.map["lanes"]) and world.route.length > 10


def test_straight_road_lanes_signs_obstacles_and_a_rectangle_goal(samples: dict[str, Path], tmp_path: Path) -> None:
    imp, diags = _imported(samples["Straight"], tmp_path)
    lanes = {lane["id"]: lane for lane in imp.map["lanes"]}
    assert set(lanes) == {"L1", "L2", "L3"}
    assert lanes["L1"]["speed_limit"] == lanes["L2"]["speed_limit"] == 20.0  # the MAX_SPEED sign, m/s
    assert lanes["L3"]["speed_limit"] == pytest.approx(130 / 3.6)  # no sign: the interstate's advisory limit
    assert lanes["L1"]["adjacent_left"] == "L2" and lanes["L2"]["adjacent_left"] == "L3"
    assert lanes["L1"]["categories"] == ["interstate", "main_carriageway"]
    assert (lanes["L1"]["left_marking"], lanes["L1"]["right_marking"]) == ("dashed", "solid")
    assert np.allclose(lanes["L1"]["left_bound"][0], [0, 1.75]) and np.allclose(lanes["L1"]["right_bound"][-1], [300, -1.75])
    parts = {p["id"]: p for p in imp.scenario["participants"]}
    assert parts["O500"]["behaviour"] == "stationary" and parts["O500"]["kind"] == "car"
    assert parts["O600"]["behaviour"] == "scripted" and parts["O600"]["box"] == {"length": 4.5, "width": 1.8}
    assert parts["O601"]["kind"] == "bus" and parts["O601"]["box"] == {"length": 12.0, "width": 2.5}
    wp = parts["O600"]["waypoints"]
    assert wp[0] == {"t": 0.0, "x": 40.0, "y": 0.0} and wp[10]["t"] == pytest.approx(1.0) and wp[10]["x"] == pytest.approx(58.0)
    sc = imp.scenario
    assert sc["ego"]["start"] == {"x": 5.0, "y": 0.0, "heading": 0.0} and sc["ego"]["speed"] == 15.0
    assert sc["route"]["start"] == {"lane": "L1", "s": pytest.approx(5.0)}
    assert sc["route"]["goal"] == {"lane": "L1", "s": pytest.approx(200.0)}
    assert sc["expect"]["goal"] == {"by": pytest.approx(25.0), "after": pytest.approx(2.0)}
    assert sc["controller"]["dt"] == 0.1 and sc["run"]["duration"] == pytest.approx(25.0)
    # the goal's speed and heading windows are not judged: said at the planning problem's line
    line = _line_of(samples["Straight"], r'<planningProblem id="1000"')
    assert {(d.code, d.span.line) for d in diags} == {("IMP710", line)}
    assert {"speed window", "heading window"} <= {w for d in diags for w in ("speed window", "heading window") if w in d.message}


def test_curve_polygon_zone_truck_and_a_circle_goal(samples: dict[str, Path], tmp_path: Path) -> None:
    imp, diags = _imported(samples["Curve"], tmp_path)
    parts = {p["id"]: p for p in imp.scenario["participants"]}
    zone = parts["O501"]
    assert zone["kind"] == "other" and zone["box"] == {"length": 6.0, "width": 2.0}
    assert zone["start"]["x"] == pytest.approx(43.0) and zone["start"]["y"] == pytest.approx(-5.0)  # the polygon's centre
    assert parts["O602"]["kind"] == "truck"
    approx = [d for d in diags if d.code == "IMP714"]
    assert len(approx) == 1 and "bounding box" in approx[0].message
    assert approx[0].span.line == _line_of(samples["Curve"], r'<staticObstacle id="501"')
    goal = imp.scenario["route"]["goal"]
    assert goal["lane"] == "L2"
    quarter = 0.5 * np.pi * 60  # the circle's centre (140, 60) ends the quarter circle
    assert goal["s"] == pytest.approx(quarter, abs=0.5)


def test_merge_starts_on_the_ramp_and_the_goal_lanelet_is_the_goal(samples: dict[str, Path], tmp_path: Path) -> None:
    imp, diags = _imported(samples["Merge"], tmp_path)
    lanes = {lane["id"]: lane for lane in imp.map["lanes"]}
    assert lanes["L20"]["successors"] == ["L4"] and lanes["L1"]["successors"] == ["L4"]
    assert lanes["L20"]["categories"] == ["access_ramp", "interstate"]
    sc = imp.scenario
    assert sc["route"]["start"]["lane"] == "L20" and sc["route"]["goal"] == {"lane": "L4", "s": pytest.approx(50.0)}
    assert {p["id"]: p["kind"] for p in sc["participants"]} == {"O603": "motorcycle"}
    assert not diags


def test_signalised_intersection_light_agrees_with_commonroad_at_every_step(samples: dict[str, Path], tmp_path: Path) -> None:
    from commonroad.common.file_reader import CommonRoadFileReader

    imp, diags = _imported(samples["Signal"], tmp_path)
    (light,) = imp.map["traffic_lights"]
    assert light["lane"] == "L30" and light["s"] == pytest.approx(48.0)  # at the stop line, not the lanelet's end
    world = build_world(load_scenario(tmp_path / "scenario.yaml")[0])
    sc, _ = CommonRoadFileReader(str(samples["Signal"])).open()
    cr = sc.lanelet_network.find_traffic_light_by_id(200)
    names = {"green": 0, "yellow": 1, "red": 2, "redYellow": 2}
    k = np.arange(400)
    expected = np.array([names[cr.get_state_at_time_step(int(i)).value] for i in k])
    assert np.array_equal(world.lights.state_at(k * 0.1)[:, 0], expected)
    parts = {p["id"]: p for p in imp.scenario["participants"]}
    assert parts["O604"]["kind"] == "pedestrian" and parts["O604"]["box"] == {"length": 0.7, "width": 0.7}
    assert parts["O605"]["kind"] == "bicycle"
    kinds = dict(world.assumptions.road_users)  # cyclists and pedestrians to the safety layer
    assert kinds == {"O604": 2, "O605": 1}
    codes = sorted((d.code, d.message.split(":")[0]) for d in diags)
    assert ("IMP714", "traffic light 200") in codes  # red-yellow as red
    assert any(d.code == "IMP710" and "goal state 2 of 2" in d.message for d in diags)
    assert any(d.code == "IMP710" and d.span.line == _line_of(samples["Signal"], r'<intersection id="301"') for d in diags)
    assert imp.scenario["route"]["goal"]["lane"] == "L40"


def test_stop_sign_at_its_line_yield_sign_reported_and_a_time_only_goal(samples: dict[str, Path], tmp_path: Path) -> None:
    imp, diags = _imported(samples["StopSign"], tmp_path)
    (stop,) = imp.map["stop_signs"]
    assert stop["lane"] == "L30" and stop["s"] == pytest.approx(48.0)
    yield_sign = [d for d in diags if "YIELD" in d.message]
    assert len(yield_sign) == 1 and yield_sign[0].span.line == _line_of(samples["StopSign"], r'<trafficSign id="102"')
    sc = imp.scenario
    assert sc["route"]["goal"]["lane"] == "L40" and sc["expect"]["goal"] == {"by": pytest.approx(30.0)}
    assert any("no position" in d.message for d in diags)


def test_a_grid_network_keeps_its_successors_and_adjacency(tmp_path: Path) -> None:
    imp, diags = _imported(grid_network(30, tmp_path / "grid.xml"), tmp_path)
    lanes = {lane["id"]: lane for lane in imp.map["lanes"]}
    assert len(lanes) == 30 and lanes["L1"]["successors"] == ["L4"] and "successors" not in lanes["L28"]
    assert lanes["L2"]["adjacent_right"] == "L1" and lanes["L2"]["adjacent_left"] == "L3"
    assert lanes["L1"]["speed_limit"] == 30.0 and lanes["L2"]["speed_limit"] == pytest.approx(50 / 3.6)
    assert not [d for d in check_world_file(tmp_path / "scenario.yaml") if d.is_error]


def test_unreadable_files_are_findings_not_tracebacks(tmp_path: Path) -> None:
    broken = tmp_path / "broken.xml"
    broken.write_text('<?xml version="1.0"?>\n<commonRoad>\n  <lanelet id="1">\n</commonRoad>\n')
    imp, diags = import_commonroad(broken)
    assert imp is None and diags[0].code == "IMP702" and diags[0].span.line == 4
    empty = tmp_path / "empty.xml"
    empty.write_text('<?xml version="1.0"?>\n<commonRoad timeStepSize="0.1" commonRoadVersion="2020a" '
                     'benchmarkID="ZAM_Empty-1_1_T-1" author="" affiliation="" source="" date="2024-01-01"/>\n')
    imp, diags = import_commonroad(empty)
    assert imp is None and [d.code for d in diags] == ["IMP703"]
    res = runner.invoke(app, ["import", str(broken), "--out", str(tmp_path / "out")])
    assert res.exit_code == 2 and "IMP702" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "out").exists()


def test_without_commonroad_io_the_importer_says_what_to_install(samples: dict[str, Path], monkeypatch) -> None:  # noqa: ANN001
    monkeypatch.setitem(sys.modules, "commonroad", None)  # what `import commonroad` meets when it is not installed
    imp, diags = import_commonroad(samples["Merge"])
    assert imp is None and diags[0].code == "IMP704" and "twolevel[commonroad]" in diags[0].hint


@pytest.mark.slow
def test_cli_import_and_check_accept_the_xml(samples: dict[str, Path], tmp_path: Path) -> None:
    res = runner.invoke(app, ["import", str(samples["StopSign"]), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "map.yaml").exists() and yaml.safe_load((tmp_path / "scenario.yaml").read_text())["map"] == "map.yaml"
    assert "IMP710" in res.output  # the yield sign
    assert runner.invoke(app, ["import", str(samples["StopSign"]), "--out", str(tmp_path), "--strict"]).exit_code == 1
    chk = runner.invoke(app, ["check", str(samples["StopSign"]), "-f", "concise"])
    assert chk.exit_code == 0 and f"{samples['StopSign']}:{_line_of(samples['StopSign'], '<trafficSign id=.102.')}:1: IMP710" in chk.output
    assert runner.invoke(app, ["check", str(samples["StopSign"]), "--strict"]).exit_code == 1
    assert runner.invoke(app, ["check", str(samples["Merge"])]).exit_code == 0


def _ego_run(samples: dict[str, Path], tmp_path: Path, seconds: str) -> tuple[Path, Path]:
    imported = tmp_path / "imported"
    assert runner.invoke(app, ["import", str(samples["Straight"]), "--out", str(imported)]).exit_code == 0
    run = tmp_path / "run"
    res = runner.invoke(app, ["simulate", str(imported / "scenario.yaml"), "--out", str(run), "--duration", seconds,
                              "--no-progress"])
    assert res.exit_code in (0, 1), res.output  # a run cut short misses its goal
    return imported, run


@pytest.mark.slow
def test_round_trip_import_simulate_export_import(samples: dict[str, Path], tmp_path: Path) -> None:
    from commonroad.common.file_reader import CommonRoadFileReader
    from commonroad.common.solution import CommonRoadSolutionReader

    from twolevel.sim.trace import read_run

    imported, run = _ego_run(samples, tmp_path, "3")
    out = tmp_path / "exported"
    res = runner.invoke(app, ["export", str(run), "--format", "commonroad", "--out", str(out)])
    assert res.exit_code == 0, res.output
    scenario_file, solution_file = out / "DEU_Straight-1_1_T-1.xml", out / "solution_DEU_Straight-1_1_T-1.xml"
    sc, pps = CommonRoadFileReader(str(scenario_file)).open()
    trace = read_run(run).columns
    ego = [o for o in sc.dynamic_obstacles if o.obstacle_id not in (600, 601)]
    assert len(ego) == 1 and len(ego[0].prediction.trajectory.state_list) == len(trace["t"]) - 1
    last = ego[0].prediction.trajectory.state_list[-1]
    # (the writer keeps 4 decimals)
    assert np.allclose(last.position, [trace["x"][-1], trace["y"][-1]], atol=1e-3)
    assert last.velocity == pytest.approx(trace["v"][-1], abs=1e-3)
    sol = CommonRoadSolutionReader.open(str(solution_file))
    assert sol.benchmark_id == "KS2:SM1:DEU_Straight-1_1_T-1:2020a"
    states = sol.planning_problem_solutions[0].trajectory.state_list
    assert states[0].time_step == 0 and np.allclose(states[0].position, [5.0, 0.0])
    # and back: the same lanes, the same obstacles plus the ego, the same goal lane
    again = tmp_path / "again"
    assert runner.invoke(app, ["import", str(scenario_file), "--out", str(again)]).exit_code == 0
    first, second = (yaml.safe_load((d / "map.yaml").read_text()) for d in (imported, again))
    a, b = ({lane["id"]: lane for lane in m["lanes"]} for m in (first, second))
    assert set(a) == set(b)
    for lid in a:
        assert np.allclose(a[lid]["left_bound"], b[lid]["left_bound"], atol=2e-3)
        assert np.allclose(a[lid]["right_bound"], b[lid]["right_bound"], atol=2e-3)
        assert a[lid].get("successors") == b[lid].get("successors") and a[lid]["speed_limit"] == pytest.approx(b[lid]["speed_limit"])
        assert a[lid]["categories"] == b[lid]["categories"] and a[lid].get("adjacent_left") == b[lid].get("adjacent_left")
    s1, s2 = (yaml.safe_load((d / "scenario.yaml").read_text()) for d in (imported, again))
    ids1, ids2 = ({p["id"] for p in s["participants"]} for s in (s1, s2))
    assert ids1 < ids2 and len(ids2 - ids1) == 1  # the ego, now an obstacle
    assert s1["route"]["goal"]["lane"] == s2["route"]["goal"]["lane"] == "L1"
    assert s2["route"]["goal"]["s"] == pytest.approx(s1["route"]["goal"]["s"], abs=0.5)
    assert s2["expect"]["goal"] == s1["expect"]["goal"]


def test_an_imported_scenario_simulates_and_exports(samples: dict[str, Path], tmp_path: Path) -> None:
    _, run = _ego_run(samples, tmp_path, "0.5")
    res = runner.invoke(app, ["export", str(run), "--out", str(tmp_path / "x")])
    assert res.exit_code == 0 and len(list((tmp_path / "x").glob("*.xml"))) == 2
    assert runner.invoke(app, ["export", str(tmp_path / "nothing")]).exit_code == 2


@pytest.mark.slow
def test_exported_lights_and_stop_lines_agree_with_the_run_at_every_step(samples: dict[str, Path], tmp_path: Path) -> None:
    from commonroad.common.file_reader import CommonRoadFileReader

    imported = tmp_path / "imported"
    assert runner.invoke(app, ["import", str(samples["Signal"]), "--out", str(imported)]).exit_code == 0
    run = tmp_path / "run"
    runner.invoke(app, ["simulate", str(imported / "scenario.yaml"), "--out", str(run), "--duration", "0.3", "--no-progress"])
    assert runner.invoke(app, ["export", str(run), "--out", str(tmp_path / "x")]).exit_code == 0
    sc, _ = CommonRoadFileReader(str(tmp_path / "x" / "DEU_Signal-1_1_T-1.xml")).open()
    (light,) = sc.lanelet_network.traffic_lights
    world = build_world(load_scenario(imported / "scenario.yaml")[0])
    names = {"green": 0, "yellow": 1, "red": 2}
    k = np.arange(400)
    assert np.array_equal([names[light.get_state_at_time_step(int(i)).value] for i in k], world.lights.state_at(k * 0.1)[:, 0])
    stop = sc.lanelet_network.find_lanelet_by_id(30).stop_line
    assert stop is not None and stop.traffic_light_ref == {light.traffic_light_id}
    assert np.allclose(0.5 * (stop.start + stop.end), [0.0, 48.0], atol=1e-3)


def test_a_light_that_is_no_green_yellow_red_cycle_becomes_a_script_that_agrees(tmp_path: Path) -> None:
    from commonroad.common.file_reader import CommonRoadFileReader
    from commonroad.scenario.traffic_light import TrafficLightCycle, TrafficLightCycleElement, TrafficLightState

    from twolevel.interop.commonroad_samples import intersection, write_scenario

    sc, pps = intersection()
    light = sc.lanelet_network.find_traffic_light_by_id(200)
    light.traffic_light_cycle = TrafficLightCycle([TrafficLightCycleElement(TrafficLightState(s), d) for s, d in
                                                   (("green", 20), ("red", 10), ("green", 5), ("yellow", 3))], time_offset=2)
    path = write_scenario(sc, pps, tmp_path / "ZAM_Odd-1_1_T-1.xml")
    imp, _ = _imported(path, tmp_path)
    (program,) = imp.map["traffic_lights"]
    assert "script" in program and program["script"][0] == {"t": 0.0, "state": "yellow"}
    world = build_world(load_scenario(tmp_path / "scenario.yaml")[0])
    cr = CommonRoadFileReader(str(path)).open()[0].lanelet_network.find_traffic_light_by_id(200)
    k = np.arange(int(world.settings.duration / 0.1))
    names = {"green": 0, "yellow": 1, "red": 2}
    assert np.array_equal(world.lights.state_at(k * 0.1)[:, 0], [names[cr.get_state_at_time_step(int(i)).value] for i in k])
