"""twolevel's criticality measures (twolevel.world.criticality, the ttc_s, thw_s and dhw_m columns
of a trace) against CommonRoad-CriMe's TTC, THW and HW on the same drives.

CriMe is the optional extra ``crime`` (``make test EXTRAS=dev+crime``; it needs Python < 3.12);
these tests skip only when it is not installed. Each drive is written as a CommonRoad scenario
with commonroad-io's writer (the ego and the vehicle ahead as dynamic obstacles on a straight
lanelet) and built as a twolevel world of the same geometry, whose signals give d_lead, v and
v_lead. Definitions compared: HW, the bumper-to-bumper gap, equals ``dhw``; TTC equals ``ttc`` at
constant speeds (CriMe extrapolates constant accelerations, twolevel constant velocities, so the
drives keep their speeds); CriMe's THW is the first time step at which the ego's recorded
trajectory passes where the vehicle ahead's rear is now, so it lies in (thw, thw + dt]. CriMe
rounds its times to two decimals.
"""

from __future__ import annotations

import logging
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")  # protobuf, inside commonroad-io
pytest.importorskip("commonroad_crime", reason="the optional extra crime (commonroad-crime) is not installed")

from helpers.world_files import load_world  # noqa: E402
from twolevel.world.criticality import headways  # noqa: E402
from twolevel.world.signals import TrafficLog, signals_along  # noqa: E402

DT, T, LENGTH, WIDTH, ROAD = 0.1, 60, 4.5, 1.8, 400.0
EGO, LEAD = 100, 101
STEPS = (0, 10, 25)
ROUNDING = 0.005 + 1e-9  # [s] CriMe rounds its times to two decimals


def _track(x0: float, v: float) -> dict[str, np.ndarray]:
    x = x0 + v * DT * np.arange(T)
    return {"x": x, "y": np.zeros(T), "psi": np.zeros(T), "v": np.full(T, v), "a": np.zeros(T)}


def _commonroad(tmp: Path, tracks: dict[int, dict[str, np.ndarray]]):
    """The drive as a CommonRoad scenario, written as XML and read back as CriMe reads it."""
    from commonroad.common.file_reader import CommonRoadFileReader
    from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
    from commonroad.common.util import FileFormat
    from commonroad.geometry.shape import Rectangle
    from commonroad.planning.planning_problem import PlanningProblemSet
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.lanelet import Lanelet, LaneletType
    from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType
    from commonroad.scenario.scenario import Scenario, ScenarioID
    from commonroad.scenario.state import CustomState, InitialState
    from commonroad.scenario.trajectory import Trajectory

    sc = Scenario(DT, ScenarioID(country_id="DEU", map_name="Crime", map_id=1))
    x = np.linspace(0.0, ROAD, 41)
    c = np.c_[x, np.zeros_like(x)]
    sc.add_objects(Lanelet(c + [0, 1.75], c, c - [0, 1.75], 1, lanelet_type={LaneletType.INTERSTATE}))
    for vid, tr in tracks.items():
        shape = Rectangle(LENGTH, WIDTH)
        states = [CustomState(time_step=k, position=np.array([tr["x"][k], 0.0]), orientation=0.0,
                              velocity=float(tr["v"][k]), acceleration=0.0) for k in range(1, T)]
        init = InitialState(time_step=0, position=np.array([tr["x"][0], 0.0]), orientation=0.0,
                            velocity=float(tr["v"][0]), acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
        sc.add_objects(DynamicObstacle(vid, ObstacleType.CAR, shape, init,
                                       TrajectoryPrediction(Trajectory(1, states), shape)))
    path = tmp / "DEU_Crime-1_1_T-1.xml"
    CommonRoadFileWriter(sc, PlanningProblemSet(), "twolevel", "", "", set(),
                         file_format=FileFormat.XML).write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    scenario, _ = CommonRoadFileReader(str(path)).open(lanelet_assignment=True)
    return scenario


def _crime(scenario) -> dict[str, list[float]]:
    """CriMe's TTC, THW and HW of the ego to the vehicle ahead at ``STEPS``."""
    logging.disable(logging.WARNING)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from commonroad_crime.data_structure.configuration import CriMeConfiguration
            from commonroad_crime.measure import HW, THW, TTC

            cfg = CriMeConfiguration()
            cfg.update(ego_id=EGO, sce=scenario)
            return {name: [float(m(cfg).compute_criticality(k, vehicle_id=LEAD, verbose=False)) for k in STEPS]
                    for name, m in (("ttc", TTC), ("thw", THW), ("dhw", HW))}
    finally:
        logging.disable(logging.NOTSET)


def _twolevel(tmp: Path, tracks: dict[int, dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """twolevel's measures at ``STEPS`` from its world's signals on the same drive."""
    (tmp / "map.yaml").write_text(
        "kind: map\nname: straight\ndefault_speed_limit: 40\n"
        f"roads:\n  - id: road\n    start: {{x: 0, y: 0, heading: 0}}\n    segments: [{{line: {ROAD}}}]\n"
        "    lanes:\n      - {id: right, offset: 0.0, width: 3.5}\n")
    box = f"box: {{length: {LENGTH}, width: {WIDTH}}}"
    (tmp / "s.yaml").write_text(
        "kind: scenario\nname: crime\nmap: map.yaml\n"
        f"ego: {{start: {{lane: right, s: 1}}, speed: 20, {box}}}\n"
        f"route: {{start: {{lane: right, s: 1}}, goal: {{lane: right, s: {ROAD - 5}}}}}\n"
        f"participants: [{{id: lead, behaviour: constant_velocity, start: {{lane: right, s: 50}}, {box}}}]\n"
        "controller: {r_near: 200}\nrun: {duration: 5, seed: 0}\n")
    w = load_world(tmp / "s.yaml")
    lead = tracks[LEAD]
    log = TrafficLog(*(lead[k][:, None] for k in ("x", "y", "psi", "v")), np.ones((T, 1), bool),
                     np.array([LENGTH]), np.array([WIDTH]))
    sig = signals_along(w, log, tracks[EGO], dt=DT)
    h = headways(sig["d_lead"], sig["v"], sig["v_lead"])
    return {k: np.asarray(v)[list(STEPS)] for k, v in h.items()}


@pytest.mark.slow
@pytest.mark.parametrize(("gap", "v", "v_lead"), [
    (30.0, 20.0, 15.0),  # closing in at 5 m/s
    (60.0, 30.0, 10.0),  # fast on a slow car
    (20.0, 25.0, 25.0),  # following at the same speed: no collision course
    (25.0, 12.0, 18.0),  # the vehicle ahead pulls away
])
def test_headways_and_ttc_equal_crimes(tmp_path: Path, gap: float, v: float, v_lead: float) -> None:
    tracks = {EGO: _track(50.0, v), LEAD: _track(50.0 + gap, v_lead)}
    theirs = _crime(_commonroad(tmp_path, tracks))
    ours = _twolevel(tmp_path, tracks)
    assert ours["dhw"] == pytest.approx(theirs["dhw"], abs=1e-6)
    assert [gap - LENGTH - (v - v_lead) * DT * k for k in STEPS] == pytest.approx(theirs["dhw"], abs=1e-6)
    for o, t in zip(ours["ttc"], theirs["ttc"]):
        assert (math.isinf(o) and math.isinf(t)) or abs(o - t) <= ROUNDING, (ours["ttc"], theirs["ttc"])
    for o, t in zip(ours["thw"], theirs["thw"]):
        assert o - ROUNDING < t <= o + DT + ROUNDING, (ours["thw"], theirs["thw"])
