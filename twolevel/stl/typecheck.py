"""Check a parsed rule file and turn it into a :class:`RuleSet`.

:func:`typecheck` resolves every name (declared input, constant, or an earlier rule), checks
intervals against the sampling period, horizons against the MPC, predicates for linearity,
calls against the built-in world predicates and, given the world's signal list, that every
input can be provided; it also flags the precedence mixes other STL tools read differently.
Codes: :mod:`twolevel.stl.codes` (STL2xx, STL3xx).

An interval bound that is not a multiple of ``dt`` is an **error** (STL209): the monitor and
the encoder would round the window to whole samples, silently changing what the rule says.
"""

from __future__ import annotations

import difflib
import itertools
import math
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Callable, Collection, Iterable, Mapping

from twolevel.diagnostics import Diagnostic, Span
from twolevel.stl import codes
from twolevel.stl.analysis import fold_term, future_horizon, nonlinear_nodes, overflowing_terms, substitute
from twolevel.stl.ast import (
    FUTURE_OPS,
    Abs,
    Arith,
    BinTemporal,
    Binary,
    Call,
    Compare,
    Declaration,
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

__all__ = ["RuleSet", "typecheck", "overflow_diagnostics", "BUILTIN_ARITY", "DOMAINS", "map_vars",
           "MAX_INTERVAL_SAMPLES", "MAX_INTERVAL_SECONDS"]

MAX_INTERVAL_SAMPLES = 10_000_000
"""Longest finite interval bound [samples of dt] (STL220): beyond it no trace is that long,
and the monitors' windows and delay lines would be absurd."""
MAX_INTERVAL_SECONDS = 1e6
"""Longest finite interval bound [s] when no ``dt`` is known (STL220): about 11.6 days."""

BUILTIN_ARITY: Mapping[str, int] = MappingProxyType({"collision_free": 1})
"""Number of arguments of each built-in world predicate: ``collision_free(d)``, d [m] (what it
means at each level: docs/architecture.md, "The rule language")."""


DOMAINS: tuple[str, ...] = ("vehicles",)
"""What a quantifier ranges over: ``vehicles``, every other participant of the scenario present
(within sensing range) at the sample (docs/architecture.md, "The rule language")."""


def map_vars(node: Node, fn: Callable[[Var], Node]) -> Node:
    """A copy of ``node`` with every :class:`Var` replaced by ``fn(var)``."""
    return rewrite(node, lambda n: fn(n) if isinstance(n, Var) else None)


@dataclass(frozen=True)
class RuleSet:
    """A checked rule file: what it reads, its constants, and its rules in order.

    ``consts`` maps each constant to its value (``None`` until the scenario binds it).
    """

    file: str
    inputs: tuple[str, ...]
    consts: Mapping[str, float | None]
    rules: tuple[Rule, ...]
    outputs: tuple[str, ...] = ()
    types: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))

    def bind(self, values: Mapping[str, float]) -> "RuleSet":
        """A copy with constants set or overridden; a name that is not a constant is a
        ``KeyError``, a value that is not finite (inf, NaN) a ``ValueError``."""
        unknown = sorted(set(values) - set(self.consts))
        if unknown:
            raise KeyError(f"not a constant of {self.file}: {', '.join(unknown)}")
        bad = sorted(k for k, v in values.items() if not math.isfinite(float(v)))
        if bad:
            raise ValueError(f"constants of {self.file} must be finite numbers: "
                             + ", ".join(f"{k} = {float(values[k])!r}" for k in bad))
        merged = dict(self.consts)
        merged.update({k: float(v) for k, v in values.items()})
        return replace(self, consts=MappingProxyType(merged))

    @property
    def unbound(self) -> tuple[str, ...]:
        """Constants still without a value."""
        return tuple(k for k, v in self.consts.items() if v is None)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.rules)

    def rule(self, name: str) -> Rule:
        for r in self.rules:
            if r.name == name:
                return r
        raise KeyError(name)

    def formula(self, name: str, *, inline: bool = True, fold: bool = False) -> Node:
        """Rule ``name``'s formula with the bound constants substituted and, with ``inline``,
        references to earlier rules replaced by their formulas (self-contained for the
        monitor and the encoder). ``fold`` also simplifies (:func:`analysis.substitute`)."""
        consts = {k: v for k, v in self.consts.items() if v is not None}
        done: dict[str, Node] = {}
        for r in self.rules:
            def swap(v: Var) -> Node:
                if v.name in consts:
                    return Num(consts[v.name], span=v.span)
                if inline and v.name in done:
                    return done[v.name]
                return v

            f = map_vars(r.formula, swap)
            done[r.name] = substitute(f, {}) if fold else f
            if r.name == name:
                return done[name]
        raise KeyError(name)


