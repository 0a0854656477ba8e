"""One case of a campaign: a scenario with parameter values and a seed, run to its verdict.

:func:`run_case` is what every worker runs (locally or on a Dask cluster). It writes the
**concrete scenario** — the scenario with its parameters' values, its ``extends`` merged, its
map and rule paths made relative to the new file — as ``scenario.yaml`` in the case's run
directory, simulates that file, judges the run, and removes the directory of a passing case
unless asked to keep it. A failure therefore reproduces from one file:
``twolevel simulate RUN_DIR/scenario.yaml``.
"""

from __future__ import annotations

import math
import os
import shutil
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from twolevel.diagnostics import Diagnostic

__all__ = ["Case", "CaseResult", "run_case", "write_concrete", "CONCRETE_FILE", "INTERRUPTED"]

CONCRETE_FILE = "scenario.yaml"
INTERRUPTED = "interrupted"
"""The ``status`` of a case a signal stopped (the run's own status then, ``run.json`` says so)."""


@dataclass(frozen=True)
class Case:
    """What to run: ``scenario`` (a path), ``parameters`` (name → value; the rest nominal), the
    ``seed`` (None: the scenario's), a criteria override (``expect``, as YAML data), and an id
    unique in its campaign (``path`` or ``path::variant``; ``#0007`` for a campaign's samples),
    and the name ``-k`` reads (``keywords``; empty: the id)."""

    id: str
    scenario: str
    parameters: Mapping[str, float] = field(default_factory=dict)
    seed: int | None = None
    expect: Mapping[str, Any] | None = None
    variant: str = ""
    keywords: str = ""


@dataclass(frozen=True)
class CaseResult:
    """A case's outcome: ``outcome`` passed / failed / error (it could not be run to a verdict),
    the verdict as JSON (``verdict``), each criterion's margin (``margins``), the failed
    criteria, the run directory (None once removed), the time the run took in its worker
    (``run_s``) and from load to verdict (``wall_s``) [s], and the diagnostics as text."""

    case: Case
    outcome: str
    status: str
    verdict: Mapping[str, Any] | None
    margins: Mapping[str, float]
    failed: tuple[str, ...]
    run_dir: str | None
    run_s: float
    wall_s: float
    messages: tuple[str, ...] = ()
    seed: int | None = None
    goal_reached_t: float | None = None

    @property
    def passed(self) -> bool:
        return self.outcome == "passed"


def _relative(target: Path, base: Path) -> str:
    try:
        return os.path.relpath(target, base)
    except ValueError:  # another drive
        return str(target)


def write_concrete(case: Case, target: str | os.PathLike[str], header: str = "") -> tuple[Path | None, list[Diagnostic]]:
    """Write ``case`` as a standalone scenario file ``target``: parameters replaced by their
    values (and no longer declared), ``extends`` merged, paths relative to ``target``, the seed
    and criteria of the case. Returns ``(path or None, diagnostics)``: None when the case is not
    a valid scenario (the diagnostics point into the original files)."""
    import yaml

    from twolevel.world.loader import _read_kind, _resolve, load_scenario
    from twolevel.world.parameters import substitute

    scn, diags = load_scenario(case.scenario, case.parameters)
    if scn is None:
        return None, diags
    doc, _ = _read_kind(Path(case.scenario), "scenario", None)
    assert doc is not None  # it just loaded
    sub, _ = substitute(doc, case.parameters)
    data = dict(sub.document.data)
    out = Path(target)
    out.parent.mkdir(parents=True, exist_ok=True)
    here = out.parent.resolve()
    locate = sub.document.locate
    data["map"] = _relative(_resolve(data["map"], locate(("map",), value=True)), here)
    rules = []
    for i, ref in enumerate(data.get("rules") or []):
        if isinstance(ref, dict):
            at = locate(("rules", i, "file"), value=True)
            rules.append({**ref, "file": _relative(_resolve(ref["file"], at), here)})
        else:
            rules.append(_relative(_resolve(ref, locate(("rules", i), value=True)), here))
    data["rules"] = rules
    for key in ("extends", "parameters", "variants"):
        data.pop(key, None)
    if case.seed is not None:
        data["run"] = {**(data.get("run") or {}), "seed": int(case.seed)}
    if case.expect is not None:
        data["expect"] = dict(case.expect)
    values = ", ".join(f"{k} = {v:g}" for k, v in sub.values.items())
    lines = [f"# {line}" for line in header.splitlines()] + [f"# from {case.scenario}" + (f" with {values}" if values else "")]
    text = "\n".join(lines) + "\n" + yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)
    from twolevel.atomic import write_text_atomic

    write_text_atomic(out, text)
    return out, diags


