"""Geometry properties: arc lengths, projection round trips, lane lookup, box separation."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from twolevel.world.geometry import LaneSet, _clamp, lane_from_reference, sample_road
from twolevel.world.schema import Road

radius = st.floats(5, 2000)
angle = st.floats(-350, 350).filter(lambda a: abs(a) > 1)


@given(radius, angle, st.floats(-3, 3))
@settings(max_examples=60, deadline=None)
def test_arc_length_is_radius_times_angle(r: float, a: float, offset: float) -> None:
    road = Road(id="r", segments=[{"arc": {"radius": r, "angle": a}}])
    ref = sample_road(road)
    assert math.isclose(ref.length, r * math.radians(abs(a)), rel_tol=1e-12)
    lane = lane_from_reference(ref, offset=offset, direction="forward", lane_id="r", index=0, width=3.5)
    inner = r - offset * math.copysign(1, a)
    assert math.isclose(lane.length, inner * math.radians(abs(a)), rel_tol=1e-9)
    # the vertices are on the circle (chords within the 1 mm sagitta)
    assert np.allclose(np.abs(lane.curvature_at(np.linspace(0, lane.length, 7))), 1 / inner)


roads = st.lists(
    st.one_of(st.builds(lambda L: {"line": L}, st.floats(1, 200)),
              st.builds(lambda r, a: {"arc": {"radius": r, "angle": a}}, st.floats(10, 300), st.floats(-120, 120).filter(lambda a: abs(a) > 1))),
    min_size=1, max_size=4,
)


@given(roads, st.floats(0, 1), st.floats(-1.5, 1.5), st.sampled_from(["forward", "backward"]), st.floats(-1.2, 1.2))
@settings(max_examples=80, deadline=None)
def test_projection_of_a_point_on_the_lane_returns_its_s(segs, frac, offset, direction, lateral) -> None:
    # a road that turns by more than 180° can curl back beside itself (or beside the straight
    # extrapolation past an end): a point 1 m off the lane may then be nearer to another part
    # of it, and "its s" is not the nearest (e.g. a 10 m then a 24 m bend, 228° in all)
    assume(sum(abs(g["arc"]["angle"]) for g in segs if "arc" in g) <= 180.0)
    ref = sample_road(Road(id="r", segments=segs, start={"x": 3, "y": -2, "heading": 30}))
    lane = lane_from_reference(ref, offset=offset, direction=direction, lane_id="r", index=0, width=3.5)
    s = frac * lane.length
    p = lane.position(s)
    s2, lat = lane.local_coordinates(p[None])
    assert abs(s2[0] - s) < 1e-6 and abs(lat[0]) < 1e-6
    # sideways too, where the offset point is unambiguous (lateral well inside the radius)
    q = lane.position(s, lateral)
    s3, lat3 = lane.local_coordinates(q[None])
    assert abs(lat3[0] - lateral) < 2e-3
    assert abs(s3[0] - s) < 0.05 * (1 + abs(lateral))


def test_position_heading_and_extrapolation_on_a_straight() -> None:
    ref = sample_road(Road(id="r", segments=[{"line": 100}], start={"heading": 90}))
    lane = lane_from_reference(ref, offset=0, direction="forward", lane_id="r", index=0, width=3.5)
    assert np.allclose(lane.position(np.array([0, 50, 110]), 1.0), [[-1, 0], [-1, 50], [-1, 110]])
    assert np.allclose(lane.heading_at(20.0), math.pi / 2)
    s, lat = lane.local_coordinates(np.array([[2.0, -5.0], [0.0, 120.0]]))
    assert np.allclose(s, [-5, 120]) and np.allclose(lat, [-2, 0])


def test_backward_lane_runs_against_the_drawing() -> None:
    ref = sample_road(Road(id="r", segments=[{"line": 100}]))
    back = lane_from_reference(ref, offset=1.75, direction="backward", lane_id="b", index=0, width=3.5)
    assert np.allclose(back.position(0.0), [100, 1.75]) and np.allclose(back.position(100.0), [0, 1.75])
    assert np.isclose(np.cos(back.heading_at(10.0)), -1)


def test_lane_lookup_tells_lanes_and_directions_apart() -> None:
    ref = sample_road(Road(id="r", segments=[{"line": 100}]))
    east = lane_from_reference(ref, offset=-1.75, direction="forward", lane_id="e", index=0, width=3.5)
    west = lane_from_reference(ref, offset=1.75, direction="backward", lane_id="w", index=1, width=3.5)
    ls = LaneSet.of((east, west))
    lane, s, lat = ls.lookup(np.array([[10, -1.0], [10, 1.0], [10, 9.0]]))
    assert list(lane) == [0, 1, -1] and np.allclose(s[:2], [10, 90]) and np.allclose(lat[:2], [0.75, 0.75])
    lane, _, _ = ls.lookup(np.array([[10, 0.1]]), heading=np.array([0.0]))  # left of centre but eastbound
    assert list(lane) == [0] or list(lane) == [-1]
    p, h = ls.pose(np.array([0, 1]), np.array([30.0, 30.0]))
    assert np.allclose(p, [[30, -1.75], [70, 1.75]]) and np.allclose(np.cos(h), [1, -1])


@settings(max_examples=300, deadline=None)
@given(i=st.one_of(st.integers(-10**6, 10**6), st.lists(st.integers(-10**6, 10**6), min_size=1, max_size=20)),
       lo=st.integers(-50, 50), width=st.integers(-5, 100))
def test_index_clamp_is_np_clip(i, lo, width):
    """The look-ups' index clamp gives np.clip's result, value and type, for scalars and arrays
    (also when the bounds cross: an empty table)."""
    a = np.asarray(i) if isinstance(i, list) else np.intp(i)
    got, want = _clamp(a, lo, lo + width), np.clip(a, lo, lo + width)
    assert type(got) is type(want) and np.array_equal(got, want)


_VALUES = st.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(max_examples=300, deadline=None)
@given(t=st.one_of(_VALUES, st.lists(_VALUES, min_size=1, max_size=20)),
       bounds=st.one_of(st.tuples(_VALUES, _VALUES), st.integers(1, 20).flatmap(
           lambda n: st.tuples(st.lists(_VALUES, min_size=n, max_size=n), st.lists(_VALUES, min_size=n, max_size=n)))))
def test_value_clamp_is_np_clip(t, bounds):
    """The interpolations' and projections' clamp of values gives np.clip's result bit for bit,
    with scalar or per-element bounds (±∞ for an extrapolating end), NaNs and crossed bounds."""
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    a = np.asarray(t, dtype=float) if isinstance(t, list) else np.float64(t)
    if lo.ndim and (np.ndim(a) == 0 or len(a) != len(lo)):
        a = np.resize(np.asarray(a, dtype=float), lo.shape)
    got, want = _clamp(a, lo, hi), np.clip(a, lo, hi)
    assert np.shape(got) == np.shape(want)
    assert np.array_equal(np.asarray(got).view(np.int64), np.asarray(want).view(np.int64))  # bits: ±0, NaNs
