"""Batched sensing equals the world's signal definitions."""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.world.provided import PROVIDED_SIGNALS, SIGNALS
from twolevel.world.sensing import Memory, others_predicted, sense
from twolevel.world.signals import TrafficLog, horizon_constants, participant_signals_along, signals_along
from twolevel.world.traffic import TrafficState

from helpers.traffic_worlds import CROSSING, world
from helpers.world_files import load_world

ROOT = Path(__file__).resolve().parents[2]


def test_batched_prediction_equals_signals_along() -> None:
    w = load_world(ROOT / "scenarios" / "traffic_rules.yaml")
    rng = np.random.default_rng(0)
    K, T, dt = 6, 40, w.settings.dt
    # approach the stop sign (route s = 78) at different speeds and decelerations, slightly off-centre
    s0 = 60.0
    v0 = rng.uniform(2, 9, K)
    acc = rng.uniform(-3, 0.5, K)
    tk = dt * np.arange(T)
    v = np.maximum(v0[:, None] + acc[:, None] * tk[None], 0.0)
    s = s0 + np.cumsum(np.concatenate([np.zeros((K, 1)), v[:, :-1] * dt], axis=1), axis=1)
    lat = rng.uniform(-0.4, 0.4, (K, 1)) * np.ones((1, T))
    pts = w.route.position(s, lat)
    psi = w.route.heading_at(s)
    # a vehicle ahead in the ego's lane and one oncoming, at constant velocity
    p0, h0 = w.lanes.pose(np.array([0, 1]), np.array([s0 + 2 + 9.0, 200.0]))
    traffic = TrafficState(0.0, p0[:, 0], p0[:, 1], h0, np.array([3.0, 5.0]),
                           np.array([0, 1]), np.array([s0 + 11.0, 200.0]), np.zeros(2), np.ones(2, bool), np.zeros(2),
                           np.full(2, -1))
    parts_len = np.full(2, 4.22)
    others = others_predicted(w, traffic, float(pts[0, 0, 0]), float(pts[0, 0, 1]), s0, T - 1, dt)
    t0 = 3.0
    got = sense(w, t0, dt, Memory.fresh(w), others, pts[..., 0], pts[..., 1], psi, v, np.zeros((K, T)),
                np.zeros((K, T)))
    for k in range(K):
        log = TrafficLog(others.x.T, others.y.T, others.psi.T, others.v.T, np.ones((T, others.n), bool),
                         parts_len[: others.n], np.full(others.n, 1.8))
        ref = signals_along(w, log, {"x": pts[k, :, 0], "y": pts[k, :, 1], "psi": psi[k], "v": v[k]}, t0=t0)
        for name in SIGNALS:
            np.testing.assert_allclose(got[name][k], ref[name], rtol=0, atol=1e-6, err_msg=f"{name} row {k}")
    assert set(got) == set(SIGNALS)  # the on-demand signals only where a rule reads them (none here)
    assert np.isfinite(got["d_stop"]).any() and np.isfinite(got["d_lead"]).any()


@functools.lru_cache(maxsize=1)
def _curved_world():
    parts = ", ".join(f"{{id: c{i}, behaviour: constant_velocity, start: {{lane: east, s: {10 * i}}}, speed: 5}}"
                      for i in range(6))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "curved.yaml"
        path.write_text(f"kind: scenario\nname: curved\nmap: {ROOT / 'maps' / 'curved_road.yaml'}\n"
                        "ego: {start: {lane: east, s: 0}, speed: 5}\n"
                        "route: {start: {lane: east, s: 0}, goal: {lane: east, s: 270}}\n"
                        f"participants: [{parts}]\nrun: {{duration: 10, seed: 0}}\n")
        return load_world(path)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 1), st.floats(0, 260), st.floats(0, 15), st.floats(-0.6, 0.6)),
                min_size=1, max_size=6), st.floats(0, 260))
