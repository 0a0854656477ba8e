"""The built-in world predicate ``collision_free(d)`` at the high level, and reachable boxes.

``collision_free(d)`` is ``|x − x_i| + |y − y_i| ≥ d`` for every nearby vehicle i (a 1-norm
diamond around its constant-velocity prediction). Vehicle–step pairs whose least 1-norm distance
from the ego's position box is at least d, and faces that can never hold, are removed exactly by
the encoder's interval pruning, given the ego's position bounds (reachable boxes).
"""

from __future__ import annotations

import math

import numpy as np

from twolevel.milp.encode import MIL501, MIL504, Builtin, EncodeError, Encoder, _span
from twolevel.milp.robtree import INF, Op, Tree, add, mk, scale
from twolevel.stl import ast

__all__ = ["collision_free_builtin", "reachable_box"]


def collision_free_builtin(x: str, y: str, others: np.ndarray) -> Builtin:
    """``collision_free(d)`` at the high level: ``|x − x_i| + |y − y_i| ≥ d`` for every other
    vehicle i — robustness ``min_i max_faces(σ₁(x − x_i) + σ₂(y − y_i)) − d``.

    ``others`` has shape (N, T, 2): each vehicle's predicted position per trace step [m] (NaN
    where absent). Pairs that cannot come within reach and faces that can never hold are
    removed by the encoder's interval pruning, exactly, given the ego's position bounds."""
    others = np.asarray(others, dtype=float)
    faces = ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0))

    def fn(enc: Encoder, args: tuple[ast.Term, ...], t: int, s: float, node: ast.Call) -> Tree:
        if len(args) != 1:
            raise EncodeError(MIL504("collision_free takes one argument (the distance d [m])",
                                     _span(node)))
        d = enc.term(args[0], t)
        if not isinstance(d, float):
            raise EncodeError(MIL501("collision_free(d): d must be known at solve time", _span(node)))
        ex, ey = enc.signal_at(x, t), enc.signal_at(y, t)
        pairs: list[Tree] = []
        for i in range(others.shape[0]):
            ox, oy = others[i, t]
            if not (math.isfinite(ox) and math.isfinite(oy)):
                continue
            dx, dy = add(ex, -ox), add(ey, -oy)
            pair = mk(True, [add(add(scale(dx, a), scale(dy, b)), -d) for a, b in faces])
            if isinstance(pair, Op) and s > 0:
                # exact: the least 1-norm distance from the ego's box to the vehicle, minus d
                (xlo, xhi), (ylo, yhi) = enc.bounds(dx), enc.bounds(dy)
                pair.lo_hint = max(xlo, -xhi, 0.0) + max(ylo, -yhi, 0.0) - d
            pairs.append(pair)
        return scale(mk(False, pairs), s) if pairs else s * INF

    return fn


def reachable_box(p0: float, v_lo: float, v_hi: float, dt: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of a coordinate over ``steps`` samples when its rate stays in [v_lo, v_hi] [m/s]:
    ``p0 + k·dt·v_lo ≤ p_k ≤ p0 + k·dt·v_hi`` for k = 1..steps [m]."""
    k = np.arange(1, steps + 1) * dt
    return p0 + k * v_lo, p0 + k * v_hi
