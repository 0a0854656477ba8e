"""Guards every MPC plan obeys besides the rules: where it may stop, and where it may drive.

One definition, used by both planners (the MILP MPC of :mod:`twolevel.control.high_level`
and the NMPC baseline of :mod:`twolevel.control.nmpc`; RSS's distance and passes by the MPC only,
at the end of its look-ahead, :mod:`twolevel.control.high_level.settings`):

* :func:`stop_lines` — the stop line the plan must keep behind at each step of the horizon: the
  stop sign's line while it applies (not yet served, within r_near; the world's definition in
  :mod:`twolevel.world.signals`), a traffic light's line at the steps where the light is red, and
  a marked crosswalk's line while it is busy (:mod:`twolevel.world.crosswalks`).
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
  take: the usable lanes beside the route's lane that run the same way, less half the ego's width.
  Sideways motion is never progress (the linearised route progress s_k would otherwise reward a
  swerve that shortens it when a stop line is near).
* :func:`rss_terminal` — **can stop behind the vehicle ahead**, whatever it does within the
  assumptions, at the end of the look-ahead (step N): the gap to the vehicle ahead in the ego's
  lane within the sensing range is at least RSS's safe distance
  (:func:`twolevel.world.assumptions.safe_distance`, the ego as the rear car: its response
  time and braking, the assumed maximum braking of the vehicle ahead) plus a margin — *or* the
  ego is beside it from :data:`BESIDE_FROM` on, in a lane of the drivable band where it keeps
  RSS's distance to the vehicles sensed in that lane (:func:`free_sides`; RSS's lateral safety:
  passing stays possible, and cannot be put off). The gap is s_ahead,N − s_0 − (distance travelled) − (L_ego + L_ahead)/2, as for the
  terminal stop (sideways motion does not shorten the distance travelled). RSS's distance is
  convex in v_N, so it lies below each of its chords over the interval the chord spans: K rows,
  one per chord over [v_lo, v̄ − w], [v̄ − w, v̄ + w], [v̄ + w, v_hi] (v̄ the linearisation's
  speed, [v_lo, v_hi] every speed the step can reach), require the gap above the chords'
  maximum — a conservative bound, exact to (2w)²/(8·brake) near v̄. When even full braking from
  now misses a row (a cut-in), the row is relaxed by the miss, so the plan brakes as hard as it
  must. The same chord over one fine step's [v_lo, v_hi] gives its ``rss_gap`` signal
  (:mod:`twolevel.control.high_level.problem`).

Units: m, m/s, m/s².
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Callable

import numpy as np

from twolevel.world.assumptions import ResponseBounds, safe_distance
from twolevel.world.signals import HorizonConstants
from twolevel.world.world import World

__all__ = ["stop_lines", "stop_lines_read", "STOP_LINE_SIGNALS", "can_stop_slope", "TerminalStop", "terminal_stop",
           "drivable_band", "RssTerminal", "rss_terminal", "free_sides", "beside_steps", "BESIDE_FROM", "Pass", "Front",
           "front_of", "chord", "CHORD_HALF_WIDTH"]

CHORD_HALF_WIDTH = 0.5
"""[m/s] w: half the width of the chord of RSS's distance around the linearisation's speed."""

BESIDE_FROM = 2.0
"""[s] A plan that passes the vehicle ahead is beside it (in the next lane) from this long after
the first plan that chose to pass, and keeps to that time and side while it passes (the
controller carries them, :class:`Pass`): a pass cannot be
put off from step to step (a "beside" that each plan may reach later can always be reached by a
swerve in its coarse part, and the car drives on at the vehicle ahead). 2 s leave room for a
lane change at the bicycle's lateral acceleration limit."""


STOP_LINE_SIGNALS: tuple[frozenset[str], frozenset[str], frozenset[str]] = (
    frozenset({"d_stop"}), frozenset({"light_red", "d_light"}), frozenset({"xwalk_busy", "d_xwalk"}))
"""The signals whose rules make a line the plan stops at: a stop sign's, a red light's, a busy
crosswalk's (:func:`stop_lines`' ``stop``, ``light`` and ``xwalk``)."""


