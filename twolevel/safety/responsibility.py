"""Who is responsible for a collision, from the recorded trajectories (pure functions over arrays).

:func:`classify` decides one collision episode, in this order:

1. **ego standing** — the ego's speed at contact is at most ``stop_speed`` and it stands outside
   every other lane: not the ego's fault (a standing ego there is hit only by someone who left
   its lane, drove backwards or ran into a standing car; the verifier only lets the ego stop
   there). An ego that stopped inside another lane (``standing_in``: a crossing lane, say) is
   judged by the rules below like a moving one;
2. **hit from behind** — the other came from behind on the ego's lane (behind the ego's centre
   along the ego's heading, within its width, heading within 45° of it, on the same lane when
   lanes are known) and the ego had been on that lane for at least RSS's response time ρ of
   others (so it did not cut in closer than the follower could respond): not the ego's fault;
3. **cut in** — the other changed into the ego's lane (the lane its centre is on) ahead of the
   ego within ρ before the contact, the ego on that lane, leaving a gap (bumper to bumper, along
   the ego's heading) below RSS's safe distance for the ego's one-step response,
   v_e·dt + v_e²/(2·brake_min) − v_o²/(2·brake_max): leaving it is the duty of the one changing
   lanes (the verifier counts on it: :mod:`twolevel.safety.verify`), not the ego's fault. A
   side-swipe before the other's centre is in the ego's lane is not recognised (lanes only);
4. **the other broke the assumptions** — it left the occupancy predicted for it
   (``other_inside`` false at some sample up to the contact; :func:`stayed_within` computes it from
   the recorded traffic): not the ego's fault;
5. otherwise **the ego is at fault**: it moved into a participant that behaved within the
   assumptions.

:func:`stayed_within` re-predicts the other's occupancy from the recorded traffic (with the
world's assumptions) and tests, sample by sample, whether its body stayed inside: inside the
set predicted from the start of the window (which catches speeding up beyond the bounds over
seconds) and inside the set predicted one step before (which catches what one step shows, e.g.
reversing).

Units: m, s, m/s, rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from twolevel.models.obb import box_corners, box_separation
from twolevel.safety.occupancy import Intervals, Occupancy, predict
from twolevel.safety.verify import Context
from twolevel.world.signals import same_way
from twolevel.world.traffic import TrafficState

__all__ = ["EGO_AT_FAULT", "EGO_STANDING", "HIT_FROM_BEHIND", "CUT_IN", "OTHER_BROKE_ASSUMPTIONS", "Responsibility",
           "classify", "contains", "stayed_within"]

EGO_AT_FAULT = "ego_at_fault"
EGO_STANDING = "ego_standing"
HIT_FROM_BEHIND = "hit_from_behind"
CUT_IN = "cut_in"
OTHER_BROKE_ASSUMPTIONS = "other_broke_assumptions"


@dataclass(frozen=True)
class Responsibility:
    """The classification of one collision: ``verdict`` (one of :data:`EGO_AT_FAULT`,
    :data:`EGO_STANDING`, :data:`HIT_FROM_BEHIND`, :data:`CUT_IN`,
    :data:`OTHER_BROKE_ASSUMPTIONS`), ``at_fault``, the time of contact ``t`` [s], the ego's speed then ``ego_speed`` [m/s], when the other first
    left its predicted occupancy ``left_at`` [s] (None: it did not), and a sentence ``reason``."""

    verdict: str
    at_fault: bool
    t: float
    ego_speed: float
    left_at: float | None
    reason: str


def classify(t: np.ndarray, ego: np.ndarray, other: np.ndarray, ego_box: tuple[float, float],
             other_box: tuple[float, float], *, other_inside: np.ndarray | None = None,
             ego_lane: np.ndarray | None = None, other_lane: np.ndarray | None = None, stop_speed: float = 0.1,
             response_time: float = 2.0, standing_in: str | None = None, brake_min: float = 4.0,
             brake_max: float = 8.0) -> Responsibility:
    """Classify the collision in the recording ``t`` (T,) [s] with the ego's and the other's
    ``[x, y, psi, v]`` (T, 4) [m, m, rad, m/s] and boxes (length, width) [m]: contact is the first
    sample at which the boxes overlap (the last sample if none does). ``other_inside`` (T,): whether
    the other was inside its predicted occupancy at each sample (None: assumed inside); lanes (T,)
    (−1: off every lane; None: unknown); ``stop_speed`` [m/s]; ``response_time`` [s]: RSS's ρ of
    others; ``standing_in``: the other lane the ego's box overlaps at contact (None: none, or
    unknown; :func:`~twolevel.safety.verify.standstill_lane`); ``brake_min`` / ``brake_max``
    [m/s²]: RSS's braking bounds (the safe distance of a cut-in)."""
    t = np.asarray(t, dtype=float)
    ego, other = np.asarray(ego, dtype=float), np.asarray(other, dtype=float)
    eb = box_corners(ego[:, 0], ego[:, 1], ego[:, 2], ego_box[0], ego_box[1])
    ob = box_corners(other[:, 0], other[:, 1], other[:, 2], other_box[0], other_box[1])
    touching = box_separation(eb, ob) < 0
    c = int(np.argmax(touching)) if touching.any() else len(t) - 1
    v_ego = float(ego[c, 3])
    inside = np.ones(len(t), dtype=bool) if other_inside is None else np.asarray(other_inside, dtype=bool)
    out = ~inside[: c + 1]
    left_at = float(t[int(np.argmax(out))]) if out.any() else None

    def done(verdict: str, reason: str) -> Responsibility:
        return Responsibility(verdict, verdict == EGO_AT_FAULT, float(t[c]), v_ego, left_at, reason)

    if abs(v_ego) <= stop_speed and standing_in is None:
        return done(EGO_STANDING, f"the ego was standing ({abs(v_ego):.2f} m/s) when it was hit")
    if _from_behind(t, ego, other, ego_box, other_box, ego_lane, other_lane, c, response_time):
        return done(HIT_FROM_BEHIND, "hit from behind on its lane, where it had been for at least the others' "
                                     f"response time ({response_time:g} s)")
    cut = _cut_in(t, ego, other, ego_box, other_box, ego_lane, other_lane, c, response_time, brake_min, brake_max)
    if cut is not None:
        return done(CUT_IN, f"the other changed into the ego's lane at {cut[0]:.1f} s, {cut[1]:.1f} m ahead of it, "
                            f"closer than the safe distance {cut[2]:.1f} m (leaving it was the other's duty)")
    if left_at is not None:
        return done(OTHER_BROKE_ASSUMPTIONS, f"the other left its predicted occupancy at {left_at:.1f} s "
                                             "(it broke the declared assumptions)")
    if abs(v_ego) <= stop_speed:
        return done(EGO_AT_FAULT, f"the ego stood inside lane '{standing_in}', where the other may legally come, "
                                  "and the other stayed within its predicted occupancy")
    return done(EGO_AT_FAULT, "the ego moved into a participant that stayed within its predicted occupancy")


