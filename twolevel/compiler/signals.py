"""Signals with two faces, and the table of what a formula can read over one trace.

At trace step ``k`` a signal is a constant known at solve time (every past sample, and the
signals of the world the plan cannot change) or an affine expression of the decision variables
(the plan's own states and inputs). :class:`AffineSignal` holds the latter as a sparse matrix
(one row per step) plus an offset; a plain array (one value per step) or a float holds the
former. :class:`TraceSignals` gives both faces to the compiler's stages: a tree leaf at one step
(:meth:`TraceSignals.at`) or dense rows over the whole trace (:meth:`TraceSignals.dense`, for
the vectorised blocks).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence, Union

import numpy as np
import scipy.sparse as sp

from twolevel.compiler.codes import MIL504, EncodeError, span_of
from twolevel.compiler.tree import Tree, lin
from twolevel.stl import ast

__all__ = ["AffineSignal", "Signal", "TraceSignals"]


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


class TraceSignals:
    """The signals and constants a formula reads over one trace of ``length`` steps (default:
    the longest signal). Lookups are memoised for the life of the table (one encoding)."""

    def __init__(self, signals: Mapping[str, Signal], length: int | None = None,
                 consts: Mapping[str, float] | None = None) -> None:
        self.signals = signals
        self.consts = dict(consts or {})
        if length is None:
            lens = [len(s) for s in signals.values()
                    if isinstance(s, AffineSignal) or np.ndim(s) > 0]
            if not lens:
                raise ValueError("give the trace length: no signal has one")
            length = max(lens)
        self.length = int(length)
        self._leaf: dict[tuple[str, int], Tree] = {}
        self._dense: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._pattern: dict[str, np.ndarray] = {}

    def get(self, name: str) -> Signal | None:
        """The signal ``name``, or None."""
        return self.signals.get(name)

    def const(self, name: str) -> float | None:
        """The constant ``name`` (None when there is none, or a signal has that name)."""
        if name in self.consts and name not in self.signals:
            return float(self.consts[name])
        return None

    def at(self, name: str, k: int, node: ast.Node | None = None) -> Tree:
        """The value of signal (or constant) ``name`` at trace step ``k`` as a tree leaf;
        ``node`` is where a diagnostic points when the name is unknown."""
        key = (name, k)
        hit = self._leaf.get(key)
        if hit is not None:
            return hit
        s = self.signals.get(name)
        if s is None:
            if name in self.consts:
                return float(self.consts[name])
            raise EncodeError(MIL504(f"unknown signal or constant '{name}'", span_of(node),
                                     hint="pass it in signals= or consts="))
        if isinstance(s, AffineSignal):
            C = s.coef
            a, b = C.indptr[k], C.indptr[k + 1]
            out = lin(tuple(int(i) for i in C.indices[a:b]),
                      tuple(float(v) for v in C.data[a:b]), float(s.offset[k]))
        elif np.ndim(s) == 0:
            out = float(s)
        else:
            out = float(np.asarray(s)[k])
        self._leaf[key] = out
        return out

    def settled(self, name: str) -> int:
        """How many leading samples of signal ``name`` are known at solve time (the recorded
        past, and every sample of a signal the plan cannot change): rows of an affine signal
        before its first coefficient; the whole trace otherwise [samples]."""
        s = self.signals.get(name)
        if isinstance(s, AffineSignal):
            counts = np.diff(s.coef.indptr)
            return int(np.argmax(counts > 0)) if counts.any() else self.length
        return self.length

    def prefix(self, name: str, k: int) -> np.ndarray:
        """The first ``k`` samples of signal ``name`` as values (``k`` ≤ :meth:`settled`)."""
        s = self.signals[name]
        if isinstance(s, AffineSignal):
            return np.asarray(s.offset[:k], float)
        return np.broadcast_to(np.asarray(s, float), (self.length,))[:k]

    def dense_width(self) -> int | None:
        """The column count every affine signal is expressed over (0 without affine signals,
        None if they differ)."""
        ws = {s.coef.shape[1] for s in self.signals.values() if isinstance(s, AffineSignal)}
        return ws.pop() if len(ws) == 1 else (0 if not ws else None)

    def dense(self, name: str, n: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Signal ``name`` as dense rows over the trace: (C (T, n), offset (T,)); None when
        there is no such signal."""
        hit = self._dense.get(name)
        if hit is not None:
            return hit
        s = self.signals.get(name)
        if s is None:
            return None
        T = self.length
        if isinstance(s, AffineSignal):
            rows = np.repeat(np.arange(T), np.diff(s.coef.indptr))
            flat = rows * n + np.asarray(s.coef.indices)
            C = np.bincount(flat, weights=np.asarray(s.coef.data, float), minlength=T * n).reshape(T, n)
            out = (C, np.asarray(s.offset, float))
        else:
            out = (np.zeros((T, n)), np.broadcast_to(np.asarray(s, float), (T,)).astype(float))
        self._dense[name] = out
        return out

    def pattern(self, name: str, n: int) -> np.ndarray:
        """The structural pattern (T, n) of signal ``name``'s coefficients: True where an entry
        exists, even when its value is 0 now."""
        hit = self._pattern.get(name)
        if hit is None:
            s = self.signals.get(name)
            hit = np.zeros((self.length, n), bool)
            if isinstance(s, AffineSignal):
                rows = np.repeat(np.arange(self.length), np.diff(s.coef.indptr))
                hit[rows, np.asarray(s.coef.indices)] = True
            self._pattern[name] = hit
        return hit
