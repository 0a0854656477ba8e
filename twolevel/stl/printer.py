"""Print AST nodes back as rule-language text.

``parse(format_file(rf)) == rf`` for every :class:`RuleFile` the parser can produce (numeric
literals are non-negative there: ``-3`` is ``Neg(Num(3))``). Parentheses are the minimum the
grammar needs plus those that keep the text free of the style warnings (STL3xx): ``and`` inside
``or``, a prefix operator left of a binary operator, chained ``->``, and ``a - b + c`` chains
(which RTAMT 0.4.10 reads right-to-left). Those clarity parentheses are left out of a formula
they would nest deeper than the parser accepts (:data:`~twolevel.stl.parser.MAX_NESTING`, e.g. a
chain of 70 ``->``): its text then needs no more nesting than the text it was parsed from, and
may draw the style warnings. Numbers print with :func:`repr` so floats round-trip; intervals in
the unit they were written in when that is exact, else in seconds.
"""

from __future__ import annotations

import math
import re

from twolevel.stl.ast import (
    Abs,
    Arith,
    BinTemporal,
    Binary,
    BoolConst,
    Call,
    Compare,
    Declaration,
    Edge,
    Interval,
    Neg,
    Node,
    Not,
    Num,
    ParticipantSignal,
    Quantifier,
    Rule,
    RuleFile,
    Temporal,
    Var,
)
from twolevel.stl.parser import MAX_NESTING

__all__ = ["format_formula", "format_term", "format_interval", "format_number", "format_rule",
           "format_declaration", "format_file"]

# Levels mirror grammar.lark, loosest (1) to tightest (11).
_XOR, _IFF, _IMP, _OR, _AND, _UNTIL, _CMP, _SUM, _PROD, _NEG, _ATOM = range(1, 12)
_BIN_LEVEL = {"xor": _XOR, "iff": _IFF, "implies": _IMP, "or": _OR, "and": _AND}
_BIN_TEXT = {"xor": "xor", "iff": "<->", "implies": "->", "or": "or", "and": "and"}


def format_number(x: float) -> str:
    """A number literal that parses back to exactly ``x`` (integers without a fraction)."""
    if not math.isfinite(x):
        raise ValueError(f"{x!r} has no literal in the rule language")
    if x == int(x) and abs(x) < 1e15:
        return str(int(x)) if x != 0 or math.copysign(1.0, x) > 0 else "-0"
    return repr(x)


def _exact_ms(x: float) -> bool:
    return math.isfinite(x * 1000.0) and float(format_number(x * 1000.0)) / 1000.0 == x


def format_interval(iv: Interval) -> str:
    """``[lo:hi]`` in the interval's unit when exact for both bounds, else in seconds."""
    if not (math.isfinite(iv.lo) and math.isfinite(iv.hi)):
        raise ValueError("an unbounded interval is written without brackets")
    if iv.unit == "ms" and _exact_ms(iv.lo) and _exact_ms(iv.hi):
        return f"[{format_number(iv.lo * 1000.0)}ms:{format_number(iv.hi * 1000.0)}ms]"
    unit = "s" if iv.unit in ("s", "ms") else ""
    return f"[{format_number(iv.lo)}{unit}:{format_number(iv.hi)}{unit}]"


def _level(node: Node) -> int:
    if isinstance(node, Binary):
        return _BIN_LEVEL[node.op]
    if isinstance(node, BinTemporal):
        return _UNTIL
    if isinstance(node, (Compare, Temporal, Not, Quantifier)):
        return _CMP
    if isinstance(node, Arith):
        return _SUM if node.op in "+-" else _PROD
    if isinstance(node, Neg):
        return _NEG
    if isinstance(node, Num) and (node.value < 0 or math.copysign(1.0, node.value) < 0):
        return _NEG
    return _ATOM