def stop_lines_read(reads: set[str] | frozenset[str]) -> tuple[bool, bool, bool]:
    """Which lines a rule reading the signals ``reads`` makes the plan stop at: (stop sign, red
    light, busy crosswalk), the flags of :func:`stop_lines`."""
    stop, light, xwalk = (bool(names & reads) for names in STOP_LINE_SIGNALS)
    return stop, light, xwalk


def stop_lines(hc: HorizonConstants, *, stop: bool, light: bool, xwalk: bool = False) -> np.ndarray:
    """Route position [m] of the line the ego must stay behind at each step k = 0..H (+inf: none):
    the stop sign's line that applies (``stop``: a rule reads d_stop), the light's line while
    it is red (``light``: a rule reads light_red or d_light) and a crosswalk's line while it is
    busy (``xwalk``: a rule reads xwalk_busy or d_xwalk)."""
    n = len(hc.t)
    out = np.full(n, np.inf)
    if stop and math.isfinite(hc.s_stop):
        out[:] = hc.s_stop
    if light and math.isfinite(hc.s_light):
        out = np.where(hc.light_red > 0.5, np.minimum(out, hc.s_light), out)
    if xwalk and math.isfinite(hc.s_xwalk):
        out = np.where(hc.xwalk_busy > 0.5, np.minimum(out, hc.s_xwalk), out)
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
            alive &= (lane >= 0) & world.lanes.usable[np.maximum(lane, 0)]  # no parking lane, no sidewalk
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
    ``s`` [m]: the route's lane and the adjacent usable lanes heading the same way (driving lanes
    and those the map declares usable: not a parking lane), less half the ego's width (the tighter
    of the two neighbouring grid points)."""
    grid, lo, hi = _band_table(world)
    i = np.clip(np.searchsorted(grid, np.asarray(s, float)), 1, len(grid) - 1)
    return np.maximum(lo[i - 1], lo[i]), np.minimum(hi[i - 1], hi[i])


def chord(f: "Callable[[np.ndarray], np.ndarray]", a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slope and intercept of the chords of ``f`` over [a, b] (elementwise; b at least a + 1e-3):
    above a convex ``f`` everywhere on [a, b]."""
    b = np.maximum(b, a + 1e-3)
    fa, fb = f(a), f(b)
    slope = (fb - fa) / (b - a)
    return slope, fa - slope * a


@dataclass(frozen=True)
class Front:
    """The vehicle the RSS terminal is about: participant ``index``, predicted route positions
    ``s`` (N+1,) [m] over the look-ahead, speed ``v`` [m/s] along the route, lateral offset ``e``
    [m], ``offset`` [m] = (L_ego + L)/2 and ``width`` [m]."""

    index: int
    s: np.ndarray
    v: float
    e: float
    offset: float
    width: float


@dataclass(frozen=True)
class Pass:
    """A pass of a vehicle ahead under way: of participant ``vehicle``, due beside it at time
    ``by`` [s], on ``side`` (1: left, 2: right, the RSS terminal disjunct the first plan of the
    pass chose), in the lane at lateral offset ``lane`` [m] (the reference's while it passes)."""

    by: float
    side: int
    vehicle: int
    lane: float


def front_of(world: World, hc: HorizonConstants, passing: Pass | None, s0: float, dt: float,
             ticks: np.ndarray) -> Front | None:
    """The vehicle ahead for the RSS terminal from route position ``s0`` [m] over the look-ahead
    at times dt·``ticks`` [s]: the one a pass under way is passing while it is sensed and its
    rear is not yet D_safe behind the ego's front, else the vehicle ahead in the ego's lane
    (``hc.ahead``), else None."""
    if passing is not None:
        j = np.flatnonzero(hc.seen == passing.vehicle)
        if len(j):
            j = int(j[0])
            offset = (world.ego.length + float(world.parts.length[passing.vehicle])) / 2
            if hc.seen_s[j] + offset + world.settings.D_safe > s0:
                return Front(passing.vehicle, hc.seen_s[j] + hc.seen_v[j] * dt * ticks, float(hc.seen_v[j]),
                             float(hc.seen_e[j]), offset, float(world.parts.width[passing.vehicle]))
    if hc.ahead < 0:
        return None
    return Front(hc.ahead, hc.s_ahead, hc.v_ahead, hc.e_ahead, hc.ahead_offset, float(world.parts.width[hc.ahead]))


