"""Traffic stepping speed: all participants of the safety (160) and scalability (121) scenarios.

Prints the time per step (median and p95 over 2000 steps) and the nearby counts seen by an ego
driving the route at its desired speed. The requirement: well under 1 ms per step for 160.
"""

from __future__ import annotations

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


if __name__ == "__main__":
    for scenario in ("safety", "scalability", "traffic_rules"):
        run(scenario)
