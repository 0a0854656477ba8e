"""The property "the ego is never at fault" over many more random worlds than the tests draw.

Each seed draws 1–5 adversarial but legal others (:func:`twolevel.safety.adversary.random_adversaries`:
braking down to the bounds, accelerating, legal cut-ins, wandering pedestrians) and the ego's
speed, and runs the reckless planner under the safety layer for ``--seconds``. Prints how many
runs started safe, how many collided and how many of those collisions were the ego's fault
(target 0), the verification outcomes, and the control step's wall and CPU time. Not a test.

    python benchmarks/never_at_fault.py [--seeds 300] [--seconds 6] [--first 0]
"""

from __future__ import annotations

import argparse
import collections
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from twolevel.safety.adversary import random_adversaries, scenario_text
from twolevel.sim.engine import simulate_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=300)
    ap.add_argument("--seconds", type=int, default=6)
    ap.add_argument("--first", type=int, default=0, help="the first seed")
    args = ap.parse_args()
    print(f"{args.seeds} worlds of {args.seconds} s, reckless planner under the safety layer; "
          f"load {os.getloadavg()[0]:.2f}")
    safe = collided = fault = 0
    outcomes: collections.Counter[str] = collections.Counter()
    verdicts: collections.Counter[str] = collections.Counter()
    p99, p99_cpu, worst, worst_cpu = [], [], 0.0, 0.0
    faulty = []
    t0 = time.perf_counter()
    for seed in range(args.first, args.first + args.seeds):
        rng = np.random.default_rng(seed)
        others = random_adversaries(rng, int(rng.integers(1, 6)), args.seconds)
        with tempfile.TemporaryDirectory() as tmp:
            path = scenario_text(Path(tmp), others, float(rng.uniform(0, 15)), float(args.seconds))
            s, diags = simulate_scenario(str(path), str(Path(tmp) / "run"), controller="reckless", frames=False,
                                         ttr_every=0)
        assert s is not None, [d.message for d in diags]
        if not s.safe_start:
            continue
        safe += 1
        collided += bool(s.collisions)
        verdicts.update(c.verdict for c in s.collisions)
        if s.at_fault:
            fault += 1
            faulty.append(seed)
        outcomes.update(s.verification)
        p99.append(s.step_ms_p99)
        p99_cpu.append(s.step_cpu_ms_p99)
        worst, worst_cpu = max(worst, s.step_ms_max), max(worst_cpu, s.step_cpu_ms_max)
    print(f"{safe} of {args.seeds} started safe; {collided} collided ({dict(verdicts)}); "
          f"{fault} at the ego's fault (target 0){': seeds ' + str(faulty) if faulty else ''}")
    print(f"steps: {dict(outcomes)}; per run p99 median {np.median(p99):.1f} ms wall / {np.median(p99_cpu):.1f} ms "
          f"CPU, worst step {worst:.1f} ms wall / {worst_cpu:.1f} ms CPU; {time.perf_counter() - t0:.0f} s in all, "
          f"load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
