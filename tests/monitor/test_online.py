"""The online monitor: ≡ the offline oracle on every prefix, sound robustness intervals,
verdicts as soon as final, rejection of unbounded future operators, and per-sample work that
does not grow with the window."""

from __future__ import annotations

import copy
import math
from collections import deque

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.monitor import wedge
from twolevel.monitor.online import OnlineMonitor
from twolevel.monitor.robustness import MonitorError, evaluate_rules, robustness
from twolevel.stl import ast as A

from helpers.formulas import formulas, traces

INF = math.inf
DT = 0.1


def _rows(sig: dict[str, np.ndarray]) -> list[dict[str, float]]:
    n = len(next(iter(sig.values())))
    return [{k: float(v[i]) for k, v in sig.items()} for i in range(n)]


def _prefix(sig: dict[str, np.ndarray], m: int) -> dict[str, np.ndarray]:
    return {k: v[:m] for k, v in sig.items()}


@settings(max_examples=300, deadline=None)
@given(formulas(scale=DT, bounded=True), traces(0, 14))
def test_online_equals_offline_on_every_prefix(f: A.Node, sig: dict[str, np.ndarray]) -> None:
    mon = OnlineMonitor(f, DT)
    rows = _rows(sig)
    for m in range(len(rows) + 1):
        with np.errstate(all="ignore"):
            want = robustness(f, _prefix(sig, m), DT)
        got = mon.finish()["formula"]
        assert np.array_equal(got, want, equal_nan=True), (m, got, want)
        # the values already final agree with the prefix's too, once past the look-ahead
        final = mon.final("formula")
        assert len(final) == max(0, m - mon.latency("formula"))
        if m < len(rows):
            mon.update(rows[m])


@settings(max_examples=80, deadline=None)
@given(formulas(scale=DT, bounded=True, max_leaves=4), traces(6, 16))
def test_intervals_contain_the_final_value(f: A.Node, sig: dict[str, np.ndarray]) -> None:
    n = len(sig["x"])
    with np.errstate(all="ignore"):
        full = robustness(f, sig, DT)
    mon = OnlineMonitor(f, DT)
    lat = mon.latency("formula")
    for m, row in enumerate(_rows(sig)):
        if m + lat >= n:  # beyond this, the full trace's end truncates the windows
            break
        mon.update(row)
        for k, lo, hi in mon.pending()["formula"]:
            assert lo <= full[k] <= hi or (math.isnan(full[k])), (k, lo, hi, full[k])
        if m >= lat:
            assert mon.interval_at("formula", m - lat) == (full[m - lat], full[m - lat])


def test_verdicts_are_final_after_the_lookahead_and_intervals_narrow() -> None:
    # eventually within 0.3 s: x > 0
    f = A.Temporal("eventually", A.Interval(0.0, 0.3), A.Compare(">", A.Var("x"), A.Num(0.0)))
    mon = OnlineMonitor(f, DT)
    assert mon.latency("formula") == 3
    assert mon.update({"x": -1.0}) == []
    assert mon.interval_at("formula", 0) == (-1.0, INF)
    assert mon.update({"x": 2.0}) == []
    # already satisfied: lower bound 2 >= 0, before the window has filled
    assert mon.interval_at("formula", 0) == (2.0, INF)
    assert mon.update({"x": -3.0}) == []
    assert mon.update({"x": -4.0}) == [("formula", 0, 2.0)]
    assert mon.interval_at("formula", 0) == (2.0, 2.0)
    assert mon.pending()["formula"] == [(1, 2.0, INF), (2, -3.0, INF), (3, -4.0, INF)]
    # an interval for a sample not yet received: nothing is known
    assert mon.interval_at("formula", 6) == (-INF, INF)
    # finish truncates: eventually over [k, end]
    assert mon.finish()["formula"].tolist() == [2.0, 2.0, -3.0, -4.0]
    # finish does not stop the monitor
    assert mon.update({"x": 5.0}) == [("formula", 1, 5.0)]


