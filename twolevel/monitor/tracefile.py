"""Recorded drives as CSV: reading them, and monitoring rules over them (``twolevel monitor``).

A trace CSV has a header row, a time column ``t`` (or ``time``) in seconds and one column per
signal [SI units]; each further row is one sample. The participants quantifiers range over are
those with a column ``present[ID]`` (> 0 where participant ID is present); participant ID's
signal NAME is the column ``NAME[ID]`` (:func:`twolevel.stl.analysis.participant_key`). The time column must increase strictly and be
uniform (spacing within 1 % of its median) unless a period ``dt`` is given, which then decides
(and makes the time column optional: sample ``k`` is at ``k * dt``). Every problem is a
:class:`~twolevel.diagnostics.Diagnostic` with the file, line and column, never an exception.

The file is streamed: cells go straight into typed arrays (8 bytes per number), so a large file
costs about its numeric size in memory.

JSON (:func:`to_json`): ``{"rules": [{"name", "verdict", "robustness", "satisfied",
"first_violation_t"}]}`` (+ ``"series"`` per rule when asked), every rule of the file in its order.
``verdict`` is ``"holds"`` (at every sample), ``"violated"`` (somewhere) or ``"not judged"``;
``robustness`` is the value at the first sample; infinite values (``true``, empty windows,
overflows) are written as the strings ``"inf"`` / ``"-inf"``; ``first_violation_t`` is in seconds
from the time column, or ``null``. A rule that could not be judged on the trace (it reads a column
the trace lacks, SIM602; its robustness is NaN somewhere, SIM607; it quantifies over participants
and the trace records none, SIM609; it reads such a rule) has ``"verdict": "not judged"``, the
code that says why (``"code"``) and ``null`` robustness, verdict and violation time: never a
vacuous ``true``.
"""

from __future__ import annotations

import bisect
import contextlib
import csv
import difflib
import io
import math
import os
import re
from array import array
from dataclasses import dataclass, field, replace
from typing import Any, BinaryIO, Iterator, Mapping, Sequence

import numpy as np

from twolevel.diagnostics import Diagnostic, Severity, Span
from twolevel.files import open_regular
from twolevel.monitor.codes import SIM601, SIM602, SIM603, SIM604, SIM605, SIM606, SIM607, SIM608, SIM609
from twolevel.monitor.errors import MonitorError
from twolevel.monitor.robustness import DEFAULT_BUILTINS, Builtin, TraceEvaluator
from twolevel.stl import ast
from twolevel.stl.analysis import PRESENT, fold_term, participant_key, participants_in, quantifies

__all__ = [
    "Trace",
    "RuleVerdict",
    "Unjudged",
    "MonitorReport",
    "read_trace",
    "monitor_trace",
    "consts_of",
    "to_json",
]

TIME_COLUMNS = ("t", "time")
SPACING_TOLERANCE = 0.01  # relative to the period
ONE_ROW_DT = 0.1  # [s] assumed when a one-row trace gives no period and none is given
MAX_CELL_ERRORS = 20
NOT_JUDGED = "not judged"  # the verdict of a rule the trace cannot judge (JSON, table)
BUILTIN_SIGNALS: Mapping[str, tuple[str, ...]] = {"collision_free": ("min_gap",)}


@dataclass(frozen=True, eq=False)
class Trace:
    """A uniformly sampled recording: times ``t`` [s], signal columns (not the time), period ``dt`` [s]."""

    path: str
    t: np.ndarray
    columns: Mapping[str, np.ndarray]
    dt: float
    #: Columns that hold text or missing cells (a simulator's ``decision``, ``light_state``),
    #: with the diagnostic to give if a rule reads one of them.
    unusable: Mapping[str, Diagnostic] = field(default_factory=dict)

    @property
    def samples(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True, eq=False)
class RuleVerdict:
    """One rule over a trace: robustness at the first sample, whether it holds there (≥ 0), the
    first time [s] its robustness signal is negative (``None`` if never), and the signal itself
    if asked for."""

    name: str
    robustness: float
    satisfied: bool
    first_violation_t: float | None
    series: np.ndarray | None = None


