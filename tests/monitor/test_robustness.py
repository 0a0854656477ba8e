"""The offline oracle: hand-computed values for every operator, boundaries and truncation, a
definitional reference on random formulas, and its errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.monitor import windows
from twolevel.monitor.robustness import DEFAULT_BUILTINS, MonitorError, evaluate_rules, robustness
from twolevel.stl import ast as A

from helpers.formulas import formulas, traces

INF = math.inf
X = np.array([1.0, -2.0, 3.0, 0.0, -1.0])
Y = np.array([-1.0, 2.0, -3.0, 4.0, 0.5])
SIG = {"x": X, "y": Y}
P = A.Var("x")  # a signal used as a formula: its robustness is its value
Q = A.Var("y")


def I(a: float, b: float) -> A.Interval:  # noqa: E743 - reads like the math
    return A.Interval(a, b)


def rob(f: A.Node, dt: float = 1.0, **kw: object) -> list[float]:
    return robustness(f, SIG, dt, **kw).tolist()  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- predicates


@pytest.mark.parametrize(
    ("op", "expected"),
    [
        ("<", [-2.0, 4.0, -6.0, 4.0, 1.5]),
        ("<=", [-2.0, 4.0, -6.0, 4.0, 1.5]),
        (">", [2.0, -4.0, 6.0, -4.0, -1.5]),
        (">=", [2.0, -4.0, 6.0, -4.0, -1.5]),
        ("==", [-2.0, -4.0, -6.0, -4.0, -1.5]),
        ("!==", [2.0, 4.0, 6.0, 4.0, 1.5]),
    ],
)
def test_compare(op: str, expected: list[float]) -> None:
    assert rob(A.Compare(op, A.Var("x"), A.Var("y"))) == expected


def test_arithmetic_terms_and_constants() -> None:
    t = A.Arith("-", A.Arith("*", A.Num(2.0), A.Var("x")), A.Abs(A.Neg(A.Var("eps"))))
    assert rob(A.Compare(">=", t, A.Num(0.0)), consts={"eps": 0.5}) == [1.5, -4.5, 5.5, -0.5, -2.5]
    # division by zero follows IEEE (no exception)
    d = rob(A.Compare(">=", A.Arith("/", A.Num(1.0), A.Arith("-", A.Var("x"), A.Var("x"))), A.Num(0.0)))
    assert d == [INF] * 5


def test_boolean_connectives() -> None:
    assert rob(A.Not(P)) == [-1.0, 2.0, -3.0, -0.0, 1.0]
    assert rob(A.Binary("and", P, Q)) == [-1.0, -2.0, -3.0, 0.0, -1.0]
    assert rob(A.Binary("or", P, Q)) == [1.0, 2.0, 3.0, 4.0, 0.5]
    assert rob(A.Binary("implies", P, Q)) == [-1.0, 2.0, -3.0, 4.0, 1.0]  # max(-l, r)
    assert rob(A.Binary("iff", P, Q)) == [-2.0, -4.0, -6.0, -4.0, -1.5]  # -|l - r|
    assert rob(A.Binary("xor", P, Q)) == [2.0, 4.0, 6.0, 4.0, 1.5]  # |l - r|
    assert rob(A.BoolConst(True)) == [INF] * 5
    assert rob(A.BoolConst(False)) == [-INF] * 5


# ----------------------------------------------------------------------------- unary temporal


def test_always_eventually_truncate_at_the_end() -> None:
    assert rob(A.Temporal("always", I(0, 2), P)) == [-2.0, -2.0, -1.0, -1.0, -1.0]
    assert rob(A.Temporal("eventually", I(0, 2), P)) == [3.0, 3.0, 3.0, 0.0, -1.0]
    # a window starting later: empty windows at the end are +inf / -inf
    assert rob(A.Temporal("always", I(3, 4), P)) == [-1.0, -1.0, INF, INF, INF]
    assert rob(A.Temporal("eventually", I(3, 4), P)) == [0.0, -1.0, -INF, -INF, -INF]
    # a window longer than the trace, and a point window
    assert rob(A.Temporal("always", I(0, 50), P)) == [-2.0, -2.0, -1.0, -1.0, -1.0]
    assert rob(A.Temporal("eventually", I(1, 1), P)) == [-2.0, 3.0, 0.0, -1.0, -INF]
    # unbounded
    assert rob(A.Temporal("always", None, P)) == [-2.0, -2.0, -1.0, -1.0, -1.0]
    assert rob(A.Temporal("eventually", I(2, INF), P)) == [3.0, 0.0, -1.0, -INF, -INF]


def test_intervals_are_in_seconds() -> None:
    # dt = 0.5 s: [0.5 s, 1 s] covers samples i+1 .. i+2
    assert rob(A.Temporal("always", I(0.5, 1.0), P), dt=0.5) == [-2.0, 0.0, -1.0, -1.0, INF]


def test_historically_once_truncate_at_the_start() -> None:
    assert rob(A.Temporal("historically", I(0, 2), P)) == [1.0, -2.0, -2.0, -2.0, -1.0]
    assert rob(A.Temporal("once", I(0, 2), P)) == [1.0, 1.0, 3.0, 3.0, 3.0]
    assert rob(A.Temporal("historically", I(2, 3), P)) == [INF, INF, 1.0, -2.0, -2.0]
    assert rob(A.Temporal("once", I(2, 3), P)) == [-INF, -INF, 1.0, 1.0, 3.0]
    assert rob(A.Temporal("historically", None, P)) == [1.0, -2.0, -2.0, -2.0, -2.0]
    assert rob(A.Temporal("once", I(1, INF), P)) == [-INF, 1.0, 1.0, 3.0, 3.0]


def test_next_prev_rise_fall_at_the_boundaries() -> None:
    assert rob(A.Temporal("next", None, P)) == [-2.0, 3.0, 0.0, -1.0, INF]
    assert rob(A.Temporal("prev", None, P)) == [INF, 1.0, -2.0, 3.0, 0.0]
    # rise: min(x[i], -x[i-1]) with x[-1] = -inf; fall: min(x[i-1], -x[i]) with x[-1] = +inf
    assert rob(A.Edge("rise", P)) == [1.0, -2.0, 2.0, -3.0, -1.0]
    assert rob(A.Edge("fall", P)) == [-1.0, 1.0, -3.0, 0.0, 0.0]


# ----------------------------------------------------------------------------- until / since


def test_until_unbounded_and_bounded() -> None:
    # u[i] = max(y[i], min(x[i], u[i+1])), u[n] = -inf
    assert rob(A.BinTemporal("until", None, P, Q)) == [1.0, 2.0, 3.0, 4.0, 0.5]
    # [1, 2]: max over m in {1, 2} of min(y[i+m], x[i .. i+m-1]); beyond the end y = -inf
    assert rob(A.BinTemporal("until", I(1, 2), P, Q)) == [1.0, -2.0, 3.0, 0.0, -INF]
    # [0, 0] is the right operand itself
    assert rob(A.BinTemporal("until", I(0, 0), P, Q)) == Y.tolist()
    # a window entirely beyond the trace
    assert rob(A.BinTemporal("until", I(6, 9), P, Q)) == [-INF] * 5


def test_until_left_holds_up_to_but_excluding_the_witness() -> None:
    # x fails only at the witness sample itself: until still holds there
    x = np.array([1.0, 1.0, -5.0])
    y = np.array([-1.0, -1.0, 2.0])
    r = robustness(A.BinTemporal("until", I(2, 2), A.Var("x"), A.Var("y")), {"x": x, "y": y}, 1.0)
    assert r.tolist() == [1.0, -INF, -INF]


def test_since_unbounded_and_bounded() -> None:
    # s[i] = max(y[i], min(x[i], s[i-1])), s[-1] = -inf
    assert rob(A.BinTemporal("since", None, P, Q)) == [-1.0, 2.0, 2.0, 4.0, 0.5]
    # [1, 2]: max over m in {1, 2} of min(y[i-m], x[i-m+1 .. i]); before the start y = -inf
    assert rob(A.BinTemporal("since", I(1, 2), P, Q)) == [-INF, -2.0, 2.0, 0.0, -1.0]


def test_unless_is_always_or_until() -> None:
    # RTAMT: l unless[a,b] r = always[0,b] l or l until[a,b] r
    assert rob(A.BinTemporal("unless", I(1, 2), P, Q)) == [1.0, -2.0, 3.0, 0.0, -1.0]
    assert rob(A.BinTemporal("unless", None, P, Q)) == [1.0, 2.0, 3.0, 4.0, 0.5]


# ----------------------------------------------------------------------------- API


def test_one_sample_and_empty_traces() -> None:
    one = {"x": np.array([2.0])}
    assert robustness(A.Temporal("always", I(0, 3), A.Var("x")), one, 1.0).tolist() == [2.0]
    assert robustness(A.Temporal("next", None, A.Var("x")), one, 1.0).tolist() == [INF]
    assert robustness(A.BinTemporal("until", I(1, 3), A.Var("x"), A.Var("x")), one, 1.0).tolist() == [-INF]
    empty = {"x": np.array([])}
    assert robustness(A.BinTemporal("since", I(0, 3), A.Var("x"), A.Var("x")), empty, 1.0).shape == (0,)


def test_rules_refer_to_earlier_rules_and_builtins() -> None:
    rules = [
        A.Rule(name="fast", formula=A.Compare(">", A.Var("x"), A.Num(0.0))),
        A.Rule(name="never_fast", formula=A.Temporal("always", None, A.Not(A.Var("fast")))),
        A.Rule(name="safe", formula=A.Call("collision_free", (A.Num(1.0),))),
    ]
    out = evaluate_rules(rules, {"x": X, "min_gap": np.array([3.0, 2.0, 0.5, 1.0, 4.0])}, 1.0)
    assert out["fast"].tolist() == X.tolist()
    assert out["never_fast"].tolist() == [-3.0, -3.0, -3.0, 0.0, 1.0]
    assert out["safe"].tolist() == [2.0, 1.0, -0.5, 0.0, 3.0]
    assert "collision_free" in DEFAULT_BUILTINS
    custom = {"collision_free": lambda s, d: s["x"] * 0 + 7.0}
    assert robustness(A.Call("collision_free", (A.Num(1.0),)), SIG, 1.0, builtins=custom).tolist() == [7.0] * 5


def test_errors_name_what_is_wrong() -> None:
    with pytest.raises(MonitorError) as e:
        robustness(A.Compare("<", A.Var("v"), A.Num(1.0)), SIG, 1.0)
    assert e.value.name == "v"
    with pytest.raises(MonitorError) as e:
        robustness(P, {"x": X, "y": Y[:3]}, 1.0)
    assert e.value.name == "y"
    with pytest.raises(MonitorError) as e:
        robustness(A.Call("collision_free", (A.Num(1.0),)), SIG, 1.0)
    assert e.value.name == "min_gap"
    with pytest.raises(MonitorError) as e:
        robustness(A.Call("teleport", ()), SIG, 1.0)
    assert e.value.name == "teleport"
    with pytest.raises(MonitorError):
        robustness(P, SIG, 0.0)


def test_deep_formulas_do_not_hit_the_recursion_limit() -> None:
    f: A.Node = P
    for _ in range(5000):
        f = A.Not(f)
    assert rob(f) == X.tolist()


# ----------------------------------------------------------------------------- against the definitions


def _reference(f: A.Node, s: dict[str, np.ndarray], n: int) -> list[float]:
    """The definitions written out sample by sample (slow, obviously right)."""

    def term(t: A.Node, i: int) -> float:
        if isinstance(t, A.Num):
            return t.value
        if isinstance(t, A.Var):
            return float(s[t.name][i])
        if isinstance(t, A.Neg):
            return -term(t.operand, i)
        if isinstance(t, A.Abs):
            return abs(term(t.operand, i))
        assert isinstance(t, A.Arith)
        a, b = term(t.left, i), term(t.right, i)
        if t.op == "/":
            return a / b
        return {"+": a + b, "-": a - b, "*": a * b}[t.op]

    def ev(g: A.Node, i: int) -> float:  # noqa: C901
        if isinstance(g, A.Compare):
            a, b = term(g.left, i), term(g.right, i)
            return {"<": b - a, "<=": b - a, ">": a - b, ">=": a - b, "==": -abs(a - b), "!==": abs(a - b)}[g.op]
        if isinstance(g, A.Var):
            return float(s[g.name][i])
        if isinstance(g, A.BoolConst):
            return INF if g.value else -INF
        if isinstance(g, A.Not):
            return -ev(g.operand, i)
        if isinstance(g, A.Binary):
            a, b = ev(g.left, i), ev(g.right, i)
            return {"and": min(a, b), "or": max(a, b), "implies": max(-a, b), "iff": -abs(a - b), "xor": abs(a - b)}[g.op]
        if isinstance(g, A.Edge):
            cur = ev(g.operand, i)
            prev = ev(g.operand, i - 1) if i > 0 else (-INF if g.op == "rise" else INF)
            return min(cur, -prev) if g.op == "rise" else min(prev, -cur)
        lo, hi = (0, n) if g.interval is None else (round(g.interval.lo), g.interval.hi)
        hi = n if hi == INF else int(round(hi))
        if isinstance(g, A.Temporal):
            if g.op == "next":
                return ev(g.operand, i + 1) if i + 1 < n else INF
            if g.op == "prev":
                return ev(g.operand, i - 1) if i > 0 else INF
            if g.op in ("always", "eventually"):
                ks = [k for k in range(i + lo, i + hi + 1) if k < n]
            else:
                ks = [k for k in range(i - hi, i - lo + 1) if k >= 0]
            vals = [ev(g.operand, k) for k in ks]
            if g.op in ("always", "historically"):
                return min(vals, default=INF)
            return max(vals, default=-INF)
        assert isinstance(g, A.BinTemporal)
        best = -INF
        for m in range(lo, hi + 1):
            if g.op == "since":
                if i - m < 0:
                    break
                hold = min((ev(g.left, k) for k in range(i - m + 1, i + 1)), default=INF)
                best = max(best, min(ev(g.right, i - m), hold))
            else:
                if i + m >= n:
                    break
                hold = min((ev(g.left, k) for k in range(i, i + m)), default=INF)
                best = max(best, min(ev(g.right, i + m), hold))
        if g.op == "unless":
            held = min((ev(g.left, k) for k in range(i, min(i + hi, n - 1) + 1)), default=INF)
            best = max(best, held)
        return best

    return [ev(f, i) for i in range(n)]


@settings(max_examples=150, deadline=None)
@given(formulas(max_leaves=4), traces(0, 9))
def test_matches_the_definitions(f: A.Node, sig: dict[str, np.ndarray]) -> None:
    n = len(sig["x"])
    with np.errstate(all="ignore"):
        ours = robustness(f, sig, 1.0)
    assert np.array_equal(ours, np.array(_reference(f, sig, n)), equal_nan=True)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.sampled_from([-2.0, -1.0, 0.0, 1.0, 3.0]), max_size=40),
    st.integers(0, 12),
    st.one_of(st.none(), st.integers(0, 12)),
)
def test_window_kernels_against_brute_force(xs: list[float], a: int, extra: int | None) -> None:
    x = np.array(xs)
    b = None if extra is None else a + extra
    n = len(xs)
    top = n - 1 if b is None else b
    want_min = [min((xs[k] for k in range(i + a, i + top + 1) if k < n), default=INF) for i in range(n)]
    want_max = [max((xs[k] for k in range(i + a, i + top + 1) if k < n), default=-INF) for i in range(n)]
    assert windows.future_window(x, a, b, "min").tolist() == want_min
    assert windows.future_window(x, a, b, "max").tolist() == want_max
