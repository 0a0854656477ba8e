"""Check rule files end to end (read → parse → typecheck) and load them for the other stages.

This is what ``twolevel check`` calls for ``*.stl`` files, and what the monitor and the encoder
call to get a :class:`~twolevel.stl.typecheck.RuleSet`. It imports no numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

from twolevel.diagnostics import Diagnostic, Span, sort_key
from twolevel.stl import codes
from twolevel.stl.ast import RuleFile
from twolevel.stl.parser import parse
from twolevel.stl.source import read_source
from twolevel.stl.typecheck import RuleSet, overflow_diagnostics, typecheck

__all__ = ["LintResult", "check_source", "check_file", "load_ruleset"]


@dataclass(frozen=True)
class LintResult:
    """The outcome of checking one rule file. ``source`` is ``None`` when it could not be read;
    ``rulefile``/``ruleset`` are ``None`` when it did not parse."""

    file: str
    source: str | None
    rulefile: RuleFile | None
    ruleset: RuleSet | None
    diagnostics: tuple[Diagnostic, ...]

    @property
    def ok(self) -> bool:
        """No error (warnings allowed)."""
        return not any(d.is_error for d in self.diagnostics)


def check_source(
    text: str,
    file: str,
    *,
    dt: float | None = None,
    horizon: int | None = None,
    provided_signals: frozenset[str] | None = None,
    participant_signals: frozenset[str] | None = None,
) -> LintResult:
    """Parse and type-check rule-file ``text`` (``file`` names it in the diagnostics)."""
    rf, diags = parse(text, file)
    rs = None
    if rf is not None:
        rs, more = typecheck(rf, dt=dt, horizon=horizon, provided_signals=provided_signals,
                             participant_signals=participant_signals)
        diags = diags + more
    return LintResult(file, text, rf, rs, tuple(sorted(diags, key=sort_key)))


def check_file(
    path: str,
    *,
    dt: float | None = None,
    horizon: int | None = None,
    provided_signals: frozenset[str] | None = None,
    participant_signals: frozenset[str] | None = None,
) -> LintResult:
    """Read and check the rule file at ``path``; never raises on bad input."""
    text, diags = read_source(path)
    if text is None:
        return LintResult(path, None, None, None, tuple(diags))
    return check_source(text, path, dt=dt, horizon=horizon, provided_signals=provided_signals,
                        participant_signals=participant_signals)


def load_ruleset(
    path: str,
    consts: Mapping[str, float] | None = None,
    *,
    dt: float | None = None,
    provided_signals: frozenset[str] | None = None,
    participant_signals: frozenset[str] | None = None,
) -> tuple[RuleSet | None, list[Diagnostic]]:
    """The checked rule set of ``path`` with ``consts`` bound, for the monitor and the encoder.

    ``None`` when the file has errors, a binding names no constant (STL219), or a constant is
    still unbound (STL217, raised to an error here). Warnings are returned alongside.
    """
    res = check_file(path, dt=dt, provided_signals=provided_signals, participant_signals=participant_signals)
    diags = list(res.diagnostics)
    if res.ruleset is None or not res.ok:
        return None, diags
    rs = res.ruleset
    consts = dict(consts or {})
    whole = Span.whole_file(path)
    unknown = sorted(set(consts) - set(rs.consts))
    for name in unknown:
        diags.append(codes.STL219(f"binding for '{name}', which is not a constant of this file", whole,
                                  hint=f"constants: {', '.join(rs.consts) or 'none'}"))
    if unknown:
        return None, diags
    bad = [name for name, value in consts.items() if not math.isfinite(float(value))]
    for name in bad:
        diags.append(codes.STL222(f"constant '{name}' is bound to {float(consts[name])!r}, not a finite number", whole,
                                  hint="bind it to a finite number"))
    if bad:
        return None, [d for d in diags if d.code != codes.STL217.id]
    rs = rs.bind(consts)
    diags = [d for d in diags if d.code != codes.STL217.id]
    if consts:  # the bound values may make a term overflow that the declared ones did not
        values = {k: v for k, v in rs.consts.items() if v is not None}
        over = [d for r in rs.rules for d in overflow_diagnostics(r.formula, values, path)]
        if over:
            return None, diags + over
    for name in rs.unbound:
        decl = res.rulefile.declaration(name) if res.rulefile else None
        span = decl.span if decl is not None and decl.span is not None else whole
        diags.append(codes.STL217(f"constant '{name}' has no value and none was bound", span,
                                  hint="bind it in the scenario's rule parameters", severity=codes.E))
    if rs.unbound:
        return None, diags
    return rs, diags
