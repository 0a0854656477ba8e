"""The scenario's other road users as runtime tables: participants one by one, populations by the
lane-full (placed deterministically from a seed), each with its kind's defaults.

Kinds (``kind:`` of a participant or a population, :data:`twolevel.world.schema.ParticipantKind`):

* ``car``, ``truck``, ``bus``, ``motorcycle``, ``other`` — vehicles: IDM by default; a box of
  4.22 m × 1.8 m;
* ``bicycle`` — a cyclist: IDM with a cyclist's defaults (:data:`CYCLIST_IDM`: 5 m/s, 1 s headway, 1.5 m jam
  distance, 1 m/s² up, 1.5 m/s² down), a box of 1.8 m × 0.65 m, keeping right in its lane (0.3 m
  from the right edge) unless its start gives a lateral offset;
* ``pedestrian`` — a walk (:mod:`twolevel.world.traffic.pedestrians`), a box of 0.5 m × 0.6 m;
* ``parked`` — a stationary vehicle, usually placed with a lateral offset (half on the kerb):
  lane traffic treats it as in its way only where it intrudes into the path a body drives
  (:mod:`twolevel.world.traffic.neighbours`).

Each is predicted by the safety layer as the road user of its kind
(:func:`twolevel.world.assumptions.user_of`: bicycles as cyclists, parked cars as vehicles);
``assumptions.road_users`` still names the kind of a participant or population and, where it
does, wins (:func:`twolevel.world.assumptions.kinds_of`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from twolevel.world.assumptions import Assumptions, kinds_of, user_of
from twolevel.world.geometry import LaneSet
from twolevel.world.schema import Box, IDMParams, MobilParams, Participant, Placement, Population, ScenarioFile
from twolevel.world.traffic import (
    CONSTANT_VELOCITY, IDM, MANOEUVRES, SCRIPTED, STATIONARY, WALK, Memory, Participants, TrafficState,
)
from twolevel.world.traffic.lanechange import KEEP_RIGHT
from twolevel.world.traffic.manoeuvres import plans_of
from twolevel.world.traffic.pedestrians import crossing_path, walks_of
from twolevel.world.traffic.triggers import AFTER, TRIGGERS

__all__ = ["CYCLIST_IDM", "BOXES", "SLOT_PREFIX", "pose_of", "population_slots", "participants_of"]

_BEHAVIOURS = {"stationary": STATIONARY, "constant_velocity": CONSTANT_VELOCITY, "idm": IDM, "scripted": SCRIPTED,
               "walk": WALK}
CYCLIST_IDM = IDMParams(v0=5.0, T=1.0, s0=1.5, a=1.0, b=1.5)
"""A cyclist's IDM defaults (a stated choice: 18 km/h, urban cycling)."""
BOXES = {"bicycle": Box(length=1.8, width=0.65), "pedestrian": Box(length=0.5, width=0.6)}
"""Boxes by kind where the scenario gives none (a vehicle's and a parked car's: the schema's)."""
SLOT_PREFIX = "sumo:"
"""Ids of the participants another traffic engine fills (``sumo:0``, …): the scenario's
``traffic.slots`` of them, after its own participants, inactive until a vehicle takes one
(:mod:`twolevel.sim.cosim`)."""


def pose_of(p: Placement, lanes: LaneSet, index: dict[str, int]) -> tuple[float, float, float, int, float, float]:
    """x, y [m], psi [rad], lane index (−1), s [m], lateral [m] of a placement."""
    if p.lane is not None:
        i = index[p.lane]
        s = p.s or 0.0
        xy, h = lanes.pose(np.array([i]), np.array([s]), np.array([p.lateral]))
        return float(xy[0, 0]), float(xy[0, 1]), float(h[0]), i, s, p.lateral
    return float(p.x or 0.0), float(p.y or 0.0), math.radians(p.heading or 0.0), -1, 0.0, 0.0