# ----------------------------------------------------------------------------- helpers


def _span(node: Node, fallback: str) -> Span:
    return node.span or Span.whole_file(fallback)


SUGGESTION_BUDGET = 200_000
"""Most name comparisons one file's "did you mean" hints may cost: a machine-written file with
tens of thousands of unknown names is still checked in linear time (its later findings go
without the hint)."""


def _did_you_mean(name: str, candidates: Iterable[str]) -> str | None:
    close = difflib.get_close_matches(name, sorted(set(candidates)), n=1, cutoff=0.6)
    return f"did you mean '{close[0]}'?" if close else None


def _walk_ctx(node: Node, formula_pos: bool = True) -> Iterable[tuple[Node, bool]]:
    """Every node with whether it stands in a formula position (else a term position)."""
    stack = [(node, formula_pos)]
    while stack:
        n, fpos = stack.pop()
        yield n, fpos
        if isinstance(n, (Compare, Arith, Neg, Abs, Call)):
            stack.extend((c, False) for c in n.children())
        else:
            stack.extend((c, True) for c in n.children())


def _is_prefix(n: Node) -> bool:
    return isinstance(n, (Not, Temporal, Quantifier))


def _operand(n: Node) -> Node:
    """The operand of a prefix operator (a quantifier's body)."""
    return n.body if isinstance(n, Quantifier) else n.operand  # type: ignore[attr-defined]


def _walk_scoped(node: Node) -> Iterable[tuple[Node, frozenset[str]]]:
    """Every node with the participant variables bound by the quantifiers above it."""
    stack: list[tuple[Node, frozenset[str]]] = [(node, frozenset())]
    while stack:
        n, scope = stack.pop()
        yield n, scope
        inner = scope | {n.var} if isinstance(n, Quantifier) else scope
        stack.extend((c, inner) for c in n.children())


