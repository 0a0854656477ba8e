"""CommonRoad scenarios written with commonroad-io's own writer: the importer's test cases and the
benchmark's default set (no public CommonRoad scenario ships in a wheel).

:func:`write_samples` writes five small scenarios — a straight road (two lanes one way, one the
other, a speed-limit sign), a curve, a merging ramp, a signalised intersection and one with a
stop sign — covering every obstacle type (parked, construction zone, car, truck, bus,
motorcycle, bicycle, pedestrian) and every goal form (rectangle with time, speed and heading
windows; circle; a goal lanelet; a group of shapes with an alternative state; a time window
only). :func:`grid_network` writes an ``n``-lanelet network for timing the import. Units: m, s,
rad; CommonRoad time steps of ``DT``.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Any, Callable

import numpy as np

__all__ = ["DT", "SAMPLES", "write_samples", "grid_network", "write_scenario", "lanelet_from_centre"]

DT = 0.1  # [s]
W = 3.5  # [m] lane width


def lanelet_from_centre(lid: int, centre: np.ndarray, width: float = W, **kw: Any) -> Any:
    """A lanelet around centre line ``centre`` (N, 2) [m]: boundaries ±width/2 along the normal."""
    from commonroad.scenario.lanelet import Lanelet

    d = np.gradient(centre, axis=0)
    n = np.c_[-d[:, 1], d[:, 0]] / np.linalg.norm(d, axis=1)[:, None]
    return Lanelet(centre + 0.5 * width * n, centre, centre - 0.5 * width * n, lid, **kw)


def _line(p0: Any, p1: Any, n: int = 11) -> np.ndarray:
    return np.linspace(np.asarray(p0, float), np.asarray(p1, float), n)


def _arc(cx: float, cy: float, r: float, a0: float, a1: float, n: int = 21) -> np.ndarray:
    a = np.linspace(a0, a1, n)
    return np.c_[cx + r * np.cos(a), cy + r * np.sin(a)]


def _scenario(name: str) -> Any:
    from commonroad.scenario.scenario import Scenario, ScenarioID

    return Scenario(DT, ScenarioID(country_id="DEU", map_name=name, map_id=1, configuration_id=1,
                                   obstacle_behavior="T", prediction_id=1))


def write_scenario(sc: Any, pps: Any, path: str | os.PathLike[str]) -> Path:
    """Write scenario ``sc`` and planning problems ``pps`` as CommonRoad XML at ``path``."""
    from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
    from commonroad.common.util import FileFormat

    logging.getLogger("commonroad").setLevel(logging.ERROR)
    CommonRoadFileWriter(sc, pps, author="twolevel", affiliation="twolevel", source="generated", tags=set(),
                         file_format=FileFormat.XML).write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    return Path(path)


def _moving(sc: Any, oid: int, typ: Any, shape: Any, p0: Any, heading: float, v: float, steps: int = 300) -> None:
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.obstacle import DynamicObstacle
    from commonroad.scenario.state import InitialState, KSState
    from commonroad.scenario.trajectory import Trajectory

    p0 = np.asarray(p0, float)
    u = np.array([math.cos(heading), math.sin(heading)])
    states = [KSState(time_step=k, position=p0 + k * DT * v * u, orientation=heading, velocity=v, steering_angle=0.0)
              for k in range(1, steps + 1)]
    init = InitialState(time_step=0, position=p0, orientation=heading, velocity=v, acceleration=0.0, yaw_rate=0.0,
                        slip_angle=0.0)
    sc.add_objects(DynamicObstacle(oid, typ, shape, init, TrajectoryPrediction(Trajectory(1, states), shape)))


def _problem(pid: int, pos: Any, v: float, goal: Any, heading: float = 0.0) -> Any:
    from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
    from commonroad.scenario.state import InitialState

    pps = PlanningProblemSet()
    pps.add_planning_problem(PlanningProblem(pid, InitialState(
        time_step=0, position=np.asarray(pos, float), orientation=heading, velocity=v,
        acceleration=0.0, yaw_rate=0.0, slip_angle=0.0), goal))
    return pps


def straight() -> tuple[Any, Any]:
    """Lanelets 1 (right) and 2 (left) eastwards, 3 westwards; a 20 m/s speed-limit sign; a parked
    car on the shoulder side, a car ahead, a bus oncoming. Goal: a rectangle with time, speed and
    heading windows."""
    from commonroad.common.util import AngleInterval, Interval
    from commonroad.geometry.shape import Rectangle
    from commonroad.planning.goal import GoalRegion
    from commonroad.scenario.lanelet import LaneletNetwork, LaneletType, LineMarking
    from commonroad.scenario.obstacle import ObstacleType, StaticObstacle
    from commonroad.scenario.state import CustomState, InitialState
    from commonroad.scenario.traffic_sign import TrafficSign, TrafficSignElement, TrafficSignIDGermany

    sc, net = _scenario("Straight"), LaneletNetwork()
    hw = {LaneletType.INTERSTATE, LaneletType.MAIN_CARRIAGE_WAY}
    net.add_lanelet(lanelet_from_centre(1, _line([0, 0], [300, 0], 31), adjacent_left=2, adjacent_left_same_direction=True,
                                        lanelet_type=hw, line_marking_left_vertices=LineMarking.DASHED,
                                        line_marking_right_vertices=LineMarking.SOLID, traffic_signs={100}))
    net.add_lanelet(lanelet_from_centre(2, _line([0, W], [300, W], 31), adjacent_right=1, adjacent_right_same_direction=True,
                                        adjacent_left=3, adjacent_left_same_direction=False, lanelet_type=hw,
                                        traffic_signs={100}))
    net.add_lanelet(lanelet_from_centre(3, _line([300, 2 * W], [0, 2 * W], 31), adjacent_left=2,
                                        adjacent_left_same_direction=False, lanelet_type=hw))
    net.add_traffic_sign(TrafficSign(100, [TrafficSignElement(TrafficSignIDGermany.MAX_SPEED, ["20.0"])], {1, 2},
                                     np.array([0.0, -3.0])), {1, 2})
    sc.add_objects(net)
    sc.add_objects(StaticObstacle(500, ObstacleType.PARKED_VEHICLE, Rectangle(4.5, 1.8),
                                  InitialState(time_step=0, position=np.array([60.0, -5.0]), orientation=0.0)))
    _moving(sc, 600, ObstacleType.CAR, Rectangle(4.5, 1.8), [40.0, 0.0], 0.0, 18.0, 250)
    _moving(sc, 601, ObstacleType.BUS, Rectangle(12.0, 2.5), [280.0, 2 * W], math.pi, 12.0, 250)
    goal = GoalRegion([CustomState(time_step=Interval(20, 250), position=Rectangle(10.0, 3.5, np.array([200.0, 0.0]), 0.0),
                                   velocity=Interval(5.0, 25.0), orientation=AngleInterval(-0.2, 0.2))])
    return sc, _problem(1000, [5.0, 0.0], 15.0, goal)


def curved() -> tuple[Any, Any]:
    """A straight lanelet into a left-turning quarter circle (radius 60 m); a truck ahead, a
    construction zone (polygon) beside the road. Goal: a circle."""
    from commonroad.common.util import Interval
    from commonroad.geometry.shape import Circle, Polygon, Rectangle
    from commonroad.planning.goal import GoalRegion
    from commonroad.scenario.lanelet import LaneletNetwork, LaneletType
    from commonroad.scenario.obstacle import ObstacleType, StaticObstacle
    from commonroad.scenario.state import CustomState, InitialState

    sc, net = _scenario("Curve"), LaneletNetwork()
    net.add_lanelet(lanelet_from_centre(1, _line([0, 0], [80, 0], 17), successor=[2], lanelet_type={LaneletType.COUNTRY}))
    net.add_lanelet(lanelet_from_centre(2, _arc(80, 60, 60, -math.pi / 2, 0, 31), predecessor=[1],
                                        lanelet_type={LaneletType.COUNTRY}))
    sc.add_objects(net)
    sc.add_objects(StaticObstacle(501, ObstacleType.CONSTRUCTION_ZONE, Polygon(np.array([[0, 0], [6, 0], [6, 2], [0, 2.0]])),
                                  InitialState(time_step=0, position=np.array([40.0, -6.0]), orientation=0.0)))
    _moving(sc, 602, ObstacleType.TRUCK, Rectangle(12.0, 2.5), [-60.0, 0.0], 0.0, 10.0)
    goal = GoalRegion([CustomState(time_step=Interval(0, 300), position=Circle(3.0, np.array([140.0, 60.0])))])
    return sc, _problem(1001, [5.0, 0.0], 10.0, goal)


def merging() -> tuple[Any, Any]:
    """A ramp (lanelet 20) joining the main lane 1 into lanelet 4; a motorcycle on the main lane.
    Goal: lanelet 4 (its polygon and its id)."""
    from commonroad.common.util import Interval
    from commonroad.geometry.shape import Polygon, Rectangle
    from commonroad.planning.goal import GoalRegion
    from commonroad.scenario.lanelet import LaneletNetwork, LaneletType
    from commonroad.scenario.obstacle import ObstacleType
    from commonroad.scenario.state import CustomState

    sc, net = _scenario("Merge"), LaneletNetwork()
    hw = {LaneletType.INTERSTATE, LaneletType.MAIN_CARRIAGE_WAY}
    ramp = np.c_[np.linspace(0, 100, 21), -12 + 12 * np.sin(np.linspace(0, math.pi / 2, 21))]
    net.add_lanelet(lanelet_from_centre(1, _line([0, 0], [100, 0], 11), successor=[4], lanelet_type=hw))
    net.add_lanelet(lanelet_from_centre(20, ramp, successor=[4], lanelet_type={LaneletType.ACCESS_RAMP, LaneletType.INTERSTATE}))
    net.add_lanelet(lanelet_from_centre(4, _line([100, 0], [200, 0], 11), predecessor=[1, 20], lanelet_type=hw))
    sc.add_objects(net)
    _moving(sc, 603, ObstacleType.MOTORCYCLE, Rectangle(2.2, 0.8), [60.0, 0.0], 0.0, 20.0, 200)
    lane4 = [[100, -W / 2], [200, -W / 2], [200, W / 2], [100, W / 2]]
    goal = GoalRegion([CustomState(time_step=Interval(0, 200), position=Polygon(np.array(lane4, float)))],
                      lanelets_of_goal_position={0: [4]})
    return sc, _problem(1002, [0.0, -12.0], 8.0, goal, math.atan(12 * math.pi / 2 / 100))


def _crossing(name: str, light: bool) -> tuple[Any, Any]:
    from commonroad.common.util import Interval
    from commonroad.geometry.shape import Circle, Rectangle, ShapeGroup
    from commonroad.planning.goal import GoalRegion
    from commonroad.scenario.intersection import Intersection, IntersectionIncomingElement
    from commonroad.scenario.lanelet import LaneletNetwork, LaneletType, LineMarking, StopLine
    from commonroad.scenario.obstacle import ObstacleType
    from commonroad.scenario.state import CustomState
    from commonroad.scenario.traffic_light import (TrafficLight, TrafficLightCycle, TrafficLightCycleElement,
                                                   TrafficLightState)
    from commonroad.scenario.traffic_sign import TrafficSign, TrafficSignElement, TrafficSignIDGermany

    sc, net = _scenario(name), LaneletNetwork()
    urban, inter = {LaneletType.URBAN}, {LaneletType.URBAN, LaneletType.INTERSECTION}
    stop = StopLine(np.array([-W / 2, 48.0]), np.array([W / 2, 48.0]), LineMarking.SOLID,
                    traffic_sign_ref=None if light else {101}, traffic_light_ref={200} if light else None)
    net.add_lanelet(lanelet_from_centre(30, _line([0, 0], [0, 50], 11), successor=[31, 32, 33], stop_line=stop,
                                        lanelet_type=urban, traffic_signs=set() if light else {101, 102},
                                        traffic_lights={200} if light else set()))
    net.add_lanelet(lanelet_from_centre(31, _line([0, 50], [0, 70], 5), predecessor=[30], successor=[40], lanelet_type=inter))
    net.add_lanelet(lanelet_from_centre(32, _arc(-10, 50, 10, 0, math.pi / 2), predecessor=[30], successor=[41],
                                        lanelet_type=inter))
    net.add_lanelet(lanelet_from_centre(33, _arc(10, 50, 10, math.pi, math.pi / 2), predecessor=[30], successor=[42],
                                        lanelet_type=inter))
    net.add_lanelet(lanelet_from_centre(40, _line([0, 70], [0, 150], 17), predecessor=[31], lanelet_type=urban))
    net.add_lanelet(lanelet_from_centre(41, _line([-10, 60], [-80, 60], 15), predecessor=[32], lanelet_type=urban))
    net.add_lanelet(lanelet_from_centre(42, _line([10, 60], [80, 60], 15), predecessor=[33], lanelet_type=urban))
    if light:
        cycle = TrafficLightCycle([TrafficLightCycleElement(TrafficLightState.RED, 40),
                                   TrafficLightCycleElement(TrafficLightState.RED_YELLOW, 10),
                                   TrafficLightCycleElement(TrafficLightState.GREEN, 100),
                                   TrafficLightCycleElement(TrafficLightState.YELLOW, 30)], time_offset=5)
        net.add_traffic_light(TrafficLight(200, np.array([3.0, 48.0]), traffic_light_cycle=cycle), {30})
    else:
        net.add_traffic_sign(TrafficSign(101, [TrafficSignElement(TrafficSignIDGermany.STOP)], {30},
                                         np.array([3.0, 47.0])), {30})
        net.add_traffic_sign(TrafficSign(102, [TrafficSignElement(TrafficSignIDGermany.YIELD)], {30},
                                         np.array([3.0, 40.0]), virtual=True), {30})
    net.add_intersection(Intersection(301, [IntersectionIncomingElement(300, incoming_lanelets={30}, successors_right={33},
                                                                        successors_straight={31}, successors_left={32})]))
    sc.add_objects(net)
    _moving(sc, 604, ObstacleType.PEDESTRIAN, Circle(0.35), [30.0, 75.0], 0.0, 1.3, 400)
    _moving(sc, 605, ObstacleType.BICYCLE, Rectangle(1.8, 0.6), [70.0, 60.0], 0.0, 4.0, 400)
    if light:
        goal = GoalRegion([CustomState(time_step=Interval(0, 400), position=ShapeGroup(
            [Rectangle(6, 3, np.array([0.0, 120.0])), Rectangle(6, 3, np.array([0.0, 130.0]))])),
            CustomState(time_step=Interval(380, 400))])
    else:
        goal = GoalRegion([CustomState(time_step=Interval(0, 300))])
    return sc, _problem(1003, [0.0, 5.0], 6.0, goal, math.pi / 2)


def intersection() -> tuple[Any, Any]:
    """A signalised intersection (red, red-yellow, green, yellow), its stop line, turns left,
    straight and right; a pedestrian and a cyclist. Goal: two rectangles and an alternative state."""
    return _crossing("Signal", light=True)


def stop_sign() -> tuple[Any, Any]:
    """The same intersection with a stop sign (and a yield sign twolevel cannot place). Goal: a time window only."""
    return _crossing("StopSign", light=False)


SAMPLES: dict[str, Callable[[], tuple[Any, Any]]] = {
    "DEU_Straight-1_1_T-1": straight, "DEU_Curve-1_1_T-1": curved, "DEU_Merge-1_1_T-1": merging,
    "DEU_Signal-1_1_T-1": intersection, "DEU_StopSign-1_1_T-1": stop_sign,
}
"""File stem → the function building that scenario and its planning problems."""


def write_samples(out_dir: str | os.PathLike[str]) -> list[Path]:
    """Write every sample scenario into ``out_dir`` (created): the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [write_scenario(*build(), out / f"{stem}.xml") for stem, build in SAMPLES.items()]


