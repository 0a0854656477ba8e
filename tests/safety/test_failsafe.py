"""Fail-safe trajectories on the detailed model: they stop, where the braking level says, on the
route; clearing a zone passes it first."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers.safety_worlds import ego_on, world
from twolevel.models import fourwheel as fw
from twolevel.models.params import VehicleParams
from twolevel.models.rollout import rollout
from twolevel.safety.failsafe import (FULL, KEEP_MIN, MIN_GAIN, FailSafeSettings, Manoeuvre, _roll_live, brake_rate,
                                      catch_up, manoeuvres, return_path, roll)
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


@settings(max_examples=200, deadline=None)
@given(v0=st.floats(0.0, 15.0), ahead=st.floats(0.0, 300.0), e_now=st.floats(-0.5, 3.0))
def test_completing_a_pass_at_its_speed_only_at_a_pace_that_gets_there(v0, ahead, e_now):
    """A car out of its lane beside what it passes completes the pass keeping its speed only at
    KEEP_MIN or more and when that gets it past within max_time (a crawl would not brake before
    its time is up: its rollout ran to max_time in half-second segments, to fail; a pull-out from
    rest at 2 m/s does get there and is what verifies it); creeping back and braking back into
    the lane are always tried. It gains speed at most at the settings' clearing acceleration and
    only as much as lets its way out beside the vehicle (from e_now to 3 m) keep within half the
    lateral acceleration bound at the speed it has at its end (regression: gaining 1.5 m/s² from
    2 m/s it reached 5.5 m/s on a way out laid out for 3 m/s, swung back into the lane of the
    stalled car it was passing, and the pull-out was refuted)."""
    fs = FailSafeSettings()
    s0 = 50.0
    plan = manoeuvres(fs, np.zeros((0, 2)), s0, v0, 9.0, (0.0, s0 + ahead, 3.0, 0.0, e_now))
    keep = [m for m in plan if m.clear_accel == 0.0]
    gain = [m for m in plan if m.clear_accel is not None and m.clear_accel != 0.0 and not math.isnan(m.e_out)]
    assert sum(m.clear_accel == 1.0 and math.isnan(m.e_out) for m in plan) == 1  # the creep
    assert {m.decel for m in plan if m.clear_accel is None} == {min(fs.decels), max(fs.decels)}
    assert len(gain) <= 1
    for m in gain:
        assert MIN_GAIN <= m.clear_accel <= max(fs.clear_accels)
        v_end = math.sqrt(v0**2 + 2 * m.clear_accel * m.d_out)
        assert v_end**2 * 6 * abs(m.e_out - e_now) / m.d_out**2 <= 0.5 * fs.a_lat_max + 1e-6
    d_ret = max(v0, 3.0) * math.sqrt(6 * 3.5 / (0.5 * fs.a_lat_max))
    assert len(keep) == (1 if v0 >= KEEP_MIN and ahead + d_ret <= v0 * fs.max_time else 0)


@settings(max_examples=300, deadline=None)
@given(s0=st.floats(0.0, 100.0), v0=st.floats(0.0, 20.0), accel=st.sampled_from([0.0, 0.5, 1.5]),
       gap=st.one_of(st.floats(-20.0, 0.0), st.floats(0.01, 100.0)),
       v_past=st.one_of(st.just(0.0), st.floats(0.1, 15.0)))
def test_a_completing_pass_returns_where_it_has_caught_up(s0, v0, accel, gap, v_past):
    """catch_up: where the car, holding its acceleration, is level with a point that drives on at
    v_past from gap ahead of it — the point is there at that moment; behind the car or standing,
    the point itself; never, when the car is no faster and gains nothing."""
    at = catch_up(s0, v0, accel, s0 + gap, v_past)
    if gap <= 0 or v_past <= 0:
        assert at == max(s0 + gap, s0)
    elif accel == 0 and v0 <= v_past:
        assert math.isinf(at)
    else:
        t = (at - (s0 + gap)) / v_past  # when the point is there
        assert at == pytest.approx(s0 + v0 * t + 0.5 * accel * t * t, rel=1e-9, abs=1e-6)
        assert at >= s0 + gap


def test_a_kept_crawl_too_slow_for_the_distance_does_not_stop_in_time():
    """What the pace rule leaves out fails anyway: keeping 1.1 m/s to a point 40 m ahead does not
    stop within max_time on the detailed model."""
    w = world("stalled")
    p = ego_params(w)
    (fs,) = roll(ego_on(w, "road", 10.0, 1.1), [Manoeuvre(4.0, 0.0, 50.0)], w.route, 10.0, w.settings.dt, p)
    assert not fs.stopped and fs.t_stop == pytest.approx(FailSafeSettings().max_time)


@settings(max_examples=30, deadline=None)
@given(live=st.lists(st.booleans(), min_size=1, max_size=5), v=st.floats(0.0, 25.0),
       delta=st.floats(-0.3, 0.3), gamma=st.floats(-1.0, 1.0), n=st.sampled_from([1, 5, 10]))
def test_rolling_only_the_moving_fail_safes_gives_their_states_of_the_whole_batch(live, v, delta, gamma, n):
    """The segments of a fail-safe roll simulate only the manoeuvres that have not stopped: each
    such row's states are bit for bit those of rolling out the whole batch; the others stand."""
    p, K = VehicleParams(), len(live)
    x = np.stack([fw.initial_state(v=v + k) for k in range(K)])
    u = np.broadcast_to(np.array([delta, gamma]) * np.linspace(1.0, 0.5, K)[:, None, None], (K, n, 2)).copy()
    mask = np.array(live)
    whole = rollout(x, u, 0.1, p).states
    got = _roll_live(x, u, mask, 0.1, p, "auto")
    assert got.shape == whole.shape
    assert np.array_equal(got[mask], whole[mask])
    assert np.array_equal(got[~mask], np.repeat(x[~mask][:, None], n + 1, axis=1))


