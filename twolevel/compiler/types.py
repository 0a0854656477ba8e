"""The encoder's data: signals with two faces, requirements, what an encoding added, its codes.

See :mod:`twolevel.compiler.driver` for the meaning; these types are re-exported there.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence, Union

import numpy as np
import scipy.sparse as sp

from twolevel.diagnostics import Code, Diagnostic, Severity, Span
from twolevel.compiler.tree import Block, Op, Tree, scale
from twolevel.stl import ast

__all__ = ["AffineSignal", "Signal", "Builtin", "Requirement", "Encoding", "Emission", "EncodeError",
           "MIL501", "MIL502", "MIL503", "MIL504"]

MIL501 = Code("MIL501", "nonlinear-predicate", Severity.ERROR,
              "A predicate is not linear in the decision variables and cannot be encoded.")
MIL502 = Code("MIL502", "unbounded-big-m", Severity.ERROR,
              "A disjunction involves an unbounded variable: no finite big-M exists.")
MIL503 = Code("MIL503", "rule-violated-by-constants", Severity.WARNING,
              "A rule is violated by signals known at solve time; no plan can satisfy it.")
MIL504 = Code("MIL504", "unknown-name", Severity.ERROR,
              "A formula names a signal, constant, rule or built-in the encoder was not given.")

_NOWHERE = Span("<rules>")


@dataclass(frozen=True)
class AffineSignal:
    """A signal affine in the decision variables: value at step k = ``coef[k] @ x + offset[k]``.

    ``coef`` is CSR with one row per trace step (a row without entries is a constant step, e.g.
    a past sample); ``offset`` has the same length."""

    coef: sp.csr_matrix
    offset: np.ndarray

    @classmethod
    def of_columns(cls, cols: Sequence[int] | np.ndarray, n_cols: int,
                   past: Sequence[float] = (), scale: float = 1.0,
                   offset: float | np.ndarray = 0.0) -> "AffineSignal":
        """``scale·x[cols[k]] + offset`` after ``len(past)`` constant past samples."""
        cols = np.asarray(cols, dtype=np.int64)
        P, H = len(past), cols.size
        T = P + H
        indptr = np.concatenate([np.zeros(P + 1, np.int64), np.arange(1, H + 1)])
        C = sp.csr_matrix((np.full(H, scale), cols, indptr), shape=(T, n_cols))
        off = np.concatenate([np.asarray(past, float), np.broadcast_to(offset, (H,))])
        return cls(C, off)

    def __len__(self) -> int:
        return int(self.offset.size)


Signal = Union[AffineSignal, np.ndarray, float]
Builtin = Callable[["Encoder", tuple[ast.Term, ...], int, float, ast.Call], Tree]


class EncodeError(Exception):
    """Raised inside the encoder with the diagnostic to report."""

    def __init__(self, diagnostic: Diagnostic) -> None:
        super().__init__(diagnostic.message)
        self.diagnostic = diagnostic


@dataclass(frozen=True)
class Requirement:
    """Require ``formula`` at the trace steps ``times`` (``name`` labels rows and diagnostics)."""

    name: str
    formula: ast.Node
    times: tuple[int, ...]


@dataclass
class Encoding:
    """What :func:`encode` added to a builder."""

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
    trees: list[tuple[str, int, object]] = field(default_factory=list)
    emissions: list["Emission"] = field(default_factory=list)
    recovered: list[tuple[str, int, int]] = field(default_factory=list)


@dataclass(frozen=True, eq=False)
class Emission:
    """Where one vectorised block put its rows (stable mode): triplets ``tri`` and rows ``rows``
    (encoder-local, i.e. relative to the start of the ``stl`` block), its binary columns
    ``bins`` (global) and its structure ``struct`` (arrays that must match for a refresh)."""

    kind: str
    tri: slice
    rows: slice
    bins: np.ndarray
    struct: tuple[np.ndarray, ...]


def _has_block(t: Tree) -> bool:
    return isinstance(t, Block) or (isinstance(t, Op) and not t.is_max and any(isinstance(k, Block) for k in t.kids))


def _span(node: ast.Node | None) -> Span:
    return node.span if node is not None and node.span is not None else _NOWHERE


