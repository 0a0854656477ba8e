"""Soundness of the occupancy prediction: participants behaving legally, at random, within the
declared assumptions (tests/helpers/legal.py) always lie inside their predicted occupancy — and the
check is strong enough to notice a prediction that is too tight."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers.safety_worlds import place, world
from helpers.legal import sample
from twolevel.world.assumptions import CYCLIST, PEDESTRIAN, VEHICLE, Assumptions, kinds_of
from twolevel.safety.network import network_of
from twolevel.safety.occupancy import Intervals, predict
from twolevel.safety.responsibility import contains

HORIZON = 5.0
MAPS = ("straight", "signals", "junction", "crossing", "bends", "highway", "curved_road")
WHO = {"car": VEHICLE, "bike": CYCLIST, "walker": PEDESTRIAN}


def escapes(name: str, who: str, lane_pick: float, s_pick: float, v_pick: float, t_abs: float, changes: bool,
            seed: int, predictor: Assumptions | None = None) -> list[tuple[float, int]]:
    """(time [s], interval) of every sample of a legal behaviour that is not inside its predicted
    occupancy (the predictor's assumptions may differ from the behaviour's, to test the test)."""
    w = world(f"sound_{name}")
    net = network_of(w)
    i = w.parts.ids.index(who)
    kind = WHO[who]
    a = w.assumptions
    bounds = replace(a.bounds(kind), lane_changes=changes and a.bounds(kind).lane_changes)
    a = replace(a, vehicle=bounds) if kind == VEHICLE else replace(a, cyclist=bounds) if kind == CYCLIST else a
    traffic = w.traffic0
    if kind == PEDESTRIAN:  # somewhere near the lanes, walking any way
        lane = w.lanes.lanes[int(lane_pick * len(w.lanes.lanes)) % len(w.lanes.lanes)]
        p, h = w.lanes.pose(np.array([lane.index]), np.array([s_pick * lane.length]), np.array([3.0]))
        traffic = place(w, traffic, who, xy=(float(p[0, 0]), float(p[0, 1]), float(h[0]) + 7 * lane_pick),
                        v=v_pick * bounds.v_max)
    else:
        if changes and name in ("signals", "crossing"):
            changes = False  # the sampler keeps to lines only without lane changes (see helpers/legal.py)
        lane = w.lanes.lanes[int(lane_pick * len(w.lanes.lanes)) % len(w.lanes.lanes)]
        limit = float(w.limits.at(np.array([lane.index]), np.array([0.0]))[0])
        traffic = place(w, traffic, who, lane.id, s_pick * lane.length, v=v_pick * bounds.speed_cap(limit))
    active = np.zeros(len(traffic.x), dtype=bool)
    active[i] = True
    traffic = replace(traffic, active=active)
    kinds = np.asarray(kinds_of(w.parts.ids, a))
    iv = Intervals.make(w.settings.dt, HORIZON)
    occ = predict(net, traffic, t_abs, iv, predictor or a, kinds)
    track = sample(net, traffic, i, t_abs, kind, bounds, np.random.default_rng(seed), HORIZON)
    out = []
    for t, corners in zip(track.t, track.corners):
        for j in np.flatnonzero((iv.t[:-1] <= t + 1e-9) & (iv.t[1:] >= t - 1e-9)):
            if not contains(occ, i, int(j), corners):
                out.append((float(t), int(j)))
    return out


behaviour = dict(
    name=st.sampled_from(MAPS), who=st.sampled_from(tuple(WHO)), lane_pick=st.floats(0, 0.999),
    s_pick=st.floats(0, 1), v_pick=st.floats(0, 1), t_abs=st.floats(0, 40), changes=st.booleans(),
    seed=st.integers(0, 2**31 - 1))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(**behaviour)
def test_legal_behaviour_stays_inside_its_occupancy(name, who, lane_pick, s_pick, v_pick, t_abs, changes, seed):
    assert escapes(name, who, lane_pick, s_pick, v_pick, t_abs, changes, seed) == []


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(**behaviour)
def test_legal_behaviour_stays_inside_its_occupancy_many(name, who, lane_pick, s_pick, v_pick, t_abs, changes, seed):
    assert escapes(name, who, lane_pick, s_pick, v_pick, t_abs, changes, seed) == []


@pytest.mark.parametrize("name, lane_pick, t_abs", [("signals", 0.0, 0.0), ("signals", 0.0, 10.0), ("crossing", 0.0, 0.0)])
def test_legal_behaviour_at_lines(name, lane_pick, t_abs):
    """Vehicles approaching a light (green, then red) and a stop sign, many seeds."""
    for seed in range(12):
        assert escapes(name, "car", lane_pick, 0.6, 0.9, t_abs, False, seed) == [], seed


def test_the_check_notices_a_prediction_that_is_too_tight():
    """With a_max halved in the predictor only, some legal behaviour escapes (hard braking falls
    behind the rear bound, hard acceleration past the front one)."""
    w = world("sound_straight")
    tight = replace(w.assumptions, vehicle=replace(w.assumptions.vehicle, a_max=4.0))
    found = [escapes("straight", "car", 0.0, 0.3, 0.8, 0.0, False, seed, predictor=tight) for seed in range(20)]
    assert any(found)


def test_the_check_notices_a_prediction_without_lane_changes():
    """A predictor that assumes vehicles keep their lane misses one wandering across the highway."""
    w = world("sound_highway")
    keep = replace(w.assumptions, vehicle=replace(w.assumptions.vehicle, lane_changes=False))
    found = [escapes("highway", "car", 0.4, 0.3, 0.5, 0.0, True, seed, predictor=keep) for seed in range(10)]
    assert any(found)
