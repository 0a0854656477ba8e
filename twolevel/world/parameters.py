"""Scenario parameters: ``${expr}`` values replaced by numbers before the scenario is validated.

A scenario declares ``parameters:`` (a range, choices or a normal distribution each, see
:class:`~twolevel.world.schema.Parameter`) and refers to them from any numeric field as the
whole value ``${name}`` or an expression of them, ``${gap + 10}``, ``${2 * v0}``, with ``+ - * /
**``, parentheses and ``min``, ``max``, ``abs``. In block style write ``s: ${gap}``; inside a flow
mapping (``{lane: a, s: "${gap}"}``) quote it, as YAML reads braces there as a mapping.

The substitution works on the document, not the text, so every value keeps its position: a
diagnostic about a substituted value points at the ``${...}`` that produced it and its hint says
which values the parameters had. Values default to each parameter's nominal value
(:meth:`~twolevel.world.schema.Parameter.nominal`); campaigns pass others.

Imported by ``twolevel check``: pydantic and the standard library only.
"""

from __future__ import annotations

import ast
import difflib
import math
import operator
import re
import warnings
from dataclasses import dataclass, replace
from typing import Any, Callable, Mapping

from pydantic import TypeAdapter, ValidationError

from twolevel.diagnostics import Diagnostic
from twolevel.world.codes import YML417, YML424, YML425
from twolevel.world.document import Document, Path_
from twolevel.world.schema import Parameter, ScenarioFile

__all__ = ["Substitution", "declared", "substitute", "explain", "evaluate", "check_variants", "REFERENCE"]

#: A value that is a parameter reference: ``${expression}`` and nothing else.
REFERENCE = re.compile(r"^\s*\$\{(.*)\}\s*$", re.DOTALL)
#: Top-level keys whose values are never substituted (they declare the parameters).
_DECLARING = ("parameters", "variants")
_BINARY: dict[type, Callable[[float, float], float]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
    ast.Pow: operator.pow,
}
_FUNCTIONS: dict[str, Callable[..., float]] = {"min": min, "max": max, "abs": abs}


class ExpressionError(ValueError):
    """An expression that cannot be evaluated; the message says why."""


@dataclass(frozen=True)
class Substitution:
    """The document with its references replaced, the values the parameters had, and for each
    replaced location the text it held (for hints and for writing the case back out)."""

    document: Document
    values: Mapping[str, float]
    references: Mapping[Path_, str]


_ADAPTER: TypeAdapter[dict[str, Parameter]] | None = None


def declared(data: Mapping[str, Any]) -> dict[str, Parameter]:
    """The parameters a scenario's data declares ({} when there are none or they are invalid:
    the scenario's validation then reports why)."""
    global _ADAPTER
    raw = data.get("parameters")
    if not isinstance(raw, dict) or not raw:
        return {}
    if _ADAPTER is None:
        _ADAPTER = TypeAdapter(dict[str, Parameter])
    try:
        return _ADAPTER.validate_python(raw)
    except ValidationError:
        return {}


def evaluate(text: str, env: Mapping[str, float]) -> float:
    """The value of the expression ``text`` over the parameter values ``env``; raises
    :class:`ExpressionError` for anything but numbers, names, ``+ - * / **``, parentheses and
    ``min``, ``max``, ``abs``, or a result that is not a finite number."""
    try:
        with warnings.catch_warnings():  # "1in" warns of an invalid literal on stderr, then fails
            warnings.simplefilter("ignore", SyntaxWarning)
            tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError):  # ValueError: a NUL character
        raise ExpressionError(f"'{text.strip()}' is not an expression") from None
    except (RecursionError, MemoryError):
        raise ExpressionError(f"'{text.strip()[:40]}…' is nested too deeply") from None

    def ev(node: ast.AST) -> float:
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            try:
                return float(node.value)
            except OverflowError:  # an integer beyond the floats
                raise ExpressionError(f"'{text.strip()}' has a number too large for a float") from None
        if isinstance(node, ast.Name):
            if node.id not in env:
                close = difflib.get_close_matches(node.id, list(env), n=1, cutoff=0.5)
                hint = f" — did you mean '{close[0]}'?" if close else ""
                raise ExpressionError(f"no parameter '{node.id}'{hint}")
            return float(env[node.id])
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            value = ev(node.operand)
            return -value if isinstance(node.op, ast.USub) else value
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            left, right = ev(node.left), ev(node.right)
            try:
                result = _BINARY[type(node.op)](left, right)
            except (ZeroDivisionError, OverflowError):
                raise ExpressionError(f"'{text.strip()}' has no value (division by zero or overflow)") from None
            if isinstance(result, complex):  # a negative number to a fractional power
                raise ExpressionError(f"'{text.strip()}' is not a real number")
            return float(result)
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS
                and not node.keywords and node.args):
            args = [ev(a) for a in node.args]
            if node.func.id == "abs" and len(args) != 1:
                raise ExpressionError(f"'{text.strip()}': abs takes one value")
            return float(_FUNCTIONS[node.func.id](*args) if len(args) > 1 or node.func.id == "abs" else args[0])
        raise ExpressionError(f"'{text.strip()}': only numbers, parameter names, + - * / **, parentheses, "
                              "min, max and abs are allowed")

    try:
        value = ev(tree)
    except RecursionError:
        raise ExpressionError(f"'{text.strip()[:40]}…' is nested too deeply") from None
    if not math.isfinite(value):
        raise ExpressionError(f"'{text.strip()}' is not a finite number")
    return value


