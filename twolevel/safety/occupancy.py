"""Set-based occupancy prediction: where each participant may be, per time interval, under the
declared assumptions (:mod:`twolevel.world.assumptions`; SPOT's method, Koschi & Althoff 2017).

For every participant and every interval [t_j, t_{j+1}] [s] after the prediction time, a union
of convex polygons that contains its body whatever it does within its bounds:

**Lane-bound users** (vehicles, cyclists) move along their lane tree
(:class:`~twolevel.safety.network.LaneTrees`: every successor branch; with lane changes, the
parallel lanes of the same direction too). Along the path:

* the front stays behind front₀ + d_max(t_{j+1}) — the farthest travel from the observed speed
  v₀, accelerating at a_max below v_switch and at a_max·v_switch/v above it (SPOT's engine
  model) up to v_cap = max(v₀, min(v_max, speed_factor · the largest limit on its tree));
* the rear stays ahead of rear₀ + d_min(t_j) — the least travel: full braking at a_max, no
  reversing;
* **stop lines**: when it obeys the line (its kind's ``stop_lines`` / ``red_lights``), the line is
  ahead of its front, and it can still stop before it (v₀² / (2·a_max) ≤ distance), its front
  stays behind the line until it may cross: for a stop sign, the earliest arrival plus the
  sign's ``stop_time`` (a user standing within :data:`STOP_ZONE` before the line may already have
  served it: no cap); for a light, the first moment at or after the earliest arrival at which the
  light is not red (a known program: a red light ahead is red for everyone on its lane). With lane
  changes, a line caps a lane group only where every member lane's line does (it may go round).
  Branches behind a capped line are unreachable while it holds;
* laterally: the lane's width (or, with lane changes, every member lane's), widened so that the
  body as observed now fits (a user straddling a marking stays predicted as wide as it is) and by
  what a rigid body sticks out of its lane on a bend (L²·κ/8 across, W·L·κ/4 along, with κ the
  sharpest turning within a body's reach, corners and joints between lanes included).

Each (participant, tree node, member lane, interval) interval of arc length is cut at the lane's
cells and each cut turned into a quad (:func:`~twolevel.safety.polygons.band_pieces`: exact on
straight pieces, a proven margin on bends). **Free users** (pedestrians; anyone off every lane;
a lane-bound user whose reach runs beyond its lane tree) get the octagon around the hull of
the discs at t_j and t_{j+1}: the smaller of the drift disc (centre p₀ + v₀·t, radius
a_max·t²/2) and the speed disc (centre p₀, radius v_cap·t), plus the body's half-diagonal — any
heading, speed and acceleration bounds only.

Soundness: everything above is an over-approximation of the reachable set under the stated
bounds (the tests sample legal behaviour and check containment). Vectorised over participants,
nodes, members, intervals and cells; the only loops are over the depth of the lane trees
(propagating line caps to branches) and over the phases of a light's program.

Units: m, s, m/s, m/s².
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twolevel.world.assumptions import PEDESTRIAN, Assumptions
from twolevel.safety.network import CELL_LENGTH, CELL_TURN, LIGHT, MAP_SLACK, STOP_SIGN, Network
from twolevel.safety.polygons import OCTAGON_NORMALS, band_pieces, disc_hull_octagons, lane_point
from twolevel.world.traffic import RED, TrafficState

__all__ = ["Intervals", "Occupancy", "ReachBounds", "reach_bounds", "predict", "travel_max", "travel_min", "time_to_travel", "lane_of",
           "kind_flags", "STOP_ZONE", "STANDING"]

STOP_ZONE = 3.0
"""A user standing this close before a stop sign's line [m] may have served it (no cap)."""
STANDING = 0.5
"""Speed [m/s] below which a user at a stop sign counts as standing there."""
_V_SWITCH_OFF = 1e6  # [m/s] stands for "no power limit" (v_switch = ∞)


