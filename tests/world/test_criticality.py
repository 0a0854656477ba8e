"""Criticality measures on hand-computed cases, with CriMe's definitions of HW and THW and the
constant-velocity TTC (test_criticality_crime.py compares them with CommonRoad-CriMe itself when
the optional extra crime is installed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twolevel.world.criticality import discs, headways, time_to_collision_any


def test_headways_to_a_slower_vehicle_ahead() -> None:
    h = headways(20.0, 10.0, 5.0)
    assert (float(h["dhw"]), float(h["thw"]), float(h["ttc"])) == (20.0, 2.0, 4.0)


@pytest.mark.parametrize(("gap", "v", "v_lead", "thw", "ttc"), [
    (20.0, 10.0, 12.0, 2.0, math.inf),  # the vehicle ahead pulls away
    (math.inf, 10.0, 10.0, math.inf, math.inf),  # nobody ahead
    (20.0, 0.0, 0.0, math.inf, math.inf),  # standing
    (-0.5, 3.0, 0.0, 0.0, 0.0),  # bumpers overlap
])
def test_headway_corner_cases(gap: float, v: float, v_lead: float, thw: float, ttc: float) -> None:
    h = headways(gap, v, v_lead)
    assert float(h["thw"]) == thw and float(h["ttc"]) == ttc


def test_headways_are_vectorised() -> None:
    h = headways(np.array([[20.0, 8.0]]), np.array([[10.0, 4.0]]), np.array([[5.0, 0.0]]))
    assert h["ttc"].tolist() == [[4.0, 2.0]] and h["thw"].tolist() == [[2.0, 2.0]]


def test_discs_cover_the_box() -> None:
    cx, cy, r = discs(np.array(0.0), np.array(0.0), np.array(math.pi / 2), 4.0, 2.0)
    assert np.allclose(cx, 0.0) and np.allclose(cy, [-4 / 3, 0.0, 4 / 3])
    assert r == pytest.approx(math.hypot(4 / 6, 1.0))
    # every corner of the box lies in a disc
    assert math.hypot(1.0, 2.0 - 4 / 3) <= float(r) + 1e-12


EGO = (np.array(0.0), np.array(0.0), np.array(0.0), np.array(10.0))


def _ttc(x: float, y: float, psi: float, v: float, near: bool = True) -> float:
    return float(time_to_collision_any(EGO, (4.0, 2.0), (np.array([x]), np.array([y]), np.array([psi]),
                                                         np.array([v])), np.array([4.0]), np.array([2.0]),
                                       np.array([near])))


def test_head_on_on_one_line() -> None:
    reach = 2 * math.hypot(4 / 6, 1.0)  # the front discs' radii
    want = (50.0 - 2 * 4 / 3 - reach) / 20.0  # their centres 4/3 m ahead of each car's centre
    assert _ttc(50.0, 0.0, math.pi, 10.0) == pytest.approx(want)


def test_no_collision_course_and_overlap() -> None:
    assert _ttc(0.0, 3.5, 0.0, 10.0) == math.inf  # side by side in the next lane, same speed
    assert _ttc(30.0, 0.0, 0.0, 12.0) == math.inf  # ahead and faster
    assert _ttc(1.0, 0.5, 0.0, 0.0) == 0.0  # overlapping now
    assert _ttc(50.0, 0.0, math.pi, 10.0, near=False) == math.inf  # not sensed


def test_crossing_traffic() -> None:
    """A car crossing from the right meets the ego's path: its discs reach the ego's as both move."""
    t = _ttc(30.0, -30.0, math.pi / 2, 10.0)
    assert 2.0 < t < 3.0
    assert float(time_to_collision_any(EGO, (4.0, 2.0), (np.zeros(0),) * 4, np.zeros(0), np.zeros(0),
                                       np.zeros(0, bool))) == math.inf
