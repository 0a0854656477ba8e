"""What moves the other participants each step: one small interface, two engines.

:class:`BuiltinTraffic` is the embedded default (:func:`twolevel.world.traffic.step`: IDM,
constant velocity, scripts, lights). A scenario's ``traffic: {engine: sumo, …}`` adds SUMO's
vehicles through libsumo (:class:`twolevel.sim.cosim.SumoTraffic`), which fill the world's
engine slots (:data:`twolevel.world.participants.SLOT_PREFIX`) each step; the closed loop
(:mod:`twolevel.sim.engine`) starts the scenario's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from twolevel.world import traffic as tr
from twolevel.world.world import World

__all__ = ["TrafficEngine", "BuiltinTraffic", "TrafficFailure"]


class TrafficFailure(Exception):
    """An engine's own simulation stopped with an error during the run (SUMO rejecting a vehicle
    of its route files when it is due, or failing on its network): ``message`` is the engine's
    words, ``t`` [s] the simulated time of the step that failed, ``hint`` what to check. Not an
    internal error: the run ends ``aborted`` with SIM632 (:mod:`twolevel.sim.engine`)."""

    def __init__(self, message: str, t: float, hint: str) -> None:
        super().__init__(message)
        self.message, self.t, self.hint = message, t, hint


class TrafficEngine(Protocol):
    """Steps the others; ``ego`` is the ego now, ``ego_next`` after the step (an engine that
    places the ego in its own simulation puts it there)."""

    def start(self, state: tr.TrafficState, ego: tr.EgoBox) -> tr.TrafficState:
        """The traffic at t = 0 (the world's initial state, completed by the engine)."""
        ...

    def step(self, state: tr.TrafficState, dt: float, ego: tr.EgoBox, ego_next: tr.EgoBox) -> tr.TrafficState:
        """The traffic ``dt`` [s] later."""
        ...

    def close(self) -> None:
        """Release what the engine holds (idempotent)."""
        ...


@dataclass(frozen=True, eq=False)
class BuiltinTraffic:
    """twolevel's own traffic (:func:`twolevel.world.traffic.step`) over every participant."""

    world: World

    def start(self, state: tr.TrafficState, ego: tr.EgoBox) -> tr.TrafficState:
        return state

    def step(self, state: tr.TrafficState, dt: float, ego: tr.EgoBox, ego_next: tr.EgoBox) -> tr.TrafficState:
        w = self.world
        return tr.step(state, dt, lanes=w.lanes, parts=w.parts, limits=w.limits, lights=w.lights, stops=w.stops,
                       ego=ego, stop_speed=w.settings.stop_speed)

    def close(self) -> None:
        return None