@dataclass(frozen=True)
class Unjudged:
    """A rule the trace cannot judge: ``code`` the diagnostic that says why (``SIM602`` a column
    missing, ``SIM607`` undefined robustness, ``SIM609`` no participants recorded; a rule that
    reads such a rule carries that rule's code)."""

    name: str
    code: str


@dataclass(frozen=True, eq=False)
class MonitorReport:
    """Every evaluated rule (``rules``) and every rule that could not be judged (``unjudged``),
    each in the rule file's order; ``order`` every rule's name in that order."""

    trace: str
    dt: float
    samples: int
    rules: tuple[RuleVerdict, ...] = field(default_factory=tuple)
    unjudged: tuple[Unjudged, ...] = field(default_factory=tuple)
    order: tuple[str, ...] = field(default_factory=tuple)

    @property
    def violated(self) -> bool:
        """True if some rule is violated at the first sample or later (the CLI's exit 1)."""
        return any(not r.satisfied or r.first_violation_t is not None for r in self.rules)


# --------------------------------------------------------------------------------- reading


class _Record:
    """Where a CSV record lies in the file: the physical lines the reader took for it (a quoted
    cell may hold line breaks) and the number of its first line."""

    def __init__(self, text: Iterator[str]) -> None:
        self._text = text
        self.lines: list[str] = []
        self.first = 1

    def physical(self) -> Iterator[str]:
        """The file's lines, each remembered for the record being read."""
        for ln in self._text:
            self.lines.append(ln)
            yield ln

    def next(self, line_num: int) -> None:
        """Forget the record read; the next one starts after line ``line_num``."""
        self.lines.clear()
        self.first = line_num + 1

    def cell_spans(self, path: str) -> list[Span]:
        """The span of every cell of the record (blanks around it left out): one scan of its text,
        as the ``csv`` module splits it (a quote opens a quoted part only at a cell's start)."""
        text = "".join(self.lines)
        n = len(text.rstrip("\r\n"))
        breaks = [m.end() for m in _LINE_END.finditer(text, 0, n)]
        bounds: list[tuple[int, int]] = []
        i = 0
        while True:
            while i < n and text[i] in " \t":
                i += 1
            k = i
            if k < n and text[k] == '"':
                k += 1
                while k < n and (text[k] != '"' or text.startswith('""', k)):
                    k += 2 if text[k] == '"' else 1
            k = text.find(",", k, n)
            end = n if k < 0 else k
            stop = end
            while stop > i and text[stop - 1] in " \t":
                stop -= 1
            bounds.append((i, stop))
            if k < 0:
                break
            i = k + 1

        def at(offset: int) -> tuple[int, int]:
            row = bisect.bisect_right(breaks, offset)
            return self.first + row, offset - (breaks[row - 1] if row else 0) + 1

        spans = []
        for lo, hi in bounds:
            (l0, c0), (l1, c1) = at(lo), at(max(hi, lo + 1) if lo < n else lo)
            spans.append(Span(path, l0, c0, l1, c1))
        return spans

    def span(self, path: str) -> Span:
        """The record's first line, whole."""
        first = self.lines[0].rstrip("\r\n") if self.lines else ""
        return Span(path, self.first, 1, self.first, len(first) + 1)


_LINE_END = re.compile(r"\r\n|\r|\n")


def _read_rows(
    path: str, diags: list[Diagnostic]
) -> tuple[list[str], list[array], list[int], dict[str, Diagnostic], Span] | None:
    """Stream the CSV: header names, one typed array per column, the file line of every row, and
    for each column holding a cell that is not a number (text, empty, NaN) the diagnostic of its
    first such cell, and where the header is. ``inf``/``-inf`` are numbers (e.g. ``d_stop`` with no
    stop line near). Lines end at LF, CRLF or CR; a record starts on the line after the previous
    one ended (a quoted cell may hold line breaks)."""
    whole = Span.whole_file(path)
    fh, refusal = open_regular(path)
    if fh is None:
        assert refusal is not None
        if refusal.kind == "missing":
            diags.append(SIM605(f"trace file '{path}' does not exist", whole, hint="check the path"))
        elif refusal.kind == "directory":
            diags.append(SIM605(f"'{path}' is a directory, not a trace file", whole))
        elif refusal.kind == "special":
            diags.append(SIM605(f"'{path}' is not a regular file: it is {refusal.detail}", whole,
                                hint="save the trace to a file first"))
        else:
            diags.append(SIM605(f"cannot read trace file '{path}': {refusal.detail}", whole))
        return None
    with fh:
        return _read_open(path, fh, diags)


