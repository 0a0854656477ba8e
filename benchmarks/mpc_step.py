"""Per-MPC-step figures of the high-level controller (the README's "Measured"). Prints figures.

Closed-loop runs on the kinematic bicycle itself (the MPC's model) on the three-lane highway with
N = 0, 6, 12, 18, 30 constant-velocity vehicles around the ego (within r_near = 40 m) and a slow
vehicle ahead in the ego's lane, so overtaking is the right choice. The run is driven by the
``modes`` path; at every step the same problem (same linearisation point) is also solved by the
``highs`` path and, offline, by the mode search's branch-and-bound run to completion (the exact
optimum). Per path: median / p95 / p99 of the total step time and of each phase, binaries, rows,
QPs per step, the share of steps within 1 % of the exact optimum, and highs/modes time ratios.
Rules: the shipped speed limit and safe distance (collision_free(D_safe = 1 m), time-headway gap)
plus staying on the road. The look-ahead is the default (10 steps of 0.1 s, then coarse steps to
5 s, with RSS's terminal distance); ``--horizon-s 1 --no-rss`` is the paper's horizon alone, for
comparing. Usage: ``python benchmarks/mpc_step.py [--quick] [--steps N] [--horizon-s S]
[--coarse-dt S] [--no-rss]``.
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

from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.high_level.settings import MPCSettings
from twolevel.models import bicycle
from twolevel.stl.lint import load_ruleset
from twolevel.world.loader import load_scenario
from twolevel.world.provided import PROVIDED_SIGNALS
from twolevel.world.world import build_world

REPO = Path(__file__).resolve().parents[1]
ROAD = "input float e\non_road = always[0:1] ((e <= 4.5) and (e >= -4.5));\n"


def world_with(n: int, seed: int, tmp: Path):
    rng = np.random.default_rng(seed)
    slots = [(lane, s) for lane in ("right", "middle", "left") for s in np.arange(72.0, 136.0, 8.0)
             if not (lane == "middle" and 88.0 <= s <= 124.0)]
    pick = rng.choice(len(slots), size=min(n, len(slots)), replace=False) if n else []
    parts = [f"{{id: slow, behaviour: constant_velocity, start: {{lane: middle, s: 125}}, speed: 6.0}}"] if n else []
    for j, i in enumerate(sorted(pick)):
        lane, s = slots[i]
        parts.append(f"{{id: v{j}, behaviour: constant_velocity, start: {{lane: {lane}, s: {s + rng.uniform(-1.5, 1.5):.2f}}},"
                     f" speed: {rng.uniform(11.5, 13.5):.2f}}}")
    text = f"""kind: scenario
