"""Diagnostic codes of the STL → MILC compiler (``MIL501``–``MIL505``) and the error that carries them.

Declared once here; each :class:`~twolevel.diagnostics.Code` registers itself. A rule the
compiler cannot encode is bad input (``bad_input``: ``twolevel plan`` exits 2). A stage raises
:class:`EncodeError` with the diagnostic; :func:`twolevel.compiler.driver.encode` turns it into
a diagnostic of the result, never an exception for its caller. No heavy imports.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Diagnostic, Severity, Span
from twolevel.stl import ast

__all__ = ["MIL501", "MIL502", "MIL503", "MIL504", "MIL505", "EncodeError", "NOWHERE", "span_of"]

MIL501 = Code("MIL501", "nonlinear-predicate", Severity.ERROR,
              "A predicate is not linear in the decision variables and cannot be encoded.", bad_input=True)
MIL502 = Code("MIL502", "unbounded-big-m", Severity.ERROR,
              "A disjunction involves an unbounded variable: no finite big-M exists.", bad_input=True)
MIL503 = Code("MIL503", "rule-violated-by-constants", Severity.WARNING,
              "A rule is violated by signals known at solve time; no plan can satisfy it.")
MIL504 = Code("MIL504", "unknown-name", Severity.ERROR,
              "A formula names a signal, constant, rule or built-in the encoder was not given.", bad_input=True)
MIL505 = Code("MIL505", "undefined-robustness", Severity.ERROR,
              "A formula's robustness is undefined (NaN: inf - inf, e.g. iff/xor of two sides both +inf), as the "
              "offline monitor finds it (SIM607): it cannot be encoded.", bad_input=True)

#: The span of a diagnostic about the rules as a whole (no single node to point at).
NOWHERE = Span("<rules>")


class EncodeError(Exception):
    """Raised inside the compiler with the diagnostic to report."""

    def __init__(self, diagnostic: Diagnostic) -> None:
        super().__init__(diagnostic.message)
        self.diagnostic = diagnostic


def span_of(node: ast.Node | None) -> Span:
    """Where ``node`` is in its rule file, or :data:`NOWHERE` when it has no span."""
    return node.span if node is not None and node.span is not None else NOWHERE
