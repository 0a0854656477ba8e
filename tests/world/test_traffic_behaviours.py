"""Traffic that behaves like traffic, on small real maps: MOBIL lane changes (passing, safe gaps,
RSS to the ego), lane changes others see while they happen, the IDM braking cap, the ego as a
leader on every lane its body reaches and as a merging car others let in, parked cars that are
in the way only when they are, and kinds of road user wired to the safety layer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.safety import context
from twolevel.world.assumptions import CYCLIST, PEDESTRIAN, VEHICLE
from twolevel.world.traffic import EgoBox
from twolevel.world.traffic.lanechange import KEEP_RIGHT

from helpers.traffic_worlds import ONE_LANE, TWO_LANES, run, world

R, L = 0, 1  # lane indices of TWO_LANES
DT = 0.1


def _accel(states: list, i: int) -> np.ndarray:
    """Participant i's acceleration over each step [m/s²], from its speeds."""
    v = np.array([st.v[i] for st in states])
    return np.diff(v) / DT


def test_mobil_passes_a_slow_vehicle_and_keeps_right_again(tmp_path: Path) -> None:
    w = world(tmp_path, TWO_LANES, "participants:\n"
              "  - {id: slow, start: {lane: r, s: 200}, speed: 10, idm: {v0: 10}}\n"
              "  - {id: fast, start: {lane: r, s: 100}, speed: 25, idm: {v0: 25}, mobil: true}\n")
    states = run(w, 40.0)
    lane = np.array([st.lane[1] for st in states])
    y = np.array([st.y[1] for st in states])
    assert all(st.lane[0] == R for st in states)  # the slow one has no lane changes
    assert (lane == L).any() and lane[-1] == R and abs(states[-1].lateral[1]) < 1e-9  # out and back
    assert states[-1].s[1] > states[-1].s[0] + 50  # it passed
    # sideways over seconds, not in a jump: at most the minimum-jerk profile's peak lateral speed
    peak = 1.875 * 3.5 / 4.0
    assert np.abs(np.diff(y)).max() <= peak * DT * 1.01
    assert ((y > 0.05) & (y < 3.45)).sum() * DT >= 2 * (4.0 - 1.0)  # two changes of 4 s each
    # never overlapping the slow car
    side_by_side = np.abs(y - np.array([st.y[0] for st in states])) < 1.8
    dx = np.abs(np.array([st.x[1] - st.x[0] for st in states]))
    assert dx[side_by_side].min() > 4.22


def test_mobil_waits_for_a_safe_gap(tmp_path: Path) -> None:
    w = world(tmp_path, TWO_LANES, "participants:\n"
              "  - {id: slow, start: {lane: r, s: 150}, speed: 10, idm: {v0: 10}}\n"
              "  - {id: stuck, start: {lane: r, s: 120}, speed: 10, idm: {v0: 25}, mobil: true}\n"
              "  - {id: coming, start: {lane: l, s: 100}, speed: 25, idm: {v0: 25}}\n")
    states = run(w, 30.0)
    lane = np.array([st.lane[1] for st in states])
    first = int(np.argmax(lane == L))
    assert (lane == L).any()
    # it changed only once the car coming up the left lane had passed it ...
    assert states[first].s[2] > states[first].s[1]
    # ... so that car never had to brake harder than b_safe for it
    assert _accel(states, 2).min() >= -4.0 - 1e-9


