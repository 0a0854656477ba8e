"""The Planner interface: its types, and the MPC and the NMPC both implementing it on a real
scenario (the shipped ``comparison``), the four-wheel NMPC planning from the detailed state."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers.world_files import load_world
from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.nmpc.controller import NmpcController
from twolevel.control.planner import EgoState, Planner, PlanStatus, PreviousPlan, Snapshot
from twolevel.control.registry import CONTROLLERS, planner_named
from twolevel.models import fourwheel as fw
from twolevel.world.world import World

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def comparison() -> World:
    return load_world(REPO / "scenarios" / "comparison.yaml")


def test_ego_state_reads_a_pose_or_a_detailed_state() -> None:
    pose = EgoState.of([1.0, 2.0, 0.5, 7.0])
    assert pose.detailed is None and pose.pose.tolist() == [1.0, 2.0, 0.5, 7.0]
    x = fw.initial_state(1.0, 2.0, 0.5, 7.0)
    x[4] = 0.3  # some lateral speed: the detailed state is more than its pose
    full = EgoState.of(x)
    assert full.detailed is not None and np.array_equal(full.detailed, x)
    assert full.pose.tolist() == [1.0, 2.0, 0.5, 7.0]  # X, Y, ψ, vx
    assert EgoState.of(full) is full


def test_only_plans_that_satisfy_the_rules_are_ok() -> None:
    assert {s for s in PlanStatus if s.ok} == {PlanStatus.OPTIMAL, PlanStatus.FEASIBLE}
    assert PlanStatus("time_limit") is PlanStatus.TIME_LIMIT


def test_a_previous_plan_is_followed_only_one_period_later_over_the_same_horizon() -> None:
    prev = PreviousPlan(1.0, np.zeros((11, 4)), np.zeros((10, 2)), np.zeros(0, np.int64))
    assert prev.precedes(1.1, 0.1, 10)
    assert not prev.precedes(1.2, 0.1, 10) and not prev.precedes(1.0, 0.1, 10)
    assert not prev.precedes(1.1, 0.1, 12) and not prev.spans(12)


def test_no_world_state_is_an_empty_road() -> None:
    snap = Snapshot.of(None)
    assert snap.memory is None and snap.traffic.x.size == 0


@pytest.mark.parametrize("name", [n for n in CONTROLLERS if n != "nmpc-fourwheel"])  # that one: below
def test_every_named_planner_implements_the_interface(comparison: World, name: str) -> None:
    planner, diags = planner_named(name, comparison)
    assert planner is not None, [d.message for d in diags]
    assert isinstance(planner, Planner)
    e = comparison.ego
    res = planner.solve(EgoState(np.array([e.x, e.y, e.psi, e.v])), 0.0, Snapshot(comparison.traffic0))
    # the reckless planner never checks the rules, and says so
    assert (res.status.ok and res.ok) if name != "reckless" else res.status is PlanStatus.UNCHECKED and not res.ok
    H = comparison.settings.H
    assert res.states.shape == (H + 1, 4) and res.controls.shape == (H, 2)
    assert planner.label == {"twolevel": "mpc", "nmpc": "nmpc", "reckless": "reckless"}[name]
    assert planner.history_depth >= 0


def test_an_unknown_planner_name_is_refused(comparison: World) -> None:
    with pytest.raises(KeyError):
        planner_named("nope", comparison)


def test_the_fourwheel_nmpc_plans_from_the_detailed_state(comparison: World) -> None:
    ctrl, diags = NmpcController.from_world(comparison, model="fourwheel")
    assert ctrl is not None, [d.message for d in diags]
    assert isinstance(ctrl, Planner)
    e = comparison.ego
    x = fw.initial_state(e.x, e.y, e.psi, e.v, ctrl.vehicle)
    x[5] = 0.4  # yawing [rad/s]: not the steady straight running the pose alone implies
    pose = np.array([e.x, e.y, e.psi, e.v])
    plans = []
    for ego in (EgoState(pose, x), x, EgoState(pose)):
        ctrl.reset()
        plans.append(ctrl.solve(ego, 0.0, comparison.traffic0))
    given, bare, pose_only = plans
    assert given.ok and bare.ok and pose_only.ok
    np.testing.assert_array_equal(given.controls, bare.controls)  # the same state, however passed
    assert not np.allclose(given.controls, pose_only.controls, atol=1e-4)  # the yaw rate is planned for
