"""The row sink: what a block of the robustness tree may do to the model while it emits.

Stage 2 (:class:`~twolevel.compiler.emitter.RowEmitter`) implements :class:`RowSink`; each
:class:`~twolevel.compiler.tree.Block` emits its rows through it only (see the block protocol in
:mod:`twolevel.compiler.tree`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

__all__ = ["RowSink"]


class RowSink(Protocol):
    """What a block may do to the model while it emits (implemented by
    :class:`~twolevel.compiler.emitter.RowEmitter`). Rows are ``Σ v·x[c] ≥ lo``; the row indices
    returned are the builder's; a ``guard`` ≥ 0 records the rows as switched on by that binary."""

    #: emit a value-independent structure at top level (the block protocol:
    #: :class:`~twolevel.compiler.tree.Block`)
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
