"""A run as CommonRoad files (``twolevel export RUN --format commonroad``), for CommonRoad's tools
and monitor (commonroad-io ≥ 2024.3: ``pip install 'twolevel[commonroad]'``).

Writes into the output folder:

* ``<scenario id>.xml`` — the run's world as a CommonRoad scenario: every lane a lanelet (its
  boundaries; lanes ``L<n>`` keep id n, the others get fresh ids), successors, predecessors,
  adjacency, use and road categories, markings; the limit in force at each lane's start a
  MAX_SPEED sign; stop signs (STOP) and lights (their cycle) with stop lines; participants as
  obstacles (stationary ones static, scripted ones with their trajectory over the run); **the
  ego as a dynamic obstacle** with its executed trajectory; the planning problem (the ego's start,
  a goal rectangle at the route's goal with the time window of ``expect.goal``);
* ``solution_<scenario id>.xml`` — a CommonRoad solution: the executed trajectory as
  kinematic single-track (KS) states, vehicle type BMW 320i, cost function SM1.

The scenario id is the run's scenario name when it is a CommonRoad benchmark id (an imported
scenario keeps its own), else ``ZAM_<name>-1_1_T-1``. What the format cannot hold (participants
whose motion depends on the ego: IDM and constant-velocity ones are exported standing at their
start) is listed (``IMP730``). Units: m, s, rad, m/s.
"""

from __future__ import annotations

import logging
import math
import os
import re
from pathlib import Path
from typing import Any

from twolevel.diagnostics import Diagnostic, Span
from twolevel.interop.codes import IMP704, IMP730
from twolevel.world.codes import YML401

__all__ = ["export_commonroad", "scenario_id_of"]

_TYPES = {"shoulder": "SHOULDER", "bus": "BUS_LANE", "bicycle": "BICYCLE_LANE", "sidewalk": "SIDEWALK",
          "crosswalk": "CROSSWALK", "parking": "PARKING", "restricted": "RESTRICTED"}
_CATEGORIES = {"interstate": "INTERSTATE", "highway": "HIGHWAY", "country": "COUNTRY", "urban": "URBAN",
               "main_carriageway": "MAIN_CARRIAGE_WAY", "access_ramp": "ACCESS_RAMP", "exit_ramp": "EXIT_RAMP",
               "drive_way": "DRIVE_WAY", "intersection": "INTERSECTION"}
_MARKINGS = {"none": "NO_MARKING", "dashed": "DASHED", "solid": "SOLID", "double_solid": "SOLID_SOLID",
             "dashed_solid": "DASHED_SOLID", "solid_dashed": "SOLID_DASHED", "curb": "CURB"}
_OBSTACLES = {"car": "CAR", "truck": "TRUCK", "bus": "BUS", "motorcycle": "MOTORCYCLE", "bicycle": "BICYCLE",
              "pedestrian": "PEDESTRIAN", "other": "UNKNOWN"}


def scenario_id_of(name: str) -> Any:
    """A CommonRoad ScenarioID for a run's scenario ``name``."""
    from commonroad.scenario.scenario import ScenarioID

    if re.fullmatch(r"[A-Z]{3}_[A-Za-z0-9]+-\d+(_\d+(_[ST]-\d+)?)?", name or ""):
        sid = ScenarioID.from_benchmark_id(name, "2020a")
    else:
        word = re.sub(r"[^A-Za-z0-9]", "", (name or "Twolevel").title()) or "Twolevel"
        sid = ScenarioID(country_id="ZAM", map_name=word, map_id=1)
    sid.configuration_id, sid.obstacle_behavior, sid.prediction_id = sid.configuration_id or 1, "T", sid.prediction_id or 1
    return sid


