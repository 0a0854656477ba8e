"""Which rules make a step of the MPC infeasible: the smallest set of rules whose removal makes
it feasible (single rules first, then pairs), found by re-solving the step's MILP without them.

``twolevel plan`` names them (MIL511) for the step it solves; the closed loop
(:mod:`twolevel.sim.unsatisfiable`) names them once per episode of infeasible steps. Each
re-solve is a feasibility problem (the linear part in HiGHS, :data:`SOLVE_LIMIT` at most), so an
explanation costs up to n + n (n − 1) / 2 solves for n rules: it is asked for once, not every step.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from twolevel.control.high_level.linearisation import StepData
from twolevel.control.planner import EgoState, WorldState
from twolevel.milp.highs import solve_highs
from twolevel.milp.solution import Status

if TYPE_CHECKING:
    from twolevel.control.high_level.controller import Carry, HighLevelController

__all__ = ["explain_infeasibility", "conflicting_rules", "SOLVE_LIMIT"]

SOLVE_LIMIT = 5.0
"""[s] Time limit of one feasibility solve."""


def explain_infeasibility(ctrl: "HighLevelController", step: StepData, past: Mapping[str, np.ndarray], P: int
                          ) -> tuple[str, ...]:
    """The rules that conflict: the smallest set (single rules first, then pairs) whose removal
    makes the step feasible; empty when even no rules is infeasible or nothing single/pairwise helps."""
    names = [r.name for r in ctrl.rules]

    def feasible(drop: frozenset[str]) -> bool:
        asm = ctrl.build(step, past, P, drop=drop)
        if asm.encoding.infeasible:
            return False
        sol = solve_highs(asm.model, time_limit=SOLVE_LIMIT)  # feasibility: the linear part is enough
        return sol.status in (Status.OPTIMAL,) or (sol.status is Status.TIME_LIMIT and sol.x is not None)

    if not feasible(frozenset(names)):
        return ()
    single = tuple(n for n in names if feasible(frozenset({n})))
    if single:
        return single
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if feasible(frozenset({a, b})):
                return (a, b)
    return ()


def conflicting_rules(ctrl: "HighLevelController", ego: EgoState | Sequence[float], t: float,
                      world_state: WorldState, history: Mapping[str, np.ndarray] | None, carry: "Carry"
                      ) -> tuple[str, ...]:
    """:func:`explain_infeasibility` of the step ``ctrl`` solved at ``t`` [s] from ``ego`` with
    ``carry`` (what it held before that solve: the same linearisation); ``ctrl``'s own carry is
    left as it is."""
    now = ctrl.carry
    ctrl.carry = carry
    try:
        step, past, P = ctrl.prepare(ego, t, world_state, history)
        return explain_infeasibility(ctrl, step, past, P)
    finally:
        ctrl.carry = now
