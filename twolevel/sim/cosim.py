"""SUMO traffic in the closed loop: libsumo in the same process, the ego moved in SUMO each step.

As CARLA's co-simulation bridge does it: the ego is a SUMO vehicle (``twolevel_ego``) that SUMO
does not drive; each step it is put where twolevel's plant has it (``moveToXY`` with
``keepRoute=2``: the nearest lane of any edge, the route replaced), then SUMO steps. SUMO's
vehicles therefore see the ego as a leader, at junctions and in lane changes, and brake for it;
they keep SUMO's right of way and SUMO's traffic-light programs (which the imported map carries
as its lights, :mod:`twolevel.interop.sumo`, so the ego's rules see the same states).

The exchange stays small: only vehicles within ``radius`` of the ego are read, by one context
subscription (position, angle, speed, length, lane and position on it), and the nearest
``slots`` of them fill the world's engine slots (:data:`twolevel.world.participants.SLOT_PREFIX`): a
vehicle keeps its slot while it stays near. SUMO's position is the front bumper's centre and its
angle is clockwise from north in degrees; twolevel's is the box's centre, counter-clockwise from
x in radians. The scenario's own participants are stepped by the built-in traffic (SUMO's
vehicles are leaders for them, they are not seen by SUMO).

Deterministic for a seed: SUMO's ``--seed`` and the random trips' draws (numpy's generator).
An error libsumo raises once SUMO runs (a vehicle of the route files it cannot insert when it is
due, a route it cannot build) is a :class:`~twolevel.sim.traffic_engine.TrafficFailure` with
SUMO's words and the time: the run ends ``aborted`` with SIM632, never a traceback.
libsumo is one simulation per process: a new run closes the one before.
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import replace
from typing import Any, Iterator

import numpy as np

from twolevel.diagnostics import Diagnostic, Span
from twolevel.sim.codes import SIM630, SIM631
from twolevel.sim.traffic_engine import BuiltinTraffic, TrafficFailure
from twolevel.world import traffic as tr
from twolevel.world.participants import SLOT_PREFIX
from twolevel.world.schema import SumoTraffic as SumoSpec
from twolevel.world.world import World

__all__ = ["SumoTraffic", "EGO_ID", "sumo_angle", "front_of"]

EGO_ID = "twolevel_ego"
"""The ego's id in SUMO."""
_ROUTE = "twolevel_ego_route"


def sumo_angle(psi: np.ndarray | float) -> np.ndarray | float:
    """SUMO's angle [deg, clockwise from north] of a heading ``psi`` [rad, counter-clockwise from x]."""
    return (90.0 - np.degrees(psi)) % 360.0


def front_of(x: float, y: float, psi: float, length: float) -> tuple[float, float]:
    """The front bumper's centre [m] of a box centred at (x, y) [m] heading ``psi`` [rad]."""
    return x + 0.5 * length * math.cos(psi), y + 0.5 * length * math.sin(psi)


