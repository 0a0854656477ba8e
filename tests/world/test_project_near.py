"""The pruned route projection (Route.project_near) equals the dense search over every interval
of each window, bit for bit, on the shipped scenarios' routes and random points."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from helpers.world_files import load_world

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module", params=["scalability", "traffic_rules", "safety", "comparison"])
def route(request):  # noqa: ANN001, ANN201
    return load_world(ROOT / "scenarios" / f"{request.param}.yaml").route


def project_near_dense(route, points: np.ndarray, s_center: np.ndarray,  # noqa: ANN001
                       half_window: float) -> tuple[np.ndarray, np.ndarray]:
    """Route.project_near onto every interval of each window: the reference the pruned search
    is compared with."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    n = len(route.s) - 1
    w = min(int(math.ceil(2 * half_window / route.spacing)) + 2, n)
    i0 = np.clip(np.floor((np.asarray(s_center, dtype=float) - half_window) / route.spacing).astype(int), 0, n - w)
    idx = i0[:, None] + np.arange(w)[None, :]  # (M, W) interval indices
    a = route.points[idx]
    d = route.points[idx + 1] - a
    l2 = np.einsum("mkj,mkj->mk", d, d)
    rel = pts[:, None, :] - a
    t_raw = np.einsum("mkj,mkj->mk", rel, d) / np.where(l2 > 0, l2, 1.0)
    t = np.clip(t_raw, np.where(idx == 0, -np.inf, 0.0), np.where(idx == n - 1, np.inf, 1.0))
    diff = rel - t[..., None] * d
    dist2 = np.einsum("mkj,mkj->mk", diff, diff)
    k = np.argmin(dist2, axis=1)
    m = np.arange(len(pts))
    i = idx[m, k]
    s = route.s[i] + t[m, k] * (route.s[i + 1] - route.s[i])
    cross = d[m, k, 0] * rel[m, k, 1] - d[m, k, 1] * rel[m, k, 0]
    return s, cross / np.sqrt(np.where(l2[m, k] > 0, l2[m, k], 1.0))


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
    s2, e2 = project_near_dense(route, pts, centre, half)
    assert np.array_equal(s1, s2)
    assert np.array_equal(e1, e2)


def test_on_route_points_project_to_themselves(route) -> None:  # noqa: ANN001
    s = np.linspace(0.0, float(route.s[-1]), 97)
    got_s, got_e = route.project_near(route.position(s), s, 5.0)
    np.testing.assert_allclose(got_s, s, atol=1e-6)
    np.testing.assert_allclose(got_e, 0.0, atol=1e-6)