class _Ids:
    """CommonRoad ids (one namespace per scenario): lanes ``L<n>`` and participants ``O<n>`` keep
    n (as the importer named them); everything else gets the next id above all of them."""

    def __init__(self, lane_ids: list[str], participant_ids: list[str]) -> None:
        self.kept = {("lane", lid): int(lid[1:]) for lid in lane_ids if re.fullmatch(r"L\d+", lid)}
        taken = set(self.kept.values())
        for pid in participant_ids:
            if re.fullmatch(r"O\d+", pid) and int(pid[1:]) not in taken:
                self.kept[("participant", pid)] = int(pid[1:])
                taken.add(int(pid[1:]))
        self.next = max(taken, default=0) + 1

    def fresh(self) -> int:
        self.next += 1
        return self.next - 1

    def of(self, what: str, name: str) -> int:
        """The id of lane or participant ``name`` (``what``: ``lane`` or ``participant``)."""
        if (what, name) not in self.kept:
            self.kept[(what, name)] = self.fresh()
        return self.kept[(what, name)]


def _lanelets(world: Any, spec: Any, ids: _Ids) -> tuple[Any, dict[int, int]]:
    """The lane network: a LaneletNetwork and lane index → lanelet id."""
    import numpy as np
    from commonroad.scenario.lanelet import Lanelet, LaneletNetwork, LaneletType, LineMarking

    lanes = world.lanes
    lid_of = {i: ids.of("lane", lane.id) for i, lane in enumerate(lanes.lanes)}
    declared = {ln.id: ln for road in spec.roads for ln in road.lane_specs()} | {ln.id: ln for ln in spec.lanes}
    net = LaneletNetwork()
    for i, lane in enumerate(lanes.lanes):
        if lane.left_bound is not None and lane.right_bound is not None:
            left, right = np.asarray(lane.left_bound, float), np.asarray(lane.right_bound, float)
        else:
            s = lane.s
            half = 0.5 * lane.width_at(s)
            left, right = lane.position(s, half), lane.position(s, -half)
        centre = 0.5 * (left + right)
        succ = [lid_of[int(j)] for j in lanes.succ[lanes.succ_ptr[i]:lanes.succ_ptr[i + 1]]]
        pred = [lid_of[int(j)] for j in lanes.pred[lanes.pred_ptr[i]:lanes.pred_ptr[i + 1]]]
        d = declared.get(lane.id)
        types = {LaneletType[_TYPES[lane.kind]]} if lane.kind in _TYPES else set()
        types |= {LaneletType[_CATEGORIES[c]] for c in (getattr(d, "categories", None) or [])}
        if not types:
            types = {LaneletType.UNKNOWN}
        kw: dict[str, Any] = {"predecessor": pred, "successor": succ, "lanelet_type": types}
        for side, adj, same in (("left", lanes.adj_left[i], lanes.adj_left_same[i]),
                                ("right", lanes.adj_right[i], lanes.adj_right_same[i])):
            if adj >= 0:
                kw[f"adjacent_{side}"] = lid_of[int(adj)]
                kw[f"adjacent_{side}_same_direction"] = bool(same)
        for side in ("left", "right"):
            mark = getattr(d, f"{side}_marking", None) if d is not None else None
            if mark in _MARKINGS:
                kw[f"line_marking_{side}_vertices"] = LineMarking[_MARKINGS[mark]]
        net.add_lanelet(Lanelet(left, centre, right, lid_of[i], **kw))
    return net, lid_of


def _stop_line(net: Any, lanelet: int, world: Any, lane: int, s: float, **refs: Any) -> None:
    import numpy as np
    from commonroad.scenario.lanelet import LineMarking, StopLine

    half = 0.5 * float(world.lanes.width_at(np.array([lane]), np.array([s]))[0])
    ln = world.lanes.lanes[lane]
    a, b = ln.position(s, half), ln.position(s, -half)
    net.find_lanelet_by_id(lanelet).stop_line = StopLine(np.asarray(a, float).ravel(), np.asarray(b, float).ravel(),
                                                         LineMarking.SOLID, **refs)