def test_negation_swaps_the_bounds() -> None:
    f = A.Not(A.Temporal("always", A.Interval(0.0, 0.2), A.Compare("<", A.Var("x"), A.Num(1.0))))
    mon = OnlineMonitor(f, DT)
    mon.update({"x": 0.0})
    assert mon.interval_at("formula", 0) == (-1.0, INF)


def test_rules_and_references_run_together() -> None:
    rules = [
        A.Rule(name="slow", formula=A.Compare("<=", A.Var("v"), A.Var("v_max"))),
        A.Rule(name="keeps_slow", formula=A.Temporal("always", A.Interval(0.0, 0.2), A.Var("slow"))),
        A.Rule(name="safe", formula=A.Call("collision_free", (A.Var("d"),))),
    ]
    rng = np.random.default_rng(3)
    sig = {"v": rng.normal(10, 2, 30), "v_max": np.full(30, 11.0), "min_gap": rng.uniform(0, 5, 30)}
    mon = OnlineMonitor(rules, DT, consts={"d": 1.0})
    for row in _rows(sig):
        mon.update(row)
    got = mon.finish()
    want = evaluate_rules(rules, sig, DT, consts={"d": 1.0})
    for name in want:
        assert np.array_equal(got[name], want[name]), name


@pytest.mark.parametrize(
    "f",
    [
        A.Temporal("always", None, A.Var("x")),
        A.Temporal("eventually", A.Interval(1.0, INF), A.Var("x")),
        A.BinTemporal("until", None, A.Var("x"), A.Var("x")),
        A.BinTemporal("unless", None, A.Var("x"), A.Var("x")),
    ],
)
def test_unbounded_future_is_rejected(f: A.Node) -> None:
    with pytest.raises(MonitorError, match="cannot run online"):
        OnlineMonitor(f, DT)


def test_unbounded_past_runs() -> None:
    f = A.BinTemporal("since", None, A.Temporal("historically", None, A.Var("x")), A.Var("y"))
    sig = {"x": np.array([3.0, 1.0, 2.0, -1.0]), "y": np.array([-2.0, 0.0, -5.0, 1.0])}
    mon = OnlineMonitor(f, DT)
    out = [mon.update(r) for r in _rows(sig)]
    assert [v for (res,) in out for v in res[2:]] == robustness(f, sig, DT).tolist()


def test_missing_signal_is_a_monitor_error_and_leaves_the_state_intact() -> None:
    f = A.Temporal("historically", A.Interval(0.0, 0.5), A.Compare(">", A.Var("x"), A.Var("y")))
    mon = OnlineMonitor(f, DT)
    mon.update({"x": 1.0, "y": 0.0})
    with pytest.raises(MonitorError) as e:
        mon.update({"x": 1.0})
    assert e.value.name == "y"
    assert mon.samples == 1
    mon.update({"x": 5.0, "y": 0.0})
    assert mon.finish()["formula"].tolist() == [1.0, 1.0]


def test_deepcopy_is_independent() -> None:
    f = A.Temporal("always", A.Interval(0.0, 0.2), A.Var("x"))
    mon = OnlineMonitor(f, DT)
    mon.update({"x": 1.0})
    twin = copy.deepcopy(mon)
    twin.update({"x": -1.0})
    mon.update({"x": 2.0})
    assert mon.finish()["formula"].tolist() == [1.0, 2.0]
    assert twin.finish()["formula"].tolist() == [-1.0, -1.0]


# ----------------------------------------------------------------------------- cost


class _CountingDeque(deque):
    ops = 0

    def append(self, x):  # type: ignore[no-untyped-def]
        _CountingDeque.ops += 1
        super().append(x)

    def pop(self):  # type: ignore[no-untyped-def]
        _CountingDeque.ops += 1
        return super().pop()

    def popleft(self):  # type: ignore[no-untyped-def]
        _CountingDeque.ops += 1
        return super().popleft()


class _CountingList(list):
    ops = 0

    def append(self, x):  # type: ignore[no-untyped-def]
        _CountingList.ops += 1
        super().append(x)

    def pop(self, *a):  # type: ignore[no-untyped-def]
        _CountingList.ops += 1
        return super().pop(*a)


