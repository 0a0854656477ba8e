"""Closed loop with rules that quantify over participants (the CommonRoad pack): the trace
records every participant's signals and the criticality columns, the low level judges the rules
(the MPC leaves them to it, MIL510), and `twolevel monitor` on the trace reproduces the
``rob_`` columns the online monitor wrote."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from twolevel.monitor.tracefile import monitor_trace, read_trace
from twolevel.sim.engine import simulate_scenario
from twolevel.sim.trace import read_run
from twolevel.stl.lint import load_ruleset
from twolevel.world.provided import PROVIDED_PARTICIPANT_SIGNALS

ROOT = Path(__file__).resolve().parents[2]
PACK = ROOT / "rules" / "commonroad"
FILES = ("R_G1_safe_distance.stl", "R_G3_speed_limits.stl", "R_G4_traffic_flow.stl")


@pytest.fixture(scope="module")
def pack_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    tmp = tmp_path_factory.mktemp("pack")
    rules = "\n".join(f"  - {PACK / f}" for f in FILES)
    (tmp / "s.yaml").write_text(f"""
kind: scenario
name: pack
map: {ROOT / 'maps' / 'highway.yaml'}
ego: {{start: {{lane: middle, s: 20}}, speed: 20.0, desired_speed: 20.0}}
route: {{start: {{lane: middle, s: 20}}, goal: {{lane: middle, s: 900}}, stop_at_goal: false}}
participants:
  - {{id: slow, behaviour: constant_velocity, start: {{lane: middle, s: 75}}, speed: 12.0}}
  - {{id: "left, fast", behaviour: constant_velocity, start: {{lane: left, s: 30}}, speed: 24.0}}
  - {{id: far, behaviour: constant_velocity, start: {{lane: middle, s: 600}}, speed: 20.0}}
rules:
{rules}
controller: {{r_near: 60, time_limit: 30}}
run: {{duration: 4, seed: 2}}
expect: {{goal: false}}
""")
    summary, diags = simulate_scenario(str(tmp / "s.yaml"), str(tmp / "run"))
    assert summary is not None, [d.message for d in diags]
    return tmp / "run", diags


def test_the_trace_records_participants_and_criticality(pack_run) -> None:
    run_dir, diags = pack_run
    run = read_run(run_dir)
    assert run.meta["status"] == "complete" and not run.problems
    cols = run.columns
    for pid in ("slow", "left, fast", "far"):  # an id with a comma survives the CSV header
        for name in ("present", "v", "d_lon", "in_same_lane", "cut_in"):
            assert f"{name}[{pid}]" in cols
    assert "precedes[slow]" not in cols  # only the signals the rules read
    assert (cols["present[slow]"] == math.inf).all() and (cols["present[far]"] == -math.inf).all()
    assert (cols["d_lon[far]"] == math.inf).all()  # absent: its absent value
    assert np.allclose(cols["v[slow]"], 12.0, atol=1e-6)
    # criticality: the slow car is the vehicle ahead
    assert np.allclose(cols["dhw_m"], cols["d_lead"])
    moving = cols["v"] > 1.0
    assert np.allclose(cols["thw_s"][moving], (cols["d_lead"] / cols["v"])[moving])
    closing = cols["v"] - cols["v_lead"] > 0.01
    assert closing.any()
    assert np.allclose(cols["ttc_s"][closing], (cols["d_lead"] / (cols["v"] - cols["v_lead"]))[closing])
    # the discs cover the boxes: while the ego drives along its lane's centre as the car ahead
    # does, a collision course along the lane is one in the plane, no later; once the MPC steers
    # away to pass the slow car (an offset or a heading of a few mrad is enough: 0.01 rad over
    # 12 m is 0.12 m), the plane's constant velocities may miss it where ttc does not
    along = (np.abs(cols["psi"]) < 1e-3) & (np.abs(cols["e"]) < 0.1)
    assert along.any()
    assert (cols["ttc_any_s"][along] <= cols["ttc_s"][along] + 1e-9).all()
    # the MPC leaves the quantified rules to the low level; R_G3 it encodes
    left = {d.message.split("'")[1] for d in diags if d.code == "MIL510"}
    assert left == {"R_G1", "R_G4"}


def test_twolevel_monitor_reproduces_the_rob_columns(pack_run) -> None:
    run_dir, _ = pack_run
    run = read_run(run_dir)
    trace, diags = read_trace(str(run_dir / "trace.csv"))
    assert trace is not None and not [d for d in diags if d.is_error]
    for f in FILES:
        rs, d = load_ruleset(str(PACK / f), dt=trace.dt, participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
        assert rs is not None, d
        report, d = monitor_trace(rs.rules, dict(rs.consts), trace, series=True)
        assert not d, [x.message for x in d]
        for verdict in report.rules:
            np.testing.assert_array_equal(verdict.series, run.columns[f"rob_{verdict.name}"])
    # the slow car ahead: R_G4 holds behind it (the ego need not keep up the traffic flow)
    assert (run.columns["rob_R_G4"] >= 0).all()
    assert np.isfinite(run.columns["rob_R_G1"]).all()
