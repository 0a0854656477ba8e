"""`twolevel import NET.net.xml`: SUMO's own lanes, links and light states are the map's.

The oracle is SUMO itself (libsumo loading the same network), not sumolib, which the importer
reads: lane shapes, widths, speeds and links as SUMO simulates them, and each link's light
state over two cycles against the imported light at the same time.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.interop import format_of, import_file
from twolevel.interop.sumo import _colour, light_program, read_net
from twolevel.world.lanes import build_lanes
from twolevel.world.loader import load_map
from twolevel.world.traffic import GREEN, RED, YELLOW, Lights
from twolevel.world.world import _cycle_row, _lights

ls = pytest.importorskip("libsumo", reason="the optional 'sumo' extra (libsumo) is not installed")
pytest.importorskip("sumolib", reason="the optional 'sumo' extra (sumolib) is not installed")

ROOT = Path(__file__).resolve().parents[2]
GRID3 = ROOT / "examples/sumo/grid3.net.xml"
_CODE = {"green": GREEN, "yellow": YELLOW, "red": RED}


def _imported(net: Path, out: Path):  # noqa: ANN202 - (map spec, lane set, index)
    result = import_file(str(net), str(out))
    assert result.written and not result.bad_input, result.diagnostics
    assert [d for d in result.diagnostics if d.is_error] == [], result.diagnostics  # the loader's check ran
    m, mdiags = load_map(result.written[0])
    assert m is not None and [d for d in mdiags if d.is_error] == [], mdiags
    lanes, index, plans = build_lanes(m.spec)
    return m.spec, lanes, index, plans


def _start(net: Path) -> None:
    if ls.simulation.isLoaded():
        ls.close()
    ls.start(["sumo", "-n", str(net), "--step-length", "1", "--no-step-log", "true", "--no-warnings", "true"])


def _on_polyline(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance [m] of points (n, 2) from the polyline (m, 2)."""
    a, d = line[:-1], np.diff(line, axis=0)
    l2 = np.maximum((d**2).sum(1), 1e-12)
    t = np.clip(((p[:, None] - a[None]) * d[None]).sum(-1) / l2, 0, 1)
    return np.hypot(*(p[:, None] - a[None] - t[..., None] * d[None]).transpose(2, 0, 1)).min(1)


def test_lanes_are_sumos_lanes(tmp_path: Path) -> None:
    spec, lanes, index, _ = _imported(GRID3, tmp_path)
    _start(GRID3)
    try:
        sumo_lanes = [lid for lid in ls.lane.getIDList()]
        assert set(sumo_lanes) == set(index), "every lane SUMO simulates, internal ones included, and no other"
        free = {ln.id: ln for ln in spec.lanes}
        for lid in sumo_lanes:
            i = index[lid]
            shape = np.asarray(ls.lane.getShape(lid), dtype=float)
            lane = lanes.lanes[i]
            # the centre line lies on SUMO's shape, from its first to its last point, at every sample
            s = np.linspace(0.0, lanes.length[i], 25)
            xy, _ = lanes.pose(np.full(25, i), s)
            assert _on_polyline(xy, shape).max() < 2e-3, lid
            assert np.allclose(lane.points[[0, -1]], shape[[0, -1]], atol=1e-3), lid
            assert abs(lanes.length[i] - np.hypot(*np.diff(shape, axis=0).T).sum()) < 0.02, lid
            assert lanes.width[i] == pytest.approx(ls.lane.getWidth(lid), abs=1e-6), lid
            assert free[lid].speed_limit == pytest.approx(ls.lane.getMaxSpeed(lid), abs=1e-6), lid
            # successors: each link's internal lane, else its target lane
            links = ls.lane.getLinks(lid)
            want = {via if via else to for to, _prio, _open, _foe, via, *_rest in links}
            assert {lanes.lanes[j].id for j in lane.successors} == want, lid
    finally:
        ls.close()


def test_neighbours_of_an_edge_are_adjacent(tmp_path: Path) -> None:
    _, lanes, index, _ = _imported(GRID3, tmp_path)
    i0, i1 = index["A0B0_0"], index["A0B0_1"]
    assert lanes.adj_left[i0] == i1 and lanes.adj_right[i1] == i0
    assert lanes.adj_right[i0] != i1 and lanes.adj_left[i1] != i0


