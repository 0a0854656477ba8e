"""What every solver backend answers, and what each one declares it can do.

The backends (:mod:`twolevel.milp.highs`, :mod:`twolevel.milp.clarabel`,
:mod:`twolevel.milp.gurobi`) each import their library lazily, map the library's statuses onto
:class:`Status`, return a :class:`Solution`, and declare their :class:`Capabilities` in a module
constant ``CAPABILITIES``. No heavy import here.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

__all__ = ["ValueEnum", "Status", "Solution", "Capabilities"]


class ValueEnum(str, enum.Enum):
    """A string enum that prints, formats, compares and hashes as its value, so that it can stand
    wherever the plain string stood (CSV cells, JSON, f-strings, dictionary keys)."""

    __str__ = str.__str__
    __format__ = str.__format__
    __hash__ = str.__hash__


class Status(ValueEnum):
    """Outcome of a solve, the same for every backend."""

    OPTIMAL = "optimal"
    INFEASIBLE = "infeasible"
    UNBOUNDED = "unbounded"
    TIME_LIMIT = "time_limit"
    ERROR = "error"


@dataclass(frozen=True)
class Solution:
    """A backend's answer. ``x`` is None when there is no primal point; on ``time_limit`` it is
    the incumbent if one was found. Times in milliseconds [ms]."""

    status: Status
    x: np.ndarray | None
    objective: float
    solve_ms: float
    setup_ms: float = 0.0
    gap: float = float("nan")
    info: dict[str, object] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status is Status.OPTIMAL


@dataclass(frozen=True)
class Capabilities:
    """What a backend does with a :class:`~twolevel.milp.model.MilpModel`.

    ``integer``: it branches on integer columns (else it needs them fixed: a mode);
    ``quadratic``: it minimises the quadratic cost ``½ xᵀPx`` (else the cost's linear part only);
    ``mip_start``: it takes a starting point; ``time_limit``: it stops at a time limit [s];
    ``in_place_update``: new values of a model of the same pattern reuse the solver object;
    ``export``: it writes the model to a file (``.mps``/``.lp``)."""

    name: str
    integer: bool
    quadratic: bool
    mip_start: bool = False
    time_limit: bool = True
    in_place_update: bool = False
    export: bool = False
