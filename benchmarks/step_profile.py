"""Where a control step's CPU time goes: per phase, over the slowest steps of a scenario.

Runs a scenario (both levels, the low level and its safety layer, as ``simulate``) with the main
phases of the step wrapped to add up their CPU time (``time.process_time``, what a step costs
when other jobs share the cores; inclusive: a phase counts the phases it calls): sensing, the
high level, the low level (its judging of candidates, the zone signals inside them, sampling),
the verifier (fail-safe rollouts, occupancy, the checks). Prints each phase's median / p99 / max
per step [ms] and the breakdown of the slowest steps. Not a test.

    python benchmarks/step_profile.py [scenario ...] [--slowest N] [--duration S]

A scenario is a path or a name of the paper's four, ``everyday/<name>`` or ``traffic/<name>``.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from twolevel.sim import engine
from twolevel.sim.engine import simulate_scenario

ROOT = Path(__file__).resolve().parents[1]

#: (label, module, attribute path) of each wrapped phase: where it is looked up when called.
PHASES: tuple[tuple[str, str, str], ...] = (
    ("sense", "twolevel.sim.engine", "ClosedLoop.sense"),
    ("high", "twolevel.sim.engine", "ClosedLoop.plan"),
    ("low", "twolevel.sim.engine", "ClosedLoop.check"),
    ("judge", "twolevel.control.low_level.judge", "Judge._timed"),
    ("zones", "twolevel.world.sensing", "participant_zone_signals"),
    ("sampling", "twolevel.control.low_level.controller", "sample_ball"),
    ("verify", "twolevel.control.low_level.guard", "Guard.verify"),
    ("failsafe", "twolevel.safety.verify", "roll"),
    ("occupancy", "twolevel.safety.verify", "predict"),
    ("check", "twolevel.safety.verify", "_judge"),
)


def _wrap(acc: dict[str, float], label: str, fn: Callable) -> Callable:
    @functools.wraps(fn)
    def timed(*a, **k):  # noqa: ANN002, ANN003, ANN202
        c0 = time.process_time()
        try:
            return fn(*a, **k)
        finally:
            acc[label] = acc.get(label, 0.0) + (time.process_time() - c0) * 1e3
    return timed


def _install(acc: dict[str, float]) -> None:
    for label, module, attr in PHASES:
        owner = importlib.import_module(module)
        *outer, name = attr.split(".")
        for part in outer:
            owner = getattr(owner, part)
        setattr(owner, name, _wrap(acc, label, getattr(owner, name)))


def _path(name: str) -> Path:
    p = Path(name)
    if p.suffix == ".yaml":
        return p
    return ROOT / "scenarios" / f"{name}.yaml"


def profile(path: Path, duration: float | None) -> tuple[list[dict[str, float]], float | None]:
    """Per step, each phase's CPU time [ms] (and ``step``: the step's, as the run records it; the
    criticality figure computed after the step is left out)."""
    acc: dict[str, float] = {}
    steps: list[dict[str, float]] = []
    original = engine.ClosedLoop.record

    def record(self, sensed, plan, applied, times, out, ttr):  # noqa: ANN001, ANN202
        steps.append({**acc, "step": times.cpu})
        acc.clear()
        return original(self, sensed, plan, applied, times, out, ttr)

    def criticality(self, sensed, applied):  # noqa: ANN001, ANN202 - after the step's timing: not counted
        kept = dict(acc)
        try:
            return original_criticality(self, sensed, applied)
        finally:
            acc.clear()
            acc.update(kept)

    _install(acc)
    original_criticality = engine.ClosedLoop.criticality
    engine.ClosedLoop.record = record  # type: ignore[method-assign]
    engine.ClosedLoop.criticality = criticality  # type: ignore[method-assign]
    with tempfile.TemporaryDirectory() as tmp:
        s, diags = simulate_scenario(str(path), str(Path(tmp) / "run"), duration=duration, frames=False)
    if s is None:
        raise SystemExit("; ".join(d.message for d in diags))
    return steps, s.goal_reached_t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*", default=["everyday/cyclist_ahead"])
    ap.add_argument("--slowest", type=int, default=5)
    ap.add_argument("--duration", type=float, default=None)
    args = ap.parse_args()
    labels = ["step"] + [p[0] for p in PHASES]
    for name in args.scenarios:
        steps, goal = profile(_path(name), args.duration)
        print(f"{name}: {len(steps)} steps, goal {goal}; CPU ms per step (inclusive phases)")
        print(f"  {'':<10} {'median':>7} {'p99':>7} {'max':>7} {'share':>6}")
        total = sum(st["step"] for st in steps)
        for lab in labels:
            col = np.array([st.get(lab, 0.0) for st in steps])
            print(f"  {lab:<10} {np.median(col):7.1f} {np.percentile(col, 99):7.1f} {col.max():7.1f} "
                  f"{col.sum() / total:6.0%}")
        print(f"  slowest {args.slowest}: " + " ".join(f"{lab:>9}" for lab in labels))
        for i in sorted(range(len(steps)), key=lambda i: -steps[i]["step"])[: args.slowest]:
            print(f"  step {i:<6}  " + " ".join(f"{steps[i].get(lab, 0.0):9.1f}" for lab in labels))


if __name__ == "__main__":
    main()