@dataclass(frozen=True, eq=False)
class Intervals:
    """Time intervals [t_j, t_{j+1}] [s] after the prediction time, on the control grid: bounds
    ``t`` (J+1,) [s] = ``k`` · ``dt``, uniform steps of dt up to ``fine`` [s], then ``coarse``
    steps each."""

    t: np.ndarray
    k: np.ndarray
    dt: float

    @classmethod
    def make(cls, dt: float, horizon: float, fine: float = 2.0, coarse: int = 3) -> "Intervals":
        """Intervals covering [0, horizon] [s] (the last one may end later)."""
        n_fine = int(round(fine / dt))
        n_all = max(1, int(math.ceil(horizon / dt - 1e-9)))
        k = list(range(min(n_fine, n_all) + 1))
        while k[-1] < n_all:
            k.append(k[-1] + max(1, coarse))
        ka = np.asarray(k, dtype=int)
        return cls(ka * dt, ka, dt)

    @property
    def count(self) -> int:
        """Number of intervals J."""
        return len(self.t) - 1


@dataclass(frozen=True, eq=False)
class Occupancy:
    """Predicted occupancy: M convex polygons, each for one participant over one interval.

    ``points`` (M, 8, 2) [m] vertices (quads repeat theirs), ``axes`` (M, 4, 2) their edge normals
    (repeated for quads), bounding circles ``centre`` (M, 2) / ``radius`` (M,) [m] and the half
    sizes ``extent`` (M, 2) [m] of axis-aligned bounding boxes about the same centre, ``interval``
    (M,) index j, ``owner`` (M,) participant index in the traffic arrays, ``lane`` (M,) the lane the
    piece lies on (−1 for free users), ``changed`` (M,) whether it is reached only by changing
    into that lane. ``predicted`` (P,): the participants predicted, ``free`` (P,) which of them
    freely. ``front_hi`` / ``rear_lo`` (P, J) [m]: the lane-bound users' bounds along the path from
    their lane's start (NaN for free users), for inspection and tests."""

    intervals: Intervals
    points: np.ndarray
    axes: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    extent: np.ndarray
    interval: np.ndarray
    owner: np.ndarray
    lane: np.ndarray
    changed: np.ndarray
    predicted: np.ndarray
    free: np.ndarray
    front_hi: np.ndarray
    rear_lo: np.ndarray


# --------------------------------------------------------------------- longitudinal reach


