"""Whole-array window kernels for the offline monitor.

Every function maps arrays to arrays with numpy and no per-sample Python loop, along the last
axis (time): a (T,) trace for the offline monitor, or (K, T) candidates for the batched one
(:mod:`twolevel.monitor.batch`), which costs one pass of numpy calls instead of K:

* :func:`sliding` — the van Herk / Gil-Werman sliding min or max, O(n) whatever the width;
* :func:`future_window` / :func:`past_window` — ``min``/``max`` over ``[i+a, i+b]`` (or
  ``[i-b, i-a]``) truncated at the ends of a finite trace, the neutral element (``+inf`` for
  min, ``-inf`` for max) where the window is empty, as RTAMT's offline discrete-time monitor;
* :func:`until` / :func:`since` — the bounded and unbounded until/since in O(n log w).

The until uses the fact that one step of the until recurrence,
``f_k(x) = max(psi[k], min(phi[k], x))``, is a "clamp" ``x -> max(P, min(Q, x))`` and clamps are
closed under composition: ``(P1, Q1) o (P2, Q2) = (max(P1, min(Q1, P2)), min(Q1, Q2))``. The
until over a window of ``w`` steps is a composition of ``w`` clamps applied to ``psi[i+w]``,
which doubling computes for every start ``i`` at once. Samples beyond the trace are the identity
clamp ``(-inf, +inf)``, i.e. ``psi = -inf`` and ``phi = +inf`` there, exactly RTAMT's padding.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

Kind = Literal["min", "max"]

_INF = np.inf


def _op(kind: Kind) -> tuple[np.ufunc, float]:
    return (np.minimum, _INF) if kind == "min" else (np.maximum, -_INF)


def sliding(x: np.ndarray, width: int, kind: Kind) -> np.ndarray:
    """``out[..., i] = min|max(x[..., i : i + width])`` for ``i = 0 .. n - width`` (Gil-Werman)."""
    n = x.shape[-1]
    if width <= 1 or n == 0:
        return x.copy()
    if width > n:
        return np.empty(x.shape[:-1] + (0,), dtype=np.float64)
    op, ident = _op(kind)
    lead = x.shape[:-1]
    blocks = -(-n // width)
    padded = np.full(lead + (blocks * width,), ident)
    padded[..., :n] = x
    grid = padded.reshape(lead + (blocks, width))
    prefix = op.accumulate(grid, axis=-1).reshape(lead + (-1,))
    suffix = op.accumulate(grid[..., ::-1], axis=-1)[..., ::-1].reshape(lead + (-1,))
    m = n - width + 1
    return op(suffix[..., :m], prefix[..., width - 1 : width - 1 + m])


def future_window(x: np.ndarray, a: int, b: int | None, kind: Kind) -> np.ndarray:
    """``out[..., i] = min|max(x[..., i+a .. min(i+b, n-1)])``; the neutral element if the window
    is empty.

    ``b = None`` means an unbounded window ``[i+a, n-1]``.
    """
    n = x.shape[-1]
    op, ident = _op(kind)
    out = np.full(x.shape, ident)
    if n == 0 or a >= n:
        return out
    if b is None:
        acc = op.accumulate(x[..., ::-1], axis=-1)[..., ::-1]
        out[..., : n - a] = acc[..., a:]
        return out
    b = min(b, n + a)  # samples beyond the trace are neutral: a longer window changes nothing
    width = b - a + 1
    padded = np.full(x.shape[:-1] + (n + b + 1,), ident)
    padded[..., :n] = x
    return sliding(padded[..., a:], width, kind)[..., :n]


def past_window(x: np.ndarray, a: int, b: int | None, kind: Kind) -> np.ndarray:
    """``out[..., i] = min|max(x[..., max(i-b, 0) .. i-a])``; the neutral element if the window is empty."""
    return future_window(x[..., ::-1], a, b, kind)[..., ::-1].copy()


def _until0(phi: np.ndarray, psi: np.ndarray, w: int) -> np.ndarray:
    """``phi until[0, w] psi`` at every sample: ``max_{m<=w} min(psi[i+m], min phi[i .. i+m-1])``."""
    lead, n = phi.shape[:-1], phi.shape[-1]
    size = n + w
    lp = np.full(lead + (size,), -_INF)  # level clamps: P (from psi) ...
    lq = np.full(lead + (size,), _INF)  # ... and Q (from phi); identity beyond the trace
    lp[..., :n] = psi
    lq[..., :n] = phi
    rp = np.full(lead + (n,), -_INF)  # running composition of the first `covered` steps, per start i
    rq = np.full(lead + (n,), _INF)
    covered = 0
    step = 1
    remaining = w
    while remaining:
        if remaining & 1:
            seg_p = lp[..., covered : covered + n]
            seg_q = lq[..., covered : covered + n]
            rp = np.maximum(rp, np.minimum(rq, seg_p))
            rq = np.minimum(rq, seg_q)
            covered += step
        remaining >>= 1
        if remaining:
            head = size - step
            if head > 0:
                new_p = lp.copy()
                new_q = lq.copy()
                new_p[..., :head] = np.maximum(lp[..., :head], np.minimum(lq[..., :head], lp[..., step:]))
                new_q[..., :head] = np.minimum(lq[..., :head], lq[..., step:])
                lp, lq = new_p, new_q
            step <<= 1
    last = np.full(lead + (n,), -_INF)
    tail = psi[..., w:]
    last[..., : tail.shape[-1]] = tail
    return np.maximum(rp, np.minimum(rq, last))


def until(phi: np.ndarray, psi: np.ndarray, a: int, b: int | None) -> np.ndarray:
    """RTAMT's ``phi until[a, b] psi`` (``b = None``: unbounded), truncated at the trace end:

    ``max_{m in [a, b], i+m < n} min(psi[i+m], min(phi[i .. i+m-1]))``, ``-inf`` if no such m.
    """
    n = phi.shape[-1]
    if n == 0:
        return np.empty(phi.shape, dtype=np.float64)
    w = n if b is None else b - a
    core = _until0(phi, psi, min(w, n))
    if a == 0:
        return core
    shifted = np.full(phi.shape, -_INF)
    if a < n:
        shifted[..., : n - a] = core[..., a:]
    hold = future_window(phi, 0, a - 1, "min")
    return np.minimum(hold, shifted)


def since(phi: np.ndarray, psi: np.ndarray, a: int, b: int | None) -> np.ndarray:
    """RTAMT's ``phi since[a, b] psi``: ``max_{m in [a, b], i-m >= 0} min(psi[i-m], min(phi[i-m+1 .. i]))``."""
    return until(phi[..., ::-1], psi[..., ::-1], a, b)[..., ::-1].copy()
