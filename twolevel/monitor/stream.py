"""The operators of the online monitor: stream nodes, each consuming its children's streams.

A node receives, at each step, one value from each child (children are aligned: they emit the
same sample index at the same step) and emits at most one value; it emits sample index ``j``
``lat`` steps after its children emitted ``j`` (``lat`` is the node's own look-ahead:
``b`` for ``always[a,b]``, 1 for ``next``, 0 for the past). ``flush()`` ends the stream with
RTAMT's end-of-trace padding and returns the values still owed, so that every node emits as
many values as the trace has samples.

Nodes work on floats (the fast path) or, after :meth:`Node.interval`, on ``(lo, hi)`` pairs:
Deshmukh et al.'s robustness intervals, where an unseen atomic value is ``(-inf, +inf)``.
Monotone stateful operators become :class:`Channels` (one scalar copy per bound).
"""

from __future__ import annotations

import copy
from collections import deque
from typing import Any, Callable

from twolevel.monitor.wedge import INF, ClampWindow, MaxWedge, MinWedge

Pair = tuple[float, float]
UNKNOWN: Pair = (-INF, INF)


class Node:
    """Base: ``lat`` steps of look-ahead, ``push`` per step, ``flush`` at the end."""

    lat = 0
    monotone = False  # stateful and non-decreasing in every child: interval() = Channels

    def push(self, *xs: Any) -> Any:
        raise NotImplementedError

    def flush(self) -> list[Any]:
        return []

    def fast_push(self) -> Callable[..., Any]:
        """The callable the generated step function uses; it may skip bookkeeping that only
        matters for the warm-up ``None`` (the generated code never reads a node before its
        look-ahead has passed)."""
        return self.push

    def interval(self) -> "Node":
        """A copy working on ``(lo, hi)`` pairs, starting from this node's (exact) state."""
        if self.monotone:
            return Channels(copy.deepcopy(self), copy.deepcopy(self))
        raise NotImplementedError(type(self).__name__)


class Channels(Node):
    """Interval form of a monotone node: one copy on the lower bounds, one on the upper."""

    def __init__(self, lo: Node, hi: Node) -> None:
        self.lo, self.hi, self.lat = lo, hi, lo.lat

    def push(self, *xs: Pair) -> Pair | None:
        lo = self.lo.push(*(x[0] for x in xs))
        hi = self.hi.push(*(x[1] for x in xs))
        return None if lo is None else (lo, hi)

    def flush(self) -> list[Pair]:
        return list(zip(self.lo.flush(), self.hi.flush()))


# --------------------------------------------------------------------------- stateless


class Atom(Node):
    """A predicate or signal read from the sample; ``code`` is its inlined Python expression."""

    def __init__(self, fn: Callable[[Any], float], code: str) -> None:
        self.fn, self.code = fn, code

    def push(self, sample: Any) -> float:
        return self.fn(sample)

    def interval(self) -> Node:
        return _Unknown()


class _Unknown(Node):
    def push(self, sample: Any) -> Pair:
        return UNKNOWN


class Const(Node):
    def __init__(self, value: float) -> None:
        self.value = value

    def push(self, sample: Any) -> Any:
        return self.value

    def interval(self) -> Node:
        return Const((self.value, self.value))


def _neg(x: float) -> float:
    return -x


def _abs_range(lo: float, hi: float) -> Pair:
    """The range of ``|d|`` for ``d`` in ``[lo, hi]`` (NaN ends read as unbounded)."""
    if lo != lo:
        lo = -INF
    if hi != hi:
        hi = INF
    if lo <= 0.0 <= hi:
        return 0.0, max(-lo, hi)
    a, b = abs(lo), abs(hi)
    return (a, b) if a <= b else (b, a)


class Stateless(Node):
    """``not and or implies iff xor``: a pure function of the aligned child values."""

    CODE = {
        "not": "-{0}",
        "and": "({0} if {0} <= {1} else {1})",
        "or": "({0} if {0} >= {1} else {1})",
        "implies": "max(-{0}, {1})",
        "iff": "-abs({0} - {1})",
        "xor": "abs({0} - {1})",
    }

    def __init__(self, op: str) -> None:
        self.op = op
        self.is_interval = False

    def code(self, args: list[str]) -> str:
        return self.CODE[self.op].format(*args)

    def push(self, *xs: Any) -> Any:
        op = self.op
        if not self.is_interval:
            if op == "not":
                return -xs[0]
            a, b = xs
            if op == "and":
                return a if a <= b else b
            if op == "or":
                return a if a >= b else b
            if op == "implies":
                return max(-a, b)
            return -abs(a - b) if op == "iff" else abs(a - b)
        if op == "not":
            lo, hi = xs[0]
            return (-hi, -lo)
        (alo, ahi), (blo, bhi) = xs
        if op == "and":
            return (min(alo, blo), min(ahi, bhi))
        if op == "or":
            return (max(alo, blo), max(ahi, bhi))
        if op == "implies":
            return (max(-ahi, blo), max(-alo, bhi))
        dlo, dhi = _abs_range(alo - bhi, ahi - blo)
        return (-dhi, -dlo) if op == "iff" else (dlo, dhi)

    def interval(self) -> Node:
        twin = Stateless(self.op)
        twin.is_interval = True
        return twin


# --------------------------------------------------------------------------- shifts


class Delay(Node):
    """The child's stream ``k`` steps later (aligns a faster child with a slower one)."""

    def __init__(self, k: int) -> None:
        self.k = self.lat = k
        self.buf: deque = deque()

    def push(self, x: Any) -> Any:
        buf = self.buf
        buf.append(x)
        return buf.popleft() if len(buf) > self.k else None

    def flush(self) -> list[Any]:
        out = list(self.buf)
        self.buf.clear()
        return out

    def interval(self) -> Node:
        twin = copy.deepcopy(self)
        twin.buf = deque((v, v) for v in self.buf)
        return twin


