"""Runs interrupted at random moments: a real ``twolevel simulate`` process is sent SIGINT,
SIGTERM or SIGHUP after a chosen delay (start-up included: imports, loading, compiled functions
being built) and what it left behind is checked.

What must hold (:func:`interrupt_run` lists every breach in ``problems``):

- no Python traceback on stderr, and the process ends within the time limit;
- its exit code is the documented one: 2 for a run that recorded the interruption (or, in
  start-up, reported it: SIM612), 128 + the signal's number when it came before the command began
  or after the run ended, 0 or 1 when the run had already finished; a SIGTERM or SIGHUP in the
  interpreter's first milliseconds, before any of twolevel's code runs, kills the process (the
  signal's default) with nothing written, and any signal in its last ones, after a completed run
  (Python restores the default handlers as it shuts down), kills it too: both are allowed;
- the run directory is readable: without ``run.json`` nothing at all was written (the signal came
  before the run began); with it, ``run.json`` says how the run ended (``complete``, or
  ``interrupted`` with the signal named), every row of ``trace.csv`` is complete (as many cells as
  the header, no half-written line) and their number is the one ``run.json`` records;
- ``report`` works on it: a report is written, or (no row) it is refused with a ``ReportError``.

``benchmarks/interruptions.py`` runs a campaign of these; ``tests/sim/test_interruptions.py`` a
few (slow).
"""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["SIGNAL_NAMES", "Interruption", "interrupt_run", "check_run_dir"]

SIGNAL_NAMES: tuple[str, ...] = ("SIGINT", "SIGTERM", "SIGHUP")


@dataclass(frozen=True)
class Interruption:
    """One interrupted run: the signal, its delay [s] after the process started (None: the run
    ended first and nothing was sent), the exit code, ``run.json``'s status (None: no run.json),
    the rows recorded, how long the process took to end after the signal [s] and every breach of
    the module docstring's invariant."""

    signal: str
    after_s: float
    sent: bool
    exit_code: int | None
    status: str | None
    rows: int
    stop_s: float
    problems: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """Nothing broke."""
        return not self.problems


def interrupt_run(scenario: str, run_dir: str | os.PathLike[str], signame: str, after_s: float, *,
                  duration: float | None = None, timeout: float = 180.0, report: bool = True) -> Interruption:
    """Start ``twolevel simulate scenario --out run_dir`` (``--duration``), send ``signame``
    ``after_s`` seconds later and check the result (see the module docstring)."""
    signum = int(getattr(signal, signame))
    run_dir = Path(run_dir).resolve()
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "twolevel", "simulate", str(Path(scenario).resolve()), "--out", str(run_dir),
           "--no-progress"]
    if duration is not None:
        cmd += ["--duration", f"{duration:g}"]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    problems: list[str] = []
    t0 = time.perf_counter()
    # run beside the run directory: ``-m`` imports from the working directory first, and the
    # twolevel to test is the installed one, not whatever checkout the caller stands in
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=run_dir.parent)
    sent = False
    try:
        proc.wait(timeout=after_s)
    except subprocess.TimeoutExpired:
        proc.send_signal(signum)
        sent = True
    t_sent = time.perf_counter()
    try:
        _, err_b = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err_b = proc.communicate()
        problems.append(f"still running {timeout:g} s after {signame}: killed")
    stop_s = time.perf_counter() - t_sent
    err = err_b.decode("utf-8", "replace")
    if "Traceback (most recent call last)" in err:
        problems.append("a traceback on stderr: " + err[err.index("Traceback"):][:400])
    code = proc.returncode
    status, rows, more = check_run_dir(run_dir, report=report)
    problems += more
    allowed = {2, 128 + signum} if sent else {0, 1}
    if sent and status == "complete":
        allowed |= {0, 1}  # the run had ended; the signal came while the command was printing
    if sent and (status == "complete" or (status is None and signum != signal.SIGINT)):
        # the interpreter's first milliseconds, before any of twolevel ran, or its last ones, after
        # the command ended (Python restores the default handlers as it shuts down): killed
        allowed.add(-signum)
    if code not in allowed:
        problems.append(f"exit code {code} (expected one of {sorted(allowed)}); stderr: {err[-300:]!r}")
    if sent and status == "interrupted" and code != 2:
        problems.append(f"the run recorded the interruption but exited {code}, not 2")
    return Interruption(signame, round(t_sent - t0, 3), sent, code, status, rows, round(stop_s, 3), tuple(problems))


def check_run_dir(run_dir: str | os.PathLike[str], *, report: bool = True) -> tuple[str | None, int, list[str]]:
    """``run.json``'s status, the rows of ``trace.csv`` and every breach of the invariant (see
    the module docstring) in ``run_dir``."""
    d = Path(run_dir)
    problems: list[str] = []
    run_file, trace_file = d / "run.json", d / "trace.csv"
    if not run_file.exists():
        if trace_file.exists():
            problems.append("trace.csv without run.json")
        return None, 0, problems
    try:
        meta = json.loads(run_file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return None, 0, [f"run.json unreadable: {exc}"]
    status = meta.get("status")
    if status not in ("complete", "interrupted"):
        problems.append(f"run.json says '{status}' ({meta.get('error', 'no error recorded')})")
    if status == "interrupted" and "interrupted by" not in str(meta.get("error", "")):
        problems.append(f"an interrupted run.json does not say by what: {meta.get('error')!r}")
    rows = 0
    if trace_file.exists():
        text = trace_file.read_text(encoding="utf-8")
        if text and not text.endswith("\n"):
            problems.append("trace.csv ends in a half-written row")
        table = list(csv.reader(io.StringIO(text)))
        header, body = (table[0], table[1:]) if table else ([], [])
        short = [i + 2 for i, r in enumerate(body) if len(r) != len(header)]
        if short:
            problems.append(f"trace.csv rows with the wrong number of cells at lines {short[:5]}")
        rows = len(body)
        if meta.get("rows") != rows:
            problems.append(f"run.json records {meta.get('rows')} rows, trace.csv holds {rows}")
    elif status is not None:
        problems.append("run.json without trace.csv")
    if report:
        problems += _report_problems(d, rows)
    return status, rows, problems


def _report_problems(run_dir: Path, rows: int) -> list[str]:
    from twolevel.report import ReportError, build_report

    try:
        build_report(run_dir, gif=False, formats=("svg",))
    except ReportError as exc:
        return [f"report refused a run with {rows} rows: {exc}"] if rows else []
    except Exception as exc:  # noqa: BLE001 - the invariant: report never fails otherwise
        return [f"report failed: {type(exc).__name__}: {exc}"]
    return []
