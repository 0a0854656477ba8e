"""Robustness expression trees: min/max trees over affine leaves, folded as they are built.

The encoder evaluates a formula at one step into such a tree: a ``float`` (a constant, ±inf
allowed), a :class:`Lin` (an affine expression of decision variables) or an :class:`Op`
(``min``/``max`` of children). Constants fold on construction, so a subformula known at solve
time never reaches the model. Negation is pushed to the leaves (``-min = max of -``).
"""

from __future__ import annotations

import math
from typing import Union

import numpy as np

__all__ = ["Lin", "Op", "Block", "Tree", "mk", "add", "scale", "negate", "bounds"]

INF = math.inf


class Lin:
    """``Σ val_i · x[idx_i] + c`` with at least one non-zero coefficient."""

    __slots__ = ("idx", "val", "c")

    def __init__(self, idx: tuple[int, ...], val: tuple[float, ...], c: float) -> None:
        self.idx = idx
        self.val = val
        self.c = c

    def __repr__(self) -> str:
        return f"Lin({dict(zip(self.idx, self.val))}, {self.c})"


class Op:
    """``min`` (``is_max`` False) or ``max`` of two or more children."""

    __slots__ = ("is_max", "kids", "lo_hint")

    def __init__(self, is_max: bool, kids: tuple["Tree", ...], lo_hint: float = -INF) -> None:
        self.is_max = is_max
        self.kids = kids
        self.lo_hint = lo_hint  # a valid lower bound tighter than interval arithmetic, if known

    def __repr__(self) -> str:
        return f"{'max' if self.is_max else 'min'}{self.kids}"


class Block:
    """A vectorised leaf: a whole family of min/max structure held in arrays (e.g. every
    vehicle–step pair of ``collision_free``). Subclasses give :meth:`bounds`, :meth:`expand`
    (the equivalent plain tree, used under negation or arithmetic), :meth:`emit` (the encoder's
    rows, vectorised) and :meth:`merge` (the ``min`` of several blocks of the same type)."""

    __slots__ = ()

    def bounds(self, lb: np.ndarray, ub: np.ndarray) -> tuple[float, float]:
        raise NotImplementedError

    def expand(self) -> "Tree":
        raise NotImplementedError

    @classmethod
    def merge(cls, blocks: list["Block"]) -> "Block":
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


def bounds(t: Tree, lb: np.ndarray, ub: np.ndarray,
           memo: dict[int, tuple[float, float, object]]) -> tuple[float, float]:
    """Interval bounds of ``t`` over the box ``lb ≤ x ≤ ub`` (memoised by identity; the memo
    keeps ``t`` alive so an identity is never reused while it is cached)."""
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
        bs = [bounds(k, lb, ub, memo) for k in t.kids]
        los = [b[0] for b in bs]
        his = [b[1] for b in bs]
        res = (max(los), max(his)) if t.is_max else (min(los), min(his))
        res = (max(res[0], t.lo_hint), res[1])
    memo[key] = (res[0], res[1], t)
    return res
