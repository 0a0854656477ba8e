"""Diagnostic codes of importing other tools' maps and scenarios and exporting runs to them
(``IMP7xx``), raised by every format's module in :mod:`twolevel.interop` (OpenDRIVE, SUMO, CommonRoad):
a finding says which element of the other tool's file it is about, at that element's line.

Declared once here; each :class:`~twolevel.diagnostics.Code` registers itself. No heavy imports
(``twolevel check FILE.xodr``, ``FILE.net.xml`` and ``FILE.xml`` go through the importer).

``IMP70x``: the input cannot be used at all (exit 2). ``IMP71x``: parts of it were not converted,
were repaired, assumed or approximated (the files are still written). ``IMP72x``: the converted
map itself. ``IMP73x``: what an export leaves out.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Severity

E, W, I = Severity.ERROR, Severity.WARNING, Severity.INFO

IMP701 = Code("IMP701", "import-unreadable", E, "The file does not exist, cannot be read or is too large.", bad_input=True)
IMP702 = Code("IMP702", "xml-syntax", E, "The file is not well-formed XML (or holds a DTD, which is refused).",
              bad_input=True)
IMP703 = Code("IMP703", "wrong-format", E,
              "The file is not the format its name says, or its reader cannot read it (an unknown format version).",
              bad_input=True)
IMP704 = Code("IMP704", "reader-missing", E,
              "The optional package that reads or writes this format is not installed (pip install 'twolevel[<format>]').",
              bad_input=True)
IMP705 = Code("IMP705", "reader-refused", E, "The format's reader could not build the map.", bad_input=True)
IMP706 = Code("IMP706", "nothing-converted", E, "No lane of the map could be converted.", bad_input=True)
IMP710 = Code("IMP710", "not-converted", W,
              "An element of the file that twolevel has no equivalent for: left out of the conversion.")
IMP711 = Code("IMP711", "repaired", I, "An element the reader mishandles, rewritten before reading.")
IMP712 = Code("IMP712", "bad-element", W, "An element whose values are invalid; it is left out.")
IMP713 = Code("IMP713", "assumed", I, "Something the format does not say, filled in with a default.")
IMP714 = Code("IMP714", "approximated", W,
              "An element converted approximately (a polygon as its bounding box, a goal region as a point on a lane).")
IMP720 = Code("IMP720", "map-too-large", W, "The converted map exceeds what the map loader reads.")
IMP721 = Code("IMP721", "map-invalid", E, "The converted map does not pass the map checks.")
IMP730 = Code("IMP730", "not-exported", W, "Part of a run or scenario the export leaves out (no equivalent in the format).")

__all__ = [name for name in dir() if name.startswith("IMP")]
