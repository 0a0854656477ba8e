"""Closed-loop figures of the paper's four scenarios and the everyday suite, per high level.

For each scenario and planner (the MILP MPC ``twolevel``, the ``nmpc`` baseline, the
``reckless`` planner; all under the low level and its safety layer): collisions and how many
were the ego's fault (target 0), whether and when the goal was reached (a route that stops at
its goal; else how far the ego got), the smallest centre distance, the control step (both
levels, sensing and the verifier: wall-clock median / p99 / max, targets p99 ≤ 50 ms and every
step < 100 ms; and the same step's CPU time, what it costs when other jobs share the cores),
the safety layer's outcomes, the smallest time to react, braking (peak deceleration; share of
steps braking harder than 4 m/s²), the ride (:mod:`twolevel.verdict.ride`: the peak offset from
the centre of the lane the ego is in, peak deceleration and |jerk|, time standing still on the
way), the verdict of the scenario's pass criteria (``expect:``), decisions and rule violations. The paper's four are compared
with the goal times and distances measured before the safety layer (``BEFORE``: main at
fb74f82, the same machine; target: no later than 10 % after them). A closing line counts
at-fault collisions, goals missed, runs over the time targets. Run directories go to ``--out``
(default a temporary folder). Prints figures; not a test.

    python benchmarks/closed_loop.py [--suite] [--controllers twolevel,nmpc,reckless] [--no-safety]
                                     [--no-monitor] [--duration S] [scenario | path/to/scenario.yaml ...]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

from twolevel.sim.engine import simulate_scenario
from twolevel.sim.trace import RunData, read_run
from twolevel.verdict.judge import judge_run, recorded_ride

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ("traffic_rules", "safety", "scalability", "comparison")
RIGHT_OF_WAY = ("yield_priority_road", "left_turn_stream", "four_way_stop_crossing", "blocked_exit", "right_turn_stream",
                "merge_cyclist")
"""The right-of-way scenarios (scenarios/traffic/), part of the suite."""
CROSSWALKS = ("zebra", "zebra_walking", "crosswalk")
"""The crosswalk scenarios (scenarios/traffic/, rules/crosswalk.stl), part of the suite."""
MERGES = ("merge", "merge_sparse")
"""The merges with no sign (scenarios/traffic/), part of the suite."""
SUITE = (tuple(sorted(p.stem for p in (ROOT / "scenarios" / "everyday").glob("*.yaml"))) + RIGHT_OF_WAY + CROSSWALKS
         + MERGES)
#: Before the safety layer (main at fb74f82, the MPC and the NMPC with the paper's low level):
#: goal time [s] of a route that stops at its goal, else the route position [m] at the end.
BEFORE: dict[tuple[str, str], tuple[str, float]] = {
    ("traffic_rules", "twolevel"): ("goal", 68.4), ("comparison", "twolevel"): ("goal", 40.9),
    ("safety", "twolevel"): ("s", 134.8), ("scalability", "twolevel"): ("s", 191.0),
    ("traffic_rules", "nmpc"): ("s", 292.7), ("comparison", "nmpc"): ("goal", 42.4),
    ("safety", "nmpc"): ("s", 134.6), ("scalability", "nmpc"): ("s", 191.0),
}


def _machine() -> str:
    from twolevel.sim.provenance import cpus as usable

    cpus = usable()
    model = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo", encoding="utf-8"):
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpus} cpus, {model}, python {sys.version.split()[0]}, numpy {np.__version__}"


def _load() -> str:
    return f"{os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else "?"


def _path(name: str) -> Path:
    if name.endswith(".yaml"):  # a scenario file given by its path
        return Path(name).resolve()
    if name in RIGHT_OF_WAY + CROSSWALKS + MERGES:
        return ROOT / "scenarios" / "traffic" / f"{name}.yaml"
    return ROOT / "scenarios" / (f"{name}.yaml" if name in SCENARIOS else f"everyday/{name}.yaml")


def _progress(name: str, ctrl: str, s, run: RunData) -> tuple[str, str]:  # noqa: ANN001 - RunSummary
    """The goal column (time, or how far it got) and the comparison with before."""
    s_end = float(run.columns.get("s", [math.nan])[-1])
    got = f"goal {s.goal_reached_t:.1f} s" if s.goal_reached_t is not None else f"s {s_end:.0f} m"
    ref = BEFORE.get((name, ctrl))
    if ref is None:
        return got, ""
    kind, value = ref
    if kind == "goal":
        now = s.goal_reached_t
        return got, f"before {value:.1f} s ({'-' if now is None else f'{now / value:.2f}x'})"
    return got, f"before s {value:.0f} m ({s_end / value:.2f}x)"


def _row(label: str, s, got: str, before: str, ride, verdict) -> str:  # noqa: ANN001 - RunSummary, Ride, Verdict
    coll = f"{s.at_fault}/{len(s.collisions)}"
    ver = " ".join(f"{k[:4]}:{v}" for k, v in sorted(s.verification.items()))
    dec = " ".join(f"{k}:{v}" for k, v in sorted(s.decisions.items()))
    viol = ",".join(f"{v.rule}x{v.steps}" for v in s.violations if v.steps) or "-"
    judged = "-" if verdict is None else "PASS" if verdict.passed else "FAIL " + ",".join(c.name for c in verdict.failed)
    nan = float("nan")
    offset, jerk, stopped = (nan, nan, nan) if ride is None else (ride.lane_offset, ride.jerk, ride.stopped)
    return (f"{label:<32} {coll:>5} {got:>14} {before:<26} {s.min_distance:6.2f} "
            f"{s.step_ms_median:6.1f} {s.step_ms_p99:6.1f} {s.step_ms_max:6.1f} | "
            f"{s.step_cpu_ms_median:5.1f} {s.step_cpu_ms_p99:5.1f} {s.step_cpu_ms_max:5.1f} | "
            f"{offset:5.2f} {s.decel_peak:5.2f} {jerk:6.1f} {stopped:5.1f} {100 * s.hard_braking_share:5.1f}% "
            f"{s.ttr_min_s:5.1f} | {judged} | {ver} | {dec} | viol {viol}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*")
    ap.add_argument("--suite", action="store_true", help="the paper's four and the everyday suite")
    ap.add_argument("--controllers", default="twolevel", help="comma-separated: twolevel, nmpc, reckless")
    ap.add_argument("--duration", type=float, default=None, help="override every scenario's duration [s]")
    ap.add_argument("--no-safety", action="store_true", help="the paper's low level alone (no safety layer)")
    ap.add_argument("--no-monitor", action="store_true", help="no low level at all (the paper's 'without monitor')")
    ap.add_argument("--out", default=None, help="where the run directories go")
    args = ap.parse_args()
    names = list(args.scenarios) or (list(SCENARIOS) + list(SUITE) if args.suite else list(SCENARIOS))
    ctrls = [c.strip() for c in args.controllers.split(",") if c.strip()]
    out = Path(args.out or tempfile.mkdtemp(prefix="closed_loop_"))
    mode = "no monitor" if args.no_monitor else "no safety layer" if args.no_safety else "safety layer on"
    print(f"machine: {_machine()}; load {_load()} at the start; {mode}")
    print(f"runs in {out}")
    print(f"{'scenario / planner':<32} {'fault':>5} {'goal':>14} {'before':<26} {'min d':>6} "
          f"{'med':>6} {'p99':>6} {'max':>6} | {'cpu':>5} {'p99':>5} {'max':>5} | {'|off|':>5} {'decel':>5} "
          f"{'jerk':>6} {'stop':>5} {'>4':>6} {'ttr':>5} | verdict | verification | decisions | violations   "
          "(ms; |off|: peak offset from the lane's centre, m; m/s², m/s³, s)")
    faults = runs = missed = failed = over_p99 = over_max = over_p99_cpu = over_max_cpu = 0
    for name in names:
        for ctrl in ctrls:
            run_dir = out / f"{Path(name).stem}_{ctrl}"
            s, diags = simulate_scenario(str(_path(name)), str(run_dir), monitor=not args.no_monitor,
                                         safety=not args.no_safety, controller=ctrl, duration=args.duration,
                                         frames=False)
            label = f"{Path(name).stem if name.endswith('.yaml') else name} / {ctrl}"
            if s is None:
                print(f"{label:<32} failed: " + "; ".join(d.message for d in diags if d.is_error), flush=True)
                continue
            verdict, _ = judge_run(run_dir, _path(name))
            run = read_run(run_dir)  # once, after judge_run recorded the ride in it
            ride = recorded_ride(run.meta)
            got, before = _progress(name, ctrl, s, run)
            print(_row(label, s, got, before, ride, verdict), flush=True)
            runs += 1
            faults += s.at_fault
            missed += s.goal_reached_t is None
            failed += verdict is not None and not verdict.passed
            over_p99 += s.step_ms_p99 > 50.0
            over_max += s.step_ms_max >= 100.0
            over_p99_cpu += s.step_cpu_ms_p99 > 50.0
            over_max_cpu += s.step_cpu_ms_max >= 100.0
    print(f"{runs} runs: {faults} collisions the ego's fault (target 0); goal not reached in {missed} "
          f"(the stalled-car and tailgater scenarios have no lawful way); {failed} failed their criteria; wall p99 > 50 ms in {over_p99}, "
          f"a step ≥ 100 ms in {over_max}; CPU p99 > 50 ms in {over_p99_cpu}, a step ≥ 100 ms in {over_max_cpu}; "
          f"load {_load()} at the end")


if __name__ == "__main__":
    main()
