"""The rules as the low level judges them, and which of them allow screening on prefixes.

**Prefix-bounded rules.** A formula built from pointwise predicates, past operators,
``and``/``or``, ``always`` and ``next`` (no ``eventually``/``until``/``unless`` and no negation
above a future operator; :func:`prefix_bounded`) has, at any sample of a trace cut short, a
robustness ≥ its robustness on the whole trace (``always`` over fewer samples, each signal at
k ≤ j the same: the rollout and the signals are causal). When every rule is, a candidate a
rule rejects on a prefix of its prediction is rejected on the whole
(:mod:`twolevel.control.low_level.screening`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from twolevel.stl import analysis, ast
from twolevel.stl.typecheck import RuleSet

__all__ = ["RuleCheck", "rule_checks", "MAX_PAST", "prefix_bounded"]

MAX_PAST = 3000
"""Past samples kept for a rule with an unbounded past operator (``once`` without a bound)."""

_POINTWISE_CALLS = frozenset({"collision_free"})
"""Built-in predicates whose value at a sample depends on the signals at that sample only."""


@dataclass(frozen=True, eq=False)
class RuleCheck:
    """One rule as the low level judges it: name, self-contained formula, past depth [samples]."""

    name: str
    formula: ast.Node
    past: int


def rule_checks(rulesets: Sequence[RuleSet], dt: float) -> tuple[list[RuleCheck], dict[str, float]]:
    """The rules of bound rule sets as :class:`RuleCheck` s (formulas self-contained, constants
    substituted), and the constants (for rules that name them)."""
    out: list[RuleCheck] = []
    consts: dict[str, float] = {}
    for rs in rulesets:
        consts.update({k: float(v) for k, v in rs.consts.items() if v is not None})
        for r in rs.rules:
            f = rs.formula(r.name)
            depth = analysis.past_depth(f, dt)
            past = int(math.ceil(depth / dt - 1e-9)) if math.isfinite(depth) else MAX_PAST
            out.append(RuleCheck(r.name, f, min(past, MAX_PAST)))
    return out, consts


def _causal(node: ast.Node) -> bool:
    """No future operator and no built-in that could look beyond the sample: the value at k
    depends on samples ≤ k only."""
    for n in node.walk():
        if isinstance(n, (ast.Temporal, ast.BinTemporal)) and n.op in ast.FUTURE_OPS:
            return False
        if isinstance(n, ast.Call) and n.name not in _POINTWISE_CALLS:
            return False
    return True


def prefix_bounded(node: ast.Node) -> bool:
    """Whether a formula's robustness at any sample of a trace cut short is ≥ its robustness on
    the whole trace (windows truncated at the end, RTAMT's offline semantics): causal formulas,
    and ``and``/``or``/``always``/``next``/past operators over prefix-bounded operands
    (``implies`` with a causal antecedent). Conservative: False when unsure."""
    if _causal(node):
        return True
    if isinstance(node, ast.Binary):
        if node.op in ("and", "or"):
            return prefix_bounded(node.left) and prefix_bounded(node.right)
        if node.op == "implies":
            return _causal(node.left) and prefix_bounded(node.right)
        return False
    if isinstance(node, ast.Temporal):
        return (node.op in ast.PAST_OPS or node.op in ("always", "next")) and prefix_bounded(node.operand)
    if isinstance(node, ast.BinTemporal):
        return node.op in ast.PAST_OPS and prefix_bounded(node.left) and prefix_bounded(node.right)
    return False