def _light_states_match(net: Path, out: Path, horizon: int = 200) -> int:
    """Every imported light against SUMO's state of its link, each second; the number compared."""
    spec, lanes, index, plans = _imported(net, out)
    lights = _lights(spec, index, plans)
    _start(net)
    try:
        links = {}  # light id -> (tls, link index)
        for tls in ls.trafficlight.getIDList():
            for k, group in enumerate(ls.trafficlight.getControlledLinks(tls)):
                for inc, _out, _via in group:
                    links[f"{tls}_{k}_{inc}"] = (tls, k)
        assert set(lights.ids) <= set(links)
        for _ in range(horizon):
            ls.simulationStep()
            # the state SUMO reports at t was in force during its last step, (t − 1, t]: compare mid-step
            t = ls.simulation.getTime()
            got = lights.state_at(t - 0.5)
            states = {tls: ls.trafficlight.getRedYellowGreenState(tls) for tls in ls.trafficlight.getIDList()}
            want = [_CODE[_colour(states[links[lid][0]][links[lid][1]])] for lid in lights.ids]
            assert list(got) == want, t
        # links green throughout get no light; every other controlled link has one
        untranslated = {lid for lid in links if lid not in lights.ids}
        for lid in untranslated:
            tls, k = links[lid]
            phases = ls.trafficlight.getAllProgramLogics(tls)[0].phases
            assert all(_colour(p.state[k]) == "green" for p in phases), lid
    finally:
        ls.close()
    return len(lights.ids)


def test_lights_follow_sumos_programs(tmp_path: Path) -> None:
    assert _light_states_match(GRID3, tmp_path) > 0


def test_lights_follow_an_offset_and_a_program_that_is_not_one_cycle(tmp_path: Path) -> None:
    text = GRID3.read_text()
    text = text.replace('<tlLogic id="A1" type="static" programID="0" offset="0">',
                        '<tlLogic id="A1" type="static" programID="0" offset="17">', 1)
    # B0: the first links green twice per cycle (not one green-yellow-red cycle: written as a script)
    block = re.search(r'<tlLogic id="B0".*?</tlLogic>', text, flags=re.S)
    assert block is not None
    new = re.sub(r'offset="0"', 'offset="5"', block.group(0))
    new = new.replace('state="rrrGyyyyy"', 'state="GGGGyyyyy"').replace('state="GGGGrrrrr"', 'state="rrrGrrrrr"')
    text = text.replace(block.group(0), new)
    net = tmp_path / "changed.net.xml"
    net.write_text(text)
    spec, _, _, _ = _imported(net, tmp_path / "out")
    kinds = {tl.id: ("cycle" if tl.cycle else "script") for tl in spec.traffic_lights}
    assert {k for lid, k in kinds.items() if lid.startswith("B0_0_")} == {"script"}
    assert {k for lid, k in kinds.items() if lid.startswith("A1_")} == {"cycle"}
    assert _light_states_match(net, tmp_path / "out2") > 0


@settings(max_examples=60, deadline=None)
@given(colours=st.lists(st.sampled_from(["green", "yellow", "red"]), min_size=1, max_size=6),
       durations=st.lists(st.integers(1, 60), min_size=6, max_size=6), offset=st.integers(0, 200),
       times=st.lists(st.floats(0, 3000, allow_nan=False), min_size=1, max_size=20))
def test_a_link_program_shows_sumos_phase_at_any_time(colours, durations, offset, times) -> None:
    dur = [float(d) for d in durations[: len(colours)]]
    program = light_program(colours, dur, float(offset))
    period = sum(dur)
    starts = np.cumsum([0.0] + dur[:-1])
    for t in times:
        pos = (t - offset) % period
        want = colours[int(np.searchsorted(starts, pos, side="right") - 1)]
        if program is None:
            assert want == "green"
            continue
        if "cycle" in program:
            c = program["cycle"]
            row = _cycle_row((c["green"], c["yellow"], c["red"], c["offset"]))
            times_, states = np.array([row[0]]), np.array([row[1]])
            lights = Lights(("l",), np.zeros(1, int), np.zeros(1), times_, states, np.array([row[2]]), np.array([row[3]]))
        else:
            steps = program["script"]
            lights = Lights(("l",), np.zeros(1, int), np.zeros(1), np.array([[s["t"] for s in steps]]),
                            np.array([[_CODE[s["state"]] for s in steps]]), np.array([math.inf]), np.zeros(1))
        near_switch = np.min(np.abs(((pos - np.append(starts, period)) + period / 2) % period - period / 2)) < 1e-6
        if not near_switch:
            assert int(lights.state_at(t)[0]) == _CODE[want], (t, program)


