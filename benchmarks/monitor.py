"""Per-sample cost of the online monitor beside RTAMT 0.4.10's online monitor, windows of
10, 100 and 1000 samples; plus the offline oracle's throughput.

RTAMT's discrete-time online monitor runs past operators directly and future ones after
``pastify()`` (which delays the output by the horizon), so every formula here is comparable:
both monitors receive one sample per ``update`` and do the same job. Our monitor's figure is the
steady state after the windows have filled; RTAMT's buffers are pre-filled, so its cost is
steady from the first sample.

Run: ``.venv/bin/python benchmarks/monitor.py`` (about a minute; RTAMT's until at w = 1000 is
slow, so it runs fewer samples).
"""

from __future__ import annotations

import os
import platform
import time
from typing import Callable

import numpy as np

from twolevel.monitor.online import OnlineMonitor
from twolevel.monitor.robustness import robustness
from twolevel.stl import ast as A

WINDOWS = (10, 100, 1000)
P = A.Compare(">=", A.Var("x"), A.Num(0.0))
Q = A.Compare(">=", A.Var("y"), A.Num(0.0))

FORMULAS: dict[str, tuple[Callable[[int], A.Node], Callable[[int], str]]] = {
    "historically[0:w]": (
        lambda w: A.Temporal("historically", A.Interval(0.0, float(w)), P),
        lambda w: f"historically[0:{w}](x >= 0)",
    ),
    "once[0:w]": (
        lambda w: A.Temporal("once", A.Interval(0.0, float(w)), P),
        lambda w: f"once[0:{w}](x >= 0)",
    ),
    "always[0:w]": (
        lambda w: A.Temporal("always", A.Interval(0.0, float(w)), P),
        lambda w: f"always[0:{w}](x >= 0)",
    ),
    "eventually[0:w]": (
        lambda w: A.Temporal("eventually", A.Interval(0.0, float(w)), P),
        lambda w: f"eventually[0:{w}](x >= 0)",
    ),
    "since[0:w]": (
        lambda w: A.BinTemporal("since", A.Interval(0.0, float(w)), P, Q),
        lambda w: f"(x >= 0) since[0:{w}] (y >= 0)",
    ),
    "until[0:w]": (
        lambda w: A.BinTemporal("until", A.Interval(0.0, float(w)), P, Q),
        lambda w: f"(x >= 0) until[0:{w}] (y >= 0)",
    ),
    "until[w/2:w]": (
        lambda w: A.BinTemporal("until", A.Interval(float(w // 2), float(w)), P, Q),
        lambda w: f"(x >= 0) until[{w // 2}:{w}] (y >= 0)",
    ),
}


def _samples(n: int, seed: int = 0) -> list[dict[str, float]]:
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(0, 1, n))  # random walks: long monotone runs fill the wedges
    y = np.cumsum(rng.normal(0, 1, n))
    return [{"x": float(a), "y": float(b)} for a, b in zip(x, y)]


def ours_per_sample(formula: A.Node, w: int, n: int = 20000) -> float:
    """Seconds per ``update`` in the steady state (after 2w warm-up samples); best of 3."""
    rows = _samples(2 * w + n)
    best = float("inf")
    for _ in range(3):
        mon = OnlineMonitor(formula, 1.0)
        update = mon.update
        for row in rows[: 2 * w]:
            update(row)
        timed = rows[2 * w :]
        t0 = time.perf_counter()
        for row in timed:
            update(row)
        best = min(best, (time.perf_counter() - t0) / len(timed))
    return best


def rtamt_per_sample(text: str, budget: float = 1.5, max_steps: int = 3000) -> float | None:
    """Seconds per RTAMT online ``update`` (pastified); None if RTAMT is not installed."""
    try:
        import rtamt
    except ImportError:
        return None
    spec = rtamt.StlDiscreteTimeSpecification()
    spec.declare_var("x", "float")
    spec.declare_var("y", "float")
    spec.declare_var("out", "float")
    spec.spec = "out = " + text
    spec.parse()
    spec.pastify()
    rows = _samples(max_steps)
    steps = 0
    t0 = time.perf_counter()
    for k, row in enumerate(rows):
        spec.update(k, [("x", row["x"]), ("y", row["y"])])
        steps += 1
        if time.perf_counter() - t0 > budget and steps >= 5:
            break
    return (time.perf_counter() - t0) / steps


def offline_per_sample(formula: A.Node, n: int = 200_000) -> float:
    rows = _samples(n)
    sig = {"x": np.array([r["x"] for r in rows]), "y": np.array([r["y"] for r in rows])}
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        robustness(formula, sig, 1.0)
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def main() -> None:
    try:
        import rtamt  # noqa: F401

        rtamt_version = "0.4.10 (installed)"
    except ImportError:
        rtamt_version = "not installed"
    print(
        f"machine: {os.cpu_count()} CPUs, {platform.machine()}, {platform.system()}; "
        f"Python {platform.python_version()}; numpy {np.__version__}; RTAMT {rtamt_version}"
    )
    print()
    print("online monitor, per sample (µs): ours vs RTAMT StlDiscreteTimeSpecification.update")
    header = f"{'formula':<18} {'w':>5} {'ours':>9} {'RTAMT':>10} {'RTAMT/ours':>11} {'offline':>9}"
    print(header)
    print("-" * len(header))
    for name, (make, text) in FORMULAS.items():
        for w in WINDOWS:
            ours = ours_per_sample(make(w), w)
            theirs = rtamt_per_sample(text(w))
            off = offline_per_sample(make(w))
            ratio = f"{theirs / ours:10.1f}x" if theirs else "         -"
            th = f"{theirs * 1e6:10.1f}" if theirs else "         -"
            print(f"{name:<18} {w:>5} {ours * 1e6:9.2f} {th} {ratio} {off * 1e6:9.3f}")
    print()
    print("offline = the vectorised oracle (robustness over 200 000 samples), µs per sample.")


if __name__ == "__main__":
    main()
