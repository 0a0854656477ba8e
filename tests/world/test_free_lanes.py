"""Free-form lanes: built from the boundaries of road lanes they are the same lanes (projection,
route, widths, signals); their geometry, adjacency and markings; and what ``check`` says of
malformed ones, at the right line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from helpers.world_files import load_world, write
from twolevel.world.geometry import MARKINGS
from twolevel.world.lanes import centre_lines
from twolevel.world.loader import load_map, load_scenario
from twolevel.world.signals import PASS_MARGIN, STOP_ZONE, TrafficLog, signals_along
from twolevel.world.world import build_world

ROOT = Path(__file__).resolve().parents[2]


def _points(a: np.ndarray) -> str:
    return "[" + ", ".join(f"[{x!r}, {y!r}]" for x, y in a.tolist()) + "]"


ROAD_MAP = """\
kind: map
roads:
  - id: road
    start: {{x: 5, y: -3, heading: 20}}
    segments: {segments}
    lanes:
      - {{id: fwd, offset: -1.75, width: {w1}, successors: [after]}}
      - {{id: back, offset: {off2}, width: {w2}, direction: backward}}
  - id: after
    start: {{x: {ax!r}, y: {ay!r}, heading: {ah!r}}}
    segments: [{{line: 40}}]
speed_limits:
  - {{id: slow, lane: fwd, s: {sign}, value: 8.0}}
stop_signs:
  - {{id: stop, lane: fwd, s: {stop}}}
traffic_lights:
  - {{id: light, lane: fwd, s: {light}, cycle: {{green: 4, yellow: 2, red: 5}}}}
"""

SCENARIO = """\
kind: scenario
map: {map}
ego:
  start: {{lane: fwd, s: 2}}
  speed: 6
route:
  start: {{lane: fwd, s: 2}}
  goal: {{lane: after, s: 30}}
participants:
  - {{id: ahead, behaviour: stationary, start: {{lane: fwd, s: {ahead}}}}}
  - {{id: oncoming, behaviour: stationary, start: {{lane: back, s: 5}}}}