map: {REPO / 'maps/highway.yaml'}
ego: {{start: {{lane: middle, s: 100}}, speed: 12.0, desired_speed: 13.0}}
route: {{start: {{lane: middle, s: 100}}, goal: {{lane: middle, s: 1400}}, stop_at_goal: false}}
participants: [{', '.join(parts)}]
controller: {{r_near: 40}}
"""
    p = tmp / f"n{n}.yaml"
    p.write_text(text)
    scn, diags = load_scenario(p)
    assert scn is not None, [d.message for d in diags]
    return build_world(scn)


def rulesets(tmp: Path):
    out = []
    (tmp / "road.stl").write_text(ROAD)
    for path in (REPO / "rules/speed_limit.stl", REPO / "rules/safe_distance.stl", tmp / "road.stl"):
        rs, d = load_ruleset(str(path), dt=0.1, provided_signals=PROVIDED_SIGNALS)
        assert rs is not None, [x.message for x in d]
        out.append(rs)
    return out


def advance(tr, dt):
    from dataclasses import replace
    return replace(tr, t=tr.t + dt, x=tr.x + tr.v * np.cos(tr.psi) * dt, y=tr.y + tr.v * np.sin(tr.psi) * dt)


def pct(a, q):
    return float(np.percentile(a, q)) if len(a) else float("nan")


def run(n: int, steps: int, seed: int, tmp: Path, exact: bool, look: dict) -> dict:
    w = world_with(n, seed, tmp)
    sets = rulesets(tmp)
    ctl = {p: HighLevelController(w, sets, MPCSettings(solver=p, time_limit=0.1 if p == "modes" else 1.0, monitor=False,
                                                       **look))
           for p in ("modes", "highs")}
    ref = HighLevelController(w, sets, MPCSettings(solver="modes", time_limit=None, monitor=False, **look))
    e = w.ego
    x = np.array([e.x, e.y, e.psi, e.v])
    tr = w.traffic0
    rec = {p: {"t": [], "cpu": [], "ph": [], "bin": [], "rows": [], "qps": [], "cost": [], "status": []} for p in ctl}
    rec["exact"] = []
    rec["nearby"] = []
    for k in range(steps):
        t = 0.1 * k
        carry = ctl["modes"].carry  # every path solves the step the modes path sees
        out = {}
        for p, c in ctl.items():
            c.carry = carry
            c0 = time.process_time()
            r = c.solve(x, t, tr, None)
            R = rec[p]
            R["cpu"].append((time.process_time() - c0) * 1e3)
            out[p] = r
            R["t"].append(r.timings_ms["total"])
            R["ph"].append(r.timings_ms)
            R["bin"].append(r.binaries)
            R["rows"].append(r.rows)
            R["qps"].append(r.qps)
            R["cost"].append(r.cost if r.ok else np.inf)
            R["status"].append(r.status.value)
        if exact:  # the same step, B&B to completion (same linearisation point as the modes path,
            # same recovery of rules violated now)
            ref.carry = carry
            step, _, _ = ref.prepare(x, t, tr, None)
            rec["nearby"].append(len(step.hc.index))
            res = ref.solve(x, t, tr, None)
            rec["exact"].append(res.cost if res.ok else np.inf)
        r = out["modes"]
        x = bicycle.step(x, r.controls[0], 0.1, ctl["modes"].params)
        tr = advance(tr, 0.1)
    return rec


def summarize(n: int, rec: dict) -> None:
    ex = np.array(rec["exact"]) if rec["exact"] else None
    print(f"\nN = {n:2d} vehicles placed, nearby (within r_near) median {np.median(rec['nearby']) if rec['nearby'] else float('nan'):.0f}"
          f", max {max(rec['nearby']) if rec['nearby'] else 0}; steps {len(rec['modes']['t'])}")
    meds = {}
    for p in ("modes", "highs"):
        R = rec[p]
        t = np.array(R["t"])
        meds[p] = t
        phases = sorted({k for ph in R["ph"] for k in ph if k not in ("total",)})
        cpu = np.array(R["cpu"])
        line = f"  {p:5s} total median {np.median(t):6.2f}  p95 {pct(t, 95):6.2f}  p99 {pct(t, 99):6.2f} ms " \
               f"(CPU median {np.median(cpu):6.2f} p99 {pct(cpu, 99):6.2f}) | " \
               f"binaries med {np.median(R['bin']):.0f} max {max(R['bin'])} | rows med {np.median(R['rows']):.0f} | " \
               f"QPs/step med {np.median(R['qps']):.0f} p99 {pct(R['qps'], 99):.0f}"
        if ex is not None:
            c = np.array(R["cost"])
            both = np.isfinite(ex)
            within = np.mean(c[both] <= ex[both] * 1.01 + 1e-6) * 100 if both.any() else float("nan")
            line += f" | within 1 % of exact: {within:5.1f} % of {both.sum()} steps"
        st = {s: R["status"].count(s) for s in set(R["status"])}
        print(line + f" | {st}")
        for ph in phases:
            v = np.array([d.get(ph, 0.0) for d in R["ph"]])
            if np.any(v > 0):
                print(f"        {ph:12s} median {np.median(v):6.3f}  p95 {pct(v, 95):6.3f}  p99 {pct(v, 99):6.3f} ms")
    r = meds["highs"] / np.maximum(meds["modes"], 1e-9)
    print(f"  highs / modes: median time ratio {np.median(meds['highs']) / np.median(meds['modes']):.1f}x, "
          f"p99 ratio {pct(meds['highs'], 99) / pct(meds['modes'], 99):.1f}x, per-step ratio median {np.median(r):.1f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer steps and vehicle counts")
    ap.add_argument("--steps", type=int, default=None, help="MPC steps per run")
    ap.add_argument("--no-exact", action="store_true", help="skip the offline exact optimum")
    ap.add_argument("--horizon-s", type=float, default=None, help="the look-ahead [s] (default 5; 1: the paper's)")
    ap.add_argument("--coarse-dt", type=float, default=None, help="length of the coarse steps [s] (default 0.5)")
    ap.add_argument("--no-rss", action="store_true", help="without RSS's terminal distance")
    a = ap.parse_args()
    look = {"horizon_s": a.horizon_s, "coarse_dt": a.coarse_dt, "rss": not a.no_rss}
    print(f"look-ahead: {MPCSettings(**look).steps} s, RSS terminal {'off' if a.no_rss else 'on'}")
    import clarabel
    import highspy  # noqa: F401
    print(f"machine: {platform.machine()} {platform.processor() or ''} cpus={os.cpu_count()} | "
          f"{platform.system()} {platform.release()} | python {sys.version.split()[0]} | numpy {np.__version__} | "
          f"clarabel {getattr(clarabel, '__version__', '?')}")
    try:
        import pyscipopt  # noqa: F401
        print("pyscipopt installed: the SCIP cross-check is not implemented in this script")
    except ImportError:
        print("pyscipopt not installed: SCIP cross-check skipped")
    ns = (0, 6, 18) if a.quick else (0, 6, 12, 18, 30)
    steps = a.steps or (25 if a.quick else 60)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for n in ns:
            t0 = time.perf_counter()
            rec = run(n, steps, seed=n, tmp=tmp, exact=not a.no_exact, look=look)
            summarize(n, rec)
            print(f"  (run took {time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
