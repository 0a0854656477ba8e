"""How both levels predict the other participants (twolevel/world/motion.py): lane followers at
constant velocity relative to their lane, through bends; the straight line where the lane is
straight and for participants off the lanes."""

from __future__ import annotations

import functools
from dataclasses import replace
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.world.motion import predicted_poses
from twolevel.world.sensing import Memory, others_predicted, sense
from twolevel.world.signals import horizon_constants
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

from helpers.world_files import load_world

ROOT = Path(__file__).resolve().parents[2]
D_SAFE = 1.0  # safe_distance.stl's clearance [m]


@functools.lru_cache(maxsize=1)
def _curvy() -> World:
    """curvy_road: lanes 'fwd' and 'back' (3.5 m) through S-bends of 35 m and 30 m radius, four
    IDM participants."""
    return load_world(ROOT / "scenarios" / "everyday" / "curvy_road.yaml")


def _traffic(w: World, lane: np.ndarray, s: np.ndarray, lateral: np.ndarray, v: np.ndarray,
             turn: np.ndarray | float = 0.0, on_lane: bool = True) -> TrafficState:
    """Every participant of ``w`` at (lane, s, lateral) [m] with speed ``v`` [m/s], heading the
    lane's plus ``turn`` [rad]; ``on_lane`` False: the same poses, tracked by no lane."""
    p, h = w.lanes.pose(lane, s, lateral)
    n = len(lane)
    return TrafficState(0.0, p[:, 0], p[:, 1], h + turn, np.asarray(v, float), lane if on_lane else np.full(n, -1),
                        s, lateral, np.ones(n, bool), np.zeros(n), np.full(n, -1))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 1), st.floats(0, 270), st.floats(0, 15), st.floats(-0.5, 0.5)),
                min_size=4, max_size=4))
def test_a_lane_follower_keeps_its_lane_through_the_bends(cars) -> None:  # noqa: ANN001
    """Over 3 s each car advances v·t along its own lane at its lateral offset (within 5 cm),
    heading along the lane — where its tangent leaves the lane of a 30 m bend by metres."""
    w = _curvy()
    lane = np.array([c[0] for c in cars])
    s, v, lat = (np.array([c[k] for c in cars]) for k in (1, 2, 3))
    tr = _traffic(w, lane, s, lat, v)
    tau = np.linspace(0.0, 3.0, 31)
    x, y, psi = predicted_poses(w, tr, np.arange(4), tau)
    for i in range(4):
        s_got, lat_got = w.lanes.project(np.full(len(tau), lane[i]), np.stack([x[i], y[i]], axis=1))
        np.testing.assert_allclose(s_got, s[i] + v[i] * tau, atol=0.05)
        np.testing.assert_allclose(lat_got, lat[i], atol=0.05)
        _, h = w.lanes.pose(np.full(len(tau), lane[i]), s[i] + v[i] * tau)
        np.testing.assert_allclose(psi[i], h, atol=1e-9)


def test_a_lane_change_in_a_bend_keeps_moving_sideways() -> None:
    """A car heading 0.1 rad left of its lane in the 30 m bend: along the lane at v·cos 0.1 and
    across it at v·sin 0.1 per second, its heading the lane's plus 0.1."""
    w = _curvy()
    lane, s, v = np.array([0, 0, 0, 0]), np.array([120.0, 130.0, 140.0, 150.0]), np.full(4, 8.0)
    tr = _traffic(w, lane, s, np.full(4, -0.4), v, turn=0.1)
    tau = np.linspace(0.0, 1.0, 11)
    x, y, psi = predicted_poses(w, tr, np.arange(4), tau)
    s_got, lat_got = w.lanes.project(np.zeros(len(tau), int), np.stack([x[0], y[0]], axis=1))
    np.testing.assert_allclose(s_got, 120.0 + 8.0 * np.cos(0.1) * tau, atol=0.05)
    np.testing.assert_allclose(lat_got, -0.4 + 8.0 * np.sin(0.1) * tau, atol=0.05)
    _, h = w.lanes.pose(np.zeros(len(tau), int), s_got)
    np.testing.assert_allclose(psi[0], h + 0.1, atol=1e-3)


