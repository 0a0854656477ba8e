"""Parse rule-file text into the AST of :mod:`twolevel.stl.ast`.

:func:`parse` returns the :class:`~twolevel.stl.ast.RuleFile` (``None`` when the text has
errors) and the diagnostics, never raises on bad input. The steps:

0. line breaks (LF, CRLF, bare CR) become LF, so that every later step counts lines alike;
1. a linear scan for unterminated ``/*`` comments and for parentheses nested deeper than
   :data:`MAX_NESTING` (before anything recursive sees the text);
2. lexing with lark's basic lexer, continuing after an unexpected character;
3. a scan for chains of prefix operators longer than :data:`MAX_NESTING`;
4. splitting the tokens into statements (at ``;`` and at a declaration keyword or ``name =``
   that begins a line), each parsed alone with lark's LALR parser: a syntax error costs one
   statement, the others are still checked;
5. an iterative (stack-safe) transformation of each parse tree into typed AST nodes: terms and
   formulas share one expression grammar, so a term used as a formula (or the reverse) is
   reported here (STL206), as are time units outside intervals (STL110) and formulas deeper
   than :data:`MAX_DEPTH` (STL108).

The lark parser is built once per process, from lark's on-disk cache when available.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twolevel.diagnostics import LINE_BREAK, Diagnostic, Span
from twolevel.stl import codes
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
    rewrite,
)

if TYPE_CHECKING:  # pragma: no cover
    from lark import Lark, Token, Tree

__all__ = ["parse", "MAX_NESTING", "MAX_DEPTH", "TERM_NODES", "FORMULA_NODES"]

MAX_NESTING = 64
"""Most parentheses/brackets open at once, and longest chain of prefix operators."""
MAX_DEPTH = 200
"""Deepest formula tree accepted (e.g. a chain of 200 'and's); keeps every recursive pass safe."""
MAX_LEX_ERRORS = 20

TERM_NODES = (Num, Neg, Arith, Abs)
"""Node types that are terms only (a :class:`Var` is both a term and a formula)."""
FORMULA_NODES = (Compare, BoolConst, Not, Binary, Temporal, BinTemporal, Edge, Call, Quantifier)
"""Node types that are formulas only (a :class:`ParticipantSignal`, like a :class:`Var`, is both)."""
DEFAULT_DOMAIN = "vehicles"
"""The domain of a quantifier written without ``in DOMAIN`` (CommonRoad's ``A o:``)."""

_GRAMMAR = Path(__file__).with_name("grammar.lark")
_LARK: "Lark | None" = None


def _parser() -> "Lark":
    """The process-wide lark parser (built lazily; lark caches the tables on disk)."""
    global _LARK
    if _LARK is None:
        from lark import Lark

        _LARK = Lark(
            _GRAMMAR.read_text(encoding="utf-8"),
            parser="lalr",
            lexer="basic",
            start="statement",
            propagate_positions=True,
            maybe_placeholders=False,
            cache=True,
        )
        # Lark.lex() builds a new lexer (and its scanner's regular expressions) on every call
        # unless the instance holds one: build it once (a third of a small file's parse time)
        _LARK.lexer = _LARK._build_lexer()
    return _LARK


# ----------------------------------------------------------------------------- token vocabulary

_BOOL_OPS = {
    "AND": "and", "AMP": "and", "AMPAMP": "and", "OR": "or", "BAR": "or", "BARBAR": "or",
    "IMPLIES": "implies", "IMPLIES_SYM": "implies", "IFF": "iff", "IFF_SYM": "iff", "XOR": "xor",
}
_TEMPORAL_OPS = {
    "ALWAYS": "always", "G_OP": "always", "EVENTUALLY": "eventually", "F_OP": "eventually",
    "HISTORICALLY": "historically", "H_OP": "historically", "ONCE": "once", "O_OP": "once",
    "NEXT": "next", "X_OP": "next", "PREV": "prev", "Y_OP": "prev",
}
_BINTEMP_OPS = {"UNTIL": "until", "U_OP": "until", "UNLESS": "unless", "W_OP": "unless",
                "SINCE": "since", "S_OP": "since"}
_QUANT_OPS = {"FORALL": "forall", "A_OP": "forall", "EXISTS": "exists", "E_OP": "exists"}
_PREFIX = set(_TEMPORAL_OPS) | {"NOT", "BANG"}
_ARITH_OR_CMP = {"PLUS", "MINUS", "STAR", "SLASH", "LT", "LE", "GT", "GE", "EQEQ", "NEQ"}
_ATOM_START = {"NUMBER", "NAME", "TRUE", "FALSE", "LPAR", "RISE", "FALL", "ABS", "MINUS"} | _PREFIX | set(_QUANT_OPS)
_STARTERS = {"INPUT", "OUTPUT", "CONST", "FLOAT", "INT", "SPECIFICATION", "IMPORT_LINE"}
_TERM_END = {"NAME", "NUMBER", "RPAR", "TRUE", "FALSE"}
_WORDS = {
    "LPAR": "'('", "RPAR": "')'", "LSQB": "'['", "RSQB": "']'", "COLON": "':'", "COMMA": "','",
    "SEMI": "';'", "EQUAL": "'='", "NAME": "a name", "NUMBER": "a number", "$END": "end of file",
    "FLOAT": "'float'", "INT": "'int'",
}
_CHAR_HINTS = {
    "#": "comments start with // or are written /* ... */",
    "'": "the language has no strings",
    '"': "the language has no strings",
    "%": "the arithmetic operators are + - * /",
    "^": "the arithmetic operators are + - * /; there is no power operator",
    "~": "negation is written 'not' or '!'",
}

# ----------------------------------------------------------------------------- helpers


def _offset_pos(text: str, offset: int) -> tuple[int, int]:
    """1-based (line, column) of a character offset."""
    line = text.count("\n", 0, offset) + 1
    col = offset - (text.rfind("\n", 0, offset) + 1) + 1
    return line, col


def _tok_span(file: str, tok: "Token") -> Span:
    return Span(file, tok.line, tok.column, tok.end_line, tok.end_column)


def _quote(tok: "Token") -> str:
    s = str(tok)
    if len(s) > 24:
        s = s[:21] + "..."
    return f"'{s}'"


def _node_span(file: str, meta: Any) -> Span:
    return Span(file, meta.line, meta.column, meta.end_line, meta.end_column)


# ----------------------------------------------------------------------------- scanning

_SCAN = re.compile(r"//[^\n]*|/\*[\s\S]*?\*/|/\*|[()\[\]]")


def _scan_nesting(text: str, file: str) -> Diagnostic | None:
    """Unterminated block comments and too-deep brackets, found without recursion."""
    depth = 0
    for m in _SCAN.finditer(text):
        c = m.group()
        if c == "(" or c == "[":
            depth += 1
            if depth > MAX_NESTING:
                line, col = _offset_pos(text, m.start())
                return codes.STL108(
                    f"parentheses nest deeper than {MAX_NESTING} levels",
                    Span(file, line, col, line, col + 1),
                    hint="split the formula into named rules and refer to them by name",
                )
        elif c == ")" or c == "]":
            depth = max(0, depth - 1)
        elif c == "/*":
            line, col = _offset_pos(text, m.start())
            return codes.STL101(
                "unterminated comment: this '/*' is never closed",
                Span(file, line, col, line, col + 2),
                hint="close the comment with */",
            )
    return None


def _lex(text: str, file: str) -> tuple[list["Token"], list[Diagnostic]]:
    """All tokens of ``text``; an unexpected character is reported and skipped."""
    from lark.exceptions import UnexpectedCharacters

    lark = _parser()
    tokens: list[Token] = []
    diags: list[Diagnostic] = []
    pos = 0
    while True:
        line_off = text.count("\n", 0, pos)
        col_off = pos - (text.rfind("\n", 0, pos) + 1)
        try:
            for tok in lark.lex(text[pos:] if pos else text):
                if pos:
                    if tok.line == 1:
                        tok.column += col_off
                    if tok.end_line == 1:
                        tok.end_column += col_off
                    tok.line += line_off
                    tok.end_line += line_off
                    tok.start_pos += pos
                    tok.end_pos += pos
                tokens.append(tok)
            return tokens, diags
        except UnexpectedCharacters as e:
            bad = pos + e.pos_in_stream
            ch = text[bad]
            line, col = _offset_pos(text, bad)
            shown = ch if ch.isprintable() and not ch.isspace() else f"U+{ord(ch):04X}"
            hint = _CHAR_HINTS.get(ch) or ("numbers are written with the ASCII digits 0-9" if ch.isdigit() else None)
            diags.append(
                codes.STL102(f"unexpected character '{shown}'", Span(file, line, col, line, col + 1), hint=hint)
            )
            if len(diags) >= MAX_LEX_ERRORS:
                return tokens, diags
            pos = bad + 1


def _scan_prefix_chains(tokens: list["Token"], file: str) -> Diagnostic | None:
    """Chains of prefix operators (``not not ... x``, ``- - ... x``) longer than the limit."""
    run = 0
    in_interval = False
    prev = None
    for tok in tokens:
        t = tok.type
        if in_interval:
            in_interval = t != "RSQB"
        elif t in _PREFIX or (t == "MINUS" and prev not in _TERM_END):
            run += 1
            if run > MAX_NESTING:
                return codes.STL108(
                    f"more than {MAX_NESTING} prefix operators in a row",
                    _tok_span(file, tok),
                    hint="split the formula into named rules and refer to them by name",
                )
        elif t == "LSQB" and prev in _TEMPORAL_OPS:
            in_interval = True
        elif t != "LPAR":
            run = 0
        prev = t
    return None


def _split(tokens: list["Token"]) -> list[list["Token"]]:
    """Tokens grouped into statements: at ';' and where a statement starts a new line."""
    chunks: list[list[Token]] = []
    cur: list[Token] = []
    n = len(tokens)
    for i, tok in enumerate(tokens):
        if cur and tok.line > cur[-1].end_line:
            starts = tok.type in _STARTERS and not (
                tok.type in ("FLOAT", "INT") and cur[-1].type in ("INPUT", "OUTPUT", "CONST")
            )
            starts = starts or (tok.type == "NAME" and i + 1 < n and tokens[i + 1].type == "EQUAL")
            if starts:
                chunks.append(cur)
                cur = []
        cur.append(tok)
        if tok.type == "SEMI":
            chunks.append(cur)
            cur = []
    if cur:
        chunks.append(cur)
    return [c for c in chunks if not (len(c) == 1 and c[0].type == "SEMI")]


# ----------------------------------------------------------------------------- syntax errors


def _after_text(text: str, chunk: list["Token"], k: int) -> str:
    """The source text of the token before position ``k``; a whole ``op[a:b]`` for an interval."""
    prev = chunk[k - 1]
    start = prev.start_pos
    if prev.type == "RSQB":
        j = k - 1
        while j > 0 and chunk[j].type != "LSQB":
            j -= 1
        if j > 0:
            start = chunk[j - 1].start_pos
    s = text[start:prev.end_pos]
    return s if len(s) <= 40 else s[:37] + "..."


def _syntax_error(
    text: str, file: str, chunk: list["Token"], k: int, expected: set[str],
    stack: list["Token"], at_eof: bool,
) -> Diagnostic:
    """Say in words what went wrong at ``chunk[k]`` (``k == len(chunk)``: the statement ended)."""
    rule = str(chunk[0]) if len(chunk) > 1 and chunk[0].type == "NAME" and chunk[1].type == "EQUAL" else None
    prev = chunk[k - 1] if k > 0 else None
    after = f" after '{_after_text(text, chunk, k)}'" if prev is not None else ""
    what = "a term" if prev is not None and prev.type in _ARITH_OR_CMP else "a formula"
    wants_atom = bool(expected & (_ATOM_START - {"NAME"}))
    if expected == {"NAME"}:
        what = "a name"
        wants_atom = True
    open_tok = stack[-1] if stack else None
    closer = {"LPAR": ("')'", "'('", "RPAR"), "LSQB": ("']'", "'['", "RSQB")}
    hint = None

    if k == len(chunk):  # the statement (or the file) ended too early
        last = chunk[-1]
        span = Span(file, last.end_line, last.end_column, last.end_line, last.end_column)
        lead = "unexpected end of file: " if at_eof else ""
        if open_tok is not None and closer[open_tok.type][2] in expected and not wants_atom:
            c, o, _ = closer[open_tok.type]
            msg = f"{lead}expected {c} to close the {o} opened at {open_tok.line}:{open_tok.column}"
            return codes.STL103(msg, span)
        if wants_atom:
            core = f"expected {what}{after}"
        else:
            core = "expected " + " or ".join(sorted(_WORDS.get(e, e.lower()) for e in expected if e != "$END")) + after
        if rule is not None:
            where = "" if at_eof else " before the next statement"
            return codes.STL101(f"{lead}the formula of rule '{rule}' is incomplete{where}", span, hint=core)
        return codes.STL101(f"{lead}{core}", span)

    tok = chunk[k]
    span = _tok_span(file, tok)
    found = f", found {_quote(tok)}"
    if tok.type in ("RPAR", "RSQB") and not stack:
        return codes.STL103(f"unmatched {_quote(tok)}: it closes nothing", span)
    if tok.type == "BANG" and text.startswith("!=", tok.start_pos) and not text.startswith("!==", tok.start_pos):
        return codes.STL101("'!=' is not an operator", Span(file, tok.line, tok.column, tok.line, tok.column + 2),
                            hint="not-equal is written !== in RTAMT's language")
    if open_tok is not None and closer[open_tok.type][2] in expected and not wants_atom:
        c, o, _ = closer[open_tok.type]
        return codes.STL103(f"expected {c} to close the {o} opened at {open_tok.line}:{open_tok.column}{found}", span)
    if tok.type == "EQUAL" and "EQEQ" in expected:
        hint = "equality is written == ('=' names a rule)"
    if tok.type == "LSQB" and prev is not None and prev.type in ("NEXT", "X_OP", "PREV", "Y_OP"):
        hint = "next and prev take no interval: they look one sample ahead or back"
    if "SEMI" in expected:
        return codes.STL101(f"expected ';' or a new statement{found}", span, hint=hint)
    if wants_atom:
        return codes.STL101(f"expected {what}{after}{found}", span, hint=hint)
    words = sorted(_WORDS.get(e, f"'{e.lower()}'") for e in expected)
    if len(words) == 1:
        return codes.STL101(f"expected {words[0]}{after}{found}", span, hint=hint)
    return codes.STL101(f"unexpected {_quote(tok)}{after}; expected one of {', '.join(words)}", span, hint=hint)


def _parse_chunk(text: str, file: str, chunk: list["Token"], at_eof: bool) -> tuple["Tree | None", Diagnostic | None]:
    from lark.exceptions import UnexpectedToken

    ip = _parser().parse_interactive(start="statement")
    stack: list[Token] = []
    for k, tok in enumerate(chunk):
        try:
            ip.feed_token(tok)
        except UnexpectedToken as e:
            return None, _syntax_error(text, file, chunk, k, set(e.expected or ()), stack, at_eof)
        if tok.type in ("LPAR", "LSQB"):
            stack.append(tok)
        elif tok.type in ("RPAR", "RSQB") and stack:
            stack.pop()
    try:
        return ip.feed_eof(chunk[-1]), None
    except UnexpectedToken as e:
        return None, _syntax_error(text, file, chunk, len(chunk), set(e.expected or ()), stack, at_eof)


# ----------------------------------------------------------------------------- tree → AST

_ERR = object()


class _Builder:
    """Turns one statement's parse tree into AST nodes, bottom-up and without recursion."""

    def __init__(self, file: str, diags: list[Diagnostic], parens: set[Span]) -> None:
        self.file = file
        self.diags = diags
        self.parens = parens
        self.too_deep = False
        self.call_terms: set[int] = set()  # calls used as numbers: participant signals, if bound


    def build(self, tree: "Tree") -> Any:
        from lark import Tree

        done: dict[int, Any] = {}
        for sub in tree.iter_subtrees():
            kids = [done[id(c)] if isinstance(c, Tree) else c for c in sub.children]
            if any(k is _ERR for k in kids):
                done[id(sub)] = _ERR
                continue
            done[id(sub)] = getattr(self, "_" + sub.data)(sub.meta, kids)
        return done[id(tree)]

    # -- checks
    def _term(self, item: tuple[Node, int]) -> bool:
        node = item[0]
        if isinstance(node, Call) and len(node.args) == 1 and isinstance(node.args[0], Var):
            # ``d_lon(o)``: a participant's signal when a quantifier binds ``o`` (:meth:`bind`)
            self.call_terms.add(id(node))
            return True
        if isinstance(node, FORMULA_NODES):
            self.diags.append(codes.STL206(
                "a formula cannot be used as a number (in arithmetic, a comparison or a call)",
                node.span or Span.whole_file(self.file),
                hint="compare signals, e.g. 'v <= v_max'; combine formulas with and/or",
            ))
            return False
        return True

    def _formula(self, item: tuple[Node, int]) -> bool:
        node = item[0]
        if isinstance(node, TERM_NODES):
            what = "a number" if isinstance(node, Num) else "an arithmetic expression"
            self.diags.append(codes.STL206(
                f"{what} is not a formula",
                node.span or Span.whole_file(self.file),
                hint="compare it with something, e.g. 'x - y >= 0'",
            ))
            return False
        return True

    def _make(self, meta: Any, node_cls: type, *args: Any, depth: int) -> Any:
        span = _node_span(self.file, meta)
        if depth > MAX_DEPTH:
            if not self.too_deep:
                self.too_deep = True
                self.diags.append(codes.STL108(
                    f"formula nested deeper than {MAX_DEPTH} levels", span,
                    hint="split the formula into named rules and refer to them by name",
                ))
            return _ERR
        return (node_cls(*args, span=span), depth)

    def _number(self, tok: "Token", in_interval: bool) -> tuple[float, str] | None:
        s = str(tok)
        unit = "ms" if s.endswith("ms") else "s" if s.endswith("s") else ""
        num = s[: len(s) - len(unit)]
        value = float(num)
        span = _tok_span(self.file, tok)
        if not math.isfinite(value):
            self.diags.append(codes.STL110(f"number {num} is out of range", span))
            return None
        if unit and not in_interval:
            self.diags.append(codes.STL110(
                f"a time unit ('{unit}') is only allowed in an interval bound", span,
                hint=f"write the plain number {num}, or use it in an interval such as [0:{s}]",
            ))
            return None
        return (value / 1000.0 if unit == "ms" else value), unit

    # -- atoms
    def _num(self, meta: Any, kids: list) -> Any:
        got = self._number(kids[0], in_interval=False)
        return _ERR if got is None else self._make(meta, Num, got[0], depth=1)

    def _var(self, meta: Any, kids: list) -> Any:
        return self._make(meta, Var, str(kids[0]), depth=1)

    def _true(self, meta: Any, kids: list) -> Any:
        return self._make(meta, BoolConst, True, depth=1)

    def _false(self, meta: Any, kids: list) -> Any:
        return self._make(meta, BoolConst, False, depth=1)

    def _paren(self, meta: Any, kids: list) -> Any:
        inner = kids[1]
        if inner[0].span is not None:
            self.parens.add(inner[0].span)
        return inner

    def _call(self, meta: Any, kids: list) -> Any:
        args = [k for k in kids[1:] if isinstance(k, tuple)]
        if not all(self._term(a) for a in args):
            return _ERR
        depth = 1 + max((a[1] for a in args), default=0)
        return self._make(meta, Call, str(kids[0]), tuple(a[0] for a in args), depth=depth)

    def _edge(self, meta: Any, kids: list) -> Any:
        inner = kids[2]
        if not self._formula(inner):
            return _ERR
        return self._make(meta, Edge, str(kids[0]), inner[0], depth=inner[1] + 1)

    def _abs(self, meta: Any, kids: list) -> Any:
        inner = kids[2]
        if not self._term(inner):
            return _ERR
        return self._make(meta, Abs, inner[0], depth=inner[1] + 1)

    # -- terms
    def _neg(self, meta: Any, kids: list) -> Any:
        inner = kids[1]
        if not self._term(inner):
            return _ERR
        return self._make(meta, Neg, inner[0], depth=inner[1] + 1)

    def _arith(self, meta: Any, kids: list) -> Any:
        left, op, right = kids
        if not (self._term(left) & self._term(right)):
            return _ERR
        return self._make(meta, Arith, str(op), left[0], right[0], depth=max(left[1], right[1]) + 1)

    # -- formulas
    def _compare(self, meta: Any, kids: list) -> Any:
        left, op, right = kids
        if not (self._term(left) & self._term(right)):
            return _ERR
        return self._make(meta, Compare, str(op), left[0], right[0], depth=max(left[1], right[1]) + 1)

    def _interval(self, meta: Any, kids: list) -> Any:
        lo = self._number(kids[1], in_interval=True)
        hi = self._number(kids[3], in_interval=True)
        if lo is None or hi is None:
            return _ERR
        unit = hi[1] if lo[1] in (hi[1], "") else "s"
        return Interval(lo[0], hi[0], unit, span=_node_span(self.file, meta))

    def _temporal(self, meta: Any, kids: list) -> Any:
        op, operand = kids[0], kids[-1]
        interval = kids[1] if len(kids) == 3 else None
        if not self._formula(operand):
            return _ERR
        if op.type in ("NOT", "BANG"):
            return self._make(meta, Not, operand[0], depth=operand[1] + 1)
        return self._make(meta, Temporal, _TEMPORAL_OPS[op.type], interval, operand[0], depth=operand[1] + 1)

    def _bintemporal(self, meta: Any, kids: list) -> Any:
        left, op, right = kids[0], kids[1], kids[-1]
        interval = kids[2] if len(kids) == 4 else None
        if not (self._formula(left) & self._formula(right)):
            return _ERR
        return self._make(meta, BinTemporal, _BINTEMP_OPS[op.type], interval, left[0], right[0],
                          depth=max(left[1], right[1]) + 1)

    def _quantifier(self, meta: Any, kids: list) -> Any:
        op, var, body = kids[0], kids[1], kids[-1]
        if not self._formula(body):
            return _ERR
        domain = str(kids[3]) if len(kids) == 6 else DEFAULT_DOMAIN
        made = self._make(meta, Quantifier, _QUANT_OPS[op.type], str(var), domain, body[0], depth=body[1] + 1)
        if made is _ERR:
            return _ERR
        return (replace(made[0], var_span=_tok_span(self.file, var)), made[1])

    def _binary(self, meta: Any, kids: list) -> Any:
        left, op, right = kids
        if not (self._formula(left) & self._formula(right)):
            return _ERR
        return self._make(meta, Binary, _BOOL_OPS[op.type], left[0], right[0], depth=max(left[1], right[1]) + 1)

    # -- statements
    def bind(self, node: Node, scope: frozenset[str] = frozenset()) -> Node:
        """``node`` with every call ``name(o)`` whose argument is a participant bound by an
        enclosing quantifier turned into a :class:`ParticipantSignal`; a call left that was used
        as a number is reported (STL206)."""
        return rewrite(node, lambda n: self._bound(n, scope))

    def _bound(self, node: Node, scope: frozenset[str]) -> Node | None:
        """:meth:`bind`'s rewrite of one node (None: bind its children)."""
        if isinstance(node, Call) and len(node.args) == 1 and isinstance(node.args[0], Var):
            if node.args[0].name in scope:
                return ParticipantSignal(node.name, node.args[0].name, span=node.span)
            if id(node) in self.call_terms:
                arg = node.args[0].name
                self.diags.append(codes.STL206(
                    f"'{node.name}({arg})' is used as a number, but no quantifier binds '{arg}': a call is a "
                    "predicate (a formula) unless it reads a participant's signal",
                    node.span or Span.whole_file(self.file),
                    hint=f"read a participant's signal inside a quantifier: forall {arg} in vehicles: "
                         f"... {node.name}({arg}) ..."))
            return node
        if isinstance(node, Quantifier):
            body = self.bind(node.body, scope | {node.var})
            return node if body is node.body else replace(node, body=body)
        return None

    def _decl_stmt(self, meta: Any, kids: list) -> Any:
        toks = [k for k in kids if not isinstance(k, tuple)]
        kind = toks[0].type.lower() if toks[0].type in ("INPUT", "OUTPUT", "CONST") else "input"
        type_tok = next(t for t in toks if t.type in ("FLOAT", "INT"))
        name = next(t for t in toks if t.type == "NAME")
        values = [k for k in kids if isinstance(k, tuple)]
        value = None
        if values:
            if not self._term(values[0]):
                return _ERR
            value = self.bind(values[0][0])
        span = _node_span(self.file, meta)
        return Declaration(kind, str(type_tok), str(name), value, span=span)  # type: ignore[arg-type]

    def _rule_stmt(self, meta: Any, kids: list) -> Any:
        name, formula = kids[0], kids[2]
        if not self._formula(formula):
            return _ERR
        return Rule(str(name), self.bind(formula[0]), name_span=_tok_span(self.file, name),
                    span=_node_span(self.file, meta))

    def _spec_stmt(self, meta: Any, kids: list) -> Any:
        return None  # `specification NAME`: RTAMT's spec name, ignored

    def _import_stmt(self, meta: Any, kids: list) -> Any:
        self.diags.append(codes.STL109(
            "imports are not supported", _node_span(self.file, meta),
            hint="declare each signal with 'input float NAME'; twolevel takes signals from the world",
        ))
        return _ERR

    def _statement(self, meta: Any, kids: list) -> Any:
        return kids[0]


# ----------------------------------------------------------------------------- entry point


def parse(text: str, file: str) -> tuple[RuleFile | None, list[Diagnostic]]:
    """Parse rule-file ``text`` (``file`` names it in spans). ``None`` when any error was found.

    Lines end at LF, CRLF or a bare CR (:data:`twolevel.diagnostics.LINE_BREAK`): the text is
    read with each of them as ``\\n``, so positions are those an editor shows.

    The result is a function of (the text with ``\\n`` line breaks, ``file``) and immutable,
    so the last few are kept: loading a scenario reads its rule files once for the names, once
    for the rules and again per parameter corner ``check`` tries; a tree of scenarios shares the
    same rule files."""
    rf, diags = _parse_cached(LINE_BREAK.sub("\n", text), file)
    return rf, list(diags)


@functools.lru_cache(maxsize=64)
def _parse_cached(text: str, file: str) -> tuple[RuleFile | None, tuple[Diagnostic, ...]]:
    rf, diags = _parse(text, file)
    return rf, tuple(diags)


def _parse(text: str, file: str) -> tuple[RuleFile | None, list[Diagnostic]]:
    pre = _scan_nesting(text, file)
    if pre is not None:
        return None, [pre]
    tokens, diags = _lex(text, file)
    deep = _scan_prefix_chains(tokens, file)
    if deep is not None:
        return None, diags + [deep]
    parens: set[Span] = set()
    builder = _Builder(file, diags, parens)
    decls: list[Declaration] = []
    rules: list[Rule] = []
    chunks = _split(tokens)
    for i, chunk in enumerate(chunks):
        tree, err = _parse_chunk(text, file, chunk, at_eof=i == len(chunks) - 1)
        if err is not None:
            diags.append(err)
            continue
        builder.too_deep = False
        item = builder.build(tree)
        if isinstance(item, Declaration):
            decls.append(item)
        elif isinstance(item, Rule):
            rules.append(item)
    if any(d.is_error for d in diags):
        return None, diags
    end_line, end_col = _offset_pos(text, len(text))
    if not decls and not rules:
        diags.append(codes.STL104(
            "the file holds no declaration and no rule", Span.whole_file(file),
            hint="declare signals ('input float v') and write rules ('name = formula;')",
        ))
    rf = RuleFile(file, tuple(decls), tuple(rules), frozenset(parens), span=Span(file, 1, 1, end_line, end_col))
    return rf, diags
