"""The trace's ``rob_<rule>`` columns: each rule's robustness on the executed trajectory.

The online monitor (:class:`~twolevel.monitor.online.OnlineMonitor`) reads one sample per step.
A rule whose window looks ahead L steps is final L steps later, so rows wait in a queue and are
written, in order, once every rule's value at their step is final. When the run ends (or is
interrupted, or crashes) the waiting rows are completed with the windows truncated at the end
(RTAMT's semantics) and written. A rule the online monitor cannot run (an unbounded future) is
evaluated by the offline monitor at the end instead.
"""

from __future__ import annotations

from collections import deque
from typing import Any, Mapping, Protocol, Sequence

import numpy as np

from twolevel.control.low_level.rules import RuleCheck
from twolevel.monitor.errors import MonitorError
from twolevel.monitor.online import OnlineMonitor
from twolevel.monitor.robustness import evaluate_rules
from twolevel.stl import ast

__all__ = ["RuleColumns"]


class _RowSink(Protocol):
    def write(self, row: Mapping[str, Any]) -> None: ...


class RuleColumns:
    """Fills the ``rob_<rule>`` columns of every row and writes the rows to a sink (a
    :class:`~twolevel.sim.trace.TraceWriter`) in order (see the module docstring); ``signals``:
    the names of every signal a sample carries; ``participants``: the ids the rules' quantifiers
    range over (each sample carries their ``present[ID]`` and signals)."""

    def __init__(self, rules: Sequence[RuleCheck], consts: Mapping[str, float], dt: float,
                 signals: Sequence[str], participants: Sequence[str] = ()) -> None:
        self.rules, self.consts, self.dt, self.signals = rules, consts, dt, signals
        self.names = [f"rob_{r.name}" for r in rules]
        try:
            self.online: OnlineMonitor | None = OnlineMonitor([ast.Rule(r.name, r.formula) for r in rules], dt,
                                                              consts=consts, participants=participants)
        except MonitorError:
            self.online = None  # unbounded future: robustness filled at the end from the offline monitor
        self.robustness: dict[str, list[float]] = {r.name: [] for r in rules}
        """Rule → its final robustness at every step so far."""
        self._rows: deque[dict[str, Any]] = deque()
        self._first = 0  # step index of _rows[0]
        self._samples: list[Mapping[str, float]] = []  # every sample, for the offline monitor

    def push(self, row: dict[str, Any], sample: Mapping[str, float], sink: _RowSink) -> None:
        """Queue the step's ``row`` with its signal ``sample``; write every row whose robustness
        is final to ``sink``."""
        self._rows.append(row)
        if self.online is None:
            self._samples.append(sample)
            return
        for rule, i, value in self.online.update(sample):
            j = i - self._first
            if 0 <= j < len(self._rows):
                self._rows[j][f"rob_{rule}"] = value
            self.robustness[rule].append(value)
        while self._rows and all(n in self._rows[0] for n in self.names):
            sink.write(self._rows.popleft())
            self._first += 1

    def finish(self, sink: _RowSink) -> None:
        """Complete the rows still waiting (windows truncated at the end) and write them to ``sink``."""
        if not self._rows:
            return
        if self.online is not None:
            final = self.online.finish()
        else:
            sig = {n: np.array([smp[n] for smp in self._samples]) for n in self.signals}
            final = evaluate_rules([ast.Rule(r.name, r.formula) for r in self.rules], sig, self.dt,
                                   consts=self.consts)
        for rule, series in final.items():
            have = len(self.robustness[rule])
            self.robustness[rule].extend(float(v) for v in series[have:])
        for j, row in enumerate(self._rows):
            i = self._first + j
            for rule in final:
                row.setdefault(f"rob_{rule}", float(final[rule][i]))
            sink.write(row)
        self._first += len(self._rows)
        self._rows.clear()
