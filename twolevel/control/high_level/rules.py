"""Which rules the MPC enforces: every rule whose signals it can predict over its horizon.

A rule reading a signal outside :data:`MPC_SIGNALS` (``min_gap``, the boxes' separation, which
the MPC's 1-norm ``collision_free`` replaces) is left to the low level with a ``MIL510`` warning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from twolevel.control.codes import MIL510
from twolevel.control.high_level.neighbours import MPC_NEIGHBOUR_PATTERNS
from twolevel.control.high_level.right_of_way import MPC_ZONE_PATTERNS
from twolevel.diagnostics import Diagnostic, Span
from twolevel.stl import analysis, ast
from twolevel.stl.typecheck import RuleSet
from twolevel.world.provided import PROVIDED_SIGNALS

__all__ = ["MPC_SIGNALS", "MpcRule", "mpc_rules"]

MPC_SIGNALS = (PROVIDED_SIGNALS - {"min_gap", "t_zone", "t_zone_out"}) | MPC_ZONE_PATTERNS | MPC_NEIGHBOUR_PATTERNS
"""The signals the MPC predicts over its horizon (:mod:`twolevel.control.high_level.problem`):
every provided one but the boxes' separation and the ego's times to a conflict area (1/v), the
participant signals of right of way (:mod:`twolevel.control.high_level.right_of_way`) and
those of the vehicles around the ego (:mod:`twolevel.control.high_level.neighbours`)."""


@dataclass(frozen=True, eq=False)
class MpcRule:
    """A rule the MPC requires: its name, self-contained formula, the signals it reads and how
    far its past operators reach (``depth`` [steps])."""

    name: str
    formula: ast.Node
    reads: frozenset[str]
    depth: int


def mpc_rules(rulesets: Sequence[RuleSet], dt: float) -> tuple[list[MpcRule], list[Diagnostic]]:
    """The rules of bound rule sets the MPC requires (period ``dt`` [s]), and a ``MIL510``
    warning for each it leaves to the low level."""
    rules: list[MpcRule] = []
    diags: list[Diagnostic] = []
    for rs in rulesets:
        for r in rs.rules:
            f = rs.formula(r.name)
            reads = frozenset(n for n in analysis.signals_read(f) if n not in rs.consts)
            missing = sorted(reads - MPC_SIGNALS)
            if missing:
                diags.append(MIL510(
                    f"rule '{r.name}' reads {', '.join(missing)}, which the MPC cannot predict; it is "
                    "left to the low level", r.span or Span(rs.file),
                    hint="at the high level use collision_free(d) instead of min_gap"))
                continue
            depth = analysis.past_depth(f, dt)
            steps = int(round(depth / dt)) if math.isfinite(depth) else 10 ** 6
            rules.append(MpcRule(r.name, f, reads, steps))
    return rules, diags
