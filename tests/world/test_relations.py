"""The participant signals' definitions on hand-computed cases (a straight route along x, lanes
3.5 m wide, the ego's box 4 m × 2 m at the route's centre line)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from helpers.world_files import load_world
from twolevel.world.relations import acceleration, lanes_occupied, relations

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def route():
    return load_world(ROOT / "scenarios" / "safety.yaml").route  # the highway's middle lane, heading 0, 3.5 m wide


def _rel(route, others: list[tuple[float, float, float, float]], near: list[bool] | None = None):
    """Others as (s, e, heading, speed), each 4 m × 2 m; the ego at s = 50, e = 0, heading 0."""
    o = np.array(others, dtype=float)
    n = len(o)
    ego = {"s": np.array([50.0]), "e": np.array([0.0]), "psi": np.array([0.0])}
    other = {"s": o[:, 0], "e": o[:, 1], "psi": o[:, 2], "v": o[:, 3]}
    mask = np.ones(n, bool) if near is None else np.array(near)
    return relations(route, ego, (4.0, 2.0), other, np.full(n, 4.0), np.full(n, 2.0), mask)


def test_a_car_ahead_in_the_lane(route) -> None:
    r = _rel(route, [(70.0, 0.0, 0.0, 10.0)])
    assert r["d_lon"][0] == pytest.approx(16.0)  # (70 - 2) - (50 + 2)
    assert r["in_same_lane"][0] == pytest.approx(2.75)  # its body reaches 2.75 m into the ego's lane
    assert r["precedes"][0] == pytest.approx(2.75)
    assert r["cut_in"][0] < 0 and r["v"][0] == pytest.approx(10.0) and r["d_lat"][0] == 0.0


def test_a_car_in_the_next_lane_is_not_in_the_same_lane(route) -> None:
    r = _rel(route, [(50.0, 3.5, 0.0, 10.0)])
    assert r["in_same_lane"][0] == pytest.approx(-0.75)  # 1.75 - 1 on each side
    assert r["precedes"][0] < 0 and r["d_lat"][0] == pytest.approx(3.5)


def test_a_car_cutting_in_from_the_left(route) -> None:
    theta = -0.1
    half_w = (4 * math.sin(0.1) + 2 * math.cos(0.1)) / 2  # its lateral half-extent at that heading
    r = _rel(route, [(60.0, 1.75, theta, 10.0)])
    assert r["in_same_lane"][0] == pytest.approx(half_w)  # across the boundary by its half-extent
    assert r["cut_in"][0] == pytest.approx(10 * math.sin(0.1))  # 1 s of its motion towards the ego
    leaving = _rel(route, [(60.0, 1.75, -theta, 10.0)])
    assert leaving["cut_in"][0] == pytest.approx(-10 * math.sin(0.1))


def test_precedes_only_the_first_car_ahead(route) -> None:
    r = _rel(route, [(70.0, 0.0, 0.0, 10.0), (60.0, 0.0, 0.0, 10.0), (65.0, 3.5, 0.0, 10.0)])
    assert r["precedes"][1] == pytest.approx(2.75)
    assert r["precedes"][0] == pytest.approx(-2.75)  # the car between is in the lane by 2.75 m
    assert r["precedes"][2] < 0
    # without the car between (out of range) the far one precedes
    r = _rel(route, [(70.0, 0.0, 0.0, 10.0), (60.0, 0.0, 0.0, 10.0)], near=[True, False])
    assert r["precedes"][0] == pytest.approx(2.75)
    assert r["d_lon"][1] == math.inf and r["in_same_lane"][1] == -math.inf and r["v"][1] == 0.0


def test_lanes_occupied_by_a_body() -> None:
    lo, hi = lanes_occupied(np.array([-1.0, 0.85, 2.0]), np.array([1.0, 2.65, 3.0]), np.array(3.5))
    assert lo.tolist() == [-1.75, -1.75, 1.75] and hi.tolist() == [1.75, 5.25, 5.25]


def test_acceleration_is_the_backward_difference_where_present() -> None:
    v = np.array([[10.0], [11.0], [13.0], [12.0]])
    near = np.array([[True], [True], [False], [True]])
    assert acceleration(v, near, 0.5)[:, 0].tolist() == [0.0, 2.0, 0.0, 0.0]
