"""Static facts about formulas: signals read, time horizons, linearity, partial evaluation.

Pure Python (no numpy): ``twolevel check`` imports it. Times are in seconds [s]; ``next`` and
``prev`` shift by one sample, i.e. ``dt`` [s] (pass ``dt=0`` when unknown: they then count 0).

:func:`substitute` is the design's "activation is partial evaluation": the signals known at solve
time (and the scenario's constants) become numbers, arithmetic over numbers and comparisons
between numbers fold, and ``true``/``false`` propagate through the connectives and temporal
operators, so an inactive rule collapses to ``true`` before the encoder creates any binary.
"""

from __future__ import annotations

import math
from typing import Callable, Iterable, Mapping, Sequence

from twolevel.stl.ast import (
    FUTURE_OPS,
    Abs,
    Arith,
    BinTemporal,
    Binary,
    BoolConst,
    Call,
    Compare,
    Edge,
    Neg,
    Node,
    Not,
    Num,
    ParticipantSignal,
    Quantifier,
    Temporal,
    Var,
    fold,
    rewrite,
)

__all__ = [
    "PRESENT",
    "participant_key",
    "split_participant_key",
    "participants_in",
    "expand_quantifiers",
    "quantifies",
    "participant_signals_read",
    "signals_read",
    "future_horizon",
    "past_depth",
    "is_constant",
    "is_linear",
    "nonlinear_nodes",
    "compare_robustness",
    "fold_constants",
    "fold_term",
    "substitute",
    "overflowing_terms",
]


# ----------------------------------------------------------------------------- participants

PRESENT = "present"
"""The participant signal that says where a participant is present: ``present[ID]`` is +inf at
the samples where it is (within sensing range) and -inf elsewhere, the robustness of "present"."""


def participant_key(name: str, pid: str) -> str:
    """The name of participant ``pid``'s signal ``name`` in a trace, a history or a sample:
    ``name[pid]`` (``d_lon[car-3]``, ``present[car-3]``)."""
    return f"{name}[{pid}]"


def split_participant_key(key: str) -> tuple[str, str] | None:
    """``(name, pid)`` of a key ``name[pid]``, or ``None`` for any other name."""
    i = key.find("[")
    if i <= 0 or not key.endswith("]") or i == len(key) - 2:
        return None
    name = key[:i]
    return (name, key[i + 1:-1]) if name.isidentifier() else None


def participants_in(names: Iterable[str]) -> list[str]:
    """The participants a set of signal names covers: every ``pid`` of a ``present[pid]``, in
    the order given (the domain a quantifier ranges over)."""
    out = []
    for key in names:
        got = split_participant_key(key)
        if got is not None and got[0] == PRESENT:
            out.append(got[1])
    return out


def _balanced(op: str, parts: list[Node], sp: object) -> Node:
    """``parts`` joined by ``op`` as a balanced tree (depth log2 of their number)."""
    while len(parts) > 1:
        parts = [Binary(op, parts[i], parts[i + 1], span=sp) if i + 1 < len(parts) else parts[i]  # type: ignore[arg-type]
                 for i in range(0, len(parts), 2)]
    return parts[0]


def _bind_participant(node: Node, var: str, pid: str) -> Node:
    """``node`` with every signal of participant variable ``var`` read from participant ``pid``'s
    columns (:func:`participant_key`)."""
    return rewrite(node, lambda n: Var(participant_key(n.name, pid), span=n.span)
                   if isinstance(n, ParticipantSignal) and n.var == var else None)


def expand_quantifiers(formula: Node, participants: Sequence[str]) -> Node:
    """``formula`` with every quantifier expanded over ``participants`` (their ids): ``forall o:
    body`` becomes the conjunction over p of ``present[p] -> body(p)``, ``exists`` the
    disjunction of ``present[p] and body(p)``, where ``body(p)`` reads ``name[p]`` for each
    ``name(o)`` (balanced trees; ``true``/``false`` for no participant). This is the quantifiers'
    meaning in the language without them: the online monitor, the MILC encoding and the tests
    against RTAMT use it; the offline and batched monitors evaluate quantifiers directly and equal
    it. A subtree of the body that reads no signal of the participant is shared by every copy
    (it has the same value in each); the rest is each participant's own (memoising evaluators
    key on node identity)."""
    if not any(isinstance(n, Quantifier) for n in formula.walk()):
        return formula
    return _expand(formula, tuple(participants))