@settings(max_examples=200, deadline=None)
@given(rows=st.lists(st.tuples(st.floats(-4, 4), st.one_of(st.just(math.nan), st.floats(-4, 4)), st.floats(0, 50),
                               st.floats(0, 30), st.one_of(st.just(math.nan), st.floats(-4, 4)), st.floats(0, 50),
                               st.floats(0, 30)), min_size=1, max_size=4),
       s=st.lists(st.floats(-10, 120), min_size=2, max_size=6))
def test_the_return_path_on_a_grid_at_once_is_column_by_column_the_same(rows, s):
    """A fail-safe's roll evaluates the lateral path once per segment, at its start and along its
    profile together ((K, n+1) positions, the manoeuvres as (K, 1) rows): each column equals the
    path evaluated at that column alone with the manoeuvres as (K,) arrays, bit for bit."""
    a = np.array(rows)
    e_from = a[:, 0]
    path = tuple(a[:, i] for i in range(1, 7))
    grid = np.array(s)[None, :] + np.arange(len(a))[:, None]  # (K, n+1)
    together = return_path(e_from[:, None], tuple(p[:, None] for p in path), grid)
    for j in range(grid.shape[1]):
        alone = return_path(e_from, path, grid[:, j])
        for t, o in zip(together, alone):
            assert np.array_equal(t[:, j], o)


@settings(max_examples=25, deadline=None)
@given(v0=st.floats(0.0, 25.0), lateral=st.floats(-0.5, 3.5), s_past=st.floats(5.0, 80.0), v_past=st.floats(0.0, 8.0),
       pick=st.lists(st.integers(0, 9), min_size=1, max_size=4, unique=True))
def test_a_batch_of_fail_safes_is_its_controls_replayed_from_the_start(v0, lateral, s_past, v_past, pick):
    """Whatever the batch (braking levels, clearing, returning to the lane, completing a pass, rolled
    together in segments planned from each segment's start), each fail-safe's commands replayed in
    one rollout from its start give its states bit for bit, and the segments' planning bounds the
    steering."""
    w = world("stalled")
    p = ego_params(w)
    s0 = 10.0
    x0 = ego_on(w, "road", s0, v0, lateral)
    st_ = FailSafeSettings()
    back = manoeuvres(st_, np.array([[30.0, 40.0]]), s0, v0, brake_rate(p), (0.0, s0 + s_past, 3.5, v_past, lateral))
    ahead = manoeuvres(st_, np.array([[30.0, 40.0]]), s0, v0, brake_rate(p))
    pool = back + ahead
    plan = [pool[i % len(pool)] for i in pick]
    for fs in roll(x0, plan, w.route, s0, w.settings.dt, p):
        assert np.all(np.abs(fs.controls[:, 0]) <= st_.delta_max) and np.all(np.abs(fs.controls[:, 1]) <= 1.0)
        if fs.steps:
            replay = rollout(fs.states[0], fs.controls[None], w.settings.dt, p).states[0]
            assert np.array_equal(replay, fs.states)
