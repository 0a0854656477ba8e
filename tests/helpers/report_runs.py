"""Hand-made run directories in the simulator's format (twolevel.sim.trace), for report tests.

A uniquely named module (not conftest) so that it imports unambiguously in a whole-suite run."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from twolevel.sim.trace import BASE_COLUMNS, TraceWriter

RULES = ("speed_limit", "stop_sign", "red_light", "collision")


def write_run(
    run_dir: Path,
    rows: Sequence[Mapping[str, Any]],
    *,
    rules: Sequence[str] = RULES,
    meta: Mapping[str, Any] | None = None,
    summary: Mapping[str, Any] | None = None,
    frames: Sequence[Mapping[str, Any]] | None = None,
    status: str = "complete",
    extra_columns: Sequence[str] | None = None,
) -> Path:
    """Write ``rows`` with the real TraceWriter (the base columns, ``extra_columns`` — by default
    the other keys of the first row but the ``rob_`` ones —, a ``rob_`` column per rule), then
    close with ``status``."""
    if extra_columns is None:
        extra_columns = [k for k in (rows[0] if rows else {}) if k not in BASE_COLUMNS and not k.startswith("rob_")]
    base = {
        "scenario": {"name": "traffic_rules", "file": "scenarios/traffic_rules.yaml", "hash": "sha256:abc123"},
        "rules": [{"name": r, "file": "rules/urban.stl", "hash": f"sha256:{i:06d}"} for i, r in enumerate(rules)],
        "settings": {"dt": 0.1, "H": 10, "r_near": 10.0, "controller": "twolevel", "monitor": True},
        "seed": 7,
        "versions": {"twolevel": "0.1.0", "numpy": np.__version__},
        "map_lines": [[[-20.0, -1.75], [400.0, -1.75]], [[-20.0, 1.75], [400.0, 1.75]], [[-20.0, 5.25], [400.0, 5.25]]],
    }
    base.update(meta or {})
    w = TraceWriter(run_dir, BASE_COLUMNS + tuple(extra_columns) + tuple(f"rob_{r}" for r in rules), base)
    for row in rows:
        w.write(row)
    w.close(status, summary if summary is not None else {"collisions": []})
    if frames is not None:
        with open(run_dir / "frames.jsonl", "w", encoding="utf-8") as fh:
            for f in frames:
                fh.write(json.dumps(f) + "\n")
    return run_dir


def traffic_rows(n: int = 300, *, dt: float = 0.1, seed: int = 0, slow: float = 1.0, violate: bool = False, collide: bool = False) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """A traffic_rules-like drive: cruise, speed-limit change, stop sign, red light, go on green.
    ``slow`` scales the step times (a slower controller); ``violate`` speeds through the limit;
    ``collide`` closes in on a stopped car until the boxes overlap."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    v_max = np.where(t < 10, 13.9, 8.3)
    v = np.minimum(v_max - 0.5, 10.0 + t)
    v = np.where((t > 11.2) & (t < 12.5), np.maximum(0.0, 8.0 - 6 * (t - 11.2)), v)
    v = np.where((t > 21.7) & (t < 26.0), 0.0, v)
    if violate:
        v = np.where((t > 15) & (t < 17), v_max + 1.5, v)
    x = np.cumsum(v * dt)
    light = np.where(t < 18, "none", np.where(t < 21, "yellow", np.where(t < 26, "red", "green")))
    lead_x = 60.0 if not collide else None
    rows, frames = [], []
    for k in range(n):
        other_x = lead_x if lead_x is not None else x[k] + max(-1.0, 12.0 - 0.12 * k)
        lat = 5.0 if lead_x is not None else 0.0  # a car parked at the kerb, or one ahead in the lane
        dx = other_x - x[k]
        dist = math.hypot(dx, lat)
        gap = math.hypot(max(abs(dx) - 4.22, 0.0), max(lat - 1.8, 0.0)) if (abs(dx) > 4.22 or lat > 1.8) else abs(dx) - 4.22
        step_high = float(rng.gamma(4.0, 0.8)) * slow
        step_low = float(rng.gamma(3.0, 0.5)) * slow
        decision = "mpc" if k % 37 else ("sampled" if k % 74 else "brake")
        rows.append({
            "t": t[k], "x": x[k], "y": 0.05 * math.sin(t[k]), "psi": 0.0, "v": v[k], "delta": 0.0, "gamma": 0.1,
            "decision": decision, "t_high_ms": step_high, "t_low_ms": step_low, "t_step_ms": step_high + step_low + 0.3,
            "n_near": int(abs(dist) < 10.0) + (k // 100), "min_dist": abs(dist), "min_gap": gap,
            "tracking_error": abs(0.05 * math.sin(t[k])) + 0.01 * (k % 7), "v_max": v_max[k], "light_state": light[k],
            "rob_speed_limit": v_max[k] + 0.5 - v[k], "rob_stop_sign": 1.0 if t[k] < 11 or t[k] > 13 else 0.2,
            "rob_red_light": 2.0, "rob_collision": gap - 1.0,
            "verification": "verified" if decision != "brake" else "failsafe",
            "ttr_s": (3.0 if decision == "mpc" else 0.0) if k % 5 == 0 else float("nan"),
            # criticality: only the car closing in (collide) is ahead in the lane, standing
            "dhw_m": gap if lat == 0.0 else math.inf, "thw_s": gap / v[k] if lat == 0.0 and v[k] > 0 else math.inf,
            "ttc_s": gap / v[k] if lat == 0.0 and v[k] > 0 else math.inf, "ttc_any_s": math.inf,
        })
        frames.append({
            "t": t[k], "ego": [x[k], 0.0, 0.0, 4.22, 1.8],
            "plan": [[x[k] + v[k] * dt * j, 0.0] for j in range(1, 11)],
            "others": [[other_x, lat, 0.0, 4.22, 1.8], [x[k] + 8.0, 3.5, 0.0, 4.22, 1.8]],
            "lights": [{"x": 250.0, "y": 2.5, "state": str(light[k]) if light[k] != "none" else "red"}],
        })
    return rows, frames