def test_predicted_vehicles_project_as_the_whole_route_search(cars, ego_s) -> None:
    # others_predicted searches each predicted sample only near where the vehicle's motion along
    # the route puts it; on the curved road (50 m and 40 m bends, vehicles off their lane's
    # heading) that must give the nearest route point as the search over the whole route does
    w = _curved_world()
    lane = np.array([c[0] for c in cars])
    s_lane = np.array([c[1] for c in cars])
    p0, h0 = w.lanes.pose(lane, s_lane)
    n = len(cars)
    traffic = TrafficState(0.0, p0[:, 0], p0[:, 1], h0 + np.array([c[3] for c in cars]), np.array([c[2] for c in cars]),
                           lane, s_lane, np.zeros(n), np.ones(n, bool), np.zeros(n), np.full(n, -1))
    ego = w.route.position(np.array([ego_s]))[0]
    got = others_predicted(w, traffic, float(ego[0]), float(ego[1]), ego_s, 10, 0.1)
    if got.n == 0:
        return
    s, e = w.route.local_coordinates(np.stack([got.x.ravel(), got.y.ravel()], axis=1))
    near = np.abs(e) < 10.0  # points far off the road may have two nearest route points
    np.testing.assert_allclose(got.s.ravel()[near], s[near], atol=1e-6)
    np.testing.assert_allclose(got.e.ravel()[near], e[near], atol=1e-6)


PARTICIPANT_RULES = """\
input float v
uses_all = forall o in vehicles: ((precedes(o) > 0 or cut_in(o) > 0) -> (d_lon(o) >= v - v(o) + a(o)
           and abs(d_lat(o)) >= 0 and in_same_lane(o) <= 10));
"""


@functools.lru_cache(maxsize=1)
def _highway_world():
    tmp = Path(tempfile.mkdtemp())
    (tmp / "rules.stl").write_text(PARTICIPANT_RULES)
    parts = ", ".join(f"{{id: car{i}, behaviour: constant_velocity, start: {{lane: middle, s: {100 + 10 * i}}}}}"
                      for i in range(6))
    (tmp / "s.yaml").write_text(f"kind: scenario\nname: hw\nmap: {ROOT / 'maps' / 'highway.yaml'}\n"
                                "ego: {start: {lane: middle, s: 20}, speed: 10}\n"
                                "route: {start: {lane: middle, s: 20}, goal: {lane: middle, s: 600}}\n"
                                f"participants: [{parts}]\nrules: [rules.stl]\ncontroller: {{r_near: 40}}\n"
                                "run: {duration: 10, seed: 0}\n")
    return load_world(tmp / "s.yaml")


def test_batched_participant_signals_equal_the_reference() -> None:
    """Participant signals over K candidates (sense) equal participant_signals_along row by row:
    a car ahead in the lane, one cutting in from the left, one behind, one ahead on the right
    lane, one beyond r_near and one braking; the candidates drift across the lane boundary."""
    w = _highway_world()
    assert w.participant_signals == ("present", "v", "a", "d_lon", "d_lat", "in_same_lane", "cut_in", "precedes")
    rng = np.random.default_rng(1)
    K, T, dt, s0 = 5, 30, w.settings.dt, 100.0
    v = np.full((K, T), 12.0)
    s = s0 + 12.0 * dt * np.arange(T)[None] * np.ones((K, 1))
    lat = rng.uniform(-0.2, 0.2, (K, 1)) + np.linspace(0, 1, T)[None] * rng.uniform(0, 2.5, (K, 1))
    pts = w.route.position(s, lat)
    psi = w.route.heading_at(s) + 0.05
    lane = np.array([1, 2, 1, 0, 1, 1])  # right 0, middle 1, left 2
    s_o = np.array([s0 + 25, s0 + 12, s0 - 15, s0 + 8, s0 + 90, s0 + 40])
    p0, h0 = w.lanes.pose(lane, s_o, np.array([0, -1.0, 0, 0, 0, 0]))
    h0 = h0 + np.array([0, -0.15, 0, 0, 0, 0])
    traffic = TrafficState(0.0, p0[:, 0], p0[:, 1], h0, np.array([8.0, 13.0, 12.0, 14.0, 10.0, 6.0]), lane, s_o,
                           np.zeros(6), np.ones(6, bool), np.zeros(6), np.full(6, -1))
    others = others_predicted(w, traffic, float(pts[0, 0, 0]), float(pts[0, 0, 1]), s0, T - 1, dt)
    got = sense(w, 0.0, dt, Memory.fresh(w), others, pts[..., 0], pts[..., 1], psi, v, np.zeros((K, T)),
                np.zeros((K, T)))
    ids = [w.parts.ids[i] for i in others.index]
    assert "car4" in ids  # sensed (within the sensing range) but beyond r_near = 40 m: never present
    for k in range(K):
        log = TrafficLog(others.x.T, others.y.T, others.psi.T, others.v.T, np.ones((T, others.n), bool),
                         w.parts.length[others.index], w.parts.width[others.index])
        ref = participant_signals_along(w, log, {"x": pts[k, :, 0], "y": pts[k, :, 1], "psi": psi[k]}, ids=ids,
                                        names=w.participant_signals)
        for key, want in ref.items():
            np.testing.assert_allclose(got[key][k], want, rtol=0, atol=1e-6, err_msg=f"{key} row {k}")
    assert set(got) - PROVIDED_SIGNALS == set(ref)
    # the cases are there: a car cuts in, one precedes, one is in the same lane, one is behind
    assert (got["cut_in[car1]"] > 0).any() and (got["precedes[car0]"] > 0).any()
    assert (got["in_same_lane[car3]"] < 0).all() and (got["in_same_lane[car1]"] > 0).any()
    assert (got["d_lon[car2]"] < 0).all() and (got["present[car2]"] == np.inf).any()
    assert (got["present[car4]"] == -np.inf).all() and (got["d_lon[car4]"] == np.inf).all()


