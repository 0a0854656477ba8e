"""Run directories: ``trace.csv`` written row by row, ``run.json`` written atomically.

A run directory survives interruption: every completed step is a flushed CSV row, and
``run.json`` is replaced atomically (write to a temporary file, ``fsync``, ``os.replace``) at the
start (``status: running``) and at the end (``complete``, ``interrupted`` or ``crashed``, with the
number of rows and, unless complete, the ``error``: which signal, or what failed). A reader that
finds ``status: running`` knows the run did not end cleanly (the process was killed) and trusts
the rows that are there.

A :class:`RunDirectory` is held by one run at a time: it takes an exclusive lock
(:class:`~twolevel.files.DirectoryLock`, released by the kernel if the process dies), so a second
run into the same directory is refused (:class:`~twolevel.files.DirectoryBusy`) instead of
interleaving its rows with the first's. Opening it refuses a symbolic link or a special file
(a FIFO) where ``trace.csv``, ``run.json`` or ``frames.jsonl`` belong
(:class:`~twolevel.files.UnsafeOutput`) before anything is touched, then removes the previous
run's outputs, the report included, so nothing of an older run stands beside the new one.
:func:`read_run` reads only regular files (a FIFO there would block it).
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
from twolevel.files import DirectoryLock, check_output, create_output, open_regular, read_regular
from twolevel.interruption import describe
from twolevel.milp.solution import ValueEnum

__all__ = ["BASE_COLUMNS", "TEXT_COLUMNS", "RunStatus", "RunDirectory", "TraceWriter", "RunData", "read_run",
           "write_json_atomic", "TRACE_FILE", "RUN_FILE", "FRAMES_FILE"]

TRACE_FILE = "trace.csv"
RUN_FILE = "run.json"
FRAMES_FILE = "frames.jsonl"
RUN_FILE_LIMIT = 1 << 28
"""[bytes] The largest ``run.json`` read back (it holds the map's lane lines: megabytes at most)."""

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
RUN_OUTPUTS: tuple[str, ...] = (TRACE_FILE, RUN_FILE, FRAMES_FILE)
"""The files a run writes."""


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
    """Stopped by the user (Ctrl-C) or by SIGTERM / SIGHUP (``error`` names it); every completed
    step is kept."""
    CRASHED = "crashed"
    """Stopped on an internal error, or the run directory could not be written; the completed
    steps are kept and ``error`` says why."""
    ABORTED = "aborted"
    """Stopped because the co-simulated traffic failed (SUMO rejected its own network or route
    files during the run, SIM632); the completed steps are kept and ``error`` says why."""


class RunDirectory:
    """The directory one run writes, held from opening to :meth:`release` (or the end of a
    ``with`` block): locked, cleared of the previous run's outputs, ``run.json`` written with
    ``meta``, this process's id (``pid``) and ``status: running`` (see the module docstring).
    Raises ``OSError`` when it cannot be held: :class:`~twolevel.files.DirectoryBusy` (another
    run holds it; its ``holder`` is the pid that run recorded), :class:`~twolevel.files.UnsafeOutput`
    (a link or a special file where an output belongs)."""

    def __init__(self, run_dir: str | os.PathLike[str], meta: Mapping[str, Any]) -> None:
        self.path = Path(run_dir)
        self._lock = DirectoryLock(self.path, holder=lambda: _recorded_pid(self.path))
        try:
            for name in RUN_OUTPUTS:
                check_output(self.path / name)
            _remove_previous_outputs(self.path)
            self.meta: dict[str, Any] = {"pid": os.getpid(), **meta}
            self.rows = 0
            self._started = time.time()
            self.record(RunStatus.RUNNING)
        except BaseException:
            self._lock.release()
            raise

    def record(self, status: RunStatus) -> None:
        """Write ``run.json``: ``meta`` with ``status``, the rows written and the wall time."""
        self.meta["status"] = RunStatus(status).value
        self.meta["rows"] = self.rows
        self.meta["wall_time_s"] = round(time.time() - self._started, 3)
        write_json_atomic(self.path / RUN_FILE, self.meta)

    def release(self) -> None:
        """Give the directory up to other runs (idempotent)."""
        self._lock.release()

    def __enter__(self) -> "RunDirectory":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _recorded_pid(run_dir: Path) -> int | None:
    """The process id the run holding ``run_dir`` recorded in its ``run.json`` (None: unknown)."""
    data, _ = read_regular(run_dir / RUN_FILE, RUN_FILE_LIMIT)
    try:
        pid = json.loads(data.decode("utf-8")).get("pid") if data else None
    except (UnicodeDecodeError, ValueError, AttributeError, RecursionError):
        return None
    return pid if isinstance(pid, int) and not isinstance(pid, bool) and pid > 0 else None


class TraceWriter:
    """Append one CSV row per simulation step to ``trace.csv`` of a :class:`RunDirectory` (one
    it is given, or one it opens on ``run_dir`` with ``meta`` and releases when closed); keep
    ``run.json`` current.

    Use as a context manager: leaving the block normally marks the run ``complete``; an
    exception marks it ``crashed`` (``KeyboardInterrupt``: ``interrupted``, its message naming
    the signal) and re-raises. Each row is flushed to the operating system as it is written
    (``flush_every`` rows; one by default), so a killed process leaves every completed step in
    the file; :func:`read_run` ignores a last line cut short.
    """

    def __init__(
        self,
        run_dir: str | os.PathLike[str] | RunDirectory,
        columns: Sequence[str],
        meta: Mapping[str, Any] | None = None,
        *,
        flush_every: int = 1,
    ) -> None:
        self.columns = tuple(columns)
        if len(set(self.columns)) != len(self.columns):
            raise ValueError("duplicate trace column names")
        self._owns = not isinstance(run_dir, RunDirectory)
        self.directory = RunDirectory(run_dir, meta or {}) if not isinstance(run_dir, RunDirectory) else run_dir
        if not self._owns and meta:
            self.directory.meta.update(meta)
        self.run_dir = self.directory.path
        self._flush_every = max(1, flush_every)
        try:
            self._fh = io.open(create_output(self.run_dir / TRACE_FILE), "w", encoding="utf-8", newline="")
            header = io.StringIO()  # quoted where a name needs it (a participant id with a comma)
            csv.writer(header, lineterminator="\n").writerow(self.columns)
            self._fh.write(header.getvalue())
            self._fh.flush()
            self.directory.record(RunStatus.RUNNING)
        except BaseException:
            if self._owns:
                self.directory.release()
            raise

    @property
    def meta(self) -> dict[str, Any]:
        """What ``run.json`` records (its directory's)."""
        return self.directory.meta

    @property
    def rows(self) -> int:
        """Rows written."""
        return self.directory.rows

    def write(self, row: Mapping[str, Any]) -> None:
        """Append one step. Missing columns are written empty; unknown keys are an error."""
        unknown = set(row) - set(self.columns)
        if unknown:
            raise KeyError(f"trace row has columns not in the header: {sorted(unknown)}")
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([_cell(row.get(c)) for c in self.columns])
        self._fh.write(buf.getvalue())
        self.directory.rows += 1
        if self.directory.rows % self._flush_every == 0:
            self._fh.flush()

    def close(self, status: RunStatus = RunStatus.COMPLETE, summary: Mapping[str, Any] | None = None) -> None:
        """Flush the trace and record the final status (and summary) in ``run.json``."""
        if self._fh.closed:
            return
        try:
            self._fh.flush()
            os.fsync(self._fh.fileno())
        finally:
            self._fh.close()
        if summary is not None:
            self.meta["summary"] = dict(summary)
        try:
            self.directory.record(status)
        finally:
            if self._owns:
                self.directory.release()

    def __enter__(self) -> "TraceWriter":
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close(RunStatus.COMPLETE, self.meta.get("summary"))
        elif issubclass(exc_type, KeyboardInterrupt):
            self.meta["error"] = describe(getattr(exc, "signum", None))
            self.close(RunStatus.INTERRUPTED, self.meta.get("summary"))
        else:
            self.meta["error"] = f"{exc_type.__name__}: {exc}"
            self.close(RunStatus.CRASHED, self.meta.get("summary"))


def _remove_previous_outputs(run_dir: Path) -> None:
    """Remove what an earlier run (and its report) wrote into ``run_dir``; links are removed,
    never followed."""
    import shutil

    for name in RUN_OUTPUTS + REPORT_OUTPUTS:
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
    data, refusal = read_regular(run_file, RUN_FILE_LIMIT)
    if data is not None:
        try:
            meta = json.loads(data.decode("utf-8"))
            if not isinstance(meta, dict):
                problems.append(f"{run_file}: not a JSON object")
                meta = {}
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
            problems.append(f"{run_file}: unreadable ({exc})")
    elif refusal is not None and refusal.kind == "missing":
        problems.append(f"{run_file} is missing: settings and summary unknown")
    elif refusal is not None:
        problems.append(f"{run_file}: unreadable ({refusal.detail})")
    if meta.get("status") not in (None, RunStatus.COMPLETE):
        problems.append(f"the run ended '{meta.get('status')}' after {meta.get('rows', '?')} steps: {meta.get('error', 'no reason recorded')}")
    trace_file = run_dir / TRACE_FILE
    columns: dict[str, Any] = {}
    fh, refusal = open_regular(trace_file)
    if fh is None:
        assert refusal is not None
        problems.append(f"{trace_file} is missing: no steps to report" if refusal.kind == "missing"
                        else f"{trace_file}: unreadable ({refusal.detail})")
        return RunData(str(run_dir), columns, meta, tuple(problems))
    try:
        with io.TextIOWrapper(fh, encoding="utf-8", newline="") as text:
            content = text.read()
        reader = csv.reader(io.StringIO(content))
        header = next(reader, None)
        raw_rows = list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        problems.append(f"{trace_file}: unreadable ({exc})")
        return RunData(str(run_dir), columns, meta, tuple(problems))
    if not header:
        problems.append(f"{trace_file} is empty")
        return RunData(str(run_dir), columns, meta, tuple(problems))
    if raw_rows and not content.endswith("\n"):  # the last row was being written: its cells may be cut
        problems.append(f"{trace_file}: row {len(raw_rows) + 1} is truncated (no line end); it is ignored")
        raw_rows.pop()
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