def _phases(v0: np.ndarray, v_cap: np.ndarray, a: np.ndarray, v_sw: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(tA, vA, c, tB, dA, dB): full acceleration to vA = min(v_switch, v_cap) over tA [s],
    power-limited (v·v' = c = a·v_switch) to v_cap over tB [s]; the distances dA, dB [m]."""
    v_sw = np.minimum(v_sw, _V_SWITCH_OFF)
    v_a = np.maximum(v0, np.minimum(v_sw, v_cap))
    t_a = (v_a - v0) / a
    c = a * v_sw
    t_b = (v_cap**2 - v_a**2) / (2 * c)
    d_a = v0 * t_a + 0.5 * a * t_a**2
    d_b = (v_cap**3 - v_a**3) / (3 * c)
    return t_a, v_a, c, t_b, d_a, d_b


def travel_max(v0: np.ndarray, v_cap: np.ndarray, a: np.ndarray, v_sw: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The farthest travel [m] after t [s] (broadcast) from speed v0 [m/s]: acceleration a
    [m/s²] below v_sw [m/s], a·v_sw/v above it, up to v_cap ≥ v0 [m/s] (SPOT's engine model)."""
    t_a, v_a, c, t_b, _, _ = _phases(v0, v_cap, a, v_sw)
    ta = np.minimum(t, t_a)
    tb = np.clip(t - t_a, 0.0, t_b)
    tc = np.maximum(t - t_a - t_b, 0.0)
    d_a = v0 * ta + 0.5 * a * ta**2
    d_b = ((v_a**2 + 2 * c * tb) ** 1.5 - v_a**3) / (3 * c)
    return d_a + d_b + v_cap * tc


def time_to_travel(v0: np.ndarray, v_cap: np.ndarray, a: np.ndarray, v_sw: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The earliest time [s] at which the travel of :func:`travel_max` reaches d ≥ 0 [m] (its
    inverse; +inf when v_cap = 0 and d > 0)."""
    t_a, v_a, c, t_b, d_a, d_b = _phases(v0, v_cap, a, v_sw)
    d = np.maximum(d, 0.0)
    in_a = (-v0 + np.sqrt(v0**2 + 2 * a * np.minimum(d, d_a))) / a
    rest = np.maximum(d - d_a, 0.0)
    in_b = ((3 * c * np.minimum(rest, d_b) + v_a**3) ** (2.0 / 3.0) - v_a**2) / (2 * c)
    rest_c = np.maximum(rest - d_b, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        in_c = np.where(rest_c > 0, rest_c / v_cap, 0.0)
    return np.where(d <= d_a, in_a, np.where(rest <= d_b, t_a + in_b, t_a + t_b + in_c))


def travel_min(v0: np.ndarray, a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The least travel [m] after t [s] from speed v0 [m/s]: braking at a [m/s²], no reversing."""
    ts = np.minimum(t, v0 / a)
    return v0 * ts - 0.5 * a * ts**2


# -------------------------------------------------------------------------------- lights


def _wait_not_red(net: Network, light: np.ndarray, t_abs: np.ndarray) -> np.ndarray:
    """Time [s] from absolute time ``t_abs`` until light ``light`` is not red (0 if not red now;
    +inf if it stays red)."""
    L = net.world.lights
    light = np.asarray(light, dtype=int)
    period = L.period[light]
    finite = np.isfinite(period)
    u = np.where(finite, np.mod(t_abs + L.offset[light], np.where(finite, period, 1.0)), t_abs + L.offset[light])
    starts, states = L.times[light], L.states[light]  # (Q, P)
    phase = np.clip((starts <= u[:, None]).sum(1) - 1, 0, starts.shape[1] - 1)
    now_ok = np.take_along_axis(states, phase[:, None], axis=1)[:, 0] != RED
    later = (starts > u[:, None]) & (states != RED) & np.isfinite(starts)
    wait_later = np.where(later, starts - u[:, None], np.inf).min(axis=1)
    wrap = np.where((states != RED) & np.isfinite(starts), starts, np.inf).min(axis=1)
    wait_wrap = np.where(finite, period - u + wrap, np.inf)
    return np.where(now_ok, 0.0, np.minimum(wait_later, wait_wrap))


# ---------------------------------------------------------------------------- prediction


def lane_of(net: Network, traffic: TrafficState, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lane and s [m] of participants ``idx``: the simulator's lane where it tracks one, else
    the lane the pose lies on (heading within 90°), else −1 (always for inactive ones)."""
    lane = traffic.lane[idx].astype(int)
    s = traffic.s[idx].astype(float)
    miss = (lane < 0) & traffic.active[idx]
    if miss.any():
        pts = np.stack([traffic.x[idx][miss], traffic.y[idx][miss]], axis=1)
        ln, sl, _ = net.world.lanes.lookup(pts, traffic.psi[idx][miss])
        lane[miss], s[miss] = ln, sl
    return lane, s


def _body_on_lane(net: Network, lane: np.ndarray, s: np.ndarray, traffic: TrafficState, idx: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The body's extent in its lane's frame at s: (ahead [m], behind [m] of s along the lane,
    lateral extra [m] beyond half the lane width)."""
    from twolevel.models.obb import box_corners

    world = net.world
    p, h = lane_point(world.lanes, lane, s)
    corners = box_corners(traffic.x[idx], traffic.y[idx], traffic.psi[idx], world.parts.length[idx],
                          world.parts.width[idx])  # (P, 4, 2)
    rel = corners - p[:, None, :]
    c, sn = np.cos(h)[:, None], np.sin(h)[:, None]
    along = rel[..., 0] * c + rel[..., 1] * sn
    across = -rel[..., 0] * sn + rel[..., 1] * c
    extra = np.maximum(0.0, np.abs(across).max(axis=1) - world.lanes.width[lane] / 2)
    return along.max(axis=1), -along.min(axis=1), extra


@dataclass(frozen=True, eq=False)
class _Users:
    """The participants being predicted (P of them) and what the prediction needs of each:
    ``idx`` (P,) into the traffic arrays, ``kind``, the speed ``v0`` [m/s] and its bound ``v_cap``,
    ``a_max`` [m/s²], ``v_sw`` [m/s], ``changes`` (may change lanes), ``lane`` (−1: none) and the
    lane-bound users' path bounds: ``front0``/``rear0`` [m] now, ``front_hi``/``rear_lo`` (P, J)
    [m], the body's ``length`` along its lane, ``width`` and ``extra`` width beyond the lane [m],
    and the tree's
    ``stretch`` [-]."""

    idx: np.ndarray
    kind: np.ndarray
    v0: np.ndarray
    v_cap: np.ndarray
    a_max: np.ndarray
    v_sw: np.ndarray
    changes: np.ndarray
    lane: np.ndarray
    front0: np.ndarray
    front_hi: np.ndarray
    rear_lo: np.ndarray
    length: np.ndarray
    width: np.ndarray
    extra: np.ndarray
    stretch: np.ndarray
    table: tuple
    bounds: np.ndarray

    def flag(self, name: str) -> np.ndarray:
        """A boolean bound of each user's kind (``stop_lines`` or ``red_lights``)."""
        return self.bounds[:, _COLUMNS.index(name)] > 0


_COLUMNS = ("v_max", "speed_factor", "a_max", "v_switch", "lane_bound", "lane_changes", "stop_lines", "red_lights")


_TABLES: list[tuple[Assumptions, np.ndarray]] = []


def _bounds_table(a: Assumptions) -> np.ndarray:
    """The bounds of each kind of road user as a table (3, 8), columns :data:`_COLUMNS` (the last
    few kept: the same assumptions come with every call of one world)."""
    for have, table in _TABLES:
        if have is a:
            return table
    table = np.array([[float(getattr(a.bounds(k), c)) for c in _COLUMNS] for k in range(3)])
    _TABLES[:] = [(a, table)] + _TABLES[:3]
    return table


def kind_flags(assumptions: Assumptions, kinds: np.ndarray, name: str) -> np.ndarray:
    """A boolean bound (a column of :data:`_COLUMNS`: ``lane_bound``, ``lane_changes``,
    ``stop_lines``, ``red_lights``) of each participant's kind of road user, ``kinds`` (N,)."""
    return _bounds_table(assumptions)[np.asarray(kinds, dtype=int), _COLUMNS.index(name)] > 0


@dataclass(frozen=True, eq=False)
class ReachBounds:
    """How far and how fast participants ``idx`` may go along their lanes under the assumptions
    (what :func:`predict` bounds their front by): speed now ``v0`` [m/s], ``v_cap`` [m/s] =
    max(v0, min(v_max, speed_factor · the largest limit on its lane tree)), ``a_max`` [m/s²] and
    ``v_switch`` [m/s] of SPOT's engine model, their ``lane`` (−1: none) and ``s0`` [m] on it,
    whether they may change lanes (``changes``) and their kinds' bounds ``col`` (P, 8)."""

    v0: np.ndarray
    v_cap: np.ndarray
    a_max: np.ndarray
    v_switch: np.ndarray
    lane: np.ndarray
    s0: np.ndarray
    changes: np.ndarray
    col: np.ndarray

    def earliest(self, d: np.ndarray) -> np.ndarray:
        """The earliest time [s] each could have travelled ``d`` (P,) [m] along its way
        (:func:`time_to_travel`)."""
        return time_to_travel(self.v0, self.v_cap, self.a_max, self.v_switch, d)


def reach_bounds(net: Network, traffic: TrafficState, idx: np.ndarray, assumptions: Assumptions,
                 kinds: np.ndarray) -> ReachBounds:
    """The :class:`ReachBounds` of participants ``idx`` (P,) of ``traffic``; ``kinds`` (N,) their
    kinds of road user. The one model of how fast others may come: the occupancy and the MPC's
    gap acceptance (:mod:`twolevel.control.high_level.right_of_way`) both read it."""
    idx = np.asarray(idx, dtype=int)
    col = _bounds_table(assumptions)[np.asarray(kinds)[idx]]  # (P, 8)
    changes = col[:, 5] > 0
    v0 = np.maximum(traffic.v[idx].astype(float), 0.0)
    lane, s0 = lane_of(net, traffic, idx)
    li = np.maximum(lane, 0)
    limit = np.where(changes, net.change.limit[li], net.keep.limit[li])
    v_cap = np.maximum(v0, np.minimum(col[:, 0], col[:, 1] * limit))
    return ReachBounds(v0, v_cap, col[:, 2], col[:, 3], lane, s0, changes, col)


def predict(net: Network, traffic: TrafficState, t: float, intervals: Intervals, assumptions: Assumptions,
            kinds: np.ndarray, include: np.ndarray | None = None,
            roi: tuple[np.ndarray, np.ndarray] | None = None, hold: np.ndarray | None = None) -> Occupancy:
    """The occupancy of the participants (active, and ``include`` (N,) if given) over
    ``intervals`` from the traffic at absolute time ``t`` [s]; ``kinds`` (N,) their kinds of road
    user (:func:`~twolevel.world.assumptions.kinds_of`). With ``roi`` = (centres (J, 2) [m],
    radii (J,) [m]) only the pieces that may reach the circle of their interval are kept (bounding
    circles of whole stretches are tested before the stretches are cut into pieces). ``hold``
    (N,): participants being overtaken, whose speed stays at most what it is
    (:mod:`twolevel.world.assumptions`)."""
    mask = traffic.active.copy()
    if include is not None:
        mask &= include
    idx = np.flatnonzero(mask)
    P, J = len(idx), intervals.count
    if P == 0 or J == 0:
        return _empty(intervals, idx, P, J)
    kind = np.asarray(kinds)[idx]
    table = tuple(assumptions.bounds(k) for k in range(3))
    r = reach_bounds(net, traffic, idx, assumptions, kinds)
    col, v0, v_cap, a_max, v_sw, lane, s0, changes = r.col, r.v0, r.v_cap, r.a_max, r.v_switch, r.lane, r.s0, r.changes
    v_max, factor = col[:, 0], col[:, 1]
    on_lane = (col[:, 4] > 0) & (lane >= 0)
    li = np.maximum(lane, 0)
    per_tree = lambda name: np.where(changes, getattr(net.change, name)[li], getattr(net.keep, name)[li])  # noqa: E731
    if hold is not None:
        v_cap = np.where(np.asarray(hold)[idx], v0, v_cap)
    stretch, shrink = per_tree("stretch"), per_tree("shrink")
    ahead, behind, extra = _body_on_lane(net, li, s0, traffic, idx)
    front0, rear0 = s0 + ahead, s0 - behind
    d_hi = travel_max(v0[:, None], v_cap[:, None], a_max[:, None], v_sw[:, None], intervals.t[None, 1:])  # (P, J)
    d_lo = travel_min(v0[:, None], a_max[:, None], intervals.t[None, :-1])
    front_hi = front0[:, None] + d_hi * stretch[:, None]
    rear_lo = rear0[:, None] + d_lo * shrink[:, None]
    on_lane &= front_hi[:, -1] <= per_tree("extent")  # reach beyond its lane tree: predicted freely
    near = np.ones(P, dtype=bool)
    if roi is not None:  # who can get within the region at all (speed bound × time, any direction)
        limit = float(net.world.limits.value.max()) if len(net.world.limits.value) else 0.0
        v_any = np.where(on_lane, v_cap, np.maximum(v0, np.where(kind == PEDESTRIAN, v_max,
                                                                 np.minimum(v_max, factor * limit))))
        body = 0.5 * np.hypot(net.world.parts.length[idx], net.world.parts.width[idx])
        d = np.hypot(traffic.x[idx][:, None] - roi[0][None, :, 0], traffic.y[idx][:, None] - roi[0][None, :, 1])
        near = np.any(d <= roi[1][None, :] + body[:, None] + v_any[:, None] * intervals.t[None, 1:], axis=1)
    users = _Users(idx, kind, v0, v_cap, a_max, v_sw, changes, li, front0, front_hi, rear_lo, ahead + behind,
                   net.world.parts.width[idx], extra, stretch, table, col)
    parts = [_tree_pieces(net, net.trees(mode), t, intervals, users, np.flatnonzero(near & on_lane & (changes == mode)),
                          roi) for mode in (False, True)]
    parts.append(_free_pieces(net, traffic, intervals, users, np.flatnonzero(near & ~on_lane), roi))
    parts = [p for p in parts if p is not None]
    if not parts:
        return _empty(intervals, idx, P, J)
    points, axes, centre, radius, extent, interval, owner, piece_lane, changed = (
        np.concatenate([p[i] for p in parts]) for i in range(9))
    fh = np.where(on_lane[:, None], front_hi, np.nan)
    rl = np.where(on_lane[:, None], rear_lo, np.nan)
    return Occupancy(intervals, points, axes, centre, radius, extent, interval, owner, piece_lane, changed, idx,
                     ~on_lane, fh, rl)


def _empty(iv: Intervals, idx: np.ndarray, P: int, J: int) -> Occupancy:
    z = np.zeros(0, dtype=int)
    return Occupancy(iv, np.zeros((0, 8, 2)), np.zeros((0, 4, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2)), z, z, z,
                     np.zeros(0, dtype=bool), idx, np.zeros(P, dtype=bool), np.full((P, J), np.nan), np.full((P, J), np.nan))


def _near(centre: np.ndarray, radius: np.ndarray, j: np.ndarray, roi: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """Which circles (centre (n, 2), radius (n,)) of intervals ``j`` (n,) meet their interval's
    region of interest (all, without one)."""
    if roi is None:
        return np.ones(len(j), dtype=bool)
    c, r = roi
    d = centre - c[j]
    return d[:, 0] ** 2 + d[:, 1] ** 2 <= (radius + r[j]) ** 2


def _tree_pieces(net: Network, tr, t: float, iv: Intervals, u: _Users, who: np.ndarray,
                 roi: tuple[np.ndarray, np.ndarray] | None) -> tuple | None:
    """Quads of the lane-bound users ``who`` (indices into the users) along trees ``tr``."""
    if not len(who):
        return None
    lanes = net.world.lanes
    J = iv.count
    # --- every user's tree nodes, flattened ---------------------------------------------
    start, stop = tr.ptr[u.lane[who]], tr.ptr[u.lane[who] + 1]
    count = stop - start
    p_of = np.repeat(who, count)  # user of each node
    first = np.repeat(np.cumsum(count) - count, count)
    node = np.repeat(start, count) + np.arange(count.sum()) - first
    parent = np.where(tr.parent[node] >= 0, first + tr.parent[node], -1)  # index into these nodes
    members = tr.members[node]  # (N, M)
    # --- line caps, then each node's stretch of its ref lane per interval ----------------
    cap = np.full((len(node), J), np.inf)
    if (tr.line[node] >= 0).any():
        cap = _line_caps(net, tr, t, iv, node, p_of, members, u)
        for d in range(1, int(tr.depth[node].max(initial=0)) + 1):  # branches behind a capped line
            at = np.flatnonzero(tr.depth[node] == d)
            cap[at] = np.minimum(cap[at], cap[parent[at]])
    off = tr.offset[node][:, None]
    ref = tr.ref[node]
    hi = np.minimum(u.front_hi[p_of], cap)
    lo = np.minimum(u.rear_lo[p_of], hi - u.length[p_of][:, None])
    # on a bend a rigid box's corners reach beyond its ends' path positions by about W·L·κ/4
    reach = (u.width[p_of] * u.length[p_of] * tr.kappa[node] / 4.0)[:, None]
    lo, hi = lo - reach, hi + reach
    a = np.where((tr.parent[node] >= 0)[:, None], np.maximum(lo - off, 0.0), lo - off)
    b = np.where(tr.leaf[node][:, None], hi - off, np.minimum(hi - off, lanes.length[ref][:, None]))
    n_i, j_i = np.nonzero(b > a)
    if not len(n_i):
        return None
    dl = tr.dlat[node[n_i]]  # (n, M) members' offsets from the ref lane
    # half widths: the lane's and what the body sticks out now; on a bend a rigid box also sticks
    # out of the band its centre keeps to, by L²·κ/8 at curvature κ (per cell, below)
    kappa = tr.kappa[node[n_i]]
    bend_out = u.length[p_of[n_i]] ** 2 * kappa / 8.0
    half = tr.half[node[n_i]] + u.extra[p_of[n_i]][:, None]
    valid = members[n_i] >= 0
    if roi is not None:  # a bounding circle of each stretch (all members), tested against the region
        spread = np.where(valid, tr.spread[node[n_i]], 0.0)  # members drawn on their own lane stray this far
        lat_lo = np.where(valid, dl - half - spread, np.inf).min(axis=1)
        lat_hi = np.where(valid, dl + half + spread, -np.inf).max(axis=1)
        r, pa, pb = ref[n_i], a[n_i, j_i], b[n_i, j_i]
        mid, h = lane_point(lanes, r, 0.5 * (pa + pb))
        lat = 0.5 * (lat_lo + lat_hi)
        centre = mid + lat[:, None] * np.stack([-np.sin(h), np.cos(h)], axis=1)
        length = pb - pa
        bend = np.minimum(2.0, np.maximum(length, 1.0) * kappa)  # how far the normal turns along it
        wide = np.maximum(np.abs(lat_lo), np.abs(lat_hi))
        slack = np.where(kappa > 0, 0.5 * np.minimum(length, CELL_LENGTH) * np.tan(CELL_TURN / 2)
                         + wide * np.sin(CELL_TURN), 0.0)  # what the quads add on bends
        radius = 0.5 * length + 0.5 * (lat_hi - lat_lo) + np.abs(lat) * bend + slack + bend_out + spread.max(axis=1)
        keep = _near(centre, radius, j_i, roi)
        n_i, j_i, dl, half, valid = n_i[keep], j_i[keep], dl[keep], half[keep], valid[keep]
    # --- per member lane ---------------------------------------------------------------------
    M = members.shape[1]
    flat = valid.ravel()
    m_i = np.tile(np.arange(M), len(n_i))[flat]
    dl, half = dl.ravel()[flat], half.ravel()[flat]
    n_i, j_i = np.repeat(n_i, M)[flat], np.repeat(j_i, M)[flat]
    if not len(n_i):
        return None
    member = members[n_i, m_i]
    r = ref[n_i]
    pa, pb = a[n_i, j_i], b[n_i, j_i]
    own = tr.own[node[n_i], m_i]
    if own.any():  # a member that is no parallel offset of the ref: its band on its own lane, mapped
        pa, pb, dl = pa.copy(), pb.copy(), np.where(own, 0.0, dl)
        pairs = np.unique(np.stack([r[own], member[own]], axis=1), axis=0)
        for rf, mb in pairs:
            at = own & (r == rf) & (member == mb)
            pa[at] = net.member_s(int(rf), int(mb), pa[at]) - MAP_SLACK
            pb[at] = net.member_s(int(rf), int(mb), pb[at]) + MAP_SLACK
        r = np.where(own, member, r)
    # --- cut at the cells into quads -------------------------------------------------------
    first_c, last_c = net.cell_ptr[r], net.cell_ptr[r + 1] - 1
    c_lo = np.minimum(np.maximum(np.searchsorted(net.cell_key, lanes.base[r] + pa, side="right") - 1, first_c), last_c)
    c_hi = np.minimum(np.maximum(np.searchsorted(net.cell_key, lanes.base[r] + pb, side="right") - 1, first_c), last_c)
    c_hi = np.maximum(c_hi, c_lo)
    n_c = c_hi - c_lo + 1
    rep = np.repeat(np.arange(len(r)), n_c)
    cell = np.repeat(c_lo, n_c) + np.arange(n_c.sum()) - np.repeat(np.cumsum(n_c) - n_c, n_c)
    sa = np.where(cell == c_lo[rep], pa[rep], net.cell_s0[cell])
    sb = np.where(cell == c_hi[rep], pb[rep], net.cell_s1[cell])
    half = half[rep] + u.length[p_of[n_i[rep]]] ** 2 * net.cell_kappa[cell] / 8.0
    quad, axes, centre, radius, extent = band_pieces(lanes, r[rep], sa, sb, dl[rep] - half, dl[rep] + half,
                                                     net.cell_turn[cell])
    jr = j_i[rep]
    keep = _near(centre, radius, jr, roi)
    rep, quad, axes, centre, radius, extent, jr = (x[keep] for x in (rep, quad, axes, centre, radius, extent, jr))
    natural = tr.natural[node[n_i[rep]]]
    changed = (natural >= 0) & (member[rep] != natural)
    return (np.concatenate([quad, quad], axis=1), np.concatenate([axes, axes], axis=1), centre, radius, extent, jr,
            u.idx[p_of[n_i[rep]]], member[rep], changed)


def _line_caps(net: Network, tr, t: float, iv: Intervals, node: np.ndarray, p_of: np.ndarray, members: np.ndarray,
               u: _Users) -> np.ndarray:
    """The path position [m] each node's users' front stays behind per interval (N, J) (+inf:
    none): per member lane the nearest line that holds them, per node the farthest over its
    members (a user who may change lanes goes round a line on one lane only)."""
    world = net.world
    line = tr.line[node]  # (N, M, K)
    has = line >= 0
    q = np.maximum(line, 0)
    lkind = net.line_kind[q]
    x_line = tr.line_x[node]
    pp = p_of[:, None, None]
    dist = x_line - u.front0[pp]
    obey = np.where(lkind == STOP_SIGN, u.flag("stop_lines")[pp], u.flag("red_lights")[pp])
    can_stop = u.v0[pp] ** 2 / (2 * u.a_max[pp]) * u.stretch[pp] <= dist
    li = net.line_index[q]
    n_stops = len(world.stops.ids)
    stop_time = world.stops.stop_time[np.minimum(li, n_stops - 1)] if n_stops else np.zeros(dist.shape)
    standing = (lkind == STOP_SIGN) & (u.v0[pp] <= STANDING) & (dist <= STOP_ZONE)
    active = has & (dist >= 0) & obey & can_stop & ~standing
    reach = time_to_travel(u.v0[pp], u.v_cap[pp], u.a_max[pp], u.v_sw[pp], dist / u.stretch[pp])
    free_at = np.where(active & (lkind == STOP_SIGN), reach + stop_time, np.inf)
    lit = active & (lkind == LIGHT)
    if lit.any():
        free_at[lit] = reach[lit] + _wait_not_red(net, li[lit], t + reach[lit])
    blocks = active[..., None] & (iv.t[1:][None, None, None, :] <= free_at[..., None])  # (N, M, K, J)
    held = np.where(blocks, x_line[..., None], np.inf)
    cap_m = np.minimum.reduce([held[:, :, k] for k in range(held.shape[2])])  # (N, M, J) nearest line
    cap_m = np.where(members[..., None] >= 0, cap_m, -np.inf)
    return np.maximum.reduce([cap_m[:, m] for m in range(cap_m.shape[1])])  # (N, J) farthest member


def _free_pieces(net: Network, traffic: TrafficState, iv: Intervals, u: _Users, sel: np.ndarray,
                 roi: tuple[np.ndarray, np.ndarray] | None) -> tuple | None:
    """Octagons of the users ``sel`` predicted freely (any heading)."""
    if not len(sel):
        return None
    world = net.world
    g = u.idx[sel]
    # speed bound: a pedestrian's own; a vehicle's under the largest limit on the map
    limit = float(world.limits.value.max()) if len(world.limits.value) else 0.0
    v_max = np.array([u.table[q].v_max if q == PEDESTRIAN else u.table[q].speed_cap(limit) for q in u.kind[sel]])
    v_cap = np.maximum(u.v0[sel], v_max)
    body = 0.5 * np.hypot(world.parts.length[g], world.parts.width[g])
    p0 = np.stack([traffic.x[g], traffic.y[g]], axis=1)
    vel = u.v0[sel][:, None] * np.stack([np.cos(traffic.psi[g]), np.sin(traffic.psi[g])], axis=1)
    t0, t1 = iv.t[:-1][None, :], iv.t[1:][None, :]  # (1, J)
    am = u.a_max[sel][:, None]
    r_drift0, r_drift1 = 0.5 * am * t0**2, 0.5 * am * t1**2
    r_speed0, r_speed1 = v_cap[:, None] * t0, v_cap[:, None] * t1
    drift = r_drift1 <= r_speed1  # the smaller disc at the end of the interval
    c0 = p0[:, None] + drift[..., None] * vel[:, None] * t0[..., None]
    c1 = p0[:, None] + drift[..., None] * vel[:, None] * t1[..., None]
    r0 = np.where(drift, r_drift0, r_speed0) + body[:, None]
    r1 = np.where(drift, r_drift1, r_speed1) + body[:, None]
    P, J = len(sel), iv.count
    p_i, j_i = np.divmod(np.arange(P * J), J)
    c0, c1, r0, r1 = c0.reshape(-1, 2), c1.reshape(-1, 2), r0.ravel(), r1.ravel()
    if roi is not None:
        half = 0.5 * np.hypot(*(c1 - c0).T)
        keep = _near(0.5 * (c0 + c1), half + np.maximum(r0, r1) / np.cos(np.pi / 8), j_i, roi)
        p_i, j_i, c0, c1, r0, r1 = p_i[keep], j_i[keep], c0[keep], c1[keep], r0[keep], r1[keep]
        if not len(p_i):
            return None
    octa, centre, radius = disc_hull_octagons(c0, r0, c1, r1)
    n = len(p_i)
    axes = np.broadcast_to(OCTAGON_NORMALS[:4], (n, 4, 2))
    return octa, axes, centre, radius, np.stack([radius, radius], axis=1), j_i, g[p_i], np.full(n, -1), \
        np.zeros(n, dtype=bool)
