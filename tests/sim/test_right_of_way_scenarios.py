"""The right-of-way scenarios (scenarios/traffic/: yield_priority_road, left_turn_stream, right_turn_stream,
four_way_stop_crossing, blocked_exit) in the closed loop with the real controller, judged against
their own ``expect:`` (the offline monitor on the trace: give_way, clear_junction), and read
back from the trace: the ego waited before the conflict area while a priority car came, went in a
gap, and never stood inside. All run with the safety layer: the MPC's give-way line reads the
priority cars' earliest arrival under the assumptions, as the verifier does, so the verifier never
refuses a crossing halfway (its braking fail-safe would stop the ego inside the area)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twolevel.monitor.tracefile import read_trace

from helpers.judged_runs import judged_run
from helpers.junction_runs import check_gaps, junction_run

ROOT = Path(__file__).resolve().parents[2]
TRAFFIC = ROOT / "scenarios" / "traffic"


def _run(tmp_path: Path, name: str, **options: Any) -> dict[str, np.ndarray]:
    """The scenario run (``options``: e.g. the controller), judged, and its trace's columns."""
    return junction_run(TRAFFIC / f"{name}.yaml", tmp_path / name, **options)


def _moves_off_briskly(c: dict[str, np.ndarray], v_go: float = 4.0, a_go: float = 1.0) -> None:
    """Moving off from the line into the turn, every executed acceleration inside the area is at
    least a_go until the speed is v_go (clear_junction at every sample; the low level used to run
    the fail-safe, keeping its speed, when a correction of the plan did not verify)."""
    inside = (c["d_zone"] <= 0) & (c["d_zone_out"] > 0)
    assert inside.any() and (c["rob_clear_junction"] >= 0).all()
    assert not (inside & (c["v"] < v_go) & (c["a"] < a_go)).any()


def _plan_holds_inside(c: dict[str, np.ndarray]) -> None:
    """Inside the area the low level executes the plan as it is: the plan keeps a margin inside
    clear_junction's bound (MPCSettings.margins), so the detailed car, which gains less speed than
    the plan's model in a tight turn, still holds it on the low level's prediction (the plan used
    to sit on a = a_go and the low level sampled corrections on most steps of moving off)."""
    inside = (c["d_zone"] <= 0) & (c["d_zone_out"] > 0)
    assert inside.any() and not (inside & (c["candidates"] > 0)).any()


@pytest.mark.slow
def test_yield_sign_waits_for_the_platoon_and_goes_in_the_gap(tmp_path: Path) -> None:
    c = _run(tmp_path, "yield_priority_road")
    inside, waiting = check_gaps(c)
    assert waiting.sum() >= 10 and inside.any()
    # while it waited a priority car was coming; it entered after the last one had passed
    first_in = int(np.flatnonzero(inside)[0])
    assert np.flatnonzero(waiting)[-1] < first_in
    assert c["t"][first_in] > 12.0


@pytest.mark.slow
def test_left_turn_waits_for_oncoming_cars_and_turns_after_them(tmp_path: Path) -> None:
    c = _run(tmp_path, "left_turn_stream")
    inside, waiting = check_gaps(c)
    assert waiting.sum() >= 10
    first_in = int(np.flatnonzero(inside)[0])
    # the last oncoming car (about 22 s in) could come sooner at its worst case under the
    # assumptions than the 9 s the turn needs: the ego turns after it has passed
    assert c["t"][first_in] > 20.0 and c["t_reach[oncoming_4]"][first_in] == np.inf


@pytest.mark.slow
def test_all_way_stop_with_crossing_traffic(tmp_path: Path) -> None:
    c = _run(tmp_path, "four_way_stop_crossing")
    inside, _ = check_gaps(c)
    assert inside.any()


@pytest.mark.slow
def test_blocked_exit_is_not_entered(tmp_path: Path) -> None:
    c = _run(tmp_path, "blocked_exit")
    inside, waiting = check_gaps(c)
    # it stood before the junction while the delivery car stood beyond it (until 12 s)
    assert waiting.sum() >= 10 and c["t"][np.flatnonzero(inside)[0]] > 12.0


