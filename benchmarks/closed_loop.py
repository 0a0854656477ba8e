"""Closed-loop figures of the paper's four scenarios (the README's "Results against the paper" and "Measured").

For each scenario (with the monitor; ``--no-monitor`` also runs the MPC alone): control-step
time of both levels together (median / p95 / p99 / max) and per level, steps over the 100 ms
budget, simulated-time-to-wall-time ratio of the whole loop (controllers + plant + traffic +
writing the run), decisions, collisions, the closest vehicle, rule violations. Run directories
go to ``--out`` (default a temporary folder). Prints figures; not a test.

    python benchmarks/closed_loop.py [--duration S] [--no-monitor] [scenario ...]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

from twolevel.sim.engine import simulate_scenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ("traffic_rules", "safety", "scalability", "comparison")


def _machine() -> str:
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:
        cpus = os.cpu_count() or 1
    model = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo", encoding="utf-8"):
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{cpus} cpus, {model}, load {load:.2f}, python {sys.version.split()[0]}, numpy {np.__version__}"


def _row(name: str, s) -> str:  # noqa: ANN001 - RunSummary
    closest = s.closest[0] if s.closest else None
    near = f"{closest.other} {closest.distance:.2f} m @ {closest.t:.1f} s" if closest else "-"
    viol = ", ".join(f"{v.rule}×{v.steps}" for v in s.violations if v.steps) or "none"
    dec = " ".join(f"{k}:{v}" for k, v in sorted(s.decisions.items()))
    return (f"{name:<22} {s.steps:5d} {s.step_ms_median:7.2f} {s.step_ms_p95:7.2f} {s.step_ms_p99:7.2f} "
            f"{s.step_ms_max:7.1f} {s.high_ms_median:6.2f}/{s.high_ms_max:6.1f} {s.low_ms_median:5.2f}/{s.low_ms_max:5.1f} "
            f"{s.steps_over_budget:4d} {s.realtime:6.1f}x  coll {len(s.collisions)}  track {s.tracking_error_max:.2f}/"
            f"{s.tracking_error_mean:.2f} m  v-limit {s.speed_over_limit_max:+.2f}  closest {near}  [{dec}]  viol: {viol}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--duration", type=float, default=None, help="override every scenario's duration [s]")
    ap.add_argument("--no-monitor", action="store_true", help="also run each scenario without the monitor")
    ap.add_argument("--out", default=None, help="where the run directories go")
    args = ap.parse_args()
    out = Path(args.out or tempfile.mkdtemp(prefix="closed_loop_"))
    print(f"machine: {_machine()}")
    print(f"runs in {out}")
    print(f"{'scenario':<22} {'steps':>5} {'med ms':>7} {'p95':>7} {'p99':>7} {'max':>7} {'high med/max':>13} "
          f"{'low med/max':>11} {'>100':>4} {'sim/wall':>7}")
    for name in args.scenarios:
        for monitor in (True, False) if args.no_monitor else (True,):
            label = name if monitor else f"{name} (no monitor)"
            path = ROOT / "scenarios" / f"{name}.yaml"
            summary, diags = simulate_scenario(str(path), str(out / (name + ("" if monitor else "_nomon"))),
                                               monitor=monitor, duration=args.duration)
            if summary is None:
                print(f"{label:<22} failed: " + "; ".join(d.message for d in diags if d.is_error))
                continue
            print(_row(label, summary), flush=True)


if __name__ == "__main__":
    main()
