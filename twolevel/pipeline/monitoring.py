"""``twolevel monitor``: every rule of a rule file evaluated over a recorded trace (offline).

Returns the verdicts and the diagnostics (:class:`MonitorResult`); the CLI renders them.
Heavy modules are imported inside :func:`monitor`.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Mapping, Sequence

from twolevel.diagnostics import Diagnostic
from twolevel.files import read_text_quietly

__all__ = ["MonitorResult", "monitor"]


@dataclass(frozen=True)
class MonitorResult:
    """What ``monitor`` found: the per-rule verdicts (``None`` when it could not run) and every
    diagnostic about the rule file and the trace."""

    report: object | None  # twolevel.monitor.tracefile.MonitorReport (kept untyped: lazy import)
    diagnostics: tuple[Diagnostic, ...]
    sources: Mapping[str, str] = field(default_factory=dict)

    @property
    def violated(self) -> bool:
        """True when some rule's robustness falls below zero at some time of the trace."""
        return bool(self.report is not None and getattr(self.report, "violated"))


def monitor(
    rules_path: str,
    trace_path: str,
    *,
    dt: float | None = None,
    consts: Mapping[str, float] | None = None,
    series: bool = False,
) -> MonitorResult:
    """Evaluate every named formula of ``rules_path`` over the recorded trace ``trace_path``
    (offline, RTAMT's discrete-time semantics). ``consts`` bind or override the rule file's
    constants; ``dt`` [s] overrides the period read from the time column."""
    from twolevel.monitor.tracefile import monitor_trace, read_trace
    from twolevel.stl.lint import load_ruleset
    from twolevel.world.provided import PROVIDED_PARTICIPANT_SIGNALS as participants

    trace, diags = read_trace(trace_path, dt=dt)
    sources = {rules_path: read_text_quietly(rules_path)}
    if trace is None or any(d.is_error for d in diags):
        ruleset, rule_diags = load_ruleset(rules_path, consts, participant_signals=participants)  # its findings too
        return MonitorResult(None, tuple(rule_diags + diags), sources)
    # the trace's period decides the windows: an interval that is not a multiple of it (STL209)
    # would be silently rounded to whole samples
    ruleset, rule_diags = load_ruleset(rules_path, consts, dt=trace.dt, participant_signals=participants)
    diags = rule_diags + diags
    if ruleset is None:
        return MonitorResult(None, tuple(diags), sources)
    report, run_diags = monitor_trace(ruleset.rules, dict(ruleset.consts), trace, series=series,
                                      participants=run_participants(trace_path))
    diags += run_diags
    return MonitorResult(report, tuple(diags), sources)


def run_participants(trace_path: str) -> Sequence[str] | None:
    """The ids of every participant of the run that wrote ``trace_path``, as its ``run.json``
    beside it records them; ``None`` when unknown (no run directory, an unreadable or older
    ``run.json``, or traffic from another engine that brings participants mid-run)."""
    text = read_text_quietly(os.path.join(os.path.dirname(os.path.abspath(trace_path)), "run.json"), 1 << 26)
    try:
        ids = json.loads(text).get("participants") if text else None
    except (ValueError, AttributeError):  # not JSON, or JSON but not an object: no evidence either way
        return None
    return tuple(ids) if isinstance(ids, list) and all(isinstance(i, str) for i in ids) else None