class Shift(Node):
    """``out[j] = x[j + a]``; ``pad`` beyond the end of the trace (``next`` is ``Shift(1, +inf)``)."""

    def __init__(self, a: int, pad: Any) -> None:
        self.a = self.lat = a
        self.pad = pad
        self.count = 0

    def push(self, x: Any) -> Any:
        self.count += 1
        return x if self.count > self.a else None

    def flush(self) -> list[Any]:
        return [self.pad] * min(self.count, self.a)

    def interval(self) -> Node:
        twin = copy.deepcopy(self)
        twin.pad = (self.pad, self.pad)
        return twin


class Lag(Node):
    """``out[k] = x[k - a]``; ``pad`` before the start of the trace (``prev`` is ``Lag(1, +inf)``)."""

    def __init__(self, a: int, pad: Any) -> None:
        self.a = a
        self.buf: deque = deque([pad] * a)

    def push(self, x: Any) -> Any:
        buf = self.buf
        buf.append(x)
        return buf.popleft()

    def interval(self) -> Node:
        twin = copy.deepcopy(self)
        twin.buf = deque((v, v) for v in self.buf)
        return twin


class Edge(Node):
    """``rise``: ``min(x[k], -x[k-1])``, ``x[-1] = -inf``; ``fall``: ``min(x[k-1], -x[k])``, ``x[-1] = +inf``."""

    def __init__(self, rise: bool) -> None:
        self.rise = rise
        self.prev: Any = -INF if rise else INF
        self.is_interval = False

    def push(self, x: Any) -> Any:
        p = self.prev
        self.prev = x
        if not self.is_interval:
            return min(x, -p) if self.rise else min(p, -x)
        (xlo, xhi), (plo, phi) = x, p
        if self.rise:
            return (min(xlo, -phi), min(xhi, -plo))
        return (min(plo, -xhi), min(phi, -xlo))

    def interval(self) -> Node:
        twin = Edge(self.rise)
        twin.prev, twin.is_interval = (self.prev, self.prev), True
        return twin


# --------------------------------------------------------------------------- windows


class FutureWindow(Node):
    """``always[a,b]`` (min) / ``eventually[a,b]`` (max): emits ``j = k - b`` on receiving ``x[k]``."""

    monotone = True

    def __init__(self, a: int, b: int, is_min: bool) -> None:
        self.b = self.lat = b
        self.wedge = (MinWedge if is_min else MaxWedge)(b - a + 1)
        self.pad = INF if is_min else -INF

    def push(self, x: float) -> float | None:
        v = self.wedge.push(x)
        return v if self.wedge.count > self.b else None

    def fast_push(self) -> Callable[..., Any]:
        return self.wedge.push

    def flush(self) -> list[float]:
        # ``b`` pads end the trace, but only the last ``min(n, b)`` emit a value still owed: the
        # others merely slide the window, which ``skip`` does at once (``b`` may be 1e301).
        wedge, n = self.wedge, self.wedge.count
        wedge.skip(self.b - n, self.pad)
        push, pad = wedge.push, self.pad
        return [push(pad) for _ in range(min(n, self.b))]


class PastWindow(Node):
    """``historically[a,b]`` (min) / ``once[a,b]`` (max) over ``x[k-b .. k-a]``; ``b=None``: unbounded."""

    monotone = True

    def __init__(self, a: int, b: int | None, is_min: bool) -> None:
        self.is_min = is_min
        self.pad = INF if is_min else -INF
        self.delay: deque = deque([None] * a)
        self.wedge = None if b is None else (MinWedge if is_min else MaxWedge)(b - a + 1)
        self.acc = self.pad

    def fast_push(self) -> Callable[..., Any]:
        return self.wedge.push if (self.wedge is not None and not self.delay) else self.push

    def push(self, x: float) -> float:
        delay = self.delay
        if delay:
            delay.append(x)
            x = delay.popleft()
            if x is None:
                return self.pad
        wedge = self.wedge
        if wedge is not None:
            return wedge.push(x)
        acc = self.acc
        if (x < acc) if self.is_min else (x > acc):
            self.acc = acc = x
        return acc


class Until0(Node):
    """``l until[0, w] r``: the composition of ``w + 1`` clamps, oldest outermost, at ``-inf``."""

    monotone = True

    def __init__(self, w: int) -> None:
        self.w = self.lat = w
        self.win = ClampWindow(w + 1, older_outer=True)
        self.count = 0

    def push(self, left: float, right: float) -> float | None:
        p = self.win.push((right, left))[0]
        self.count += 1
        return p if self.count > self.w else None

    def flush(self) -> list[float]:
        # Sample ``j`` still owed (the last ``min(n, w)``) composes the clamps ``j .. n-1``: the
        # window's suffixes, read off without pushing ``w`` identities (``w`` may be 1e301).
        owed = min(self.count, self.w)
        sufs = self.win.suffixes()
        return [c[0] for c in sufs[len(sufs) - owed :]] if owed else []


class Since0(Node):
    """``l since[0, w] r`` (``w=None``: unbounded), newest clamp outermost, at ``-inf``."""

    monotone = True

    def __init__(self, w: int | None) -> None:
        self.win = None if w is None else ClampWindow(w + 1, older_outer=False)
        self.acc = -INF

    def push(self, left: float, right: float) -> float:
        if self.win is not None:
            return self.win.push((right, left))[0]
        acc = self.acc
        acc = left if left < acc else acc
        self.acc = acc = right if right > acc else acc
        return acc

