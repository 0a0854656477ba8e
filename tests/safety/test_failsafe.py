"""Fail-safe trajectories on the detailed model: they stop, where the braking level says, on the
route; clearing a zone passes it first."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers.safety_worlds import ego_on, world
from twolevel.models import fourwheel as fw
from twolevel.safety.failsafe import FULL, FailSafeSettings, Manoeuvre, brake_rate, manoeuvres, roll
from twolevel.safety.network import network_of
from twolevel.safety.verify import ego_params


@pytest.mark.parametrize("v0", [5.0, 15.0, 25.0])
def test_braking_stops_the_detailed_model_within_its_distance(v0):
    """Each level stops the four-wheel model (speed ≤ v_stop, then held) within the distance
    v²/(2·b) of its deceleration b, plus what the one-step actuation and load-transfer lags add."""
    w = world("stalled")
    p = ego_params(w)
    plan = [Manoeuvre(4.0), Manoeuvre(6.0), Manoeuvre(FULL)]
    for fs in roll(ego_on(w, "road", 10.0, v0), plan, w.route, 0.0, w.settings.dt, p):
        b = brake_rate(p) if math.isinf(fs.manoeuvre.decel) else fs.manoeuvre.decel
        travel = fs.states[-1, 0] - fs.states[0, 0]
        assert fs.stopped and abs(fs.states[-1, 3]) <= FailSafeSettings().v_stop
        assert v0**2 / (2 * b) * 0.97 <= travel <= v0**2 / (2 * b) * 1.03 + 0.15 * v0
        assert fs.t_stop == pytest.approx(fs.steps * w.settings.dt)
        assert np.array_equal(fs.control_at(fs.steps + 3), np.array([0.0, -1.0]))


def test_braking_follows_a_curved_route():
    """On the bends of the curved road the fail-safe keeps within 0.2 m of the route."""
    w = world("scenarios/comparison.yaml")
    p = ego_params(w)
    r = w.route
    for s0, v0 in ((70.0, 12.0), (115.0, 10.0), (180.0, 9.0)):
        pt, h = r.position(np.array([s0]))[0], float(r.heading_at(np.array([s0]))[0])
        x0 = fw.initial_state(pt[0], pt[1], h, v0)
        for fs in roll(x0, [Manoeuvre(4.0), Manoeuvre(FULL)], r, s0, w.settings.dt, p):
            _, e = r.local_coordinates(fs.states[:, :2])
            assert fs.stopped and np.abs(e).max() < 0.2


def test_clearing_a_zone_passes_it_before_braking():
    w = world("crossing_scn")
    net = network_of(w)
    (z_in, z_out), = net.zones
    s_ego = z_in + 2.0
    plan = manoeuvres(FailSafeSettings(), net.zones, s_ego, 0.0, brake_rate(ego_params(w)))
    clear = [m for m in plan if m.clear_accel is not None]
    assert clear and all(m.clear_accel > 0 for m in clear)  # from standstill only gaining speed clears
    (fs,) = roll(ego_on(w, "east", 80.0 + s_ego, 0.0), clear[:1], w.route, s_ego, w.settings.dt, ego_params(w))
    s_end, _ = w.route.local_coordinates(fs.states[-1:, :2])
    assert fs.stopped and s_end[0] > z_out


def test_no_clearing_without_a_zone_in_reach():
    w = world("crossing_scn")
    net = network_of(w)
    far = manoeuvres(FailSafeSettings(), net.zones, 0.0, 5.0, 9.0)
    assert [m.name for m in far] == ["brake 4", "brake 6", "brake full"]
    near = manoeuvres(FailSafeSettings(), net.zones, 10.0, 10.0, 9.0)
    assert len(near) == 7 and near[3].name.startswith("clear +0 to")
