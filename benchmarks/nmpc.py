"""NMPC baseline vs the twolevel high level: per-step solve time on the same closed-loop steps.

Scenario ``comparison`` (curved road, four speed-limit changes, one oncoming car), H = 10,
dt = 0.1 s. The twolevel high-level MPC (``HighLevelController``, solver "modes") drives the
kinematic bicycle in closed loop; its states, times, traffic and applied controls are recorded,
and the same steps are replayed through the kinematic NMPC and the four-wheel NMPC (each
warm-started from its own previous solution, as in a run). Timed per step: the high level's
``timings_ms["total"]``; the NMPC's ``timings_ms["total"]`` (of which IPOPT's wall time is
``solve``). The four-wheel NMPC replays the first ``--fourwheel-steps`` steps (it is slow).

Also each controller's own closed loop (twolevel high level alone vs kinematic NMPC) on the
kinematic plant and on the four-wheel plant (the model mismatch the paper's comparison is about;
no low-level monitor here): lateral tracking error max/mean over the route before its last
15 m (where the reference piles up at the goal), the largest speed above the limit in force.

Usage: ``python benchmarks/nmpc.py [--steps 450] [--fourwheel-steps 60] [--expand]``.
Prints figures; not a test.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.high_level.settings import MPCSettings
from twolevel.control.nmpc.controller import NmpcController, NmpcOptions
from twolevel.models import bicycle
from twolevel.models import fourwheel as fw
from twolevel.models.rollout import rollout_accel
from twolevel.world import traffic as tr
from twolevel.world.loader import load_scenario
from twolevel.world.world import World, build_world

REPO = Path(__file__).resolve().parents[1]


def _machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import casadi

    return (f"machine: {os.cpu_count()} cpus, {cpu}, python {sys.version.split()[0]}, numpy {np.__version__}, "
            f"casadi {casadi.__version__} (IPOPT, MUMPS)")


def closed_loop(ctrl, world: World, steps: int, plant: str = "kinematic"):
    """Run ``ctrl`` on the kinematic plant (or the four-wheel model, driven through the compiled
    rollout with a → γ by the actuation map); returns the per-step inputs, results and states
    [X, Y, ψ, v]."""
    e = world.ego
    x = np.array([e.x, e.y, e.psi, e.v])
    full = fw.initial_state(e.x, e.y, e.psi, e.v)
    traffic = world.traffic0
    dt = world.settings.dt
    hist: dict[str, list[float]] = {"delta": [], "a": []}
    inputs, results, xs = [], [], [x]
    for k in range(steps):
        h = {n: np.asarray(v) for n, v in hist.items()}
        inputs.append((x, k * dt, traffic, h))
        r = ctrl.solve(x, k * dt, traffic, h)
        results.append(r)
        u = r.controls[0]
        hist["delta"].append(float(u[0]))
        hist["a"].append(float(u[1]))
        traffic = tr.step(traffic, dt, lanes=world.lanes, parts=world.parts, limits=world.limits, lights=world.lights,
                          stops=world.stops, ego=tr.EgoBox(*(float(c) for c in x[:4]), length=world.ego.length),
                          stop_speed=world.settings.stop_speed)
        if plant == "kinematic":
            x = bicycle.step(x, u, dt, ctrl.params)
        else:
            full = rollout_accel(full, u[None, None, :], dt).states[0, -1]
            x = full[:4].copy()
        xs.append(x)
    return inputs, results, np.array(xs)


def replay(ctrl, inputs) -> list:
    return [ctrl.solve(*inp) for inp in inputs]


def _stats(ms: np.ndarray) -> tuple[float, float, float]:
    return float(np.median(ms)), float(np.percentile(ms, 95)), float(np.max(ms))


def tracking(world: World, xs: np.ndarray) -> tuple[float, float, float]:
    s, e = world.route.local_coordinates(xs[:, :2])
    keep = s < world.route.s[-1] - 15.0
    over = xs[:, 3] - world.route.limit_at(s)
    return float(np.max(np.abs(e[keep]))), float(np.mean(np.abs(e[keep]))), float(np.max(over[keep]))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=450)
    ap.add_argument("--fourwheel-steps", type=int, default=60)
    ap.add_argument("--expand", action="store_true", help="four-wheel NLP as one SX graph (slow build, faster solve)")
    a = ap.parse_args()
    print(_machine())
    scn, diags = load_scenario(REPO / "scenarios" / "comparison.yaml")
    assert scn is not None, [d.message for d in diags]
    world = build_world(scn)
    st = MPCSettings(H=world.settings.H, dt=world.settings.dt, solver="modes", time_limit=world.settings.time_limit)
    hl, _ = HighLevelController.from_world(world, st)
    kin, _ = NmpcController.from_world(world, st)
    t0 = time.perf_counter()
    fwc, _ = NmpcController.from_world(world, st, model="fourwheel", options=NmpcOptions(expand=a.expand or None))
    build_fw = time.perf_counter() - t0
    assert hl is not None and kin is not None and fwc is not None
    print(f"scenario comparison: H = {st.H}, dt = {st.dt} s, {a.steps} closed-loop steps of the twolevel high level "
          f"(kinematic plant); four-wheel NMPC: {fwc.problem.substeps} internal steps per dt, "
          f"{fwc.problem.n_w} variables, {fwc.problem.n_g} constraints, built in {build_fw:.1f} s "
          f"(expand={bool(a.expand)})")

    # warm-up: two steps build the cold- and the warm-start IPOPT instances (built lazily)
    inputs, hl_res, hl_xs = closed_loop(hl, world, a.steps)
    for c in (kin, fwc):
        replay(c, inputs[:2])
        c.reset()
    kin_res = replay(kin, inputs)
    fw_res = replay(fwc, inputs[: a.fourwheel_steps])

    rows = [("twolevel high level (modes)", hl_res), ("NMPC kinematic (IPOPT)", kin_res),
            ("NMPC four-wheel (IPOPT)", fw_res)]
    print(f"\nper-step controller time [ms] on the same steps (NMPC: prepare + IPOPT; four-wheel: first "
          f"{len(fw_res)} steps)")
    print(f"{'controller':30s} {'steps':>5} {'median':>8} {'p95':>8} {'max':>8} {'med/HL':>7} {'p95/HL':>7} "
          f"{'Hz@med':>7} {'IPOPT med':>9} {'iters med':>9} {'ok':>5}")
    for name, res in rows:
        ms = np.array([r.timings_ms["total"] for r in res])
        med, p95, mx = _stats(ms)
        n = len(res)
        hl_sub = _stats(np.array([r.timings_ms["total"] for r in hl_res[:n]]))
        it = np.median([r.qps for r in res]) if "NMPC" in name else float("nan")
        ip = np.median([r.timings_ms["solve"] for r in res]) if "NMPC" in name else float("nan")
        ok = sum(r.ok for r in res)
        print(f"{name:30s} {n:5d} {med:8.2f} {p95:8.2f} {mx:8.1f} {med / hl_sub[0]:7.2f} {p95 / hl_sub[1]:7.2f} "
              f"{1e3 / med:7.1f} {ip:9.2f} {it:9.1f} {ok:5d}")
    solve_fw = np.array([r.timings_ms["solve"] for r in fw_res])
    print(f"four-wheel NMPC IPOPT time alone: median {np.median(solve_fw):.0f} ms, max {solve_fw.max():.0f} ms "
          f"→ {1e3 / np.median(solve_fw):.1f} Hz (paper: NMPC on the detailed model below 5 Hz)")

    # each controller's own closed loop, on the kinematic plant and on the four-wheel plant
    kin.reset()
    _, kin_own, kin_xs = closed_loop(kin, world, a.steps)
    loops = {"kinematic": ((hl_xs, hl_res), (kin_xs, kin_own))}
    hl.reset()
    kin.reset()
    _, hl_fw_res, hl_fw_xs = closed_loop(hl, world, a.steps, "fourwheel")
    _, kin_fw_res, kin_fw_xs = closed_loop(kin, world, a.steps, "fourwheel")
    loops["four-wheel"] = ((hl_fw_xs, hl_fw_res), (kin_fw_xs, kin_fw_res))
    print("\nown closed loop, high level alone (no low-level monitor), route before its last 15 m:")
    print(f"{'plant':11s} {'controller':30s} {'max |e| m':>10} {'mean |e| m':>11} {'max v - v_max':>14} {'fallbacks':>9}")
    for plant, pair in loops.items():
        for name, (xs, res) in zip(("twolevel high level (modes)", "NMPC kinematic (IPOPT)"), pair):
            emax, emean, over = tracking(world, xs)
            fb = sum(r.status == "fallback" for r in res)
            print(f"{plant:11s} {name:30s} {emax:10.3f} {emean:11.4f} {over:14.3f} {fb:9d}")
    print("paper (CARLA, detailed plant): max tracking error 0.29 m twolevel vs 0.93 m NMPC kinematic")


if __name__ == "__main__":
    main()
