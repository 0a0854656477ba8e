"""The high-level planners a run can choose by name (``twolevel simulate --controller``).

* ``twolevel``: the paper's MILP MPC (:mod:`twolevel.control.high_level.controller`);
* ``nmpc`` / ``nmpc-fourwheel``: the NMPC baseline on the kinematic or the four-wheel model
  (:mod:`twolevel.control.nmpc.controller`), the paper's comparison;
* ``reckless``: tracks the route as fast as it allows and ignores traffic and rules
  (:mod:`twolevel.control.reckless`), to show what the low level's safety layer guarantees.

Each is made from a scenario's world with its own rule files and settings.
"""

from __future__ import annotations

from typing import Callable

from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.nmpc.controller import NmpcController
from twolevel.control.planner import Planner
from twolevel.control.reckless import RecklessPlanner
from twolevel.diagnostics import Diagnostic
from twolevel.world.world import World

__all__ = ["CONTROLLERS", "planner_named"]

_MAKERS: dict[str, Callable[[World], tuple[Planner | None, list[Diagnostic]]]] = {
    "twolevel": lambda world: HighLevelController.from_world(world),
    "nmpc": lambda world: NmpcController.from_world(world, model="kinematic"),
    "nmpc-fourwheel": lambda world: NmpcController.from_world(world, model="fourwheel"),
    "reckless": lambda world: RecklessPlanner.from_world(world),
}

CONTROLLERS: tuple[str, ...] = tuple(_MAKERS)
"""The names, the paper's controller first."""


def planner_named(name: str, world: World) -> tuple[Planner | None, list[Diagnostic]]:
    """The planner ``name`` (one of :data:`CONTROLLERS`) for ``world``; (None, diagnostics) when
    its rule files or settings are unusable. Raises KeyError for an unknown name."""
    return _MAKERS[name](world)