def test_untranslatable_parts_are_reported_at_their_line(tmp_path: Path) -> None:
    lines = GRID3.read_text().splitlines(keepends=True)
    at = next(k for k, line in enumerate(lines) if line.lstrip().startswith("<junction "))
    lines.insert(at, '    <roundabout nodes="A0 A1" edges="A0A1"/>\n    <weird id="w"/>\n')
    net = tmp_path / "extra.net.xml"
    net.write_text("".join(lines))
    doc, diags = read_net(str(net))
    assert doc is not None
    by_message = {d.message.split(">")[0]: d for d in diags if d.code == "IMP710" and d.message.startswith("<")}
    assert by_message["<roundabout"].span.line == at + 1 and by_message["<weird"].span.line == at + 2
    assert by_message["<roundabout"].span.file == str(net)


def test_unreadable_networks_are_diagnostics(tmp_path: Path) -> None:
    bad = tmp_path / "bad.net.xml"
    bad.write_text("<net>\n  <edge id='a'>\n</net>\n")
    doc, diags = read_net(str(bad))
    assert doc is None and diags[0].code == "IMP702" and diags[0].span.line == 3
    other = tmp_path / "routes.net.xml"
    other.write_text("<routes/>\n")
    assert read_net(str(other))[1][0].code == "IMP703"
    assert read_net(str(tmp_path / "missing.net.xml"))[1][0].code == "IMP701"
    dtd = tmp_path / "dtd.net.xml"
    dtd.write_text('<?xml version="1.0"?>\n<!DOCTYPE net [<!ENTITY a "aaaa">]>\n<net/>\n')
    assert read_net(str(dtd))[1][0].code == "IMP702"  # the importers' shared reader refuses DTDs


def test_a_sumo_network_is_chosen_before_the_xml_formats(tmp_path: Path) -> None:
    assert format_of(GRID3).name == "SUMO"
    crossing = tmp_path / "commonroad.net.xml"  # a .net.xml is SUMO's whatever its content
    crossing.write_text("<commonRoad/>\n")
    assert format_of(crossing).name == "SUMO" and import_file(crossing, tmp_path).bad_input
    assert [d.code for d in import_file(crossing, tmp_path).diagnostics] == ["IMP703"]


def test_without_sumolib_the_import_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(__import__("sys").modules, "sumolib", None)  # import sumolib raises ImportError
    doc, diags = read_net(str(GRID3))
    assert doc is None and [d.code for d in diags] == ["IMP704"] and "twolevel[sumo]" in (diags[0].hint or "")


def test_the_size_check_counts_nodes_as_the_map_loader_does(tmp_path: Path) -> None:
    from twolevel.interop.output import _nodes
    from twolevel.world.document import read_document

    result = import_file(GRID3, tmp_path)
    doc, _ = read_document(result.written[0])
    assert doc is not None and result.map is not None
    assert _nodes(result.map) == len(doc.where)  # one entry per node the loader built


def test_cli_import_writes_a_map_that_check_accepts(tmp_path: Path) -> None:
    runner = CliRunner()
    res = runner.invoke(app, ["import", str(GRID3), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "grid3.yaml").is_file()
    assert runner.invoke(app, ["check", str(tmp_path / "grid3.yaml")]).exit_code == 0
    checked = runner.invoke(app, ["check", str(GRID3)])  # through the importer, as every format's file
    assert checked.exit_code == 0 and "IMP710" in checked.output, checked.output
    strict = runner.invoke(app, ["import", str(GRID3), "--out", str(tmp_path), "--strict"])
    assert strict.exit_code == 1  # the priority junctions' right of way is not translated
    assert runner.invoke(app, ["import", str(tmp_path / "x.xodr2"), "--out", str(tmp_path)]).exit_code == 2
    assert runner.invoke(app, ["import", str(tmp_path / "none.net.xml"), "--out", str(tmp_path)]).exit_code == 2


def test_stop_links_become_stop_signs_at_the_lane_end(tmp_path: Path) -> None:
    text = GRID3.read_text().replace(
        '<connection from="A1A0" to="A0B0" fromLane="0" toLane="0" via=":A0_0_0" dir="l" state="M"/>',
        '<connection from="A1A0" to="A0B0" fromLane="0" toLane="0" via=":A0_0_0" dir="l" state="s"/>')
    assert 'state="s"' in text
    net = tmp_path / "stop.net.xml"
    net.write_text(text)
    spec, lanes, index, _ = _imported(net, tmp_path / "out")
    assert [(s.lane, s.s) for s in spec.stop_signs] == [("A1A0_0", pytest.approx(lanes.length[index["A1A0_0"]], abs=1e-3))]
    plain, _, _, _ = _imported(GRID3, tmp_path / "plain")
    assert plain.stop_signs == []