class SumoTraffic:
    """The SUMO engine of one run (see the module docstring). ``sumo_ms`` and ``exchange_ms``
    hold each step's cost [ms]: SUMO's own step (with the random trips' top-up), and moving the
    ego plus reading and converting the vehicles near it."""

    def __init__(self, world: World, spec: SumoSpec, ls: Any, seed: int) -> None:
        self.world, self.spec, self.ls = world, spec, ls
        self.rng = np.random.default_rng(seed)
        ids = world.parts.ids
        self.first = next((i for i, name in enumerate(ids) if name.startswith(SLOT_PREFIX)), len(ids))
        self.k = len(ids) - self.first
        self.slot_of: dict[str, int] = {}
        self.free = list(range(self.k))
        self.sumo_ms: list[float] = []
        self.exchange_ms: list[float] = []
        self.lane_scale: dict[str, tuple[int, float]] = {}
        self.edges: list[str] = []
        self.trips = 0
        self.open = True

    # ------------------------------------------------------------------------------ set-up
    @classmethod
    def launch(cls, world: World, spec: SumoSpec, scenario: str) -> tuple["SumoTraffic | None", list[Diagnostic]]:
        """Start SUMO on the scenario's network and routes; None and SIM630/SIM631 when it cannot."""
        where = Span.whole_file(scenario)
        try:
            import libsumo as ls  # noqa: PLC0415 - the optional 'sumo' extra
        except ImportError:
            return None, [SIM630("SUMO traffic needs libsumo, which is not installed", where,
                                 hint="pip install 'twolevel[sumo]'")]
        seed = world.settings.seed if spec.seed is None else spec.seed
        seed = int(seed) % (2**31 - 1)
        args = ["sumo", "-n", spec.net, "--step-length", f"{world.settings.dt:.9g}", "--seed", str(seed),
                "--no-step-log", "true", "--no-warnings", "true", "--collision.action", "warn",
                "--time-to-teleport", "-1", "--begin", "0"]
        if spec.routes:
            args += ["-r", ",".join(spec.routes)]
        if ls.simulation.isLoaded():
            ls.close()
        try:
            ls.start(args)
        except Exception as exc:  # libsumo's TraCIException / FatalTraCIError
            return None, [SIM631(f"SUMO did not start: {exc}", where,
                                 hint="check the network and route files with sumo -n NET -r ROUTES")]
        return cls(world, spec, ls, seed), []

    def start(self, state: tr.TrafficState, ego: tr.EgoBox) -> tr.TrafficState:
        """Insert the ego where it starts (on the edge there), subscribe to the vehicles around it,
        and insert the random trips; the traffic at t = 0 is the world's (SUMO inserts its
        vehicles in its first step). A failure of SUMO's is a :class:`TrafficFailure`."""
        with self._failing_at(state.t):
            return self._start(state, ego)

    def _start(self, state: tr.TrafficState, ego: tr.EgoBox) -> tr.TrafficState:
        ls = self.ls
        tc = ls.constants
        fx, fy = front_of(ego.x, ego.y, ego.psi, ego.length)
        edge, pos, lane = ls.simulation.convertRoad(fx, fy, False, "passenger")
        if edge.startswith(":"):  # inside a junction: a route needs a normal edge; moveToXY places it anyway
            edge, pos, lane = ls.lane.getLinks(f"{edge}_{lane}")[0][0].rsplit("_", 1)[0], 0.0, 0
        ls.route.add(_ROUTE, [edge])
        ls.vehicle.add(EGO_ID, _ROUTE, departLane=str(lane), departPos=f"{max(pos, 0.0):.3f}",
                       departSpeed=f"{ego.v:.3f}")
        ls.vehicle.setLength(EGO_ID, ego.length)
        ls.vehicle.setColor(EGO_ID, (255, 0, 0, 255))
        ls.vehicle.setSpeedMode(EGO_ID, 0)
        ls.vehicle.setLaneChangeMode(EGO_ID, 0)
        ls.vehicle.subscribeContext(EGO_ID, tc.CMD_GET_VEHICLE_VARIABLE, float(self.spec.radius),
                                    [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_LENGTH, tc.VAR_LANE_ID,
                                     tc.VAR_LANEPOSITION])
        self._move(ego)
        if self.spec.random_trips is not None:
            allowed = lambda lane: not lane or "passenger" in lane  # noqa: E731 - empty: every class
            self.edges = sorted(e for e in ls.edge.getIDList()
                                if not e.startswith(":") and any(allowed(ls.lane.getAllowed(f"{e}_{i}"))
                                                                 for i in range(ls.edge.getLaneNumber(e))))
            self._top_up()
        return state

    # ------------------------------------------------------------------------------ each step
    def step(self, state: tr.TrafficState, dt: float, ego: tr.EgoBox, ego_next: tr.EgoBox) -> tr.TrafficState:
        """The scenario's own participants by the built-in traffic, then the ego moved to
        ``ego_next`` in SUMO, SUMO's step, and the vehicles near the ego into the slots. A failure
        of SUMO's is a :class:`TrafficFailure`."""
        with self._failing_at(state.t + dt):
            return self._step(state, dt, ego, ego_next)

    @contextlib.contextmanager
    def _failing_at(self, t: float) -> Iterator[None]:
        """libsumo's errors (TraCIException, FatalTraCIError) inside as a :class:`TrafficFailure`
        at simulated time ``t`` [s], with what to check."""
        try:
            yield
        except (self.ls.TraCIException, self.ls.FatalTraCIError) as exc:
            files = " ".join(["-n", self.spec.net] + (["-r", ",".join(self.spec.routes)] if self.spec.routes else []))
            raise TrafficFailure(
                str(exc).strip() or type(exc).__name__, t,
                f"SUMO rejected its network or route files when it reached t = {t:g} s; run them alone to see "
                f"SUMO's own report (sumo {files} --end {math.ceil(t) + 1}) and fix the vehicle, route or "
                "flow it names") from exc

    def _step(self, state: tr.TrafficState, dt: float, ego: tr.EgoBox, ego_next: tr.EgoBox) -> tr.TrafficState:
        if self.first:
            state = BuiltinTraffic(self.world).step(state, dt, ego, ego_next)
        else:
            state = replace(state, t=state.t + dt)
        a = time.perf_counter()
        self._move(ego_next)
        b = time.perf_counter()
        self.ls.simulationStep()
        if self.spec.random_trips is not None:
            self._top_up()
        c = time.perf_counter()
        state = self._read(state)
        d = time.perf_counter()
        self.sumo_ms.append((c - b) * 1e3)
        self.exchange_ms.append((b - a + d - c) * 1e3)
        return state

    def _move(self, ego: tr.EgoBox) -> None:
        fx, fy = front_of(ego.x, ego.y, ego.psi, ego.length)
        self.ls.vehicle.moveToXY(EGO_ID, "", -1, fx, fy, float(sumo_angle(ego.psi)), keepRoute=2)

    def _top_up(self) -> None:
        """New random trips until ``random_trips.vehicles`` are running or waiting to enter."""
        ls = self.ls
        kept = self.spec.random_trips.vehicles  # type: ignore[union-attr]
        missing = kept - (ls.vehicle.getIDCount() - 1) - len(ls.simulation.getPendingVehicles())  # the ego is one
        n = len(self.edges)
        for _ in range(max(missing, 0)):
            for _try in range(10):
                a, b = self.rng.choice(n, 2, replace=False)
                route = ls.simulation.findRoute(self.edges[a], self.edges[b]).edges
                if route:
                    break
            else:
                continue
            name = f"trip{self.trips}"
            self.trips += 1
            ls.route.add(name, list(route))
            ls.vehicle.add(name, name, departLane="best", departPos="random", departSpeed="max")

    def _read(self, state: tr.TrafficState) -> tr.TrafficState:
        """The vehicles near the ego into the slots: the nearest ``slots`` keep or take one."""
        ls = self.ls
        tc = ls.constants
        near = ls.vehicle.getContextSubscriptionResults(EGO_ID)
        near.pop(EGO_ID, None)
        ids = sorted(near)
        if len(ids) > self.k:
            ex, ey = ls.vehicle.getPosition(EGO_ID)
            dist = {vid: math.hypot(near[vid][tc.VAR_POSITION][0] - ex, near[vid][tc.VAR_POSITION][1] - ey) for vid in ids}
            ids = sorted(sorted(ids, key=lambda vid: (dist[vid], vid))[: self.k])
        keep = set(ids)
        for vid in [v for v in self.slot_of if v not in keep]:
            self.free.append(self.slot_of.pop(vid))
        self.free.sort(reverse=True)
        for vid in ids:
            if vid not in self.slot_of:
                self.slot_of[vid] = self.free.pop()
        k, first = self.k, self.first
        x, y, psi, v = (a[first:].copy() for a in (state.x, state.y, state.psi, state.v))
        lane, s = state.lane[first:].copy(), state.s[first:].copy()
        active = np.zeros(k, dtype=bool)
        if ids:
            rows = [near[vid] for vid in ids]
            slot = np.fromiter((self.slot_of[vid] for vid in ids), dtype=int, count=len(ids))
            pos = np.array([r[tc.VAR_POSITION] for r in rows], dtype=float)
            h = np.radians(90.0 - np.array([r[tc.VAR_ANGLE] for r in rows], dtype=float))
            half = 0.5 * np.array([r[tc.VAR_LENGTH] for r in rows], dtype=float)
            x[slot], y[slot] = pos[:, 0] - half * np.cos(h), pos[:, 1] - half * np.sin(h)
            psi[slot], v[slot] = h, [r[tc.VAR_SPEED] for r in rows]
            li, scale = zip(*(self._lane(r[tc.VAR_LANE_ID]) for r in rows))
            lane[slot] = li
            s[slot] = np.maximum(np.array([r[tc.VAR_LANEPOSITION] for r in rows]) * np.array(scale) - half, 0.0)
            active[slot] = True
        cat = lambda a, b: np.concatenate([a[:first], b])  # noqa: E731
        return replace(state, x=cat(state.x, x), y=cat(state.y, y), psi=cat(state.psi, psi), v=cat(state.v, v),
                       lane=cat(state.lane, np.where(active, lane, -1)), s=cat(state.s, s),
                       lateral=cat(state.lateral, np.zeros(k)), active=cat(state.active, active))

    def _lane(self, lane_id: str) -> tuple[int, float]:
        """The twolevel lane of a SUMO lane id (−1 if the map has none) and the factor from SUMO's
        position on it to twolevel's [m/m] (their lengths may differ slightly)."""
        got = self.lane_scale.get(lane_id)
        if got is None:
            i = self.world.lanes.index.get(lane_id, -1)
            sumo_len = float(self.ls.lane.getLength(lane_id)) if lane_id else 0.0
            got = (i, float(self.world.lanes.length[i]) / sumo_len if i >= 0 and sumo_len > 0 else 1.0)
            self.lane_scale[lane_id] = got
        return got

    def close(self) -> None:
        """End SUMO (idempotent)."""
        if self.open:
            self.open = False
            if self.ls.simulation.isLoaded():
                self.ls.close()
