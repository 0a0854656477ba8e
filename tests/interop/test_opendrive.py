"""`twolevel import MAP.xodr`: OpenDRIVE maps written by scenariogeneration, converted through CARLA's
parser, against an independent oracle of their geometry (tests/helpers/opendrive_maps.py): lane
boundaries where the reference line and width polynomials put them, successors where the topology
says, routes through junctions, and hostile files ending in findings, never a traceback."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

pytest.importorskip("carla")
xodr = pytest.importorskip("scenariogeneration.xodr")

from helpers import opendrive_maps as om  # noqa: E402
from twolevel.cli import app  # noqa: E402
from twolevel.interop import import_file  # noqa: E402

runner = CliRunner()
TOL = 0.02  # [m] how far an imported boundary may lie from the oracle's (sampling sag is 0.01 m)


def _imported(path: Path, out: Path, **options: object) -> dict:
    result = import_file(path, out, **options)
    assert result.written, [str(d) for d in result.diagnostics]
    assert not [d for d in result.diagnostics if d.is_error], [f"{d.code} {d.message}" for d in result.diagnostics]
    return {ln["id"]: ln for ln in result.map["lanes"]} | {"_data": result.map}


def _assert_borders(path: Path, lanes: dict, road: str, section: int, lane: int, s: np.ndarray) -> None:
    rec = lanes[f"r{road}_{section}_{lane}"]
    left, right = om.borders(path, road, section, lane, s)
    d_left = om.distance_to_polyline(left, np.asarray(rec["left_bound"]))
    d_right = om.distance_to_polyline(right, np.asarray(rec["right_bound"]))
    assert d_left.max() < TOL and d_right.max() < TOL, (lane, d_left.max(), d_right.max())


@pytest.mark.parametrize("name, geometry", [
    ("straight", [xodr.Line(200)]),
    ("arcs", [xodr.Line(50), xodr.Arc(0.01, angle=math.pi / 2), xodr.Arc(-0.04, angle=math.pi / 3), xodr.Line(30)]),
    ("spirals", [xodr.Line(30), xodr.Spiral(0.0, 0.02, length=40), xodr.Arc(0.02, length=40),
                 xodr.Spiral(0.02, -0.01, length=60), xodr.Line(30)]),
])
def test_lane_boundaries_follow_the_reference_line(tmp_path: Path, name: str, geometry: list) -> None:
    path = om.write(om.single_road(geometry, name, lane_width=3.5), tmp_path / f"{name}.xodr")
    lanes = _imported(path, tmp_path / "out")
    length = float(__import__("xml.etree.ElementTree", fromlist=["x"]).parse(path).getroot().find("road").get("length"))
    s = np.linspace(0.5, length - 0.5, 41)
    for lane in (1, -1, -2):
        _assert_borders(path, lanes, "1", 0, lane, s)
    # direction of travel: the right lanes drive along the reference line, the left lane against it
    fwd, back = np.asarray(lanes["r1_0_-1"]["left_bound"]), np.asarray(lanes["r1_0_1"]["left_bound"])
    start, _ = om.borders(path, "1", 0, -1, np.array([0.0]))
    assert np.hypot(*(fwd[0] - start[0])) < 0.01 and np.hypot(*(back[-1] - start[0])) < 0.01
    assert lanes["r1_0_-1"]["adjacent_right"] == "r1_0_-2" and lanes["r1_0_-1"]["adjacent_left"] == "r1_0_1"


def test_widths_that_change_along_a_road_and_lane_sections(tmp_path: Path) -> None:
    odr = xodr.OpenDrive("widths")
    r1 = xodr.create_road(xodr.Line(100), id=1, left_lanes=1, right_lanes=3, lane_width=3.0, lane_width_end=4.0)
    r2 = xodr.create_road(xodr.Line(150), id=2, left_lanes=1, right_lanes=[xodr.LaneDef(50, 100, 3, 2, -2)],
                          lane_width=3.5)
    r1.add_successor(xodr.ElementType.road, 2, xodr.ContactPoint.start)
    r2.add_predecessor(xodr.ElementType.road, 1, xodr.ContactPoint.end)
    odr.add_road(r1)
    odr.add_road(r2)
    path = om.write(odr, tmp_path / "widths.xodr")
    lanes = _imported(path, tmp_path / "out")
    s = np.linspace(0.5, 99.5, 34)
    for lane in (-1, -2, -3, 1):
        _assert_borders(path, lanes, "1", 0, lane, s)
    w = om.widths(path, "1", 0, -1, np.array([0.0, 50.0, 100.0]))
    assert w[0] == pytest.approx(3.0) and w[-1] == pytest.approx(4.0)  # the oracle reads the file right
    # the merge: road 2's middle section narrows lane -2 to nothing over 50 m (lane -3 takes its place);
    # the last metres, under 0.1 m wide, are one straight piece (a lane is at least 0.1 m wide
    # between its ends)
    for section, span in ((0, (0.5, 49.5)), (1, (50.5, 99.5)), (2, (100.5, 149.5))):
        for lane in (-1, -2):
            top = 94.0 if (section, lane) == (1, -2) else span[1]
            _assert_borders(path, lanes, "2", section, lane, np.linspace(span[0], top, 25))
    # successors across the road link and the lane sections
    assert "r2_0_-1" in lanes["r1_0_-1"]["successors"]
    assert "r2_1_-1" in lanes["r2_0_-1"]["successors"] and "r2_2_-1" in lanes["r2_1_-1"]["successors"]
    assert "r1_0_1" in lanes["r2_0_1"]["successors"]  # the left lane drives back from road 2 into road 1


def _reachable(lanes: dict, start: str, depth: int = 3) -> set[str]:
    seen, frontier = {start}, [start]
    for _ in range(depth):
        frontier = [n for lid in frontier for n in lanes[lid].get("successors", []) if n not in seen]
        seen.update(frontier)
    return seen


def test_a_four_way_junction_connects_every_arm_to_every_other(tmp_path: Path) -> None:
    path = om.write(om.four_way(), tmp_path / "junction4.xodr")
    lanes = _imported(path, tmp_path / "out")
    connecting = [lid for lid in lanes if lid.startswith("r2") and len(lid.split("_")[0]) == 4]  # roads 200…
    assert len(connecting) == 24  # two lanes in from each of four arms, three ways out each
    for a in range(1, 5):
        reach = {lid.split("_")[0] for lid in _reachable(lanes, f"r{a}_0_-1") | _reachable(lanes, f"r{a}_0_-2")}
        assert reach >= {f"r{b}" for b in range(1, 5) if b != a}, (a, reach)
        for lid in (f"r{a}_0_1", f"r{a}_0_2"):  # lanes leaving the junction lead nowhere on this map
            assert not lanes[lid].get("successors")


def test_a_route_through_the_junction_loads_and_plans_its_reference(tmp_path: Path) -> None:
    from twolevel.world.loader import load_scenario

    path = om.write(om.four_way(), tmp_path / "junction4.xodr")
    lanes = _imported(path, tmp_path)
    out_lane = next(lid for lid in _reachable(lanes, "r1_0_-1") if lid.startswith("r3_"))
    (tmp_path / "s.yaml").write_text(
        "kind: scenario\nmap: junction4.yaml\n"
        "ego: {start: {lane: r1_0_-1, s: 5}, speed: 5}\n"
        f"route: {{start: {{lane: r1_0_-1, s: 5}}, goal: {{lane: {out_lane}, s: 50}}}}\n")
    scenario, diags = load_scenario(tmp_path / "s.yaml")
    assert scenario is not None, [str(d) for d in diags]
    result = runner.invoke(app, ["check", str(tmp_path / "s.yaml"), "-f", "concise"])
    assert result.exit_code == 0, result.output


def _roundabout(tmp_path: Path) -> Path:
    """A one-lane ring of radius 40 m (four arcs, counter-clockwise) joined by four three-way
    junctions, each with a spoke (1 + 1 lanes); written by scenariogeneration."""
    odr = xodr.OpenDrive("roundabout")
    R, gap = 40.0, 12.0
    jcs = [xodr.CommonJunctionCreator(id=900 + k, name=f"j{k}", startnum=100 * (k + 1)) for k in range(4)]
    ring = [xodr.create_road(xodr.Arc(1 / R, angle=math.pi / 2 - 2 * gap / R), id=10 + k, left_lanes=0, right_lanes=1,
                             lane_width=4.0) for k in range(4)]
    spokes = [xodr.create_road(xodr.Line(60), id=20 + k, left_lanes=1, right_lanes=1, lane_width=3.5) for k in range(4)]
    for k in range(4):
        th = math.pi / 2 * k
        tang = th + math.pi / 2
        cx, cy = R * math.cos(th), R * math.sin(th)  # the junction on the ring, in the ring's frame
        back, fwd = ring[(k - 1) % 4], ring[k]
        # ring points gap metres before and after the junction, along the circle
        b_ang, f_ang = th - gap / R, th + gap / R
        jcs[k].add_incoming_road_cartesian_geometry(back, R * math.cos(b_ang) - cx, R * math.sin(b_ang) - cy,
                                                    b_ang + math.pi / 2, "successor")
        jcs[k].add_incoming_road_cartesian_geometry(fwd, R * math.cos(f_ang) - cx, R * math.sin(f_ang) - cy,
                                                    f_ang + math.pi / 2 + math.pi, "predecessor")
        jcs[k].add_incoming_road_cartesian_geometry(spokes[k], gap * math.cos(th), gap * math.sin(th), th + math.pi,
                                                    "predecessor")
        jcs[k].add_connection(back.id, fwd.id, -1, -1)
        jcs[k].add_connection(back.id, spokes[k].id, -1, -1)
        jcs[k].add_connection(spokes[k].id, fwd.id, 1, -1)
        del tang
    for r in ring + spokes:
        odr.add_road(r)
    for jc in jcs:
        odr.add_junction_creator(jc)
    return om.write(odr, tmp_path / "roundabout.xodr")


def test_a_roundabout_closes_its_ring_and_every_spoke_enters_and_leaves_it(tmp_path: Path) -> None:
    path = _roundabout(tmp_path)
    lanes = _imported(path, tmp_path / "out")
    for k in range(4):  # around the ring: each ring lane reaches the next through a junction
        assert f"r{10 + (k + 1) % 4}_0_-1" in _reachable(lanes, f"r{10 + k}_0_-1", 2)
        assert f"r{20 + k}_0_-1" in _reachable(lanes, f"r{10 + (k - 1) % 4}_0_-1", 2)  # leave by the spoke
        assert f"r{10 + k}_0_-1" in _reachable(lanes, f"r{20 + k}_0_1", 2)  # enter from the spoke
    s = np.linspace(0.5, (math.pi / 2 - 24 / 40) * 40 - 0.5, 21)
    for k in range(4):
        _assert_borders(path, lanes, str(10 + k), 0, -1, s)


def test_signals_become_signs_lights_and_limits_on_their_lanes(tmp_path: Path) -> None:
    road = xodr.create_road(xodr.Line(200), id=1, left_lanes=2, right_lanes=2, lane_width=3.5)
    road.add_type(xodr.RoadType.motorway, s=0, country="DE", speed=120, speed_unit="km/h")
    limit = xodr.Signal(s=50, t=-8, country="DE", Type="274", subtype="58", value=80, unit="km/h", id="10")
    limit.add_validity(-2, -1)
    road.add_signal(limit)
    road.add_signal(xodr.Signal(s=190, t=-8, country="DE", Type="206", id="11"))
    road.add_signal(xodr.Signal(s=195, t=-8, country="DE", Type="294", id="14"))  # the stop sign's line
    road.add_signal(xodr.Signal(s=120, t=8, country="OpenDRIVE", Type="1000001", dynamic=xodr.Dynamic.yes, id="12",
                                orientation=xodr.Orientation.negative))
    road.add_signal(xodr.Signal(s=100, t=-8, country="DE", Type="101", id="13"))  # a danger sign: not converted
    odr = xodr.OpenDrive("signals")
    odr.add_road(road)
    path = om.write(odr, tmp_path / "signals.xodr")
    result = import_file(path, tmp_path / "out")
    data = result.map
    assert [ln["speed_limit"] for ln in data["lanes"]] == pytest.approx([120 / 3.6] * 4, abs=1e-3)
    assert {(x["lane"], x["s"], round(x["value"] * 3.6)) for x in data["speed_limits"]} == {
        ("r1_0_-1", 50.0, 80), ("r1_0_-2", 50.0, 80)}
    assert {(x["lane"], x["s"]) for x in data["stop_signs"]} == {("r1_0_-1", 195.0), ("r1_0_-2", 195.0)}
    # the light faces traffic driving against s: 80 m along the left lanes from their start at s = 200
    assert {(x["lane"], x["s"]) for x in data["traffic_lights"]} == {("r1_0_1", 80.0), ("r1_0_2", 80.0)}
    not_converted = [d for d in result.diagnostics if d.code == "IMP710"]
    lines = path.read_text().splitlines()
    assert len(not_converted) == 1 and 'id="13"' in lines[not_converted[0].span.line - 1]


def test_shoulders_only_on_request(tmp_path: Path) -> None:
    road = xodr.create_road(xodr.Line(80), id=1, left_lanes=1, right_lanes=1, lane_width=3.5)
    road.lanes.lanesections[0].add_right_lane(xodr.Lane(lane_type=xodr.LaneType.shoulder, a=2.0))
    odr = xodr.OpenDrive("shoulder")
    odr.add_road(road)
    path = om.write(odr, tmp_path / "shoulder.xodr")
    plain = _imported(path, tmp_path / "a")
    assert "r1_0_-2" not in plain
    wide = _imported(path, tmp_path / "b", include=("shoulder",))
    assert wide["r1_0_-2"]["type"] == "shoulder" and wide["r1_0_-1"]["adjacent_right"] == "r1_0_-2"
    _assert_borders(path, wide, "1", 0, -2, np.linspace(0.5, 79.5, 9))


def test_degenerate_spirals_and_colliding_junction_ids_are_repaired_and_said(tmp_path: Path) -> None:
    odr = xodr.OpenDrive("collide")
    roads = [xodr.create_road(xodr.Line(60), id=i + 1, left_lanes=1, right_lanes=1, lane_width=3.5) for i in range(3)]
    jc = xodr.CommonJunctionCreator(id=2, name="j", startnum=100)  # junction 2 = road 2's id
    for i, r in enumerate(roads):
        odr.add_road(r)
        jc.add_incoming_road_circular_geometry(r, radius=15, angle=i * 2 * math.pi / 3, road_connection="successor")
    jc.add_connection(1, 2)
    jc.add_connection(1, 3)
    odr.add_junction_creator(jc)
    path = om.write(odr, tmp_path / "collide.xodr")
    assert 'curvStart="' in path.read_text()
    result = import_file(path, tmp_path / "out")
    repaired = sorted(d.message.split(" ")[0] + d.message.split(" ")[1] for d in result.diagnostics if d.code == "IMP711")
    assert any("junctionid" in m for m in repaired) and any("spiral" in m for m in repaired), repaired
    lanes = {ln["id"]: ln for ln in result.map["lanes"]}
    assert lanes["r1_0_-1"].get("successors"), "without the renumbering no lane enters the junction"
    assert not [d for d in result.diagnostics if d.is_error]


def test_the_cli_imports_and_check_reads_the_xodr_through_the_importer(tmp_path: Path) -> None:
    path = om.write(om.four_way(), tmp_path / "junction4.xodr")
    result = runner.invoke(app, ["import", str(path), "--out", str(tmp_path / "out"), "-f", "concise"])
    assert result.exit_code == 0, result.output
    written = tmp_path / "out" / "junction4.yaml"
    assert yaml.safe_load(written.read_text())["kind"] == "map"
    assert runner.invoke(app, ["check", str(written), "-f", "concise"]).exit_code == 0
    checked = runner.invoke(app, ["check", str(path), "-f", "json"])
    assert checked.exit_code == 0, checked.output
    assert "IMP710" in checked.output  # the junction's priorities: said, not silently dropped
    bad = runner.invoke(app, ["import", str(path), "--out", str(tmp_path / "o2"), "--include", "lava"])
    assert bad.exit_code == 2 and "lava" in bad.output


def test_without_the_reader_the_import_says_which_extra_to_install(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = om.write(om.single_road([xodr.Line(50)], "plain"), tmp_path / "plain.xodr")
    monkeypatch.setitem(__import__("sys").modules, "carla", None)  # `import carla` raises ImportError
    result = runner.invoke(app, ["import", str(path), "--out", str(tmp_path / "out"), "-f", "concise"])
    assert result.exit_code == 2 and "IMP704" in result.output and "twolevel[opendrive]" in result.output


STRAIGHT = """<?xml version='1.0' encoding='utf-8'?>
<OpenDRIVE>
  <header revMajor="1" revMinor="6" name="s"/>
  <road id="1" junction="-1" length="{length}">
    <link>{link}</link>
    <planView><geometry s="0" x="0" y="0" hdg="{hdg}" length="{length}"><line/></geometry></planView>
    <lanes><laneSection s="{section}">
      <center><lane id="0" type="none"/></center>
      <right><lane id="-1" type="driving"><width sOffset="0" a="{width}" b="0" c="0" d="0"/></lane></right>
    </laneSection></lanes>
  </road>
