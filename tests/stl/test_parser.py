"""Parser: precedence, aliases, units, spans, worded errors, speed."""

from __future__ import annotations

from pathlib import Path

import pytest

from twolevel.stl.ast import (
    Arith, BinTemporal, Binary, BoolConst, Call, Compare, Edge, Interval, Neg, Not, Num, Temporal, Var, Abs,
)
from twolevel.stl.parser import parse


def formula(src: str):
    rf, diags = parse(f"r = {src};", "t.stl")
    assert rf is not None, [d.message for d in diags]
    return rf.rules[0].formula


a, b, c, d = Var("a"), Var("b"), Var("c"), Var("d")
ZERO = Num(0.0)
RULES = Path(__file__).resolve().parents[2] / "rules"


@pytest.mark.parametrize(
    "src, tree",
    [
        ("a - b + c > 0", Compare(">", Arith("+", Arith("-", a, b), c), ZERO)),
        ("a / b * c > 0", Compare(">", Arith("*", Arith("/", a, b), c), ZERO)),
        ("a - b - c > 0", Compare(">", Arith("-", Arith("-", a, b), c), ZERO)),
        ("a + b * c > 0", Compare(">", Arith("+", a, Arith("*", b, c)), ZERO)),
        ("-a >= 0", Compare(">=", Neg(a), ZERO)),
        ("- -a >= -1", Compare(">=", Neg(Neg(a)), Neg(Num(1.0)))),
        ("abs(a - b) <= 1", Compare("<=", Abs(Arith("-", a, b)), Num(1.0))),
        ("always a > 0", Temporal("always", None, Compare(">", a, ZERO))),
        ("always a and b", Binary("and", Temporal("always", None, a), b)),
        ("not a > 0", Not(Compare(">", a, ZERO))),
        ("not a -> b", Binary("implies", Not(a), b)),
        ("a -> b -> c", Binary("implies", a, Binary("implies", b, c))),
        ("a or b and c", Binary("or", a, Binary("and", b, c))),
        ("a and b or c", Binary("or", Binary("and", a, b), c)),
        ("a and b until c", Binary("and", a, BinTemporal("until", None, b, c))),
        ("a until b until c", BinTemporal("until", None, BinTemporal("until", None, a, b), c)),
        ("always a until b", BinTemporal("until", None, Temporal("always", None, a), b)),
        ("a or b -> c", Binary("implies", Binary("or", a, b), c)),
        ("a -> b <-> c", Binary("iff", Binary("implies", a, b), c)),
        ("a <-> b xor c", Binary("xor", Binary("iff", a, b), c)),
        ("a xor b xor c", Binary("xor", Binary("xor", a, b), c)),
        ("eventually always a", Temporal("eventually", None, Temporal("always", None, a))),
        ("next prev a", Temporal("next", None, Temporal("prev", None, a))),
        ("rise(a > 0) and fall(b)", Binary("and", Edge("rise", Compare(">", a, ZERO)), Edge("fall", b))),
        ("collision_free(1.5)", Call("collision_free", (Num(1.5),))),
        ("foo()", Call("foo", ())),
        ("true or false", Binary("or", BoolConst(True), BoolConst(False))),
        ("(a)", a),
        ("a !== 1e-3", Compare("!==", a, Num(0.001))),
    ],
)
def test_precedence(src: str, tree) -> None:
    assert formula(src) == tree


ALIASES = [
    ("always[0:1] a", "G[0:1] a"),
    ("eventually[0:1] a", "F[0:1] a"),
    ("historically[0:1] a", "H[0:1] a"),
    ("once[0:1] a", "O[0:1] a"),
    ("next a", "X a"),
    ("prev a", "Y a"),
    ("a until[0:1] b", "a U[0:1] b"),
    ("a unless[0:1] b", "a W[0:1] b"),
    ("a since[0:1] b", "a S[0:1] b"),
    ("not a", "!a"),
    ("a and b", "a & b"),
    ("a and b", "a && b"),
    ("a or b", "a | b"),
    ("a or b", "a || b"),
    ("a implies b", "a -> b"),
    ("a iff b", "a <-> b"),
    ("always[0:1] a", "always[0,1] a"),
    ("always[0:1] a", "always[0s:1000ms] a"),
    ("always[0:0.5] a", "always[0:500ms] a"),
]


@pytest.mark.parametrize("long, short", ALIASES)
def test_aliases_give_identical_trees(long: str, short: str) -> None:
    assert formula(long) == formula(short)


def test_interval_units_in_seconds() -> None:
    f = formula("always[250ms:2s] a")
    assert isinstance(f, Temporal) and f.interval == Interval(0.25, 2.0)
    assert f.interval.unit == "s"
    assert formula("eventually[0:1] a").interval.unit == ""


