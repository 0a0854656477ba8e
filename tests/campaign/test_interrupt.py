"""``twolevel test``, ``sweep`` and ``falsify`` (local worker processes) stopped by a real signal:
the workers stop (their runs record the interruption), the outputs hold every case that
completed, written whole, the exit code is 128 + the signal's number, stderr says so in one line,
and no process of the campaign is left behind. A Ctrl-C is sent as a terminal sends it: to the
whole foreground process group."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import pytest
import xmlschema
from helpers.processes import left_behind

HERE = Path(__file__).resolve().parent
SCENARIOS = HERE.parent / "scenarios"
SUITE = SCENARIOS / "suite"
NONE = SCENARIOS / "campaign" / "none.yaml"
pytestmark = pytest.mark.slow


def _start(args: list[str], cwd: Path) -> subprocess.Popen:
    # a session of its own, as a terminal's: the process group a Ctrl-C goes to, and a way to
    # find every process the campaign started
    return subprocess.Popen([sys.executable, "-m", "twolevel", *args], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, start_new_session=True, text=True)


def _interrupt(proc: subprocess.Popen, signame: str, ready: Callable[[], bool] | None = None,
               line: str | None = None) -> tuple[str, str]:
    """Wait until ``ready()`` or a stdout line contains ``line``, send ``signame`` (SIGINT to the
    process group), and return stdout and stderr once the process has ended."""
    deadline = time.monotonic() + 300
    seen = []
    if line is not None:
        assert proc.stdout is not None
        for text in proc.stdout:
            seen.append(text)
            if line in text:
                break
    while ready is not None and not ready() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "the campaign ended before it could be interrupted"
    sig = getattr(signal, signame)
    if signame == "SIGINT":
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=180)
    finally:
        proc.kill()
    assert left_behind(proc.pid) == [], "processes of the campaign were left behind"
    return "".join(seen) + out, err


def _some_run(runs: Path, status: str, name: str = "*") -> bool:
    """Some run below ``runs`` (whose folder matches ``name``) has ``status`` in its run.json
    ("running": under way)."""
    for meta in runs.glob(f"{name}/run.json"):
        try:
            if json.loads(meta.read_text())["status"] == status:
                return True
        except (OSError, ValueError, KeyError):  # being replaced: atomically, but read it again
            pass
    return False


def _interrupted_runs(runs: Path) -> list[str]:
    out = []
    for meta in runs.glob("*/run.json"):
        data = json.loads(meta.read_text())
        assert data["status"] in ("complete", "interrupted"), data["status"]
        if data["status"] == "interrupted":
            out.append(data["error"])
    return out


def _said(signame: str) -> str:
    return "interrupted by the user (Ctrl-C)" if signame == "SIGINT" else f"interrupted by {signame}"


def _suite_with_a_long_case(tmp: Path) -> Path:
    """The suite with its stuck case running 120 s instead of 10 (≈ 20 s of wall time): the case
    under way when the signal comes is that one, not a sub-second case that may complete before the
    signal reaches its worker (a race the faster steps made likely under load)."""
    out = tmp / "suite"
    out.mkdir()
    root = SCENARIOS.parent.parent
    for f in SUITE.glob("*.yaml"):
        text = f.read_text().replace("../../../rules/", f"{root}/rules/").replace("map: ../", f"map: {SCENARIOS}/")
        if f.name == "stuck.yaml":
            text = text.replace("run: {duration: 10,", "run: {duration: 120,")
        (out / f.name).write_text(text)
    return out


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM", "SIGHUP"])
def test_an_interrupted_suite_writes_what_completed_and_stops_its_workers(tmp_path: Path, signame: str) -> None:
    suite = _suite_with_a_long_case(tmp_path)
    proc = _start(["test", str(suite), "-j", "2", "--runs-dir", "runs", "--keep-passed", "--junit-xml", "junit.xml",
                   "--json", "results.json", "--cache-file", "cache.json"], tmp_path)
    # after the first case's line ("PASSED  <case> (6.8 s)"), once the long case is under way (a
    # run that has not written its run.json yet is cancelled, not interrupted: nothing records it)
    out, err = _interrupt(proc, signame, ready=lambda: _some_run(tmp_path / "runs", "running", "*stuck*"),
                          line=" s)")
    assert proc.returncode == 128 + getattr(signal, signame), (out, err)
    assert "Traceback" not in err and err.strip().splitlines() == [err.strip()], err
    assert err.startswith(f"twolevel: {_said(signame)}: ") and " of 8 cases completed" in err
    data = json.loads((tmp_path / "results.json").read_text())
    done = [c["id"] for c in data["cases"]]
    assert 1 <= len(done) < 8 and done == sorted(done)
    assert all(c["status"] == "complete" and c["outcome"] in ("passed", "failed") for c in data["cases"])
    doc = xmlschema.XMLSchema(str(HERE / "junit.xsd")).to_dict(str(tmp_path / "junit.xml"))  # valid, whole
    assert doc["testsuite"][0]["@tests"] == len(done)
    assert not (tmp_path / "cache.json").exists()  # the last failures are not forgotten for the cases not run
    stopped = _interrupted_runs(tmp_path / "runs")
    assert stopped and all(e == _said(signame) for e in stopped)  # the running cases recorded it themselves
    assert len(list((tmp_path / "runs").glob("*/run.json"))) == len(done) + len(stopped)


def test_an_interrupted_sweep_tabulates_the_runs_that_completed(tmp_path: Path) -> None:
    proc = _start(["sweep", str(SUITE / "goal_at.yaml"), "--samples", "8", "-j", "2", "--out", "sweep",
                   "--keep-passed"], tmp_path)
    runs = tmp_path / "sweep" / "runs"
    out, err = _interrupt(proc, "SIGTERM", ready=lambda: _some_run(runs, "complete"))
    assert proc.returncode == 143 and "Traceback" not in err and "runs completed" in err, (out, err)
    with (tmp_path / "sweep" / "results.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert 1 <= len(rows) < 8 and all(r["status"] == "complete" for r in rows)
    assert len(json.loads((tmp_path / "sweep" / "results.json").read_text())) == len(rows)
    assert (tmp_path / "sweep" / "report.html").exists()
    assert _interrupted_runs(runs) == ["interrupted by SIGTERM"] * (len(list(runs.glob("*/run.json"))) - len(rows))


def test_an_interrupted_search_records_the_simulations_that_completed(tmp_path: Path) -> None:
    proc = _start(["falsify", str(NONE), "--objective", "at_fault", "--budget", "16", "-j", "2", "--out", "search"],
                  tmp_path)
    out, err = _interrupt(proc, "SIGHUP", line="generation 1:")
    assert proc.returncode == 129 and "Traceback" not in err and "no counterexample among them" in err, (out, err)
    summary = json.loads((tmp_path / "search" / "falsify.json").read_text())
    assert summary["interrupted"] == "interrupted by SIGHUP" and 1 <= summary["simulations"] < 16
    with (tmp_path / "search" / "results.csv").open(newline="") as fh:
        assert len(list(csv.DictReader(fh))) == summary["simulations"]