def _from_behind(t: np.ndarray, ego: np.ndarray, other: np.ndarray, ego_box: tuple[float, float],
                 other_box: tuple[float, float], ego_lane: np.ndarray | None, other_lane: np.ndarray | None, c: int,
                 response_time: float) -> bool:
    x, y, psi = ego[c, 0], ego[c, 1], ego[c, 2]
    dx, dy = other[c, 0] - x, other[c, 1] - y
    along = dx * math.cos(psi) + dy * math.sin(psi)
    across = -dx * math.sin(psi) + dy * math.cos(psi)
    behind = along < 0 and abs(across) < 0.5 * (ego_box[1] + other_box[1])
    aligned = bool(same_way(other[c, 2], psi))
    if not (behind and aligned):
        return False
    if ego_lane is None or other_lane is None:
        return True
    el, ol = np.asarray(ego_lane), np.asarray(other_lane)
    if el[c] < 0 or ol[c] != el[c]:
        return False
    window = t >= t[c] - response_time - 1e-9
    window[c + 1:] = False
    stayed = bool(np.all(el[window] == el[c])) and t[c] - t[0] >= response_time - 1e-9
    return stayed


def _cut_in(t: np.ndarray, ego: np.ndarray, other: np.ndarray, ego_box: tuple[float, float],
            other_box: tuple[float, float], ego_lane: np.ndarray | None, other_lane: np.ndarray | None, c: int,
            response_time: float, brake_min: float, brake_max: float) -> tuple[float, float, float] | None:
    """(time [s], gap [m], safe distance [m]) of the other's change into the ego's lane that left
    too small a gap, within ρ before contact sample ``c`` (None: none did)."""
    if ego_lane is None or other_lane is None or c == 0:
        return None
    el, ol = np.asarray(ego_lane), np.asarray(other_lane)
    lane = el[c]
    if lane < 0 or ol[c] != lane:
        return None
    entered = np.flatnonzero((ol[1:c + 1] == lane) & (ol[:c] != lane) & (el[1:c + 1] == lane)) + 1
    entered = entered[t[entered] >= t[c] - response_time - 1e-9]
    if not len(entered):
        return None
    j = int(entered[-1])
    psi = ego[j, 2]
    along = (other[j, 0] - ego[j, 0]) * math.cos(psi) + (other[j, 1] - ego[j, 1]) * math.sin(psi)
    gap = along - 0.5 * (ego_box[0] + other_box[0])
    if along <= 0:
        return None
    v_e, v_o = max(float(ego[j, 3]), 0.0), max(float(other[j, 3]), 0.0)
    dt = float(t[1] - t[0])
    safe = v_e * dt + v_e**2 / (2 * brake_min) - v_o**2 / (2 * brake_max)
    return (float(t[j]), float(gap), float(safe)) if gap < safe else None


