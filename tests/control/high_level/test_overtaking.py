"""Passing over the oncoming lane (twolevel/control/high_level/overtaking.py) and the fail-safes
that take the ego back into its lane (twolevel/safety/failsafe.py, verify.py): the band opens the
oncoming lane only where the markings and zones allow it, the gap acceptance refuses an oncoming
car closing, and in the closed loop the ego passes a stalled car when the oncoming lane is free
and waits behind one where the centre line is solid."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.high_level.guards import Front, front_of
from twolevel.control.high_level.overtaking import (EDGE_MARGIN, oncoming_band, oncoming_free, out_of_lane,
                                                    room_to_pull_out, waiting_room)
from twolevel.control.high_level.steering import PASS_DAMPING
from twolevel.models.params import BicycleParams
from twolevel.safety.failsafe import return_path
from twolevel.world.assumptions import ResponseBounds, opposite_safe_distance
from twolevel.world.signals import horizon_constants

from helpers.judged_runs import judged_run
from helpers.world_files import load_world

ROOT = Path(__file__).resolve().parents[3]
EVERYDAY = ROOT / "scenarios" / "everyday"


def test_opposite_safe_distance_is_rss_definition_4() -> None:
    ego, other = ResponseBounds(0.5, 2.0, 4.0, 8.0), ResponseBounds(1.0, 3.0, 5.0, 8.0)
    # ego at 10 m/s: (10 + 11)/2·0.5 + 11²/8; other at 8 m/s: (8 + 11)/2·1 + 11²/10
    want = 5.25 + 121 / 8 + 9.5 + 121 / 10
    assert opposite_safe_distance(10.0, 8.0, ego, other) == pytest.approx(want)
    assert opposite_safe_distance(10.0, 8.0, ego, other) < opposite_safe_distance(10.0, 9.0, ego, other)


def test_the_oncoming_lane_opens_only_where_markings_and_zones_allow() -> None:
    dashed = load_world(EVERYDAY / "overtake_stalled.yaml")  # route s = east's s − 10
    solid = load_world(EVERYDAY / "overtake_solid_line.yaml")  # route s = east's s − 250
    zone = load_world(EVERYDAY / "overtake_tractor_zone.yaml")  # route s = east's s − 500
    lo, hi, open_ = oncoming_band(dashed, np.array([50.0]))
    # to the oncoming lane's far edge, the body EDGE_MARGIN inside it
    assert open_[0] and hi[0] == pytest.approx(3.5 + 1.75 - dashed.ego.width / 2 - EDGE_MARGIN)
    assert out_of_lane(dashed, 50.0) < hi[0]
    for w, s in ((solid, 110.0), (zone, 60.0)):  # east 360 m (solid line), east 560 m (no-overtaking zone)
        lo, hi, open_ = oncoming_band(w, np.array([s]))
        assert not open_[0] and hi[0] == pytest.approx(1.75 - w.ego.width / 2)
    assert oncoming_band(solid, np.array([20.0]))[2][0]  # east 270 m: dashed again


@settings(max_examples=30, deadline=None)
@given(width=st.floats(1.9, 4.5))
def test_a_pass_keeps_the_body_off_the_roads_edge_but_never_off_the_oncoming_lanes_centre(tmp_path_factory,
                                                                                         width: float) -> None:
    """Regression: the band of a pass reached the road's edge less half the ego's width, so the
    plans drifted until the box's corner was 0.23 m from the edge. Now the body keeps
    EDGE_MARGIN inside it, except on an oncoming lane too narrow for that beside its centre."""
    path = tmp_path_factory.mktemp("narrow") / "road.yaml"
    text = (ROOT / "maps" / "passing_road.yaml").read_text(encoding="utf-8")
    path.write_text(text.replace("offset: 1.75, width: 3.5", f"offset: {1.75 + (width - 3.5) / 2}, width: {width}"),
                    encoding="utf-8")
    scn = (EVERYDAY / "overtake_stalled.yaml").read_text(encoding="utf-8").replace("../../maps/passing_road.yaml",
                                                                                 str(path))
    scn_path = path.with_name("scn.yaml")
    scn_path.write_text(scn.replace("../../rules/", str(ROOT / "rules") + "/"), encoding="utf-8")
    w = load_world(scn_path)
    lo, hi, open_ = oncoming_band(w, np.array([50.0]))
    centre, edge = 1.75 + width / 2, 1.75 + width - w.ego.width / 2  # the oncoming lane's centre; the box at the edge
    assert open_[0] and lo[0] == pytest.approx(-1.75 + w.ego.width / 2)  # the right edge: no oncoming lane there
    assert hi[0] == pytest.approx(max(edge - EDGE_MARGIN, min(centre, edge)))
    assert hi[0] <= edge - min(EDGE_MARGIN, max(width / 2 - w.ego.width / 2, 0.0)) + 1e-9


def _gap_accepted(oncoming_at: float | None) -> bool:
    """Whether the ego, 40 m behind the stalled car at 10 m/s, accepts the oncoming gap with an
    oncoming car ``oncoming_at`` [m] along the road at 12 m/s (None: none)."""
    w = load_world(EVERYDAY / "overtake_stalled.yaml")
    tr = w.traffic0
    if oncoming_at is not None:  # the stalled car's state, moved onto the oncoming lane at x = oncoming_at
        tr = dataclasses.replace(
            tr, x=np.append(tr.x, oncoming_at), y=np.append(tr.y, 1.75), psi=np.append(tr.psi, np.pi),
            v=np.append(tr.v, 12.0), active=np.append(tr.active, True))
        w = dataclasses.replace(w, parts=dataclasses.replace(
            w.parts, length=np.append(w.parts.length, 4.5), width=np.append(w.parts.width, 1.8),
            ids=tuple(w.parts.ids) + ("oncoming",)))
    x0 = (40.0, -1.75, 0.0, 10.0)
    hc = horizon_constants(w, tr, 0.0, x0)
    front = front_of(w, hc, None, 30.0, 0.1, np.arange(len(hc.t)))
    assert front is not None and front.index == 0
    return oncoming_free(w, hc, front, 30.0, 10.0)


def test_the_gap_is_accepted_when_free_and_refused_with_an_oncoming_car_closing() -> None:
    assert _gap_accepted(None)
    assert not _gap_accepted(200.0)  # 160 m away, closing at 22 m/s: too short for the pass
    assert _gap_accepted(-50.0)  # already behind the ego, driving away


@settings(max_examples=60, deadline=None)
@given(e_from=st.floats(-3, 3), e_out=st.floats(-3, 3), e_goal=st.floats(-1, 1), d_out=st.floats(1, 30),
       gap=st.floats(0, 20), d_ret=st.floats(1, 30))
def test_return_path_is_smooth_from_start_to_goal(e_from: float, e_out: float, e_goal: float, d_out: float,
                                                  gap: float, d_ret: float) -> None:
    path = tuple(np.array([x]) for x in (e_out, 0.0, d_out, e_goal, d_out + gap, d_ret))
    s = np.linspace(-5.0, d_out + gap + d_ret + 5.0, 400)
    e, slope, _ = return_path(np.array([e_from]), path, s)
    assert e[0] == pytest.approx(e_from) and e[-1] == pytest.approx(e_goal)
    assert slope[0] == 0.0 and slope[-1] == 0.0
    beside = (s >= d_out) & (s <= d_out + gap)
    assert np.allclose(e[beside], e_out)
    lo, hi = min(e_from, e_out, e_goal), max(e_from, e_out, e_goal)
    assert ((e >= lo - 1e-9) & (e <= hi + 1e-9)).all()  # no overshoot


def _simulate(tmp_path: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    path = EVERYDAY / f"{name}.yaml"
    run_dir = judged_run(path, tmp_path / name)  # goal (as expected), road, collisions, rules
    data = np.genfromtxt(run_dir / "trace.csv", delimiter=",", names=True, usecols=("x", "y", "v"))
    return np.column_stack([data["x"], data["y"]]), data["v"]


@pytest.mark.slow
def test_a_stalled_car_is_passed_over_the_free_oncoming_lane(tmp_path: Path) -> None:
    xy, v = _simulate(tmp_path, "overtake_stalled")
    w = load_world(EVERYDAY / "overtake_stalled.yaml")
    out = xy[:, 1] - w.ego.width / 2 > 0.0  # wholly over the centre line (y = 0)
    assert out.any()
    assert xy[out, 0].min() < 80.0 - 2.1 and xy[out, 0].max() > 80.0 + 2.1  # beside the stalled car, out of its lane
    assert abs(xy[-1, 1] + 1.75) < 0.2  # back in its lane
    assert v[xy[:, 0] < 100.0].min() > 3.0  # without stopping (it stops at its goal)


@pytest.mark.slow
def test_the_ego_waits_behind_a_stalled_car_across_a_solid_line(tmp_path: Path) -> None:
    xy, v = _simulate(tmp_path, "overtake_solid_line")
    w = load_world(EVERYDAY / "overtake_solid_line.yaml")
    assert (xy[:, 1] + w.ego.width / 2 < 0.05).all()  # never over the centre line
    assert v[-1] < 0.1 and xy[-1, 0] < 360.0 - 4.0  # standing behind it


@pytest.mark.slow
def test_the_ego_follows_a_tractor_through_a_no_overtaking_zone(tmp_path: Path) -> None:
    xy, v = _simulate(tmp_path, "overtake_tractor_zone")  # the goal (in the zone) is reached: judged
    w = load_world(EVERYDAY / "overtake_tractor_zone.yaml")
    assert (xy[:, 1] + w.ego.width / 2 < 0.05).all()  # never over the centre line


def _front(w, s: float, v: float, length: float = 4.22, width: float = 1.8) -> Front:
    """A vehicle in the ego's lane at route position ``s`` [m] driving at ``v`` [m/s]."""
    return Front(0, s + v * 0.5 * np.arange(41), v, 0.0, (w.ego.length + length) / 2, width)


