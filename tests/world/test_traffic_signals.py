"""Traffic (IDM, lights, stop signs) and signals computed by hand on a small straight map."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.world.provided import PROVIDED_SIGNALS
from twolevel.world.signals import StopMemory, TrafficLog, horizon_constants, signals_along, update_stop_memory
from twolevel.world.traffic import GREEN, RED, YELLOW, EgoBox, nearby
from twolevel.world.world import World

from helpers import traffic_worlds
from helpers.traffic_worlds import run

MAP = """\
kind: map
default_speed_limit: 10
roads:
  - id: road
    segments: [{line: 400}]
    lanes:
      - {id: a, offset: 0}
      - {id: b, offset: 3.5}
speed_limits:
  - {id: s1, lane: a, s: 100, value: 6}
stop_signs:
  - {id: stop, lane: a, s: 50, stop_time: 1.0}
traffic_lights:
  - {id: tl, lane: a, s: 200, cycle: {green: 10, yellow: 2, red: 8, offset: 5}}
  - {id: tl2, lane: b, s: 300, script: [{t: 0, state: red}, {t: 4, state: green}]}
"""


def world(tmp: Path, participants: str, extra: str = "") -> World:
    """The world of a scenario on :data:`MAP` whose ego starts on lane a."""
    return traffic_worlds.world(tmp, MAP, participants + extra, ego_lane="a", goal=390)


def test_light_cycle_with_offset_and_script(tmp_path: Path) -> None:
    w = world(tmp_path, "")
    t = np.array([0, 4.9, 5, 6.9, 7, 14.9, 15, 20, 24.9, 25])
    # cycle: u = (t + 5) mod 20: green [0,10), yellow [10,12), red [12,20)
    assert list(w.lights.state_at(t)[:, 0]) == [GREEN, GREEN, YELLOW, YELLOW, RED, RED, GREEN, GREEN, GREEN, YELLOW]
    assert list(w.lights.state_at(np.array([0, 3.9, 4, 100]))[:, 1]) == [RED, RED, GREEN, GREEN]


def test_idm_stops_behind_a_stopped_car_without_collision(tmp_path: Path) -> None:
    w = world(tmp_path, "participants:\n"
              "  - {id: wall, behaviour: stationary, start: {lane: b, s: 150}}\n"
              "  - {id: car, behaviour: idm, start: {lane: b, s: 10}, speed: 10}\n")
    states = run(w, 60.0)
    gap = np.array([st.s[0] - st.s[1] - 4.22 for st in states])
    assert gap.min() > 0.5  # never touches
    assert states[-1].v[1] < 0.05 and 1.0 < gap[-1] < 3.0  # stands ~s0 = 2 m behind
    assert np.all(np.diff([st.s[1] for st in states]) >= -1e-9)  # never reverses


def test_idm_reacts_to_the_ego_as_leader(tmp_path: Path) -> None:
    w = world(tmp_path, "participants:\n  - {id: car, behaviour: idm, start: {lane: a, s: 150}, speed: 6}\n")
    ego = EgoBox(180.0, 0.0, 0.0, 0.0)  # the ego stands on lane a at s = 180
    states = run(w, 40.0, ego=ego)
    gaps = [180.0 - st.s[0] - 4.22 for st in states]
    assert min(gaps) > 0.5 and states[-1].v[0] < 0.05


def test_idm_stops_at_stop_sign_then_goes_and_waits_at_red(tmp_path: Path) -> None:
    w = world(tmp_path, "participants:\n  - {id: car, behaviour: idm, start: {lane: a, s: 10}, speed: 8}\n")
    states = run(w, 40.0)
    s = np.array([st.s[0] + 4.22 / 2 for st in states])  # front bumper
    v = np.array([st.v[0] for st in states])
    near_sign = (s > 46) & (s <= 50.01)
    assert (v[near_sign] < 0.1).sum() >= 10  # stood still ≥ 1 s at the line
    assert s.max() > 60  # then went on
    # the light at 200: red in [7, 15) + 20k; the car must not cross on red
    t = np.array([st.t for st in states])
    state = w.lights.state_at(t)[:, 0]
    crossed = np.flatnonzero((s[:-1] <= 200) & (s[1:] > 200))
    assert all(state[k] != RED for k in crossed)


def test_nearby(tmp_path: Path) -> None:
    w = world(tmp_path, "participants:\n  - {id: c1, behaviour: stationary, start: {lane: a, s: 8}}\n"
              "  - {id: c2, behaviour: stationary, start: {lane: b, s: 30}}\n")
    assert list(nearby(w.traffic0, 0.0, 0.0, 10.0)) == [True, False]


def test_signals_by_hand(tmp_path: Path) -> None:
    w = world(tmp_path, "participants:\n"
              "  - {id: lead, behaviour: constant_velocity, start: {lane: a, s: 20}, speed: 2}\n"
              "  - {id: side, behaviour: stationary, start: {lane: b, s: 14}}\n",
              "controller: {r_near: 10}\n")  # the paper's radius (by default 2 s at the 10 m/s limit: 20 m)
    T = 5
    x = np.array([0.0, 11, 44, 48, 48])
    ego = {"x": x, "y": np.zeros(T), "psi": np.zeros(T), "v": np.array([5.0, 5, 3, 0, 0])}
    traffic = TrafficLog.of(run(w, 0.4), w.parts.length, w.parts.width)
    sig = signals_along(w, traffic, ego)
    assert set(sig) == PROVIDED_SIGNALS
    assert np.allclose(sig["s"], x) and np.allclose(sig["e"], 0)
    assert list(sig["v_max"]) == [10, 10, 10, 10, 10]
    # stop line at 50: beyond r_near = 10 m at x = 0, 10; 6 m at 44; 2 m at 48 (then stopped:
    # needs 1 s standstill, only 0.1 s here)
    assert list(sig["d_stop"]) == [np.inf, np.inf, 6.0, 2.0, 2.0]
    # the lead car moves at 2 m/s from s = 20: at t = 0.1, s = 20.2, ego at 11 → 20.2 − 11 − 4.22
    assert np.isinf(sig["d_lead"][0]) and np.isclose(sig["d_lead"][1], 20.2 - 11 - 4.22)
    assert np.isclose(sig["v_lead"][1], 2.0) and sig["v_lead"][0] == 5.0
    # side car at (14, 3.5): in lane b, never a leader; its boxes are 3.5 − 1.8 = 1.7 m apart at t1
    assert np.isclose(sig["min_gap"][1], min(1.7, 20.2 - 11 - 4.22))
    assert list(sig["n_near"]) == [0, 2, 0, 0, 0]
    assert list(sig["light_red"]) == [0] * 5 and np.all(np.isinf(sig["d_light"]))


def test_stop_sign_served_after_standstill(tmp_path: Path) -> None:
    w = world(tmp_path, "")
    T = 40
    x = np.concatenate([np.linspace(40, 48, 10), np.full(15, 48.0), np.linspace(48.5, 60, 15)])
    v = np.concatenate([np.full(10, 3.0), np.zeros(15), np.full(15, 3.0)])
    sig = signals_along(w, None, {"x": x, "y": np.zeros(T), "psi": np.zeros(T), "v": v})
    d = sig["d_stop"]
    assert np.isclose(d[10], 2.0)  # stopped, not yet served
    assert np.isclose(d[19], 2.0) and np.isinf(d[20])  # 1.0 s of standstill at index 20
    assert np.all(np.isinf(d[20:]))
    # incremental memory agrees
    mem = StopMemory.fresh(w)
    served = []
    for k in range(T):
        mem = update_stop_memory(mem, w, float(x[k]), float(v[k]), w.settings.dt)
        served.append(mem.served[0])
    assert served.index(True) == 20
    # running the sign: d_stop goes negative
    x2 = np.linspace(40, 60, T)
    d2 = signals_along(w, None, {"x": x2, "y": np.zeros(T), "psi": np.zeros(T), "v": np.full(T, 5.0)})["d_stop"]
    assert d2[np.searchsorted(x2, 52)] < 0


def test_red_light_signals(tmp_path: Path) -> None:
    w = world(tmp_path, "")
    # light at 200; at t0 = 7 s it is red (until 15 s)
    T = 10
    x = np.linspace(192, 201, T)
    sig = signals_along(w, None, {"x": x, "y": np.zeros(T), "psi": np.zeros(T), "v": np.full(T, 10.0)}, t0=7.0)
    assert np.all(sig["light_red"] == 1)
    assert np.allclose(sig["d_light"], 200 - x)  # crossed on red: still applies, negative
    sig = signals_along(w, None, {"x": x, "y": np.zeros(T), "psi": np.zeros(T), "v": np.full(T, 10.0)}, t0=0.0)
    assert np.all(sig["light_red"] == 0)  # green
    assert np.all(np.isinf(sig["d_light"][x > 200]))  # crossed on green: no longer applies


def test_horizon_constants(tmp_path: Path) -> None:
    w = world(tmp_path, "participants:\n  - {id: lead, behaviour: constant_velocity, start: {lane: a, s: 96}, speed: 3}\n")
    hc = horizon_constants(w, w.traffic0, 6.5, (92.0, 0.0, 0.0, 8.0))
    assert hc.t.shape == (11,) and np.isclose(hc.t[-1], 7.5)
    assert np.allclose(hc.s_ref[0], 92.0) and np.all(np.diff(hc.s_ref) > 0)
    assert np.all(hc.v_max[hc.s_ref < 100] == 10) and np.all(hc.v_max[hc.s_ref >= 100] == 6)
    assert np.isinf(hc.s_stop) and np.isinf(hc.s_light)
    assert hc.lead == 0 and np.allclose(hc.s_lead, 96 + 3 * 0.1 * np.arange(11))
    assert hc.xy.shape == (1, 11, 2) and np.isclose(hc.lead_offset, 4.22)
    hc = horizon_constants(w, w.traffic0, 6.5, (192.0, 0.0, 0.0, 4.0))
    assert hc.s_light == 200 and list(hc.light_red) == [1] * 11  # yellow at 6.5 s, can stop → red
    hc = horizon_constants(w, w.traffic0, 0.0, (45.0, 0.0, 0.0, 4.0))
    assert hc.s_stop == 50 and hc.index.size == 0
