"""Small real worlds for the traffic tests: maps as YAML text, a scenario written around a list of
participants, and a runner that steps the traffic (with an ego that is a fixed box, a function of
time, or absent) and keeps every state."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from twolevel.world.traffic import EgoBox, TrafficState, step
from twolevel.world.world import World

from helpers.world_files import load_world

TWO_LANES = """\
kind: map
default_speed_limit: 30
roads:
  - id: road
    segments: [{line: 1500}]
    lanes:
      - {id: r, offset: 0}
      - {id: l, offset: 3.5}
"""
"""A straight one-way road, 1.5 km: lane r (y = 0) and lane l to its left (y = 3.5)."""

ONE_LANE = """\
kind: map
default_speed_limit: 30
roads:
  - id: road
    segments: [{line: 1500}]
"""
"""A single lane 'road' along y = 0."""

CROSSING = """\
kind: map
default_speed_limit: 14
roads:
  - id: main
    start: {x: 0, y: 0, heading: 0}
    segments: [{line: 300}]
    lanes:
      - {id: e, offset: -1.75}
      - {id: w, offset: 1.75, direction: backward}
  - id: side
    start: {x: 150, y: -150, heading: 90}
    segments: [{line: 300}]
    lanes:
      - {id: n, offset: -1.75}
      - {id: s, offset: 1.75, direction: backward}
stop_signs:
  - {id: stop_n, lane: n, s: 145, stop_time: 1.0}
"""
"""A two-way main road (e eastwards along y = −1.75, w westwards) crossed at x = 150 by a two-way
side road (n northwards along x = 151.75) with a stop sign 145 m up lane n (y = −5)."""


def world(tmp: Path, map_text: str, body: str, ego_lane: str = "r", goal: float = 1400.0) -> World:
    """The world of a scenario on ``map_text`` whose ego starts on ``ego_lane`` at s = 0;
    ``body`` is the rest of the scenario (participants, assumptions, ...)."""
    (tmp / "map.yaml").write_text(map_text)
    (tmp / "scn.yaml").write_text(
        f"kind: scenario\nmap: map.yaml\nego: {{start: {{lane: {ego_lane}, s: 0}}}}\n"
        f"route: {{start: {{lane: {ego_lane}, s: 0}}, goal: {{lane: {ego_lane}, s: {goal}}}}}\n" + body)
    return load_world(tmp / "scn.yaml")


Ego = EgoBox | Callable[[float], EgoBox] | None


def run(w: World, seconds: float, ego: Ego = None) -> list[TrafficState]:
    """Every traffic state from t = 0 over ``seconds`` [s]; ``ego`` a box, a box by time, or none."""
    st, out = w.traffic0, [w.traffic0]
    for _ in range(int(round(seconds / w.settings.dt))):
        box = ego(st.t) if callable(ego) else ego
        st = step(st, w.settings.dt, lanes=w.lanes, parts=w.parts, limits=w.limits, lights=w.lights, stops=w.stops,
                  ego=box)
        out.append(st)
    return out


def replay(w: World, trace: Path) -> tuple[list[TrafficState], list[dict[str, float]]]:
    """The traffic of a simulated run, stepped again against the ego of its ``trace.csv`` (as the
    closed loop steps it: each step sees the ego at the step's start), and the trace's rows."""
    import csv

    with open(trace, newline="") as f:
        rows = [{k: float(r[k]) for k in ("t", "x", "y", "psi", "v")} for r in csv.DictReader(f)]
    e = w.ego
    boxes = [EgoBox(r["x"], r["y"], r["psi"], r["v"], e.length, e.width, w.route.lanes) for r in rows]
    return run(w, len(rows) * w.settings.dt, ego=lambda t: boxes[min(int(round(t / w.settings.dt)), len(boxes) - 1)]), rows
