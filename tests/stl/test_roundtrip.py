"""parse(print(ast)) == ast over generated ASTs, and the printer's text is warning-free."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.stl.ast import (
    Abs, Arith, BinTemporal, Binary, BoolConst, Call, Compare, Declaration, Edge, Interval, Neg, Not, Num,
    ParticipantSignal, Quantifier, Rule, RuleFile, Temporal, Var,
)
from twolevel.stl.parser import parse
from twolevel.stl.printer import format_file, format_formula
from twolevel.stl.typecheck import typecheck

NAMES = ["v", "x", "d_stop", "v_max", "a1", "b_2"]
names = st.sampled_from(NAMES)
numbers = st.one_of(
    st.integers(0, 1000).map(float),
    st.floats(0.0, 1e6, allow_nan=False, allow_infinity=False).map(abs),
    st.floats(1e-9, 1e-3),
)
terms = st.recursive(
    st.one_of(numbers.map(Num), names.map(Var)),
    lambda t: st.one_of(
        st.builds(Neg, t),
        st.builds(Arith, st.sampled_from(["+", "-", "*", "/"]), t, t),
        st.builds(Abs, t),
    ),
    max_leaves=5,
)


@st.composite
def intervals(draw):
    lo, hi = sorted((draw(st.floats(0, 100)), draw(st.floats(0, 100))))
    if draw(st.booleans()):
        lo, hi = float(round(lo)), float(round(hi))
    return Interval(lo, hi, draw(st.sampled_from(["", "s", "ms"])))


atoms = st.one_of(
    st.builds(Compare, st.sampled_from(["<", "<=", ">", ">=", "==", "!=="]), terms, terms),
    st.booleans().map(BoolConst),
    names.map(Var),
    st.builds(lambda t: Call("collision_free", (t,)), terms),
)


def _extend(f):
    return st.one_of(
        st.builds(Not, f),
        st.builds(Binary, st.sampled_from(["and", "or", "implies", "iff", "xor"]), f, f),
        st.builds(Temporal, st.sampled_from(["always", "eventually", "historically", "once"]),
                  st.none() | intervals(), f),
        st.builds(Temporal, st.sampled_from(["next", "prev"]), st.none(), f),
        st.builds(BinTemporal, st.sampled_from(["until", "unless", "since"]), st.none() | intervals(), f, f),
        st.builds(Edge, st.sampled_from(["rise", "fall"]), f),
    )


formulas = st.recursive(atoms, _extend, max_leaves=8)


def _file(fs: list) -> RuleFile:
    decls = tuple(Declaration("input", "float", n) for n in NAMES)
    return RuleFile("gen.stl", decls, tuple(Rule(f"r{i}", f) for i, f in enumerate(fs)))


@pytest.mark.filterwarnings("ignore::hypothesis.errors.HypothesisWarning")
@settings(max_examples=300, deadline=None)
@given(st.lists(formulas, min_size=1, max_size=3))
def test_parse_print_parse(fs: list) -> None:
    rf = _file(fs)
    text = format_file(rf)
    back, diags = parse(text, "gen.stl")
    assert back is not None, (text, [d.message for d in diags])
    assert back == rf, text
    assert format_file(back) == text  # printing is stable
    # the printer's parentheses keep the text free of precedence/portability warnings
    _, more = typecheck(back)
    assert not [d for d in more if d.code.startswith("STL3")], (text, [d.message for d in more])


participant_terms = st.recursive(
    st.one_of(numbers.map(Num), names.map(Var),
              st.sampled_from(["d_lon", "v", "cut_in"]).map(lambda n: ParticipantSignal(n, "o"))),
    lambda t: st.one_of(st.builds(Neg, t), st.builds(Arith, st.sampled_from(["+", "-", "*", "/"]), t, t)),
    max_leaves=4,
)
participant_atoms = st.one_of(
    st.builds(Compare, st.sampled_from(["<", "<=", ">", ">="]), participant_terms, participant_terms),
    st.sampled_from(["in_same_lane", "precedes"]).map(lambda n: ParticipantSignal(n, "o")),
    atoms,
)
quantified = st.builds(Quantifier, st.sampled_from(["forall", "exists"]), st.just("o"), st.just("vehicles"),
                       st.recursive(participant_atoms, _extend, max_leaves=5))


@pytest.mark.filterwarnings("ignore::hypothesis.errors.HypothesisWarning")
@settings(max_examples=200, deadline=None)
@given(st.lists(st.recursive(quantified, _extend, max_leaves=3), min_size=1, max_size=2))
def test_quantified_formulas_round_trip(fs: list) -> None:
    """Quantifiers and participant signals print as text that parses back to the same tree,
    without style warnings."""
    rf = _file(fs)
    text = format_file(rf)
    back, diags = parse(text, "gen.stl")
    assert back is not None, (text, [d.message for d in diags])
    assert back == rf, text
    assert format_file(back) == text
    _, more = typecheck(back)
    assert not [d for d in more if d.code.startswith("STL3")], (text, [d.message for d in more])


def test_commonroad_spelling_reads_as_the_long_form() -> None:
    """CommonRoad's ``A a1:`` / ``E a1:`` are ``forall``/``exists`` over vehicles."""
    short, _ = parse("r = A a1: (in_same_lane(a1)) -> E a2: (d_lon(a2) > 0);", "s.stl")
    long, _ = parse("r = (forall a1 in vehicles: in_same_lane(a1)) -> exists a2 in vehicles: d_lon(a2) > 0;",
                    "l.stl")
    assert short is not None and short == long
    assert isinstance(short.rules[0].formula.left, Quantifier)


@settings(max_examples=200, deadline=None)
@given(terms)
def test_terms_round_trip(t) -> None:
    back, diags = parse(f"r = {format_formula(t)} >= 0;", "t.stl")
    assert back is not None and back.rules[0].formula.left == t


@pytest.mark.parametrize(
    "formula",
    [
        " -> ".join(["a > 0"] * 70),  # right-assoc chain: clarity parentheses nested 69 deep
        " - ".join(["a"] * 70) + " > 0",  # left chain RTAMT reads right-to-left: 68 deep
        " / ".join(["a"] * 70) + " > 0",
        "(" * 64 + "a > 0" + ")" * 64 + " -> b > 0 -> c > 0",  # parentheses at the limit already
        " and ".join(f"(not p{k} > 0)" for k in range(60)) + " -> " + " -> ".join(["a > 0"] * 40),
    ],
)
def test_deep_chains_print_as_text_the_parser_accepts(formula: str) -> None:
    """Regression: chains of 67 or more '->' (and long '-' chains) printed with clarity
    parentheses nested deeper than the parser accepts."""
    decls = "input float a\ninput float b\ninput float c\n" + "".join(f"input float p{k}\n" for k in range(60))
    rf, diags = parse(decls + f"r = {formula};\n", "deep.stl")
    assert rf is not None, [d.message for d in diags]
    text = format_file(rf)
    back, diags = parse(text, "deep.stl")
    assert back == rf, [d.message for d in diags]
    assert format_file(back) == text
