"""The robustness tree: the compiler's intermediate representation (IR).

Who makes it and who reads it:

* produced by stage 1, :class:`twolevel.compiler.evaluator.Evaluator` (a formula at one trace
  step → a tree), and by the built-ins it calls (:mod:`twolevel.compiler.collision`);
* consumed by stage 2, :class:`twolevel.compiler.emitter.RowEmitter` (a tree → rows of the
  model), by the driver (:func:`twolevel.compiler.driver.encode`: bounds of the margin, rule
  recovery) and, outside the compiler, by :mod:`twolevel.control.high_level.template`, which pattern-matches
  the top-level trees of a stable encoding (``Encoding.trees``: a ``min`` of :class:`Block` s and
  at most one constant) to refresh a step model in place. A change of the node classes or of the
  invariants below must keep that consumer right.

A tree (:data:`Tree`) is one of

* ``float`` — a constant known at solve time; ``+inf`` holds always, ``−inf`` never;
* :class:`Lin` — ``Σ val_i · x[idx_i] + c``, affine in the decision variables ``x``;
* :class:`Op` — the ``min`` or ``max`` of two or more children;
* :class:`Block` — a vectorised leaf: a whole family of min/max structure held in arrays,
  emitted through a :class:`~twolevel.compiler.sink.RowSink` (the block protocol: see the class).

Invariants, kept by building trees only through :func:`lin`, :func:`mk`, :func:`add` and
:func:`scale`:

* **constants folded**: a :class:`Lin` has distinct indices and at least one non-zero
  coefficient (else it is a float); an :class:`Op` has at most one float child, never its
  neutral element (−inf under ``max``) and never its absorbing one (the whole ``Op`` is then that
  constant); an :class:`Op` of one child is that child. A subformula known at solve time never
  reaches the model.
* **flat**: an :class:`Op` has no child :class:`Op` of the same kind.
* **negation at the leaves**: there is no negation node; ``scale(t, −1)`` swaps ``min`` and
  ``max`` down to the leaves (``−min(a, b) = max(−a, −b)``).
* **blocks are never scaled or added to**: :func:`scale` and :func:`add` replace a block by its
  plain tree (``Block.expand``); several blocks of one type under one ``min`` merge into one.
* **shared, by identity**: stage 1 memoises each (subformula, step, sign), so a subformula
  reached twice is the same object; :class:`Parents` counts the parents of each ``Op`` by
  identity and :class:`IntervalBounds` memoises by identity (keeping the tree alive).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Protocol, Union

import numpy as np

from twolevel.compiler.sink import RowSink

__all__ = ["INF", "Lin", "Op", "Block", "Tree", "lin", "mk", "add", "scale", "negate",
           "ColumnBounds", "Box", "IntervalBounds", "Parents"]

INF = math.inf


class Lin:
    """``Σ val_i · x[idx_i] + c`` with at least one non-zero coefficient (make it with :func:`lin`)."""

    __slots__ = ("idx", "val", "c")

    def __init__(self, idx: tuple[int, ...], val: tuple[float, ...], c: float) -> None:
        self.idx = idx
        self.val = val
        self.c = c

    def __repr__(self) -> str:
        return f"Lin({dict(zip(self.idx, self.val))}, {self.c})"


class Op:
    """``min`` (``is_max`` False) or ``max`` of two or more children (make it with :func:`mk`).

    ``lo_hint`` is a valid lower bound tighter than interval arithmetic, when the producer knows
    one (set before the first :class:`IntervalBounds` query of the node)."""

    __slots__ = ("is_max", "kids", "lo_hint")

    def __init__(self, is_max: bool, kids: tuple["Tree", ...], lo_hint: float = -INF) -> None:
        self.is_max = is_max
        self.kids = kids
        self.lo_hint = lo_hint

    def __repr__(self) -> str:
        return f"{'max' if self.is_max else 'min'}{self.kids}"


class Block:
    """A vectorised leaf of the robustness tree: the block protocol.

    A block stands for a whole family of min/max structure held in arrays, so that a rule over the
    horizon and twenty vehicles is bounded and emitted by a few numpy calls instead of a tree of
    thousands of nodes. Two kinds exist:

    * :class:`~twolevel.compiler.affine_block.AffineBlock` — ``always`` over a conjunction of linear
      predicates: one row per (predicate, step);
    * :class:`~twolevel.compiler.collision.CollisionBlock` — ``collision_free(d)``: one
      max-of-four-faces per vehicle–step pair.

    A block is a leaf of the :data:`Tree` whose value is the ``min`` over its pieces. It is
    produced by stage 1 (:class:`~twolevel.compiler.evaluator.Evaluator` and the built-ins it
    calls) and lowered by stage 2 (:class:`~twolevel.compiler.emitter.RowEmitter`, which
    implements :class:`~twolevel.compiler.sink.RowSink`). A subclass gives:

    * :meth:`Block.bounds` — interval bounds over the column box ``lb ≤ x ≤ ub``;
    * :meth:`Block.expand` — the equivalent plain tree (used when the block is negated, scaled, added
      to, or required above a margin that is not a constant);
    * :meth:`Block.merge` — the ``min`` of several blocks of its type as one block;
    * :meth:`Block.emit` — the rows for ``block ≥ margin`` whenever ``x[guard] = 1`` (always when
      ``guard`` is −1), through the sink only, encoding exactly what :meth:`expand` would:
      pieces that always hold are dropped, pieces that can never hold fail the requirement, big-M
      comes from the bounds. In stable mode at top level (``sink.stable`` and ``guard < 0``) it emits
      a structure that does not depend on the current values (redundant rows kept) and records it
      with ``RowSink.record``, so that :mod:`twolevel.control.high_level.template` can later
      rewrite the values in place;
    * :attr:`Block.kind` — its name in those records.
    """

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


Tree = Union[float, Lin, Op, Block]


def lin(idx: tuple[int, ...], val: tuple[float, ...], c: float) -> Tree:
    """A :class:`Lin`, or a float when every coefficient is zero (merging repeated indices)."""
    if len(set(idx)) != len(idx):
        acc: dict[int, float] = {}
        for i, v in zip(idx, val):
            acc[i] = acc.get(i, 0.0) + v
        idx, val = tuple(acc), tuple(acc.values())
    keep = [k for k, v in enumerate(val) if v != 0.0]
    if not keep:
        return float(c)
    if len(keep) != len(val):
        idx = tuple(idx[k] for k in keep)
        val = tuple(val[k] for k in keep)
    return Lin(idx, val, float(c))


def mk(is_max: bool, kids: list[Tree] | tuple[Tree, ...]) -> Tree:
    """``max``/``min`` of ``kids`` with constants folded and same-kind children flattened."""
    absorbing = INF if is_max else -INF  # max(…, +inf) = +inf
    neutral = -absorbing
    best: float | None = None
    out: list[Tree] = []
    if not is_max:
        blocks = [k for k in kids if isinstance(k, Block)]
        if len(blocks) > 1 and all(type(b) is type(blocks[0]) for b in blocks):
            kids = [k for k in kids if not isinstance(k, Block)] + [type(blocks[0]).merge(blocks)]
    for k in kids:
        if isinstance(k, float):
            if k == absorbing:
                return absorbing
            if k == neutral:
                continue
            best = k if best is None else (max(best, k) if is_max else min(best, k))
        elif isinstance(k, Op) and k.is_max == is_max:
            for kk in k.kids:
                if isinstance(kk, float):
                    best = kk if best is None else (max(best, kk) if is_max else min(best, kk))
                else:
                    out.append(kk)
        else:
            out.append(k)
    if best is not None:
        out.append(best)
    if not out:
        return neutral
    if len(out) == 1:
        return out[0]
    return Op(is_max, tuple(out))


def scale(t: Tree, k: float) -> Tree:
    """``k · t``; a negative factor swaps min and max."""
    if isinstance(t, float):
        if k == 0.0:
            return 0.0
        return t * k
    if k == 0.0:
        return 0.0
    if k == 1.0:
        return t
    if isinstance(t, Block):
        return scale(t.expand(), k)
    if isinstance(t, Lin):
        return Lin(t.idx, tuple(v * k for v in t.val), t.c * k)
    return Op(t.is_max if k > 0 else not t.is_max, tuple(scale(c, k) for c in t.kids))


def negate(t: Tree) -> Tree:
    """``−t``."""
    return scale(t, -1.0)


def add(a: Tree, b: Tree) -> Tree:
    """``a + b``; a sum with a min/max distributes over its children."""
    if isinstance(a, Block):
        a = a.expand()
    if isinstance(b, Block):
        b = b.expand()
    if isinstance(a, Op):
        return mk(a.is_max, [add(k, b) for k in a.kids])
    if isinstance(b, Op):
        return mk(b.is_max, [add(a, k) for k in b.kids])
    if isinstance(a, float):
        if isinstance(b, float):
            return a + b
        return Lin(b.idx, b.val, b.c + a) if math.isfinite(a) else a
    if isinstance(b, float):
        return Lin(a.idx, a.val, a.c + b) if math.isfinite(b) else b
    return lin(a.idx + b.idx, a.val + b.val, a.c + b.c)


# ---------------------------------------------------------------------------- analyses


class ColumnBounds(Protocol):
    """Anything that holds the current bounds of every column (a
    :class:`~twolevel.milp.builder.ModelBuilder` while columns are added, a :class:`Box`)."""

    @property
    def lb(self) -> np.ndarray: ...

    @property
    def ub(self) -> np.ndarray: ...


@dataclass(frozen=True)
class Box:
    """Fixed column bounds ``lb ≤ x ≤ ub``."""

    lb: np.ndarray
    ub: np.ndarray


class IntervalBounds:
    """Interval bounds of trees over the box of ``columns`` (read afresh at every query, so
    columns added later count), memoised by identity; the memo keeps each tree alive so an
    identity is never reused while it is cached. One instance is shared by the stages of one
    encoding."""

    def __init__(self, columns: ColumnBounds) -> None:
        self.columns = columns
        self._memo: dict[int, tuple[float, float, object]] = {}

    def __call__(self, t: Tree) -> tuple[float, float]:
        """(lowest, highest) value of ``t`` over the box."""
        return _bounds(t, self.columns.lb, self.columns.ub, self._memo)


def _bounds(t: Tree, lb: np.ndarray, ub: np.ndarray,
            memo: dict[int, tuple[float, float, object]]) -> tuple[float, float]:
    if isinstance(t, float):
        return t, t
    key = id(t)
    hit = memo.get(key)
    if hit is not None:
        return hit[0], hit[1]
    if isinstance(t, Block):
        res = t.bounds(lb, ub)
        memo[key] = (res[0], res[1], t)
        return res
    if isinstance(t, Lin):
        lo = hi = t.c
        for i, v in zip(t.idx, t.val):
            a, b = v * lb[i], v * ub[i]
            if a > b:
                a, b = b, a
            lo += a
            hi += b
        res = (lo, hi)
    else:
        bs = [_bounds(k, lb, ub, memo) for k in t.kids]
        los = [b[0] for b in bs]
        his = [b[1] for b in bs]
        res = (max(los), max(his)) if t.is_max else (min(los), min(his))
        res = (max(res[0], t.lo_hint), res[1])
    memo[key] = (res[0], res[1], t)
    return res


class Parents:
    """How many parents each :class:`Op` has in the trees built so far (by identity). Stage 1
    counts (:meth:`add`); stage 2 encodes a node with two or more parents once, through one
    shared variable (:meth:`shared`). Nodes counted must be kept alive by their producer."""

    def __init__(self) -> None:
        self._n: dict[int, int] = {}

    def add(self, t: Tree) -> None:
        """Count one more parent of ``t`` (nothing unless ``t`` is an :class:`Op`)."""
        if isinstance(t, Op):
            self._n[id(t)] = self._n.get(id(t), 0) + 1

    def shared(self, t: Tree) -> bool:
        """``t`` has two or more parents."""
        return self._n.get(id(t), 0) >= 2
