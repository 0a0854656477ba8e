"""A small map and a scenario on it, as YAML text, a writer, and the world of a scenario file: the
loader tests' starting point (each golden case edits one line of them) and every test's way from a
scenario file to its world."""

from __future__ import annotations

import textwrap
from pathlib import Path

from twolevel.world.loader import load_scenario
from twolevel.world.world import World, build_world

MAP = """\
kind: map
name: tiny
roads:
  - id: main
    start: {x: 0, y: 0, heading: 0}
    segments:
      - line: 100
      - arc: {radius: 50, angle: 90}
    lanes:
      - {id: r, offset: -1.75, speed_limit: 13.9, successors: [next]}
      - {id: l, offset: 1.75, direction: backward}
  - id: next
    start: {x: 150, y: 50, heading: 90}
    segments:
      - line: 50
speed_limits:
  - {id: sl1, lane: r, s: 60, value: 8.3}
stop_signs:
  - {id: stop1, lane: r, s: 80}
traffic_lights:
  - id: tl1
    lane: next
    s: 30
    cycle: {green: 10, yellow: 3, red: 20}
"""

SCENARIO = """\
kind: scenario
map: map.yaml
ego:
  start: {lane: r, s: 5}
  speed: 5
route:
  start: {lane: r, s: 5}
  goal: {lane: next, s: 45}
participants:
  - {id: parked, behaviour: stationary, start: {lane: r, s: 60}}
rules: []
"""


def write(tmp: Path, name: str, text: str) -> Path:
    p = tmp / name
    p.write_text(textwrap.dedent(text))
    return p


def load_world(path: Path | str) -> World:
    """The world of the scenario file at ``path``, loaded and built for real (the loader's
    messages shown if it does not load)."""
    scn, diags = load_scenario(path)
    assert scn is not None, [d.message for d in diags]
    return build_world(scn)


def write_conflicting(tmp: Path, repo: Path) -> Path:
    """A scenario on the shipped highway whose rules contradict each other from the start (faster
    than 12.2 m/s within 0.5 s, never faster than 12 m/s), with the shipped speed limit beside
    them: no plan satisfies every rule."""
    (tmp / "fast.stl").write_text("input float v\ngo_fast = always[0.5:1] (v >= 12.2);\n")
    (tmp / "slow.stl").write_text("input float v\nstay_slow = always[0:1] (v <= 12);\n")
    return write(tmp, "s.yaml", f"""kind: scenario
map: {repo / 'maps/highway.yaml'}
ego: {{start: {{lane: middle, s: 20}}, speed: 11.0}}
route: {{start: {{lane: middle, s: 20}}, goal: {{lane: middle, s: 900}}}}
rules: [{tmp / 'fast.stl'}, {tmp / 'slow.stl'}, {repo / 'rules/speed_limit.stl'}]
""")