@pytest.mark.slow
def test_right_turn_merges_behind_the_stream_from_the_left(tmp_path: Path) -> None:
    c = _run(tmp_path, "right_turn_stream")
    _moves_off_briskly(c)
    _plan_holds_inside(c)
    inside, waiting = check_gaps(c)
    assert waiting.sum() >= 10
    first_in = int(np.flatnonzero(inside)[0])
    assert np.flatnonzero(waiting)[-1] < first_in
    # it turned in behind the last car of the platoon (at the junction about 8 s in)
    assert c["t"][first_in] > 8.0 and c["t_reach[from_left_3]"][first_in] == np.inf


@pytest.mark.slow
def test_the_nmpc_baseline_waits_in_its_lane(tmp_path: Path) -> None:
    """The NMPC baseline at the yield line: its reference used to run on past the give-way line,
    and with no lateral band the plan slid sideways along the line (7 m off the route, standing
    across the verge); the reference now stops at the line, as at a stop line."""
    path = TRAFFIC / "yield_priority_road.yaml"
    run_dir = judged_run(path, tmp_path / "nmpc", judge=False, controller="nmpc", duration=15.0)
    trace, _ = read_trace(str(run_dir / "trace.csv"))
    assert trace is not None
    e, d_zone, v = (np.asarray(trace.columns[k], float) for k in ("e", "d_zone", "v"))
    before = d_zone > 0
    assert ((v < 0.3) & before).sum() >= 10  # it waited at the line
    assert np.max(np.abs(e[before])) < 0.3


@pytest.mark.slow
def test_merge_behind_a_cyclist_after_a_pedestrian(tmp_path: Path) -> None:
    c = _run(tmp_path, "merge_cyclist")
    _moves_off_briskly(c)
    _plan_holds_inside(c)
    # behind the cyclist a refused correction gives way to the fail-safe (braking), not to a plan
    # that would close in on the cyclist: the collision rule (D_safe) held throughout
    assert (c["rob_no_collision"] >= 0).all()
    inside, waiting = check_gaps(c)
    first_in = int(np.flatnonzero(inside)[0])
    # it gave way to the cyclist and to the car on the priority road: in after both had passed
    assert c["t_reach[cyclist]"][first_in] == np.inf and c["t_reach[car]"][first_in] == np.inf
    assert waiting.sum() >= 10 and np.flatnonzero(waiting)[-1] < first_in
    # behind the cyclist, which it does not pass (a cyclist is passed only over the oncoming lane,
    # twolevel.world.clearance), the ego keeps its box in its lane: never over the centre line
    out = c["d_zone_out"] <= 0
    assert np.isfinite(c["over_centre"][out]).sum() >= 50 and (c["over_centre"][out] < 0).all()


@pytest.mark.slow
def test_the_nmpc_baseline_stops_straight_waits_and_clears_the_all_way_stop(tmp_path: Path) -> None:
    """The NMPC baseline at the 4-way stop: the line's bound on its positions alone it met by
    turning across its lane (0.58 m off, 0.1 rad askew; the safety layer then found no fail-safe
    to move off with: stuck at 58 m of 140), a few millimetres past the line it took the line
    as passed and drove in while it had to give way, and it moved off at the paper's cost's
    0.86 m/s², slower than the clearing the give-way line had let it go for (braked to a stop
    inside). Now: a straight stop at the line, waiting, clearing at CLEAR_ACCEL, the goal."""
    c = _run(tmp_path, "four_way_stop_crossing", controller="nmpc")  # goal, no collision at fault, the rules
    inside, waiting = check_gaps(c)
    before = c["d_zone"] > 0
    assert np.max(np.abs(c["e"][before])) < 0.1  # straight in its lane up to the area
    assert waiting.sum() >= 10 and inside.any()
    first_in = int(np.flatnonzero(inside)[0])
    assert np.flatnonzero(waiting)[-1] < first_in  # it waited, then went
    approach = c["t"] < c["t"][np.flatnonzero(c["v"] < 0.1)[0]]  # up to its first stop
    assert np.min(c["a"][approach]) >= -3.5  # braked for the line at about stop_decel (5.2 m/s² before)
