"""The solver objects built on a step model, kept from step to step.

A :class:`Backend` is the Clarabel QP with the binaries fixed (:class:`~twolevel.milp.clarabel.FixedModeQP`)
and the mode search over it (:class:`~twolevel.milp.modes.ModeSearch`). Building one costs a
Clarabel set-up; a model of a shape already seen reuses the one built on it, with the new values
put in place. A refreshable model (:mod:`twolevel.control.high_level.template`) keeps its own
backend; any other model finds one by :func:`~twolevel.control.high_level.problem.shape_key`
in a small LRU (:class:`BackendCache`).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

from twolevel.control.high_level.problem import Assembled, shape_key
from twolevel.milp.clarabel import FixedModeQP
from twolevel.milp.modes import ModeSearch

__all__ = ["Backend", "BackendCache"]


@dataclass(frozen=True, eq=False)
class Backend:
    """The fixed-mode QP of a model and the mode search over it."""

    qp: FixedModeQP
    search: ModeSearch

    @classmethod
    def of(cls, asm: Assembled) -> "Backend":
        qp = FixedModeQP(asm.model)
        return cls(qp, ModeSearch(qp))


class BackendCache:
    """Backends by model shape, most recently used last; at most ``capacity``."""

    def __init__(self, capacity: int = 8) -> None:
        self.capacity = capacity
        self._store: OrderedDict[tuple, Backend] = OrderedDict()

    def get(self, asm: Assembled) -> Backend:
        """The backend of a model of ``asm``'s shape, now solving ``asm``'s model (built when
        none is kept)."""
        key = shape_key(asm.model)
        hit = self._store.get(key)
        if hit is not None:
            self._store.move_to_end(key)
            hit.qp.model = asm.model
            return hit
        backend = Backend.of(asm)
        self._store[key] = backend
        while len(self._store) > self.capacity:
            self._store.popitem(last=False)
        return backend
