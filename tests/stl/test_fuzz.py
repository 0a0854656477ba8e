"""Whatever the text, checking it returns diagnostics and never raises."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.stl.lint import check_source

PIECES = [
    "input", "output", "const", "float", "int", "specification", "import x", "r", "v", "s", "=", "==", "!==",
    "!=", "<", "<=", ">", ">=", "+", "-", "*", "/", "(", ")", "[", "]", ":", ",", ";", "\n", " ", "0", "1.5",
    "2ms", "3s", "1e999", "always", "G", "eventually", "until", "U", "since", "not", "!", "and", "&", "or",
    "|", "->", "<->", "xor", "rise", "fall", "abs", "true", "false", "collision_free", "foo", "next", "prev",
    "//c\n", "/*", "*/", "$", "é", "\t",
]


@settings(max_examples=400, deadline=None)
@given(st.lists(st.sampled_from(PIECES), max_size=40).map(" ".join), st.sampled_from([None, 0.1]))
def test_never_raises(text: str, dt: float | None) -> None:
    result = check_source(text, "fuzz.stl", dt=dt, horizon=10)
    for d in result.diagnostics:
        assert d.code.startswith("STL") and d.span.line >= 1 and d.span.column >= 1
    assert result.rulefile is not None or any(d.is_error for d in result.diagnostics)
    assert (result.ruleset is None) == (result.rulefile is None)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=80))
def test_never_raises_on_any_unicode(text: str) -> None:
    check_source(text, "fuzz.stl")


# ----------------------------------------------------------------------------- the fuzzing harness
# twolevel.fuzz.rules writes files from the grammar and mangles them (line endings, odd characters,
# long chains, edge numbers); its probe holds check, the renderers, the printer and the monitor
# to the invariant. benchmarks/fuzz.py runs the same harness for long campaigns.

from twolevel.fuzz.rules import generate, probe  # noqa: E402


def _holds(rnd) -> None:
    text = generate(rnd)
    outcome = probe(text, dt=rnd.choice([None, 0.1]), horizon=rnd.choice([None, 10]), seed=rnd.randrange(1000))
    assert not outcome.broken, f"{outcome.verdict}: {outcome.detail}\n{text!r}"


@settings(max_examples=150, deadline=None)
@given(st.randoms(use_true_random=False))
def test_generated_rule_files_hold_the_invariant(rnd) -> None:
    _holds(rnd)


@pytest.mark.slow
@settings(max_examples=1000, deadline=None)
@given(st.randoms(use_true_random=False))
def test_generated_rule_files_hold_the_invariant_at_length(rnd) -> None:
    _holds(rnd)
