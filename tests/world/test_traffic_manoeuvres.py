"""Manoeuvre primitives of scripted participants on small real maps — lane changes, braking to a
speed, stops that hold, speed profiles over time and distance, lane following — started at a time,
after the previous one, or by the ego's distance or headway; and what ``check`` says about chains
it cannot run (YML416/420, YML433) or runs limited to the assumptions (YML434)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.world.loader import check_world_file
from twolevel.world.traffic import EgoBox

from helpers.traffic_worlds import ONE_LANE, TWO_LANES, run, world

R, L = 0, 1
DT = 0.1


def _chain(tmp: Path, items: str, *, lane: str = "r", speed: float = 10.0, map_text: str = TWO_LANES,
           extra: str = "") -> tuple:
    body = (f"participants:\n  - id: p\n    start: {{lane: {lane}, s: 100}}\n    speed: {speed}\n"
            f"    manoeuvres:\n{items}" + extra)
    return world(tmp, map_text, body, ego_lane=lane)


def test_brake_to_then_accelerate_at_the_rates_asked(tmp_path: Path) -> None:
    w = _chain(tmp_path, "      - {brake_to: 4, decel: 2, at: 1}\n      - {accelerate_to: 8, accel: 1, after: 2}\n")
    v = np.array([st.v[0] for st in run(w, 14.0)])
    a = np.diff(v) / DT
    assert (v[: int(1.0 / DT) + 1] == 10.0).all()  # keeps its initial speed until t = 1
    assert a.min() == pytest.approx(-2.0) and a.max() == pytest.approx(1.0)
    low = np.flatnonzero(np.isclose(v, 4.0))
    assert low[0] * DT == pytest.approx(1.0 + 3.0, abs=0.11)  # 10 → 4 at 2 m/s²: 3 s
    assert (len(low) - 1) * DT == pytest.approx(2.0, abs=0.11)  # held 2 s, then up to 8
    assert v[-1] == pytest.approx(8.0)


def test_stop_holds_then_the_next_starts(tmp_path: Path) -> None:
    w = _chain(tmp_path, "      - {stop: true, decel: 5, at: 0.5, hold: 3}\n      - {follow_lane: 6}\n")
    v = np.array([st.v[0] for st in run(w, 12.0)])
    still = np.flatnonzero(v < 1e-9)
    assert still[0] * DT == pytest.approx(0.5 + 2.0, abs=0.11)  # 10 m/s at 5 m/s²
    assert len(still) * DT == pytest.approx(3.0 - 2.0, abs=0.11)  # the hold counts from its start at 0.5 s
    assert v[-1] == pytest.approx(6.0)  # then keeps its lane at 6 m/s


@pytest.mark.parametrize("along,points,check", [
    ("time", "[[0, 10], [2, 6], [5, 6]]", lambda t, s, v: np.isclose(v[int(round(3.0 / DT))], 6.0)),
    ("distance", "[[0, 10], [30, 4]]", lambda t, s, v: np.isclose(v[np.argmax(s >= 130)], 4.0, atol=0.2)),
])
def test_speed_profiles_over_time_and_distance(tmp_path: Path, along: str, points: str, check) -> None:  # noqa: ANN001
    w = _chain(tmp_path, f"      - {{speed_profile: {points}, along: {along}}}\n")
    states = run(w, 8.0)
    v = np.array([st.v[0] for st in states])
    s = np.array([st.s[0] for st in states])
    assert check(None, s, v) and (np.diff(v) <= 1e-9).all()  # slows as told, never speeds up
    assert np.abs(np.diff(v) / DT).max() <= 8.0 + 1e-9  # within a vehicle's assumed a_max


def test_a_lane_change_moves_sideways_over_its_duration(tmp_path: Path) -> None:
    w = _chain(tmp_path, "      - {lane_change: left, duration: 3, at: 1}\n")
    states = run(w, 6.0)
    y = np.array([st.y[0] for st in states])
    lane = np.array([st.lane[0] for st in states])
    assert lane[0] == R and lane[-1] == L and y[-1] == pytest.approx(3.5)
    moving = np.flatnonzero(np.abs(np.diff(y)) > 1e-9)
    assert moving[0] * DT == pytest.approx(1.0, abs=0.11) and (moving[-1] - moving[0] + 1) * DT == pytest.approx(3.0, abs=0.11)


@pytest.mark.parametrize("trigger,ego_x,fires_at", [
    ("ego_within: 30", 40.0, 3.0),  # 60 − 10 t ≤ 30 m
    ("ego_within: 30", -30.0, None),  # 130 − 10 t stays above 30 m for the 8 s
    ("ego_headway: 2", 40.0, 2.0),  # (60 − 10 t) / 20 m/s ≤ 2 s
])
def test_ego_triggers(tmp_path: Path, trigger: str, ego_x: float, fires_at: float | None) -> None:
    """p drives at 10 m/s from s = 100; the ego at 20 m/s from ``ego_x`` closes in at 10 m/s."""
    w = _chain(tmp_path, f"      - {{brake_to: 5, decel: 5, {trigger}}}\n")
    states = run(w, 8.0, ego=lambda t: EgoBox(ego_x + 20.0 * t, 0.0, 0.0, 20.0))
    v = np.array([st.v[0] for st in states])
    if fires_at is None:
        assert (v == 10.0).all()
    else:
        first = int(np.argmax(v < 10.0))  # the step after the one it started in
        assert first > 0 and abs(first * DT - fires_at) <= DT + 1e-9


def test_a_braking_request_beyond_the_kinds_bound_is_limited(tmp_path: Path) -> None:
    w = _chain(tmp_path, "      - {stop: true, decel: 11}\n", map_text=ONE_LANE, lane="road")
    a = np.diff([st.v[0] for st in run(w, 3.0)]) / DT
    assert a.min() == pytest.approx(-8.0)  # a vehicle's assumed a_max


# ------------------------------------------------------------------ what check says


def _check(tmp: Path, items: str, *, lane: str = "r", kind: str = "car") -> list[tuple[str, int, int]]:
    (tmp / "map.yaml").write_text(TWO_LANES)
    (tmp / "scn.yaml").write_text(
        "kind: scenario\nmap: map.yaml\nego: {start: {lane: r, s: 0}}\n"
        "route: {start: {lane: r, s: 0}, goal: {lane: r, s: 1000}}\n"
        f"participants:\n  - id: p\n    kind: {kind}\n    start: {{lane: {lane}, s: 100}}\n    manoeuvres:\n{items}")
    return [(d.code, d.span.line, d.span.column) for d in check_world_file(tmp / "scn.yaml")]


@pytest.mark.parametrize("items,expected", [
    ("      - {lane_change: left}\n      - {lane_change: left}\n", [("YML420", 11, 23)]),  # no lane left of l
    ("      - {lane_change: right}\n", [("YML420", 10, 23)]),
    ("      - {lane_change: nowhere}\n", [("YML416", 10, 23)]),
    ("      - {brake_to: 0, decel: 15}\n", [("YML433", 10, 30)]),
    ("      - {brake_to: 0, decel: 9}\n", [("YML434", 10, 30)]),  # beyond a vehicle's 8 m/s², limited
    ("      - {speed_profile: [[0, 10], [1, 0]]}\n", [("YML434", 10, 35)]),  # 10 m/s² between the points
    ("      - {lane_change: left, duration: 3}\n      - {brake_to: 2, decel: 6, after_start: 1}\n", []),
])
def test_check_finds_chains_it_cannot_run_at_the_value(tmp_path: Path, items: str, expected: list) -> None:
    assert _check(tmp_path, items) == expected


def test_check_judges_a_cyclist_by_a_cyclists_bounds(tmp_path: Path) -> None:
    assert [c for c, *_ in _check(tmp_path, "      - {brake_to: 0, decel: 7}\n", kind="bicycle")] == ["YML434"]
    assert _check(tmp_path, "      - {brake_to: 0, decel: 7}\n", kind="car") == []
