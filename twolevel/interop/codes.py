"""Diagnostic codes of importers and exporters (``YML44x``: maps and scenarios from and to other
formats — CommonRoad, OpenDRIVE, SUMO). Shared by every format: a finding says which element of
the foreign file it is about, at that element's line.

Declared once here; each :class:`~twolevel.diagnostics.Code` registers itself. Imported by
``twolevel check``: no heavy imports.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Severity

E, W = Severity.ERROR, Severity.WARNING

YML440 = Code("YML440", "format-support-missing", E,
              "The optional package that reads or writes this format is not installed (pip install 'twolevel[<format>]').",
              bad_input=True)
YML441 = Code("YML441", "foreign-file-unreadable", E,
              "The file cannot be read as the format it claims to be (malformed XML, an unknown format version).",
              bad_input=True)
YML442 = Code("YML442", "not-converted", W,
              "An element of the foreign file that twolevel has no equivalent for: left out of the conversion.")
YML443 = Code("YML443", "approximated", W,
              "An element converted approximately (a polygon as its bounding box, a goal region as a point on a lane).")
YML444 = Code("YML444", "not-exported", W, "Part of a run or scenario the export leaves out (no equivalent in the format).")

__all__ = [name for name in dir() if name.startswith("YML")]
