"""Online verification: an intended step is safe if a fail-safe after it avoids every place the
others may legally be until the ego stands, outside every other lane (Pek, Manzinger, Koschi,
Althoff, "Using online verification to prevent autonomous vehicles from causing accidents",
Nature Machine Intelligence 2020).

:func:`verify_step` takes the ego's detailed state and the actuator command [δ, γ] any planner
intends for the next control step, and:

1. rolls the step out on the detailed model (the plant's equations and parameters);
2. rolls out fail-safes from the state after it (:mod:`twolevel.safety.failsafe`: braking at
   RSS's brake_min, firmer, full; clearing a conflict zone first when one is near), gentlest first;
3. predicts the occupancy of every participant that could come near, per time interval, up to
   the fail-safe's standstill (:mod:`twolevel.safety.occupancy`);
4. checks the ego's swept box over every interval — the intended step, then the fail-safe —
   against the occupancy of that interval (separating axes, :mod:`twolevel.models.obb`;
   a bounding-circle filter first);
5. requires the standstill to be *invariably safe*: the ego's box at rest overlaps no lane other
   than its route's (:attr:`~twolevel.safety.network.Network.foreign`), so nobody may legally
   come where it stands — standing inside a crossing or merging lane is refused, even if nobody
   is predicted there within the horizon, since someone may be later.

The first fail-safe that passes is kept in the :class:`Verdict` (its commands from the state
after the step, so the caller can execute it from the next step on when the next plan fails:
by induction a verified fail-safe is always at hand). A step none of whose fail-safes passes is
refuted, and the verdict names, for each fail-safe tried, the participant and interval (or the
lane at standstill) that refuted it.

**What is left to others, by assumption** (each a documented responsibility, not a check):

* **followers**: a lane-bound participant (a vehicle or cyclist) behind the ego on the ego's lane
  (along its lane successors; the lane the simulator tracks it on, or the one its pose lies on)
  keeps a safe distance (RSS); while the ego's body is within its route lane (± ``lane_tolerance``) its
  occupancy is not checked. When the ego leaves its lane (the high level may use the adjacent
  lanes) followers are checked like everyone else;
* **cut-ins**: a participant changing into the ego's lane leaves the ego RSS's distance; while
  the ego is within its lane, occupancy a participant reaches only by changing into a lane of the
  ego's route is not checked. Every fail-safe brakes at least at RSS's brake_min from the next
  step, so a cut-in that leaves RSS's distance is one the fail-safe stops for;
* **after standstill** the ego is not checked against anyone: a standing ego outside every other
  lane is hit only by someone who left its lane, drove backwards or ran into a standing car.

:func:`verify_initial_state` checks the state itself (the fail-safes from it, without a step):
a scenario that starts unsafe is reported. :func:`time_to_react` is a criticality figure: how
many steps of an intended plan could still be followed before a fail-safe from there no longer
verifies.

Units: m, s, m/s, rad; timings in ms.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields, replace
from typing import Callable, Mapping

import numpy as np

from twolevel.models.obb import box_corners, intersects, rect_axes
from twolevel.models.params import VehicleParams
from twolevel.models.rollout import Backend, rollout
from twolevel.safety.failsafe import FailSafe, FailSafeSettings, brake_rate, manoeuvres, roll
from twolevel.safety.network import FOREIGN_TOLERANCE, Network, network_of
from twolevel.safety.occupancy import Intervals, Occupancy, kind_flags, lane_of, predict
from twolevel.world.area import drivable_area
from twolevel.world.clearance import passing_clearance
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["VerifySettings", "Context", "Refutation", "Verdict", "TimeToReact", "context", "verify_step",
           "verify_initial_state", "time_to_react", "ego_params", "standstill_lane"]


@dataclass(frozen=True)
class VerifySettings:
    """``margin`` [m]: the ego's box grows by it on every side (the sweep between samples, the
    turning of the box within an interval); ``fine`` [s] of intervals of one control step, then
    ``coarse`` steps each; ``lane_tolerance`` [m]: how far the ego's body may stick out of its
    route lane and still count as in it (followers, cut-ins); ``failsafe`` settings; rollout
    ``backend``."""

    margin: float = 0.1
    fine: float = 2.0
    coarse: int = 3
    lane_tolerance: float = 0.0
    failsafe: FailSafeSettings = FailSafeSettings()
    backend: Backend = "auto"


@dataclass(frozen=True, eq=False)
class Context:
    """What verification needs of a world, built once (:func:`context`): the world, its
    :class:`~twolevel.safety.network.Network`, the ego's detailed-model parameters, every
    participant's kind of road user (N,), the settings and the full-braking deceleration
    ``brake_full`` [m/s²]."""

    world: World
    network: Network
    params: VehicleParams
    kinds: np.ndarray
    settings: VerifySettings
    brake_full: float


@dataclass(frozen=True)
class Refutation:
    """Why one fail-safe failed: ``reason`` is ``collision`` (with ``participant`` over the
    interval [``t0``, ``t1``] [s] after the verification time — [0, dt] is the intended step
    itself), ``standstill`` (at rest on ``lane``, another lane) or ``no_stop`` (not standing
    after the settings' max_time)."""

    failsafe: str
    reason: str
    participant: str | None = None
    t0: float = math.nan
    t1: float = math.nan
    lane: str | None = None

    def __str__(self) -> str:
        if self.reason == "collision":
            return f"{self.failsafe}: may meet '{self.participant}' in [{self.t0:.1f}, {self.t1:.1f}] s"
        if self.reason == "standstill":
            return f"{self.failsafe}: stands on lane '{self.lane}'"
        return f"{self.failsafe}: does not stop"


@dataclass(frozen=True, eq=False)
class Verdict:
    """The outcome of one verification: ``verified``; the ``failsafe`` that passed (None if none
    did), from the state after the intended step (or from the state itself for an initial check);
    ``refutations`` of the fail-safes that failed before it (all of them when none passed);
    ``horizon`` [s] the occupancy covered; ``participants``: how many could come near the ego's
    trajectories (had a piece of occupancy within their region);
    ``timings_ms``: ``step`` (the intended step's rollout), ``failsafe``, ``prediction``,
    ``check``, ``total``."""

    verified: bool
    failsafe: FailSafe | None
    refutations: tuple[Refutation, ...]
    horizon: float
    participants: int
    timings_ms: Mapping[str, float] = field(default_factory=dict)

    @property
    def refuted_by(self) -> Refutation | None:
        """The refutation of the last fail-safe tried, when none passed."""
        return None if self.verified or not self.refutations else self.refutations[-1]


@dataclass(frozen=True)
class TimeToReact:
    """How many ``steps`` of an intended plan can be followed with a verified fail-safe after
    each (−1: not even now; the plan's length H: at least that many, ``at_least``), and the same
    in ``seconds``."""

    steps: int
    seconds: float
    at_least: bool


def ego_params(world: World) -> VehicleParams:
    """The ego's detailed-model parameters: the scenario's overrides and box (as the simulator
    builds its plant)."""
    names = {f.name for f in fields(VehicleParams)}
    p = VehicleParams().with_overrides({k: v for k, v in world.ego.vehicle.items() if k in names})
    return replace(p, length=world.ego.length, width=world.ego.width)


def context(world: World, params: VehicleParams | None = None, settings: VerifySettings | None = None) -> Context:
    """The verification context of a world (builds its network once)."""
    p = params or ego_params(world)
    return Context(world, network_of(world), p, world.parts.user,
                   settings or VerifySettings(), brake_rate(p))


# --------------------------------------------------------------------------- the checks


@dataclass
class _Prediction:
    """The occupancy computed so far in one verification, for the participants ``include`` (N,)
    (``hold`` (N,): those being overtaken, who do not speed up, :func:`_back`)
    and the region of interest ``roi`` (a circle per interval) it was cut to; recomputed when a
    trajectory needs a longer horizon or leaves the region."""

    include: np.ndarray
    hold: np.ndarray | None = None
    occ: Occupancy | None = None
    roi: tuple[np.ndarray, np.ndarray] | None = None
    ms: float = 0.0


def _route_state(ctx: Context, x: np.ndarray, s_hint: float | None) -> tuple[float, float]:
    """Route position s [m] and lateral offset e [m] of the ego's centre."""
    r = ctx.world.route
    pt = np.asarray(x[:2], dtype=float)[None]
    if s_hint is None:
        s, e = r.local_coordinates(pt)
        return float(s[0]), float(e[0])
    s, e = r.project_near(pt, np.array([s_hint]), 15.0 + abs(float(x[3])) * 0.5)
    return float(s[0]), float(e[0])


def _excluded(ctx: Context, traffic: TrafficState, s_ego: float, e_ego: float) -> tuple[np.ndarray, frozenset[int]]:
    """Followers (N,) bool and the protected lanes (cut-ins into them are the cutter's duty), both
    empty when the ego's body is not within its route lane."""
    w = ctx.world
    n = len(traffic.x)
    width = float(w.route.width_at(np.array([s_ego]))[0])
    inside = abs(e_ego) + w.ego.width / 2 <= width / 2 + ctx.settings.lane_tolerance
    if not inside or n == 0:
        return np.zeros(n, dtype=bool), frozenset()
    pieces = w.route.pieces
    # the piece the ego is on; the first one when it starts behind the route's start (s < 0)
    j = max((i for i, pc in enumerate(pieces) if pc[3] <= s_ego + 1e-9), default=0)
    lane_e, a, _, start = pieces[j]
    s_lane = a + s_ego - start
    protected = frozenset(int(pc[0]) for pc in pieces[j:])
    # followers: on a lane whose own lane tree reaches the ego's lane with the ego ahead of them
    tr = ctx.network.keep
    # the simulator's lane, or the one the pose lies on (scripted participants); lane-bound users only
    lane, s_on = lane_of(ctx.network, traffic, np.arange(n))
    on = traffic.active & (lane >= 0) & kind_flags(w.assumptions, ctx.kinds, "lane_bound")
    follower = np.zeros(n, dtype=bool)
    idx = np.flatnonzero(on)
    if len(idx):
        start_n, stop_n = tr.ptr[lane[idx]], tr.ptr[lane[idx] + 1]
        count = stop_n - start_n
        owner = np.repeat(np.arange(len(idx)), count)
        node = np.repeat(start_n, count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        hit = tr.ref[node] == lane_e
        x_ego_rear = tr.offset[node] + s_lane - w.ego.length / 2
        front = s_on[idx][owner] + w.parts.length[idx][owner] / 2
        behind = hit & (front <= x_ego_rear)
        follower[idx[np.unique(owner[behind])]] = True
    return follower, protected


PASS_REACH = 60.0
"""[m] How far ahead of the ego a vehicle in its lane may be and still be the one it is passing."""


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))


