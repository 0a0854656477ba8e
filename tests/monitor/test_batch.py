"""The batched monitor equals the offline oracle, candidate by candidate."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import formulas as F
from twolevel.monitor.batch import robustness_batch
from twolevel.monitor.errors import MonitorError
from twolevel.monitor.robustness import robustness
from twolevel.stl import ast as A
from twolevel.stl.parser import parse


def _stack(traces: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {k: np.stack([tr[k] for tr in traces]) for k in traces[0]}


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 12).flatmap(lambda n: st.lists(F.signals(n), min_size=1, max_size=4)), F.formulas())
def test_equals_oracle_row_by_row(traces: list[dict[str, np.ndarray]], formula: A.Node) -> None:
    batch = robustness_batch(formula, _stack(traces), 1.0)
    for k, tr in enumerate(traces):
        np.testing.assert_array_equal(batch[k], robustness(formula, tr, 1.0))


def test_shared_signals_broadcast_and_builtin() -> None:
    rf, _ = parse("input float v\ninput float min_gap\nr = always[0:0.2] collision_free(1.0) and once[0:0.3] (v <= 2);", "x.stl")
    assert rf is not None
    formula = rf.rules[0].formula
    v = np.array([[0.0, 1.0, 3.0, 4.0, 5.0], [3.0, 3.0, 3.0, 3.0, 1.0]])
    gap = np.array([5.0, 4.0, 0.5, 2.0, 3.0])  # shared by both candidates
    out = robustness_batch(formula, {"v": v, "min_gap": gap}, 0.1)
    for k in range(2):
        np.testing.assert_allclose(out[k], robustness(formula, {"v": v[k], "min_gap": gap}, 0.1))


def test_missing_signal_is_a_monitor_error() -> None:
    with pytest.raises(MonitorError):
        robustness_batch(A.Compare("<", A.Var("q"), A.Num(1.0)), {"v": np.zeros((2, 3))}, 0.1)


@settings(max_examples=50, deadline=None)
@given(st.integers(2, 10).flatmap(lambda n: st.lists(F.signals(n), min_size=1, max_size=3)), F.formulas(),
       st.integers(0, 30))
def test_signals_the_formula_does_not_read_change_nothing(traces, formula, extra):
    """The batch evaluator makes (K, T) views of the signals a formula reads, when it reads them:
    with many more signals beside (shared or per candidate) the robustness is the same, bit for bit."""
    signals = _stack(traces)
    K, T = next(iter(signals.values())).shape
    rng = np.random.default_rng(extra)
    more = {**signals, **{f"unused_{i}": rng.normal(size=(K, T) if i % 2 else T) for i in range(extra)}}
    assert np.array_equal(robustness_batch(formula, more, 1.0), robustness_batch(formula, signals, 1.0),
                          equal_nan=True)


def test_a_signal_with_more_than_two_axes_is_refused():
    rf, _ = parse("input float v\nr = always (v <= 2);", "x.stl")
    assert rf is not None
    with pytest.raises(MonitorError, match=r"\(K, T\) or \(T,\)"):
        robustness_batch(rf.rules[0].formula, {"v": np.zeros((2, 4)), "w": np.zeros((2, 3, 4))}, 0.1)
