"""Diagnostic codes of the command line's paths (``CLI0xx``), raised by :mod:`twolevel.pipeline.checking`.

Declared once here; each :class:`~twolevel.diagnostics.Code` registers itself. ``twolevel check``
imports it: no heavy imports.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Severity

__all__ = ["CLI001", "CLI002", "CLI003"]

CLI001 = Code("CLI001", "path-not-found", Severity.ERROR, "A path given on the command line does not exist.",
              bad_input=True)
CLI002 = Code("CLI002", "unsupported-file", Severity.ERROR,
              "A file given on the command line is of no kind twolevel checks.", bad_input=True)
CLI003 = Code("CLI003", "nothing-to-check", Severity.WARNING,
              "A folder given on the command line holds no rule, map or scenario file.")