def test_mobil_leaves_the_ego_rss_distance(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """IDM alone would let the driver change in front of the ego (the ego's IDM braking stays
    above −b_safe); RSS's distance behind it does not, until the ego has gone by."""
    body = ("participants:\n"
            "  - {id: slow, start: {lane: r, s: 135}, speed: 10, idm: {v0: 10}}\n"
            "  - {id: stuck, start: {lane: r, s: 120}, speed: 10, idm: {v0: 30}, mobil: true}\n")
    ego = lambda t: EgoBox(20.0 * t, 3.5, 0.0, 20.0)  # noqa: E731  (116 m behind: RSS wants 132 m)
    states = run(world(tmp_path, TWO_LANES, body, ego_lane="l"), 20.0, ego=ego)
    lane = np.array([st.lane[1] for st in states])
    k = int(np.argmax(lane == L))
    assert (lane == L).any() and ego(k * DT).x > states[k].x[1]  # it changed once the ego had gone by
    # the same driver with IDM's safety alone (the ego braking at 0.2 m/s² for it) would change at once
    from twolevel.world.traffic import mobil
    monkeypatch.setattr(mobil, "safe_distance", lambda *_: 0.0)
    states = run(world(tmp_path, TWO_LANES, body, ego_lane="l"), 1.0, ego=ego)
    assert states[-1].lane[1] == L


@pytest.mark.parametrize("body,cap", [
    ("", 8.0),
    ("assumptions: {vehicle: {a_max: 6}}\n", 6.0),
])
def test_idm_braking_never_exceeds_the_assumed_bound(tmp_path: Path, body: str, cap: float) -> None:
    """Regression: an IDM car placed 5 m behind a standing one at 15 m/s asked for −100 m/s² and
    more; its braking is now capped at the assumptions' a_max (and then it collides)."""
    w = world(tmp_path, ONE_LANE, "participants:\n"
              "  - {id: wall, behaviour: stationary, start: {lane: road, s: 100}}\n"
              "  - {id: car, start: {lane: road, s: 90.78}, speed: 15}\n" + body, ego_lane="road")
    states = run(w, 5.0)
    a = _accel(states, 1)
    assert a.min() >= -cap - 1e-9
    assert a.min() <= -cap + 1e-9  # it does brake at the cap
    assert np.all(np.array([st.memory.accel[1] for st in states[1:]]) >= -cap - 1e-9)


def test_a_cyclist_keeps_right_and_brakes_within_its_own_bound(tmp_path: Path) -> None:
    w = world(tmp_path, ONE_LANE, "participants:\n"
              "  - {id: wall, behaviour: stationary, start: {lane: road, s: 100}}\n"
              "  - {id: bike, kind: bicycle, start: {lane: road, s: 93}, speed: 8}\n", ego_lane="road")
    states = run(w, 5.0)
    assert w.parts.user[1] == CYCLIST and w.parts.length[1] == 1.8
    assert states[0].lateral[1] == pytest.approx(-(3.5 / 2 - 0.65 / 2 - KEEP_RIGHT))
    assert _accel(states, 1).min() >= -6.0 - 1e-9  # a cyclist's assumed a_max


def test_a_lane_change_is_seen_by_both_lanes_while_it_happens(tmp_path: Path) -> None:
    w = world(tmp_path, TWO_LANES, "participants:\n"
              "  - id: changer\n"
              "    start: {lane: l, s: 100}\n"
              "    speed: 15\n"
              "    manoeuvres: [{lane_change: right, duration: 4}]\n"
              "  - {id: behind_r, start: {lane: r, s: 72}, speed: 15, idm: {v0: 15}}\n"
              "  - {id: behind_l, start: {lane: l, s: 85}, speed: 15, idm: {v0: 25}}\n")
    states = run(w, 8.0)
    a_r, a_l = _accel(states, 1), _accel(states, 2)
    steps = int(4.0 / DT)
    assert a_r[: steps - 5].min() < -0.1  # the lane it moves into brakes for it before it has arrived
    assert a_l[5] < 0  # the lane it leaves still follows it ...
    assert a_l[-1] > 0  # ... and speeds up once it has gone
    psi = np.array([st.psi[0] for st in states[1:steps]])
    assert psi.min() < -0.05  # its heading shows the move (what the ego senses and predicts from)


def test_the_ego_leads_on_the_lane_its_body_reaches_into(tmp_path: Path) -> None:
    """The ego stands across the lane line (its centre in lane l, 0.8 m of its body in lane r):
    a car on lane r stops behind it."""
    w = world(tmp_path, TWO_LANES, "participants:\n  - {id: car, start: {lane: r, s: 200}, speed: 15}\n")
    states = run(w, 40.0, ego=EgoBox(300.0, 2.0, 0.0, 0.0))
    gap = np.array([300.0 - 2.11 - (st.s[0] + 2.11) for st in states])
    assert gap.min() > 0.5 and states[-1].v[0] < 0.05


def test_regression_the_ego_at_an_angle_across_the_lane_line_is_in_the_way(tmp_path: Path) -> None:
    """The ego stands turned 0.29 rad towards lane r with its centre 0.44 m inside lane l (a merge
    the safety layer stopped half-way): its centre and half width alone leave 2.19 − 0.9 = 1.29 m
    beside it, enough for a car on lane r to pass, but its turned box reaches 0.73 m into lane r.
    The car on lane r used to drive into it; it stops behind it."""
    w = world(tmp_path, TWO_LANES, "participants:\n  - {id: car, start: {lane: r, s: 200}, speed: 15}\n")
    states = run(w, 40.0, ego=EgoBox(300.0, 2.19, -0.289, 0.0))
    rear = 300.0 - (2.11 * np.cos(0.289) + 0.9 * np.sin(0.289))  # the turned box's rearmost point
    front = np.array([st.s[0] + 2.11 for st in states])
    assert front.max() < rear and states[-1].v[0] < 0.05


@pytest.mark.parametrize("route,psi,behind,yields", [
    (True, 0.0, 75.0, True),     # its route continues on lane l: it has to get over (indicator on)
    (False, 0.06, 75.0, True),   # drifting towards lane l at 0.9 m/s
    (False, 0.0, 75.0, False),   # neither: nobody slows down for it
    (True, 0.0, 93.0, False),    # too close behind: letting it in would take more than p · b_safe
])
def test_vehicles_behind_open_a_gap_for_a_merging_ego(tmp_path: Path, route: bool, psi: float, behind: float,
                                                       yields: bool) -> None:
    w = world(tmp_path, TWO_LANES, f"participants:\n  - {{id: car, start: {{lane: l, s: {behind}}}, speed: 15, "
                                   "idm: {v0: 20}}\n")
    lanes = (L,) if route else ()
    states = run(w, 1.0, ego=lambda t: EgoBox(100.0 + 15.0 * t, 0.0, psi, 15.0, route=lanes))
    a = _accel(states, 0)
    if yields:
        assert a.max() < 0 and a.min() >= -0.5 * 4.0 - 1e-9  # brakes, within politeness · b_safe
    else:
        assert a.min() > 0  # keeps its own pace


MERGE = (Path(__file__).resolve().parents[2] / "maps" / "merge.yaml").read_text()


@pytest.mark.parametrize("to_end,joins,v,back,yields", [
    (30.0, True, 10.0, 40.0, True),    # 30 m before the ramp's end, its route joining main_b: others let it in
    (30.0, False, 10.0, 40.0, False),  # a route that does not join: nobody slows down for it
    (90.0, True, 10.0, 40.0, False),   # still far from the merge
    (30.0, True, 1.0, 100.0, False),   # crawling at the ramp's end: it waits for a gap, nobody stops for it
    (30.0, True, 2.5, 100.0, True),    # (the car 100 m back would brake gently for it if it moved)
])
def test_vehicles_on_the_main_road_let_a_merging_ego_in_at_a_lane_end(tmp_path: Path, to_end: float, joins: bool,
                                                                      v: float, back: float, yields: bool) -> None:
    """The ramp ends into main_b, as main_a does: a car on main_a ``back`` metres further from the
    merge than the ego treats it as a leader that far ahead of it, within its politeness."""
    w = world(tmp_path, MERGE, "", ego_lane="ramp", goal=100)
    idx = {ln.id: k for k, ln in enumerate(w.lanes.lanes)}
    ramp, main_a = idx["ramp"], idx["main_a"]
    s_car = float(w.lanes.length[main_a]) - to_end - back
    w = world(tmp_path, MERGE, f"participants:\n  - {{id: car, start: {{lane: main_a, s: {s_car}}}, speed: 12, "
                               "idm: {v0: 12}}\n", ego_lane="ramp", goal=100)
    s_ego = float(w.lanes.length[ramp]) - to_end
    p, h = w.lanes.pose(np.array([ramp]), np.array([s_ego]))
    route = (ramp, idx["main_b"]) if joins else (ramp,)
    states = run(w, 1.0, ego=EgoBox(float(p[0, 0]), float(p[0, 1]), float(h[0]), v, route=route))
    a = _accel(states, 0)
    if yields:
        assert a.max() < 0 and a.min() >= -0.5 * 4.0 - 1e-9  # brakes, within politeness · b_safe
    else:
        assert a.min() >= 0  # keeps its own pace


def test_a_parked_car_on_the_kerb_is_not_in_the_way(tmp_path: Path) -> None:
    w = world(tmp_path, ONE_LANE, "participants:\n"
              "  - {id: kerb, kind: parked, start: {lane: road, s: 150, lateral: -2.9}}\n"
              "  - {id: car, start: {lane: road, s: 50}, speed: 12, idm: {v0: 12}}\n", ego_lane="road")
    states = run(w, 20.0)
    assert min(st.v[1] for st in states) > 11.9 and states[-1].s[1] > 250
    assert w.parts.kind[0] == 0 and w.parts.user[0] == VEHICLE


def test_a_parked_car_half_in_the_lane_blocks_it_only(tmp_path: Path) -> None:
    """Half in the lane (its centre on the lane's edge) it is in everybody's way: on a single
    lane they queue behind it; with a lane beside, a MOBIL driver passes it and comes back."""
    one = world(tmp_path, ONE_LANE, "participants:\n"
                "  - {id: half, kind: parked, start: {lane: road, s: 150, lateral: -1.75}}\n"
                "  - {id: car, start: {lane: road, s: 50}, speed: 12, idm: {v0: 12}, mobil: true}\n", ego_lane="road")
    queued = run(one, 40.0)
    assert queued[-1].v[1] < 0.05 and 0.5 < 150 - queued[-1].s[1] - 4.22 < 3.0
    two = world(tmp_path, TWO_LANES, "participants:\n"
                "  - {id: half, kind: parked, start: {lane: r, s: 150, lateral: -1.75}}\n"
                "  - {id: passer, start: {lane: r, s: 50}, speed: 12, idm: {v0: 12}, mobil: true}\n"
                "  - {id: queuer, start: {lane: r, s: 10}, speed: 12, idm: {v0: 12}}\n")
    states = run(two, 60.0)
    assert states[-1].s[1] > 300 and states[-1].lane[1] == R  # passed, back in its lane
    assert states[-1].v[2] < 0.05 and states[-1].s[2] < 150  # the one without lane changes queues


def test_kinds_are_the_road_users_the_safety_layer_predicts(tmp_path: Path) -> None:
    w = world(tmp_path, TWO_LANES, "participants:\n"
              "  - {id: walker, kind: pedestrian, walk: {lane: r, s: 100}}\n"
              "  - {id: bike, kind: bicycle, start: {lane: r, s: 20}, speed: 5}\n"
              "  - {id: parked, kind: parked, start: {lane: r, s: 50, lateral: -2}}\n"
              "  - {id: car, start: {lane: l, s: 20}}\n"
              "  - {id: odd, kind: bicycle, start: {lane: l, s: 60}}\n"
              "assumptions: {road_users: {odd: pedestrian}}\n")
    assert list(w.parts.user) == [PEDESTRIAN, CYCLIST, VEHICLE, VEHICLE, PEDESTRIAN]  # road_users wins
    assert list(context(w).kinds) == list(w.parts.user)
