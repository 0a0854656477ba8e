"""Diagnostic codes of recorded traces and of monitoring them (``SIM60x``).

Declared once here; each :class:`~twolevel.diagnostics.Code` registers itself. No heavy imports.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Severity

E, W, I = Severity.ERROR, Severity.WARNING, Severity.INFO

SIM601 = Code("SIM601", "bad-time-column", E, "The trace's time column is missing, not increasing or not uniform.")
SIM602 = Code("SIM602", "missing-signal-column", E, "A rule reads a signal the trace has no column for.")
SIM603 = Code("SIM603", "bad-cell", E, "A trace cell is empty, not a number, NaN or infinite, or a row has the wrong width.")
SIM604 = Code("SIM604", "empty-trace", E, "The trace file has no samples.")
SIM605 = Code("SIM605", "unreadable-trace", E, "The trace file is missing, binary, not UTF-8 or cannot be read.")
SIM606 = Code("SIM606", "bad-header", E, "The trace's header has an empty or repeated column name.")
SIM607 = Code("SIM607", "cannot-monitor", E, "A rule cannot be evaluated on the trace.")
SIM608 = Code("SIM608", "assumed-period", I, "The sampling period could not be read from the trace and was assumed.")
SIM609 = Code("SIM609", "no-participants", E, "A rule quantifies over participants but the trace has no presence "
              "column (present[ID]) for any: the rule is not judged (its quantifiers would hold vacuously).")
