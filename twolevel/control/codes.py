"""Diagnostic codes of the planners and ``twolevel plan`` (``MIL51x``–``MIL53x``).

``MIL501``–``MIL504`` (encoding) live in :mod:`twolevel.compiler.codes`. Declared once here; each
:class:`~twolevel.diagnostics.Code` registers itself. No heavy imports.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Severity

E, W, I = Severity.ERROR, Severity.WARNING, Severity.INFO

__all__ = ["MIL510", "MIL511", "MIL512", "MIL513", "MIL514", "MIL515", "MIL516", "MIL517", "MIL530"]

MIL510 = Code("MIL510", "signal-not-predictable", W,
              "A rule reads a signal the MPC cannot predict over its horizon; the rule is left to the low level.")
MIL511 = Code("MIL511", "plan-infeasible", E,
              "No plan satisfies every active rule; the rules named conflict (found by dropping rules one at a time).")
MIL512 = Code("MIL512", "bad-solver", E, "The requested solver is unknown or not installed.", bad_input=True)
MIL513 = Code("MIL513", "bad-plan-time", E, "The requested time is outside the run or the trace cannot give the state at it.",
              bad_input=True)
MIL514 = Code("MIL514", "emit-failed", E, "The model could not be written to the requested file.", bad_input=True)
MIL515 = Code("MIL515", "fallback-plan", W, "The MPC found no plan in time; the previous plan shifted (or braking) is used.")
MIL516 = Code("MIL516", "bad-trace", E, "The trace file cannot give the ego state at the requested time.", bad_input=True)
MIL517 = Code("MIL517", "rule-recovering", W,
              "A rule is already violated now by signals known at solve time (e.g. a vehicle cut in closer "
              "than the gap); the MPC requires it from the first step the plan can still change, to recover.")
MIL530 = Code("MIL530", "nmpc-rule-not-smooth", W,
              "A rule cannot be written as a smooth constraint of the NMPC baseline; the NMPC ignores it.")
