"""What traffic is made of: the map's lights, stop lines and limits, the participants' fixed
properties, and the state that changes every step.

Units: m, s, m/s, m/s², rad. Every table is a frozen dataclass of numpy arrays indexed by
participant (N,) or by line; participant arrays are full length even where a field concerns a
few (a pedestrian's path is NaN for a car), so that the step works on whole arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from twolevel.world.assumptions import RSS_BOUNDS, ResponseBounds
from twolevel.world.geometry import step_index

__all__ = [
    "GREEN", "YELLOW", "RED", "STATIONARY", "CONSTANT_VELOCITY", "IDM", "SCRIPTED", "MANOEUVRES", "WALK", "BIG",
    "Lights", "StopLines", "Conflicts", "SpeedLimits", "Plans", "Walks", "Participants", "Memory", "TrafficState",
    "EgoBox", "nearby",
]

GREEN, YELLOW, RED = 0, 1, 2
STATIONARY, CONSTANT_VELOCITY, IDM, SCRIPTED, MANOEUVRES, WALK = 0, 1, 2, 3, 4, 5
"""Behaviours: standing; constant speed along its lane (or straight on); IDM (with MOBIL lane
changes when enabled); waypoints linear in time; manoeuvre primitives along its lane; a
pedestrian's walk."""
BIG = 1e7
"""[m] Separates lanes in sort keys ``lane · BIG + s``."""


@dataclass(frozen=True, eq=False)
class Lights:
    """Traffic lights: stop line (lane index, s [m]) and program. Each light's program is phase
    start times ``times`` (n, P) [s] (padded with +inf) and ``states`` (n, P), repeating with
    ``period`` (n,) [s] (+inf for a script), shifted by ``offset`` (n,) [s]: the state at time t
    is the phase in force at u = (t + offset) mod period."""

    ids: tuple[str, ...]
    lane: np.ndarray
    s: np.ndarray
    times: np.ndarray
    states: np.ndarray
    period: np.ndarray
    offset: np.ndarray

    def state_at(self, t: np.ndarray | float) -> np.ndarray:
        """States (..., n) in {GREEN, YELLOW, RED} at times ``t`` (...) [s]."""
        t = np.asarray(t, dtype=float)[..., None]
        u = np.where(np.isfinite(self.period), np.mod(t + self.offset, np.where(np.isfinite(self.period), self.period, 1.0)),
                     t + self.offset)
        phase = (self.times <= u[..., None]).sum(-1) - 1
        phase = np.clip(phase, 0, self.times.shape[1] - 1)
        return np.take_along_axis(np.broadcast_to(self.states, phase.shape + (self.states.shape[1],)),
                                  phase[..., None], axis=-1)[..., 0]


@dataclass(frozen=True, eq=False)
class Conflicts:
    """Where the way on beyond each give-way line crosses or joins another lane: one row per
    (line, lane traffic comes along) — the conflicting lane itself and the lanes leading into it
    — with the conflict's position ``s`` [m] in that lane's coordinates (beyond its end for a
    lane leading into the conflicting one) and ``path`` [m], how far past the line the conflict
    lies. Built by :func:`twolevel.world.traffic.junctions.conflicts_of`; this is the hook where
    a map's junctions (conflict zones with priorities) enter."""

    line: np.ndarray
    lane: np.ndarray
    s: np.ndarray
    path: np.ndarray

    @classmethod
    def none(cls) -> "Conflicts":
        """No conflicts."""
        z = np.zeros(0)
        return cls(z.astype(int), z.astype(int), z, z)


@dataclass(frozen=True, eq=False)
class StopLines:
    """Give-way lines: stop signs (``must_stop``: stand still for ``stop_time`` [s]) — and yield
    lines (``must_stop`` false: no standstill needed) once a map has them — at (lane index, s
    [m]), with the priority traffic each must let pass (``conflicts``)."""

    ids: tuple[str, ...]
    lane: np.ndarray
    s: np.ndarray
    stop_time: np.ndarray
    must_stop: np.ndarray | None = None
    conflicts: Conflicts = field(default_factory=Conflicts.none)

    @property
    def stopping(self) -> np.ndarray:
        """Whether each line requires a standstill (N,)."""
        return np.ones(len(self.ids), dtype=bool) if self.must_stop is None else self.must_stop


