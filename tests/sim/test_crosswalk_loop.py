"""The ego yields at a zebra crossing (rules/crosswalk.stl) in closed loop: scenarios/traffic/zebra.yaml
(a pedestrian waiting at the kerb as the ego comes at 50 km/h) and zebra_walking.yaml (one already
crossing), with the MILP MPC and with the NMPC baseline; each run judged against its own
``expect:``, its trace read for where the ego was while the pedestrian waited or walked, and
`twolevel monitor` on the trace reproducing the online robustness column. And `twolevel check`
on the rule file: clean, and a typo'd signal name gets the usual diagnostic."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.monitor.tracefile import monitor_trace, read_trace
from twolevel.sim.engine import simulate_scenario
from twolevel.sim.trace import read_run
from twolevel.stl.lint import load_ruleset
from twolevel.verdict.judge import judge_run
from twolevel.world.provided import PROVIDED_SIGNALS
from twolevel.world.traffic.pedestrians import STOP_SHORT

from helpers.traffic_worlds import replay
from helpers.world_files import load_world

ROOT = Path(__file__).resolve().parents[2]
RULE = ROOT / "rules" / "crosswalk.stl"
X_CROSS = 120.0  # the zebra's centre line on both scenarios' street [m]


def _run(tmp: Path, name: str | Path, controller: str = "twolevel") -> tuple[dict[str, np.ndarray], list, object]:
    """Simulate ``name`` (a scenario of scenarios/traffic/, or a path), assert it meets its own
    criteria (goal, no collision, rules, peak deceleration ≤ 4 m/s²), and return the trace's
    columns, the replayed traffic and the world."""
    path = name if isinstance(name, Path) else ROOT / "scenarios" / "traffic" / f"{name}.yaml"
    summary, diags = simulate_scenario(str(path), str(tmp / path.stem), frames=False, ttr_every=0,
                                       controller=controller)
    assert summary is not None and summary.status == "complete", [d.message for d in diags]
    verdict, _ = judge_run(summary.run_dir, str(path))
    assert verdict.passed, [c.detail for c in verdict.failed]
    w = load_world(path)
    states, _ = replay(w, Path(summary.run_dir) / "trace.csv")
    return read_run(summary.run_dir).columns, states, w


def _check_yielded(cols: dict[str, np.ndarray], states: list, w, *, stood: bool) -> None:
    busy, d = cols["xwalk_busy"], cols["d_xwalk"]
    assert busy.any() and (d[busy > 0.5] > 0).all()  # before the line whenever it was busy
    # never inside the crossing while the pedestrian was on the ego's lane (y from -3.5 to 0) or
    # within half a metre of it (the replayed traffic, not the signal)
    front = cols["x"] + w.ego.length / 2 * np.cos(cols["psi"])
    ped_y = np.array([st.y[0] for st in states[: len(front)]])
    on_lane = np.array([bool(st.active[0]) for st in states[: len(front)]]) & (np.abs(ped_y + 1.75) <= 2.25)
    assert on_lane.any()
    assert (front[on_lane] < X_CROSS - STOP_SHORT + 0.05).all()
    assert max(st.memory.phase[0] for st in states[1:]) == 3  # the pedestrian got across
    v = cols["v"]
    assert np.max(-np.diff(v)) / w.settings.dt <= 4.0  # comfortably: it saw the pedestrian early
    if stood:
        assert ((v < 0.05) & (busy > 0.5)).any()  # it stood while the pedestrian waited or walked
    assert (busy[-10:] == 0).all() and cols["s"][-1] > 200.0  # and drove on to the goal


@pytest.mark.slow
def test_mpc_stops_for_a_pedestrian_waiting_at_the_zebra_and_monitor_agrees(tmp_path: Path) -> None:
    cols, states, w = _run(tmp_path, "zebra")
    _check_yielded(cols, states, w, stood=True)
    trace, diags = read_trace(str(tmp_path / "zebra" / "trace.csv"))
    assert trace is not None and not [x for x in diags if x.is_error]
    rs, d = load_ruleset(str(RULE), dt=trace.dt, provided_signals=PROVIDED_SIGNALS)
    assert rs is not None, d
    report, d = monitor_trace(rs.rules, dict(rs.consts), trace, series=True)
    assert not d, [x.message for x in d]
    (verdict,) = report.rules
    np.testing.assert_array_equal(verdict.series, cols["rob_yield_crosswalk"])
    assert verdict.series.min() > 0


@pytest.mark.slow
def test_mpc_yields_to_a_pedestrian_already_walking(tmp_path: Path) -> None:
    cols, states, w = _run(tmp_path, "zebra_walking")
    _check_yielded(cols, states, w, stood=False)
    assert cols["v"][cols["xwalk_busy"] > 0.5].min() < 1.0  # it slowed down to walking pace for them


@pytest.mark.slow
def test_nmpc_stops_for_a_pedestrian_waiting_at_the_zebra(tmp_path: Path) -> None:
    cols, states, w = _run(tmp_path, "zebra", controller="nmpc")
    _check_yielded(cols, states, w, stood=True)


@pytest.mark.slow
def test_a_pedestrian_beyond_the_rules_r_near_is_stopped_for_from_the_sensing_range(tmp_path: Path) -> None:
    """With r_near 20 m the rule sees the waiting pedestrian only 16 m before the line at 13.9 m/s
    (stopping would take 6 m/s²: the rule's dilemma, under which it binds no more and the ego
    passed at speed). The ego's sensors reach 100 m, and the reference stops for the rule's own
    line seen from there (twolevel/control/high_level/crossers.py, ``crosswalk_halt``): it stands
    before the line within 4 m/s², the crosswalk is busy only while it can stop, the rule holds,
    the pedestrian crosses before it, nobody is hit. (The dilemma itself: the signal's tests,
    tests/world/test_crosswalks.py.)"""
    path = tmp_path / "late.yaml"
    path.write_text(f"kind: scenario\nname: zebra_late\nextends: {ROOT / 'scenarios' / 'traffic' / 'zebra.yaml'}\n"
                    "controller: {r_near: 20}\n")
    cols, states, w = _run(tmp_path, path)
    _check_yielded(cols, states, w, stood=True)


def test_check_accepts_the_rule_and_names_a_typo(tmp_path: Path) -> None:
    runner = CliRunner()
    res = runner.invoke(app, ["check", str(RULE), "--dt", "0.1", "--horizon", "10", "-f", "concise"],
                        env={"GITHUB_ACTIONS": ""})
    assert res.exit_code == 0, res.output
    typo = tmp_path / "typo.stl"
    typo.write_text(RULE.read_text().replace("(d_xwalk > 0)", "(d_xwalks > 0)"))
    res = runner.invoke(app, ["check", str(typo), "-f", "concise"], env={"GITHUB_ACTIONS": ""})
    assert res.exit_code == 1 and "STL201" in res.output and "d_xwalks" in res.output
    # a consistent misspelling is an input the world does not provide, found with the scenario
    (tmp_path / "cw.stl").write_text(RULE.read_text().replace("xwalk_busy", "xwalk_bussy"))
    scn = (ROOT / "scenarios" / "traffic" / "zebra.yaml").read_text()
    scn = scn.replace("../../rules/crosswalk.stl", "cw.stl").replace("../../", str(ROOT) + "/")
    (tmp_path / "z.yaml").write_text(scn)
    res = runner.invoke(app, ["check", str(tmp_path / "z.yaml"), "-f", "concise"], env={"GITHUB_ACTIONS": ""})
    assert res.exit_code == 1 and "STL216" in res.output and "xwalk_bussy" in res.output