def test_the_waiting_room_is_judged_from_where_the_ego_waits() -> None:
    """Behind a stalled car the ego keeps the room to pull out from however far back it still is
    (it used to appear only ~30 m before it, when a pass from rest *at the ego's position* first
    fitted the sensing range, and the ego braked at 7.7 m/s² for it)."""
    w = load_world(EVERYDAY / "overtake_wait_oncoming.yaml")
    p = BicycleParams()
    f = _front(w, 70.0, 0.0)
    rooms = [waiting_room(w, p, f, s0, 0.0, 2.6) for s0 in (0.0, 20.0, 40.0, 50.0)]
    assert rooms[0] > 10.0 and rooms == pytest.approx([rooms[0]] * 4)


def test_a_tractor_is_waited_behind_with_room_when_the_sight_allows_its_pass() -> None:
    """Behind a tractor at 3 m/s the pass is judged at its pace: 500 m of sight allow it (room to
    pull out kept), 400 m do not (the unseen car at the speed bound is too near; no room)."""
    w = load_world(EVERYDAY / "overtake_tractor_oncoming.yaml")
    p = BicycleParams()
    f = _front(w, 100.0, 3.0, 5.0, 2.4)
    assert w.settings.sensor_range == 500.0 and waiting_room(w, p, f, 60.0, 0.0, 2.6) > 10.0
    short = dataclasses.replace(w, settings=dataclasses.replace(w.settings, sensor_range=400.0))
    assert waiting_room(short, p, f, 60.0, 0.0, 2.6) == 0.0