def _expand(node: Node, pids: tuple[str, ...]) -> Node:
    return rewrite(node, lambda n: _expanded(n, pids) if isinstance(n, Quantifier) else None)


def _expanded(node: Quantifier, pids: tuple[str, ...]) -> Node:
    """One quantifier expanded over ``pids`` (its body's quantifiers first)."""
    body = _expand(node.body, pids)
    sp = node.span
    forall = node.op == "forall"
    if not pids:
        return BoolConst(forall, span=sp)
    parts: list[Node] = [Binary("implies" if forall else "and", Var(participant_key(PRESENT, p), span=sp),
                                _bind_participant(body, node.var, p), span=sp) for p in pids]
    return _balanced("and" if forall else "or", parts, sp)


def signals_read(formula: Node) -> set[str]:
    """Every name the formula reads: signals, constants and references to other rules, and each
    participant signal as its columns' pattern (``d_lon[*]``, :func:`participant_key`)."""
    return {n.name for n in formula.walk() if isinstance(n, Var)} | {
        participant_key(n.name, "*") for n in formula.walk() if isinstance(n, ParticipantSignal)}


def participant_signals_read(formula: Node) -> set[str]:
    """The names of the participant signals the formula reads (``d_lon`` for ``d_lon(o)``)."""
    return {n.name for n in formula.walk() if isinstance(n, ParticipantSignal)}


def quantifies(formula: Node) -> bool:
    """Whether the formula holds a quantifier over participants."""
    return any(isinstance(n, Quantifier) for n in formula.walk())


def _horizon(node: Node, dt: float, refs: Mapping[str, float], future: bool) -> float:
    """Future horizon (``future=True``) or past depth of ``node`` [s]."""
    rec: Callable[[Node], float] = lambda n: _horizon(n, dt, refs, future)  # noqa: E731
    if isinstance(node, Var):
        return refs.get(node.name, 0.0)
    if isinstance(node, (Not, Edge)):
        inner = rec(node.operand)
        return inner + dt if (isinstance(node, Edge) and not future) else inner
    if isinstance(node, Binary):
        return max(rec(node.left), rec(node.right))
    if isinstance(node, Quantifier):
        return rec(node.body)
    same = future
    if isinstance(node, Temporal):
        inner = rec(node.operand)
        ahead = node.op in FUTURE_OPS
        if node.op in ("next", "prev"):
            lo = hi = dt
        elif node.interval is None:
            lo, hi = 0.0, math.inf
        else:
            lo, hi = node.interval.lo, node.interval.hi
        if ahead == same:  # the operator looks the way we measure: widths add up
            return hi + inner
        return max(0.0, inner - lo)  # looks the other way: only reduces the reach
    if isinstance(node, BinTemporal):
        left, right = rec(node.left), rec(node.right)
        ahead = node.op in FUTURE_OPS
        lo, hi = (0.0, math.inf) if node.interval is None else (node.interval.lo, node.interval.hi)
        if ahead == same:
            return hi + max(left, right)
        return max(0.0, left, right - lo)
    return 0.0  # predicates, constants, calls: the current sample only


def future_horizon(formula: Node, dt: float = 0.0, refs: Mapping[str, float] | None = None) -> float:
    """How far ahead of the current sample the formula reads [s] (``inf`` if unbounded).

    ``refs`` gives the horizon of rules the formula refers to by name.
    """
    return _horizon(formula, dt, refs or {}, True)


def past_depth(formula: Node, dt: float = 0.0, refs: Mapping[str, float] | None = None) -> float:
    """How far back before the current sample the formula reads [s] (``inf`` if unbounded)."""
    return _horizon(formula, dt, refs or {}, False)


# ----------------------------------------------------------------------------- linearity


def is_constant(term: Node, constants: frozenset[str] | set[str] = frozenset()) -> bool:
    """True when the term involves only numbers and the named ``constants``."""
    return all(not isinstance(n, ParticipantSignal) and (not isinstance(n, Var) or n.name in constants)
               for n in term.walk())