def _signs_and_lights(world: Any, net: Any, lid_of: dict[int, int], ids: _Ids, diags: list[Diagnostic],
                      span: Span) -> None:
    import numpy as np
    from commonroad.scenario.traffic_light import (TrafficLight, TrafficLightCycle, TrafficLightCycleElement,
                                                   TrafficLightState)
    from commonroad.scenario.traffic_sign import TrafficSign, TrafficSignElement, TrafficSignIDZamunda

    lanes = world.lanes
    n = len(lanes.lanes)
    if n and len(world.limits.value):
        start = world.limits.at(np.arange(n), np.full(n, 1e-6))
        for value in sorted(set(np.round(start, 3).tolist())):
            on = [lid_of[i] for i in range(n) if round(float(start[i]), 3) == value]
            sid = ids.fresh()
            first = lanes.lanes[int(np.flatnonzero(np.round(start, 3) == value)[0])].position(0.0)
            net.add_traffic_sign(TrafficSign(sid, [TrafficSignElement(TrafficSignIDZamunda.MAX_SPEED, [f"{value:g}"])],
                                             set(on), np.asarray(first, float).ravel()), set(on))
    for k in range(len(world.stops.ids)):
        lane, s = int(world.stops.lane[k]), float(world.stops.s[k])
        sid = ids.fresh()
        pos = np.asarray(lanes.lanes[lane].position(s), float).ravel()
        net.add_traffic_sign(TrafficSign(sid, [TrafficSignElement(TrafficSignIDZamunda.STOP)], {lid_of[lane]}, pos),
                             {lid_of[lane]})
        _stop_line(net, lid_of[lane], world, lane, s, traffic_sign_ref={sid})
    L = world.lights
    dt = world.settings.dt
    names = {0: TrafficLightState.GREEN, 1: TrafficLightState.YELLOW, 2: TrafficLightState.RED}
    for k in range(len(L.ids)):
        lane, s = int(L.lane[k]), float(L.s[k])
        times = L.times[k][np.isfinite(L.times[k])]
        states = L.states[k][: len(times)]
        period = float(L.period[k]) if np.isfinite(L.period[k]) else max(world.settings.duration, float(times[-1]) + dt)
        ends = np.append(times[1:], period)
        steps = np.maximum(np.round((ends - times) / dt).astype(int), 0)
        elements = [TrafficLightCycleElement(names[int(st)], int(d)) for st, d in zip(states, steps) if d > 0]
        if not np.isfinite(L.period[k]):
            diags.append(IMP730(f"light {L.ids[k]}'s script is exported as one cycle of {period:g} s", span))
        offset = int(round((-float(L.offset[k]) % period) / dt)) if np.isfinite(L.period[k]) else 0
        tid = ids.fresh()
        pos = np.asarray(lanes.lanes[lane].position(s), float).ravel()
        net.add_traffic_light(TrafficLight(tid, pos, TrafficLightCycle(elements, time_offset=offset)), {lid_of[lane]})
        _stop_line(net, lid_of[lane], world, lane, s, traffic_light_ref={tid})


def _shape(kind: str, length: float, width: float) -> Any:
    from commonroad.geometry.shape import Circle, Rectangle

    return Circle(0.5 * max(length, width)) if kind == "pedestrian" else Rectangle(length, width)