def test_on_a_straight_lane_and_off_the_lanes_the_prediction_is_the_straight_line() -> None:
    """On the first straight (s < 30, 1 s at 15 m/s still before the bend) and for poses tracked by
    no lane (pedestrians, waypoints: here in the bend), exactly x + v·cos ψ·t: the same numbers
    as before bends were followed. A lane change on the straight included."""
    w = _curvy()
    tau = 0.1 * np.arange(11)
    cases = [
        _traffic(w, np.array([0, 0, 1, 0]), np.array([5.0, 10.0, 305.0, 20.0]), np.array([0.0, 0.3, 0.0, -0.5]),
                 np.array([15.0, 7.0, 10.0, 12.0]), turn=np.array([0.0, 0.0, 0.0, 0.08])),
        _traffic(w, np.array([0, 0, 1, 1]), np.array([90.0, 120.0, 200.0, 230.0]), np.zeros(4), np.full(4, 9.0),
                 on_lane=False),
    ]
    for tr in cases:
        x, y, psi = predicted_poses(w, tr, np.arange(4), tau)
        assert np.array_equal(x, tr.x[:, None] + (tr.v * np.cos(tr.psi))[:, None] * tau[None])
        assert np.array_equal(y, tr.y[:, None] + (tr.v * np.sin(tr.psi))[:, None] * tau[None])
        assert np.array_equal(psi, np.repeat(tr.psi[:, None], len(tau), axis=1))


def test_regression_an_oncoming_car_in_a_bend_keeps_its_lane_for_the_low_level() -> None:
    """The ego entering curvy_road's first (left-hand) bend at 7.5 m/s meets an oncoming car at 10
    m/s in its own lane, both on their lanes' centres. Predicted on its tangent, the car drifted
    into the ego's lane: the box separation the low level judges ``collision_free(D_safe)`` on fell
    below D_safe = 1 m and it braked fully (8.9 m/s² on curvy_road, 25 steps). Along its lane the
    separation stays above D_safe all over the horizon, and the MPC is given the same prediction."""
    w = _curvy()
    H, dt = w.settings.H, w.settings.dt
    ego_lane_s = 52.0  # route s = lane s − 5
    level = w.lanes.pose(np.array([0]), np.array([ego_lane_s + 17.0]))[0]
    oncoming = float(w.lanes.project(np.array([1]), level)[0][0])
    # the slow car far ahead, the oncoming car 17 m ahead in the bend, two more far away
    tr = _traffic(w, np.array([0, 1, 1, 1]), np.array([200.0, oncoming, 60.0, 20.0]), np.zeros(4),
                  np.array([7.0, 10.0, 10.0, 10.0]))
    tau = dt * np.arange(H + 1)
    p, h = w.lanes.pose(np.zeros(H + 1, int), ego_lane_s + 7.5 * tau)
    ex, ey = p[:, 0][None], p[:, 1][None]
    others = others_predicted(w, tr, float(ex[0, 0]), float(ey[0, 0]), ego_lane_s - 5.0, H, dt)
    assert list(others.index) == [1]

    def gap(o) -> np.ndarray:  # noqa: ANN001
        zeros = np.zeros((1, H + 1))
        return sense(w, 0.0, dt, Memory.fresh(w), o, ex, ey, h[None], np.full((1, H + 1), 7.5), zeros,
                     zeros)["min_gap"][0]

    assert np.all(gap(others) >= D_SAFE + 0.2)
    tangent = replace(others, x=tr.x[[1], None] + 10.0 * np.cos(tr.psi[1]) * tau[None],
                      y=tr.y[[1], None] + 10.0 * np.sin(tr.psi[1]) * tau[None], psi=np.full((1, H + 1), tr.psi[1]))
    assert gap(tangent).min() < D_SAFE  # what the straight line predicted: a collision ahead
    hc = horizon_constants(w, tr, 0.0, (float(ex[0, 0]), float(ey[0, 0]), float(h[0]), 7.5))
    assert list(hc.index) == [1]
    np.testing.assert_array_equal(hc.xy[0, :, 0], others.x[0])
    np.testing.assert_array_equal(hc.xy[0, :, 1], others.y[0])
    np.testing.assert_array_equal(hc.psi[0], others.psi[0])
