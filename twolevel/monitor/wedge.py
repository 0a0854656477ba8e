"""Streaming window aggregates with O(1) amortised work per sample, whatever the window.

* :class:`MinWedge` / :class:`MaxWedge` — Lemire's monotone wedge: the min (max) of the last
  ``width`` pushed values. Each value enters once and leaves at most once.
* :class:`ClampWindow` — the composition of the last ``size`` clamps ``x -> max(P, min(Q, x))``
  (one step of the until/since recurrence, see :mod:`twolevel.monitor.windows`), kept with the
  two-stacks queue, which needs only associativity: each clamp is pushed once, moved once to
  the front stack and popped once.

``deque_factory`` is a class attribute so a test can count the container operations.
"""

from __future__ import annotations

from collections import deque
from typing import Callable

INF = float("inf")

Clamp = tuple[float, float]
IDENTITY: Clamp = (-INF, INF)


class MinWedge:
    """The minimum of the last ``width`` values pushed (``width >= 1``)."""

    __slots__ = ("vals", "idx", "width", "count")
    deque_factory: Callable[[], deque] = deque

    def __init__(self, width: int) -> None:
        self.vals = self.deque_factory()
        self.idx = self.deque_factory()
        self.width = width
        self.count = 0

    def push(self, x: float) -> float:
        """Push ``x``; return the minimum of the window that ends with it."""
        vals = self.vals
        idx = self.idx
        while vals and vals[-1] >= x:
            vals.pop()
            idx.pop()
        k = self.count
        vals.append(x)
        idx.append(k)
        self.count = k + 1
        if idx[0] <= k - self.width:
            vals.popleft()
            idx.popleft()
        return vals[0]

    def skip(self, m: int, pad: float) -> None:
        """Exactly ``m`` pushes of ``pad`` (``+inf``: no value exceeds it) in O(1) amortised,
        whatever ``m``: the end-of-trace padding of a window ``1e300`` samples long."""
        if m <= 0:
            return
        vals, idx = self.vals, self.idx
        while vals and vals[-1] >= pad:
            vals.pop()
            idx.pop()
        self._append_skipped(m, pad)

    def _append_skipped(self, m: int, pad: float) -> None:
        vals, idx = self.vals, self.idx
        k = self.count + m - 1
        vals.append(pad)
        idx.append(k)
        self.count = k + 1
        while idx[0] <= k - self.width:
            vals.popleft()
            idx.popleft()


class MaxWedge(MinWedge):
    """The maximum of the last ``width`` values pushed (``width >= 1``)."""

    __slots__ = ()

    def push(self, x: float) -> float:
        vals = self.vals
        idx = self.idx
        while vals and vals[-1] <= x:
            vals.pop()
            idx.pop()
        k = self.count
        vals.append(x)
        idx.append(k)
        self.count = k + 1
        if idx[0] <= k - self.width:
            vals.popleft()
            idx.popleft()
        return vals[0]

    def skip(self, m: int, pad: float) -> None:
        """Exactly ``m`` pushes of ``pad`` (``-inf``: no value is below it)."""
        if m <= 0:
            return
        vals, idx = self.vals, self.idx
        while vals and vals[-1] <= pad:
            vals.pop()
            idx.pop()
        self._append_skipped(m, pad)


def compose(outer: Clamp, inner: Clamp) -> Clamp:
    """``outer o inner`` for clamps ``x -> max(P, min(Q, x))``."""
    po, qo = outer
    pi, qi = inner
    return (max(po, qo if qo < pi else pi), qo if qo < qi else qi)


class ClampWindow:
    """The composition of the last ``size`` clamps pushed (two-stacks sliding aggregation).

    ``older_outer=True`` composes the oldest clamp outermost (until: ``f_j o f_{j+1} o ...``);
    ``False`` the newest outermost (since: ``f_k o f_{k-1} o ...``).
    """

    __slots__ = ("front", "back", "back_agg", "size", "held", "older_outer")
    stack_factory: Callable[[], list] = list

    def __init__(self, size: int, older_outer: bool) -> None:
        self.front = self.stack_factory()  # aggregates, oldest element last (the top)
        self.back = self.stack_factory()  # raw clamps, oldest first
        self.back_agg: Clamp = IDENTITY
        self.size = size
        self.held = 0
        self.older_outer = older_outer

    def _op(self, older: Clamp, newer: Clamp) -> Clamp:
        return compose(older, newer) if self.older_outer else compose(newer, older)

    def push(self, clamp: Clamp) -> Clamp:
        """Push a clamp (dropping the oldest beyond ``size``); return the window's composition."""
        back = self.back
        self.back_agg = self._op(self.back_agg, clamp) if back else clamp
        back.append(clamp)
        if self.held == self.size:
            front = self.front
            if not front:
                acc: Clamp | None = None
                for c in reversed(back):
                    acc = c if acc is None else self._op(c, acc)
                    front.append(acc)
                back.clear()
                self.back_agg = IDENTITY
            front.pop()
        else:
            self.held += 1
        front = self.front
        if front:
            return self._op(front[-1], self.back_agg) if self.back else front[-1]
        return self.back_agg

    def suffixes(self) -> list[Clamp]:
        """The composition of every suffix of the window, longest (from the oldest clamp) first:
        what pushing identities until the window is empty would return, without the pushes."""
        out: list[Clamp] = []
        acc = IDENTITY
        for c in reversed(self.back):
            acc = self._op(c, acc)
            out.append(acc)
        out.reverse()
        back = self.back_agg if self.back else IDENTITY
        head = [self._op(f, back) for f in reversed(self.front)]
        return head + out