controller: {{r_near: 40}}
"""


def _free_map(text: str, tmp: Path) -> str:
    """The same map with every road lane written as a free-form lane (its boundaries)."""
    road_map = write(tmp, "road_only.yaml", text)
    m, diags = load_map(road_map)
    assert m is not None, diags
    from twolevel.world.lanes import build_lanes

    lanes, _, _ = build_lanes(m.spec)
    out = ["kind: map", "lanes:"]
    for ln in lanes.lanes:
        succ = ", ".join(lanes.lanes[j].id for j in ln.successors)
        out += [f"  - id: {ln.id}", f"    left_bound: {_points(ln.left_bound)}", f"    right_bound: {_points(ln.right_bound)}",
                f"    successors: [{succ}]"]
    rest = text[text.index("speed_limits:"):]
    return "\n".join(out) + "\n" + rest


segment = st.one_of(st.builds(lambda L: {"line": L}, st.floats(5, 80)),
                    st.builds(lambda r, a: {"arc": {"radius": r, "angle": a}}, st.floats(15, 120),
                              st.floats(-70, 70).filter(lambda a: abs(a) > 2)))


@settings(max_examples=15, deadline=None)
@example([{"arc": {"radius": 15.0, "angle": 69.0}}], 4.0, 3.0, 0.0, 0.0, 0)  # laterals 2e-5 m apart
@example([{"line": 18.0}, {"arc": {"radius": 15.0, "angle": 45.0}}], 3.0, 3.0, 0.0, 0.0, 0)  # s 0.02 m apart by the joint
@example([{"line": 6.5}, {"arc": {"radius": 15.0, "angle": 62.0}}, {"line": 6.5}], 3.0, 3.0, 0.0, 0.0, 0)  # d_stop: s 0.024 m apart
@example([{"arc": {"radius": 61.0, "angle": -19.5}}], 3.75, 3.0, 0.0, 0.0, 29231)  # a point 2 mm from fwd's end: 'after' in one
@example([{"arc": {"radius": 57.1, "angle": 67.9}}], 3.0, 3.0, 0.0, 0.6896860465779628, 0)  # yellow: can stop in one only
@given(st.lists(segment, min_size=1, max_size=3), st.floats(2.8, 4.0), st.floats(2.8, 4.0), st.floats(0, 1),
       st.floats(0, 1), st.integers(0, 2**31 - 1))
def test_free_form_lanes_from_road_boundaries_are_the_same_lanes(tmp_path_factory, segments, w1, w2, f1, f2, seed):
    """The same map written with road lanes and with free-form lanes (the road lanes' boundaries)
    gives the same lanes, lookups, route and signals, within sampling tolerance (chords against
    exact arc lengths, headings halfway between chords against analytic tangents)."""
    from twolevel.world.layout import lane_ends, lane_length
    from twolevel.world.schema import Road

    tmp = tmp_path_factory.mktemp("same")
    road = Road(id="road", start={"x": 5, "y": -3, "heading": 20}, segments=segments,
                lanes=[{"id": "fwd", "offset": -1.75, "width": w1}])
    end = lane_ends(road, road.lanes[0])[1]
    length = lane_length(road, -1.75)
    assume(length > 20 and all(seg["arc"]["radius"] > 1.75 + w1 + w2 for seg in segments if "arc" in seg))
    text = ROAD_MAP.format(segments=json.dumps(segments), w1=w1, w2=w2, off2=(w1 + w2) / 2 - 1.75,
                           ax=end.x, ay=end.y, ah=math.degrees(end.heading), sign=round(0.2 * length, 3),
                           stop=round(0.4 * length, 3), light=round(0.7 * length, 3))
    worlds = []
    for name, body in (("road", text), ("free", _free_map(text, tmp))):
        write(tmp, f"{name}.yaml", body)
        scn, diags = load_scenario(write(tmp, f"{name}_scn.yaml", SCENARIO.format(map=f"{name}.yaml", ahead=round(0.5 * length, 3))))
        assert scn is not None and not [d for d in diags if d.is_error], [d.message for d in diags]
        worlds.append(build_world(scn))
    road_w, free_w = worlds
    a, b = road_w.lanes, free_w.lanes
    # the lanes: same ids, lengths (chords against exact arcs), widths, boundaries, graph, adjacency
    assert [ln.id for ln in a.lanes] == [ln.id for ln in b.lanes]
    assert np.allclose(a.length, b.length, rtol=1e-4, atol=1e-6)
    assert np.allclose(a.widths, b.widths, atol=1e-9) and np.allclose(a.left_bound, b.left_bound, atol=1e-9)
    assert (a.succ == b.succ).all() and (a.pred == b.pred).all()
    assert (a.adj_left == b.adj_left).all() and (a.adj_left_same == b.adj_left_same).all()
    # projection of points near the lanes
    rng = np.random.default_rng(seed)
    lane = rng.integers(0, 2, 200)
    s = rng.uniform(0, 1, 200) * a.length[lane]
    pts, _ = a.pose(lane, s, rng.uniform(-1.2, 1.2, 200))
    la, sa, ea = a.lookup(pts)
    lb, sb, eb = b.lookup(pts)
    # a point within the tolerance of a lane's end is as much at its successor's start: either
    # lane is the right answer there (the two maps end their lanes 2e-4·L apart)
    at = 1e-3 + 2e-4 * a.length[la]

    def joint(l1: np.ndarray, s1: np.ndarray, l2: np.ndarray, s2: np.ndarray) -> np.ndarray:
        follows = np.array([j in a.lanes[i].successors for i, j in zip(l1, l2)], dtype=bool)
        return follows & (s1 >= a.length[l1] - at) & (s2 <= at)

    same = la == lb
    assert (same | joint(la, sa, lb, sb) | joint(lb, sb, la, sa)).all()
    # laterals: the free lane's centre is the mean of sampled boundaries, the road lane's the exact
    # offset curve; on a tight arc near a sample boundary they differ by a few 1e-5 m
    assert np.allclose(sa[same], sb[same], atol=1e-3 + 2e-4 * sa[same]) and np.allclose(ea, eb, atol=1e-4)
    assert np.allclose(a.width_at(lane, s), b.width_at(lane, s * b.length[lane] / a.length[lane]), atol=1e-6)
    # the route and what it carries
    ra, rb = road_w.route, free_w.route
    assert abs(ra.length - rb.length) <= 2e-4 * ra.length
    n = min(len(ra.s), len(rb.s))
    assert np.allclose(ra.points[:n], rb.points[:n], atol=0.01 + 2e-4 * ra.length)
    assert np.allclose(ra.width, rb.width[: len(ra.width)] if len(rb.width) >= len(ra.width) else ra.width, atol=1e-6)
    assert np.allclose(road_w.route_stops, free_w.route_stops, atol=2e-4 * ra.length)
    assert np.allclose(road_w.route_lights, free_w.route_lights, atol=2e-4 * ra.length)
    # every signal along a drive that weaves about the route, past the stopped car's lane
    T = 120
    u = np.linspace(0, 1, T)
    xy = ra.position(u * ra.length, 0.8 * np.sin(7 * u * (1 + f1)))
    ego = {"x": xy[:, 0], "y": xy[:, 1], "psi": ra.heading_at(u * ra.length), "v": 8.0 * (1 - u) * (0.5 + f2)}
    tr = [TrafficLog.of([w.traffic0] * T, w.parts.length, w.parts.width) for w in worlds]
    sa_, sb_ = signals_along(road_w, tr[0], ego), signals_along(free_w, tr[1], ego)
    # the two polylines place their vertices differently about a line-arc joint: a point 0.7 m off
    # the centre there projects up to 2 cm apart along the route (tight arc, r = 15 m)
    # a distance along the route (d_stop, d_light, d_lead, rss_gap) is a position on the route (stop
    # line, light, car: within 2e-4·L of each other, as asserted above) less the ego's (within
    # tol["s"]): its tolerance is their sum
    at = 2e-4 * ra.length
    tol = {"min_gap": 0.03 + 4e-4 * ra.length, "s": 0.03 + at, "e": 1e-3, "over_centre": 1e-3}  # e plus the line's offset
    tol.update(dict.fromkeys(("d_stop", "d_light", "d_lead", "rss_gap"), tol["s"] + at + 1e-6))
    # a flag or distance that switches where the ego is at a given distance to a stop line or light
    # (its line, the sensing radius, PASS_MARGIN past it, the yellow light's stopping distance) may
    # switch one sample apart in the two worlds: it is compared where both are farther than the
    # tolerance from every such distance
    r_near, v = road_w.settings.r_near, ego["v"]
    switches = {"light": (road_w.route_lights, free_w.route_lights,
                          [0.0, r_near, -PASS_MARGIN, v**2 / (2 * road_w.settings.yellow_decel)]),
                "stop": (road_w.route_stops, free_w.route_stops, [0.0, r_near, -PASS_MARGIN, STOP_ZONE])}
    away = {}
    for what, (line_a, line_b, marks) in switches.items():
        d = np.stack([line_a[:, None] - sa_["s"][None], line_b[:, None] - sb_["s"][None]])  # (2, lines, T)
        gaps = [np.abs(d - np.broadcast_to(m, d.shape[-1:])) for m in marks]
        away[what] = np.all([(g > tol["d_light"]).all(axis=(0, 1)) for g in gaps], axis=0)
    only = {"light_red": away["light"], "d_light": away["light"], "d_stop": away["stop"]}
    for name in sa_:
        x, y = sa_[name], sb_[name]
        if name in only:
            x, y = x[only[name]], y[only[name]]
        both_inf = np.isinf(x) & np.isinf(y) & (np.sign(x) == np.sign(y))
        x, y = np.where(both_inf, 0.0, x), np.where(both_inf, 0.0, y)
        assert np.all(both_inf | (np.abs(x - y) <= tol.get(name, 1e-6))), name


def test_centre_lines_of_an_evenly_sampled_circle_are_its_tangents():
    theta = np.linspace(0.3, 2.0, 50)
    pts = np.stack([20 * np.cos(theta), 20 * np.sin(theta)], axis=1)
    heading, s, kappa = centre_lines(np.concatenate([pts, pts[::-1]]), np.array([50, 50]))
    inner = slice(1, 49)
    assert np.allclose(heading[inner], theta[inner] + math.pi / 2, atol=1e-12)
    assert np.allclose(kappa[1:48], 1 / 20, rtol=1e-3)
    assert np.allclose(heading[51:99] - heading[51], theta[::-1][1:49] - theta[::-1][1], atol=1e-12)  # clockwise
    assert s[49] == pytest.approx(s[99]) and kappa[49] == 0.0  # lines start over at 0; no curvature between them


def test_free_form_example_map_adjacency_markings_and_kinds():
    w = load_world(ROOT / "examples" / "world" / "free_form.yaml")
    ls = w.lanes
    i = dict(ls.index)
    assert ls.left[i["right"]] == i["left"] and ls.right[i["left"]] == i["right"]  # found from the shared boundary
    assert ls.adj_right[i["right"]] == i["bus"] and ls.right[i["right"]] == i["bus"]
    assert ls.left[i["right_next"]] == i["left_next"] and ls.right[i["left_next"]] == i["right_next"]  # declared, mirrored
    assert list(ls.pred[ls.pred_ptr[i["right_next"]]:ls.pred_ptr[i["right_next"] + 1]]) == [i["right"]]
    assert not ls.usable[i["bus"]] and ls.usable[i["right"]]
    # markings: the right lane's dashed left line is the left lane's right line; its solid right line the bus lane's left
    mk = ls.markings
    assert MARKINGS[mk.at(i["left"], 50.0, False)] == "dashed"
    assert MARKINGS[mk.at(i["bus"], 50.0, True)] == "solid"
    assert MARKINGS[mk.at(i["bus"], 50.0, False)] == "curb"
    # the right lane widens 3.0 -> 3.75 m and the route follows it
    assert ls.width_at(np.array([i["right"]] * 2), np.array([0.0, ls.length[i["right"]]])) == pytest.approx([3.0, 3.75], abs=0.01)
    assert w.route.width[0] == pytest.approx(3.0 + 0.75 * 5 / 120, abs=0.01) and w.route.width[-1] == pytest.approx(3.75)


FREE = """\
kind: map
lanes:
  - id: a
    left_bound: [[0, 3.5], [50, 3.5], [100, 3.5]]
    right_bound: [[0, 0], [50, 0], [100, 0]]
    successors: [b]
  - id: b
    centre: [[100, 1.75], [150, 1.75]]
    width: 3.5
"""


@pytest.mark.parametrize("old, new, code, line, words", [
    ("right_bound: [[0, 0], [50, 0], [100, 0]]", "right_bound: [[0, 0], [100, 0]]", "YML420", 5, "paired point by point"),
    ("left_bound: [[0, 3.5], [50, 3.5], [100, 3.5]]", "left_bound: [[0, 3.5], [50, -1], [100, 3.5]]", "YML420", 4, "boundaries cross"),
    ("left_bound: [[0, 3.5], [50, 3.5], [100, 3.5]]", "left_bound: [[0, 3.5], [50, 0.05], [100, 3.5]]", "YML420", 5, "wide here"),
    ("[50, 3.5], [100, 3.5]]\n    right_bound: [[0, 0], [50, 0]", "[0, 3.5], [100, 3.5]]\n    right_bound: [[0, 0], [0, 0]", "YML420", 4,
     "at least 0.01 m apart"),
    ("centre: [[100, 1.75], [150, 1.75]]", "centre: [[110, 1.75], [150, 1.75]]", "YML420", 6, "does not follow"),
    ("    width: 3.5\n", "    widths: [3.5, 3.5, 3.5]\n", "YML420", 9, "widths for 2 centre points"),
    ("    width: 3.5\n", "", "YML415", 7, "needs its 'width'"),
    ("    successors: [b]\n", "    successors: [c]\n", "YML416", 6, "no lane 'c'"),
    ("    successors: [b]\n", "    successors: [b]\n    adjacent_left: b\n", "YML420", 7, "no boundary within"),
    ("    width: 3.5\n", "    width: 3.5\n    type: lorry\n", "YML415", 10, "must be 'driving'"),
    ("    width: 3.5\n", "    width: .inf\n", "YML414", 9, "finite"),
    ("centre: [[100, 1.75], [150, 1.75]]", "centre: [[100, 1.75], [101, 1.75], [101, 40]]", "YML420", 8, "folds"),
])
def test_malformed_free_form_lanes_are_reported_at_their_line(tmp_path, old, new, code, line, words):
    assert old in FREE
    m, diags = load_map(write(tmp_path, "map.yaml", FREE.replace(old, new, 1)))
    errors = [(d.code, d.span.line) for d in diags if d.is_error]
    assert m is None and errors[0] == (code, line), [(d.code, d.span.line, d.message) for d in diags]
    assert words in diags[0].message + (diags[0].hint or "")


def test_markings_and_zones_are_checked_against_their_lanes(tmp_path):
    text = FREE + "markings:\n  - {lane: a, side: left, type: solid, s_range: [120, 130]}\n" \
                  "no_overtaking:\n  - {lane: zz, s_range: [0, 10]}\n"
    m, diags = load_map(write(tmp_path, "map.yaml", text))
    assert m is None and [(d.code, d.span.line) for d in diags] == [("YML420", 11), ("YML416", 13)]


def test_a_map_of_free_form_lanes_only_checks_clean_and_a_map_needs_some_lane(tmp_path):
    m, diags = load_map(write(tmp_path, "map.yaml", FREE))
    assert m is not None and diags == []
    m, diags = load_map(write(tmp_path, "empty.yaml", "kind: map\nname: nothing\n"))
    assert m is None and diags[0].code == "YML415" and "at least one" in diags[0].message