def _fmt(node: Node, need: int, left_of_op: bool, clear: bool = True) -> str:
    """``node`` as text, parenthesised when its level is below ``need`` or, with ``clear``, for
    clarity.

    ``left_of_op``: the text will be followed by a binary operator (a prefix operator here would
    read as covering it, STL304), so a prefix node gets parentheses (with ``clear``).
    """
    level = _level(node)
    prefix = isinstance(node, (Temporal, Not, Quantifier))
    if level < need or (prefix and left_of_op and clear):
        return "(" + _fmt(node, 0, False, clear) + ")"
    if isinstance(node, Num):
        return format_number(node.value)
    if isinstance(node, Var):
        return node.name
    if isinstance(node, BoolConst):
        return "true" if node.value else "false"
    if isinstance(node, Call):
        return f"{node.name}({', '.join(_fmt(a, 0, False, clear) for a in node.args)})"
    if isinstance(node, ParticipantSignal):
        return f"{node.name}({node.var})"
    if isinstance(node, Quantifier):
        return f"{node.op} {node.var} in {node.domain}: " + _fmt(node.body, _CMP, False, clear)
    if isinstance(node, Abs):
        return f"abs({_fmt(node.operand, 0, False, clear)})"
    if isinstance(node, Edge):
        return f"{node.op}({_fmt(node.operand, 0, False, clear)})"
    if isinstance(node, Neg):
        return "-" + _fmt(node.operand, _NEG, False, clear)
    if isinstance(node, Arith):
        # Left operand: same level allowed, except chains RTAMT reads right-to-left (a-b+c, a/b*c).
        rtl = clear and isinstance(node.left, Arith) and node.left.op in "-/" and _level(node.left) == level
        return f"{_fmt(node.left, level + rtl, False, clear)} {node.op} {_fmt(node.right, level + 1, False, clear)}"
    if isinstance(node, Compare):
        return f"{_fmt(node.left, _SUM, False, clear)} {node.op} {_fmt(node.right, _SUM, False, clear)}"
    if isinstance(node, Not):
        return "not " + _fmt(node.operand, _CMP, False, clear)
    if isinstance(node, Temporal):
        iv = "" if node.interval is None else format_interval(node.interval)
        return f"{node.op}{iv} " + _fmt(node.operand, _CMP, False, clear)
    if isinstance(node, BinTemporal):
        iv = "" if node.interval is None else format_interval(node.interval)
        return f"{_fmt(node.left, _UNTIL, True, clear)} {node.op}{iv} {_fmt(node.right, _CMP, left_of_op, clear)}"
    if isinstance(node, Binary):
        # and/or/xor/iff are left-associative, -> right-associative; a different connective as a
        # child is always parenthesised (clarity: STL301-303).
        def side(child: Node, base: int, left: bool) -> str:
            mixed = isinstance(child, Binary) and child.op != node.op
            chained = node.op == "implies" and isinstance(child, Binary) and child.op == "implies"
            need_ = _ATOM if clear and (mixed or chained) else base
            return _fmt(child, need_, True if left else left_of_op, clear)

        if node.op == "implies":
            lhs, rhs = side(node.left, level + 1, True), side(node.right, level, False)
        else:
            lhs, rhs = side(node.left, level, True), side(node.right, level + 1, False)
        return f"{lhs} {_BIN_TEXT[node.op]} {rhs}"
    raise TypeError(f"cannot print {type(node).__name__}")


_BRACKET = re.compile(r"[][()]")


def _nesting(text: str) -> int:
    """Most parentheses and brackets open at once in ``text`` (as the parser counts them)."""
    depth = deepest = 0
    for c in _BRACKET.findall(text):
        depth += 1 if c in "([" else -1
        deepest = max(deepest, depth)
    return deepest


def format_formula(f: Node) -> str:
    """A formula (or term) as text that parses back to an equal node: with the clarity
    parentheses, unless they would nest deeper than the parser accepts."""
    text = _fmt(f, 0, False)
    return text if _nesting(text) <= MAX_NESTING else _fmt(f, 0, False, clear=False)


format_term = format_formula


def format_declaration(d: Declaration) -> str:
    value = "" if d.value is None else " = " + format_formula(d.value)
    return f"{d.kind} {d.type} {d.name}{value}"


def format_rule(r: Rule) -> str:
    return f"{r.name} = {format_formula(r.formula)};"


def format_file(rf: RuleFile) -> str:
    """The whole file: declarations, a blank line, then one rule per line."""
    lines = [format_declaration(d) for d in rf.declarations]
    if rf.declarations and rf.rules:
        lines.append("")
    lines += [format_rule(r) for r in rf.rules]
    return "\n".join(lines) + "\n"
