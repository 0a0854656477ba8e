"""The two solve paths reach the same optimum: the mode search's branch-and-bound run to completion
and the HiGHS path (L1 mode selection, then the exact QP), on random small MPC instances, many of
them with a slow vehicle ahead where the best plan changes lane."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.mpc_worlds import INSTANCE_EGO, INSTANCE_ROUTE, INSTANCE_RULES, controller, make_world, random_instance, rules


@pytest.mark.parametrize("seed", range(20))
def test_mode_search_to_completion_and_highs_agree(tmp_path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    w = random_instance(tmp_path, rng, seed)
    rs = rules(tmp_path, INSTANCE_RULES)
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
    # the B&B is exact for the quadratic cost, within its gap (bnb_gap = 1e-4, relative): never
    # worse than the L1-selected mode's QP by more (mirror-image plans, passing left or right,
    # can differ by less)
    assert exact.cost <= highs.cost * (1 + 1e-4) + 1e-6
    # and the two reach the same optimum within tolerance; a recovering step (a rule already
    # violated now, required from a later step) is a harder instance for the L1 mode selection
    # (seed 2: 2.3 % above the exact optimum)
    tol = 0.05 if exact.message.startswith("recovering") else 0.02
    assert highs.cost <= exact.cost * (1 + tol) + 1e-6


def test_the_only_good_plan_changes_lane(tmp_path) -> None:
    w = make_world(tmp_path, "highway.yaml", INSTANCE_EGO % 14.0, INSTANCE_ROUTE,
                   "[{id: slow, behaviour: constant_velocity, start: {lane: middle, s: 36}, speed: 2.0},"
                   " {id: right, behaviour: constant_velocity, start: {lane: right, s: 22}, speed: 14.0}]",
                   extra="controller: {r_near: 60}", name="overtake")
    rs = rules(tmp_path, INSTANCE_RULES)
    e = w.ego
    x0 = np.array([e.x, e.y, e.psi, e.v])
    exact = controller(w, [rs], solver="modes", time_limit=None).solve(x0, 0.0, w.traffic0)
    highs = controller(w, [rs], solver="highs", time_limit=None).solve(x0, 0.0, w.traffic0)
    assert exact.status == highs.status == "optimal" and exact.binaries > 0
    assert abs(exact.cost - highs.cost) <= 0.02 * exact.cost
    lateral = exact.states[-1, 1] - x0[1]
    assert lateral > 1.0                          # out to the free left lane (a car beside blocks the right)
    assert abs(highs.states[-1, 1] - exact.states[-1, 1]) < 0.5