def beside_steps(times: np.ndarray, by: float | None = None) -> np.ndarray:
    """The steps k (1..N) at whose times ``times`` (N+1,) [s] from now being beside the vehicle
    ahead is required of a plan that passes it: from ``by`` [s] on (the time a pass already
    planned is due; None: a new pass, due in :data:`BESIDE_FROM`), and at least the last step."""
    t = np.asarray(times)[1:]
    due = BESIDE_FROM if by is None else by
    return np.flatnonzero(t >= min(due, float(t[-1])) - 1e-9) + 1


def free_sides(world: World, hc: HorizonConstants, front: Front, *, lateral: float, band: tuple[float, float],
               s: np.ndarray, v: np.ndarray, t: np.ndarray) -> tuple[bool, bool]:
    """Whether the ego may pass the vehicle ``front`` on the left and on the right: that offset
    ``lateral`` [m] from its lies in the drivable ``band`` (lo, hi) [m], and at the times ``t``
    (J,) [s] it would be beside it (:func:`beside_steps`), where the ego would then be (route
    positions ``s`` (J,) [m], speeds ``v`` (J,) [m/s]), it keeps RSS's distance to every other
    vehicle sensed in that lane, predicted at constant speed — behind one ahead of it (the ego's
    response, ``world.settings.response``) and ahead of one behind it (the others' response,
    ``world.assumptions.response``: whoever changes lanes leaves the follower its distance).
    Vehicles beyond the sensing range are unknown: the check is as good as it."""
    width = float(world.route.width_at(s[0]))
    out = []
    for side in (1.0, -1.0):
        e_side = front.e + side * width
        if not band[0] <= front.e + side * lateral <= band[1]:
            out.append(False)
            continue
        there = (np.abs(hc.seen_e - e_side) < width / 2) & (hc.seen_v > 0) & (hc.seen != front.index)
        v_j = hc.seen_v[there][:, None]
        s_j = hc.seen_s[there][:, None] + v_j * t[None]  # (m, J)
        gap = np.abs(s_j - s[None]) - (world.ego.length + world.parts.length[hc.seen[there]][:, None]) / 2
        need = np.where(s_j >= s[None], safe_distance(v[None], v_j, world.settings.response),
                        safe_distance(v_j, v[None], world.assumptions.response)) + world.settings.D_safe
        out.append(bool(np.all(gap >= need)))
    return out[0], out[1]


@dataclass(frozen=True, eq=False)
class RssTerminal:
    """*Can stop behind the vehicle ahead* at the end of the look-ahead (:func:`rss_terminal`), a
    disjunction of three: **behind** it — for each chord j of K,
    ``slope[j]``·v_N + (distance travelled from now to N) ≤ ``bound[j]`` [m] (v_0's share of the
    distance moved into the bound) —, or **passing** it, on the left the lateral offsets
    e_k ≥ ``left[k−1]`` [m], on the right e_k ≤ ``right[k−1]`` [m] (NaN: free at step k; beside it
    from :func:`beside_steps` on, and at the last fine step on the way there in proportion to the
    time left, so that each plan starts the lane change it is committed to; ``sides``: whether
    the ego may pass there, :func:`free_sides`). ``front``: the vehicle's participant index (−1:
    none, and every disjunct holds). ``rule`` (H, 2): the chord (slope [s], intercept [m]) of
    RSS's distance to the world's vehicle ahead over each fine step's reachable speeds, for the
    ``rss_gap`` signal (NaN: none), ``gap0`` [m]: ``rss_gap`` now, and ``due`` [s]: when from now
    the ego is to be beside the vehicle."""

    slope: np.ndarray
    bound: np.ndarray
    left: np.ndarray
    right: np.ndarray
    sides: tuple[bool, bool]
    front: int
    rule: np.ndarray
    gap0: float = float("inf")
    due: float = BESIDE_FROM

    @property
    def active(self) -> bool:
        return self.front >= 0