def contains(occ: Occupancy, owner: int, interval: int, corners: np.ndarray) -> bool:
    """Whether every corner (4, 2) [m] lies in one of the polygons predicted for participant
    ``owner`` over ``interval`` (a corner on the boundary counts as inside)."""
    sel = np.flatnonzero((occ.owner == owner) & (occ.interval == interval))
    if not len(sel):
        return False
    axes, pts = occ.axes[sel], occ.points[sel]  # (S, 4, 2), (S, 8, 2)
    proj = np.einsum("sad,svd->sav", axes, pts)
    lo, hi = proj.min(-1), proj.max(-1)  # (S, 4)
    q = np.einsum("sad,cd->sca", axes, corners)  # (S, 4 corners, 4 axes)
    tol = 1e-6
    inside = np.all((q >= lo[:, None, :] - tol) & (q <= hi[:, None, :] + tol), axis=-1)  # (S, corners)
    return bool(inside.any(axis=0).all())


def stayed_within(ctx: Context, traffic: Sequence[TrafficState], i: int) -> np.ndarray:
    """Whether participant ``i`` stayed inside its predicted occupancy at each recorded sample of
    ``traffic`` (T TrafficStates one control step apart, the first the start of the window) (T,):
    sample k must lie in the set predicted from sample 0 for the interval ending at k and in the
    set predicted from sample k − 1 for one step (the context's network, assumptions, kinds)."""
    net, world, kinds = ctx.network, ctx.world, ctx.kinds
    dt = world.settings.dt
    T = len(traffic)
    out = np.ones(T, dtype=bool)
    if T < 2:
        return out
    only = np.zeros(len(traffic[0].x), dtype=bool)
    only[i] = True
    L, W = float(world.parts.length[i]), float(world.parts.width[i])
    corners = [box_corners(s.x[i], s.y[i], s.psi[i], L, W) for s in traffic]
    whole = Intervals(dt * np.arange(T), np.arange(T), dt)
    long = predict(net, traffic[0], traffic[0].t, whole, world.assumptions, kinds, only)
    one = Intervals(np.array([0.0, dt]), np.array([0, 1]), dt)
    for k in range(1, T):  # a collision episode's window: a few dozen samples
        if not traffic[k].active[i]:
            continue
        step = predict(net, traffic[k - 1], traffic[k - 1].t, one, world.assumptions, kinds, only)
        out[k] = contains(long, i, k - 1, corners[k]) and contains(step, i, 0, corners[k])
    return out
