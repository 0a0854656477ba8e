"""The road around a run, for its figures: the edges of every lane (the drivable area's
boundary), and along the ego's route position the route lane's edges and how far the road
reaches either side. Computed from the scenario the run names (its world), when it can be read."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Road", "road_of"]

MAX_SAMPLES = 300  # route positions the band is computed at (interpolated in between)


@dataclass(frozen=True)
class Road:
    """``edges``: lane edge polylines [[x, y], …]; ``t`` (N,) [s] with the route lane's half
    width ``lane`` and the road's reach ``left`` (> 0) and ``right`` (< 0) [m] at the ego's route
    position then; ``tolerance`` of the on_road criterion [m] (None when not judged)."""

    edges: list[list[list[float]]]
    t: np.ndarray
    lane: np.ndarray
    left: np.ndarray
    right: np.ndarray
    tolerance: float | None


def road_of(run: Any) -> tuple[Road | None, str | None]:
    """The :class:`Road` of a run (``RunData``), or None and why not (None when the run names no
    scenario or records no route position: a trace from elsewhere has no road to draw)."""
    from twolevel.verdict.drivable import lane_edges, road_band
    from twolevel.world.loader import load_scenario
    from twolevel.world.world import build_world

    path = (run.meta.get("scenario") or {}).get("path") if isinstance(run.meta.get("scenario"), dict) else None
    t, s = run.columns.get("t"), run.columns.get("s")
    if path is None or not isinstance(t, np.ndarray) or not isinstance(s, np.ndarray) or t.size == 0:
        return None, None  # nothing to draw them from (a trace from elsewhere): not a problem of the run
    scn, _ = load_scenario(path)
    if scn is None:
        return None, f"no road edges: the scenario {path} cannot be loaded"
    world = build_world(scn)
    s = np.clip(np.nan_to_num(s, nan=0.0), 0.0, world.route.length)
    pick = np.unique(np.linspace(0, t.size - 1, min(t.size, MAX_SAMPLES)).round().astype(int))
    left, right = road_band(world.lanes, world.route, s[pick])
    on_road = scn.spec.expect.on_road
    return Road(run.meta.get("road_edges") or lane_edges(world.lanes), t,
                0.5 * world.route.width_at(s), np.interp(t, t[pick], left), np.interp(t, t[pick], right),
                None if on_road is None else on_road.tolerance), None