def _back(ctx: Context, traffic: TrafficState, s_ego: float, e_ego: float, pose: np.ndarray, v_ego: float
          ) -> tuple[float, float, float, float, float, np.ndarray] | None:
    """Where a fail-safe must take the ego back to, when at route position ``s_ego`` [m] with
    lateral offset ``e_ego`` [m] and speed ``v_ego`` [m/s] its ``pose`` [X m, Y m, ψ rad] puts its
    box so far out of the route's lane (and the lanes running its way) that standing there would be
    standing on another lane — each corner of the box against the lane where that corner lies along
    the route, so that in a bend (where the lane curves under the car) a box within its lane counts
    as within it:
    (lateral offset of the route lane's centre [m], route position its centre must pass to be
    ahead of the vehicles in the route's lane it is beside or passing (ahead of it within
    :data:`PASS_REACH` and slower along the route than its ``v_ego``: it closes on them), with
    D_safe to spare, −inf when there are none; the lateral offset [m]
    beside them on the ego's side, with the clearance each is owed
    (:func:`twolevel.world.clearance.passing_clearance`), NaN when none; the fastest of
    their speeds along the route [m/s] (0 when none: they may drive on at up to it); ``e_ego``;
    which participants (N,) are being overtaken: those and, until the ego is back in its lane,
    the slower ones it has passed (behind it in the route's lane within :data:`PASS_REACH`) do not
    speed up — the Vienna Convention on Road Traffic, art. 11(3), as the assumptions state,
    :mod:`twolevel.world.assumptions`). None: it is in its lane."""
    w, m = ctx.world, ctx.settings.margin
    corners = box_corners(pose[0], pose[1], pose[2], ctx.params.length, ctx.params.width)
    near = 0.5 * math.hypot(ctx.params.length, ctx.params.width) + 1.0
    s_c, e_c = w.route.project_near(corners, np.full(4, s_ego), near)
    area = drivable_area(w.lanes, w.route, np.concatenate([[s_ego], s_c]), oncoming=False)
    lo, hi = float(area.same_lo[0]), float(area.same_hi[0])
    slack = m - FOREIGN_TOLERANCE + 0.05
    if np.all((area.same_lo[1:] + slack <= e_c) & (e_c <= area.same_hi[1:] - slack)):
        return None
    clear = 0.5 * ctx.params.width + slack
    lo, hi = lo + clear, hi - clear
    if lo > hi:
        return None
    s_past, e_beside, v_past = -math.inf, math.nan, 0.0
    passed = np.zeros(len(traffic.x), dtype=bool)
    side = 1.0 if e_ego >= 0 else -1.0
    idx = np.flatnonzero(traffic.active)
    if len(idx):
        s_i, e_i = w.route.project_near(traffic.xy[idx], np.full(len(idx), s_ego), PASS_REACH + 10.0)
        half = 0.5 * float(w.route.width_at(np.array([s_ego]))[0])
        length = w.parts.length[idx]
        in_lane = np.abs(e_i) < half + 0.5 * w.parts.width[idx]
        along = traffic.v[idx] * np.cos(traffic.psi[idx] - w.route.heading_at(s_i))
        # being passed: beside the ego, or ahead within reach and slower (the ego closes on it; one
        # that keeps its distance or draws away is not passed, and no fail-safe chases it)
        level = s_i - length / 2 < s_ego + w.ego.length / 2
        beside = in_lane & (s_i + length / 2 > s_ego - w.ego.length / 2) & (s_i - s_ego < PASS_REACH) & (
            level | (along < v_ego))
        # passed and not yet returned in front of: behind it in the route's lane, slower than it
        behind = in_lane & (s_i < s_ego) & (s_ego - s_i < PASS_REACH) & (along < v_ego)
        passed[idx[behind]] = True
        if beside.any():
            s_past = float(np.max(s_i[beside] + length[beside] / 2)) + w.ego.length / 2 + w.settings.D_safe
            owed = passing_clearance(w.parts.user[idx][beside], float(w.route.limit_at(s_ego)))
            reach = e_i[beside] + side * (0.5 * (w.parts.width[idx][beside] + ctx.params.width) + owed)
            out = half + 0.5 * ctx.params.width + m + 0.25  # wholly out of the lane (its occupancy spans it)
            e_beside = float(side * max(float(np.max(side * reach)), out))
            v_past = max(float(np.max(along[beside])), 0.0)
            passed[idx[beside]] = True
    return min(max(0.0, lo), hi), s_past, e_beside, v_past, e_ego, passed


