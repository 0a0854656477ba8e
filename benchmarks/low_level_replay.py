"""The low level's cost on recorded situations, with and without candidate screening.

Runs a scenario once (both levels, the monitor on), records the low level's inputs at every
step, then replays ``LowLevelController.decide`` on them for each setting of
``LowLevelSettings.screen``, each step ``--repeat`` times, keeping the fastest (robust to other
jobs sharing the cores). Prints per decision the median / max of those times [ms] and the ratio
to the first setting, and checks that every setting decides the same. Not a test.

    python benchmarks/low_level_replay.py [scenario] [--repeat N] [--duration S]
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from twolevel.control.low_level import controller as ll
from twolevel.sim.engine import simulate_scenario

ROOT = Path(__file__).resolve().parents[1]
SETTINGS: tuple[tuple[int, ...], ...] = ((), (3,), (3, 6))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", nargs="?", default="scalability")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--duration", type=float, default=None)
    args = ap.parse_args()

    calls: list[tuple[ll.LowLevelController, tuple, dict, str]] = []
    original = ll.LowLevelController.decide

    def recording(self, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        d = original(self, *a, **k)
        calls.append((self, a, k, d.decision))
        return d

    ll.LowLevelController.decide = recording  # type: ignore[method-assign]
    try:
        simulate_scenario(str(ROOT / "scenarios" / f"{args.scenario}.yaml"), tempfile.mkdtemp(prefix="llreplay_"),
                          monitor=True, duration=args.duration)
    finally:
        ll.LowLevelController.decide = original  # type: ignore[method-assign]
    if not calls:
        print("no low-level steps recorded")
        return
    base = calls[0][0]
    ctrls = []
    for screen in SETTINGS:
        c = ll.LowLevelController(base.world, base.rules, params=base.params, consts=base.consts,
                                  settings=dataclasses.replace(base.settings, screen=screen))
        c.warm_up(np.asarray(calls[0][1][0]))
        ctrls.append(c)
    times = np.zeros((len(SETTINGS), len(calls)))
    same = True
    for i, (_, a, k, decision) in enumerate(calls):
        ref = None
        for s, c in enumerate(ctrls):
            best = np.inf
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                d = c.decide(*a, **k)
                best = min(best, time.perf_counter() - t0)
            times[s, i] = best * 1e3
            key = (d.decision, d.candidates, tuple(d.control), tuple(sorted(d.robustness.items())))
            same &= ref is None or key == ref
            ref = key if ref is None else ref
    decisions = np.array([c[3] for c in calls])
    print(f"{args.scenario}: {len(calls)} steps, fastest of {args.repeat}; same decisions in every setting: {same}")
    print("median/p99/max ms per step (median ratio to the first setting); worst per-step ratio: "
          + ", ".join(f"{SETTINGS[s]}: {np.max(times[s] / times[0]):.2f}x" for s in range(1, len(SETTINGS))))
    print(f"{'decision':<16} {'n':>4} " + " ".join(f"{'screen=' + str(s):>30}" for s in SETTINGS))
    for dec in ["all"] + sorted(set(decisions)):
        m = np.ones(len(calls), bool) if dec == "all" else decisions == dec
        cells = []
        for s in range(len(SETTINGS)):
            med, p99, mx = np.median(times[s, m]), np.percentile(times[s, m], 99), times[s, m].max()
            ratio = med / max(np.median(times[0, m]), 1e-9)
            cells.append(f"{med:6.2f}/{p99:6.2f}/{mx:6.2f} ({ratio:4.2f}x)")
        print(f"{dec:<16} {int(m.sum()):4d} " + " ".join(f"{c:>30}" for c in cells))


if __name__ == "__main__":
    main()
