"""Worlds for the safety tests: the small maps and scenarios of ``tests/safety/worlds/`` loaded
with the real loader, and helpers to place participants and the ego."""

from __future__ import annotations

import functools
from dataclasses import replace
from pathlib import Path

import numpy as np

from twolevel.models import fourwheel as fw
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

from helpers.world_files import load_world

HERE = Path(__file__).resolve().parents[1] / "safety" / "worlds"
REPO = Path(__file__).resolve().parents[2]


@functools.lru_cache(maxsize=None)
def world(name: str) -> World:
    """The world of ``tests/safety/worlds/<name>.yaml`` (or a repository path), built once."""
    path = HERE / f"{name}.yaml" if not name.endswith(".yaml") else REPO / name
    return load_world(path)


def lane_index(w: World, lane: str) -> int:
    return next(ln.index for ln in w.lanes.lanes if ln.id == lane)


def place(w: World, traffic: TrafficState, pid: str, lane: str | None = None, s: float = 0.0,
          v: float | None = None, lateral: float = 0.0, xy: tuple[float, float, float] | None = None) -> TrafficState:
    """``traffic`` with participant ``pid`` on ``lane`` at ``s`` [m] (or at a free pose ``xy`` =
    (x, y, heading [rad])) and speed ``v`` [m/s]."""
    i = w.parts.ids.index(pid)
    arrays = {k: getattr(traffic, k).copy() for k in ("x", "y", "psi", "v", "lane", "s", "lateral")}
    if lane is not None:
        li = lane_index(w, lane)
        p, h = w.lanes.pose(np.array([li]), np.array([s]), np.array([lateral]))
        arrays["lane"][i], arrays["s"][i], arrays["lateral"][i] = li, s, lateral
        arrays["x"][i], arrays["y"][i], arrays["psi"][i] = p[0, 0], p[0, 1], h[0]
    elif xy is not None:
        arrays["lane"][i] = -1
        arrays["x"][i], arrays["y"][i], arrays["psi"][i] = xy
    if v is not None:
        arrays["v"][i] = v
    return replace(traffic, **arrays)


def ego_on(w: World, lane: str, s: float, v: float, lateral: float = 0.0) -> np.ndarray:
    """The ego's detailed state on ``lane`` at ``s`` [m], heading along it, rolling at ``v`` [m/s]."""
    li = lane_index(w, lane)
    p, h = w.lanes.pose(np.array([li]), np.array([s]), np.array([lateral]))
    return fw.initial_state(p[0, 0], p[0, 1], h[0], v)