@dataclass(frozen=True, eq=False)
class _Sweep:
    """The ego's swept region per interval along a trajectory: the corners of its boxes at every
    sample within (J, S·4, 2), the axes of the boxes at both ends (J, 4, 2), a bounding circle
    ``centre`` (J, 2) / ``radius`` (J,) [m] and the half sizes ``extent`` (J, 2) [m] of its
    axis-aligned bounding box about the same centre; J intervals reach the trajectory's last
    sample."""

    points: np.ndarray
    axes: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    extent: np.ndarray

    @property
    def count(self) -> int:
        return len(self.radius)


def _sweep(states: np.ndarray, iv: Intervals, length: float, width: float, margin: float) -> _Sweep:
    """The sweep of ``states`` (T, 12), one sample per control step from the verification time,
    over the intervals ``iv`` that reach its last sample."""
    T = len(states)
    J = max(1, min(int(np.searchsorted(iv.k, T - 1, side="left")), iv.count))
    boxes = box_corners(states[:, 0], states[:, 1], states[:, 2], length + 2 * margin, width + 2 * margin)
    S = int(np.max(np.diff(iv.k[: J + 1]))) + 1
    k = iv.k[:J, None] + np.arange(S)[None, :]
    k = np.minimum(np.minimum(k, iv.k[1:J + 1, None]), T - 1)
    pts = boxes[k].reshape(J, S * 4, 2)
    ends = np.concatenate([rect_axes(boxes[np.minimum(iv.k[:J], T - 1)]),
                           rect_axes(boxes[np.minimum(iv.k[1:J + 1], T - 1)])], axis=1)
    lo = np.minimum.reduce([pts[:, i] for i in range(pts.shape[1])])
    hi = np.maximum.reduce([pts[:, i] for i in range(pts.shape[1])])
    centre = 0.5 * (lo + hi)
    return _Sweep(pts, ends, centre, 0.5 * np.hypot(*(hi - lo).T), 0.5 * (hi - lo))