@settings(max_examples=60, deadline=None)
@given(gap=st.floats(0.0, 40.0), v0=st.floats(0.0, 8.0), v_front=st.floats(0.0, 5.0))
def test_a_pass_begins_only_with_room_to_pull_out(gap: float, v0: float, v_front: float) -> None:
    """room_to_pull_out: true exactly when the lane change out fits into the gap less D_safe
    (the front's own travel not counted: it may brake); more room never hurts."""
    w = load_world(EVERYDAY / "overtake_wait_oncoming.yaml")
    p = BicycleParams()
    f = _front(w, 100.0, v_front)
    s0 = 100.0 - f.offset - w.settings.D_safe - gap
    ok = room_to_pull_out(w, p, f, s0, v0, 3.4)
    assert room_to_pull_out(w, p, f, s0 - 5.0, v0, 3.4) or not ok
    assert not room_to_pull_out(w, p, f, s0, v0, 3.4) if gap < 5.0 else True  # no lane change is that short
    assert room_to_pull_out(w, p, f, 100.0 - f.offset - w.settings.D_safe - 40.0, 0.0, 3.4)


@pytest.mark.parametrize("name, x, passing", [("overtake_stalled", 30.0, True), ("overtake_stalled", 10.0, False),
                                              ("overtake_solid_line", 270.0, False)])
def test_over_the_oncoming_lane_the_heading_damps_the_lateral_velocity(name: str, x: float, passing: bool) -> None:
    """Regression: arriving in the oncoming lane with 1.5–2 m/s of lateral velocity, the plans
    swung 0.5–0.6 m past the passing lane's centre (the heading weighed in rad, about the ego's
    own heading). While the reference takes the oncoming lane in, the heading's reference is the
    route's and its weight in the cost is 1 + PASS_DAMPING·v² (the lateral velocity it causes);
    elsewhere the paper's cost is untouched."""
    w = load_world(EVERYDAY / f"{name}.yaml")
    ctrl, _ = HighLevelController.from_world(w)
    x0 = np.array([x, w.ego.y, 0.05, w.ego.v])  # 0.05 rad off the route's heading
    step, past, P = ctrl.prepare(x0, 0.0, w.traffic0, None)
    asm = ctrl.build(step, past, P)
    span = step.steps / step.steps[0]
    diag = asm.model.P.diagonal()[asm.layout.x[:, 2]]  # the heading columns' Hessian: 2·weight·span
    if not passing:
        assert step.head_weight is None and np.allclose(step.omega[:, 2], 0.05)  # the ego's heading, as the paper's
        assert np.allclose(diag, 2.0 * span)
        return
    v = step.xs_bar[1:, 3]
    assert step.head_weight == pytest.approx(1.0 + PASS_DAMPING * v * v)
    assert np.allclose(step.omega[:, 2], 0.0)  # the route's heading
    assert diag == pytest.approx(2.0 * span * (1.0 + PASS_DAMPING * v * v))