def rss_terminal(hc: HorizonConstants, front: Front | None, response: ResponseBounds, *, s0: float, v0: float,
                 steps: np.ndarray, H: int, v_lo: np.ndarray, v_hi: np.ndarray, v_bar: np.ndarray, margin: float,
                 a_min: float, lateral: float, sides: tuple[bool, bool], beside: np.ndarray, e0: float, due: float,
                 chords: int = 3, early: float | None = None) -> RssTerminal:
    """The terminal disjunction of the module docstring's *can stop behind the vehicle ahead*
    (``front``, :func:`front_of`) for a look-ahead of ``steps`` (N,) [s] from the ego at route
    position ``s0`` [m] and speed ``v0`` [m/s]: ``v_lo``/``v_hi`` (N,) [m/s] bound the speeds
    each step k = 1..N can reach, ``v_bar`` (N,) [m/s] are the linearisation's, ``margin`` [m] is
    kept beyond RSS's distance, ``a_min`` [m/s²] is full braking (< 0), ``lateral`` [m] the
    offset from the front's that counts as beside it, ``sides`` (left, right) whether being
    beside is allowed (:func:`free_sides`), ``beside`` the steps at which it is required
    (:func:`beside_steps`), ``e0`` [m] the ego's lateral offset now and ``due`` [s] the time
    from now it is due there; ``early``: the share of the way there required at the last fine
    step (None: in proportion to the time left). The ``rss_gap`` signal's chords are of the
    world's vehicle ahead (``hc``)."""
    N = len(steps)
    rule, gap0 = np.full((H, 2), np.nan), float("inf")
    if hc.ahead >= 0:  # the signal's vehicle: the world's (rss_gap)
        def g(v: np.ndarray) -> np.ndarray:
            return safe_distance(v, hc.v_ahead, response)

        rule = np.stack(chord(g, v_lo[:H], np.maximum(v_hi[:H], v_lo[:H])), axis=1)
        gap0 = float(hc.s_ahead[0] - hc.ahead_offset - s0 - g(np.asarray(v0)))
    if front is None:
        free = np.full(N, np.nan)
        return RssTerminal(np.zeros(chords), np.ones(chords), free, free, (True, True), -1, rule, gap0)

    def f(v: np.ndarray) -> np.ndarray:
        return safe_distance(v, front.v, response)

    lo, hi = float(v_lo[-1]), max(float(v_hi[-1]), float(v_lo[-1]))
    vb = min(max(float(v_bar[-1]), lo), hi)
    w = CHORD_HALF_WIDTH
    cuts = np.array([lo, min(max(vb - w, lo), hi), min(max(vb + w, lo), hi), hi]) if chords == 3 else \
        np.linspace(lo, hi, chords + 1)
    slope, icpt = chord(f, cuts[:-1], cuts[1:])
    share = 0.5 * steps[0] * v0  # v_0's share of the distance travelled
    bound = front.s[N] - front.offset - margin - s0 - share - icpt
    # full braking from now: the least distance and speed the last step can have
    vbrk = np.empty(N + 1)
    vbrk[0] = v0
    for i in range(N):  # N ≈ 20 scalar steps
        vbrk[i + 1] = max(vbrk[i] + a_min * steps[i], 0.0)
    travelled = float(np.sum(0.5 * steps * (vbrk[:-1] + vbrk[1:]))) - share
    miss = slope * vbrk[N] + travelled - bound  # > 0: even full braking misses the row
    bound = bound + np.maximum(miss, 0.0) + np.where(miss > -1e-6, 1e-6, 0.0)
    side = []
    for e_side in (front.e + lateral, front.e - lateral):
        at = np.full(N, np.nan)
        at[beside - 1] = e_side
        if H not in beside:  # on the way there by the end of the fine part, as far as the time allows
            share = min(1.0, H * steps[0] / max(due, 1e-9)) if early is None else early
            at[H - 1] = e0 + (e_side - e0) * share
        side.append(at)
    return RssTerminal(slope, bound, side[0], side[1], sides, front.index, rule, gap0, due)
