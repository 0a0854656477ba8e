"""The two solve paths reach the same optimum: the mode search's branch-and-bound run to completion
and the HiGHS path (L1 mode selection, then the exact QP), on random small MPC instances, many of
them with a slow vehicle ahead where the best plan changes lane."""

from __future__ import annotations

import numpy as np
import pytest

from mpc_worlds import controller, make_world, rules

EGO = "{start: {lane: middle, s: 20}, speed: %.2f, desired_speed: 15.0}"
ROUTE = "{start: {lane: middle, s: 20}, goal: {lane: middle, s: 900}, stop_at_goal: false}"
RULES = ("input float e\ninput float v\nno_collision = always[0:1] collision_free(5);\n"
         "on_road = always[0:1] ((e <= 4.5) and (e >= -4.5));\nspeed = always[0:1] (v <= 16);\n")


def _instance(tmp_path, rng: np.random.Generator, i: int):
    n = int(rng.integers(1, 4))
    parts = []
    for j in range(n):
        lane = ["middle", "left", "right"][int(rng.integers(0, 3))] if j else "middle"
        s = float(rng.uniform(28, 34)) if j == 0 else float(rng.uniform(22, 45))
        v = float(rng.uniform(0, 6)) if j == 0 else float(rng.uniform(5, 15))
        parts.append(f"{{id: v{j}, behaviour: constant_velocity, start: {{lane: {lane}, s: {s:.2f}}}, speed: {v:.2f}}}")
    w = make_world(tmp_path, "highway.yaml", EGO % float(rng.uniform(8, 15)), ROUTE, "[" + ", ".join(parts) + "]",
                   extra="controller: {r_near: 60}", name=f"inst{i}")
    return w


@pytest.mark.parametrize("seed", range(20))
def test_mode_search_to_completion_and_highs_agree(tmp_path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    w = _instance(tmp_path, rng, seed)
    rs = rules(tmp_path, RULES)
    e = w.ego
    x0 = np.array([e.x, e.y, e.psi, e.v])
    # refresh=False: the same (minimal) encoding on both paths, so the models are identical
    exact = controller(w, [rs], solver="modes", time_limit=None, relinearise=False, refresh=False).solve(
        x0, 0.0, w.traffic0)
    highs = controller(w, [rs], solver="highs", time_limit=None, relinearise=False).solve(x0, 0.0, w.traffic0)
    assert exact.binaries == highs.binaries and exact.rows == highs.rows
    assert exact.ok == highs.ok                   # both find a plan, or both prove there is none
    if not exact.ok:
        assert exact.status == highs.status == "fallback" and exact.certified
        return
    assert exact.status == highs.status == "optimal" and exact.certified
    # the B&B is exact for the quadratic cost: never worse than the L1-selected mode's QP
    assert exact.cost <= highs.cost * (1 + 1e-6) + 1e-6
    # and the two reach the same optimum within tolerance; a recovering step (a rule already
    # violated now, required from a later step) is a harder instance for the L1 mode selection
    # (seed 2: 2.3 % above the exact optimum)
    tol = 0.05 if exact.message.startswith("recovering") else 0.02
    assert highs.cost <= exact.cost * (1 + tol) + 1e-6


def test_the_only_good_plan_changes_lane(tmp_path) -> None:
    w = make_world(tmp_path, "highway.yaml", EGO % 14.0, ROUTE,
                   "[{id: slow, behaviour: constant_velocity, start: {lane: middle, s: 36}, speed: 2.0},"
                   " {id: right, behaviour: constant_velocity, start: {lane: right, s: 22}, speed: 14.0}]",
                   extra="controller: {r_near: 60}", name="overtake")
    rs = rules(tmp_path, RULES)
    e = w.ego
    x0 = np.array([e.x, e.y, e.psi, e.v])
    exact = controller(w, [rs], solver="modes", time_limit=None).solve(x0, 0.0, w.traffic0)
    highs = controller(w, [rs], solver="highs", time_limit=None).solve(x0, 0.0, w.traffic0)
    assert exact.status == highs.status == "optimal" and exact.binaries > 0
    assert abs(exact.cost - highs.cost) <= 0.02 * exact.cost
    lateral = exact.states[-1, 1] - x0[1]
    assert lateral > 1.0                          # out to the free left lane (a car beside blocks the right)
    assert abs(highs.states[-1, 1] - exact.states[-1, 1]) < 0.5
