"""Diagnostic codes of verdicts and campaigns (``SIM62x``: judging runs, suites, sweeps, searches).

Declared once here; each :class:`~twolevel.diagnostics.Code` registers itself. No heavy imports.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Severity

E, W = Severity.ERROR, Severity.WARNING

__all__ = ["SIM620", "SIM621", "SIM622", "SIM623"]

SIM620 = Code("SIM620", "cannot-judge-run", E, "A run cannot be judged against its criteria (unreadable run or scenario).")
SIM621 = Code("SIM621", "no-scenarios", E, "No scenario was found below the paths given.")
SIM622 = Code("SIM622", "bad-campaign-setting", E, "A campaign setting is out of range or names nothing.")
SIM623 = Code("SIM623", "case-crashed", E, "A case could not be run to its verdict (a worker failed).")
