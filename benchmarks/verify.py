"""Verification of one control step (twolevel.safety) at 0, 5, 20 and 40 nearby participants.

The three-lane highway (maps/highway.yaml) with N vehicles placed within 45 m of the ego (all
lanes, ahead and behind; seeded), a steady flow at the ego's 12 m/s, one of them a slower leader
on the ego's lane. The ego drives a plain planner — hold 12 m/s (accelerate at 1 m/s² below it),
whatever is ahead — and every step
:func:`~twolevel.safety.verify.verify_step` checks that command; when it is refuted the ego
executes the fail-safe verified last (as the low level will), so the run stays safe and the
verifier sees the situations a real run produces: free road, closing in on the leader,
emergency braking. The traffic steps with the ego as a leader for IDM.

Printed per N: median / p95 / p99 of the whole verification [ms] (wall clock) and its median in
CPU time of the process (what the verification costs when other jobs share the cores), the split
into intended step, fail-safe rollouts, prediction and checks (medians and p99, wall), the
participants that could come near the ego's trajectories (median, max), how many steps verified,
and the ratio of each median to N = 0's.
Usage: ``python benchmarks/verify.py [--steps 200] [--quick] [--coarse 3]`` (``--coarse 1``:
uniform intervals of one control step over the whole horizon).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from twolevel.models import fourwheel as fw
from twolevel.models.actuation import gamma_from_accel
from twolevel.models.rollout import rollout
from twolevel.safety.verify import VerifySettings, context, verify_initial_state, verify_step
from twolevel.world import traffic as tr
from twolevel.world.loader import load_scenario
from twolevel.world.world import build_world

REPO = Path(__file__).resolve().parents[1]
COUNTS = (0, 5, 20, 40)


def world_with(n: int, seed: int, tmp: Path):
    """The highway with the ego at 12 m/s on the middle lane and n vehicles within 45 m of it, on
    all three lanes, at 12 m/s (constant velocity: a steady flow, every one within the declared
    assumptions); ahead of the ego on its lane a leader at 10 m/s that it closes in on."""
    rng = np.random.default_rng(seed)
    slots = [(lane, s) for lane in ("right", "left", "middle") for s in np.arange(156.0, 246.0, 7.5)
             if not (lane == "middle" and 185.0 <= s <= 235.0)]
    pick = sorted(rng.choice(len(slots), size=min(n - 1, len(slots)), replace=False)) if n > 1 else []
    parts = ["{id: leader, behaviour: constant_velocity, start: {lane: middle, s: 236}, speed: 10.0}"] if n else []
    for j, i in enumerate(pick):
        lane, s = slots[i]
        parts.append(f"{{id: v{j}, behaviour: constant_velocity, start: {{lane: {lane}, s: {s + rng.uniform(-1, 1):.2f}}},"
                     " speed: 12.0}")
    text = f"""kind: scenario
map: {REPO / 'maps/highway.yaml'}
ego: {{start: {{lane: middle, s: 200}}, speed: 12.0}}
route: {{start: {{lane: middle, s: 200}}, goal: {{lane: middle, s: 1450}}, stop_at_goal: false}}
participants: [{', '.join(parts)}]
"""
    p = tmp / f"n{n}.yaml"
    p.write_text(text)
    scn, diags = load_scenario(p)
    assert scn is not None, [d.message for d in diags]
    return build_world(scn)


def run(n: int, steps: int, seed: int, tmp: Path, coarse: int = 3) -> dict[str, np.ndarray]:
    w = world_with(n, seed, tmp)
    ctx = context(w, settings=VerifySettings(coarse=coarse))
    dt = w.settings.dt
    x = fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, w.ego.v, ctx.params)
    traffic = w.traffic0
    first = verify_initial_state(ctx, x, traffic, 0.0)
    fs, k_fs = first.failsafe, 0
    verify_step(ctx, x, np.array([0.0, 0.0]), traffic, 0.0)  # warm-up (compiled rollouts)
    s_ego = 0.0
    rows: dict[str, list[float]] = {k: [] for k in ("total", "cpu", "step", "failsafe", "prediction", "check", "near",
                                                    "ok")}
    for k in range(steps):
        a = 1.0 if x[3] < 12.0 else 0.0
        u = np.array([0.0, float(gamma_from_accel(a, max(x[3], 0.0), ctx.params))])
        s_ego = float(w.route.project_near(x[None, :2], np.array([s_ego]), 10.0)[0][0])  # as the simulator tracks it
        c0 = time.process_time()
        v = verify_step(ctx, x, u, traffic, k * dt, s_hint=s_ego)
        cpu = (time.process_time() - c0) * 1e3
        for key in ("total", "step", "failsafe", "prediction", "check"):
            rows[key].append(v.timings_ms.get(key, 0.0))
        rows["near"].append(v.participants)
        rows["ok"].append(float(v.verified))
        if v.verified:
            fs, k_fs = v.failsafe, 0
        elif fs is not None:
            u, k_fs = fs.control_at(k_fs), k_fs + 1
        else:
            u = np.array([0.0, -1.0])
        x = rollout(x, u[None, None, :], dt, ctx.params).states[0, 1]
        traffic = tr.step(traffic, dt, lanes=w.lanes, parts=w.parts, limits=w.limits, lights=w.lights, stops=w.stops,
                          ego=tr.EgoBox(float(x[0]), float(x[1]), float(x[2]), float(x[3]), w.ego.length))
        rows["cpu"].append(cpu)
    return {k: np.asarray(v) for k, v in rows.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="50 steps per count")
    ap.add_argument("--coarse", type=int, default=3, help="steps per interval beyond the first 2 s (1: uniform)")
    args = ap.parse_args(argv)
    steps = 50 if args.quick else args.steps
    print(f"verify_step on the highway, {steps} steps per count, intervals of {args.coarse} steps beyond 2 s; "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
    print(f"{'N':>3} {'near med/max':>12} {'verified':>9} {'median':>7} {'p95':>7} {'p99':>7} {'cpu':>6} {'×N=0':>6} | "
          f"{'step':>5} {'fail-safe':>10} {'predict':>13} {'check':>11}  (median, p99 ms)")
    base = None
    with tempfile.TemporaryDirectory() as tmp:
        for n in COUNTS:
            r = run(n, steps, args.seed, Path(tmp), args.coarse)
            q = np.percentile(r["total"], [50, 95, 99])
            base = base or q[0]
            split = " ".join(f"{np.median(r[k]):5.2f}/{np.percentile(r[k], 99):5.2f}" for k in ("step", "failsafe",
                                                                                             "prediction", "check"))
            print(f"{n:>3} {np.median(r['near']):>6.0f}/{r['near'].max():<5.0f} {r['ok'].mean():>8.0%} "
                  f"{q[0]:7.2f} {q[1]:7.2f} {q[2]:7.2f} {np.median(r['cpu']):6.2f} {q[0] / base:6.2f} | {split}")
    print("targets (at 20): median ≤ 5 ms, p99 ≤ 20 ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
