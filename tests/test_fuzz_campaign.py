"""Fuzzing campaigns (:mod:`twolevel.fuzz.campaign`, ``benchmarks/fuzz.py``): the same tally
whatever the number of workers, hangs stopped by the alarm or by killing the worker, a worker
that dies counted, and an interrupted campaign leaving its partial tally in ``--out``."""

from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

import pytest
from helpers.fuzz_targets import KINDS, misbehaving
from helpers.processes import left_behind

from twolevel.fuzz.campaign import CRASH, HANG, Campaign, run_campaign

REPO = Path(__file__).resolve().parents[1]


def _counts(tally: object) -> dict:
    return {k: v for k, v in asdict(tally).items() if k not in ("seconds", "load")}


@pytest.mark.slow
@pytest.mark.parametrize("target", ["rules", "traces", "world"])
def test_the_tally_is_the_same_whatever_the_number_of_workers(tmp_path: Path, target: str) -> None:
    options = {"root": str(REPO), "run_every": 1000}
    one = run_campaign(target, 24, Campaign(seed=5, jobs=1, options=options, scratch=tmp_path, report=lambda _: None))
    two = run_campaign(target, 24, Campaign(seed=5, jobs=2, options=options, scratch=tmp_path, report=lambda _: None))
    assert one.inputs == 24 and one.refused + one.accepted == 24
    assert _counts(one) == _counts(two)


@pytest.mark.slow
def test_hangs_and_dead_workers_are_counted_and_the_campaign_goes_on(tmp_path: Path) -> None:
    lines: list[str] = []
    c = Campaign(seed=4, jobs=2, timeout=1.0, grace=1.0, hang_s=0.3, scratch=tmp_path, report=lines.append,
                 out=tmp_path / "tally.json", options={"slow_s": 0.5})
    tally = run_campaign("misbehaving", 14, c, target=misbehaving)
    kinds = [random.Random(f"4:misbehaving:{i}").choice(KINDS) for i in range(14)]
    assert {"slow", "sleeps", "stuck", "dies"} <= set(kinds)  # the seed exercises every way to misbehave
    assert tally.inputs == 14
    assert tally.accepted == kinds.count("ok") + kinds.count("slow")
    assert tally.hangs == kinds.count("slow") + kinds.count("sleeps") + kinds.count("stuck")
    assert tally.internal == kinds.count("dies")
    slow = [ln for ln in lines if ": accepted," in ln]  # finished, but over the limit: shown with its input
    assert len(slow) == kinds.count("slow") and all("'a slow input'" in ln for ln in slow)
    stopped = [ln for ln in lines if f": {HANG}," in ln]
    assert sum("stopped by the alarm" in ln for ln in stopped) == kinds.count("sleeps")
    assert sum("the worker was killed" in ln for ln in stopped) == kinds.count("stuck")
    assert sum(f": {CRASH}," in ln for ln in lines) == kinds.count("dies")
    order = [int(ln.split("#")[1].split(" ")[0]) for ln in lines]
    assert order == sorted(order)  # reported in input order
    written = json.loads((tmp_path / "tally.json").read_text())
    assert written["targets"][0]["inputs"] == 14 and written["targets"][0]["hangs"] == tally.hangs


@pytest.mark.slow
def test_an_interrupted_campaign_leaves_its_partial_tally(tmp_path: Path) -> None:
    out = tmp_path / "tally.json"
    proc = subprocess.Popen([sys.executable, str(REPO / "benchmarks" / "fuzz.py"), "--target", "rules=100000",
                             "--jobs", "2", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if json.loads(out.read_text())["targets"][0]["inputs"] > 0:
                break
        except (OSError, ValueError, KeyError, IndexError):  # not yet written (never half-written)
            pass
        time.sleep(0.2)
    assert proc.poll() is None
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 143 and "Traceback" not in stderr, stderr
    data = json.loads(out.read_text())
    tally = data["targets"][0]
    assert data["status"] == "interrupted" and 0 < tally["inputs"] < 100000
    assert tally["refused"] + tally["accepted"] == tally["inputs"]
    assert f"{tally['inputs']}/100000" in stdout  # the partial table
    assert left_behind(proc.pid) == []  # the workers were stopped with it

