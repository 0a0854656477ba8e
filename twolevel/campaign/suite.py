"""``twolevel test``: every scenario below some paths, and every variant each lists, run as a
suite — in parallel on an executor, each case judged by its criteria.

Case ids are the scenario's path as given (``scenarios/cut_in.yaml``) and, for a variant,
``path::name``. ``-k`` selects cases as pytest does: words match as case-insensitive
substrings of the case's name below the folder it was found in (that folder's own name, the
path below it, ``::variant``; a file given by itself: its name), never of the folders above,
so where a suite is checked out does not change what a word selects; combined with ``and``,
``or``, ``not`` and parentheses. With ``failed_first`` the cases that failed last time (the cache file) run first. Results come back
in case order whatever order the workers finish in, so a suite's outputs depend only on the
cases and the seed. Outputs: JUnit XML (:func:`junit_xml`), JSON (:func:`suite_json`), GitHub
annotations (:func:`annotations`).
"""

from __future__ import annotations

import json
import os
import re
import signal
import time
from concurrent.futures import Executor, Future, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from twolevel.campaign.case import INTERRUPTED, Case, CaseResult, run_case
from twolevel.diagnostics import Diagnostic, Span

__all__ = ["discover", "select", "order_failed_first", "run_cases", "SuiteResult", "SuiteInterrupted", "junit_xml",
           "suite_json", "annotations", "read_cache", "write_cache", "run_dir_name", "KeywordError"]


class KeywordError(ValueError):
    """A ``-k`` expression that cannot be read."""


class SuiteInterrupted(KeyboardInterrupt):
    """A batch of cases a signal stopped: ``results`` are the cases that completed (in case
    order), ``signum`` the signal (raised by runners that return lists, such as a search's)."""

    def __init__(self, signum: int, results: Sequence[CaseResult]) -> None:
        from twolevel.interruption import describe

        super().__init__(describe(signum))
        self.signum = signum
        self.results = tuple(results)


@dataclass(frozen=True)
class SuiteResult:
    """Every case's result (in case order) and the suite's wall time [s]."""

    results: tuple[CaseResult, ...]
    wall_s: float
    interrupted: int | None = None
    """The signal that stopped the suite (None: it ran to the end); ``results`` then holds the
    cases that completed, in case order."""

    @property
    def counts(self) -> dict[str, int]:
        out = {"passed": 0, "failed": 0, "error": 0}
        for r in self.results:
            out[r.outcome] = out.get(r.outcome, 0) + 1
        return out

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.results)


def discover(paths: Sequence[str]) -> tuple[list[Case], list[Diagnostic]]:
    """The cases below ``paths``: each scenario file once (maps and rule files are skipped),
    then one case per variant it lists. Unreadable scenarios still give a case (it errors
    when run, with its diagnostics)."""
    from twolevel.pipeline.checking import RULE_SUFFIXES, collect_paths
    from twolevel.verdict.codes import SIM621
    from twolevel.world.document import read_document
    from twolevel.world.loader import file_kind

    files, diags = collect_paths(paths)
    cases: list[Case] = []
    for f in files:
        if f.endswith(RULE_SUFFIXES):
            continue
        doc, _ = read_document(f)
        if doc is not None and file_kind(doc.data) == "map":
            continue
        name = _keyword_name(f, paths)
        cases.append(Case(f, f, keywords=name))
        variants = doc.data.get("variants") if doc is not None else None
        for v in variants if isinstance(variants, list) else []:
            if isinstance(v, dict) and isinstance(v.get("name"), str):
                params = v.get("parameters") if isinstance(v.get("parameters"), dict) else {}
                seed = v.get("seed") if isinstance(v.get("seed"), int) else None
                expect = v.get("expect") if isinstance(v.get("expect"), dict) else None
                cases.append(Case(f"{f}::{v['name']}", f, dict(params), seed, expect, v["name"],
                                  f"{name}::{v['name']}"))
    if not cases and not any(d.is_error for d in diags):
        diags.append(SIM621(f"no scenario below {', '.join(paths)}", Span.whole_file(paths[0] if paths else "."),
                            hint="give scenario files (.yaml) or folders holding them"))
    return cases, diags


def _keyword_name(file: str, paths: Sequence[str]) -> str:
    """The part of the scenario ``file``'s path that ``-k`` reads: from the folder among ``paths``
    that holds it (its name included), or the file's name when it was given itself."""
    f = Path(file).resolve()
    best = f.name
    for p in paths:
        root = Path(p).resolve()
        if root.is_dir() and f.is_relative_to(root):
            below = (Path(root.name) / f.relative_to(root)).as_posix()
            best = below if len(below) > len(best) else best
    return best


_TOKEN = re.compile(r"\s*(\(|\)|[^\s()]+)")