def _first_collision(occ: Occupancy, checked: np.ndarray, sw: _Sweep) -> int | None:
    """Index of the occupancy polygon that meets the sweep earliest (None: none does)."""
    sel = np.flatnonzero(checked & (occ.interval < sw.count))
    if not len(sel):
        return None
    j = occ.interval[sel]
    d = np.abs(occ.centre[sel] - sw.centre[j]) <= occ.extent[sel] + sw.extent[j]  # bounding boxes meet
    near = d[:, 0] & d[:, 1]
    cand, j = sel[near], j[near]
    if not len(cand):
        return None
    hit = intersects(sw.points[j], sw.axes[j], occ.points[cand], occ.axes[cand])
    if not hit.any():
        return None
    order = np.lexsort((cand[hit], j[hit]))
    return int(cand[hit][order[0]])


def standstill_lane(ctx: Context, state: np.ndarray) -> int | None:
    """The other lane (index) the ego's box at rest overlaps at ``state`` (its first three
    components X, Y [m], ψ [rad]); None: standing there is invariably safe."""
    net = ctx.network
    if not len(net.foreign):
        return None
    m = ctx.settings.margin
    box = box_corners(state[0], state[1], state[2], ctx.params.length + 2 * m, ctx.params.width + 2 * m)
    reach = 0.5 * math.hypot(ctx.params.length, ctx.params.width) + m + CELL_REACH
    near = np.flatnonzero(np.hypot(net.foreign_centre[:, 0] - state[0], net.foreign_centre[:, 1] - state[1]) <= reach)
    if not len(near):
        return None
    hit = intersects(box[None], rect_axes(box[None]), net.foreign[near], net.foreign_axes[near])
    return int(net.foreign_lane[near[np.argmax(hit)]]) if hit.any() else None