def grid_network(n: int, path: str | os.PathLike[str], points: int = 21) -> Path:
    """A network of ``n`` lanelets (rows of 50 m lanelets, three side by side, chained by
    successors, 30 m/s signs on every tenth) and one planning problem, written at ``path``."""
    from commonroad.common.util import Interval
    from commonroad.planning.goal import GoalRegion
    from commonroad.scenario.lanelet import LaneletNetwork, LaneletType
    from commonroad.scenario.state import CustomState
    from commonroad.scenario.traffic_sign import TrafficSign, TrafficSignElement, TrafficSignIDGermany

    sc, net = _scenario("Grid"), LaneletNetwork()
    per_row = 3
    cols = math.ceil(n / per_row)
    for i in range(n):
        col, row = divmod(i, per_row)
        lid = 1 + i
        y = row * W
        kw: dict[str, Any] = {"lanelet_type": {LaneletType.URBAN}}
        if col + 1 < cols and lid + per_row <= n:
            kw["successor"] = [lid + per_row]
        if col > 0:
            kw["predecessor"] = [lid - per_row]
        if row > 0:
            kw.update(adjacent_right=lid - 1, adjacent_right_same_direction=True)
        if row + 1 < per_row and lid + 1 <= n and (lid + 1 - 1) // per_row == col:
            kw.update(adjacent_left=lid + 1, adjacent_left_same_direction=True)
        if i % 10 == 0:
            kw["traffic_signs"] = {100000 + i}
        net.add_lanelet(lanelet_from_centre(lid, _line([50 * col, y], [50 * col + 50, y], points), **kw))
        if i % 10 == 0:
            net.add_traffic_sign(TrafficSign(100000 + i, [TrafficSignElement(TrafficSignIDGermany.MAX_SPEED, ["30"])],
                                             {lid}, np.array([50.0 * col, y - 3])), {lid})
    sc.add_objects(net)
    goal = GoalRegion([CustomState(time_step=Interval(0, 1000))], lanelets_of_goal_position=None)
    return write_scenario(sc, _problem(9_000_000, [1.0, 0.0], 10.0, goal), path)
