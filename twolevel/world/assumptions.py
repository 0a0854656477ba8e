"""The declared assumptions about other road users: what the safety guarantee rests on.

A participant that keeps within these bounds can never be hit by the ego while the ego moves
(:mod:`twolevel.safety.verify`); one that leaves them breaks the assumptions, and a collision
with it is classified as not the ego's fault (:mod:`twolevel.safety.responsibility`). Every
default below is a published figure or, where no set-based source exists, a stated choice.

**Vehicles** (Koschi & Althoff, "SPOT: A tool for set-based prediction of traffic
participants", IEEE IV 2017; Althoff & Magdici, "Set-based prediction of traffic participants
on arbitrary road networks", IEEE T-IV 2016 — SPOT's published defaults):

* speed ≤ min(``v_max``, ``speed_factor`` · the speed limit in force); SPOT's speeding factor
  f_S = 0.2 (20 % over the limit) and v_max = 83.33 m/s. A vehicle observed faster than that
  has broken the bound; its own speed becomes its bound (SPOT drops a violated assumption per
  participant rather than predicting the impossible);
* |acceleration| ≤ ``a_max`` = 8 m/s² (SPOT: friction-limited, braking and driving alike), and
  above the switching speed ``v_switch`` the drive acceleration is power-limited,
  a ≤ a_max · v_switch / v (SPOT's engine model). v_switch = 7.319 m/s is the switching
  velocity of CommonRoad's vehicle models (Althoff & Würsching, "CommonRoad: Vehicle Models",
  2020, vehicles 1–3), the more permissive of SPOT's 5 m/s and it;
* no reversing (SPOT's constraint C_back);
* lane-bound: the body stays on its lane and the lanes that follow it (every branch at a
  junction); with ``lane_changes`` also on the parallel lanes of the same direction (SPOT's
  C_lane, lane changes where the markings allow them — the map has no markings, so anywhere);
* ``stop_lines``: it stops at a stop sign's line whose lane it is on, unless already too close
  to stop (|braking| ≤ a_max) or standing at the line (it may have served it);
  ``red_lights``: its front does not cross a light's line while the light is red, unless it
  cannot stop before it (Koschi & Althoff, "Set-based prediction of traffic participants
  considering occlusions and traffic rules", IEEE T-IV 2021: traffic rules as constraints).
* being overtaken, it does not speed up (Vienna Convention on Road Traffic 1968, art. 11(3):
  "every driver who is being overtaken shall ... not accelerate"; German StVO §5(6)): while the
  ego is out of its lane passing it, its speed stays at most what it is
  (:mod:`twolevel.safety.verify`, ``hold`` in :func:`twolevel.safety.occupancy.predict`).

**Cyclists**: the vehicle model with their own bounds. No set-based source gives them; our
choice: v_max = 12.5 m/s (45 km/h, the assisted top speed of the fastest e-bikes, S-pedelecs),
not bound by the motor-vehicle limit (``speed_factor`` = ∞), a_max = 6 m/s² (≈ 0.6 g, the
braking limit of a bicycle before it pitches over), power-limited above v_switch = 2 m/s;
lane-bound with lane changes; they obey stop lines and red lights.

**Pedestrians** (Koschi, Pek, Beikirch, Althoff, "Set-based prediction of pedestrians in urban
environments considering formalized traffic rules", IEEE ITSC 2018 — SPOT's pedestrian
defaults): speed ≤ v_max = 2 m/s (7.2 km/h), |acceleration| ≤ a_max = 0.6 m/s², any heading, not
lane-bound. These are SPOT's figures for walking pedestrians; a running one exceeds them (a
scenario with runners must raise them).

**Response** (Responsibility-Sensitive Safety: Shalev-Shwartz, Shammah, Shashua, "On a formal
model of safe and scalable self-driving cars", 2017; the values are the initial ones of Intel's
ad-rss-lib, "Parameter discussion"): other road users respond within ``time`` = 2 s (ρ_other),
may accelerate at ``accel_max`` = 3.5 m/s² during it, then brake at least ``brake_min`` = 4 m/s²;
the vehicle ahead brakes at most ``brake_max`` = 8 m/s². A follower in the ego's lane that keeps
this distance never hits the ego; the verifier leaves followers to it (see
:mod:`twolevel.safety.verify`), and the responsibility classification counts a rear-end
collision as not the ego's fault once the ego has been ahead in the lane for ρ_other.

Which participant is which road user: its ``kind`` in the scenario (:func:`user_of`: a
``bicycle`` is a cyclist, a ``pedestrian`` a pedestrian, every other kind — ``parked`` too — a
vehicle); where ``assumptions.road_users`` maps a participant or population id to ``vehicle``,
``cyclist`` or ``pedestrian``, that wins.

They belong to the world: a scenario declares them (its ``assumptions:`` section, read by
:func:`from_spec` into :attr:`twolevel.world.world.World.assumptions`), and the safety layer
(:mod:`twolevel.safety`) rests on them. Light module (no numpy): ``twolevel check`` imports it
for the defaults and the warnings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any, Mapping, Sequence

__all__ = [
    "VEHICLE", "CYCLIST", "PEDESTRIAN", "KIND_NAMES", "MotionBounds", "ResponseBounds", "Assumptions",
    "VEHICLE_BOUNDS", "CYCLIST_BOUNDS", "PEDESTRIAN_BOUNDS", "RSS_BOUNDS", "safe_distance", "opposite_safe_distance", "safe_speed",
    "stopping_speed", "kinds_of", "user_of", "from_spec", "tighter_than_default",
]

VEHICLE, CYCLIST, PEDESTRIAN = 0, 1, 2
KIND_NAMES = ("vehicle", "cyclist", "pedestrian")


@dataclass(frozen=True)
class MotionBounds:
    """How one kind of road user may move (see the module docstring for the sources).

    ``v_max`` [m/s]: speed bound; ``speed_factor`` [-]: also v ≤ speed_factor · limit in force
    (∞: not bound by limits); ``a_max`` [m/s²]: largest |acceleration| (braking and driving);
    ``v_switch`` [m/s]: above it the drive acceleration is ≤ a_max · v_switch / v (∞: never);
    ``lane_bound``: moves along lanes (else freely, any heading); ``lane_changes``: may move to
    the parallel lanes of the same direction; ``stop_lines`` / ``red_lights``: obeys them."""

    v_max: float
    speed_factor: float
    a_max: float
    v_switch: float
    lane_bound: bool = True
    lane_changes: bool = True
    stop_lines: bool = True
    red_lights: bool = True

    def speed_cap(self, limit: float) -> float:
        """The speed bound [m/s] where the limit in force is ``limit`` [m/s]."""
        return min(self.v_max, self.speed_factor * limit)


@dataclass(frozen=True)
class ResponseBounds:
    """RSS's response of other road users: ``time`` ρ [s], ``accel_max`` [m/s²] during it,
    ``brake_min`` [m/s²] at least afterwards, ``brake_max`` [m/s²] at most (the front car)."""

    time: float = 2.0
    accel_max: float = 3.5
    brake_min: float = 4.0
    brake_max: float = 8.0


VEHICLE_BOUNDS = MotionBounds(v_max=83.33, speed_factor=1.2, a_max=8.0, v_switch=7.319)
CYCLIST_BOUNDS = MotionBounds(v_max=12.5, speed_factor=math.inf, a_max=6.0, v_switch=2.0)
PEDESTRIAN_BOUNDS = MotionBounds(v_max=2.0, speed_factor=math.inf, a_max=0.6, v_switch=math.inf, lane_bound=False,
                                 lane_changes=False, stop_lines=False, red_lights=False)
RSS_BOUNDS = ResponseBounds()


@dataclass(frozen=True)
class Assumptions:
    """The bounds per kind of road user (indexed by :data:`VEHICLE`, :data:`CYCLIST`,
    :data:`PEDESTRIAN`), the RSS response, and which participants (by id, or by population id)
    are cyclists or pedestrians (everyone else is a vehicle)."""

    vehicle: MotionBounds = VEHICLE_BOUNDS
    cyclist: MotionBounds = CYCLIST_BOUNDS
    pedestrian: MotionBounds = PEDESTRIAN_BOUNDS
    response: ResponseBounds = RSS_BOUNDS
    road_users: tuple[tuple[str, int], ...] = ()

    def bounds(self, kind: int) -> MotionBounds:
        """The bounds of one kind of road user."""
        return (self.vehicle, self.cyclist, self.pedestrian)[kind]


def safe_distance(v_rear: Any, v_front: Any, r: ResponseBounds = RSS_BOUNDS) -> Any:
    """RSS's minimal safe longitudinal gap [m] between a rear car at ``v_rear`` and a front car
    at ``v_front`` [m/s], same direction: the rear one responds within ρ at up to accel_max,
    then brakes at brake_min; the front one brakes at up to brake_max (Shalev-Shwartz et al.
    2017, Def. 1). Numbers or numpy arrays (elementwise, broadcast); convex in ``v_rear``."""
    v_resp = v_rear + r.time * r.accel_max
    d = (v_rear * r.time + 0.5 * r.accel_max * r.time**2 + v_resp**2 / (2 * r.brake_min)
         - v_front**2 / (2 * r.brake_max))
    return (d + abs(d)) / 2  # max(0, d), exactly, for numbers and arrays alike


def opposite_safe_distance(v_ego: Any, v_other: Any, ego: ResponseBounds = RSS_BOUNDS,
                           other: ResponseBounds = RSS_BOUNDS) -> Any:
    """RSS's minimal safe longitudinal gap [m] between two cars driving towards each other at
    speeds ``v_ego`` and ``v_other`` [m/s] (magnitudes): each responds within its ρ at up to its
    accel_max, then brakes at its brake_min (Shalev-Shwartz et al. 2017, Def. 4; ``ego``: the one
    in the other's lane, here the passing ego, ``other``: the oncoming one). Numbers or numpy
    arrays (elementwise, broadcast)."""
    def leg(v: Any, r: ResponseBounds) -> Any:
        v_resp = v + r.time * r.accel_max
        return 0.5 * (v + v_resp) * r.time + v_resp**2 / (2 * r.brake_min)

    return leg(v_ego, ego) + leg(v_other, other)


def safe_speed(gap: float, v_front: float = 0.0, r: ResponseBounds = RSS_BOUNDS) -> float:
    """The largest speed [m/s] of a rear car whose :func:`safe_distance` behind a front car at
    ``v_front`` [m/s] is at most ``gap`` [m] (the inverse of safe_distance in the rear car's
    speed); 0 when even a standing rear car needs more."""
    rho, acc, b = r.time, r.accel_max, r.brake_min
    # v·ρ + acc·ρ²/2 + (v + ρ·acc)²/(2b) − v_front²/(2·brake_max) = gap, a quadratic in v
    c = 0.5 * acc * rho**2 + (rho * acc) ** 2 / (2 * b) - v_front**2 / (2 * r.brake_max) - gap
    if c >= 0:
        return 0.0
    p = rho + rho * acc / b  # v²/(2b) + p·v + c = 0
    return max(0.0, (-p + math.sqrt(p * p - 2 * c / b)) * b)  # (rounding: never below 0)


def stopping_speed(distance: float, r: ResponseBounds = RSS_BOUNDS) -> float:
    """The largest speed [m/s] of a rear car that stops within ``distance`` [m] behind a
    standing one (responding within ρ at up to accel_max, then braking at brake_min)."""
    return safe_speed(distance, 0.0, r)


def kinds_of(ids: Sequence[str], a: Assumptions, default: Sequence[int] | None = None) -> list[int]:
    """The kind of road user of each participant id: named directly in ``road_users``, or a
    member ``<population>-<n>`` of a named population; else its ``default`` (the kind its
    scenario gives it), or a vehicle."""
    table = dict(a.road_users)
    out = []
    for k, pid in enumerate(ids):
        kind = table.get(pid)
        if kind is None and "-" in pid:
            kind = table.get(pid.rsplit("-", 1)[0])
        out.append(kind if kind is not None else (VEHICLE if default is None else default[k]))
    return out


_KIND_INDEX = {name: i for i, name in enumerate(KIND_NAMES)}


def _merge(base: MotionBounds, over: Any) -> MotionBounds:
    if over is None:
        return base
    given = {f.name: getattr(over, f.name) for f in fields(base) if getattr(over, f.name, None) is not None}
    return replace(base, **given)


_USER_OF_PARTICIPANT = {"bicycle": "cyclist", "pedestrian": "pedestrian"}
"""A participant's ``kind`` → its kind of road user (others: vehicle)."""


def user_of(kind: str) -> int:
    """The road user (:data:`VEHICLE`, :data:`CYCLIST`, :data:`PEDESTRIAN`) a participant of this
    ``kind`` is predicted as."""
    return _KIND_INDEX[_USER_OF_PARTICIPANT.get(kind, "vehicle")]


def from_spec(spec: Any, kinds: Mapping[str, str] | None = None) -> Assumptions:
    """The assumptions a scenario's ``assumptions:`` section declares (the schema's model, or
    None for the defaults): fields it leaves out keep the defaults above. ``kinds`` (participant
    id → its ``kind``: bicycle, pedestrian, car, …) makes bicycles cyclists and pedestrians
    pedestrians unless ``road_users`` names them."""
    implied = {pid: _KIND_INDEX[_USER_OF_PARTICIPANT[k]] for pid, k in (kinds or {}).items()
               if k in _USER_OF_PARTICIPANT}
    if spec is None:
        return Assumptions(road_users=tuple(sorted(implied.items())))
    resp = RSS_BOUNDS
    if spec.response is not None:
        resp = replace(RSS_BOUNDS, **{f.name: getattr(spec.response, f.name) for f in fields(RSS_BOUNDS)
                                       if getattr(spec.response, f.name, None) is not None})
    return Assumptions(_merge(VEHICLE_BOUNDS, spec.vehicle), _merge(CYCLIST_BOUNDS, spec.cyclist),
                       _merge(PEDESTRIAN_BOUNDS, spec.pedestrian), resp,
                       tuple(sorted({**implied, **{k: _KIND_INDEX[v] for k, v in spec.road_users.items()}}.items())))


_LARGER_IS_LOOSER = ("v_max", "speed_factor", "a_max", "v_switch", "time", "accel_max", "brake_max")


def tighter_than_default(section: str, given: Mapping[str, Any]) -> list[tuple[str, Any, Any]]:
    """Fields of an ``assumptions:`` section (``vehicle``, ``cyclist``, ``pedestrian`` or
    ``response``) that are *tighter* than the defaults, so that the guarantee covers fewer of
    the behaviours others may show: (name, given, default) for each. Larger speed and
    acceleration bounds, a longer response and permissions (lane changes allowed, rules not
    obeyed) are looser; a larger ``brake_min`` (followers assumed to brake harder) is tighter."""
    base: Any = RSS_BOUNDS if section == "response" else (VEHICLE_BOUNDS, CYCLIST_BOUNDS, PEDESTRIAN_BOUNDS)[
        _KIND_INDEX[section]]
    out = []
    for name, value in given.items():
        if value is None or not hasattr(base, name):
            continue
        default = getattr(base, name)
        if name in _LARGER_IS_LOOSER:
            tighter = value < default
        elif name == "brake_min":
            tighter = value > default
        elif name == "lane_changes":
            tighter = default and not value
        else:  # stop_lines / red_lights: assuming an obedience the default does not is tighter
            tighter = value and not default
        if tighter:
            out.append((name, value, default))
    return out