def select(cases: Sequence[Case], expression: str | None) -> list[Case]:
    """The cases whose id matches the ``-k`` expression (all when None or empty). Raises
    :class:`KeywordError` for an expression that cannot be read."""
    if not expression or not expression.strip():
        return list(cases)
    tokens = _TOKEN.findall(expression)

    def parse(ident: str) -> bool:
        pos = 0

        def peek() -> str | None:
            return tokens[pos] if pos < len(tokens) else None

        def take() -> str:
            nonlocal pos
            if pos >= len(tokens):
                raise KeywordError(f"-k '{expression}': the expression ends too early")
            pos += 1
            return tokens[pos - 1]

        def or_() -> bool:
            value = and_()
            while peek() == "or":
                take()
                value = and_() or value
            return value

        def and_() -> bool:
            value = not_()
            while peek() == "and":
                take()
                value = not_() and value
            return value

        def not_() -> bool:
            if peek() == "not":
                take()
                return not not_()
            tok = take()
            if tok == "(":
                value = or_()
                if take() != ")":
                    raise KeywordError(f"-k '{expression}': missing ')'")
                return value
            if tok in (")", "and", "or"):
                raise KeywordError(f"-k '{expression}': unexpected '{tok}'")
            return tok.lower() in ident.lower()

        value = or_()
        if pos != len(tokens):
            raise KeywordError(f"-k '{expression}': unexpected '{tokens[pos]}'")
        return value

    return [c for c in cases if parse(c.keywords or c.id)]


def read_cache(path: str | os.PathLike[str]) -> set[str]:
    """The ids of the cases that failed in the last run (empty when there is no cache)."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return set()
    failed = data.get("failed") if isinstance(data, dict) else None
    return {str(x) for x in failed} if isinstance(failed, list) else set()


def write_cache(path: str | os.PathLike[str], results: Iterable[CaseResult]) -> None:
    """Remember the cases that did not pass (for ``--failed-first``), atomically."""
    from twolevel.atomic import write_json_atomic

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, {"failed": sorted(r.case.id for r in results if not r.passed)})


def order_failed_first(cases: Sequence[Case], failed: set[str]) -> list[Case]:
    """Cases that failed last time first, each group in its own order."""
    return [c for c in cases if c.id in failed] + [c for c in cases if c.id not in failed]


def run_dir_name(case_id: str) -> str:
    """A folder name for a case id: path separators and odd characters become '_'."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", case_id.replace(os.sep, "__")).strip("_.") or "case"


def run_cases(cases: Sequence[Case], executor: Executor, runs_dir: str | os.PathLike[str], *,
              keep_passed: bool = False, frames: bool = True,
              on_result: Callable[[CaseResult], None] | None = None) -> SuiteResult:
    """Run every case on ``executor`` (run directories ``runs_dir/<case>``) and collect the
    results in case order; ``on_result`` is called as each case finishes (for a live view).

    A ``KeyboardInterrupt`` (Ctrl-C, or SIGTERM / SIGHUP under :mod:`twolevel.interruption`)
    stops the suite: the cases not started are cancelled, the running ones stopped (the
    executor's ``interrupt``, :class:`~twolevel.campaign.executor.LocalExecutor`; their run
    directories say so), and the result holds the cases that completed, with the signal."""
    from twolevel import interruption

    t0 = time.perf_counter()
    futures: dict[Future, int] = {}
    out: list[CaseResult | None] = [None] * len(cases)

    def collect(fut: Future) -> CaseResult:
        i = futures[fut]
        try:
            result = fut.result()
        except Exception as exc:  # the worker process itself died
            result = CaseResult(cases[i], "error", "crashed", None, {}, (), None, 0.0, 0.0,
                                (f"the worker failed: {type(exc).__name__}: {exc}",))
        out[i] = result
        return result

    try:
        for i, case in enumerate(cases):
            run_dir = str(Path(runs_dir) / run_dir_name(case.id))
            futures[executor.submit(run_case, case, run_dir, keep_passed, frames)] = i
        for fut in as_completed(futures):
            result = collect(fut)
            if on_result is not None:
                on_result(result)
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", None) or interruption.received() or signal.SIGINT
        with interruption.shielded():  # stopping the workers; a second signal kills them instead
            stop = getattr(executor, "interrupt", None)
            if stop is not None:
                stop(signum)
            else:
                executor.shutdown(wait=False, cancel_futures=True)
            for fut in futures:
                if out[futures[fut]] is None and fut.done() and not fut.cancelled():
                    collect(fut)
        done = tuple(r for r in out if r is not None and r.status != INTERRUPTED)
        return SuiteResult(done, time.perf_counter() - t0, int(signum))
    return SuiteResult(tuple(r for r in out if r is not None), time.perf_counter() - t0)


# ----------------------------------------------------------------------------- outputs


