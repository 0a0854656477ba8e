"""Quantifiers over participants in the monitors: the offline oracle evaluates them directly,
and equals the expansion into the language without them (``present[p] -> body(p)``); the batched
monitor equals the oracle row by row, the online monitor equals it sample by sample, and RTAMT
0.4.10 agrees on the expanded formulas."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from twolevel.monitor.batch import robustness_batch
from twolevel.monitor.errors import MonitorError
from twolevel.monitor.online import OnlineMonitor
from twolevel.monitor.robustness import robustness
from twolevel.monitor.tracefile import monitor_trace, read_trace
from twolevel.stl import ast as A
from twolevel.stl.analysis import expand_quantifiers, participants_in
from twolevel.stl.parser import parse

from helpers.formulas import PARTICIPANTS, participant_traces, quantified_formulas

SLOW = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _pids(sig: dict[str, np.ndarray]) -> list[str]:
    return participants_in(sig)


@SLOW
@given(quantified_formulas(), participant_traces(1, 12))
def test_offline_equals_the_expansion(f: A.Node, sig: dict[str, np.ndarray]) -> None:
    got = robustness(f, sig, 1.0)
    want = robustness(expand_quantifiers(f, _pids(sig)), sig, 1.0)
    assert np.array_equal(got, want, equal_nan=True)


@SLOW
@given(quantified_formulas(), participant_traces(1, 10), participant_traces(1, 10))
def test_batch_equals_the_oracle_row_by_row(f: A.Node, one: dict[str, np.ndarray], two: dict[str, np.ndarray]) -> None:
    n = min(len(one["x"]), len(two["x"]))
    keys = sorted(set(one) & set(two))
    sig = {k: np.stack([one[k][:n], two[k][:n]]) for k in keys}
    rows = robustness_batch(f, sig, 1.0)
    for i, trace in enumerate(({k: one[k][:n] for k in keys}, {k: two[k][:n] for k in keys})):
        assert np.array_equal(rows[i], robustness(f, trace, 1.0), equal_nan=True)


@SLOW
@given(quantified_formulas(bounded=True), participant_traces(1, 12))
def test_online_equals_the_oracle(f: A.Node, sig: dict[str, np.ndarray]) -> None:
    mon = OnlineMonitor(f, 1.0, participants=_pids(sig))
    n = len(sig["x"])
    for k in range(n):
        mon.update({name: float(col[k]) for name, col in sig.items()})
    want = robustness(f, sig, 1.0)
    final = mon.final("formula")
    assert np.array_equal(final, want[: len(final)], equal_nan=True)  # the values final so far
    assert np.array_equal(mon.finish()["formula"], want, equal_nan=True)


def _rule(text: str) -> A.Node:
    rf, diags = parse(f"r = {text};", "q.stl")
    assert rf is not None, diags
    return rf.rules[0].formula


def test_no_participant_present_makes_forall_true_and_exists_false() -> None:
    sig = {"x": np.zeros(3), "present[a]": np.full(3, -np.inf), "p[a]": np.full(3, -5.0)}
    assert robustness(_rule("forall o in vehicles: p(o) > 0"), sig, 1.0).tolist() == [math.inf] * 3
    assert robustness(_rule("exists o in vehicles: p(o) > 0"), sig, 1.0).tolist() == [-math.inf] * 3
    none = {"x": np.zeros(3)}
    assert robustness(_rule("forall o in vehicles: p(o) > 0"), none, 1.0).tolist() == [math.inf] * 3


def test_the_worst_present_participant_decides() -> None:
    sig = {"x": np.zeros(4),
           "present[a]": np.array([np.inf, np.inf, -np.inf, -np.inf]), "p[a]": np.array([1.0, -2.0, -9.0, -9.0]),
           "present[b]": np.array([np.inf, -np.inf, np.inf, -np.inf]), "p[b]": np.array([3.0, -7.0, 4.0, -9.0])}
    assert robustness(_rule("forall o in vehicles: p(o) > 0"), sig, 1.0).tolist() == [1.0, -2.0, 4.0, math.inf]
    assert robustness(_rule("exists o in vehicles: p(o) > 0"), sig, 1.0).tolist() == [3.0, -2.0, 4.0, -math.inf]


def test_a_body_reads_its_participant_over_the_whole_trace() -> None:
    """Temporal operators inside the body see the participant's samples where it is absent too
    (its absent values): ``once`` remembers a cut-in of a participant that has since left."""
    sig = {"x": np.zeros(4), "present[a]": np.array([np.inf, -np.inf, np.inf, np.inf]),
           "p[a]": np.array([2.0, -1.0, -1.0, -1.0])}
    f = _rule("forall o in vehicles: not once[0:2] (p(o) > 0)")
    assert robustness(f, sig, 1.0).tolist() == [-2.0, math.inf, -2.0, 1.0]


def test_online_needs_the_participants() -> None:
    with pytest.raises(MonitorError, match="participants"):
        OnlineMonitor(_rule("forall o in vehicles: p(o) > 0"), 0.1)


def test_a_participant_without_its_column_is_reported() -> None:
    sig = {"x": np.zeros(2), "present[a]": np.full(2, np.inf)}
    with pytest.raises(MonitorError, match=r"p\[a\]"):
        robustness(_rule("forall o in vehicles: p(o) > 0"), sig, 1.0)


def _csv(tmp_path: Path, text: str) -> str:
    p = tmp_path / "trace.csv"
    p.write_text(text, encoding="utf-8")
    return str(p)


def test_monitor_reads_participant_columns(tmp_path: Path) -> None:
    """present[ID] may be written 1/0 (normalised to +inf/-inf); NAME[ID] is its signal."""
    path = _csv(tmp_path, "t,v,present[lead],d_lon[lead],present[car 2],d_lon[car 2]\n"
                          "0,10,1,30,0,inf\n0.1,10,1,4,1,50\n0.2,10,0,inf,1,3\n")
    trace, diags = read_trace(path)
    assert trace is not None and not diags
    assert trace.columns["present[lead]"].tolist() == [math.inf, math.inf, -math.inf]
    rf, _ = parse("input float v\nsafe = forall o in vehicles: (d_lon(o) >= 0.5 * v);", "r.stl")
    report, diags = monitor_trace(rf, {}, trace, series=True)
    assert not diags
    assert report.rules[0].series.tolist() == [25.0, -1.0, -2.0]
    assert report.rules[0].first_violation_t == pytest.approx(0.1)


def test_monitor_reports_a_missing_participant_column_and_no_participants(tmp_path: Path) -> None:
    rf, _ = parse("input float v\nsafe = forall o in vehicles: (d_lon(o) >= 0.5 * v);", "r.stl")
    trace, _ = read_trace(_csv(tmp_path, "t,v,present[lead]\n0,1,1\n0.1,1,1\n"))
    report, diags = monitor_trace(rf, {}, trace)
    assert [d.code for d in diags] == ["SIM602"] and "d_lon[lead]" in diags[0].message
    assert report.rules == ()
    trace, _ = read_trace(_csv(tmp_path, "t,v\n0,1\n0.1,1\n"))
    report, diags = monitor_trace(rf, {}, trace)
    assert [(d.code, d.is_error) for d in diags] == [("SIM609", True)]  # not a vacuous +inf
    assert report.rules == () and [(u.name, u.code) for u in report.unjudged] == [("safe", "SIM609")]


def test_participants_in_keeps_the_trace_order() -> None:
    assert participants_in(["t", "present[b]", "d_lon[b]", "present[a]", "present[]", "x[a"]) == ["b", "a"]
    assert list(PARTICIPANTS) == ["a", "b", "c"]