CELL_REACH = 40.0
"""Bound on a foreign quad's half diagonal [m] (cells are at most 50 m long; lanes ≤ 10 m wide)."""


_NOWHERE = 1e12  # [m] the centre of an empty region of interest


def _covers(roi: tuple[np.ndarray, np.ndarray], sw: _Sweep) -> bool:
    """Whether every interval's circle of the sweep lies within the region of interest."""
    c, r = roi
    d = np.hypot(*(sw.centre - c[: sw.count]).T)
    return bool(np.all(d + sw.radius <= r[: sw.count] + 1e-9))


def _union(iv: Intervals, circles: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """A circle per interval containing every given circle of that interval (each a pair of
    centres (≤ J, 2) and radii (≤ J,), for the first intervals; none: far away)."""
    J = iv.count
    c = np.full((len(circles), J, 2), np.nan)
    r = np.full((len(circles), J), np.nan)
    for i, (ci, ri) in enumerate(circles):  # a handful
        n = min(len(ri), J)
        c[i, :n], r[i, :n] = ci[:n], ri[:n]
    n = (~np.isnan(r)).sum(axis=0)
    centre = np.nansum(c, axis=0) / np.maximum(n, 1)[:, None]
    reach = np.hypot(*(c - centre[None]).transpose(2, 0, 1)) + r
    radius = np.where(np.isnan(reach), -np.inf, reach).max(axis=0)
    return np.where((n > 0)[:, None], centre, _NOWHERE), np.where(n > 0, radius, 0.0)


_SLACK = 1.0
"""Lateral slack [m] of the braking envelope around the route (a fail-safe tracks it within cm)."""


def _envelope(ctx: Context, iv: Intervals, start: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Circles per interval around the stretch of route between where braking harder than the
    car can (1.2 × full braking) and where not braking at all would put the ego, from route
    position s [m] at speed v [m/s] at time t [s] after the verification time (``start``): every
    braking fail-safe from there lies within them, so one prediction serves them all."""
    s, v, t0 = start
    r = ctx.world.route
    t_a = np.maximum(iv.t[:-1] - t0, 0.0)
    t_b = np.maximum(iv.t[1:] - t0, 0.0)
    hard = 1.2 * ctx.brake_full
    lo = s + np.where(t_a < v / hard, v * t_a - 0.5 * hard * t_a**2, v**2 / (2 * hard))
    hi = s + v * t_b
    mid = r.position(0.5 * (lo + hi))
    body = 0.5 * math.hypot(ctx.params.length, ctx.params.width) + ctx.settings.margin + _SLACK
    return mid, 0.5 * (hi - lo) + body


def _predict(ctx: Context, pred: _Prediction, traffic: TrafficState, t: float, trajectories: list[np.ndarray],
             brake_from: tuple[float, float, float] | None = None) -> tuple[Occupancy, list[_Sweep]]:
    """The occupancy, near enough to the ego's ``trajectories`` and long enough for them (computed,
    or recomputed for all of them together when one is not covered), and their sweeps. With
    ``brake_from``, a new prediction also covers every braking fail-safe from there
    (:func:`_envelope`)."""
    st, dt = ctx.settings, ctx.world.settings.dt
    size = (ctx.params.length, ctx.params.width, st.margin)
    horizon = max((len(x) - 1) * dt for x in trajectories)
    have = pred.occ
    if have is not None and have.intervals.t[-1] >= horizon - 1e-9:
        sweeps = [_sweep(x, have.intervals, *size) for x in trajectories]
        if all(_covers(pred.roi, sw) for sw in sweeps):  # type: ignore[arg-type]
            return have, sweeps
    t0 = time.perf_counter()
    iv = Intervals.make(dt, horizon, st.fine, st.coarse)
    sweeps = [_sweep(x, iv, *size) for x in trajectories]
    circles = [(sw.centre, sw.radius) for sw in sweeps]
    if brake_from is not None:
        circles.append(_envelope(ctx, iv, brake_from))
    roi = _union(iv, circles)
    pred.occ = predict(ctx.network, traffic, t, iv, ctx.world.assumptions, ctx.kinds, pred.include, roi,
                       hold=pred.hold)
    pred.roi = roi
    pred.ms += (time.perf_counter() - t0) * 1e3
    return pred.occ, sweeps


def _judge(ctx: Context, occ: Occupancy, sw: _Sweep, fs: FailSafe, checked: np.ndarray) -> Refutation | None:
    """None if the trajectory of sweep ``sw`` (the intended steps, then the fail-safe ``fs``)
    passes; else why not."""
    hit = _first_collision(occ, checked, sw)
    if hit is not None:
        j = int(occ.interval[hit])
        return Refutation(fs.name, "collision", ctx.world.parts.ids[int(occ.owner[hit])],
                          float(occ.intervals.t[j]), float(occ.intervals.t[j + 1]))
    lane = standstill_lane(ctx, fs.states[-1])
    if lane is not None:
        return Refutation(fs.name, "standstill", lane=ctx.world.lanes.lanes[lane].id)
    return None


def _verify(ctx: Context, x_start: np.ndarray, prefix: np.ndarray, traffic: TrafficState, t: float,
            s_hint: float | None, tm: dict[str, float], pred: _Prediction | None
            ) -> tuple[FailSafe | None, list[Refutation], _Prediction]:
    """Try the fail-safes from ``x_start`` after the ``prefix`` states (from the verification time
    on); the first that passes. Followers and cut-ins are judged where the ego is now. A car in
    its lane whose braking would leave it standing over the lane's edge (pulling out: its heading
    and steering carry it on sideways while it stops) counts as out of it, as where it would
    stand shows (:func:`_back` there): the fail-safes that steer back or complete the pass are
    tried then."""
    s, e = _route_state(ctx, x_start, s_hint)
    now = _route_state(ctx, prefix[0], s_hint) if len(prefix) else (s, e)
    follower, protected = _excluded(ctx, traffic, *now)
    back = _back(ctx, traffic, s, e, x_start[:3], float(x_start[3]))
    fs, refuted, pred, stood = _first_safe(ctx, x_start, prefix, traffic, t, tm, pred, follower, protected, s, back)
    if fs is None and back is None and stood is not None:
        s_at, e_at = _route_state(ctx, stood, s)
        back = _back(ctx, traffic, s_at, e_at, stood[:3], float(x_start[3]))
        if back is not None:
            fs, more, pred, _ = _first_safe(ctx, x_start, prefix, traffic, t, tm, pred, follower, protected, s, back)
            refuted += more
    return fs, refuted, pred


def _first_safe(ctx: Context, x_start: np.ndarray, prefix: np.ndarray, traffic: TrafficState, t: float,
                tm: dict[str, float], pred: _Prediction | None, follower: np.ndarray, protected: frozenset[int],
                s: float, back: tuple[float, float, float, float, float, np.ndarray] | None
                ) -> tuple[FailSafe | None, list[Refutation], _Prediction, np.ndarray | None]:
    """:func:`_verify`'s trial of the manoeuvres for the ego at route position ``s`` [m] (``back``:
    :func:`_back`'s): the first fail-safe that passes, the refutations of those before it, the
    prediction (reused when its participants and holds are the same) and the state where the
    first fail-safe refuted for standing on another lane stands (None: none was)."""
    w, st = ctx.world, ctx.settings
    hold = None if back is None else back[5]
    if pred is None or not np.array_equal(pred.include, ~follower) or not _same(pred.hold, hold):
        pred = _Prediction(~follower, hold)
    plan = manoeuvres(st.failsafe, ctx.network.zones, s, max(float(x_start[3]), 0.0), ctx.brake_full,
                      None if back is None else back[:5])
    refuted: list[Refutation] = []
    stood: np.ndarray | None = None
    for batch in (plan[:1], plan[1:]):  # the gentlest alone (usually enough), then the others together
        if not batch:
            continue
        t0 = time.perf_counter()
        fss = roll(x_start, batch, w.route, s, w.settings.dt, ctx.params, st.failsafe, st.backend)
        tm["failsafe"] = tm.get("failsafe", 0.0) + (time.perf_counter() - t0) * 1e3
        stopped = [fs for fs in fss if fs.stopped]
        refuted += [Refutation(fs.name, "no_stop") for fs in fss if not fs.stopped]
        if not stopped:
            continue
        occ, sweeps = _predict(ctx, pred, traffic, t, [np.concatenate([prefix, fs.states]) for fs in stopped],
                               (s, max(float(x_start[3]), 0.0), len(prefix) * w.settings.dt))
        t0 = time.perf_counter()
        checked = np.ones(len(occ.lane), dtype=bool)
        if protected:  # cut-ins into the ego's lanes are the cutter's duty
            checked = ~(occ.changed & np.isin(occ.lane, list(protected)))
        for fs, sw in zip(stopped, sweeps):
            why = _judge(ctx, occ, sw, fs, checked)
            if why is None:
                tm["check"] = tm.get("check", 0.0) + (time.perf_counter() - t0) * 1e3
                return fs, refuted, pred, stood
            if why.reason == "standstill" and stood is None:
                stood = fs.states[-1]
            refuted.append(why)
        tm["check"] = tm.get("check", 0.0) + (time.perf_counter() - t0) * 1e3
    return None, refuted, pred, stood


def _verdict(ctx: Context, fs: FailSafe | None, refuted: list[Refutation], pred: _Prediction, tm: dict[str, float],
             t_start: float) -> Verdict:
    tm["prediction"] = pred.ms
    tm["total"] = (time.perf_counter() - t_start) * 1e3
    occ = pred.occ
    horizon = float(occ.intervals.t[-1]) if occ is not None else 0.0
    near = len(np.unique(occ.owner)) if occ is not None else 0
    return Verdict(fs is not None, fs, tuple(refuted), horizon, near, tm)


def verify_step(ctx: Context, x0: np.ndarray, control: np.ndarray, traffic: TrafficState, t: float,
                s_hint: float | None = None) -> Verdict:
    """Whether the command ``control`` = [δ rad, γ] for the next step from the ego's detailed state
    ``x0`` (12,) at time ``t`` [s], with the others as ``traffic`` shows them now, keeps a fail-safe
    (see the module docstring). ``s_hint`` [m]: the ego's route position, if known (speeds up the
    projection)."""
    t_start = time.perf_counter()
    tm: dict[str, float] = {}
    x0 = np.asarray(x0, dtype=float)
    x1 = rollout(x0, np.asarray(control, dtype=float).reshape(1, 1, 2), ctx.world.settings.dt, ctx.params,
                 ctx.settings.backend).states[0, 1]
    tm["step"] = (time.perf_counter() - t_start) * 1e3
    fs, refuted, pred = _verify(ctx, x1, x0[None], traffic, t, s_hint, tm, None)
    return _verdict(ctx, fs, refuted, pred, tm, t_start)


def verify_initial_state(ctx: Context, x0: np.ndarray, traffic: TrafficState, t: float = 0.0,
                         s_hint: float | None = None) -> Verdict:
    """Whether the state ``x0`` itself has a fail-safe (at the start of a run: a scenario that
    starts unsafe is reported by a refuted verdict)."""
    t_start = time.perf_counter()
    tm: dict[str, float] = {}
    fs, refuted, pred = _verify(ctx, np.asarray(x0, dtype=float), np.zeros((0, 12)), traffic, t, s_hint, tm, None)
    return _verdict(ctx, fs, refuted, pred, tm, t_start)


def time_to_react(ctx: Context, x0: np.ndarray, plan: np.ndarray, traffic: TrafficState, t: float,
                  s_hint: float | None = None, known: int = -1) -> TimeToReact:
    """How many steps of the intended ``plan`` (H, 2) [δ rad, γ] from ``x0`` could be followed with
    a verified fail-safe after each: the largest k such that the fail-safe after k steps verifies,
    found by bisection from k = H down (assuming that once no fail-safe verifies after k steps,
    none does after more: the others' sets only grow). ``known``: a number of steps already known
    to be followable (1 when the plan's first step was just verified; −1: nothing known), which
    spares those checks."""
    dt = ctx.world.settings.dt
    plan = np.asarray(plan, dtype=float).reshape(-1, 2)
    H = len(plan)
    xs = rollout(np.asarray(x0, dtype=float), plan[None], dt, ctx.params, ctx.settings.backend).states[0]  # (H+1, 12)
    tm: dict[str, float] = {}
    cache: list[_Prediction | None] = [None]

    def ok(k: int) -> bool:
        fs, _, cache[0] = _verify(ctx, xs[k], xs[:k], traffic, t, s_hint, tm, cache[0])
        return fs is not None

    if ok(H):
        return TimeToReact(H, H * dt, True)
    if known < 0 and not ok(0):
        return TimeToReact(-1, -dt, False)
    lo, hi = max(known, 0), H  # ok(lo), not ok(hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return TimeToReact(lo, lo * dt, False)
