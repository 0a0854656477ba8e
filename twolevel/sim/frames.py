"""The animation's inputs: ``frames.jsonl`` (one JSON line per step, flushed as written) and the
map's lane centre lines for ``run.json`` (format: :mod:`twolevel.report.animation`)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from twolevel.files import create_output
from twolevel.sim.trace import FRAMES_FILE
from twolevel.world.traffic import GREEN, RED, YELLOW, TrafficState
from twolevel.world.world import World

__all__ = ["FRAMES_FILE", "FrameWriter", "map_lines", "light_positions"]

VIEW_RADIUS = 60.0  # [m] other vehicles drawn around the ego
_STATE_NAMES = {GREEN: "green", YELLOW: "yellow", RED: "red"}


def map_lines(world: World, spacing: float = 2.0, digits: int = 2) -> list[list[list[float]]]:
    """Every lane's centre line as a polyline subsampled about every ``spacing`` [m]."""
    out = []
    for lane in world.lanes.lanes:
        n = max(2, int(np.ceil(lane.length / spacing)) + 1)
        pts = lane.position(np.linspace(lane.s[0], lane.s[-1], n))
        out.append(np.round(pts, digits).tolist())
    return out


def light_positions(world: World) -> np.ndarray:
    """Stop-line positions (n, 2) [m] of the traffic lights."""
    if len(world.lights.ids) == 0:
        return np.zeros((0, 2))
    xy, _ = world.lanes.pose(world.lights.lane, world.lights.s)
    return xy


class FrameWriter:
    """Append one frame per step to ``frames.jsonl`` in the run directory."""

    def __init__(self, run_dir: str | os.PathLike[str], world: World) -> None:
        self._fh = open(create_output(Path(run_dir) / FRAMES_FILE), "w", encoding="utf-8")
        self._world = world
        self._lights = light_positions(world)

    def write(self, t: float, ego: Sequence[float], plan: np.ndarray | None, traffic: TrafficState) -> None:
        """One frame: ego (x, y, psi) [m, m, rad], the plan's positions (H+1, ≥2), the traffic."""
        w = self._world
        x, y, psi = (float(v) for v in ego[:3])
        near = np.flatnonzero(traffic.active & (np.hypot(traffic.x - x, traffic.y - y) <= VIEW_RADIUS))
        others = np.stack([traffic.x[near], traffic.y[near], traffic.psi[near], w.parts.length[near],
                           w.parts.width[near]], axis=1) if near.size else np.zeros((0, 5))
        states = w.lights.state_at(t) if len(self._lights) else np.zeros(0, int)
        frame: dict[str, Any] = {
            "t": round(t, 6),
            "ego": [round(x, 3), round(y, 3), round(psi, 4), w.ego.length, w.ego.width],
            "plan": np.round(plan[:, :2], 3).tolist() if plan is not None else [],
            "others": np.round(others, 3).tolist(),
            "lights": [{"x": round(float(p[0]), 2), "y": round(float(p[1]), 2), "state": _STATE_NAMES.get(int(s), "none")}
                       for p, s in zip(self._lights, states)],
        }
        self._fh.write(json.dumps(frame, separators=(",", ":")) + "\n")
        self._fh.flush()

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()
