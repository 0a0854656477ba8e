"""Closed-loop runs through a junction under rules/right_of_way.stl, read back for the tests: the
trace's columns (the run judged against its own ``expect:``, and ``twolevel monitor`` agreeing
with the run's own ``rob_`` columns), and the checks such runs share — no car with priority
within the margin while the ego is inside its conflict area, the ego never standing inside it,
nor in any lane its route conflicts with (by the ego's box on the map's lanes)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.monitor.tracefile import read_trace
from twolevel.world.loader import load_scenario
from twolevel.world.world import build_world

from helpers.judged_runs import judged_run

ROOT = Path(__file__).resolve().parents[2]


def monitored(trace_csv: Path, c: dict[str, np.ndarray]) -> None:
    """``twolevel monitor rules/right_of_way.stl`` on the trace: both rules hold at every sample,
    and its robustness series are the run's own ``rob_`` columns."""
    r = CliRunner().invoke(app, ["monitor", str(ROOT / "rules" / "right_of_way.stl"), str(trace_csv),
                                 "--format", "json", "--series"])
    assert r.exit_code == 0, r.output
    for rule in json.loads(r.output)["rules"]:
        series = np.array([np.inf if v == "inf" else v for v in rule["series"]], dtype=float)
        np.testing.assert_allclose(series, c[f"rob_{rule['name']}"], rtol=1e-6, atol=1e-6)


def junction_run(path: Path, out: Path, **options: Any) -> dict[str, np.ndarray]:
    """Scenario ``path`` run into ``out`` (``options`` to :func:`judged_run`: e.g. the controller)
    and judged (goal, no collision at fault, its ``expect:``); its trace's columns and times
    (``t``), the monitor agreeing with them."""
    run_dir = judged_run(path, out, **options)
    trace, _ = read_trace(str(run_dir / "trace.csv"))
    assert trace is not None
    c = {k: np.asarray(v, float) for k, v in trace.columns.items()}
    c["t"] = np.asarray(trace.t, float)
    monitored(run_dir / "trace.csv", c)
    return c


def check_gaps(c: dict[str, np.ndarray], margin: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """No priority car within the margin [s] while the ego is inside its conflict area, and the
    ego never standing inside; returns (inside, waiting): the samples inside, and those standing
    within 6 m before the area."""
    inside = (c["d_zone"] <= 0) & (c["d_zone_out"] > 0)
    for key in [k for k in c if k.startswith("priority[")]:
        pid = key[len("priority["):-1]
        close = (c[key] > 0.5) & (c[f"t_reach[{pid}]"] < margin)
        assert not (inside & close).any(), pid
    waiting = (c["v"] < 0.3) & (c["d_zone"] > 0) & (c["d_zone"] < 6.0)
    assert not (inside & (c["v"] < 0.3) & (c["a"] < 0.5)).any()  # never stood in the junction
    return inside, waiting


def standing_in_conflicting_lanes(path: Path, c: dict[str, np.ndarray], speed: float = 0.3) -> np.ndarray:
    """The samples at which the ego stands (speed below ``speed`` [m/s]) with any part of its box
    on a lane its route conflicts with at a junction (the other connecting lanes of each conflict
    and the lanes leading into them): points 1 m apart or closer over its box, each within a
    lane's half width of its centre line and within its length."""
    w = build_world(load_scenario(path)[0])
    lanes = np.unique(w.zones.lane)
    assert len(lanes), "the route crosses no conflict"
    hl, hw = 0.5 * float(w.ego.length), 0.5 * float(w.ego.width)
    along = np.linspace(-hl, hl, int(np.ceil(2 * hl)) + 1)
    across = np.linspace(-hw, hw, int(np.ceil(2 * hw)) + 1)
    u, v = (g.ravel() for g in np.meshgrid(along, across))  # (P,) box coordinates [m]
    stand = np.flatnonzero(c["v"] < speed)
    cos, sin = np.cos(c["psi"][stand])[:, None], np.sin(c["psi"][stand])[:, None]
    pts = np.stack([c["x"][stand][:, None] + cos * u - sin * v, c["y"][stand][:, None] + sin * u + cos * v], axis=-1)
    flat = pts.reshape(-1, 2)
    hit = np.zeros(len(flat), dtype=bool)
    for lane in lanes:
        s, lat = w.lanes.project(np.full(len(flat), lane), flat)
        s_in = np.clip(s, 0.0, w.lanes.length[lane])
        hit |= (np.abs(lat) <= 0.5 * w.lanes.width_at(np.full(len(flat), lane), s_in)) & (s >= 0) & (s <= w.lanes.length[lane])
    out = np.zeros(len(c["v"]), dtype=bool)
    out[stand] = hit.reshape(len(stand), -1).any(axis=1)
    return out
