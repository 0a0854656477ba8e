"""Who is responsible for a collision: the classification over recorded arrays, and whether the
other stayed within its predicted occupancy (the real predictor on recorded traffic)."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.safety_worlds import place, world
from twolevel.safety.responsibility import (
    CUT_IN, EGO_AT_FAULT, EGO_STANDING, HIT_FROM_BEHIND, OTHER_BROKE_ASSUMPTIONS, classify, stayed_within,
)
from twolevel.safety.verify import context

BOX = (4.22, 1.8)
DT = 0.1


def straight(x0: float, v: float, a: float = 0.0, n: int = 40, y: float = 0.0) -> np.ndarray:
    """[x, y, psi, v] (n, 4) driving along +x from x0 [m] at v [m/s], accelerating at a [m/s²]
    (never reversing)."""
    t = DT * np.arange(n)
    stop = v / -a if a < 0 else np.inf
    tt = np.minimum(t, stop)
    return np.stack([x0 + v * tt + 0.5 * a * tt**2, np.full(n, y), np.zeros(n), np.maximum(v + a * t, 0.0)], axis=1)


def times(n: int = 40) -> np.ndarray:
    return DT * np.arange(n)


def test_a_standing_ego_is_not_at_fault():
    ego = straight(0.0, 0.0)
    other = straight(-30.0, 10.0)
    r = classify(times(), ego, other, BOX, BOX)
    assert r.verdict == EGO_STANDING and not r.at_fault
    assert r.ego_speed == 0.0 and 2.4 < r.t < 2.7


def test_standing_inside_another_lane_is_no_excuse():
    """Stopped inside a crossing lane and hit by a car that kept the assumptions: the ego's fault
    (the paper's low level stops there; the verifier never does)."""
    ego = straight(0.0, 0.0)
    other = np.stack([np.full(40, 0.0), -30.0 + 12.0 * times(), np.full(40, np.pi / 2), np.full(40, 12.0)], axis=1)
    r = classify(times(), ego, other, BOX, BOX, standing_in="north")
    assert r.verdict == EGO_AT_FAULT and r.at_fault and "inside lane 'north'" in r.reason
    assert classify(times(), ego, other, BOX, BOX).verdict == EGO_STANDING


@pytest.mark.parametrize("ahead, fault", [(6.0, False), (40.0, True)])
def test_a_cut_in_closer_than_the_safe_distance_is_the_cutters_fault(ahead, fault):
    """A car changes into the ego's lane ``ahead`` [m] (centres) in front of it at 1 s and stops
    at 8 m/s²; the ego at 15 m/s runs into it. From 6 m (a 1.8 m gap, far below the safe
    distance) it is the car's doing; from 40 m the ego had room to stop: its fault."""
    n = 60
    ego = straight(0.0, 15.0, n=n)
    other = straight(ahead + 15.0 * 1.0, 15.0, n=n)
    t = times(n)
    stop = t >= 1.0  # brakes from 1 s, when it enters the lane
    tb = np.maximum(t - 1.0, 0.0)
    tt = np.minimum(tb, 15.0 / 8.0)
    other[:, 0] = ahead + 15.0 * np.minimum(t, 1.0) + np.where(stop, 15.0 * tt - 4.0 * tt**2, 0.0)
    other[:, 3] = np.where(stop, np.maximum(15.0 - 8.0 * tb, 0.0), 15.0)
    ego_lane = np.zeros(n, dtype=int)
    other_lane = np.where(t < 1.0, 1, 0)
    r = classify(t, ego, other, BOX, BOX, ego_lane=ego_lane, other_lane=other_lane)
    assert r.verdict == (EGO_AT_FAULT if fault else CUT_IN) and r.at_fault is fault
    if not fault:
        assert "changed into the ego's lane at 1.0 s" in r.reason


def test_hit_from_behind_on_its_lane():
    ego = straight(0.0, 5.0)
    other = straight(-20.0, 12.0)
    lanes = np.zeros(40, dtype=int)
    r = classify(times(), ego, other, BOX, BOX, ego_lane=lanes, other_lane=lanes, response_time=2.0)
    assert r.verdict == HIT_FROM_BEHIND and not r.at_fault


def test_cutting_in_closer_than_the_follower_can_respond_is_the_egos_fault():
    """The ego changed into the lane 0.5 s before the impact (less than the 2 s response time):
    being hit from behind then is the ego's doing."""
    ego = straight(0.0, 5.0)
    other = straight(-20.0, 12.0)
    ego_lane = np.where(times() < 2.0, 1, 0)
    r = classify(times(), ego, other, BOX, BOX, ego_lane=ego_lane, other_lane=np.zeros(40, dtype=int),
                 response_time=2.0)
    assert r.verdict == EGO_AT_FAULT and r.at_fault


def test_driving_into_a_participant_within_its_occupancy_is_the_egos_fault():
    ego = straight(0.0, 12.0)
    other = straight(30.0, 0.0)
    r = classify(times(), ego, other, BOX, BOX, other_inside=np.ones(40, dtype=bool))
    assert r.verdict == EGO_AT_FAULT and r.at_fault and r.left_at is None


def test_a_participant_that_left_its_occupancy_broke_the_assumptions():
    ego = straight(0.0, 12.0)
    other = straight(30.0, 0.0)
    inside = times() < 1.05
    r = classify(times(), ego, other, BOX, BOX, other_inside=inside)
    assert r.verdict == OTHER_BROKE_ASSUMPTIONS and not r.at_fault
    assert r.left_at == pytest.approx(1.1)


def test_leaving_the_occupancy_after_the_contact_does_not_count():
    ego = straight(0.0, 12.0)
    other = straight(30.0, 0.0)
    r = classify(times(), ego, other, BOX, BOX, other_inside=times() < 3.5)
    assert r.verdict == EGO_AT_FAULT


# ----------------------------------------------------------- against the real prediction


def recorded(decel: float, n: int = 20, reverse: bool = False) -> list:
    """The stalled-car world's participant driving at 15 m/s from s = 100 m, then braking at
    ``decel`` [m/s²] (or rolling backwards at 1 m/s), one traffic state per control step."""
    w = world("stalled")
    out = []
    for k in range(n):
        t = k * DT
        if reverse:
            s, v = 100.0 - 1.0 * t, 1.0
        else:
            tt = min(t, 15.0 / decel)
            s, v = 100.0 + 15.0 * tt - 0.5 * decel * tt**2, max(15.0 - decel * t, 0.0)
        st = place(w, w.traffic0, "stalled", "road", s, v=v)
        out.append(type(st)(**{**st.__dict__, "t": t}))
    return out


@pytest.mark.parametrize("decel, inside", [(6.0, True), (20.0, False)])
def test_braking_within_the_bound_stays_inside_beyond_it_does_not(decel, inside):
    ctx = context(world("stalled"))
    within = stayed_within(ctx, recorded(decel), 0)
    assert bool(within.all()) is inside
    if not inside:
        assert not within[1:8].all()


def test_reversing_leaves_the_occupancy():
    ctx = context(world("stalled"))
    assert not stayed_within(ctx, recorded(0.0, reverse=True), 0)[1:].any()


def test_a_rear_end_into_a_car_braking_beyond_the_bounds_is_not_the_egos_fault():
    """End to end: the ego follows at 15 m/s; the car ahead stops at 20 m/s²; the ego runs into
    it: the car left its occupancy, so the collision is not the ego's fault."""
    ctx = context(world("stalled"))
    traffic = recorded(20.0, n=30)
    other = np.array([[s.x[0], s.y[0], s.psi[0], s.v[0]] for s in traffic])
    ego = straight(88.0, 15.0, n=30)
    r = classify(times(30), ego, other, BOX, BOX, other_inside=stayed_within(ctx, traffic, 0))
    assert r.verdict == OTHER_BROKE_ASSUMPTIONS and r.left_at is not None and r.left_at < r.t
