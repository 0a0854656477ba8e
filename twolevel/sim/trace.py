"""Run directories: ``trace.csv`` written row by row, ``run.json`` written atomically.

A run directory survives interruption: every completed step is a flushed CSV row, and
``run.json`` is replaced atomically (write to a temporary file, ``fsync``, ``os.replace``) at the
start (``status: running``) and at the end (``complete``, ``interrupted`` or ``crashed``, with the
number of rows). A reader that finds ``status: running`` knows the run did not end cleanly and
trusts the rows that are there.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from twolevel.atomic import write_json_atomic
from twolevel.milp.solution import ValueEnum

__all__ = ["BASE_COLUMNS", "TEXT_COLUMNS", "RunStatus", "TraceWriter", "RunData", "read_run", "write_json_atomic"]

TRACE_FILE = "trace.csv"
RUN_FILE = "run.json"

#: The columns every trace starts with, in order (what each holds: :mod:`twolevel.sim.engine`).
BASE_COLUMNS: tuple[str, ...] = (
    "t",
    "x",
    "y",
    "psi",
    "v",
    "delta",
    "gamma",
    "decision",
    "t_high_ms",
    "t_low_ms",
    "t_step_ms",
    "n_near",
    "min_dist",
    "min_gap",
    "tracking_error",
    "v_max",
    "light_state",
)

TEXT_COLUMNS = frozenset({"decision", "light_state", "verification", "failsafe", "refuted"})

#: Files a report writes into a run directory: a new run in the same directory removes them, so
#: a report of the previous run never stands beside the new trace.
REPORT_OUTPUTS: tuple[str, ...] = ("report.html", "summary.json", "summary.md", "animation.gif", "figures")


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    f = float(value)
    if math.isnan(f):
        return "nan"
    if math.isinf(f):
        return "inf" if f > 0 else "-inf"
    return repr(f)


class RunStatus(ValueEnum):
    """How a run ended, as ``run.json`` records it (``status``)."""

    RUNNING = "running"
    """Written at the start: a reader that still finds it knows the run did not end cleanly."""
    COMPLETE = "complete"
    """Every step ran (to the scenario's duration, or the goal)."""
    INTERRUPTED = "interrupted"
    """Stopped by the user (Ctrl-C); every completed step is kept."""
    CRASHED = "crashed"
    """Stopped on an internal error, or the run directory could not be written; the completed
    steps are kept and ``error`` says why."""


class TraceWriter:
    """Append one CSV row per simulation step; keep ``run.json`` current.

    Use as a context manager: leaving the block normally marks the run ``complete``; an
    exception marks it ``crashed`` (``KeyboardInterrupt``: ``interrupted``) and re-raises.
    Each row is flushed to the operating system as it is written (``flush_every`` rows; one by
    default), so a killed process leaves every completed step in the file; :func:`read_run`
    ignores a last line cut short.
    """

    def __init__(
        self,
        run_dir: str | os.PathLike[str],
        columns: Sequence[str],
        meta: Mapping[str, Any],
        *,
        flush_every: int = 1,
    ) -> None:
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        _remove_stale_report(self.run_dir)
        self.columns = tuple(columns)
        if len(set(self.columns)) != len(self.columns):
            raise ValueError("duplicate trace column names")
        self.meta: dict[str, Any] = dict(meta)
        self.rows = 0
        self._flush_every = max(1, flush_every)
        self._started = time.time()
        self._fh = open(self.run_dir / TRACE_FILE, "w", encoding="utf-8", newline="")
        self._fh.write(",".join(self.columns) + "\n")
        self._fh.flush()
        self._write_meta(RunStatus.RUNNING)

    def write(self, row: Mapping[str, Any]) -> None:
        """Append one step. Missing columns are written empty; unknown keys are an error."""
        unknown = set(row) - set(self.columns)
        if unknown:
            raise KeyError(f"trace row has columns not in the header: {sorted(unknown)}")
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([_cell(row.get(c)) for c in self.columns])
        self._fh.write(buf.getvalue())
        self.rows += 1
        if self.rows % self._flush_every == 0:
            self._fh.flush()

    def close(self, status: RunStatus = RunStatus.COMPLETE, summary: Mapping[str, Any] | None = None) -> None:
        """Flush the trace and record the final status (and summary) in ``run.json``."""
        if self._fh.closed:
            return
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self._fh.close()
        if summary is not None:
            self.meta["summary"] = dict(summary)
        self._write_meta(status)

    def _write_meta(self, status: RunStatus) -> None:
        self.meta["status"] = RunStatus(status).value
        self.meta["rows"] = self.rows
        self.meta["wall_time_s"] = round(time.time() - self._started, 3)
        write_json_atomic(self.run_dir / RUN_FILE, self.meta)

    def __enter__(self) -> "TraceWriter":
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close(RunStatus.COMPLETE, self.meta.get("summary"))
        elif issubclass(exc_type, KeyboardInterrupt):
            self.meta["error"] = "interrupted by the user (Ctrl-C)"
            self.close(RunStatus.INTERRUPTED, self.meta.get("summary"))
        else:
            self.meta["error"] = f"{exc_type.__name__}: {exc}"
            self.close(RunStatus.CRASHED, self.meta.get("summary"))


def _remove_stale_report(run_dir: Path) -> None:
    import shutil

    for name in REPORT_OUTPUTS:
        p = run_dir / name
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        elif p.exists() or p.is_symlink():
            p.unlink()


@dataclass(frozen=True)
class RunData:
    """A run directory read back: numeric columns as float arrays, text columns as lists."""

    run_dir: str
    columns: Mapping[str, Any]
    meta: Mapping[str, Any]
    problems: tuple[str, ...] = field(default=())

    @property
    def rows(self) -> int:
        return len(self.columns.get("t", ()))


def read_run(run_dir: str | os.PathLike[str]) -> RunData:
    """Read ``trace.csv`` and ``run.json``. Never raises on a damaged run: what is missing or
    truncated is listed in ``problems`` and the readable part is returned."""
    import numpy as np

    run_dir = Path(run_dir)
    problems: list[str] = []
    meta: dict[str, Any] = {}
    run_file = run_dir / RUN_FILE
    if not run_dir.is_dir():
        return RunData(str(run_dir), {}, {}, (f"'{run_dir}' is not a run directory",))
    if run_file.exists():
        try:
            meta = json.loads(run_file.read_text(encoding="utf-8"))
            if not isinstance(meta, dict):
                problems.append(f"{run_file}: not a JSON object")
                meta = {}
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            problems.append(f"{run_file}: unreadable ({exc})")
    else:
        problems.append(f"{run_file} is missing: settings and summary unknown")
    if meta.get("status") not in (None, RunStatus.COMPLETE):
        problems.append(f"the run ended '{meta.get('status')}' after {meta.get('rows', '?')} steps: {meta.get('error', 'no reason recorded')}")
    trace_file = run_dir / TRACE_FILE
    columns: dict[str, Any] = {}
    if not trace_file.exists():
        problems.append(f"{trace_file} is missing: no steps to report")
        return RunData(str(run_dir), columns, meta, tuple(problems))
    try:
        with open(trace_file, encoding="utf-8", newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            raw_rows = list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        problems.append(f"{trace_file}: unreadable ({exc})")
        return RunData(str(run_dir), columns, meta, tuple(problems))
    if not header:
        problems.append(f"{trace_file} is empty")
        return RunData(str(run_dir), columns, meta, tuple(problems))
    good = [r for r in raw_rows if len(r) == len(header)]
    if len(good) != len(raw_rows):
        bad = next(i for i, r in enumerate(raw_rows) if len(r) != len(header))
        problems.append(f"{trace_file}: row {bad + 2} is truncated; {len(raw_rows) - len(good)} row(s) ignored")
        good = raw_rows[:bad]
    for j, name in enumerate(header):
        values = [r[j] for r in good]
        if name in TEXT_COLUMNS:
            columns[name] = values
            continue
        try:
            columns[name] = np.array([float(v) if v != "" else np.nan for v in values], dtype=float)
        except ValueError:
            columns[name] = values
    return RunData(str(run_dir), columns, meta, tuple(problems))
