"""Real ``twolevel simulate`` processes interrupted by SIGINT, SIGTERM and SIGHUP: mid-run, in
start-up, and at a few random moments (:mod:`twolevel.fuzz.interrupts` checks what each left:
no traceback, the documented exit code, run.json saying how the run ended, every row intact,
report working). ``benchmarks/interruptions.py`` runs the long campaign."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from twolevel.fuzz.interrupts import SIGNAL_NAMES, check_run_dir, interrupt_run

REPO = Path(__file__).resolve().parents[2]
SCENARIO = str(REPO / "scenarios" / "traffic_rules.yaml")
pytestmark = pytest.mark.slow


def _rows(trace: Path) -> int:
    try:
        return max(0, trace.read_text().count("\n") - 1)
    except OSError:
        return 0


@pytest.mark.parametrize("signame", ["SIGTERM", "SIGHUP", "SIGINT"])
def test_a_signal_mid_run_is_recorded_and_the_rows_kept(tmp_path: Path, signame: str) -> None:
    run_dir = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "twolevel", "simulate", SCENARIO, "--out", str(run_dir),
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 240
    while _rows(run_dir / "trace.csv") < 5 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(getattr(signal, signame))
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 2 and b"Traceback" not in err and b"SIM612" in err
    status, rows, problems = check_run_dir(run_dir)
    assert problems == [] and status == "interrupted" and rows >= 5
    meta = json.loads((run_dir / "run.json").read_text())
    assert meta["error"] == ("interrupted by the user (Ctrl-C)" if signame == "SIGINT" else f"interrupted by {signame}")
    assert meta["summary"]["status"] == "interrupted" and meta["summary"]["steps"] == rows


def test_an_interruption_during_the_imports_is_one_line(tmp_path: Path) -> None:
    r = interrupt_run(SCENARIO, tmp_path / "run", "SIGINT", 0.25, report=False)
    assert r.sent and r.ok, r.problems
    assert r.status is None and not (tmp_path / "run").exists()


def test_a_few_interruptions_at_random_moments(tmp_path: Path) -> None:
    rng = random.Random(17)
    for i in range(3):
        r = interrupt_run(SCENARIO, tmp_path / f"run{i}", rng.choice(SIGNAL_NAMES), round(rng.uniform(0, 8), 2),
                          duration=4)
        assert r.ok, r


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM", "SIGHUP"])
def test_a_signal_while_compiled_functions_are_built_ends_the_run(tmp_path: Path, signame: str) -> None:
    """The warm-up (the low level's compiled rollouts being built, the C compiler in a
    subprocess) is stopped by the first signal: here a compiler that never finishes (a stuck
    build), which held the signal for its whole time limit when the warm-up only ended at a
    checkpoint. The compiler is killed and the run directory says the run was interrupted."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    started = tmp_path / "gcc-pid"
    gcc = bin_dir / "gcc"
    gcc.write_text(f"#!/bin/sh\necho $$ > '{started}.tmp' && mv '{started}.tmp' '{started}'\nexec sleep 600\n")
    gcc.chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}"}
    run_dir = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "twolevel", "simulate", SCENARIO, "--out", str(run_dir),
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    deadline = time.monotonic() + 240
    while not started.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert started.exists() and proc.poll() is None, "the compiler was never started"
    assert (run_dir / "run.json").exists(), "the compiler ran before the run directory was written"
    proc.send_signal(getattr(signal, signame))
    try:
        _, err = proc.communicate(timeout=60)  # held, the signal would wait for the compiler's 600 s
    finally:
        proc.kill()
    assert proc.returncode == 2 and b"Traceback" not in err and b"SIM612" in err, err.decode()[-2000:]
    status, rows, problems = check_run_dir(run_dir)
    assert problems == [] and status == "interrupted" and rows == 0
    meta = json.loads((run_dir / "run.json").read_text())
    assert meta["error"] == ("interrupted by the user (Ctrl-C)" if signame == "SIGINT" else f"interrupted by {signame}")
    compiler = int(started.read_text())
    for _ in range(100):  # the compiler was killed with the run, not left behind
        if not _alive(compiler):
            break
        time.sleep(0.05)
    assert not _alive(compiler)


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False
