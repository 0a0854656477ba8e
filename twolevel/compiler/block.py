"""The block protocol: vectorised leaves of the robustness tree, and the row sink they emit into.

A block stands for a whole family of min/max structure held in arrays, so that a rule over the
horizon and twenty vehicles is bounded and emitted by a few numpy calls instead of a tree of
thousands of nodes. Two kinds exist:

* :class:`~twolevel.compiler.affine_block.AffineBlock` — ``always`` over a conjunction of linear
  predicates: one row per (predicate, step);
* :class:`~twolevel.compiler.collision.CollisionBlock` — ``collision_free(d)``: one
  max-of-four-faces per vehicle–step pair.

A block is a leaf of the :data:`~twolevel.compiler.tree.Tree` whose value is the ``min`` over its
pieces. It is produced by stage 1 (:class:`~twolevel.compiler.evaluator.Evaluator` and the
built-ins it calls) and lowered by stage 2 (:class:`~twolevel.compiler.emitter.RowEmitter`,
which implements :class:`RowSink`). A subclass gives:

* :meth:`Block.bounds` — interval bounds over the column box ``lb ≤ x ≤ ub``;
* :meth:`Block.expand` — the equivalent plain tree (used when the block is negated, scaled, added
  to, or required above a margin that is not a constant);
* :meth:`Block.merge` — the ``min`` of several blocks of its type as one block;
* :meth:`Block.emit` — the rows for ``block ≥ margin`` whenever ``x[guard] = 1`` (always when
  ``guard`` is −1), through the :class:`RowSink` only, encoding exactly what :meth:`expand` would:
  pieces that always hold are dropped, pieces that can never hold fail the requirement, big-M
  comes from the bounds. In stable mode at top level (``sink.stable`` and ``guard < 0``) it emits
  a structure that does not depend on the current values (redundant rows kept) and records it
  with :meth:`RowSink.record`, so that :mod:`twolevel.control.high_level.template` can later rewrite the
  values in place;
* :attr:`Block.kind` — its name in those records.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Protocol

import numpy as np

if TYPE_CHECKING:  # annotations only: tree.py imports this module
    from twolevel.compiler.tree import Tree

__all__ = ["Block", "RowSink"]


class RowSink(Protocol):
    """What a block may do to the model while it emits (implemented by
    :class:`~twolevel.compiler.emitter.RowEmitter`). Rows are ``Σ v·x[c] ≥ lo``; the row indices
    returned are the builder's; a ``guard`` ≥ 0 records the rows as switched on by that binary."""

    #: emit a value-independent structure at top level (see the module docstring)
    stable: bool

    @property
    def lb(self) -> np.ndarray:
        """Current lower bound of every column."""
        ...

    @property
    def ub(self) -> np.ndarray:
        """Current upper bound of every column."""
        ...

    def fail(self, guard: int) -> None:
        """The requirement cannot hold: forbid ``guard``, or make the model infeasible."""
        ...

    def add_binaries(self, name: str, n: int) -> np.ndarray:
        """``n`` new binary columns; their indices."""
        ...

    def tighten(self, cols: np.ndarray, lb: np.ndarray | float, ub: np.ndarray | float) -> None:
        """Intersect the bounds of ``cols`` with [lb, ub]."""
        ...

    def emit_rows(self, cols: np.ndarray, vals: np.ndarray, lo: np.ndarray, guard: int = -1) -> np.ndarray:
        """Rows ``Σ_j vals[i, j]·x[cols[i, j]] ≥ lo[i]`` (dense (n, m) arrays)."""
        ...

    def emit_triplets(self, n: int, r: np.ndarray, c: np.ndarray, v: np.ndarray, lo: np.ndarray,
                      guard: int = -1) -> np.ndarray:
        """``n`` rows from triplets with rows ``r`` numbered from 0."""
        ...

    def emit_covers(self, owner: np.ndarray, cols: np.ndarray, n_groups: int, *, extra_col: int = -1,
                    lo: float = 1.0) -> np.ndarray:
        """One row per group g: ``Σ_{owner[i] = g} x[cols[i]] (− x[extra_col]) ≥ lo``."""
        ...

    def add_disjunctions(self, bins: np.ndarray, rows: np.ndarray, covers: np.ndarray, starts: np.ndarray,
                         guard: int) -> None:
        """Disjunction j: binaries ``bins[starts[j]:starts[j+1]]``, binary i switching on row
        ``rows[i]``, cover row ``covers[j]``, inside ``guard``."""
        ...

    def mark(self) -> tuple[int, int]:
        """Where emission stands: (triplets, rows) emitted so far by this encoding."""
        ...

    def record(self, kind: str, since: tuple[int, int], bins: np.ndarray, struct: tuple[np.ndarray, ...]) -> None:
        """Record the stable emission of one block: everything emitted since the :meth:`mark`
        ``since``, its binaries ``bins`` and the arrays ``struct`` that a refresh must match."""
        ...


class Block:
    """A vectorised leaf of the robustness tree; see the module docstring."""

    __slots__ = ()
    kind: ClassVar[str] = "?"

    def bounds(self, lb: np.ndarray, ub: np.ndarray) -> tuple[float, float]:
        """(lowest, highest) value over the column box ``lb ≤ x ≤ ub``."""
        raise NotImplementedError

    def expand(self) -> Tree:
        """The equivalent plain tree."""
        raise NotImplementedError

    @classmethod
    def merge(cls, blocks: list[Block]) -> Block:
        """The ``min`` of ``blocks`` (all of this type) as one block."""
        raise NotImplementedError

    def emit(self, sink: RowSink, margin: float, guard: int) -> None:
        """Rows for ``self ≥ margin`` whenever ``x[guard] = 1`` (always when ``guard`` is −1)."""
        raise NotImplementedError
