"""The pruned route projection (Route.project_near) equals the dense search over every interval
of each window, bit for bit, on the shipped scenarios' routes and random points."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from twolevel.world.loader import load_scenario
from twolevel.world.world import build_world

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module", params=["scalability", "traffic_rules", "safety", "comparison"])
def route(request):  # noqa: ANN001, ANN201
    scn, _ = load_scenario(ROOT / "scenarios" / f"{request.param}.yaml")
    return build_world(scn).route


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), half=st.sampled_from([0.3, 3.0, 15.0, 45.0, 83.0, 1e4]),
       spread=st.floats(0.0, 40.0))
def test_pruned_equals_dense(route, seed: int, half: float, spread: float) -> None:  # noqa: ANN001
    rng = np.random.default_rng(seed)
    L = float(route.s[-1])
    M = 300
    centre = rng.uniform(-20.0, L + 20.0, M)
    near = route.position(np.clip(centre + rng.normal(0.0, spread + 1e-3, M), -10.0, L + 10.0),
                          rng.normal(0.0, spread + 1e-3, M))
    pts = near + rng.normal(0.0, 2.0, (M, 2))
    s1, e1 = route.project_near(pts, centre, half)
    s2, e2 = route._project_near_dense(pts, centre, half)
    assert np.array_equal(s1, s2)
    assert np.array_equal(e1, e2)


def test_on_route_points_project_to_themselves(route) -> None:  # noqa: ANN001
    s = np.linspace(0.0, float(route.s[-1]), 97)
    got_s, got_e = route.project_near(route.position(s), s, 5.0)
    np.testing.assert_allclose(got_s, s, atol=1e-6)
    np.testing.assert_allclose(got_e, 0.0, atol=1e-6)
