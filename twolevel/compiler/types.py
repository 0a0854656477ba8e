"""The compiler's records: what it is asked (:class:`Requirement`), what it answers
(:class:`Encoding`, :class:`Emission`), what it keeps while emitting (:class:`PendingDisjunction`)
and what a built-in predicate sees of it (:class:`BuiltinContext`, :data:`Builtin`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from twolevel.compiler.signals import TraceSignals
from twolevel.compiler.tree import Tree
from twolevel.diagnostics import Diagnostic
from twolevel.stl import ast

__all__ = ["Requirement", "Encoding", "Emission", "PendingDisjunction", "BuiltinContext", "Builtin"]


@dataclass(frozen=True)
class Requirement:
    """Require ``formula`` at the trace steps ``times`` (``name`` labels rows and diagnostics)."""

    name: str
    formula: ast.Node
    times: tuple[int, ...]


@dataclass(frozen=True, eq=False)
class Emission:
    """Where one vectorised block put its rows (stable mode): triplets ``tri`` and rows ``rows``
    (local to the encoding, i.e. relative to the start of its ``stl`` block), its binary columns
    ``bins`` (the builder's) and its structure ``struct`` (arrays that must match for a refresh)."""

    kind: str
    tri: slice
    rows: slice
    bins: np.ndarray
    struct: tuple[np.ndarray, ...]


@dataclass
class Encoding:
    """What :func:`~twolevel.compiler.driver.encode` added to a builder."""

    mode: str
    rho: int = -1  # column of the margin variable in robustness mode
    rows: int = 0
    binaries: int = 0
    continuous: int = 0
    disjunctions: int = 0
    infeasible: bool = False  # a requirement is false by constants alone
    diagnostics: list[Diagnostic] = field(default_factory=list)
    # stable mode: each requirement's folded tree (name, step, tree) and every block emission
    # (:class:`Emission`), for refreshing the values of a model of the same structure
    trees: list[tuple[str, int, Tree]] = field(default_factory=list)
    emissions: list[Emission] = field(default_factory=list)
    recovered: list[tuple[str, int, int]] = field(default_factory=list)
    unmargined: list[tuple[str, int]] = field(default_factory=list)  # (name, step): margin left out, see encode


@dataclass(slots=True)
class PendingDisjunction:
    """A disjunction emitted but not yet registered with the builder (that happens when the
    encoding's rows are flushed, once their global indices are final): id, binary columns, cover
    row, enclosing guard (−1 at top level), label (rule@step) and the disjuncts' trees. ``rows``:
    the row of each binary when the emitter knew them at once (vectorised blocks); None when
    they are the rows recorded under each binary as its guard."""

    id: int
    binaries: np.ndarray | list[int]
    cover: int
    guard: int
    label: str
    sources: tuple[object, ...] = ()
    rows: tuple[np.ndarray, ...] | None = None


class BuiltinContext(Protocol):
    """What a built-in predicate sees of stage 1 (:class:`~twolevel.compiler.evaluator.Evaluator`)."""

    @property
    def signals(self) -> TraceSignals:
        """The trace's signals."""
        ...

    def term(self, node: ast.Node, t: int) -> Tree:
        """An arithmetic term at step ``t`` as a tree."""
        ...

    def bounds(self, t: Tree) -> tuple[float, float]:
        """Interval bounds of a tree over the current column bounds."""
        ...


#: A built-in predicate ``name(args)``: (context, args, step t, sign s = ±1, the call node) →
#: ``s ·`` its robustness at step t as a tree.
Builtin = Callable[[BuiltinContext, tuple[ast.Term, ...], int, float, ast.Call], Tree]
