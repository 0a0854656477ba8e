"""Differential test: the offline oracle against RTAMT 0.4.10's offline discrete-time monitor
(``rtamt.StlDiscreteTimeSpecification().evaluate``) on random formulas and signals.

Restricted to what RTAMT 0.4.10 computes correctly (its known faults): the emitter below
parenthesises every arithmetic operation (RTAMT reads ``a-b+c`` as ``a-(b+c)``), never writes a
leading unary minus (``-a>=0`` is rejected; we write ``(0 - a)``), writes ``!==`` for not-equal,
and the generator never inverts an interval, uses no ``true``/``false`` literal (not accepted in
a formula), no bare ``unless`` (RTAMT fails on it), no bare signal as a formula (RTAMT's offline
``always`` pads the input list in place) and keeps ``iff``/``xor`` to finite operands (Python's
``min`` and numpy's ``minimum`` treat NaN differently); traces have at least two samples
(RTAMT's ``evaluate`` raises ``UnboundLocalError`` on one).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings

from twolevel.monitor.robustness import robustness
from twolevel.stl import ast as A
from twolevel.stl.analysis import expand_quantifiers, participants_in

from helpers.formulas import SIGNALS, formulas, participant_traces, quantified_formulas, traces

rtamt = pytest.importorskip("rtamt")

_CMP = {"<": "<", "<=": "<=", ">": ">", ">=": ">=", "==": "==", "!==": "!=="}
_BOOL = {"and": "and", "or": "or", "implies": "->", "iff": "<->", "xor": "xor"}


def _num(v: float) -> str:
    return f"(0 - {-v!r})" if v < 0 else repr(float(v))


def _interval(iv: A.Interval | None) -> str:
    if iv is None:
        return ""
    assert math.isfinite(iv.hi) and iv.lo <= iv.hi
    return f"[{int(round(iv.lo))}:{int(round(iv.hi))}]"


def emit(node: A.Node) -> str:  # noqa: C901 - one case per node type
    """RTAMT specification text for an AST (every operation parenthesised)."""
    if isinstance(node, A.Num):
        return _num(node.value)
    if isinstance(node, A.Var):
        return _name(node.name)
    if isinstance(node, A.Neg):
        return f"(0 - {emit(node.operand)})"
    if isinstance(node, A.Abs):
        return f"abs({emit(node.operand)})"
    if isinstance(node, A.Arith):
        return f"({emit(node.left)} {node.op} {emit(node.right)})"
    if isinstance(node, A.Compare):
        return f"({emit(node.left)} {_CMP[node.op]} {emit(node.right)})"
    if isinstance(node, A.Not):
        return f"(not {emit(node.operand)})"
    if isinstance(node, A.Binary):
        return f"({emit(node.left)} {_BOOL[node.op]} {emit(node.right)})"
    if isinstance(node, A.Temporal):
        return f"({node.op}{_interval(node.interval)} {emit(node.operand)})"
    if isinstance(node, A.BinTemporal):
        return f"({emit(node.left)} {node.op}{_interval(node.interval)} {emit(node.right)})"
    if isinstance(node, A.Edge):
        return f"({node.op}({emit(node.operand)}))"
    raise TypeError(type(node).__name__)


def _name(name: str) -> str:
    """A participant's column ``p[a]`` as an RTAMT identifier ``p__a``."""
    return name.replace("[", "__").replace("]", "")


def rtamt_robustness(node: A.Node, sig: dict[str, np.ndarray]) -> np.ndarray:
    spec = rtamt.StlDiscreteTimeSpecification()
    for name in sig:
        spec.declare_var(_name(name), "float")
    spec.declare_var("out", "float")
    spec.spec = "out = " + emit(node)
    spec.parse()
    n = len(sig["x"])
    data = {"time": list(range(n))}
    data.update({_name(k): [float(v) for v in sig[k]] for k in sig})
    return np.array([v for _, v in spec.evaluate(data)], dtype=np.float64)


def test_emitter_parenthesises_arithmetic_chains() -> None:
    t = A.Arith("+", A.Arith("-", A.Var("x"), A.Var("y")), A.Num(-1.0))
    assert emit(A.Compare(">=", t, A.Num(0.0))) == "(((x - y) + (0 - 1.0)) >= 0.0)"


def test_known_values_agree() -> None:
    sig = {"x": np.array([1.0, -2.0, 3.0, 0.0]), "y": np.array([0.0, 1.0, -1.0, 2.0]), "z": np.zeros(4)}
    p = A.Compare(">=", A.Var("x"), A.Num(0.0))
    q = A.Compare(">", A.Var("y"), A.Num(0.5))
    f = A.BinTemporal("until", A.Interval(1.0, 2.0), p, q)
    assert rtamt_robustness(f, sig).tolist() == robustness(f, sig, 1.0).tolist()


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(formulas(rtamt_safe=True, max_leaves=5), traces(2, 12))  # RTAMT fails on 1 sample
def test_offline_matches_rtamt(f: A.Node, sig: dict[str, np.ndarray]) -> None:
    want = rtamt_robustness(f, sig)
    got = robustness(f, sig, 1.0)
    assert np.array_equal(got, want, equal_nan=True), (emit(f), got, want)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(quantified_formulas(rtamt_safe=True), participant_traces(2, 10))
def test_quantifiers_match_rtamt_on_the_expanded_formula(f: A.Node, sig: dict[str, np.ndarray]) -> None:
    """The offline monitor's quantifiers (evaluated directly) against RTAMT on their expansion
    into the language without quantifiers (conjunctions of present[p] -> body(p)); RTAMT has no
    true/false literal, which an empty domain expands to."""
    assume(participants_in(sig))
    want = rtamt_robustness(expand_quantifiers(f, participants_in(sig)), sig)
    got = robustness(f, sig, 1.0)
    assert np.array_equal(got, want, equal_nan=True), (emit(expand_quantifiers(f, participants_in(sig))), got, want)
