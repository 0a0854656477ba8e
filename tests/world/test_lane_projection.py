"""LaneSet.project picks each point's nearest interval of its lane by a linear first-minimum per
group (geometry._first_min) instead of sorting every (point, interval) pair: the same choice as
the sort, bit for bit, on random values and on the shipped junction maps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from helpers.world_files import load_world
from twolevel.world.geometry import _first_min

ROOT = Path(__file__).resolve().parents[2]


def first_min_sorted(values: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The earlier selection: a stable sort by (group, value), the first of each group."""
    group = np.repeat(np.arange(len(counts)), counts)
    order = np.lexsort((values, group))
    return order[np.concatenate([[True], group[order][1:] != group[order][:-1]])]


@settings(max_examples=100, deadline=None)
@given(counts=st.lists(st.integers(1, 6), min_size=1, max_size=12), data=st.data())
def test_first_min_is_the_sorted_selection(counts, data):
    """Ties (few distinct values), infinities and NaNs included."""
    counts = np.array(counts)
    pool = st.sampled_from([0.0, 1.0, 2.5, np.inf, np.nan]) | st.floats(0.0, 10.0)
    values = np.array(data.draw(st.lists(pool, min_size=int(counts.sum()), max_size=int(counts.sum()))))
    assert np.array_equal(_first_min(values, counts), first_min_sorted(values, counts))


@pytest.fixture(scope="module", params=["four_way_stop_crossing", "left_turn_stream", "yield_priority_road"])
def lanes(request):  # noqa: ANN001, ANN201
    return load_world(ROOT / "scenarios" / "traffic" / f"{request.param}.yaml").lanes


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_projection_is_the_nearest_interval_of_each_lane(lanes, seed):
    """Random points near the map onto random lanes: s and lateral equal those from the
    nearest interval chosen by the sort (ties to the first), within rounding of the formula."""
    rng = np.random.default_rng(seed)
    n = 60
    lane = rng.integers(0, len(lanes.length), n)
    lo, hi = lanes.points.min(axis=0) - 20.0, lanes.points.max(axis=0) + 20.0
    pts = rng.uniform(lo, hi, (n, 2))
    s, lat = lanes.project(lane, pts)
    for i in range(n):  # the reference: every interval of the lane, one point at a time
        k = np.arange(lanes.vptr[lane[i]], lanes.vptr[lane[i] + 1] - 1)
        a, d = lanes.points[k], lanes.points[k + 1] - lanes.points[k]
        l2 = np.einsum("kj,kj->k", d, d)
        rel = pts[i] - a
        t = np.einsum("kj,kj->k", rel, d) / np.where(l2 > 0, l2, 1.0)
        t = np.clip(t, np.where(k == k[0], -np.inf, 0.0), np.where(k == k[-1], np.inf, 1.0))
        diff = rel - t[:, None] * d
        dist2 = np.where(l2 > 0, np.einsum("kj,kj->k", diff, diff), np.inf)
        j = first_min_sorted(dist2, np.array([len(k)]))[0]
        s_ref = lanes.key[k[j]] + t[j] * (lanes.key[k[j] + 1] - lanes.key[k[j]]) - lanes.base[lane[i]]
        lat_ref = (d[j, 0] * rel[j, 1] - d[j, 1] * rel[j, 0]) / np.sqrt(l2[j])
        assert s[i] == pytest.approx(s_ref, abs=1e-9) and lat[i] == pytest.approx(lat_ref, abs=1e-9)
