"""The pipeline end to end through the real CLI: plan, simulate, monitor the run, report it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from twolevel.cli import app

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = str(ROOT / "scenarios" / "traffic_rules.yaml")
runner = CliRunner()


def _only_goal_missed(run_dir: Path) -> bool:
    """A run cut short by --duration: every criterion met but reaching the goal (exit 1)."""
    verdict = json.loads((run_dir / "run.json").read_text())["verdict"]
    return [c["name"] for c in verdict["criteria"] if not c["passed"]] == ["goal"]


def test_plan_json_has_the_documented_shape() -> None:
    res = runner.invoke(app, ["plan", SCENARIO, "--format", "json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert {"status", "objective", "solve_ms", "binaries", "rows", "columns", "plan", "rules"} <= set(out)
    assert out["status"] == "optimal" and len(out["plan"]) == 19 and len(out["plan"][0]) == 7
    assert {r["name"] for r in out["rules"]} >= {"speed_limit", "stop_sign", "red_light"}


@pytest.mark.parametrize("suffix", [".mps", ".lp"])
def test_plan_emits_a_model_file(tmp_path: Path, suffix: str) -> None:
    target = tmp_path / f"model{suffix}"
    res = runner.invoke(app, ["plan", SCENARIO, "--emit", str(target), "--format", "json"])
    assert res.exit_code == 0 and target.stat().st_size > 100


def test_plan_bad_input_exits_2_without_traceback(tmp_path: Path) -> None:
    for args in (["--solver", "nope"], ["--emit", str(tmp_path / "m.txt")], ["--at", "1.0"]):
        res = runner.invoke(app, ["plan", SCENARIO, *args])
        assert res.exit_code == 2 and "Traceback" not in res.output, args
    res = runner.invoke(app, ["plan", str(tmp_path / "missing.yaml")])
    assert res.exit_code == 2 and "YML401" in res.stderr


def test_simulate_then_monitor_and_report_the_run(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    res = runner.invoke(app, ["simulate", SCENARIO, "--out", str(run_dir), "--duration", "2", "--no-progress"])
    assert res.exit_code == 1 and _only_goal_missed(run_dir), res.output
    assert "control step median" in res.stdout
    meta = json.loads((run_dir / "run.json").read_text())
    assert meta["status"] == "complete" and meta["rows"] == 20
    # the run's trace is monitorable as it is, and agrees with the simulator's verdict
    mon = runner.invoke(app, ["monitor", str(ROOT / "rules" / "speed_limit.stl"), str(run_dir / "trace.csv"), "--format", "json"])
    assert mon.exit_code == 0, mon.output
    assert json.loads(mon.stdout)["rules"][0]["first_violation_t"] is None
    rep = runner.invoke(app, ["report", str(run_dir), "--no-gif", "--figure-format", "png"])
    assert rep.exit_code == 0, rep.output
    assert (run_dir / "report.html").exists()


def test_simulate_bad_input_exits_2(tmp_path: Path) -> None:
    res = runner.invoke(app, ["simulate", SCENARIO, "--out", str(tmp_path / "r"), "--controller", "nope", "--no-progress"])
    assert res.exit_code == 2 and "SIM610" in res.stderr
    res = runner.invoke(app, ["simulate", SCENARIO, "--out", str(tmp_path / "r"), "--duration", "-1", "--no-progress"])
    assert res.exit_code == 2


@pytest.mark.parametrize("model", ["kinematic", "fourwheel"])
def test_simulate_with_the_nmpc_baseline(tmp_path: Path, model: str) -> None:
    run_dir = tmp_path / model
    args = ["simulate", str(ROOT / "scenarios" / "comparison.yaml"), "--out", str(run_dir), "--controller", "nmpc",
            "--nmpc-model", model, "--no-monitor", "--duration", "0.5", "--no-progress"]
    res = runner.invoke(app, args)
    assert res.exit_code == 1 and _only_goal_missed(run_dir), res.output
    meta = json.loads((run_dir / "run.json").read_text())
    assert meta["settings"]["controller"] == ("nmpc" if model == "kinematic" else "nmpc-fourwheel")
    assert set(meta["summary"]["decisions"]) == {"nmpc"}


def test_plan_reports_bad_input_not_a_rule_conflict(tmp_path: Path) -> None:
    """A non-linear rule or a timeout used to be blamed on conflicting rules (MIL511) (review)."""
    scen = tmp_path / "s.yaml"
    (tmp_path / "nonlin.stl").write_text("input float v\ninput float v_max\nr = always[0:1] (v * v <= v_max);\n")
    text = (ROOT / "examples" / "scenario" / "scenario.yaml").read_text()
    text = text.replace("map: map.yaml", f"map: {ROOT / 'examples' / 'scenario' / 'map.yaml'}")
    text = text.split("rules:")[0] + "rules:\n  - nonlin.stl\nrun: {duration: 5}\n"
    scen.write_text(text)
    res = runner.invoke(app, ["plan", str(scen)])
    assert res.exit_code == 2 and "MIL501" in res.stderr and "MIL511" not in res.stderr
    res = runner.invoke(app, ["plan", SCENARIO, "--time-limit", "0.001"])
    assert "MIL511" not in res.stderr


def test_plan_at_nan_is_refused(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    assert runner.invoke(app, ["simulate", SCENARIO, "--out", str(run_dir), "--duration", "0.5", "--no-progress"]).exit_code == 1
    assert _only_goal_missed(run_dir)
    res = runner.invoke(app, ["plan", SCENARIO, "--trace", str(run_dir / "trace.csv"), "--at", "nan"])
    assert res.exit_code == 2 and "MIL513" in res.stderr
