"""Adversarial but legal traffic: small scenarios whose other road users behave as badly as the
declared assumptions allow (:mod:`twolevel.world.assumptions`), for the property test "the ego
is never at fault" and its benchmark.

The world is a straight two-lane one-way road (lanes ``right`` and ``left``, 3.5 m, limit
``LIMIT``) with the ego on the right lane. Each other road user is an :class:`Adversary`, scripted
(waypoints every control step, :mod:`twolevel.world.traffic`):

* a **leader** ahead of the ego on its lane, or a car on the **left** lane (ahead or behind),
  with a piecewise-constant acceleration in [−8, 2] m/s² per second of the run (random braking
  down to the assumptions' a_max, and accelerating), never reversing, never faster than 1.2 × the
  limit; a car on the left lane may **change** into the ego's lane (over 2 s) — but only where
  that leaves the ego RSS's safe distance even if the ego drives as fast as it can (at most
  ``EGO_ACCEL`` m/s² up to the limit + 1 m/s), which is the duty of the one changing lanes the
  verifier counts on; a change that would not is dropped;
* a **walker** (declared a pedestrian) anywhere on or beside the road ahead, accelerating in a
  random direction each second at most 0.6 m/s², never faster than 2 m/s.

Followers on the ego's lane are left out: keeping RSS's distance behind the ego is theirs to do,
and a script cannot react to the ego. Units: m, s, m/s, m/s².
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Adversary", "LIMIT", "EGO_S", "EGO_ACCEL", "scenario_text", "random_adversaries"]

LIMIT = 15.0
"""[m/s] The road's speed limit."""
EGO_S = 30.0
"""[m] The ego's start along the right lane."""
EGO_ACCEL = 4.0
"""[m/s²] Bound on the ego's acceleration used to place cut-ins legally."""
_DT = 0.1
_LANE_Y = {"right": -1.75, "left": 1.75}
_LENGTH = 4.22
_MAP = """kind: map
name: two_lanes
default_speed_limit: {limit}
roads:
  - id: road
    start: {{x: 0, y: 0, heading: 0}}
    segments: [{{line: 600}}]
    lanes:
      - {{id: right, offset: -1.75}}
      - {{id: left, offset: 1.75}}
"""


@dataclass(frozen=True)
class Adversary:
    """One other road user: ``role`` (``leader``, ``left`` or ``walker``); where it starts,
    ``ahead`` [m] of the ego's centre along the road (a walker: also ``y`` [m] across it); its
    speed ``v0`` [m/s]; ``accels``: the acceleration [m/s²] in each second of the run (a
    walker's: its size, with ``headings`` [rad] its direction); ``change_at`` [s]: when a car on
    the left lane starts changing into the ego's lane (None: never)."""

    role: str
    ahead: float
    v0: float
    accels: tuple[float, ...]
    y: float = 0.0
    headings: tuple[float, ...] = ()
    change_at: float | None = None


def _ego_front_max(t: float, v0: float) -> tuple[float, float]:
    """The farthest the ego's centre can be along the road at ``t`` [s] and its speed then."""
    v_top = max(v0, LIMIT + 1.0)
    t_acc = (v_top - v0) / EGO_ACCEL
    ta = min(t, t_acc)
    s = v0 * ta + 0.5 * EGO_ACCEL * ta**2 + v_top * max(t - t_acc, 0.0)
    return EGO_S + s, v0 + EGO_ACCEL * ta


def _car(a: Adversary, duration: float, ego_v0: float) -> list[tuple[float, float, float]]:
    """A car's waypoints (t, x, y), its lane change kept only where legal."""
    cap = 1.2 * LIMIT
    n = int(round(duration / _DT)) + 10
    x, v = EGO_S + a.ahead, max(a.v0, 0.0)
    y0 = _LANE_Y["right" if a.role == "leader" else "left"]
    change = a.change_at if a.role == "left" else None
    xs, vs = [x], [v]
    for k in range(n):
        acc = a.accels[min(int(k * _DT), len(a.accels) - 1)] if a.accels else 0.0
        acc = min(acc, 8.0 * 7.319 / max(v, 1e-9))  # the power limit above v_switch
        v_new = min(max(v + acc * _DT, 0.0), cap)
        x += v * _DT
        v = v_new
        xs.append(x)
        vs.append(v)
    if change is not None:  # legal only if the gap when its centre crosses into the ego's lane is safe
        k_mid = int(round((change + 1.0) / _DT))
        if k_mid >= len(xs):
            change = None
        else:
            e_x, e_v = _ego_front_max(k_mid * _DT, ego_v0)
            gap = xs[k_mid] - e_x - _LENGTH
            safe = e_v * _DT + e_v**2 / (2 * 4.0) - vs[k_mid] ** 2 / (2 * 8.0) + 1.0
            if gap < safe:
                change = None
    out = []
    for k, xk in enumerate(xs):
        t = k * _DT
        y = y0
        if change is not None and t > change:
            f = min((t - change) / 2.0, 1.0)
            y = y0 + (_LANE_Y["right"] - y0) * 0.5 * (1 - math.cos(math.pi * f))
        out.append((round(t, 3), round(xk, 4), round(y, 4)))
    return out