class _Checker:
    def __init__(self, rf: RuleFile, dt: float | None, horizon: int | None,
                 provided: frozenset[str] | None, builtins: frozenset[str],
                 participant_signals: frozenset[str] | None = None) -> None:
        self.rf, self.dt, self.horizon, self.provided, self.builtins = rf, dt, horizon, provided, builtins
        self.participant_signals = participant_signals
        self.file = rf.path
        self.diags: list[Diagnostic] = []
        self.parens = rf.parenthesized
        self.budget = SUGGESTION_BUDGET
        self.suggested: dict[tuple[str, tuple[int, ...]], str | None] = {}

    def did_you_mean(self, name: str, *groups: Collection[str]) -> str | None:
        """A "did you mean" hint for ``name`` from the names in ``groups``: once per name and
        source of candidates (the same, possibly growing, collections), within
        :data:`SUGGESTION_BUDGET` comparisons per file (``None`` beyond it)."""
        key = (name, tuple(id(g) for g in groups))
        if key not in self.suggested:
            cost = sum(len(g) for g in groups)
            if cost > self.budget:
                return None
            self.budget -= cost
            self.suggested[key] = _did_you_mean(name, itertools.chain(*groups))
        return self.suggested[key]

    def bare(self, n: Node) -> bool:
        return n.span not in self.parens

    # -- intervals
    def interval(self, iv: Interval) -> None:
        sp = _span(iv, self.file)
        if iv.lo > iv.hi:
            self.diags.append(codes.STL207(f"interval [{iv.lo:g}:{iv.hi:g}] is inverted: it holds no time", sp,
                                           hint=f"write [{iv.hi:g}:{iv.lo:g}]"))
            return
        if self.too_long(iv, sp):
            return
        if iv.lo == iv.hi:
            self.diags.append(codes.STL208(f"interval [{iv.lo:g}:{iv.hi:g}] is a single instant", sp,
                                           hint="the operator only shifts time; widen the interval if a window was meant"))
        if self.dt:
            for b in (iv.lo, iv.hi):
                k = b / self.dt
                if abs(k - round(k)) > 1e-9 * max(1.0, abs(k)):
                    self.diags.append(codes.STL209(
                        f"interval bound {b:g} s is not a multiple of dt = {self.dt:g} s", sp,
                        hint=f"use {round(k) * self.dt:g} or {(math.floor(k) if round(k) > k else math.ceil(k)) * self.dt:g}"))
                    break

    def too_long(self, iv: Interval, sp: Span) -> bool:
        """STL220 for a finite bound beyond the limit (1e7 samples at ``dt``, else 1e6 s)."""
        far = iv.hi if iv.bounded else iv.lo
        if self.dt:
            limit, what = MAX_INTERVAL_SAMPLES * self.dt, f"{MAX_INTERVAL_SAMPLES:.0e} samples of dt = {self.dt:g} s"
        else:
            limit, what = MAX_INTERVAL_SECONDS, f"{MAX_INTERVAL_SECONDS:g} s"
        if not (math.isfinite(far) and far > limit):
            return False
        self.diags.append(codes.STL220(
            f"interval [{iv.lo:g}:{iv.hi:g}] reaches {far:g} s, beyond the limit of {what}", sp,
            hint="no trace is that long: use a shorter bound, or drop the bound for an unbounded operator"))
        return True

    # -- precedence / portability
    def style(self, f: Node) -> None:
        for n in f.walk():
            if isinstance(n, Binary):
                for c in (n.left, n.right):
                    if isinstance(c, Binary) and self.bare(c) and {n.op, c.op} == {"and", "or"}:
                        self.diags.append(codes.STL301(
                            f"'{c.op}' inside '{n.op}' without parentheses", _span(c, self.file),
                            hint="add parentheses: tools differ on whether 'and' binds tighter than 'or'"))
                if n.op == "implies" and isinstance(n.right, Binary) and n.right.op == "implies" and self.bare(n.right):
                    self.diags.append(codes.STL303(
                        "chained '->' without parentheses", _span(n, self.file),
                        hint="write a -> (b -> c) or (a -> b) -> c: tools differ on the grouping"))
            if isinstance(n, (Binary, BinTemporal)):
                self.prefix_left_of(n)
            if isinstance(n, Arith) and isinstance(n.left, Arith) and self.bare(n.left):
                same = (n.op in "+-") == (n.left.op in "+-")
                if same and n.left.op in "-/":
                    self.diags.append(codes.STL305(
                        f"'a {n.left.op} b {n.op} c' without parentheses", _span(n, self.file),
                        hint=f"write (a {n.left.op} b) {n.op} c: RTAMT 0.4.10 computes a {n.left.op} (b {n.op} c)"))

    def prefix_left_of(self, b: Binary | BinTemporal) -> None:
        """A bare prefix operator whose text ends right before ``b``'s operator."""
        n = b.left
        while isinstance(n, (Binary, BinTemporal)) and self.bare(n):
            n = n.right
        if not (_is_prefix(n) and self.bare(n)):
            return
        chain = [n]
        while _is_prefix(_operand(chain[-1])) and self.bare(_operand(chain[-1])):
            chain.append(_operand(chain[-1]))
        op = b.op if isinstance(b, BinTemporal) else {"implies": "->", "iff": "<->"}.get(b.op, b.op)
        temporal = next((c for c in chain if isinstance(c, (Temporal, Quantifier))), None)
        if temporal is not None:
            word = f"{temporal.op} {temporal.var}:" if isinstance(temporal, Quantifier) else temporal.op
            self.diags.append(codes.STL304(
                f"'{word}' followed by '{op}' without parentheses", _span(temporal, self.file),
                hint=f"here it means ({word} ...) {op} ...; write the parentheses, "
                     f"or {word} (... {op} ...) if the operator should cover both"))
        elif b.op == "implies":
            self.diags.append(codes.STL302(
                "'not' followed by '->' without parentheses", _span(chain[0], self.file),
                hint="here it means (not a) -> b; write the parentheses, or not (a -> b)"))


