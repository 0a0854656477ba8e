"""CommonRoad's side of the cross-check: runs in crmonitor's own virtual environment (built by
``make crosscheck``; commonroad-stl-monitor pins its own RTAMT, commonroad-io 2024.3 and torch,
so it cannot share twolevel's). It imports nothing of twolevel.

    python crmonitor_side.py CASES.json RESULTS.json [--xml-dir DIR]

CASES.json (written by ``run.py``): ``{"cases": {name: case}}``, each case a straight interstate
``{"dt", "length", "lane_width", "lanes": [{"id", "y"}], "speed_limit", "ego", "rules",
"vehicles": [{"id", "length", "width", "x", "y", "psi", "v", "a"}]}`` (one value per time step).
For each case a CommonRoad scenario is built with commonroad-io (lanelets of 100 m along x, the
limit as a MAX_SPEED sign on every lanelet, every vehicle — the ego too — a dynamic obstacle whose
states carry position, orientation, speed and acceleration), written as XML, read back, and each
rule evaluated by crmonitor's offline evaluator with its robustness scaling on (its default: every
predicate divided by a constant and clipped to [-1, 1]) and off (SI units per predicate).
RESULTS.json: per case and rule the two robustness series, the CPU times of building the world
and of each evaluation, and the import time.
"""

from __future__ import annotations

import json
import logging
import sys
import time
from pathlib import Path

logging.disable(logging.WARNING)
_T0 = time.perf_counter()
import numpy as np  # noqa: E402
from commonroad.common.file_reader import CommonRoadFileReader  # noqa: E402
from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile  # noqa: E402
from commonroad.common.util import FileFormat  # noqa: E402
from commonroad.geometry.shape import Rectangle  # noqa: E402
from commonroad.planning.planning_problem import PlanningProblemSet  # noqa: E402
from commonroad.prediction.prediction import TrajectoryPrediction  # noqa: E402
from commonroad.scenario.lanelet import Lanelet, LaneletNetwork, LaneletType, LineMarking  # noqa: E402
from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType  # noqa: E402
from commonroad.scenario.scenario import Scenario, ScenarioID  # noqa: E402
from commonroad.scenario.state import CustomState, InitialState  # noqa: E402
from commonroad.scenario.traffic_sign import TrafficSign, TrafficSignElement, TrafficSignIDGermany  # noqa: E402
from commonroad.scenario.trajectory import Trajectory  # noqa: E402
from crmonitor.common import World  # noqa: E402
from crmonitor.evaluation import OfflineRuleEvaluator  # noqa: E402
from crmonitor.evaluation.predicate_interface import PredicateEvaluationInterfaceConfig  # noqa: E402
from crmonitor.predicates.base import PredicateConfig  # noqa: E402

IMPORT_S = time.perf_counter() - _T0
PIECE = 100.0  # [m] lanelet length
SIGN_ID = 9000


def _lanelets(case: dict) -> LaneletNetwork:
    net = LaneletNetwork()
    w = float(case["lane_width"])
    lanes = sorted(case["lanes"], key=lambda ln: ln["y"])  # right to left
    pieces = int(np.ceil(float(case["length"]) / PIECE))
    ids = {}
    for j, lane in enumerate(lanes):
        for k in range(pieces):
            ids[j, k] = 1000 + 100 * j + k  # vehicles are 100, 101, …
    for j, lane in enumerate(lanes):
        for k in range(pieces):
            x = np.linspace(k * PIECE, (k + 1) * PIECE, 21)
            c = np.c_[x, np.full_like(x, float(lane["y"]))]
            left = ids.get((j + 1, k))
            right = ids.get((j - 1, k))
            net.add_lanelet(Lanelet(
                c + [0, w / 2], c, c - [0, w / 2], ids[j, k],
                predecessor=[ids[j, k - 1]] if k else [], successor=[ids[j, k + 1]] if k + 1 < pieces else [],
                adjacent_left=left, adjacent_left_same_direction=True if left else None,
                adjacent_right=right, adjacent_right_same_direction=True if right else None,
                line_marking_left_vertices=LineMarking.DASHED if left else LineMarking.SOLID,
                line_marking_right_vertices=LineMarking.DASHED if right else LineMarking.SOLID,
                lanelet_type={LaneletType.INTERSTATE, LaneletType.MAIN_CARRIAGE_WAY}, traffic_signs={SIGN_ID}))
    first = {ids[j, k] for j in range(len(lanes)) for k in range(pieces)}
    sign = TrafficSign(SIGN_ID, [TrafficSignElement(TrafficSignIDGermany.MAX_SPEED, [str(case["speed_limit"])])],
                       first, np.array([0.0, -w]))
    net.add_traffic_sign(sign, first)
    return net


def _obstacle(v: dict) -> DynamicObstacle:
    shape = Rectangle(float(v["length"]), float(v["width"]))
    n = len(v["x"])
    pos = [np.array([v["x"][k], v["y"][k]]) for k in range(n)]
    states = [CustomState(time_step=k, position=pos[k], orientation=float(v["psi"][k]), velocity=float(v["v"][k]),
                          acceleration=float(v["a"][k])) for k in range(1, n)]
    init = InitialState(time_step=0, position=pos[0], orientation=float(v["psi"][0]), velocity=float(v["v"][0]),
                        acceleration=float(v["a"][0]), yaw_rate=0.0, slip_angle=0.0)
    return DynamicObstacle(int(v["id"]), ObstacleType.CAR, shape, init, TrajectoryPrediction(Trajectory(1, states), shape))


def scenario(name: str, case: dict, xml_dir: Path) -> Path:
    """The case as a CommonRoad scenario, written as XML."""
    sc = Scenario(float(case["dt"]), ScenarioID(country_id="DEU", map_name=name.replace("_", ""), map_id=1))
    sc.add_objects(_lanelets(case))
    for v in case["vehicles"]:
        sc.add_objects(_obstacle(v))
    path = xml_dir / f"DEU_{name.replace('_', '')}-1_1_T-1.xml"
    CommonRoadFileWriter(sc, PlanningProblemSet(), "twolevel cross-check", "", "", set(),
                         file_format=FileFormat.XML).write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    return path


def evaluate(name: str, case: dict, xml_dir: Path) -> dict:
    sc, _ = CommonRoadFileReader(str(scenario(name, case, xml_dir))).open()
    c0 = time.process_time()
    world = World.create_from_scenario(sc)
    out = {"world_cpu_s": time.process_time() - c0, "rules": {}}
    for rule in case["rules"]:
        res = {}
        for key, scale in (("scaled", True), ("unscaled", False)):
            cfg = PredicateEvaluationInterfaceConfig(base=PredicateConfig(scale_rob=scale))
            ev = OfflineRuleEvaluator.create_for_rule(rule, dt=world.dt, predicate_interface_config=cfg)
            c1 = time.process_time()
            rob = ev.evaluate(world, int(case["ego"]))
            res[key] = [float(x) for x in rob]
            res[f"{key}_cpu_s"] = time.process_time() - c1
        out["rules"][rule] = res
    return out


def main(argv: list[str]) -> int:
    src, dst = Path(argv[0]), Path(argv[1])
    xml_dir = Path(argv[argv.index("--xml-dir") + 1]) if "--xml-dir" in argv else dst.parent
    xml_dir.mkdir(parents=True, exist_ok=True)
    cases = json.loads(src.read_text(encoding="utf-8"))["cases"]
    results = {"import_s": IMPORT_S, "cases": {name: evaluate(name, case, xml_dir) for name, case in cases.items()}}
    dst.write_text(json.dumps(results), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
