"""The encoding agrees with the offline monitor (the oracle) on random formulas and trajectories."""

from __future__ import annotations

import numpy as np
import pytest

from twolevel.monitor.robustness import robustness

from helpers.milp_oracle import check_optimal_robustness, check_satisfaction_of_a_fixed_trajectory
from helpers.milp_systems import DT, PAST, T, random_formula, with_known

NOW = PAST  # trace index of the current sample
SEEDS = range(120)


def _case(seed: int):
    rng = np.random.default_rng(seed)
    f = random_formula(rng, depth=int(rng.integers(1, 4)))
    p_past = rng.uniform(-2, 2, PAST + 1)
    v_past = rng.uniform(-1, 1, PAST + 1)
    c = rng.uniform(-2, 2, T)
    times = (NOW,) if rng.random() < 0.7 else (NOW, NOW + 2)
    return rng, f, p_past, v_past, c, times


def _monitor(f, p, v, c, times):
    rho = robustness(f, {"p": p, "v": v, "c": c}, DT)
    return min(float(rho[t]) for t in times)


@pytest.mark.parametrize("seed", SEEDS)
def test_satisfaction_of_a_fixed_trajectory_matches_the_monitor(seed: int) -> None:
    rng, f, p_past, v_past, c, times = _case(seed)
    check_satisfaction_of_a_fixed_trajectory(rng, f, times, p_past, v_past, with_known(p_past, v_past, c),
                                             lambda p, v: _monitor(f, p, v, c, times))


@pytest.mark.parametrize("seed", SEEDS)
def test_optimal_robustness_equals_the_monitor_of_the_plan(seed: int) -> None:
    _, f, p_past, v_past, c, times = _case(seed)
    check_optimal_robustness(f, times, p_past, v_past, with_known(p_past, v_past, c),
                             lambda p, v: _monitor(f, p, v, c, times))