def _obstacles(world: Any, spec_parts: list[Any], ids: _Ids, diags: list[Diagnostic], span: Span) -> list[Any]:
    import numpy as np
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType, StaticObstacle
    from commonroad.scenario.state import InitialState, PMState
    from commonroad.scenario.trajectory import Trajectory

    P, tr = world.parts, world.traffic0
    kinds = {p.id: p.kind for p in spec_parts}
    behaviour = {p.id: p.behaviour for p in spec_parts}
    dt = world.settings.dt
    steps = int(round(world.settings.duration / dt))
    out = []
    for i, pid in enumerate(P.ids):
        oid = ids.of("participant", pid)
        kind = kinds.get(pid.rsplit("-", 1)[0] if pid not in kinds else pid, "car")
        shape = _shape(kind, float(P.length[i]), float(P.width[i]))
        init = InitialState(time_step=0, position=np.array([tr.x[i], tr.y[i]], float), orientation=float(tr.psi[i]),
                            velocity=float(tr.v[i]), acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
        how = behaviour.get(pid, "population")
        if how == "scripted":
            t = np.arange(steps + 1) * dt
            st, sxy = P.script_t[i], P.script_xy[i]
            x, y = np.interp(t, st, sxy[:, 0]), np.interp(t, st, sxy[:, 1])
            vx, vy = np.gradient(x, dt), np.gradient(y, dt)
            states = [PMState(time_step=k, position=np.array([x[k], y[k]]), velocity=float(vx[k]),
                              velocity_y=float(vy[k])) for k in range(1, steps + 1)]
            init = InitialState(time_step=0, position=np.array([x[0], y[0]]), orientation=float(np.arctan2(vy[0], vx[0]))
                                if math.hypot(vx[0], vy[0]) > 1e-9 else float(tr.psi[i]), velocity=float(math.hypot(vx[0], vy[0])),
                                acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
            out.append(DynamicObstacle(oid, ObstacleType[_OBSTACLES[kind]], shape, init,
                                       TrajectoryPrediction(Trajectory(1, states), shape)))
            continue
        if how != "stationary":
            diags.append(IMP730(f"participant {pid} ({how}) reacts to the ego: exported standing at its start", span))
        if kind in ("pedestrian", "bicycle"):  # the format's static obstacles are vehicles, zones and boundaries
            states = [PMState(time_step=k, position=init.position, velocity=0.0, velocity_y=0.0) for k in range(1, steps + 1)]
            out.append(DynamicObstacle(oid, ObstacleType[_OBSTACLES[kind]], shape, init,
                                       TrajectoryPrediction(Trajectory(1, states), shape)))
        else:
            out.append(StaticObstacle(oid, ObstacleType.PARKED_VEHICLE if kind != "other" else ObstacleType.UNKNOWN,
                                      shape, InitialState(time_step=0, position=init.position, orientation=init.orientation)))
    return out


def _ks_states(cols: Any) -> list[Any]:
    import numpy as np
    from commonroad.scenario.state import KSState

    x, y, psi, v, delta = (np.asarray(cols[c], float) for c in ("x", "y", "psi", "v", "delta"))
    return [KSState(time_step=k, position=np.array([x[k], y[k]]), steering_angle=float(delta[k]), velocity=float(v[k]),
                    orientation=float(psi[k])) for k in range(len(x))]


def _problem(world: Any, spec: Any, ego0: Any, dt: float, pid: int) -> Any:
    import numpy as np
    from commonroad.common.util import Interval
    from commonroad.geometry.shape import Rectangle
    from commonroad.planning.goal import GoalRegion
    from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
    from commonroad.scenario.state import CustomState, InitialState

    route = world.route
    end = float(route.s[-1])
    p = np.asarray(route.position(end), float).ravel()[:2]
    h = float(np.asarray(route.heading_at(end)).ravel()[0])
    width = float(np.asarray(route.width_at(end)).ravel()[0])
    goal = spec.expect.goal
    lo = int(round(goal.after / dt)) if goal is not None and goal.after is not None else 0
    hi = int(round((goal.by if goal is not None and goal.by is not None else world.settings.duration) / dt))
    region = CustomState(time_step=Interval(lo, max(hi, lo)), position=Rectangle(4.0, width, p, h))
    init = InitialState(time_step=0, position=np.array([ego0.position[0], ego0.position[1]]), orientation=ego0.orientation,
                        velocity=ego0.velocity, acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
    pps = PlanningProblemSet()
    pps.add_planning_problem(PlanningProblem(pid, init, GoalRegion([region])))
    return pps


def export_commonroad(run_dir: str | os.PathLike[str], out_dir: str | os.PathLike[str]) -> tuple[list[Path], list[Diagnostic]]:
    """Write the run in ``run_dir`` as CommonRoad files into ``out_dir``: (paths, findings)."""
    run_dir = str(run_dir)
    span = Span.whole_file(os.path.join(run_dir, "run.json"))
    try:
        import commonroad  # noqa: F401
    except ImportError:
        return [], [IMP704("writing CommonRoad files needs commonroad-io", span, hint="pip install 'twolevel[commonroad]'")]
    import numpy as np
    from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
    from commonroad.common.solution import (CommonRoadSolutionWriter, CostFunction, PlanningProblemSolution, Solution,
                                            VehicleModel, VehicleType)
    from commonroad.common.util import FileFormat
    from commonroad.geometry.shape import Rectangle
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType
    from commonroad.scenario.scenario import Scenario
    from commonroad.scenario.state import InitialState
    from commonroad.scenario.trajectory import Trajectory

    from twolevel.sim.trace import read_run
    from twolevel.world.loader import load_scenario
    from twolevel.world.world import build_world

    run = read_run(run_dir)
    path = (run.meta.get("scenario") or {}).get("path")
    if run.rows < 2 or not path:
        why = "; ".join(run.problems) or "fewer than two steps recorded"
        return [], [YML401(f"'{run_dir}' holds no run to export: {why}", span)]
    scn, diags = load_scenario(path)
    if scn is None:
        return [], [YML401(f"the run's scenario '{path}' cannot be loaded", span)] + diags
    logging.getLogger("commonroad").setLevel(logging.ERROR)
    world = build_world(scn)
    dt = float(world.settings.dt)
    found: list[Diagnostic] = []
    ids = _Ids([lane.id for lane in world.lanes.lanes], list(world.parts.ids))
    sid = scenario_id_of(scn.spec.name)
    sc = Scenario(dt, sid)
    net, lid_of = _lanelets(world, scn.map.spec, ids)
    _signs_and_lights(world, net, lid_of, ids, found, span)
    sc.add_objects(net)
    for ob in _obstacles(world, list(scn.spec.participants), ids, found, span):
        sc.add_objects(ob)
    ks = _ks_states(run.columns)
    ego_id, pp_id = ids.fresh(), ids.fresh()
    box = Rectangle(world.ego.length, world.ego.width)
    ego0 = ks[0]
    init = InitialState(time_step=0, position=ego0.position, orientation=ego0.orientation, velocity=ego0.velocity,
                        acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
    sc.add_objects(DynamicObstacle(ego_id, ObstacleType.CAR, box, init, TrajectoryPrediction(Trajectory(1, ks[1:]), box)))
    pps = _problem(world, scn.spec, ego0, dt, pp_id)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scenario_file = out / f"{sid}.xml"
    CommonRoadFileWriter(sc, pps, author="twolevel", affiliation="twolevel", source=f"twolevel run {os.path.basename(run_dir)}",
                         tags=set(), file_format=FileFormat.XML).write_to_file(str(scenario_file), OverwriteExistingFile.ALWAYS)
    cpu = run.columns.get("t_step_cpu_ms", run.columns.get("t_step_ms"))
    seconds = float(np.nansum(cpu)) / 1000.0 if cpu is not None else 0.0
    sol = Solution(sid, [PlanningProblemSolution(planning_problem_id=pp_id, vehicle_model=VehicleModel.KS,
                                                 vehicle_type=VehicleType.BMW_320i, cost_function=CostFunction.SM1,
                                                 trajectory=Trajectory(0, ks))],
                   computation_time=seconds, processor_name="twolevel")
    solution_file = out / f"solution_{sid}.xml"
    CommonRoadSolutionWriter(sol).write_to_file(output_path=str(out), filename=solution_file.name, overwrite=True)
    return [scenario_file, solution_file], found
