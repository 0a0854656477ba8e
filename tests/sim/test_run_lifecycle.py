"""A simulate run's directory whatever happens: held by one run, refused when unsafe, recorded
when the run crashes at its first step, and a duration that would run nothing is refused."""

from __future__ import annotations

import json
import os
from pathlib import Path

from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.sim import engine
from twolevel.sim.trace import RunDirectory, read_run

REPO = Path(__file__).resolve().parents[2]
SCENARIO = str(REPO / "scenarios" / "traffic_rules.yaml")
runner = CliRunner()


def _simulate(run_dir: Path, *more: str):  # noqa: ANN202
    return runner.invoke(app, ["simulate", SCENARIO, "--out", str(run_dir), "--no-progress", *more])


def test_a_second_run_into_a_held_directory_is_refused(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    with RunDirectory(run_dir, {"first": True}):
        res = _simulate(run_dir, "--duration", "0.3")
        meta = json.loads((run_dir / "run.json").read_text())
    assert res.exit_code == 2 and "SIM617" in res.stderr and f"process {os.getpid()}" in res.stderr
    assert "Traceback" not in res.output
    assert meta["first"] is True and meta["status"] == "running" and not (run_dir / "trace.csv").exists()


def test_a_duration_shorter_than_a_step_is_refused(tmp_path: Path) -> None:
    res = _simulate(tmp_path / "run", "--duration", "0.01")
    assert res.exit_code == 2 and "SIM611" in res.stderr and "dt = 0.1" in res.stderr
    assert not (tmp_path / "run").exists()


def test_unsafe_outputs_are_refused_and_left_alone(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    victim = tmp_path / "precious.csv"
    victim.write_text("keep me")
    (run_dir / "trace.csv").symlink_to(victim)
    res = _simulate(run_dir, "--duration", "0.3")
    assert res.exit_code == 2 and "SIM615" in res.stderr and "symbolic link" in res.stderr
    assert victim.read_text() == "keep me"
    (run_dir / "trace.csv").unlink()
    os.mkfifo(run_dir / "frames.jsonl")
    res = _simulate(run_dir, "--duration", "0.3")  # a FIFO would block the writer
    assert res.exit_code == 2 and "SIM615" in res.stderr and "FIFO" in res.stderr


def test_a_crash_at_the_first_step_leaves_run_json(tmp_path: Path, monkeypatch) -> None:
    """Fault injection: sensing raises at step 0, as an internal error would."""
    def broken(self, k, state, history):  # noqa: ANN001, ANN202
        raise RuntimeError("sensing failed at step 0")

    monkeypatch.setattr(engine.ClosedLoop, "sense", broken)
    res = _simulate(tmp_path / "run", "--duration", "0.5")
    assert res.exit_code == 2 and "SIM613" in res.stderr and "Traceback" not in res.output
    run = read_run(tmp_path / "run")
    assert run.meta["status"] == "crashed" and run.meta["rows"] == 0 and run.rows == 0
    assert "sensing failed at step 0" in run.meta["error"] and "Traceback" in run.meta["traceback"]
    assert run.meta["summary"]["steps"] == 0 and run.meta["pid"] == os.getpid()
