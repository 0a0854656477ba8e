"""The offline monitor is the oracle: every rule's robustness on the returned plan, computed from
the plan's states with the world's own geometry and traffic, is ≥ 0 whenever a step is optimal."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.mpc_worlds import INSTANCE_RULES, controller, random_instance, rules
from twolevel.monitor.robustness import robustness


@pytest.mark.parametrize("seed", range(100, 115))
@pytest.mark.parametrize("solver", ["modes", "highs"])
def test_optimal_plans_satisfy_every_rule_by_the_monitor(tmp_path, seed: int, solver: str) -> None:
    rng = np.random.default_rng(seed)
    w = random_instance(tmp_path, rng, seed)
    rs = rules(tmp_path, INSTANCE_RULES)
    e = w.ego
    x0 = np.array([e.x, e.y, e.psi, e.v])
    res = controller(w, [rs], solver=solver, time_limit=None).solve(x0, 0.0, w.traffic0)
    if res.status != "optimal":
        assert res.status == "fallback"
        return
    xs = res.states
    s, lat = w.route.local_coordinates(xs[:, :2])
    tr = w.traffic0
    t = 0.1 * np.arange(xs.shape[0])
    ox = tr.x[:, None] + tr.v[:, None] * np.cos(tr.psi)[:, None] * t[None]
    oy = tr.y[:, None] + tr.v[:, None] * np.sin(tr.psi)[:, None] * t[None]
    near = np.hypot(tr.x - x0[0], tr.y - x0[1]) <= w.settings.r_near

    def cf(sig, d):  # the high-level collision_free: 1-norm diamond to every nearby vehicle
        dist = np.abs(sig["x"][None] - ox[near]) + np.abs(sig["y"][None] - oy[near])
        return (dist.min(axis=0) if near.any() else np.full(len(sig["x"]), np.inf)) - d

    sig = {"x": xs[:, 0], "y": xs[:, 1], "v": xs[:, 3], "e": lat}
    for r in rs.rules:
        rho = robustness(rs.formula(r.name), sig, 0.1, builtins={"collision_free": cf})[0]
        assert rho >= -1e-6, (r.name, rho)
        assert res.rule_robustness[r.name] == pytest.approx(rho, abs=1e-6)