def nonlinear_nodes(formula: Node, constants: frozenset[str] | set[str] = frozenset()) -> list[Arith]:
    """The arithmetic nodes that make a predicate non-linear in the signals: a product of two
    non-constant terms, or a division by a non-constant term.

    ``abs(t)`` of a linear ``t`` is *not* reported: it is piecewise linear, which a MILC encodes
    (with one binary where it is not convexly placed).
    """
    out = []
    for n in formula.walk():
        if isinstance(n, Arith):
            if n.op == "*" and not is_constant(n.left, constants) and not is_constant(n.right, constants):
                out.append(n)
            elif n.op == "/" and not is_constant(n.right, constants):
                out.append(n)
    return out


def is_linear(term: Node, constants: frozenset[str] | set[str] = frozenset()) -> bool:
    """True when the term (or every predicate of a formula) is affine in the signals, with
    ``abs`` allowed (piecewise linear, encodable)."""
    return not nonlinear_nodes(term, constants)


# ----------------------------------------------------------------------------- partial evaluation


def compare_robustness(op: str, a: float, b: float) -> float:
    """Robustness of ``a op b`` (RTAMT's quantitative semantics, as the offline monitor
    :mod:`twolevel.monitor.robustness` computes it): ``b - a`` for ``<``/``<=``, ``a - b`` for
    ``>``/``>=``, ``-|a - b|`` for ``==``, ``|a - b|`` for ``!==``."""
    if op in ("<", "<="):
        return b - a
    if op in (">", ">="):
        return a - b
    if op == "==":
        return -abs(a - b)
    return abs(a - b)


def _arith(op: str, a: float, b: float) -> float | None:
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    return a / b if b != 0 else None


def _is(node: Node, value: bool) -> bool:
    return isinstance(node, BoolConst) and node.value is value


def _as_formula(node: Node, fold_predicates: bool) -> Node:
    """A number in a formula position (a substituted signal read as a formula, whose robustness
    is its value) becomes ``value >= 0``, or ``true``/``false`` when predicates fold."""
    if not isinstance(node, Num):
        return node
    if fold_predicates:
        return BoolConst(node.value >= 0, span=node.span)
    return Compare(">=", node, Num(0.0), span=node.span)


def _fold(node: Node, values: Mapping[str, float], fold_predicates: bool) -> Node:
    term = lambda n: _fold(n, values, fold_predicates)  # noqa: E731
    rec = lambda n: _as_formula(_fold(n, values, fold_predicates), fold_predicates)  # noqa: E731
    sp = node.span
    if isinstance(node, Var):
        return Num(float(values[node.name]), span=sp) if node.name in values else node
    if isinstance(node, (Num, BoolConst, ParticipantSignal)):
        return node
    if isinstance(node, Quantifier):
        body = rec(node.body)
        if isinstance(body, BoolConst) and body.value is (node.op == "forall"):
            return body  # forall: true and exists: false whatever the participants
        return Quantifier(node.op, node.var, node.domain, body, var_span=node.var_span, span=sp)
    if isinstance(node, Neg):
        inner = term(node.operand)
        return Num(-inner.value, span=sp) if isinstance(inner, Num) else Neg(inner, span=sp)
    if isinstance(node, Abs):
        inner = term(node.operand)
        return Num(abs(inner.value), span=sp) if isinstance(inner, Num) else Abs(inner, span=sp)
    if isinstance(node, Arith):
        a, b = term(node.left), term(node.right)
        if isinstance(a, Num) and isinstance(b, Num):
            v = _arith(node.op, a.value, b.value)
            if v is not None and math.isfinite(v):
                return Num(v, span=sp)
        return Arith(node.op, a, b, span=sp)
    if isinstance(node, Compare):
        a, b = term(node.left), term(node.right)
        if fold_predicates and isinstance(a, Num) and isinstance(b, Num):
            return BoolConst(compare_robustness(node.op, a.value, b.value) >= 0, span=sp)
        return Compare(node.op, a, b, span=sp)
    if isinstance(node, Call):
        return Call(node.name, tuple(term(a) for a in node.args), span=sp)
    if isinstance(node, Not):
        inner = rec(node.operand)
        return BoolConst(not inner.value, span=sp) if isinstance(inner, BoolConst) else Not(inner, span=sp)
    if isinstance(node, Edge):
        return Edge(node.op, rec(node.operand), span=sp)
    if isinstance(node, Binary):
        a, b = rec(node.left), rec(node.right)
        return _simplify_binary(node.op, a, b, sp)
    if isinstance(node, Temporal):
        inner = rec(node.operand)
        if isinstance(inner, BoolConst):
            return BoolConst(inner.value, span=sp)
        return Temporal(node.op, node.interval, inner, span=sp)
    if isinstance(node, BinTemporal):
        a, b = rec(node.left), rec(node.right)
        if _is(b, False) and node.op in ("until", "since"):
            return BoolConst(False, span=sp)  # the right side never holds
        if _is(a, True) and node.op in ("until", "since"):  # the left side always holds
            return Temporal("eventually" if node.op == "until" else "once", node.interval, b, span=sp)
        if _is(a, True) and node.op == "unless":
            return BoolConst(True, span=sp)  # weak until with an always-true left side
        return BinTemporal(node.op, node.interval, a, b, span=sp)
    raise TypeError(f"unknown node {type(node).__name__}")