def _work_per_sample(f: A.Node, n: int, seed: int) -> float:
    _CountingDeque.ops = 0
    _CountingList.ops = 0
    rng = np.random.default_rng(seed)
    mon = OnlineMonitor(f, 1.0)
    # a slowly drifting signal with noise: long monotone runs fill the wedges
    x = np.cumsum(rng.normal(0, 1, n))
    y = -np.cumsum(rng.normal(0, 1, n))
    for a, b in zip(x, y):
        mon.update({"x": float(a), "y": float(b)})
    return (_CountingDeque.ops + _CountingList.ops) / n


@pytest.mark.parametrize("op", ["historically", "always", "eventually", "once", "until", "since"])
def test_work_per_sample_does_not_grow_with_the_window(op: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(wedge.MinWedge, "deque_factory", _CountingDeque)
    monkeypatch.setattr(wedge.ClampWindow, "stack_factory", _CountingList)
    p, q = A.Compare(">", A.Var("x"), A.Num(0.0)), A.Compare(">", A.Var("y"), A.Num(0.0))
    costs = []
    for w in (10, 100, 1000):
        iv = A.Interval(0.0, float(w))
        f = A.BinTemporal(op, iv, p, q) if op in ("until", "since") else A.Temporal(op, iv, p)
        costs.append(_work_per_sample(f, 6000, seed=w))
    # amortised O(1): each value enters and leaves each structure once; a bounded constant
    # whatever the window (an O(w) rescan would be ~w operations per sample)
    assert max(costs) <= 8.0, costs
    assert costs[2] <= costs[0] * 1.5 + 0.5, costs


def test_deep_formulas_run_and_too_deep_terms_are_a_monitor_error() -> None:
    f: A.Node = A.Var("x")
    for _ in range(5000):
        f = A.Not(f)
    mon = OnlineMonitor(f, DT)
    mon.update({"x": 2.0})
    assert mon.finish()["formula"].tolist() == [2.0]
    t: A.Node = A.Var("x")
    for _ in range(20000):
        t = A.Neg(t)
    with pytest.raises(MonitorError, match="nested too deeply"):
        OnlineMonitor(A.Compare(">", t, A.Num(0.0)), DT)


@pytest.mark.parametrize(
    "f",
    [
        A.Temporal("eventually", A.Interval(0.0, 1e300), A.Compare("<=", A.Var("x"), A.Num(1.0))),
        A.Temporal("always", A.Interval(0.3, 1e300), A.Var("x")),
        A.BinTemporal("until", A.Interval(0.0, 1e300), A.Var("x"), A.Var("y")),
        A.BinTemporal("unless", A.Interval(0.2, 1e300), A.Var("x"), A.Var("y")),
    ],
    ids=["eventually", "always", "until", "unless"],
)
def test_finish_with_a_huge_window_pads_only_what_it_owes(f: A.Node) -> None:
    # 1e300 s at dt 0.1 is 1e301 samples of padding: finish() used to push every one (a hang).
    sig = {"x": np.array([3.0, 1.0, -2.0, 0.5, 4.0]), "y": np.array([-1.0, 2.0, -3.0, 0.0, -1.0])}
    mon = OnlineMonitor(f, DT)
    for m, row in enumerate(_rows(sig)):
        mon.update(row)
        want = robustness(f, _prefix(sig, m + 1), DT)
        assert np.array_equal(mon.finish()["formula"], want), m


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-5, 5), max_size=12), st.integers(1, 6), st.integers(0, 20), st.booleans())
def test_wedge_skip_equals_pushing_the_pad(xs: list[float], width: int, m: int, is_min: bool) -> None:
    pad = INF if is_min else -INF
    a, b = ((wedge.MinWedge(width), wedge.MinWedge(width)) if is_min else (wedge.MaxWedge(width), wedge.MaxWedge(width)))
    for x in xs:
        a.push(x)
        b.push(x)
    for _ in range(m):
        a.push(pad)
    b.skip(m, pad)
    assert (list(a.vals), list(a.idx), a.count) == (list(b.vals), list(b.idx), b.count)
    assert a.push(pad) == b.push(pad)
