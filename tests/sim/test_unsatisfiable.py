"""Rules no plan can satisfy, explained: once per episode in closed loop (SIM618, the summary
and run.json: which rules, what the car did instead), and ``plan`` claims no optimality for its
fallback."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest
from typer.testing import CliRunner

from helpers.world_files import write_conflicting
from twolevel.cli import app
from twolevel.pipeline.planning import plan_scenario
from twolevel.sim.summary import StepDecision
from twolevel.sim.unsatisfiable import UnsatisfiableLog

REPO = Path(__file__).resolve().parents[2]
runner = CliRunner()


@pytest.fixture
def conflicting(tmp_path: Path) -> Path:
    return write_conflicting(tmp_path, REPO)


def test_episodes_are_explained_once_each() -> None:
    asked: list[float] = []
    log = UnsatisfiableLog()
    pattern = [False, True, True, True, False, True, False]
    for k, bad in enumerate(pattern):
        t = k * 0.1
        log.observe(t, bad, StepDecision.BRAKE if k % 2 else StepDecision.SAMPLED, 10.0 - k,
                    lambda t=t: (asked.append(t), ("a", "b"))[1])
    eps = log.all()
    assert asked == [0.1, 0.5] and len(eps) == 2
    first = eps[0]
    assert (first.t_start, first.t_end, first.steps, first.rules) == (0.1, 0.3, 3, ("a", "b"))
    assert first.decisions == {"brake": 2, "sampled": 1} and (first.v_start, first.v_end) == (9.0, 7.0)
    assert "rules a, b conflict" in first.describe() and "brake 2" in first.describe()
    log.close()
    assert len(log.episodes) == 2 and log.all() == eps


def test_simulate_names_the_conflicting_rules_once_per_episode(conflicting: Path, tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        res = runner.invoke(app, ["simulate", str(conflicting), "--out", str(tmp_path / "run"), "--duration", "1",
                                  "--no-progress"])
    finally:
        os.umask(old)
    assert res.exit_code == 1, res.output
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    episodes = meta["summary"]["unsatisfiable"]
    assert episodes and set(episodes[0]["rules"]) == {"go_fast", "stay_slow"} and episodes[0]["explained"]
    assert all(sum(e["decisions"].values()) == e["steps"] for e in episodes)
    assert res.stderr.count("SIM618") == len(episodes) and "go_fast, stay_slow" in res.stderr
    assert "no plan satisfied the rules" in res.stdout
    for name in ("run.json", "trace.csv", "frames.jsonl"):  # the user's umask, not 0600
        assert stat.S_IMODE((tmp_path / "run" / name).stat().st_mode) == 0o644, name


def test_a_run_whose_rules_hold_has_no_episode(tmp_path: Path) -> None:
    res = runner.invoke(app, ["simulate", str(REPO / "scenarios/traffic_rules.yaml"), "--out", str(tmp_path / "run"),
                              "--duration", "0.5", "--no-progress"])
    assert res.exit_code == 1 and "SIM618" not in res.stderr
    assert json.loads((tmp_path / "run" / "run.json").read_text())["summary"]["unsatisfiable"] == []


def test_plan_does_not_claim_optimality_for_a_fallback(conflicting: Path) -> None:
    rep, _ = plan_scenario(str(conflicting))
    assert rep is not None and rep.status == "fallback" and rep.certificate == "infeasible"
    res = runner.invoke(app, ["plan", str(conflicting)])
    assert res.exit_code == 1 and "optimal" not in res.stdout and "infeasible" in res.stdout
    res = runner.invoke(app, ["plan", str(conflicting), "--format", "json"])
    assert json.loads(res.stdout)["certified"] == "infeasible"
    res = runner.invoke(app, ["plan", str(REPO / "scenarios/traffic_rules.yaml"), "--format", "json"])
    assert json.loads(res.stdout)["certified"] == "optimal"