@pytest.mark.parametrize("psi,leads", [
    (np.pi / 2, False),  # crossing at right angles (cos 90° = 6e−17 counted as "ahead" before the fix)
    (np.pi / 2 - 0.3, False),  # turning across
    (0.3, True),  # changing lanes in front: still the car ahead
    (0.0, True),
])
def test_regression_a_vehicle_crossing_at_right_angles_is_no_car_ahead(tmp_path: Path, psi: float,
                                                                       leads: bool) -> None:
    """A vehicle in the middle of the ego's lane 15 m ahead, heading ``psi`` against the ego's
    heading 0: d_lead (monitors, batched sensing, the MPC's horizon constants) counts it only
    when it travels the ego's way (within LEAD_HEADING)."""
    w = world(tmp_path, CROSSING, "participants: [{id: car, behaviour: stationary, start: {lane: n, s: 10}}]\n"
              "controller: {r_near: 40}\n", ego_lane="e", goal=290)
    ego_x, car_x, y = 120.0, 135.0, -1.75
    traffic = TrafficState(0.0, np.array([car_x]), np.array([y]), np.array([psi]), np.array([5.0]), np.array([-1]),
                           np.zeros(1), np.zeros(1), np.ones(1, bool), np.zeros(1), np.full(1, -1))
    gap = car_x - ego_x - 4.22
    log = TrafficLog(traffic.x[None], traffic.y[None], traffic.psi[None], traffic.v[None], np.ones((1, 1), bool),
                     w.parts.length, w.parts.width)
    ego = {"x": np.array([ego_x]), "y": np.array([y]), "psi": np.zeros(1), "v": np.array([10.0])}
    ref = signals_along(w, log, ego)
    s0 = float(ref["s"][0])
    others = others_predicted(w, traffic, ego_x, y, s0, 3, 0.1)
    got = sense(w, 0.0, 0.1, Memory.fresh(w), others, np.full((1, 4), ego_x), np.full((1, 4), y), np.zeros((1, 4)),
                np.full((1, 4), 10.0), np.zeros((1, 4)), np.zeros((1, 4)))
    hc = horizon_constants(w, traffic, 0.0, (ego_x, y, 0.0, 10.0))
    if leads:
        assert ref["d_lead"][0] == pytest.approx(gap) and got["d_lead"][0, 0] == pytest.approx(gap)
        assert hc.lead == 0
    else:
        assert np.isinf(ref["d_lead"][0]) and np.isinf(got["d_lead"][0, 0]) and hc.lead == -1
        assert ref["v_lead"][0] == 10.0
    assert 0 < ref["min_gap"][0] <= car_x - ego_x - 2.11  # seen all the same: no_collision and min_gap keep it
