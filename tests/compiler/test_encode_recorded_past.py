"""A past operator's window over the recorded past (the trace's settled prefix) is one constant,
the offline monitor's robustness of its operand there (twolevel.compiler.evaluator): the encoding
still agrees with the monitor over long pasts, and the tree holds one leaf for the whole past."""

from __future__ import annotations

import numpy as np
import pytest

from twolevel.compiler.evaluator import Evaluator
from twolevel.compiler.signals import TraceSignals
from twolevel.compiler.tree import IntervalBounds, Op
from twolevel.milp.builder import ModelBuilder
from twolevel.monitor.robustness import robustness
from twolevel.stl import ast

from helpers.milp_oracle import check_optimal_robustness, check_satisfaction_of_a_fixed_trajectory
from helpers.milp_systems import DT, H, double_integrator, random_formula, with_known

PAST = 40  # recorded samples before now
SEEDS = range(40)


def _case(seed: int):
    """A random formula under a past operator whose window reaches 1–4 s back, over a long past."""
    rng = np.random.default_rng(1000 + seed)
    op = ["once", "historically"][int(rng.integers(0, 2))]
    a = int(rng.integers(0, 3))
    b = a + int(rng.integers(10, 40))
    f = ast.Temporal(op, ast.Interval(a * DT, b * DT), random_formula(rng, depth=int(rng.integers(0, 3))))
    if rng.random() < 0.5:
        f = ast.Temporal("always", ast.Interval(0.0, 5 * DT), f)  # required over the horizon, as the rules are
    p_past = np.cumsum(rng.uniform(-0.2, 0.2, PAST + 1))
    v_past = rng.uniform(-1, 1, PAST + 1)
    c = rng.uniform(-2, 2, PAST + 1 + H)
    return rng, f, p_past, v_past, c


def _monitor(f, c):
    return lambda p, v: float(robustness(f, {"p": p, "v": v, "c": c}, DT)[PAST])


@pytest.mark.parametrize("seed", SEEDS)
def test_satisfaction_over_a_long_past_matches_the_monitor(seed: int) -> None:
    rng, f, p_past, v_past, c = _case(seed)
    check_satisfaction_of_a_fixed_trajectory(rng, f, (PAST,), p_past, v_past, with_known(p_past, v_past, c),
                                             _monitor(f, c))


@pytest.mark.parametrize("seed", SEEDS)
def test_optimal_robustness_over_a_long_past_equals_the_monitor(seed: int) -> None:
    _, f, p_past, v_past, c = _case(seed)
    check_optimal_robustness(f, (PAST,), p_past, v_past, with_known(p_past, v_past, c), _monitor(f, c))


class _Reads(TraceSignals):
    """The trace's signals, noting every sample read as a tree leaf."""

    def __init__(self, *args, **kwargs) -> None:  # noqa: ANN002, ANN003
        super().__init__(*args, **kwargs)
        self.read: set[tuple[str, int]] = set()

    def at(self, name, k, node=None):  # noqa: ANN001, ANN201
        self.read.add((name, k))
        return super().at(name, k, node)


def _evaluator(p_past: np.ndarray) -> tuple[Evaluator, _Reads]:
    b = ModelBuilder()
    _, _, _, sig = double_integrator(b, p_past, np.zeros(len(p_past)))
    b.build()
    table = _Reads(sig)
    return Evaluator(table, DT, IntervalBounds(b)), table


def test_the_recorded_past_is_one_leaf_equal_to_the_monitors() -> None:
    rng = np.random.default_rng(7)
    p_past = rng.uniform(-2, 2, PAST + 1)
    ev, table = _evaluator(p_past)
    phi = ast.Compare("<=", ast.Var("p"), ast.Num(1.0))
    f = ast.Temporal("once", ast.Interval(0.0, 3.0), phi)  # 30 samples back
    for k in range(1, H + 1):
        tree = ev.rob(f, PAST + k, 1.0)
        assert isinstance(tree, Op) and tree.is_max
        consts = [x for x in tree.kids if isinstance(x, float)]
        # one constant for the window's recorded part (now included), one leaf per planned step
        assert len(tree.kids) == k + 1 and len(consts) == 1, tree
        lo = PAST + k - 30
        assert consts[0] == pytest.approx(float(np.max(1.0 - p_past[lo:])))
    assert isinstance(ev.rob(f, PAST, 1.0), float)  # now: wholly recorded, a constant
    assert not {k for _, k in table.read if k <= PAST}  # no recorded sample became a leaf
    neg = ev.rob(f, PAST + 2, -1.0)  # negated: the min of the negated values
    assert isinstance(neg, Op) and not neg.is_max
    assert [x for x in neg.kids if isinstance(x, float)][0] == pytest.approx(-float(np.max(1.0 - p_past[PAST - 28:])))


def test_an_operand_reading_ahead_stops_before_the_plan() -> None:
    """once[0:3] eventually[0:0.5] p <= 1: the recorded part ends 5 samples before now; the
    samples from there on read the plan and stay leaves."""
    rng = np.random.default_rng(8)
    p_past = rng.uniform(-2, 2, PAST + 1)
    ev, table = _evaluator(p_past)
    inner = ast.Temporal("eventually", ast.Interval(0.0, 0.5), ast.Compare("<=", ast.Var("p"), ast.Num(1.0)))
    done = ev.recorded(inner)
    assert done is not None and len(done) == PAST + 1 - 5
    ref = robustness(inner, {"p": p_past}, DT)
    np.testing.assert_allclose(done, ref[:PAST + 1 - 5])
    tree = ev.rob(ast.Temporal("once", ast.Interval(0.0, 3.0), inner), PAST + 1, 1.0)
    assert isinstance(tree, Op) and sum(isinstance(x, float) for x in tree.kids) <= 1
    assert min(k for _, k in table.read) == PAST + 1 - 5  # leaves from the first sample reading the plan
