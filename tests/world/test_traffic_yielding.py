"""Giving way, on small real maps: at a stop sign to crossing priority traffic (the ego
included), with conflicts found from the lanes' geometry; pedestrians who cross at a crosswalk
and wait for a gap, or step out without looking, and vehicles that stop for them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from twolevel.world.traffic import EgoBox
from twolevel.world.traffic.junctions import ZONE

from helpers.traffic_worlds import CROSSING, TWO_LANES, run, world

DT = 0.1
CONFLICT_X = 151.75  # where lane n (x = 151.75) crosses lane e (y = -1.75): s = 151.75 on e
CONFLICT_N = 148.25  # the same point on lane n (which starts at y = -150)


def test_stop_lines_find_the_lanes_they_cross(tmp_path: Path) -> None:
    w = world(tmp_path, CROSSING, "", ego_lane="e", goal=290)
    c = w.stops.conflicts
    crossed = {w.lanes.lanes[k].id: (s, path) for k, s, path in zip(c.lane, c.s, c.path)}
    assert set(crossed) == {"e", "w"}  # not lane s beside it, not lane n itself
    assert crossed["e"][0] == np.float64(CONFLICT_X) or abs(crossed["e"][0] - CONFLICT_X) < 1e-6
    assert abs(crossed["e"][1] - 3.25) < 1e-6 and abs(crossed["w"][1] - 6.75) < 1e-6  # metres past the line


def _minor_and_major(tmp: Path, major: str, ego_lane: str = "e") -> tuple:
    w = world(tmp, CROSSING, "participants:\n  - {id: minor, start: {lane: n, s: 120}, speed: 8}\n" + major,
              ego_lane=ego_lane, goal=290)
    return w


def test_a_vehicle_yields_at_a_stop_sign_to_crossing_priority_traffic(tmp_path: Path) -> None:
    w = _minor_and_major(tmp_path, "  - {id: major, start: {lane: e, s: 20}, speed: 12, idm: {v0: 12}}\n")
    states = run(w, 25.0)
    served = np.array([st.served[0] for st in states])
    go = int(np.argmax(served == 0))
    standing = np.array([st.v[0] < 0.1 for st in states])
    assert served[-1] == 0 and standing[:go].sum() * DT > 1.0 + 1.0  # it waited longer than its stop time
    # it went only once the priority car had cleared the conflict, with a 6.5 s gap to nothing else
    assert states[go].s[1] - 2.11 > CONFLICT_X + ZONE - 0.5
    # and the two were never in the conflict at once
    in_minor = np.array([abs(st.s[0] - CONFLICT_N) < 2.11 + 1.75 for st in states])
    in_major = np.array([abs(st.s[1] - CONFLICT_X) < 2.11 + 1.75 for st in states])
    assert not (in_minor & in_major).any()
    # without priority traffic it goes when its stop time is up
    alone = run(_minor_and_major(tmp_path, ""), 25.0)
    first_stand = int(np.argmax([st.v[0] < 0.1 for st in alone]))
    go_alone = int(np.argmax([st.served[0] == 0 for st in alone]))
    assert (go_alone - first_stand) * DT < 1.5 < (go - first_stand) * DT


def test_the_ego_is_priority_traffic_at_a_stop_sign(tmp_path: Path) -> None:
    w = _minor_and_major(tmp_path, "")
    ego = lambda t: EgoBox(20.0 + 12.0 * t, -1.75, 0.0, 12.0)  # noqa: E731  (the ego on lane e)
    states = run(w, 25.0, ego=ego)
    go = int(np.argmax([st.served[0] == 0 for st in states]))
    assert ego(go * DT).x - 2.11 > CONFLICT_X  # it waited for the ego to pass


def test_pedestrians_wait_for_a_gap_then_cross_and_vehicles_stop_for_them(tmp_path: Path) -> None:
    """At a crosswalk (s = 200) a pedestrian waits for the car coming up lane r (it would arrive
    before the pedestrian were across it, plus 2 s) — that car is too close to stop comfortably,
    so it passes first —, then crosses; the next car slows down for it."""
    w = world(tmp_path, TWO_LANES, "participants:\n"
              "  - {id: ped, kind: pedestrian, walk: {lane: r, s: 200, crosswalk: true}}\n"
              "  - {id: first, start: {lane: r, s: 170}, speed: 12, idm: {v0: 12}}\n"
              "  - {id: second, start: {lane: r, s: 60}, speed: 12, idm: {v0: 12}}\n")
    states = run(w, 25.0)
    phase = np.array([st.memory.phase[0] for st in states])
    walking = int(np.argmax(phase == 2))
    assert phase[0] == 0 and phase[1] == 1 and walking > 1  # waited at the kerb
    assert states[walking].s[1] - 2.11 > 200  # the first car had gone by
    assert 0 < min(st.v[1] for st in states)  # which did not stop
    assert (phase == 3).any() and not states[-1].active[0]  # across, and gone from the scene
    # the second car, which can stop comfortably for a pedestrian at a crosswalk, slowed down
    assert min(st.v[2] for st in states) < 11.0
    # walking pace reached within the assumed acceleration of pedestrians (0.6 m/s²), never above 2 m/s
    v = np.array([st.v[0] for st in states])
    assert v.max() == 1.4 and np.abs(np.diff(v)).max() <= 0.6 * DT + 1e-12


def test_vehicles_keep_out_of_a_crossing_while_a_pedestrian_is_on_their_lane(tmp_path: Path) -> None:
    w = world(tmp_path, TWO_LANES, "participants:\n"
              "  - {id: ped, kind: pedestrian, walk: {lane: r, s: 200, gap: 0}}\n"
              "  - {id: car, start: {lane: r, s: 140}, speed: 12, idm: {v0: 12}}\n")
    states = run(w, 20.0)
    on_lane = np.array([st.active[0] and -1.75 - 0.3 <= st.y[0] <= 1.75 + 0.3 for st in states])
    front = np.array([st.s[1] + 2.11 for st in states])
    assert on_lane.any() and front[on_lane].max() < 200 - 0.3  # out of the crossing while it is on the lane
    assert min(st.v[1] for st in states) < 8.0 and states[-1].s[1] > 220  # slowed down for it, then went on


def test_a_pedestrian_steps_out_without_looking_when_its_gap_is_zero(tmp_path: Path) -> None:
    w = world(tmp_path, TWO_LANES, "participants:\n"
              "  - {id: ped, kind: pedestrian, walk: {lane: r, s: 200, gap: 0, ego_within: 40}}\n")
    states = run(w, 6.0, ego=lambda t: EgoBox(150.0 + 10.0 * t, 0.0, 0.0, 10.0))
    phase = np.array([st.memory.phase[0] for st in states])
    walking = int(np.argmax(phase == 2))
    assert 1.0 <= walking * DT <= 1.0 + 2.5 * DT  # the ego came within 40 m at 1 s: off it went
    assert states[walking].y[0] < states[-1].y[0]  # walking across, left of the lane's direction


def test_a_walk_of_a_distance_stands_at_its_end(tmp_path: Path) -> None:
    w = world(tmp_path, TWO_LANES, "participants:\n"
              "  - {id: ped, kind: pedestrian, start: {x: 100, y: -3, heading: 90}, walk: {distance: 4, gap: 0}}\n")
    states = run(w, 10.0)
    assert states[-1].active[0] and abs(states[-1].y[0] - 1.0) < 1e-3 and states[-1].v[0] == 0.0
    v = np.array([st.v[0] for st in states])
    assert np.abs(np.diff(v)).max() <= 0.6 * DT + 1e-12  # it slows to a stop within its bound


def test_regression_an_all_way_stop_lets_one_through_at_a_time(tmp_path: Path) -> None:
    """Three cars stand at the all-way stop of maps/four_way_stop.yaml (from the south and the north:
    parallel ways, no conflict; from the east: across both). The west car goes only once the others have cleared the crossing. It used to go a step
    after them: a car moving off its line at 0.1 m/s was counted 100 s away from the conflict."""
    four_way = (Path(__file__).resolve().parents[2] / "maps" / "four_way_stop.yaml").read_text()
    w = world(tmp_path, four_way, "participants:\n"
              "  - {id: north_1, start: {lane: south_in, s: 67}, speed: 8.0}\n"
              "  - {id: south_1, start: {lane: north_in, s: 63}, speed: 8.0}\n"
              "  - {id: west_1, start: {lane: east_in, s: 59}, speed: 8.0}\n", ego_lane="west_in", goal=80)
    states = run(w, 30.0)
    # the crossing is the square |x|, |y| < 3.5 at the map's centre: who has a part of its body in it
    inside = np.array([[abs(st.x[i]) < 3.5 + 2.11 and abs(st.y[i]) < 3.5 + 2.11 and st.active[i]
                        for i in range(3)] for st in states])
    assert inside[:, 0].any() and inside[:, 1].any() and inside[:, 2].any()  # everybody crossed
    assert not (inside[:, 2] & (inside[:, 0] | inside[:, 1])).any()  # west never with the others
    served = np.array([[st.served[i] >= 0 for i in range(3)] for st in states])
    assert served.all(axis=1)[-1] and int(np.argmax(served[:, 2])) > int(np.argmax(inside[:, 0])) + 10
