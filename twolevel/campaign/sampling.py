"""Points in a scenario's parameter space: grids, random samples, and the unit box searches use.

Every parameter maps the unit interval onto its values: a ``range`` linearly, ``choices`` in
equal slices, a ``normal`` through its quantile function (truncated to the range when one is
given), so a uniform point of the unit box is a draw from the declared distributions and an
optimiser can search the box ``[0, 1]^d`` whatever the parameters are. Deterministic for a seed.
"""

from __future__ import annotations

import itertools
import math
from statistics import NormalDist
from typing import Mapping

import numpy as np

from twolevel.world.schema import Parameter

__all__ = ["value_at", "values_at", "grid", "random_points", "MAX_GRID"]

MAX_GRID = 100_000
"""The largest grid a sweep accepts (points)."""


def value_at(p: Parameter, u: float) -> float:
    """The parameter's value at ``u`` ∈ [0, 1] of its unit interval."""
    u = min(max(float(u), 0.0), 1.0)
    if p.choices is not None:
        value = p.choices[min(int(u * len(p.choices)), len(p.choices) - 1)]
    elif p.normal is not None:
        dist = NormalDist(p.normal.mean, p.normal.std)
        lo, hi = (dist.cdf(p.range[0]), dist.cdf(p.range[1])) if p.range is not None else (0.0, 1.0)
        q = min(max(lo + u * (hi - lo), 1e-12), 1 - 1e-12)
        value = dist.inv_cdf(q)
        if p.range is not None:
            value = min(max(value, p.range[0]), p.range[1])
    else:
        assert p.range is not None
        value = p.range[0] + u * (p.range[1] - p.range[0])
    return float(round(value)) if p.integer else float(value)


def values_at(params: Mapping[str, Parameter], u: np.ndarray) -> dict[str, float]:
    """Parameter values at the point ``u`` (d,) of the unit box (parameters in their order)."""
    return {name: value_at(p, float(x)) for (name, p), x in zip(params.items(), u)}


def _grid_axis(p: Parameter) -> list[float]:
    if p.choices is not None:
        return [float(round(c)) if p.integer else float(c) for c in p.choices]
    if p.normal is not None:
        return sorted({value_at(p, (i + 0.5) / p.steps) for i in range(p.steps)})
    n = p.steps
    return sorted({value_at(p, i / (n - 1) if n > 1 else 0.5) for i in range(n)})


def grid(params: Mapping[str, Parameter]) -> list[dict[str, float]]:
    """Every combination of each parameter's grid values (``steps`` points across a range,
    every choice, ``steps`` quantiles of a normal). Raises ValueError past :data:`MAX_GRID`."""
    axes = [_grid_axis(p) for p in params.values()]
    size = math.prod(len(a) for a in axes)
    if size > MAX_GRID:
        raise ValueError(f"the grid has {size} points, more than {MAX_GRID}: lower 'steps' or sample with --samples")
    return [dict(zip(params, combo)) for combo in itertools.product(*axes)]


def random_points(params: Mapping[str, Parameter], n: int, seed: int) -> list[dict[str, float]]:
    """``n`` independent draws from the parameters' distributions (seeded)."""
    u = np.random.default_rng(seed).random((n, len(params)))
    return [values_at(params, row) for row in u]