def _margins(verdict: Mapping[str, Any] | None) -> dict[str, float]:
    out: dict[str, float] = {}
    for c in (verdict or {}).get("criteria", []):
        m = c.get("margin")
        out[c["name"]] = math.inf if m == "inf" else -math.inf if m in ("-inf", None) else float(m)
    return out


def run_case(case: Case, run_dir: str, keep_passed: bool = False, frames: bool = True) -> CaseResult:
    """Run ``case`` into ``run_dir`` (its concrete scenario, trace, run.json with the verdict)
    and judge it. Never raises: a case that cannot be run is an ``error`` outcome with the
    reason in ``messages``."""
    from twolevel import interruption
    from twolevel.sim.trace import RunStatus

    t0 = time.perf_counter()
    messages: list[str] = []
    try:
        interruption.checkpoint()  # a case taken after the campaign was interrupted is not started
    except KeyboardInterrupt as exc:
        return CaseResult(case, "error", INTERRUPTED, None, {}, (), None, 0.0, 0.0, (str(exc),))
    try:
        from twolevel.sim.engine import simulate_scenario
        from twolevel.verdict.judge import judge_run

        path, diags = write_concrete(case, Path(run_dir) / CONCRETE_FILE)
        messages += [f"{d.span}: {d.code} [{d.severity.value}] {d.message}" for d in diags if d.is_error]
        if path is None:
            return CaseResult(case, "error", "invalid", None, {}, (), None, 0.0, time.perf_counter() - t0, tuple(messages))
        r0 = time.perf_counter()
        summary, diags = simulate_scenario(str(path), run_dir, frames=frames)
        run_s = time.perf_counter() - r0
        messages += [f"{d.span}: {d.code} [{d.severity.value}] {d.message}" for d in diags if d.is_error]
        if summary is None:
            status = INTERRUPTED if interruption.received() is not None else "invalid"  # SIM612: in start-up
            return CaseResult(case, "error", status, None, {}, (), run_dir, run_s, time.perf_counter() - t0, tuple(messages))
        with interruption.shielded():  # the run is written: its verdict too, whatever arrives now
            verdict, diags = judge_run(run_dir, path)
        messages += [f"{d.span}: {d.code} [{d.severity.value}] {d.message}" for d in diags if d.is_error]
    except KeyboardInterrupt as exc:  # while the concrete scenario was written: nothing ran
        return CaseResult(case, "error", INTERRUPTED, None, {}, (), None, 0.0, time.perf_counter() - t0, (str(exc),))
    except Exception as exc:  # a worker must report, never die: the campaign goes on
        messages.append(f"internal error: {type(exc).__name__}: {exc}\n{traceback.format_exc()}")
        return CaseResult(case, "error", "crashed", None, {}, (), run_dir if os.path.isdir(run_dir) else None,
                          0.0, time.perf_counter() - t0, tuple(messages))
    if verdict is None:
        return CaseResult(case, "error", summary.status.value, None, {}, (), run_dir, run_s, time.perf_counter() - t0,
                          tuple(messages), summary.seed)
    outcome = "passed" if verdict.passed else ("failed" if summary.status is RunStatus.COMPLETE else "error")
    kept: str | None = run_dir
    if outcome == "passed" and not keep_passed:
        shutil.rmtree(run_dir, ignore_errors=True)
        kept = None
    return CaseResult(case, outcome, summary.status.value, verdict.to_json(), _margins(verdict.to_json()),
                      tuple(c.name for c in verdict.failed), kept, run_s, time.perf_counter() - t0, tuple(messages),
                      summary.seed, summary.goal_reached_t)