def typecheck(
    rf: RuleFile,
    *,
    dt: float | None = None,
    horizon: int | None = None,
    provided_signals: frozenset[str] | None = None,
    builtins: frozenset[str] = frozenset({"collision_free"}),
    participant_signals: frozenset[str] | None = None,
) -> tuple[RuleSet, list[Diagnostic]]:
    """Check ``rf``; ``dt`` [s] enables the multiple-of-dt check, ``horizon`` [steps] with ``dt``
    the horizon check, ``provided_signals`` the check that the world provides every input,
    ``participant_signals`` the check that it provides every participant signal read (``None``:
    any name is accepted)."""
    ck = _Checker(rf, dt, horizon, provided_signals, builtins, participant_signals)
    diags = ck.diags
    file = rf.path
    first: dict[str, Node] = {}
    inputs: list[str] = []
    outputs: list[str] = []
    consts: dict[str, float | None] = {}
    types: dict[str, str] = {}
    used: set[str] = set()

    def duplicate(name: str, node: Node, span: Span) -> bool:
        if name in first:
            prev = first[name].span
            where = f" (first at line {prev.line})" if prev else ""
            diags.append(codes.STL203(f"'{name}' is declared twice{where}", span))
            return True
        first[name] = node
        return False

    # -- declarations
    for d in rf.declarations:
        sp = _span(d, file)
        if duplicate(d.name, d, sp):
            continue
        types[d.name] = d.type
        if d.kind == "input":
            inputs.append(d.name)
        elif d.kind == "output":
            outputs.append(d.name)
        else:
            consts[d.name] = _const_value(d, consts, ck)
    values = {k: v for k, v in consts.items() if v is not None}
    # -- rules
    rule_lines = {r.name: r for r in rf.rules}
    defined: dict[str, float] = {}  # earlier rules -> future horizon [s]
    assigned: set[str] = set()
    rules: list[Rule] = []
    for r in rf.rules:
        nsp = r.name_span or _span(r, file)
        prior = first.get(r.name)
        if isinstance(prior, Declaration) and prior.kind != "output":
            diags.append(codes.STL205(f"'{r.name}' is declared as {'an input' if prior.kind == 'input' else 'a constant'}; a rule cannot assign it", nsp,
                                      hint="give the rule its own name"))
            continue
        if r.name in assigned:
            diags.append(codes.STL203(f"rule '{r.name}' is defined twice", nsp))
            continue
        if not isinstance(prior, Declaration):
            first[r.name] = r
        _check_names(r, ck, inputs, consts, outputs, defined, rule_lines, used)
        _check_quantifiers(r, ck, set(first) | set(rule_lines))
        for n in r.formula.walk():
            if isinstance(n, (Temporal, BinTemporal)):
                if n.interval is not None:
                    ck.interval(n.interval)
                elif n.op in FUTURE_OPS and n.op != "next":  # next looks one sample ahead
                    diags.append(codes.STL210(
                        f"unbounded '{n.op}': the rule cannot be decided online or inside the MPC horizon",
                        _span(n, file), hint=f"bound it, e.g. {n.op}[0:1]"))
            elif isinstance(n, Call):
                _check_call(n, ck)
            elif isinstance(n, Arith) and n.op == "/":
                _check_divisor(n, values, ck)
            elif isinstance(n, Compare) and n.op in ("==", "!=="):
                if not _integral(n, types):
                    diags.append(codes.STL213(
                        f"'{n.op}' compares real numbers exactly", _span(n, file),
                        hint="compare with a tolerance, e.g. abs(a - b) <= eps"))
        ck.diags.extend(overflow_diagnostics(r.formula, values, file))
        for n in nonlinear_nodes(r.formula, frozenset(consts)):
            what = "a product of two signal expressions" if n.op == "*" else "a division by a signal expression"
            diags.append(codes.STL212(f"{what} is not linear: the rule cannot be encoded in the MPC", _span(n, file),
                                      hint="rewrite it linearly, or keep this rule for the monitors only"))
        fh = future_horizon(r.formula, dt or 0.0, defined)
        if horizon is not None and dt and math.isfinite(fh) and fh > horizon * dt + 1e-9:
            diags.append(codes.STL211(
                f"rule '{r.name}' looks {fh:g} s ahead, beyond the MPC horizon of {horizon} x {dt:g} s = {horizon * dt:g} s",
                nsp, hint="shorten its intervals or lengthen the horizon"))
        ck.style(r.formula)
        defined[r.name] = fh
        assigned.add(r.name)
        rules.append(r)
    # -- declarations never used
    for d in rf.declarations:
        if first.get(d.name) is not d:
            continue
        if d.kind == "output" and d.name not in assigned:
            diags.append(codes.STL202(f"output '{d.name}' is declared but no rule assigns it", _span(d, file)))
        elif d.kind != "output" and d.name not in used:
            diags.append(codes.STL202(f"{'input' if d.kind == 'input' else 'constant'} '{d.name}' is declared but never used",
                                      _span(d, file), hint="remove the declaration or use it in a rule"))
        if d.kind == "input" and provided_signals is not None and d.name not in provided_signals:
            listed = ", ".join(sorted(provided_signals)) or "(nothing)"
            near = ck.did_you_mean(d.name, provided_signals)
            diags.append(codes.STL216(f"the world does not provide signal '{d.name}'", _span(d, file),
                                      hint=(near + " " if near else "") + f"the world provides: {listed}"))
    rs = RuleSet(file, tuple(inputs), MappingProxyType(consts), tuple(rules), tuple(outputs), MappingProxyType(types))
    return rs, diags