</OpenDRIVE>
"""
_OK = {"length": "100", "hdg": "0", "section": "0", "width": "3.5", "link": ""}


@pytest.mark.parametrize("text, code, status", [
    ("not xml at all", "IMP702", 2),
    (STRAIGHT.format(**_OK)[:300], "IMP702", 2),
    ('<?xml version="1.0"?>\n<!DOCTYPE l [<!ENTITY a "aaaa"><!ENTITY b "&a;&a;&a;&a;">]>\n<OpenDRIVE>&b;</OpenDRIVE>',
     "IMP702", 2),
    ("<CommonRoad/>", "IMP703", 2),
    ("<OpenDRIVE/>", "IMP706", 2),
    (STRAIGHT.format(**_OK | {"length": "abc"}), "IMP712", 2),
    (STRAIGHT.format(**_OK | {"hdg": "nan"}), "IMP712", 2),
    (STRAIGHT.format(**_OK | {"length": "1e308"}), "IMP706", 2),
    (STRAIGHT.format(**_OK).replace("<line/>", "<link/>"), "IMP712", 2),
    (STRAIGHT.format(**_OK | {"section": "500"}), "IMP705", 2),
    (STRAIGHT.format(**_OK | {"link": '<successor elementType="road" elementId="99"/>'}), "IMP712", 0),
    (STRAIGHT.format(**_OK | {"width": "-3"}), "IMP721", 1),
    (STRAIGHT.format(**_OK).replace('id="1"', 'id="one"'), "IMP712", 2),
    (STRAIGHT.format(**_OK).replace("<line/>", '<spiral curvStart="0" curvEnd="1e6"/>'), "IMP712", 2),
])
def test_malformed_and_hostile_files_end_in_findings(tmp_path: Path, text: str, code: str, status: int) -> None:
    path = tmp_path / "bad.xodr"
    path.write_text(text)
    result = runner.invoke(app, ["import", str(path), "--out", str(tmp_path / "out"), "-f", "json"])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert result.exit_code == status, result.output
    assert code in result.output and "Traceback" not in result.output


def test_a_reader_crash_is_a_finding() -> None:
    """CARLA's parser dies of a segmentation fault on a <geometry> holding no known piece (the
    import leaves such roads out before it reads); it runs in a child process, so even such a
    crash is an answer, not the end of twolevel."""
    from twolevel.interop.carla_reader import isolated, read

    text = STRAIGHT.format(**_OK).replace("<line/>", "<link/><line/>")
    answers, why = isolated(read, "crash", text, [(1, -1, [1.0, 2.0], False, 99.0)])
    assert answers is None and why is not None and "crashed" in why
    answers, why = isolated(read, "fine", STRAIGHT.format(**_OK), [(1, -1, [1.0, 2.0], False, 99.0)])
    assert why is None and answers[0][0][0] == pytest.approx([1.0, 0.0], abs=1e-6)