def population_slots(pop: Population, lanes: LaneSet, index: dict[str, int], ego_lane: int, ego_s: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Places a population may use: (lane index, s [m]) one box length + ``min_gap`` apart along
    each of its lanes within ``s_range``, keeping that pitch clear of the ego."""
    pitch = _box(pop).length + pop.min_gap
    ls, ss = [], []
    for name in pop.lanes:
        li = index[name]
        lo, hi = pop.s_range or (0.0, float(lanes.length[li]))
        hi = min(hi, float(lanes.length[li]))
        slots = np.arange(lo + _box(pop).length / 2, hi - _box(pop).length / 2 + 1e-9, pitch)
        if li == ego_lane:
            slots = slots[np.abs(slots - ego_s) >= pitch]
        ls.append(np.full(len(slots), li))
        ss.append(slots)
    return np.concatenate(ls).astype(int), np.concatenate(ss)


def _box(who: Participant | Population) -> Box:
    return who.box if "box" in who.model_fields_set or who.kind not in BOXES else BOXES[who.kind]


def _idm_row(who: Participant | Population) -> list[float]:
    p = who.idm
    if who.kind == "bicycle":
        p = CYCLIST_IDM.model_copy(update={k: getattr(who.idm, k) for k in who.idm.model_fields_set})
    return [math.nan if p.v0 is None else p.v0, p.T, p.s0, p.a, p.b, p.delta]


def _mobil_row(m: MobilParams | None) -> list[float]:
    m = m or MobilParams()
    return [m.politeness, m.threshold, m.b_safe, m.bias_right, m.duration]


def _keeps_right(who: Participant | Population) -> bool:
    start = getattr(who, "start", None)
    return who.kind == "bicycle" and (start is None or "lateral" not in start.model_fields_set)


def _row(who: Participant | Population, rid: str, behaviour: int, pose: tuple[float, float, float, int, float, float],
         v: float, lanes: LaneSet) -> dict[str, Any]:
    x, y, psi, lane, s, lat = pose
    box = _box(who)
    right = _keeps_right(who) and lane >= 0
    if right:  # keep right: the pose moves across the lane
        lat = -max(0.0, float(lanes.width[lane]) / 2 - box.width / 2 - KEEP_RIGHT)
        xy, h = lanes.pose(np.array([lane]), np.array([s]), np.array([lat]))
        x, y, psi = float(xy[0, 0]), float(xy[0, 1]), float(h[0])
    return dict(id=rid, kind=behaviour, x=x, y=y, psi=psi, v=v, lane=lane, s=s, lat=lat, L=box.length, W=box.width,
                idm=_idm_row(who), mobil=_mobil_row(who.mobil), changes=who.mobil is not None,
                gap=who.critical_gap, right=KEEP_RIGHT if right else math.nan, user=user_of(who.kind), wp=[],
                plan=None, walk=None)


def _participant(p: Participant, lanes: LaneSet, index: dict[str, int]) -> dict[str, Any]:
    behaviour = p.behaviour_of
    code = MANOEUVRES if p.manoeuvres is not None else _BEHAVIOURS[behaviour]
    pose = pose_of(p.start, lanes, index) if p.start is not None else (0.0, 0.0, 0.0, -1, 0.0, 0.0)
    row = _row(p, p.id, code, pose, p.speed, lanes)
    if p.waypoints:
        wp = [(w.t, w.x, w.y) for w in p.waypoints]
        row.update(x=wp[0][1], y=wp[0][2], psi=math.atan2(wp[1][2] - wp[0][2], wp[1][1] - wp[0][1]), wp=wp)
    row["plan"] = p.manoeuvres
    if p.walk is not None:
        w = p.walk
        if w.lane is not None:
            origin, heading, length = crossing_path(lanes, index[w.lane], float(w.s or 0.0), w.side == "right")
        else:
            origin, heading, length = np.array([row["x"], row["y"]]), float(row["psi"]), float(w.distance or 0.0)
        trig = next((k for k in ("at", "ego_within", "ego_headway") if getattr(w, k) is not None), None)
        row.update(x=float(origin[0]), y=float(origin[1]), psi=heading, v=0.0, lane=-1, s=0.0, lat=0.0,
                   walk=(origin, heading, length, w.speed, AFTER if trig is None else TRIGGERS[trig],
                         0.0 if trig is None else float(getattr(w, trig)), w.gap, w.crosswalk, w.lane is not None))
    return row


def _slot(k: int, box: Box, lanes: LaneSet) -> dict[str, Any]:
    """Engine slot ``k``: a car of ``box`` the traffic engine moves (stationary to the built-in
    traffic, off the map until the engine fills it)."""
    car = Participant.model_construct(id=f"{SLOT_PREFIX}{k}", kind="car", box=box)  # placed by the engine, not here
    return _row(car, car.id, STATIONARY, (0.0, 0.0, 0.0, -1, 0.0, 0.0), 0.0, lanes)


def participants_of(spec: ScenarioFile, lanes: LaneSet, index: dict[str, int], assumptions: Assumptions,
                    ego_lane: int, ego_s: float) -> tuple[Participants, TrafficState]:
    """The participants (one by one, then each population's, deterministic for the seed, then the
    traffic engine's slots, inactive) and their state at t = 0."""
    rows = [_participant(p, lanes, index) for p in spec.participants]
    for pop in spec.populations:
        rng = np.random.default_rng(spec.run.seed if pop.seed is None else pop.seed)
        slot_lane, slot_s = population_slots(pop, lanes, index, ego_lane, ego_s)
        take = np.sort(rng.choice(len(slot_s), size=min(pop.count, len(slot_s)), replace=False))
        li, sv = slot_lane[take], slot_s[take]
        speeds = rng.uniform(*pop.speed_range, size=len(sv))
        xy, h = lanes.pose(li, sv)
        for j in range(len(sv)):
            pose = (float(xy[j, 0]), float(xy[j, 1]), float(h[j]), int(li[j]), float(sv[j]), 0.0)
            v = 0.0 if pop.behaviour == "stationary" else float(speeds[j])
            rows.append(_row(pop, f"{pop.id}-{j}", _BEHAVIOURS[pop.behaviour], pose, v, lanes))
    engine = spec.traffic.slots if spec.traffic is not None else 0
    rows += [_slot(k, spec.traffic.box, lanes) for k in range(engine)]  # type: ignore[union-attr]
    n = len(rows)
    wmax = max([len(r["wp"]) for r in rows] + [2])
    st = np.zeros((n, wmax))
    sxy = np.zeros((n, wmax, 2))
    for i, r in enumerate(rows):
        wp = r["wp"] or [(0.0, r["x"], r["y"]), (1.0, r["x"], r["y"])]
        arr = np.asarray(wp, dtype=float)
        st[i, : len(arr)], sxy[i, : len(arr)] = arr[:, 0], arr[:, 1:]
        st[i, len(arr):] = arr[-1, 0] + np.arange(1, wmax - len(arr) + 1)
        sxy[i, len(arr):] = arr[-1, 1:]
    col = lambda name, dtype=float: np.array([r[name] for r in rows], dtype=dtype).reshape(n)  # noqa: E731
    ids = tuple(str(r["id"]) for r in rows)
    user = np.array(kinds_of(ids, assumptions, default=[int(r["user"]) for r in rows]), dtype=int).reshape(n)
    bounds = np.array([[b.v_max, b.speed_factor, b.a_max, b.v_switch] for b in map(assumptions.bounds, user)],
                      dtype=float).reshape(n, 4)
    walks = walks_of(n, [(i, *r["walk"]) for i, r in enumerate(rows) if r["walk"] is not None], lanes)
    parts = Participants(ids, col("kind", int), col("L"), col("W"), np.array([r["idm"] for r in rows], dtype=float).reshape(n, 6),
                         st, sxy, user, bounds, np.array([r["mobil"] for r in rows], dtype=float).reshape(n, 5),
                         col("changes", bool), col("gap"), col("right"), plans_of([r["plan"] for r in rows], index),
                         walks, assumptions.response)
    state = TrafficState(0.0, col("x"), col("y"), col("psi"), col("v"), col("lane", int), col("s"), col("lat"),
                         np.arange(n) < n - engine, np.zeros(n), np.full(n, -1, dtype=int), Memory.fresh(n))
    return parts, state
