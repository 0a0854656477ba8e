"""Cost of the kinematic bicycle's exact step on numpy, the MPC's hot path. Prints figures.

:func:`twolevel.models.bicycle.step` runs once per MPC step on one state (the linearisation
point past the previous plan), over whole batches in :func:`~twolevel.models.bicycle.rollout`,
and :func:`~twolevel.models.bicycle.linearize` once per MPC step over the horizon. Each figure
is the best of ``--repeat`` rounds of ``--number`` calls (the least disturbed by other jobs).
Usage: ``python benchmarks/bicycle_step.py [--number N] [--repeat R]``.
"""

from __future__ import annotations

import argparse
import timeit

import numpy as np

from twolevel.models import bicycle


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--number", type=int, default=2000, help="calls per round")
    ap.add_argument("--repeat", type=int, default=7, help="rounds (the best is printed)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    x1, u1 = np.array([1.0, 2.0, 0.3, 12.0]), np.array([0.05, -1.0])
    xk, uk = rng.normal(size=(256, 4)), rng.normal(scale=0.1, size=(256, 2))
    xs, us = rng.normal(size=(10, 4)), rng.normal(scale=0.1, size=(10, 2))
    us_roll = rng.normal(scale=0.1, size=(64, 10, 2))
    cases = {
        "step, one state": lambda: bicycle.step(x1, u1, 0.1),
        "step, 256 states": lambda: bicycle.step(xk, uk, 0.1),
        "rollout, 64 x H=10": lambda: bicycle.rollout(x1, us_roll, 0.1),
        "linearize, H=10": lambda: bicycle.linearize(xs, us, 0.1),
    }
    print(f"{'case':<22} {'µs per call':>12}")
    for name, fn in cases.items():
        best = min(timeit.repeat(fn, number=args.number, repeat=args.repeat)) / args.number
        print(f"{name:<22} {best * 1e6:12.2f}")


if __name__ == "__main__":
    main()