def test_keywords_and_names() -> None:
    """Keywords are whole words only; lower-case one-letter signals stay names."""
    f = formula("always_on and s > 0 and Gx > 0 and ms >= 1")
    assert {v.name for v in f.walk() if isinstance(v, Var)} == {"always_on", "s", "Gx", "ms"}


def test_statements_without_semicolons_and_headers() -> None:
    rf, diags = parse(
        "specification spec\ninput float v\nint k\nconst float c = -2.5\nconst float later\n"
        "out = G[0:1] (v > c)\nout2 = v < k;\n", "t.stl")
    assert diags == [] and rf is not None
    assert [(x.kind, x.type, x.name) for x in rf.declarations] == [
        ("input", "float", "v"), ("input", "int", "k"), ("const", "float", "c"), ("const", "float", "later")]
    assert rf.declarations[2].value == Neg(Num(2.5))
    assert [r.name for r in rf.rules] == ["out", "out2"]


def test_spans_are_one_based_end_exclusive() -> None:
    rf, _ = parse("input float speed\nr = always[0:1] (speed <= 3);", "t.stl")
    f = rf.rules[0].formula
    var = next(n for n in f.walk() if isinstance(n, Var))
    assert (var.span.line, var.span.column, var.span.end_line, var.span.end_column) == (2, 18, 2, 23)
    assert (f.span.line, f.span.column, f.span.end_column) == (2, 5, 29)
    assert (rf.rules[0].name_span.column, rf.rules[0].name_span.end_column) == (1, 2)
    assert f.interval.span.column == 11
    # parentheses are recorded (by the span of what they enclose), not part of equality
    assert f.operand.span in rf.parenthesized


@pytest.mark.parametrize(
    "src, message",
    [
        ("input float v\nr = always[0:1] (v > 0 and\n   (v < 3);", "expected ')' to close the '(' opened at 2:17"),
        ("r = a and", "unexpected end of file: the formula of rule 'r' is incomplete"),
        ("r = a $ b", "unexpected character '$'"),
        ("r = always[0:1] ;", "expected a formula after 'always[0:1]', found ';'"),
        ("r = a b", "expected ';' or a new statement, found 'b'"),
        ("r = a != b", "'!=' is not an operator"),
        ("r = next[0:1] a", "expected a formula after 'next', found '['"),
        ("input float", "unexpected end of file: expected a name after 'float'"),
        ("r = a +", "the formula of rule 'r' is incomplete"),
        ("r = a > 0)", "unmatched ')': it closes nothing"),
    ],
)
def test_errors_in_words(src: str, message: str) -> None:
    rf, diags = parse(src, "t.stl")
    assert rf is None
    texts = [d.message + " " + (d.hint or "") for d in diags]
    assert any(message in t for t in texts), texts
    for t in texts:  # never lark's terminal names
        for name in ("RPAR", "LPAR", "NAME", "$END", "SEMI", "NUMBER", "Token("):
            assert name not in t


def test_not_equal_hint_and_incomplete_hint() -> None:
    _, diags = parse("r = a != b", "t.stl")
    assert diags[0].hint == "not-equal is written !== in RTAMT's language"
    _, diags = parse("r = a and", "t.stl")
    assert diags[0].hint == "expected a formula after 'and'"


def test_recovery_reports_each_bad_statement() -> None:
    rf, diags = parse("x = a and;\ny = (b;\nz = c\nw = d d\n", "t.stl")
    assert rf is None
    assert [(d.code, d.span.line) for d in diags] == [("STL101", 1), ("STL103", 2), ("STL101", 4)]


def test_number_out_of_range() -> None:
    rf, diags = parse("r = a < 1e999;", "t.stl")
    assert rf is None and diags[0].code == "STL110"


@pytest.mark.parametrize("digits", ["\u0661\u0662", "\uff11\uff12", "1\u0662", "\u0967.5", "1e\u0663"])
def test_numbers_are_ascii_digits_only(digits: str) -> None:
    """Regression: digits of other scripts (Arabic-Indic, fullwidth, Devanagari) were read as
    numbers, since the lexer's pattern used the Unicode-aware \\d."""
    rf, diags = parse(f"input float a\nr = a > {digits};\n", "t.stl")
    assert rf is None
    bad = [d for d in diags if d.code == "STL102"]
    assert bad and bad[0].span.line == 2 and "ASCII digits" in (bad[0].hint or "")


def test_a_text_parsed_again_gives_a_fresh_list_of_findings() -> None:
    """Parses are kept by (text, file): what a caller does with the findings changes no later parse;
    the same text under other line endings is the same parse."""
    text = "input float v\nr = v >;\n"
    _, diags = parse(text, "a.stl")
    assert diags
    diags.clear()
    again, diags2 = parse(text, "a.stl")
    assert again is None and diags2 and diags2[0].span.line == 2
    assert parse(text.replace("\n", "\r"), "a.stl")[1] == diags2
    assert parse(text, "b.stl")[1][0].span.file == "b.stl"
