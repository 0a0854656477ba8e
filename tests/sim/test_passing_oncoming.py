"""Passing over the oncoming lane after waiting for oncoming traffic, in the closed loop (the MPC's
pass, twolevel/control/high_level/overtaking.py, under the safety layer): scenarios on
maps/passing_road.yaml with oncoming cars (scenarios/everyday/overtake_*). Each run is judged by
the scenario's own criteria (goal, road, collisions, rules) and checked for what a driving
instructor would ask of a pass: never standing with the body over the centre line, not pulling
out while an oncoming car is closer than RSS's opposite-direction distance, back in the lane
after the pass, no hard braking where nothing appears suddenly.

The oncoming cars are ``constant_velocity`` participants: where they are at any time follows
from the scenario (the recorded frames show only those within r_near)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from twolevel.sim.trace import read_run
from twolevel.world.assumptions import opposite_safe_distance

from helpers.judged_runs import judged_run
from helpers.world_files import load_world

ROOT = Path(__file__).resolve().parents[2]
EVERYDAY = ROOT / "scenarios" / "everyday"
LANE_Y = -1.75
"""[m] The centre of the ego's lane (east) on the passing road; the centre line is y = 0."""
STANDING = 0.5
"""[m/s] Below this the ego counts as standing."""


@dataclass(frozen=True)
class Pass:
    """What one closed-loop run of a passing scenario shows: the trace's times ``t`` [s], ego
    positions ``x``, ``y`` [m], speeds ``v`` [m/s], how far its body reaches over the centre line
    ``over`` [m], the least margin [m] by which the gap to any oncoming car ahead exceeded RSS's
    opposite-direction distance while the ego was over the line (+inf: none ahead then), the
    peak deceleration [m/s²] (the recorded ride's), the at-fault collisions and when each
    oncoming car drew level with the ego (``level`` [s]), and how close the box came to the road's
    edge (``edge`` [m], the on_road criterion's)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    v: np.ndarray
    over: np.ndarray
    rss_margin: float
    decel: float
    at_fault: int
    level: tuple[float, ...]
    edge: float = 0.0


def _run(tmp_path: Path, name: str) -> Pass:
    path = EVERYDAY / f"{name}.yaml"
    run = read_run(judged_run(path, tmp_path / name))  # goal, road, collisions, rules
    c = run.columns
    t, x, y, v, over = (np.asarray(c[k], float) for k in ("t", "x", "y", "v", "over_centre"))
    w = load_world(path)
    tr = w.traffic0
    onc = np.flatnonzero(np.cos(tr.psi) < -0.9)  # driving west, on the oncoming lane
    xo = tr.x[onc][None, :] + (tr.v[onc] * np.cos(tr.psi[onc]))[None, :] * t[:, None]  # (T, n)
    gap = xo - x[:, None] - (w.ego.length + w.parts.length[onc][None, :]) / 2
    need = opposite_safe_distance(v[:, None], tr.v[onc][None, :], w.settings.response, w.assumptions.response)
    ahead = (over[:, None] > 0) & (xo > x[:, None])
    margin = float(np.min(np.where(ahead, gap - need, np.inf))) if len(onc) else float("inf")
    level = tuple(float(t[np.argmax(xo[:, j] <= x)]) if (xo[:, j] <= x).any() else float("inf")
                  for j in range(len(onc)))
    road = [c for c in run.meta["verdict"]["criteria"] if c["name"] == "on_road"][0]
    return Pass(t, x, y, v, over, margin, float(run.meta["ride"]["decel"]), int(run.meta["summary"]["at_fault"]),
                level, -float(road["measured"]))


def _check_pass(p: Pass, obstacle_x: float, *, decel: float = 4.0) -> None:
    """What every pass here must show (the module docstring)."""
    assert p.at_fault == 0
    assert p.over.max() > 0.0  # it passed over the centre line
    assert not ((p.v < STANDING) & (p.over > 0.0)).any()  # never standing over it
    out = np.flatnonzero(p.over > 0.0)
    assert p.x[out[-1]] > obstacle_x  # back in its lane only once past the obstacle
    assert p.over[-1] <= 0.0 and abs(p.y[-1] - LANE_Y) < 0.3  # and back in its lane at the end
    assert p.rss_margin >= 0.0  # RSS's opposite-direction distance to every oncoming car ahead
    assert p.decel <= decel


@pytest.mark.slow
def test_the_ego_waits_for_an_oncoming_car_then_passes_a_stalled_car(runs) -> None:
    p = runs("overtake_wait_oncoming")
    _check_pass(p, 80.0)
    first_out = p.t[np.argmax(p.over > 0.0)]
    assert first_out > p.level[0]  # it let the oncoming car go by first
    assert p.v[(p.t > 8.0) & (p.t < p.level[0])].max() < STANDING  # waiting behind the stalled car


_RUNS: dict[str, Pass] = {}


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory):
    """The runs of this module by scenario name, each simulated once."""
    def get(name: str) -> Pass:
        if name not in _RUNS:
            _RUNS[name] = _run(tmp_path_factory.mktemp(name), name)
        return _RUNS[name]
    return get


@pytest.fixture(scope="module")
def stream(runs) -> Pass:
    return runs("overtake_oncoming_stream")


@pytest.mark.slow
def test_the_ego_takes_the_long_gap_in_a_stream_of_oncoming_cars(stream: Pass) -> None:
    _check_pass(stream, 80.0)
    assert stream.t[np.argmax(stream.over > 0.0)] > stream.level[1]  # neither before the first car nor in the short gap


@pytest.mark.slow
def test_the_pull_out_into_the_long_gap_is_gentle(stream: Pass) -> None:
    """Regression: the first steps of the pull-out from rest into the long gap were refuted (the
    completing fail-safe that kept 2 m/s was too slow for the far oncoming car; the one gaining
    1.5 m/s² reached 5.5 m/s on a way out laid out for 3 m/s and swung back towards the stalled
    car), and on the way back in, the stalled car just passed could have driven off after the
    ego's braking fail-safe: the ego braked at 5.6 m/s², then 4.02 m/s². Now the gain fits the way
    out (twolevel/safety/failsafe.py) and a vehicle just passed does not speed up until the ego
    is back in its lane (twolevel/safety/verify.py)."""
    assert stream.decel <= 4.0


@pytest.mark.slow
@pytest.mark.parametrize("name", ["overtake_wait_oncoming", "overtake_parked_half"])
def test_the_pull_out_from_rest_is_gentle(runs, name: str) -> None:
    """Regression: with completing the pass at the speed it has offered only from 3 m/s, the
    verifier refused the first steps of the pull-out from rest (2 m/s) and the ego braked at
    5.6 m/s² before it went."""
    assert runs(name).decel <= 4.0


@pytest.mark.slow
@pytest.mark.parametrize("name", ["overtake_wait_oncoming", "overtake_oncoming_stream", "overtake_parked_half"])
def test_a_pass_runs_near_the_passing_lanes_centre_and_off_the_roads_edge(runs, name: str) -> None:
    """Regression: arriving in the oncoming lane with 1.5–2 m/s of lateral velocity, the plans
    swung to 4.08 m from the ego's lane's centre (the passing lane's is 3.5 m) and the box came
    0.23 m from the road's edge. Now the band keeps the body 0.5 m inside the edge and the lateral
    velocity is damped over the oncoming lane (twolevel/control/high_level/overtaking.py,
    steering.py)."""
    p = runs(name)
    e = p.y - LANE_Y
    assert e.max() > 3.0  # it passed over the oncoming lane
    assert e.max() <= 3.85
    assert p.edge >= 0.3


@pytest.mark.slow
def test_the_ego_passes_a_car_parked_half_in_its_lane_once_the_oncoming_car_is_by(runs) -> None:
    p = runs("overtake_parked_half")
    _check_pass(p, 80.0)
    assert p.t[np.argmax(p.over > 0.0)] > p.level[0]


@pytest.mark.slow
def test_the_ego_follows_a_tractor_then_passes_it_in_a_gap(tmp_path: Path) -> None:
    """Regression: the completing fail-safe returned ahead of where the tractor was when it
    started, not where it would be, so every step of the pass was refuted and the ego crept back
    behind it; it now returns where it catches up with it (twolevel/safety/failsafe.catch_up)."""
    p = _run(tmp_path, "overtake_tractor_oncoming")
    first_out = float(p.t[np.argmax(p.over > 0.0)])
    _check_pass(p, 70.0 + 3.0 * float(p.t[np.flatnonzero(p.over > 0.0)[-1]]))  # the tractor drives on at 3 m/s
    assert first_out > p.level[1]  # after both oncoming cars
    behind = (p.t > 10.0) & (p.t < p.level[1])
    assert np.all(np.abs(p.v[behind] - 3.0) < 1.0)  # following it at its pace meanwhile


@pytest.mark.slow
def test_an_oncoming_car_coming_into_sight_mid_pass_leaves_the_pass_its_distance(tmp_path: Path) -> None:
    p = _run(tmp_path, "overtake_oncoming_unseen")
    _check_pass(p, 80.0)
    first_out = int(np.argmax(p.over > 0.0))
    w = load_world(EVERYDAY / "overtake_oncoming_unseen.yaml")
    onc = int(np.flatnonzero(np.cos(w.traffic0.psi) < -0.9)[0])
    x_then = w.traffic0.x[onc] - w.traffic0.v[onc] * p.t[first_out]
    assert x_then - p.x[first_out] > w.settings.sensor_range  # beyond the sensing range when it pulled out
