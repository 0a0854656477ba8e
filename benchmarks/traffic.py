"""Traffic stepping speed: all participants of the safety (160) and scalability (121) scenarios,
and the cost per vehicle with MOBIL lane changes on and off.

Prints the time per step (median and p95 over 2000 steps) and the nearby counts seen by an ego
driving the route at its desired speed. The requirement: well under 1 ms per step for 160.

Then, for IDM populations of N vehicles on the three-lane highway (maps/highway.yaml, 1.5 km,
18–28 m/s, an ego driving the middle lane among them), the median step time per vehicle [µs]
with MOBIL off and on side by side: the step is vectorised over vehicles (no per-vehicle Python
loops), so the cost per vehicle falls as N grows until the arrays dominate.

    python benchmarks/traffic.py [--steps K]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from twolevel.world.loader import load_scenario
from twolevel.world.traffic import EgoBox, nearby, step
from twolevel.world.world import build_world

ROOT = Path(__file__).resolve().parent.parent


def run(name: str, steps: int = 2000) -> None:
    scn, diags = load_scenario(ROOT / "scenarios" / f"{name}.yaml")
    assert scn is not None, diags
    w = build_world(scn)
    dt = w.settings.dt
    st = w.traffic0
    s_ego = float(w.route.local_coordinates(np.array([[w.ego.x, w.ego.y]]))[0][0])
    times, near = [], []
    for _ in range(steps):
        s_ego = min(s_ego + float(w.route.desired_speed_at(s_ego)) * dt, w.route.length)
        (ex, ey), eh = w.route.position(s_ego), float(w.route.heading_at(s_ego))
        ego = EgoBox(float(ex), float(ey), eh, float(w.route.desired_speed_at(s_ego)), w.ego.length)
        t = time.perf_counter()
        st = step(st, dt, lanes=w.lanes, parts=w.parts, limits=w.limits, lights=w.lights, stops=w.stops, ego=ego)
        times.append(time.perf_counter() - t)
        near.append(int(nearby(st, ex, ey, w.settings.r_near).sum()))
    ms = np.array(times) * 1e3
    print(f"{name:12s} N={len(w.parts.ids):4d}  step median {np.median(ms):.3f} ms  p95 {np.percentile(ms, 95):.3f} ms"
          f"  max nearby {max(near[:300])} (first 30 s, r_near={w.settings.r_near:g} m)  active at end {int(st.active.sum())}")


def _population(n: int, mobil: bool, tmp: Path) -> Path:
    """A highway scenario of ``n`` IDM vehicles spread over the three lanes, MOBIL on or off."""
    path = tmp / f"flow_{n}_{int(mobil)}.yaml"
    path.write_text(
        f"kind: scenario\nmap: {ROOT / 'maps' / 'highway.yaml'}\n"
        "ego: {start: {lane: middle, s: 50}, speed: 22}\n"
        "route: {start: {lane: middle, s: 50}, goal: {lane: middle, s: 1450}, stop_at_goal: false}\n"
        f"populations:\n  - {{id: flow, count: {n}, lanes: [right, middle, left], speed_range: [18, 28], min_gap: 2,"
        f" mobil: {'true' if mobil else 'false'}, idm: {{v0: 26}}}}\n"
        "run: {duration: 60, seed: 1}\n")
    return path


def per_vehicle(n: int, mobil: bool, steps: int, tmp: Path) -> tuple[float, int]:
    """Median step time per vehicle [µs] of ``n`` vehicles over ``steps`` steps, and how many lane
    changes began."""
    scn, diags = load_scenario(_population(n, mobil, tmp))
    assert scn is not None, diags
    w = build_world(scn)
    dt, st = w.settings.dt, w.traffic0
    times, changes = [], 0
    for k in range(steps):
        x = 50.0 + 22.0 * k * dt
        ego = EgoBox(x, 0.0, 0.0, 22.0, w.ego.length, w.ego.width, w.route.lanes)
        t = time.perf_counter()
        nxt = step(st, dt, lanes=w.lanes, parts=w.parts, limits=w.limits, lights=w.lights, stops=w.stops, ego=ego)
        times.append(time.perf_counter() - t)
        changes += int(((nxt.remembered.lc_from >= 0) & (st.remembered.lc_from < 0)).sum())
        st = nxt
    return float(np.median(times)) * 1e6 / len(w.parts.ids), changes


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=300, help="steps per population size (default 300)")
    args = ap.parse_args()
    for scenario in ("safety", "scalability", "traffic_rules"):
        run(scenario)
    print(f"\nper vehicle, median over {args.steps} steps [µs / vehicle / step]")
    print(f"{'N':>6s} {'MOBIL off':>10s} {'MOBIL on':>10s} {'on/off':>7s} {'lane changes':>13s}")
    with tempfile.TemporaryDirectory() as d:
        for n in (25, 100, 400):
            off, _ = per_vehicle(n, False, args.steps, Path(d))
            on, lc = per_vehicle(n, True, args.steps, Path(d))
            print(f"{n:6d} {off:10.2f} {on:10.2f} {on / off:7.2f} {lc:13d}")
