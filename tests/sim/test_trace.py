"""Run directories survive interruption and read back what was written."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from twolevel.sim.trace import BASE_COLUMNS, TraceWriter, read_run

COLUMNS = BASE_COLUMNS + ("rob_speed",)


def _row(k: int) -> dict[str, object]:
    return {"t": k * 0.1, "x": 1.5 * k, "v": 10.0 + k / 3, "decision": "mpc", "light_state": "green", "rob_speed": -math.inf if k == 2 else 0.25}


def test_complete_run_round_trips_exactly(tmp_path) -> None:
    with TraceWriter(tmp_path, COLUMNS, {"seed": 7}) as w:
        for k in range(5):
            w.write(_row(k))
        w.meta["summary"] = {"steps": 5}
    run = read_run(tmp_path)
    assert run.problems == ()
    assert run.meta["status"] == "complete" and run.meta["rows"] == 5 and run.meta["summary"] == {"steps": 5}
    assert np.array_equal(run.columns["t"], np.array([k * 0.1 for k in range(5)]))  # repr round-trips floats
    assert run.columns["v"][4] == 10.0 + 4 / 3
    assert run.columns["rob_speed"][2] == -math.inf
    assert np.isnan(run.columns["y"]).all()  # unset columns are empty, read as NaN
    assert run.columns["decision"] == ["mpc"] * 5


def test_crash_marks_run_and_keeps_rows(tmp_path) -> None:
    with pytest.raises(RuntimeError):
        with TraceWriter(tmp_path, COLUMNS, {}) as w:
            for k in range(3):
                w.write(_row(k))
            raise RuntimeError("solver exploded")
    run = read_run(tmp_path)
    assert run.rows == 3
    assert run.meta["status"] == "crashed" and "solver exploded" in run.meta["error"]
    assert any("crashed" in p for p in run.problems)


def test_unknown_column_is_refused(tmp_path) -> None:
    w = TraceWriter(tmp_path, COLUMNS, {})
    with pytest.raises(KeyError):
        w.write({"t": 0.0, "bogus": 1})
    w.close()


def test_killed_process_leaves_completed_rows_readable(tmp_path) -> None:
    """SIGKILL (no chance to clean up) mid-run: every written row survives; status says running."""
    script = textwrap.dedent(
        f"""
        import time, sys
        from twolevel.sim.trace import TraceWriter
        w = TraceWriter({str(tmp_path)!r}, ("t", "x"), {{}})
        k = 0
        while True:
            w.write({{"t": k * 0.1, "x": k}})
            k += 1
            if k == 20:
                print("ready", flush=True)
            time.sleep(0.001)
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    run = read_run(tmp_path)
    assert run.rows >= 20
    assert np.array_equal(run.columns["x"], np.arange(run.rows, dtype=float))
    assert run.meta["status"] == "running"
    assert any("running" in p for p in run.problems)


def test_truncated_last_line_is_reported_not_fatal(tmp_path) -> None:
    with TraceWriter(tmp_path, ("t", "x", "y"), {}) as w:
        for k in range(4):
            w.write({"t": k, "x": k, "y": k})
    with open(tmp_path / "trace.csv", "a") as fh:
        fh.write("4,4")  # a row cut short by a crash
    run = read_run(tmp_path)
    assert run.rows == 4
    assert any("truncated" in p for p in run.problems)


def test_missing_files_are_listed(tmp_path) -> None:
    run = read_run(tmp_path)
    assert run.rows == 0
    assert any("run.json is missing" in p for p in run.problems)
    assert any("trace.csv is missing" in p for p in run.problems)
    assert read_run(tmp_path / "nope").problems




def test_a_new_run_removes_the_previous_runs_report(tmp_path) -> None:
    """Re-running into a run directory left the old report.html beside the new trace (review)."""
    (tmp_path / "report.html").write_text("old")
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "speed.png").write_bytes(b"png")
    (tmp_path / "notes.txt").write_text("mine")
    with TraceWriter(tmp_path, ("t",), {}) as w:
        w.write({"t": 0.0})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "run.json", "trace.csv"]