def _const_value(d: Declaration, consts: Mapping[str, float | None], ck: _Checker) -> float | None:
    sp = _span(d, ck.file)
    if d.value is None:
        ck.diags.append(codes.STL217(f"constant '{d.name}' has no value: the scenario must bind it", sp))
        return None
    known = {k: v for k, v in consts.items() if v is not None}
    folded = fold_term(d.value, known)
    if isinstance(folded, Num) and math.isfinite(folded.value):
        return folded.value
    bad = sorted({n.name for n in folded.walk() if isinstance(n, Var)})
    if not bad:  # numbers only, yet no finite number: an overflow or a division by zero
        ck.diags.append(codes.STL222(f"the value of constant '{d.name}' is not a finite number (infinite or NaN)",
                                     _span(d.value, ck.file), hint="a constant must be a finite number"))
        return None
    why = f"it reads {', '.join(repr(b) for b in bad)}" if bad else "it does not evaluate to a finite number"
    ck.diags.append(codes.STL218(f"the value of constant '{d.name}' is not a constant: {why}", _span(d.value, ck.file),
                                 hint="a constant's value may use numbers and earlier constants that have values"))
    return None


def _check_names(r: Rule, ck: _Checker, inputs: list[str], consts: Mapping[str, float | None],
                 outputs: list[str], defined: Mapping[str, float], rule_lines: Mapping[str, Rule],
                 used: set[str]) -> None:
    seen: set[tuple[str, int, int]] = set()
    bound = {q.var for q in r.formula.walk() if isinstance(q, Quantifier)}
    for n, fpos in _walk_ctx(r.formula):
        if not isinstance(n, Var) or n.name in bound:  # participants: _check_quantifiers
            continue
        sp = _span(n, ck.file)
        key = (n.name, sp.line, sp.column)
        if key in seen:
            continue
        seen.add(key)
        if n.name in consts or n.name in inputs:
            used.add(n.name)
        elif n.name in defined:
            if not fpos:
                ck.diags.append(codes.STL206(f"rule '{n.name}' is a formula; it cannot be used as a number", sp))
        elif n.name == r.name:
            ck.diags.append(codes.STL204(f"rule '{r.name}' refers to itself", sp))
        elif n.name in rule_lines:
            later = rule_lines[n.name].span
            where = f" (line {later.line})" if later else ""
            ck.diags.append(codes.STL204(f"rule '{n.name}' is used before it is defined{where}", sp,
                                         hint="define it earlier in the file"))
        elif n.name in outputs:
            ck.diags.append(codes.STL201(f"'{n.name}' is declared as an output but no rule assigns it", sp))
        else:
            hint = ck.did_you_mean(n.name, inputs, consts, defined)
            if ck.provided is not None and n.name in ck.provided:
                extra = f"the world provides '{n.name}': declare it with 'input float {n.name}'"
                hint = f"{hint} or {extra}" if hint else extra
            elif hint is None:
                hint = f"declare it, e.g. 'input float {n.name}'"
            ck.diags.append(codes.STL201(f"undeclared name '{n.name}'", sp, hint=hint))


def overflow_diagnostics(formula: Node, values: Mapping[str, float], file: str) -> list[Diagnostic]:
    """STL223 for each innermost term of ``formula`` that overflows once the constants take
    ``values`` (``1e308 * 10``): its robustness would be infinite or NaN at every sample."""
    return [codes.STL223("this arithmetic on constants overflows: its value is not a finite number", _span(n, file),
                         hint="keep constants and their products within ±1.8e308; rescale the units")
            for n in overflowing_terms(formula, values)]