def _walker(a: Adversary, duration: float) -> list[tuple[float, float, float]]:
    """A pedestrian's waypoints (t, x, y) within 2 m/s and 0.6 m/s²."""
    n = int(round(duration / _DT)) + 10
    x, y = EGO_S + a.ahead, a.y
    h0 = a.headings[0] if a.headings else 0.0
    vx, vy = a.v0 * math.cos(h0), a.v0 * math.sin(h0)
    out = [(0.0, round(x, 4), round(y, 4))]
    for k in range(n):
        j = min(int(k * _DT), len(a.accels) - 1)
        size = min(abs(a.accels[j]), 0.6) if a.accels else 0.0
        h = a.headings[min(j, len(a.headings) - 1)] if a.headings else 0.0
        nvx, nvy = vx + size * math.cos(h) * _DT, vy + size * math.sin(h) * _DT
        speed = math.hypot(nvx, nvy)
        if speed > 2.0:
            nvx, nvy = nvx * 2.0 / speed, nvy * 2.0 / speed
        x, y = x + vx * _DT, y + vy * _DT
        vx, vy = nvx, nvy
        out.append((round((k + 1) * _DT, 3), round(x, 4), round(y, 4)))
    return out


def scenario_text(folder: Path, others: list[Adversary], ego_v0: float, duration: float, name: str = "adversaries"
                  ) -> Path:
    """Write the two-lane road and the scenario with the ego at ``ego_v0`` [m/s] (the reckless
    planner's work: no rule files) and ``others`` for ``duration`` [s] into ``folder``; the
    scenario's path."""
    (folder / "two_lanes.yaml").write_text(_MAP.format(limit=LIMIT), encoding="utf-8")
    parts, walkers = [], []
    for i, a in enumerate(others):
        pid = f"{a.role}_{i}"
        if a.role == "walker":
            wp = _walker(a, duration)
            walkers.append(pid)
            box = "\n    box: {length: 0.5, width: 0.5}"
        else:
            wp = _car(a, duration, ego_v0)
            box = ""
        v0 = math.hypot(wp[1][1] - wp[0][1], wp[1][2] - wp[0][2]) / _DT
        pts = "\n".join(f"      - {{t: {t:g}, x: {x:g}, y: {y:g}}}" for t, x, y in wp)
        parts.append(f"  - id: {pid}\n    behaviour: scripted\n    speed: {v0:.4f}{box}\n    waypoints:\n{pts}")
    users = ", ".join(f"{w}: pedestrian" for w in walkers)
    text = f"""kind: scenario
name: {name}
map: two_lanes.yaml
ego: {{start: {{lane: right, s: {EGO_S}}}, speed: {ego_v0}}}
route: {{start: {{lane: right, s: {EGO_S}}}, goal: {{lane: right, s: 580}}, stop_at_goal: false}}
participants:
{chr(10).join(parts) if parts else "  []"}
assumptions:
  road_users: {{{users}}}
run: {{duration: {duration}, seed: 0}}
"""
    path = folder / f"{name}.yaml"
    path.write_text(text.replace("participants:\n  []", "participants: []"), encoding="utf-8")
    return path


def random_adversaries(rng, count: int, seconds: int) -> list[Adversary]:  # noqa: ANN001 - numpy Generator
    """``count`` adversaries drawn with ``rng`` (a numpy Generator) for ``seconds`` [s]."""
    out = []
    for _ in range(count):
        role = str(rng.choice(["leader", "left", "walker"]))
        accels = tuple(float(a) for a in rng.uniform(-8.0, 2.0, seconds))
        if role == "walker":
            out.append(Adversary(role, float(rng.uniform(10, 80)), float(rng.uniform(0, 2)),
                                 tuple(float(a) for a in rng.uniform(0, 0.6, seconds)), float(rng.uniform(-8, 8)),
                                 tuple(float(h) for h in rng.uniform(-math.pi, math.pi, seconds))))
        elif role == "leader":
            out.append(Adversary(role, float(rng.uniform(8, 70)), float(rng.uniform(0, 18)), accels))
        else:
            change = float(rng.uniform(0, seconds)) if rng.random() < 0.6 else None
            out.append(Adversary(role, float(rng.uniform(-30, 70)), float(rng.uniform(0, 18)), accels,
                                 change_at=change))
    return out