def _read_open(
    path: str, fh: BinaryIO, diags: list[Diagnostic]
) -> tuple[list[str], list[array], list[int], dict[str, Diagnostic], Span] | None:
    whole = Span.whole_file(path)
    try:
        head = fh.read(8192)
        fh.seek(0)
    except OSError as exc:
        diags.append(SIM605(f"cannot read trace file '{path}': {exc.strerror or exc}", whole))
        return None
    if b"\x00" in head:
        diags.append(SIM605("the trace file is binary (it contains NUL bytes), not CSV text", whole))
        return None
    if not head.strip():
        diags.append(SIM604("the trace file is empty: expected a header row such as 't,v,v_max'", whole))
        return None
    header: list[str] | None = None
    cols: list[array] = []
    lines = array("l")
    unusable: dict[str, Diagnostic] = {}
    errors = 0
    line = 0
    try:
        with _text_of(fh) as text:
            record = _Record(text)
            reader = csv.reader(record.physical(), skipinitialspace=True)
            for row in reader:
                line = record.first  # where the record starts (a quoted cell may span lines)
                if not row or all(not c.strip() for c in row):
                    record.next(reader.line_num)
                    continue
                if header is None:
                    header = [c.strip() for c in row]
                    header_span = record.span(path)
                    cols = [array("d") for _ in header]
                    if not _check_header(record.cell_spans(path), header, diags):
                        return None
                    record.next(reader.line_num)
                    continue
                if len(row) != len(header):
                    diags.append(SIM603(f"row has {len(row)} cells but the header has {len(header)} columns",
                                        record.span(path)))
                    errors += 1
                else:
                    where: list[Span] | None = None  # cell spans, computed once per row if needed
                    for j, cell in enumerate(row):
                        text = cell.strip()
                        try:
                            value = float(text)
                        except ValueError:
                            value = math.nan
                            what = "is empty" if not text else f"'{text[:40]}' is not a number"
                        else:
                            what = "is NaN" if math.isnan(value) else ""
                        if what and header[j] not in unusable:
                            if where is None:
                                where = record.cell_spans(path)
                            unusable[header[j]] = SIM603(
                                f"cell in column '{header[j]}' {what}",
                                where[j] if j < len(where) else record.span(path),
                                hint="a signal read by a rule must be a number in every row (inf is allowed, NaN is not)",
                            )
                        cols[j].append(value)
                    lines.append(line)
                record.next(reader.line_num)
                if errors >= MAX_CELL_ERRORS:
                    diags.append(SIM603(f"stopped after {errors} bad rows", Span(path, line, 1)))
                    return None
    except UnicodeDecodeError:
        bad = _first_non_utf8_line(fh)
        diags.append(
            SIM605(
                f"line {bad} of the trace file is not valid UTF-8",
                Span(path, bad, 1),
                hint="save the file as UTF-8",
            )
        )
        return None
    except (csv.Error, OSError) as exc:
        diags.append(SIM605(f"cannot read the trace file: {exc}", Span(path, max(line, 1), 1)))
        return None
    if header is None:
        diags.append(SIM604("the trace file is empty: expected a header row such as 't,v,v_max'", whole))
        return None
    if errors:
        return None
    return header, cols, list(lines), unusable, header_span


@contextlib.contextmanager
def _text_of(fh: BinaryIO) -> Iterator[io.TextIOWrapper]:
    """``fh`` read as UTF-8 text (BOM dropped, newlines kept for csv); ``fh`` stays open after."""
    text = io.TextIOWrapper(fh, encoding="utf-8-sig", newline="")
    try:
        yield text
    finally:
        text.detach()


def _first_non_utf8_line(fh: BinaryIO) -> int:
    """The 1-based number of the first line that does not decode as UTF-8 (streamed)."""
    fh.seek(0)
    for number, raw in enumerate(fh, start=1):
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError:
                return number
    return 1


