"""Episodes of the closed loop in which no plan satisfied every rule, explained once each.

When the high level finds no plan that satisfies every rule (the MILP is infeasible) it falls
back on its previous plan shifted by a step, or braking, and the low level checks that as usual.
An episode is a maximal run of such steps. At its first step the rules that conflict are found
(:func:`~twolevel.control.high_level.conflicts.conflicting_rules`: the step re-solved without
each rule, then each pair; only the MILP planner can say, others leave it unexplained), outside
the step's timing; over the episode the decisions the car applied and its speed are recorded.
The run's summary (``run.json``, the command's table) lists the episodes and ``simulate`` gives
one SIM618 for each.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from twolevel.sim.summary import StepDecision, Unsatisfiable

__all__ = ["UnsatisfiableLog"]


@dataclass
class _Open:
    t_start: float
    rules: tuple[str, ...] | None
    v_start: float
    t_end: float = 0.0
    v_end: float = 0.0
    decisions: dict[str, int] = field(default_factory=dict)


class UnsatisfiableLog:
    """The episodes of a run so far (:attr:`episodes`, closed ones; :meth:`close` ends the open one)."""

    def __init__(self) -> None:
        self.episodes: list[Unsatisfiable] = []
        self._open: _Open | None = None

    def observe(self, t: float, unsatisfiable: bool, decision: StepDecision, v: float,
                explain: Callable[[], tuple[str, ...] | None]) -> None:
        """Step at ``t`` [s]: whether no plan satisfied the rules, the ``decision`` applied and the
        speed ``v`` [m/s]; ``explain`` is called at an episode's first step (the conflicting rules,
        None when the planner cannot say)."""
        if not unsatisfiable:
            self.close()
            return
        if self._open is None:
            self._open = _Open(t, explain(), v)
        ep = self._open
        ep.t_end, ep.v_end = t, v
        ep.decisions[str(decision)] = ep.decisions.get(str(decision), 0) + 1

    def close(self) -> None:
        """End the open episode, if any (the run ended, or a plan satisfied the rules again)."""
        if self._open is not None:
            self.episodes.append(_episode(self._open))
            self._open = None

    def all(self) -> tuple[Unsatisfiable, ...]:
        """Every episode, the open one included (as it stands)."""
        return (*self.episodes, *(() if self._open is None else (_episode(self._open),)))


def _episode(ep: _Open) -> Unsatisfiable:
    return Unsatisfiable(round(ep.t_start, 9), round(ep.t_end, 9), sum(ep.decisions.values()), ep.rules or (),
                         bool(ep.rules), dict(ep.decisions), ep.v_start, ep.v_end)
