"""The typed syntax tree of STL rule files.

Frozen dataclasses; every node carries the :class:`~twolevel.diagnostics.Span` it was parsed
from. Spans do not take part in equality, so ``parse(print(ast)) == ast`` compares meaning.

Two kinds of nodes:

* **terms** (real-valued): :class:`Num`, :class:`Var`, :class:`Neg`, :class:`Arith`, :class:`Abs`;
* **formulas** (robustness-valued): :class:`Compare`, :class:`BoolConst`, :class:`Not`,
  :class:`Binary`, :class:`Temporal`, :class:`BinTemporal`, :class:`Edge`, :class:`Call`
  (built-in world predicates such as ``collision_free(d)``), :class:`Quantifier` (``forall o in
  vehicles: ...``), and :class:`Var` used as a formula (a reference to an earlier named rule or a
  signal, whose value is its robustness, as in RTAMT);
* :class:`ParticipantSignal` (``d_lon(o)``: a signal of the participant a quantifier binds) is,
  like :class:`Var`, a term and, used as a formula, its robustness.

Time intervals are stored in seconds. Time is discrete: an interval ``[a, b]`` covers the
samples ``round(a/dt) .. round(b/dt)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Callable, Iterator, Literal, TypeVar, Union

from twolevel.diagnostics import Span

ArithOp = Literal["+", "-", "*", "/"]
CompareOp = Literal["<", "<=", ">", ">=", "==", "!=="]
BoolOp = Literal["and", "or", "implies", "iff", "xor"]
UnaryTemporalOp = Literal["always", "eventually", "historically", "once", "next", "prev"]
BinaryTemporalOp = Literal["until", "unless", "since"]
EdgeOp = Literal["rise", "fall"]

FUTURE_OPS = frozenset({"always", "eventually", "next", "until", "unless"})
PAST_OPS = frozenset({"historically", "once", "prev", "since"})


@dataclass(frozen=True)
class Node:
    """Base of every node: its source span (ignored by ``==`` and ``hash``)."""

    span: Span | None = field(default=None, compare=False, repr=False, kw_only=True)

    def children(self) -> tuple["Node", ...]:
        return ()

    def walk(self) -> Iterator["Node"]:
        """Every node of this subtree, parents before children (iterative: safe on deep trees)."""
        stack: list[Node] = [self]
        while stack:
            node = stack.pop()
            yield node
            stack.extend(reversed(node.children()))


# ----------------------------------------------------------------------------- terms


@dataclass(frozen=True)
class Num(Node):
    """A numeric literal."""

    value: float


@dataclass(frozen=True)
class Var(Node):
    """A named signal, constant, or (as a formula) an earlier rule."""

    name: str


@dataclass(frozen=True)
class Neg(Node):
    """Arithmetic negation ``-t``."""

    operand: "Term"

    def children(self) -> tuple[Node, ...]:
        return (self.operand,)


@dataclass(frozen=True)
class Arith(Node):
    """``left op right`` for ``+ - * /``."""

    op: ArithOp
    left: "Term"
    right: "Term"

    def children(self) -> tuple[Node, ...]:
        return (self.left, self.right)


@dataclass(frozen=True)
class Abs(Node):
    """``abs(t)``."""

    operand: "Term"

    def children(self) -> tuple[Node, ...]:
        return (self.operand,)


@dataclass(frozen=True)
class ParticipantSignal(Node):
    """``name(var)``: signal ``name`` of the participant bound to ``var`` by an enclosing
    :class:`Quantifier` (``d_lon(o)``). The world names these signals
    (:mod:`twolevel.world.provided`); their values over a trace are the columns ``name[ID]``, one
    per participant (:func:`twolevel.stl.analysis.participant_key`)."""

    name: str
    var: str


Term = Union[Num, Var, Neg, Arith, Abs, ParticipantSignal]

# ----------------------------------------------------------------------------- formulas


@dataclass(frozen=True)
class Interval(Node):
    """A closed time window ``[lo, hi]`` in seconds; ``hi`` may be ``math.inf``.

    ``unit`` records how the source wrote it ("s", "ms" or "" for a bare number) so the printer
    can write it back the same way; it does not take part in equality.
    """

    lo: float
    hi: float
    unit: str = field(default="", compare=False)

    @property
    def bounded(self) -> bool:
        return math.isfinite(self.hi)

    def steps(self, dt: float) -> tuple[int, int | None]:
        """The window in samples of period ``dt`` [s]; ``None`` for an unbounded end."""
        lo = int(round(self.lo / dt))
        hi = int(round(self.hi / dt)) if self.bounded else None
        return lo, hi


@dataclass(frozen=True)
class Compare(Node):
    """A predicate ``left op right``. Robustness: ``right - left`` for ``<``/``<=``,
    ``left - right`` for ``>``/``>=``, ``-|left - right|`` for ``==``, ``|left - right|`` for ``!==``."""

    op: CompareOp
    left: Term
    right: Term

    def children(self) -> tuple[Node, ...]:
        return (self.left, self.right)


@dataclass(frozen=True)
class BoolConst(Node):
    """``true`` (robustness +inf) or ``false`` (robustness -inf)."""

    value: bool


@dataclass(frozen=True)
class Not(Node):
    operand: "Formula"

    def children(self) -> tuple[Node, ...]:
        return (self.operand,)


@dataclass(frozen=True)
class Binary(Node):
    """Boolean connectives: ``and`` (min), ``or`` (max), ``implies``, ``iff``, ``xor``."""

    op: BoolOp
    left: "Formula"
    right: "Formula"

    def children(self) -> tuple[Node, ...]:
        return (self.left, self.right)


@dataclass(frozen=True)
class Temporal(Node):
    """Unary temporal operators. ``interval`` is ``None`` for the unbounded forms and always
    ``None`` for ``next``/``prev`` (one sample)."""

    op: UnaryTemporalOp
    interval: Interval | None
    operand: "Formula"

    def children(self) -> tuple[Node, ...]:
        return (self.operand,) if self.interval is None else (self.interval, self.operand)


@dataclass(frozen=True)
class BinTemporal(Node):
    """``left until[a,b] right``, ``left unless[a,b] right``, ``left since[a,b] right``."""

    op: BinaryTemporalOp
    interval: Interval | None
    left: "Formula"
    right: "Formula"

    def children(self) -> tuple[Node, ...]:
        base: tuple[Node, ...] = (self.left, self.right)
        return base if self.interval is None else (self.interval,) + base


@dataclass(frozen=True)
class Edge(Node):
    """``rise(phi)``: min(phi[t], -phi[t-1]); ``fall(phi)``: min(-phi[t], phi[t-1])."""

    op: EdgeOp
    operand: "Formula"

    def children(self) -> tuple[Node, ...]:
        return (self.operand,)


@dataclass(frozen=True)
class Call(Node):
    """A built-in world predicate, e.g. ``collision_free(d)``; its meaning depends on the level
    (docs/architecture.md, "The rule language")."""

    name: str
    args: tuple[Term, ...]

    def children(self) -> tuple[Node, ...]:
        return self.args


QuantifierOp = Literal["forall", "exists"]


@dataclass(frozen=True)
class Quantifier(Node):
    """``forall var in domain: body`` and ``exists var in domain: body`` (CommonRoad's
    ``A var:`` / ``E var:``). At each sample the robustness is the minimum (``forall``) or the
    maximum (``exists``) of the body's over the participants of ``domain`` present at that
    sample, +inf (``forall``) or -inf (``exists``) when none is; the body is evaluated over the
    whole trace of each participant. Exactly: ``forall`` is the conjunction over every participant
    p of ``present[p] -> body(p)`` and ``exists`` the disjunction of ``present[p] and body(p)``,
    with ``present[p]`` +inf where p is present and -inf elsewhere
    (:func:`twolevel.stl.analysis.expand_quantifiers`). ``var_span`` locates the variable."""

    op: QuantifierOp
    var: str
    domain: str
    body: "Formula"
    var_span: Span | None = field(default=None, compare=False, repr=False)

    def children(self) -> tuple[Node, ...]:
        return (self.body,)


Formula = Union[Compare, BoolConst, Not, Binary, Temporal, BinTemporal, Edge, Call, Var, Quantifier,
                ParticipantSignal]

# ----------------------------------------------------------------------------- file level

DeclKind = Literal["input", "output", "const"]


@dataclass(frozen=True)
class Declaration(Node):
    """``input float v``, ``output float out``, ``const float eps = 0.1``."""

    kind: DeclKind
    type: str
    name: str
    value: Term | None = None

    def children(self) -> tuple[Node, ...]:
        return () if self.value is None else (self.value,)


@dataclass(frozen=True)
class Rule(Node):
    """A named formula statement ``name = formula;``. ``name_span`` locates the name."""

    name: str
    formula: Formula
    name_span: Span | None = field(default=None, compare=False, repr=False)

    def children(self) -> tuple[Node, ...]:
        return (self.formula,)


@dataclass(frozen=True)
class RuleFile(Node):
    """A parsed rule file: its declarations and rules, in source order.

    ``parenthesized`` holds the spans of the subexpressions the source wrapped in parentheses
    (the span of the expression inside them); the style checks (STL3xx) read it. It does not take
    part in equality.
    """

    path: str = field(compare=False)
    declarations: tuple[Declaration, ...] = ()
    rules: tuple[Rule, ...] = ()
    parenthesized: frozenset[Span] = field(default=frozenset(), compare=False, repr=False)

    def children(self) -> tuple[Node, ...]:
        return self.declarations + self.rules

    def declaration(self, name: str) -> Declaration | None:
        for d in self.declarations:
            if d.name == name:
                return d
        return None

    def rule(self, name: str) -> Rule | None:
        for r in self.rules:
            if r.name == name:
                return r
        return None


_T = TypeVar("_T")


def fold(
    root: Node, apply: Callable[[Node, list[_T]], _T], *, leaves: tuple[type[Node], ...] = ()
) -> _T:
    """Evaluate a tree bottom-up: ``apply(node, values of its children)`` for every node, children
    first, each shared subtree once (by identity); intervals are parameters, not children. Nodes of
    the ``leaves`` types are applied with no children (their subtrees are not visited). Iterative,
    so deep formulas do not reach the recursion limit. The monitors evaluate formulas with it."""
    memo: dict[int, _T] = {}
    stack: list[tuple[Node, bool]] = [(root, False)]
    while stack:
        node, ready = stack.pop()
        if id(node) in memo:
            continue
        kids = () if isinstance(node, leaves) else [c for c in node.children() if not isinstance(c, Interval)]
        if not ready:
            stack.append((node, True))
            stack.extend((c, False) for c in kids if id(c) not in memo)
            continue
        memo[id(node)] = apply(node, [memo[id(c)] for c in kids])
    return memo[id(root)]


def rewrite(node: Node, fn: Callable[[Node], Node | None]) -> Node:
    """A copy of ``node`` with each node for which ``fn`` gives a node replaced by it (its
    subtree is not visited further: ``fn`` recurses itself when it needs to); ``fn`` gives
    ``None`` to keep a node and visit its children. A node none of whose children changed is kept
    as it is (the same object), so unchanged subtrees stay shared; intervals are parameters, not
    visited. Substitutions, participant binding and quantifier expansion are built on it."""
    new = fn(node)
    if new is not None:
        return new
    changes: dict[str, object] = {}
    for f in fields(node):
        value = getattr(node, f.name)
        if isinstance(value, Node) and not isinstance(value, Interval):
            kid = rewrite(value, fn)
            if kid is not value:
                changes[f.name] = kid
        elif isinstance(value, tuple) and value and isinstance(value[0], Node):
            kids = tuple(rewrite(v, fn) for v in value)
            if any(a is not b for a, b in zip(kids, value)):
                changes[f.name] = kids
    return replace(node, **changes) if changes else node