def _check_header(spans: list[Span], header: list[str], diags: list[Diagnostic]) -> bool:
    ok = True
    seen: set[str] = set()
    for j, name in enumerate(header):
        span = spans[min(j, len(spans) - 1)]
        if not name:
            diags.append(SIM606(f"column {j + 1} of the header has no name", span))
            ok = False
        elif name in seen:
            diags.append(SIM606(f"column '{name}' appears twice in the header", span))
            ok = False
        seen.add(name)
    return ok


def read_trace(path: str | os.PathLike[str], *, dt: float | None = None) -> tuple[Trace | None, list[Diagnostic]]:
    """Read a trace CSV. ``dt`` [s] overrides the period read from the time column.

    Returns the trace (``None`` if it cannot be used) and the diagnostics found.
    """
    path = os.fspath(path)
    diags: list[Diagnostic] = []
    whole = Span.whole_file(path)
    if dt is not None and not (math.isfinite(dt) and dt > 0):
        diags.append(SIM601(f"the sampling period must be a positive number of seconds, got {dt}", whole))
        return None, diags
    read = _read_rows(path, diags)
    if read is None:
        return None, diags
    header, cols, lines, unusable, header_span = read
    tcol = next((c for c in TIME_COLUMNS if c in header), None)
    if tcol is not None and tcol in unusable:
        diags.append(unusable[tcol])
        return None, diags
    n = len(lines)
    columns = {name: np.frombuffer(col, dtype=np.float64) if len(col) else np.empty(0) for name, col in zip(header, cols)}
    if tcol is None and dt is None:
        diags.append(
            SIM601(
                "the trace has no time column",
                header_span,
                hint="name the time column 't' or 'time' (seconds), or give the period with --dt",
            )
        )
        return None, diags
    if n == 0:
        diags.append(SIM604("the trace has a header but no samples", whole, hint="record at least one row"))
        return None, diags
    t = columns.pop(tcol) if tcol is not None else np.arange(n) * dt
    if tcol is not None:
        infinite = np.flatnonzero(~np.isfinite(t))
        if infinite.size:
            k = int(infinite[0])
            diags.append(SIM601(f"time {t[k]:g}: the time column must hold finite numbers of seconds",
                                Span(path, lines[k], 1)))
            return None, diags
        diffs = np.diff(t)
        bad = np.flatnonzero(diffs <= 0)
        if bad.size:
            k = int(bad[0]) + 1
            diags.append(
                SIM601(
                    f"time goes from {t[k - 1]:g} s to {t[k]:g} s: the time column must increase strictly",
                    Span(path, lines[k], 1),
                    hint="sort the rows by time and remove repeated samples",
                )
            )
            return None, diags
        period = float(np.sort(diffs)[(n - 2) // 2]) if n > 1 else None  # lower median
        if period is not None:
            off = np.flatnonzero(np.abs(diffs - (dt or period)) > SPACING_TOLERANCE * (dt or period))
            if off.size:
                k = int(off[0]) + 1
                where = Span(path, lines[k], 1)
                if dt is None:
                    diags.append(
                        SIM601(
                            f"samples are not uniform: {diffs[k - 1]:g} s between this row and the previous one, "
                            f"but {period:g} s elsewhere",
                            where,
                            hint="resample the trace to a fixed period (or give --dt to take rows as samples)",
                        )
                    )
                    return None, diags
                diags.append(
                    SIM601(
                        f"the time column's spacing ({diffs[k - 1]:g} s here) differs from --dt {dt:g} s; "
                        f"rows are taken as samples every {dt:g} s",
                        where,
                        severity=Severity.WARNING,
                    )
                )
        if dt is None:
            if period is None:
                diags.append(
                    SIM608(
                        f"one sample: the period cannot be read from the time column; {ONE_ROW_DT:g} s is assumed",
                        Span(path, lines[0], 1),
                        hint="give --dt to choose it",
                    )
                )
                dt = ONE_ROW_DT
            else:
                span_dt = float(t[-1] - t[0]) / (n - 1)  # uniform: the mean is the most accurate
                dt = float(f"{span_dt:.12g}")  # 0.1, not 0.09999999999999998 from decimal times
    assert dt is not None
    for name in unusable:
        columns.pop(name, None)
    for pid in participants_in(columns):  # presence as a robustness: +inf where present (> 0), else -inf
        key = participant_key(PRESENT, pid)
        columns[key] = np.where(columns[key] > 0, np.inf, -np.inf)
    return Trace(path, t, columns, float(dt), unusable), diags


# --------------------------------------------------------------------------------- monitoring


def consts_of(rule_file: ast.RuleFile) -> dict[str, float]:
    """The values of the file's ``const float NAME = value`` declarations (in order)."""
    out: dict[str, float] = {}
    for d in rule_file.declarations:
        if d.kind == "const" and d.value is not None:
            value = fold_term(d.value, out)  # the type checker's folding: finite numbers only
            if isinstance(value, ast.Num):
                out[d.name] = float(value.value)
    return out


def _reads(formula: ast.Node, skip: set[str]) -> list[ast.Var | ast.Call | ast.ParticipantSignal]:
    """The signal reads of a formula (Vars not in ``skip``, built-in calls, participant signals),
    in source order."""
    return [
        n for n in formula.walk()
        if (isinstance(n, ast.Var) and n.name not in skip) or isinstance(n, (ast.Call, ast.ParticipantSignal))
    ]


def _columns_read(node: ast.Var | ast.Call | ast.ParticipantSignal, pids: Sequence[str]) -> list[str]:
    """The trace columns a signal read needs: the signal's, a built-in's, or the participant
    signal's column of every participant."""
    if isinstance(node, ast.Var):
        return [node.name]
    if isinstance(node, ast.ParticipantSignal):
        return [participant_key(node.name, p) for p in pids]
    return list(BUILTIN_SIGNALS.get(node.name, ()))


def _listed(names: Sequence[str], most: int = 20) -> str:
    """``names`` for a hint, the first ``most`` of them (a trace may have 100,000 columns)."""
    if not names:
        return "(none)"
    more = f", … ({len(names) - most} more)" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def _finite(x: float) -> Any:
    if math.isnan(x):
        return None
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return float(x)


def monitor_trace(
    rules: Sequence[ast.Rule] | ast.RuleFile,
    consts: Mapping[str, float],
    trace: Trace,
    *,
    series: bool = False,
    builtins: Mapping[str, Builtin] | None = None,
    participants: Sequence[str] | None = None,
) -> tuple[MonitorReport, list[Diagnostic]]:
    """Evaluate every rule over the trace (offline, RTAMT semantics). A rule that cannot be judged
    on it (it reads a column the trace lacks, its robustness is undefined, it quantifies over
    participants the trace does not record, or it reads such a rule) gets no verdict: a
    diagnostic, and an entry in the report's ``unjudged``. ``participants``: the ids the run
    had, when known (its ``run.json``); an empty one says the run had none, so a quantifier is
    judged over the empty set instead of being refused as unrecorded (SIM609)."""
    if isinstance(rules, ast.RuleFile):
        consts = {**consts_of(rules), **consts}
        rules = rules.rules
    builtins = DEFAULT_BUILTINS if builtins is None else builtins
    diags: list[Diagnostic] = []
    report_rules: list[RuleVerdict] = []
    failed: dict[str, str] = {}  # rule name -> the code of why it was not judged
    known = list(trace.columns)
    whole = Span.whole_file(trace.path)
    order = tuple(r.name for r in rules)
    if trace.samples == 0:
        diags.append(SIM604("the trace has no samples", whole))
        return MonitorReport(trace.path, trace.dt, 0, (), tuple(Unjudged(n, SIM604.id) for n in order), order), diags
    hints: dict[str, str] = {}
    skip = set(consts) | {r.name for r in rules}  # once: per rule it made R rules cost O(R²)
    pids = participants_in(trace.columns)
    none_took_part = participants is not None and len(participants) == 0  # the empty set is then the truth
    evaluator: TraceEvaluator | MonitorError
    try:
        evaluator = TraceEvaluator(trace.columns, trace.dt, consts=consts, builtins=builtins)
    except MonitorError as exc:  # e.g. no signal column: every rule that gets to run reports it
        evaluator = exc
    for rule in rules:
        missing = []
        why: str | None = None
        if not pids and not none_took_part and quantifies(rule.formula):
            why = SIM609.id
            had = f" (its run had {len(participants)}: {_listed(participants)})" if participants else ""
            diags.append(SIM609(
                f"rule '{rule.name}' cannot be judged: it quantifies over participants, but the trace "
                f"{os.path.basename(trace.path)} records none{had} (no column {participant_key(PRESENT, 'ID')}), "
                "so its quantifiers would hold vacuously",
                rule.name_span or rule.span or whole,
                hint="re-run `twolevel simulate` with this rule file among the scenario's rules: a run records "
                     "each participant's presence present[ID] and signals NAME[ID] only when a loaded rule reads them"))
        for node in _reads(rule.formula, skip):
            for name in _columns_read(node, pids):
                if name in trace.unusable and name not in missing:
                    missing.append(name)
                    bad = trace.unusable[name]
                    diags.append(replace(bad, message=f"rule '{rule.name}' reads signal '{name}': {bad.message}"))
                elif name not in trace.columns and name not in missing:
                    missing.append(name)
                    if name not in hints:  # once per name: O(columns) each, and many rules may read it
                        close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
                        hints[name] = f"did you mean '{close[0]}'?" if close else f"the trace has columns: {_listed(known)}"
                    hint = hints[name]
                    diags.append(
                        SIM602(
                            f"rule '{rule.name}' reads signal '{name}', but the trace {os.path.basename(trace.path)} "
                            f"has no column '{name}'",
                            node.span or rule.name_span or rule.span or whole,
                            hint=hint,
                        )
                    )
        deps = [failed[n.name] for n in rule.formula.walk() if isinstance(n, ast.Var) and n.name in failed]
        if missing:
            why = (trace.unusable[missing[0]].code if missing[0] in trace.unusable else SIM602.id)
        why = why or (deps[0] if deps else None)
        if why is not None:
            failed[rule.name] = why
            continue
        try:
            if isinstance(evaluator, MonitorError):
                raise evaluator
            with np.errstate(all="ignore"):
                rob = evaluator.evaluate(rule.formula)
            undefined = np.flatnonzero(np.isnan(rob))
            if undefined.size:
                raise MonitorError(
                    f"its robustness is undefined (NaN) from t = {float(trace.t[undefined[0]]):g} s: a term there is "
                    "inf - inf or 0 * inf (it overflows, or reads an infinite signal)", rule.name)
            evaluator.add(rule.name, rob)
        except MonitorError as exc:
            diags.append(SIM607(f"rule '{rule.name}': {exc.message}", rule.name_span or rule.span or whole))
            failed[rule.name] = SIM607.id
            continue
        neg = np.flatnonzero(rob < 0)
        report_rules.append(
            RuleVerdict(
                name=rule.name,
                robustness=float(rob[0]),
                satisfied=bool(rob[0] >= 0),
                first_violation_t=float(trace.t[neg[0]]) if neg.size else None,
                series=rob if series else None,
            )
        )
    unjudged = tuple(Unjudged(name, code) for name, code in failed.items())
    return MonitorReport(trace.path, trace.dt, trace.samples, tuple(report_rules), unjudged, order), diags


def to_json(report: MonitorReport) -> dict[str, Any]:
    """The report as JSON-safe data (see the module docstring for inf/NaN)."""
    items: dict[str, dict[str, Any]] = {}
    for r in report.rules:
        item: dict[str, Any] = {
            "name": r.name,
            "verdict": "holds" if r.satisfied and r.first_violation_t is None else "violated",
            "robustness": _finite(r.robustness),
            "satisfied": r.satisfied,
            "first_violation_t": r.first_violation_t,
        }
        if r.series is not None:
            item["series"] = [_finite(float(v)) for v in r.series]
        items[r.name] = item
    for u in report.unjudged:
        items[u.name] = {"name": u.name, "verdict": NOT_JUDGED, "code": u.code, "robustness": None,
                         "satisfied": None, "first_violation_t": None}
    order = report.order or tuple(items)
    return {"rules": [items[name] for name in order if name in items]}
