"""Guards every MPC plan obeys besides the rules: where it may stop, and where it may drive.

One definition, used by both planners (the MILP MPC of :mod:`twolevel.control.high_level`
and the NMPC baseline of :mod:`twolevel.control.nmpc`):

* :func:`stop_lines` — the stop line the plan must keep behind at each step of the horizon: the
  stop sign's line while it applies (not yet served, within r_near; the world's definition in
  :mod:`twolevel.world.signals`), and a traffic light's line at the steps where the light is red.
* **Can still stop** at the end of the horizon (recursive feasibility): with d_H = s_line − s_H
  − margin the distance left after the last step and b a comfortable deceleration, the exact
  condition is v_H² ≤ 2·b·d_H (the NMPC writes it so). The MILP needs it linear:
  :func:`can_stop_slope` gives the chord k = sqrt(2·b·D)/D of sqrt(2·b·d) over [0, D], and
  v_H ≤ k·d_H implies v_H² ≤ 2·b·d_H for 0 ≤ d_H ≤ D. D is the distance from which a line
  applies (r_near), so d_H ≤ D holds. The set {v ≤ k·d} is kept by braking at up to 2·b, so a
  plan that meets it leaves the next step a plan that meets it too.
  :func:`terminal_stop` adds, when even full braking from now cannot meet the chord (a line first
  seen too close at speed), the constant by which full braking misses it, so the step stays
  feasible and the plan brakes as hard as it must.
* :func:`drivable_band` — the lateral offsets from the route [m] the ego's reference point may
  take: the lanes beside the route's lane that run the same way, less half the ego's width.
  Sideways motion is never progress (the linearised route progress s_k would otherwise reward a
  swerve that shortens it when a stop line is near).

Units: m, m/s, m/s².
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from twolevel.world.signals import HorizonConstants
from twolevel.world.world import World

__all__ = ["stop_lines", "can_stop_slope", "TerminalStop", "terminal_stop", "drivable_band"]


def stop_lines(hc: HorizonConstants, *, stop: bool, light: bool) -> np.ndarray:
    """Route position [m] of the line the ego must stay behind at each step k = 0..H (+inf: none):
    the stop sign's line that applies (``stop``: a rule reads d_stop) and the light's line while
    it is red (``light``: a rule reads light_red or d_light)."""
    n = len(hc.t)
    out = np.full(n, np.inf)
    if stop and math.isfinite(hc.s_stop):
        out[:] = hc.s_stop
    if light and math.isfinite(hc.s_light):
        out = np.where(hc.light_red > 0.5, np.minimum(out, hc.s_light), out)
    return out


def can_stop_slope(decel: float, reach: float) -> float:
    """The chord slope k [1/s] of sqrt(2·decel·d) over d ∈ [0, reach]: v ≤ k·d ⇒ v² ≤ 2·decel·d."""
    reach = max(float(reach), 1e-3)
    return math.sqrt(2.0 * decel * reach) / reach


@dataclass(frozen=True)
class TerminalStop:
    """The linear terminal condition v_H ≤ slope·(s_line − margin − s_H) + offset, or inactive
    (``slope`` = 0). ``s_line`` [m], ``margin`` [m], ``slope`` [1/s], ``offset`` [m/s]."""

    s_line: float = math.inf
    margin: float = 0.0
    slope: float = 0.0
    offset: float = 0.0

    @property
    def active(self) -> bool:
        return self.slope > 0.0


def terminal_stop(s_line: float, s_brake: float, v_brake: float, *, decel: float, reach: float,
                  margin: float) -> TerminalStop:
    """The terminal condition for a line at ``s_line`` [m] (+inf: none). ``s_brake`` [m] and
    ``v_brake`` [m/s]: where full braking from now is at the end of the horizon (as the plan's
    route progress reads it). Inactive when there is no line or full braking cannot stop before
    it (the rules themselves decide then); otherwise relaxed by what full braking misses."""
    if not math.isfinite(s_line) or s_brake > s_line + 1e-6:
        return TerminalStop()
    k = can_stop_slope(decel, reach)
    miss = v_brake - k * (s_line - margin - s_brake)
    return TerminalStop(float(s_line), float(margin), k, max(0.0, float(miss)) + (0.05 if miss > -0.05 else 0.0))


_BANDS: "weakref.WeakKeyDictionary[object, tuple[np.ndarray, np.ndarray, np.ndarray]]" = weakref.WeakKeyDictionary()


def _band_table(world: World, spacing: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s, lo, hi) on a coarse grid along the route, computed once per world."""
    hit = _BANDS.get(world.route)
    if hit is not None:
        return hit
    route = world.route
    s = np.arange(0.0, float(route.s[-1]) + spacing, spacing)
    w = route.width_at(s)
    head = route.heading_at(s)
    half = 0.5 * world.ego.width
    lo, hi = -w / 2 + half, w / 2 - half
    for side in (1.0, -1.0):
        alive = np.ones(len(s), bool)
        for j in (1, 2, 3):
            pts = route.position(s, side * j * w)
            chunks = [world.lanes.lookup(pts[i:i + 64], head[i:i + 64])[0] for i in range(0, len(s), 64)]
            lane = np.concatenate(chunks) if chunks else np.zeros(0, int)
            alive &= lane >= 0
            if side > 0:
                hi = np.where(alive, w / 2 + j * w - half, hi)
            else:
                lo = np.where(alive, -w / 2 - j * w + half, lo)
            if not alive.any():
                break
    out = (s, lo, hi)
    _BANDS[world.route] = out
    return out


def drivable_band(world: World, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lateral bounds (lo, hi) [m] (+ left) for the ego's reference point at route positions
    ``s`` [m]: the route's lane and the adjacent lanes heading the same way, less half the ego's
    width (the tighter of the two neighbouring grid points)."""
    grid, lo, hi = _band_table(world)
    i = np.clip(np.searchsorted(grid, np.asarray(s, float)), 1, len(grid) - 1)
    return np.maximum(lo[i - 1], lo[i]), np.minimum(hi[i - 1], hi[i])