@dataclass(frozen=True, eq=False)
class SpeedLimits:
    """Speed limit by (lane, s): breakpoints with global keys ``base[lane] + s`` (sorted) and values [m/s]."""

    key: np.ndarray
    value: np.ndarray
    base: np.ndarray

    def at(self, lane: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Limit [m/s] in force at (lane index, s [m])."""
        return self.value[step_index(self.key, self.base[lane] + s)]


@dataclass(frozen=True, eq=False)
class Plans:
    """Manoeuvre primitives of scripted participants, (N, P) padded (``count`` (N,) each has):
    ``action`` (:data:`twolevel.world.traffic.manoeuvres.ACTIONS`), trigger kind ``trigger`` and
    its value ``when`` ([s] or [m]), target ``speed`` [m/s] reached at ``accel`` or ``decel``
    [m/s²], ``duration`` [s] (of a lane change), ``hold`` [s] (least time a ``follow_lane``
    or ``stop`` lasts), lane change ``side`` (+1 left, −1 right, 0: to ``lane``), ``lane`` (a lane
    index or −1), and speed profiles ``profile_x`` (N, P, K) [s or m from the primitive's start]
    / ``profile_v`` (N, P, K) [m/s] (padded past their last point, which ``profile_end`` (N, P)
    gives), ``along_distance`` (N, P)."""

    count: np.ndarray
    action: np.ndarray
    trigger: np.ndarray
    when: np.ndarray
    speed: np.ndarray
    accel: np.ndarray
    decel: np.ndarray
    duration: np.ndarray
    hold: np.ndarray
    side: np.ndarray
    lane: np.ndarray
    profile_x: np.ndarray
    profile_v: np.ndarray
    along_distance: np.ndarray
    profile_end: np.ndarray

    @classmethod
    def empty(cls, n: int) -> "Plans":
        """No participant has primitives."""
        z = np.zeros((n, 1))
        zi = np.zeros((n, 1), dtype=int)
        return cls(np.zeros(n, dtype=int), zi, zi, z, z, z, z, z, z, zi, zi - 1, np.zeros((n, 1, 2)), np.zeros((n, 1, 2)),
                   np.zeros((n, 1), dtype=bool), z)


@dataclass(frozen=True, eq=False)
class Walks:
    """Pedestrians' walks: a straight path from ``origin`` (N, 2) [m] along ``heading`` (N,)
    [rad] for ``length`` (N,) [m] at ``speed`` (N,) [m/s], started by ``trigger``/``when`` (as
    manoeuvres), waiting at the kerb for a time ``gap`` (N,) [s] in the traffic (0: steps out
    without looking); ``crosswalk`` (N,): a marked crossing, where vehicles let a waiting pedestrian
    cross; ``leaves`` (N,): it leaves the scene once across (a walk across the road; else it
    stands at the end of its path). Rows (R,) say where a path crosses a lane: ``row_owner`` (participant), ``row_lane``,
    ``row_s`` [m] (the crossing on the lane), ``row_enter``/``row_leave`` [m] (distance walked
    where the path enters and leaves the lane)."""

    origin: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    speed: np.ndarray
    trigger: np.ndarray
    when: np.ndarray
    gap: np.ndarray
    crosswalk: np.ndarray
    leaves: np.ndarray
    row_owner: np.ndarray
    row_lane: np.ndarray
    row_s: np.ndarray
    row_enter: np.ndarray
    row_leave: np.ndarray

    @classmethod
    def empty(cls, n: int) -> "Walks":
        """Nobody walks."""
        z, zi = np.zeros(0), np.zeros(0, dtype=int)
        return cls(np.zeros((n, 2)), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n, dtype=int), np.zeros(n),
                   np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), zi, zi, z, z, z)


@dataclass(frozen=True, eq=False)
class Participants:
    """What does not change: ids, behaviour ``kind`` (N,), boxes (N,) [m], IDM parameters (N, 6)
    as v0 [m/s] (NaN: min(120 km/h, lane limit)), T [s], s0 [m], a [m/s²], b [m/s²], delta, and
    scripted waypoints ``script_t`` (N, W) [s] / ``script_xy`` (N, W, 2) [m] padded with the last.

    ``user`` (N,): the kind of road user the safety layer predicts it as
    (:data:`twolevel.world.assumptions.VEHICLE`, ``CYCLIST``, ``PEDESTRIAN``); ``bounds`` (N, 4):
    that kind's assumed v_max [m/s], speed_factor [-], a_max [m/s²], v_switch [m/s], which every
    behaviour but waypoints keeps within; ``mobil`` (N, 5): politeness [-], threshold [m/s²],
    b_safe [m/s²], bias_right [m/s²], lane-change duration [s] (politeness and b_safe also set
    how hard it brakes to let a merging ego in); ``changes`` (N,): MOBIL lane changes on;
    ``critical_gap`` (N,) [s]: the time gap it accepts in priority traffic at a give-way line;
    ``keep_right`` (N,) [m]: distance kept from the right edge of the lane (NaN: keeps its
    lateral offset); ``plans``, ``walks``: manoeuvres and pedestrians' walks; ``response``: RSS's
    response of others, which a lane change in front of the ego leaves room for."""

    ids: tuple[str, ...]
    kind: np.ndarray
    length: np.ndarray
    width: np.ndarray
    idm: np.ndarray
    script_t: np.ndarray
    script_xy: np.ndarray
    user: np.ndarray
    bounds: np.ndarray
    mobil: np.ndarray
    changes: np.ndarray
    critical_gap: np.ndarray
    keep_right: np.ndarray
    plans: Plans
    walks: Walks
    response: ResponseBounds = RSS_BOUNDS


@dataclass(frozen=True, eq=False)
class Memory:
    """What the behaviours remember between steps, per participant (N,):

    * a lane change under way: ``lc_from`` (lane it leaves, −1: none), lateral offsets
      ``lc_lat0`` → ``lc_lat1`` [m] in the frame of the lane it moves into, ``lc_t`` [s] into a
      change lasting ``lc_T`` [s]; ``lc_done`` [s]: when its last change ended;
    * ``odo`` [m]: distance travelled (a pedestrian: walked along its path);
    * manoeuvres: ``next`` (index of the next primitive), ``started`` [s] (when the last one
      began), ``ended`` [s] (when it ended; +inf while it runs), ``lon`` (the primitive setting
      the speed, −1: none) begun at ``lon_t0`` [s] and odometer ``lon_odo0`` [m];
    * ``phase``: a pedestrian 0 before its trigger, 1 waiting at the kerb, 2 walking, 3 across;
    * ``accel`` [m/s²]: the acceleration of the last step (along the lane)."""

    lc_from: np.ndarray
    lc_lat0: np.ndarray
    lc_lat1: np.ndarray
    lc_t: np.ndarray
    lc_T: np.ndarray
    lc_done: np.ndarray
    odo: np.ndarray
    next: np.ndarray
    started: np.ndarray
    ended: np.ndarray
    lon: np.ndarray
    lon_t0: np.ndarray
    lon_odo0: np.ndarray
    phase: np.ndarray
    accel: np.ndarray

    @classmethod
    def fresh(cls, n: int) -> "Memory":
        """Nothing remembered yet (at t = 0: the "previous primitive" ended at 0)."""
        z = np.zeros(n)
        return cls(np.full(n, -1), z, z, z, np.ones(n), np.full(n, -np.inf), z, np.zeros(n, dtype=int), z, z,
                   np.full(n, -1), z, z, np.zeros(n, dtype=int), z)

    def but(self, **arrays: np.ndarray) -> "Memory":
        """A copy with ``arrays`` replaced."""
        return replace(self, **arrays)


@dataclass(frozen=True, eq=False)
class TrafficState:
    """Every participant at time ``t`` [s]: pose x, y [m], psi [rad], speed v [m/s] (along its
    lane for lane-bound ones); lane index (−1 off-lane; during a lane change the lane it moves
    into), s and lateral [m] on it; ``active`` (false once off the map); IDM stop-sign memory:
    ``stop_timer`` [s] of standstill at a stop line and ``served`` (index of the last stop sign
    served, −1); the behaviours' ``memory`` (None: fresh)."""

    t: float
    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    v: np.ndarray
    lane: np.ndarray
    s: np.ndarray
    lateral: np.ndarray
    active: np.ndarray
    stop_timer: np.ndarray
    served: np.ndarray
    memory: Memory | None = None

    @property
    def xy(self) -> np.ndarray:
        """Positions (N, 2) [m]."""
        return np.stack([self.x, self.y], axis=1)

    @property
    def remembered(self) -> Memory:
        """The behaviours' memory (fresh when none is kept yet)."""
        return self.memory if self.memory is not None else Memory.fresh(len(self.x))


@dataclass(frozen=True)
class EgoBox:
    """The ego as other traffic sees it: position [m], heading [rad], speed [m/s], box length
    and width [m], and the lanes its route runs along (``route``, lane indices: where it is
    heading, as its indicator shows)."""

    x: float
    y: float
    psi: float
    v: float
    length: float = 4.22
    width: float = 1.8
    route: tuple[int, ...] = ()


def nearby(state: TrafficState, x: float, y: float, r_near: float) -> np.ndarray:
    """Mask (N,) of active participants whose centre is within ``r_near`` [m] of (x, y)."""
    return state.active & (np.hypot(state.x - x, state.y - y) <= r_near)