def _simplify_binary(op: str, a: Node, b: Node, sp: object) -> Node:
    ca, cb = isinstance(a, BoolConst), isinstance(b, BoolConst)
    if op == "and":
        if _is(a, False) or _is(b, False):
            return BoolConst(False, span=sp)
        if _is(a, True):
            return b
        if _is(b, True):
            return a
    elif op == "or":
        if _is(a, True) or _is(b, True):
            return BoolConst(True, span=sp)
        if _is(a, False):
            return b
        if _is(b, False):
            return a
    elif op == "implies":
        if _is(a, False) or _is(b, True):
            return BoolConst(True, span=sp)
        if _is(a, True):
            return b
        if _is(b, False):
            return Not(a, span=sp)
    elif ca and cb:  # iff / xor: only when both sides are known
        same = a.value is b.value  # type: ignore[union-attr]
        return BoolConst(same if op == "iff" else not same, span=sp)
    return Binary(op, a, b, span=sp)  # type: ignore[arg-type]


def substitute(formula: Node, values: Mapping[str, float], *, fold_predicates: bool = True) -> Node:
    """Replace the named signals/constants by numbers and simplify (partial evaluation).

    Arithmetic over numbers folds (not a division by zero); a comparison between numbers becomes
    ``true``/``false`` by the sign of its robustness (pass ``fold_predicates=False`` to keep its
    finite robustness value instead); ``true``/``false`` propagate through not, and, or, implies
    (iff/xor only when both sides are known), every unary temporal operator, ``until``/``since``
    whose right side is false or left side true, and ``unless`` whose left side is true.
    ``rise``/``fall`` are kept (their value at the first sample depends on the monitor).

    Folding a temporal operator over a constant is exact wherever its window holds a sample; at
    the end of a finite trace, where a truncated window can be empty, the monitor decides.
    """
    return _as_formula(_fold(formula, values, fold_predicates), fold_predicates)


def fold_constants(formula: Node) -> Node:
    """:func:`substitute` with no values: fold what the text already fixes."""
    return substitute(formula, {})


def fold_term(term: Node, values: Mapping[str, float] | None = None) -> Node:
    """A term with the named values substituted and its arithmetic folded (a :class:`Num` when
    it is constant)."""
    return _fold(term, values or {}, True)


def overflowing_terms(formula: Node, values: Mapping[str, float] | None = None) -> list[Arith]:
    """The arithmetic nodes of ``formula`` whose operands are constant (numbers, and the names
    bound in ``values``) and finite but whose result is not, as ``1e308 * 10`` or ``c * c`` with
    ``c = 1e300``: the innermost such nodes. A division by zero is not listed (the type checker
    reports it on its own)."""
    values = values or {}
    found: list[Arith] = []

    def value(node: Node, args: list[float | None]) -> float | None:
        if isinstance(node, Num):
            return node.value
        if isinstance(node, Var):
            return values.get(node.name)
        if isinstance(node, Neg) and args[0] is not None:
            return -args[0]
        if isinstance(node, Abs) and args[0] is not None:
            return abs(args[0])
        if isinstance(node, Arith) and args[0] is not None and args[1] is not None:
            v = _arith(node.op, args[0], args[1])
            if v is not None and math.isfinite(v):
                return v
            if v is not None:
                found.append(node)
        return None

    fold(formula, value)
    return found
