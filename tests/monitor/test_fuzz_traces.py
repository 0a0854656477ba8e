"""Trace CSVs fuzzed: a reformatted trace (line endings, quoting, column order, blanks, a BOM,
blank lines) never changes a verdict or a finding, a verdict agrees with its robustness, and
mangled bytes get diagnostics inside the file. The harness is :mod:`twolevel.fuzz.traces`
(benchmarks/fuzz.py runs it for long campaigns)."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.fuzz.traces import PLAIN, generate, probe, write


def _holds(rnd: random.Random) -> None:
    case = generate(rnd)
    outcome = probe(case, variants=3, seed=rnd.randrange(1000))
    assert not outcome.broken, f"{outcome.verdict}: {outcome.detail}\n{write(case, PLAIN, rnd)!r}\n{case.rules}"


@settings(max_examples=60, deadline=None)
@given(st.randoms(use_true_random=False))
def test_reformatting_a_trace_never_changes_a_verdict(rnd: random.Random) -> None:
    _holds(rnd)


@pytest.mark.slow
@settings(max_examples=400, deadline=None)
@given(st.randoms(use_true_random=False))
def test_reformatting_a_trace_never_changes_a_verdict_at_length(rnd: random.Random) -> None:
    _holds(rnd)