def substitute(doc: Document, values: Mapping[str, float] | None = None) -> tuple[Substitution, list[Diagnostic]]:
    """Replace every ``${...}`` value of a scenario document by its number.

    ``values`` override the nominal values of the declared parameters (a name that is not
    declared is YML425). Returns the substitution and its diagnostics (YML424 for a reference
    that cannot be evaluated or is not the whole value); never raises for bad input.
    """
    params = declared(doc.data)
    diags: list[Diagnostic] = []
    env = {name: p.nominal() for name, p in params.items()}
    for name, value in (values or {}).items():
        if name not in params:
            close = difflib.get_close_matches(name, list(params), n=1, cutoff=0.5)
            diags.append(YML425(f"the scenario declares no parameter '{name}'", doc.locate(("parameters",)),
                                hint=f"did you mean '{close[0]}'?" if close else
                                f"declared: {', '.join(params) or 'none'}"))
            continue
        env[name] = float(round(value)) if params[name].integer else float(value)
    refs: dict[Path_, str] = {}

    def walk(value: Any, loc: Path_) -> Any:
        if isinstance(value, dict):
            return {k: (v if not loc and k in _DECLARING else walk(v, loc + (k,))) for k, v in value.items()}
        if isinstance(value, list):
            return [walk(v, loc + (i,)) for i, v in enumerate(value)]
        if isinstance(value, str) and "${" in value:
            m = REFERENCE.match(value)
            where = doc.locate(loc, value=True)
            if m is None:
                diags.append(YML424(f"'{value}': a parameter reference must be the whole value", where,
                                    hint="write the value as ${expression}, e.g. s: ${gap + 10}"))
                return value
            try:
                number = evaluate(m.group(1), env)
            except ExpressionError as exc:
                diags.append(YML424(str(exc), where, hint="parameters are declared under 'parameters:'"))
                return value
            refs[loc] = value.strip()
            return int(number) if number.is_integer() and abs(number) < 2**53 else number
        return value

    data = walk(doc.data, ())
    return Substitution(Document(doc.path, data, doc.where), env, refs), diags


def explain(diags: list[Diagnostic], sub: Substitution) -> list[Diagnostic]:
    """The diagnostics, those about a substituted value with a hint naming the reference and
    the parameter values it was evaluated with."""
    if not sub.references:
        return diags
    spans = {sub.document.locate(loc, value=True): text for loc, text in sub.references.items()}
    shown = ", ".join(f"{k} = {v:g}" for k, v in sub.values.items())
    out = []
    for d in diags:
        text = spans.get(d.span)
        if text is None:
            out.append(d)
            continue
        note = f"the value comes from {text} with {shown}"
        out.append(replace(d, hint=f"{d.hint}; {note}" if d.hint else note))
    return out


def check_variants(spec: ScenarioFile, doc: Document) -> list[Diagnostic]:
    """Variants have distinct names and give values only to declared parameters."""
    out: list[Diagnostic] = []
    seen: dict[str, int] = {}
    for i, variant in enumerate(spec.variants):
        if variant.name in seen:
            first = doc.locate(("variants", seen[variant.name], "name"), value=True)
            out.append(YML417(f"duplicate variant name '{variant.name}'", doc.locate(("variants", i, "name"), value=True),
                              hint=f"first defined at {first.file}:{first.line}"))
        seen.setdefault(variant.name, i)
        for name in variant.parameters:
            if name not in spec.parameters:
                close = difflib.get_close_matches(name, list(spec.parameters), n=1, cutoff=0.5)
                out.append(YML425(f"variant '{variant.name}' sets '{name}', which the scenario does not declare",
                                  doc.locate(("variants", i, "parameters", name)),
                                  hint=f"did you mean '{close[0]}'?" if close else
                                  f"declared parameters: {', '.join(spec.parameters) or 'none'}"))
    return out