def _failure_text(r: CaseResult) -> tuple[str, str]:
    """A one-line message and the full text of a case that did not pass."""
    if r.outcome == "error":
        return (r.messages[0].splitlines()[0] if r.messages else f"the run ended '{r.status}'"), "\n".join(r.messages)
    crit = [c for c in (r.verdict or {}).get("criteria", []) if not c.get("passed")]
    lines = [f"{c['name']}: {c['detail']} (measured {c.get('measured')}, bound {c.get('bound')}, margin {c.get('margin')})"
             for c in crit]
    if r.run_dir:
        lines.append(f"run directory: {r.run_dir}")
    return "; ".join(f"{c['name']}: {c['detail']}" for c in crit) or "failed", "\n".join(lines)


def junit_xml(suite: SuiteResult, name: str = "twolevel") -> str:
    """The suite as JUnit XML: one ``testsuite``, one ``testcase`` per case (``classname`` the
    scenario file, ``name`` the variant or ``nominal``), a ``failure`` per failed case and an
    ``error`` per case that could not be run; the seed, parameters and kept run directory in
    ``system-out``. Valid against the Jenkins xUnit plugin's junit-10 schema."""
    from xml.etree import ElementTree as ET

    counts = suite.counts
    root = ET.Element("testsuites", name=name, tests=str(len(suite.results)), failures=str(counts["failed"]),
                      errors=str(counts["error"]), time=f"{suite.wall_s:.3f}")
    ts = ET.SubElement(root, "testsuite", name=name, tests=str(len(suite.results)), failures=str(counts["failed"]),
                       errors=str(counts["error"]), skipped="0", time=f"{suite.wall_s:.3f}",
                       timestamp=time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime()), hostname="localhost")
    for r in suite.results:
        tc = ET.SubElement(ts, "testcase", name=r.case.variant or "nominal", classname=r.case.scenario,
                           time=f"{r.wall_s:.3f}")
        if not r.passed:
            message, text = _failure_text(r)
            tag, kind = ("failure", "criteria") if r.outcome == "failed" else ("error", r.status)
            el = ET.SubElement(tc, tag, message=message, type=kind)
            el.text = text
        out = [f"seed: {r.seed}"] + [f"parameter {k} = {v:g}" for k, v in sorted(r.case.parameters.items())]
        out += [f"run directory: {r.run_dir}"] if r.run_dir else []
        ET.SubElement(tc, "system-out").text = "\n".join(out)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def suite_json(suite: SuiteResult) -> dict[str, Any]:
    """The suite as JSON: counts, wall time and every case with its verdict."""
    return {
        "passed": suite.passed, "counts": suite.counts, "wall_s": round(suite.wall_s, 3),
        "cases": [{"id": r.case.id, "scenario": r.case.scenario, "variant": r.case.variant or None,
                   "parameters": dict(r.case.parameters), "seed": r.seed, "outcome": r.outcome, "status": r.status,
                   "failed": list(r.failed), "run_dir": r.run_dir, "wall_s": round(r.wall_s, 3),
                   "verdict": r.verdict, "messages": list(r.messages)} for r in suite.results],
    }


def _where(case: Case, key: Sequence[Any]) -> Span:
    """Where the scenario states a criterion (or the nearest place that exists)."""
    from twolevel.world.loader import _read_kind

    doc, _ = _read_kind(Path(case.scenario), "scenario", None)
    if doc is None:
        return Span.whole_file(case.scenario)
    if case.variant:
        variants = doc.data.get("variants") or []
        i = next((j for j, v in enumerate(variants) if isinstance(v, dict) and v.get("name") == case.variant), None)
        if i is not None and ("variants", i, *key) in doc.where:
            return doc.locate(("variants", i, *key))
    return doc.locate(tuple(key))


def annotations(suite: SuiteResult) -> str:
    """GitHub Actions workflow commands: one ``::error`` per failed criterion (at the line that
    states it) and per case that could not be run."""

    def esc(text: str, prop: bool = False) -> str:
        text = text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")
        return text.replace(":", "%3A").replace(",", "%2C") if prop else text

    lines = []
    for r in suite.results:
        if r.outcome == "error":
            span = Span.whole_file(r.case.scenario)
            msg = _failure_text(r)[0]
            lines.append(f"::error file={esc(span.file, True)},line={span.line},title={esc(r.case.id + ': could not run', True)}::{esc(msg)}")
            continue
        for c in (r.verdict or {}).get("criteria", []):
            if c.get("passed"):
                continue
            span = _where(r.case, c.get("key") or ["expect"])
            title = f"{r.case.id}: {c['name']} failed"
            lines.append(f"::error file={esc(span.file, True)},line={span.line},col={span.column},"
                         f"title={esc(title, True)}::{esc(c['detail'])}")
    return "\n".join(lines) + ("\n" if lines else "")
