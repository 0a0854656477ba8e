"""Small scenarios for the MPC and low-level tests, written to a temporary directory, and a closed loop on the
kinematic bicycle itself (the MPC's own model) with constant-velocity traffic."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.high_level.settings import MPCSettings
from twolevel.models import bicycle
from twolevel.stl.lint import load_ruleset
from twolevel.world.provided import PROVIDED_SIGNALS
from twolevel.world.world import World

from helpers.world_files import load_world

REPO = Path(__file__).resolve().parents[2]
MAPS = REPO / "maps"


def make_world(tmp: Path, map_name: str, ego: str, route: str, participants: str = "[]",
               extra: str = "", name: str = "t") -> World:
    text = f"""kind: scenario
name: {name}
map: {MAPS / map_name}
ego: {ego}
route: {route}
participants: {participants}
{extra}
run: {{duration: 10, seed: 0}}
"""
    p = tmp / f"{name}.yaml"
    p.write_text(text)
    return load_world(p)


def rules(tmp: Path, text: str, name: str = "r"):
    p = tmp / f"{name}.stl"
    p.write_text(text)
    rs, diags = load_ruleset(str(p), dt=0.1, provided_signals=PROVIDED_SIGNALS)
    assert rs is not None, [d.message for d in diags]
    return rs

def highway_world(tmp_path: Path, rules: str, participants: str = "", speed: float = 15.0):  # noqa: ANN201
    """The low level's test world: the highway, the ego in the middle lane at s = 20 m and
    ``speed`` [m/s], ``participants`` (YAML list items), and the rule file ``rules`` (text).
    Returns (world, ruleset)."""
    (tmp_path / "r.stl").write_text(rules)
    (tmp_path / "s.yaml").write_text(f"""
kind: scenario
name: unit
map: {MAPS / 'highway.yaml'}
ego: {{start: {{lane: middle, s: 20}}, speed: {speed}}}
route: {{start: {{lane: middle, s: 20}}, goal: {{lane: middle, s: 600}}, stop_at_goal: false}}
participants: [{participants}]
rules: [r.stl]
run: {{duration: 5, seed: 3}}
""")
    w = load_world(tmp_path / "s.yaml")
    rs, d = load_ruleset(str(tmp_path / "r.stl"), dt=0.1, provided_signals=PROVIDED_SIGNALS)
    assert rs is not None, [x.message for x in d]
    return w, rs


def controller(world: World, rulesets, **kw) -> HighLevelController:
    st = MPCSettings(H=10, dt=0.1, **{"time_limit": None, **kw})  # B&B to completion: deterministic
    return HighLevelController(world, rulesets, st)


def advance(traffic, dt: float):
    """Constant-velocity traffic (heading kept)."""
    return replace(traffic, t=traffic.t + dt, x=traffic.x + traffic.v * np.cos(traffic.psi) * dt,
                   y=traffic.y + traffic.v * np.sin(traffic.psi) * dt)


def closed_loop(ctrl: HighLevelController, world: World, steps: int, x0=None, history_names=()):
    """Run ``steps`` MPC steps on the kinematic model; returns (states (steps+1, 4), results, traffic list)."""
    e = world.ego
    x = np.array([e.x, e.y, e.psi, e.v]) if x0 is None else np.asarray(x0, float)
    traffic = world.traffic0
    xs, res, tr = [x], [], [traffic]
    dt = ctrl.settings.dt
    hist: dict[str, list[float]] = {k: [] for k in history_names}
    for k in range(steps):
        h = {n: np.asarray(v) for n, v in hist.items()} if history_names else None
        r = ctrl.solve(x, k * dt, traffic, h)
        res.append(r)
        if history_names:
            from twolevel.world.signals import signals_along
            sig = signals_along(world, None, {"x": np.array([x[0]]), "y": np.array([x[1]]), "psi": np.array([x[2]]),
                                              "v": np.array([x[3]])}, t0=k * dt)
            for n in history_names:
                hist[n].append(float(sig[n][0]))
        x = bicycle.step(x, r.controls[0], dt, ctrl.params)
        traffic = advance(traffic, dt)
        xs.append(x)
        tr.append(traffic)
    return np.array(xs), res, tr


INSTANCE_EGO = "{start: {lane: middle, s: 20}, speed: %.2f, desired_speed: 15.0}"
INSTANCE_ROUTE = "{start: {lane: middle, s: 20}, goal: {lane: middle, s: 900}, stop_at_goal: false}"
INSTANCE_RULES = ("input float e\ninput float v\nno_collision = always[0:1] collision_free(5);\n"
                  "on_road = always[0:1] ((e <= 4.5) and (e >= -4.5));\nspeed = always[0:1] (v <= 16);\n")
"""The ego, route and rules of :func:`random_instance`."""


def random_instance(tmp_path: Path, rng: np.random.Generator, i: int) -> World:
    """A random small highway instance: the ego in the middle lane, one to three constant-velocity
    vehicles, often a slow one just ahead (where the best plan changes lane)."""
    n = int(rng.integers(1, 4))
    parts = []
    for j in range(n):
        lane = ["middle", "left", "right"][int(rng.integers(0, 3))] if j else "middle"
        s = float(rng.uniform(28, 34)) if j == 0 else float(rng.uniform(22, 45))
        v = float(rng.uniform(0, 6)) if j == 0 else float(rng.uniform(5, 15))
        parts.append(f"{{id: v{j}, behaviour: constant_velocity, start: {{lane: {lane}, s: {s:.2f}}}, speed: {v:.2f}}}")
    return make_world(tmp_path, "highway.yaml", INSTANCE_EGO % float(rng.uniform(8, 15)), INSTANCE_ROUTE,
                      "[" + ", ".join(parts) + "]", extra="controller: {r_near: 60}", name=f"inst{i}")