def _check_divisor(n: Arith, values: Mapping[str, float], ck: _Checker) -> None:
    """STL221 when the divisor of ``n`` folds to 0 (a literal, or constants with ``values``)."""
    d = fold_term(n.right, values)
    if isinstance(d, Num) and d.value == 0:
        ck.diags.append(codes.STL221("division by zero: the term is infinite (or NaN) at every sample",
                                     _span(n.right, ck.file), hint="divide by a non-zero constant or a signal"))


def _check_quantifiers(r: Rule, ck: _Checker, names: set[str]) -> None:
    """Quantifiers and what they bind: a known domain (STL224), no nesting (STL228), a variable
    that shadows nothing (STL227) and is used (STL229) only through its signals (STL226), each a
    signal the world provides (STL216)."""
    known = ck.participant_signals
    reported: set[int] = set()  # the arguments of a participant signal's call (STL225 says it)
    for n, scope in _walk_scoped(r.formula):
        if isinstance(n, Call) and known is not None and n.name in known:
            reported.update(id(a) for a in n.args)
        if isinstance(n, Quantifier):
            vsp = n.var_span or _span(n, ck.file)
            if n.domain not in DOMAINS:
                near = ck.did_you_mean(n.domain, DOMAINS)
                ck.diags.append(codes.STL224(f"unknown domain '{n.domain}'", _span(n, ck.file),
                                             hint=(near + " " if near else "") + f"domains: {', '.join(DOMAINS)}"))
            if scope:
                ck.diags.append(codes.STL228(
                    f"quantifier over '{n.var}' inside the quantifier over '{sorted(scope)[0]}'", _span(n, ck.file),
                    hint="participant signals relate one participant to the ego; write the rule with one quantifier"))
            if n.var in names or n.var in scope:
                what = "an enclosing quantifier's variable" if n.var in scope else "a declared name or a rule"
                ck.diags.append(codes.STL227(f"'{n.var}' is already {what}", vsp,
                                             hint="give the participant its own name, e.g. 'o'"))
            if not any(isinstance(m, ParticipantSignal) and m.var == n.var for m in n.body.walk()):
                ck.diags.append(codes.STL229(
                    f"the body reads no signal of '{n.var}'", vsp,
                    hint=f"read its signals, e.g. d_lon({n.var}); as written the rule only asks whether any "
                         "participant is present"))
        elif isinstance(n, Var) and n.name in scope and id(n) not in reported:
            ck.diags.append(codes.STL226(
                f"participant '{n.name}' is not a number or a formula", _span(n, ck.file),
                hint=f"read one of its signals, e.g. d_lon({n.name}) or v({n.name})"))
        elif isinstance(n, ParticipantSignal) and known is not None and n.name not in known:
            near = ck.did_you_mean(n.name, known)
            ck.diags.append(codes.STL216(
                f"the world provides no participant signal '{n.name}'", _span(n, ck.file),
                hint=(near + " " if near else "") + f"participant signals: {', '.join(sorted(known))}"))


def _check_call(n: Call, ck: _Checker) -> None:
    sp = _span(n, ck.file)
    known = ck.participant_signals
    if known is not None and n.name in known:
        got = ", ".join(a.name if isinstance(a, Var) else "..." for a in n.args)
        ck.diags.append(codes.STL225(
            f"'{n.name}({got})' reads a participant's signal: it takes one participant bound by a quantifier",
            sp, hint=f"forall o in vehicles: ... {n.name}(o) ..."))
        return
    if n.name not in ck.builtins:
        near = ck.did_you_mean(n.name, ck.builtins)
        known = ", ".join(sorted(ck.builtins)) or "none"
        ck.diags.append(codes.STL214(f"unknown function '{n.name}'", sp,
                                     hint=(near + " " if near else "") + f"built-in predicates: {known}"))
        return
    want = BUILTIN_ARITY.get(n.name)
    if want is not None and len(n.args) != want:
        ck.diags.append(codes.STL215(
            f"'{n.name}' takes {want} argument{'s' if want != 1 else ''}, got {len(n.args)}", sp))


def _integral(n: Compare, types: Mapping[str, str]) -> bool:
    """True when both sides are integer-valued (int signals/constants and integral numbers)."""
    for m in n.walk():
        if isinstance(m, ParticipantSignal):
            return False
        if isinstance(m, Var) and types.get(m.name) != "int":
            return False
        if isinstance(m, Num) and m.value != int(m.value):
            return False
        if isinstance(m, Arith) and m.op == "/":
            return False
    return True
