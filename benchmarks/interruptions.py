"""Interruption campaign: real ``twolevel simulate`` runs stopped by SIGINT, SIGTERM or SIGHUP at
random moments, start-up included, and what each left behind checked
(:mod:`twolevel.fuzz.interrupts`: no traceback, the documented exit code, every run directory
readable, ``run.json`` saying how the run ended, every completed row intact, ``report`` working).

    python benchmarks/interruptions.py                     # 20 interruptions, seed 0
    python benchmarks/interruptions.py --runs 50 --seed 3 --latest 20

The moments are drawn uniformly between 0 and ``--latest`` seconds after the process starts (on
a quiet 2-core machine the imports take ~1 s, loading and compiling ~2 s more, and the default run
of ``--duration 40`` simulated seconds ~20 s more, so every signal interrupts: start-up or steps,
in proportion to the time each takes; a run that ends first is counted as such). Prints one
line per run and the totals; exits 1 if any run broke the invariant. Deterministic in its draws
for a seed (what the process was doing at that moment depends on the machine's speed).
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from twolevel.fuzz.interrupts import SIGNAL_NAMES, interrupt_run

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--latest", type=float, default=15.0, metavar="SECONDS", help="latest moment of a signal")
    ap.add_argument("--duration", type=float, default=40.0, metavar="SECONDS", help="simulated time of each run")
    ap.add_argument("--scenario", default=str(REPO / "scenarios/traffic_rules.yaml"))
    args = ap.parse_args()
    rng = random.Random(args.seed)
    results = []
    t0 = time.perf_counter()
    print(f"{'#':>3} {'signal':>7} {'at [s]':>7} {'exit':>5} {'run.json':>12} {'rows':>5} {'stop [s]':>8}  problems")
    with tempfile.TemporaryDirectory(prefix="twolevel-interrupts-") as tmp:
        for i in range(args.runs):
            signame = rng.choice(SIGNAL_NAMES)
            after = round(rng.uniform(0.0, args.latest), 2)
            r = interrupt_run(args.scenario, Path(tmp) / f"run{i}", signame, after, duration=args.duration)
            results.append(r)
            print(f"{i:>3} {signame if r.sent else '(none)':>7} {r.after_s:>7.2f} {r.exit_code!s:>5} {r.status or '-':>12} {r.rows:>5} "
                  f"{r.stop_s:>8.2f}  {'; '.join(r.problems) or 'ok'}", flush=True)
    broken = [r for r in results if not r.ok]
    ended = Counter((r.status or "nothing written") if r.sent else "ended first" for r in results)
    stops = sorted(r.stop_s for r in results if r.sent)
    print(f"\n{len(results)} interruptions in {time.perf_counter() - t0:.0f} s: {len(results) - len(broken)} ok, "
          f"{len(broken)} broke the invariant; outcomes: {dict(sorted(ended.items()))}; signals: "
          f"{dict(sorted(Counter(r.signal for r in results).items()))}")
    if stops:
        print(f"time from the signal to the process's end: median {stops[len(stops) // 2]:.2f} s, max {stops[-1]:.2f} s")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
