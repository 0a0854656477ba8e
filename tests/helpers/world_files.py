"""A small map and a scenario on it, as YAML text, and a writer: the loader tests' starting point
(each golden case edits one line of them)."""

from __future__ import annotations

import textwrap
from pathlib import Path

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
