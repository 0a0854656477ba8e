"""Other tools' maps and scenarios made twolevel ones, and runs exported: one module per format,
one table choosing among them.

``twolevel import FILE --out DIR`` and ``twolevel check FILE`` pick the importer from
:data:`FORMATS` (:func:`format_of`: the file's suffix, and for a suffix several formats share,
such as ``.xml``, a marker in the file's first bytes). Each importer module has
``import_file(path, out_dir, **options) -> ImportResult``: it writes the map (and the scenario,
when the format has one) with :mod:`twolevel.interop.output`, checks what it wrote with the map
loader, and reports what it left out, repaired, assumed or approximated at the element it came
from (:mod:`twolevel.interop.codes`, ``IMP7xx``). Exporters (``commonroad_export``) write runs
in another format.

No heavy imports here: a format's package (an optional extra) is imported when a file of it is read.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twolevel.diagnostics import Diagnostic

__all__ = ["Format", "FORMATS", "ImportResult", "format_of", "import_file"]

_SNIFF = 4096
"""Bytes read from a file's start to find a format's marker."""


@dataclass(frozen=True)
class Format:
    """One row of :data:`FORMATS`: files whose name ends in ``suffix`` (lower case) — and, when
    ``marker`` is set, whose first bytes contain it — are read by ``module`` (format ``name``)."""

    suffix: str
    module: str
    name: str
    marker: bytes | None = None


FORMATS: tuple[Format, ...] = (
    Format(".xodr", "twolevel.interop.opendrive", "OpenDRIVE"),
    Format(".net.xml", "twolevel.interop.sumo", "SUMO"),
    Format(".xml", "twolevel.interop.commonroad", "CommonRoad", b"<commonRoad"),
)
"""Every importer, tried in order: a longer suffix (``.net.xml``) goes before a shorter one it ends
in (``.xml``), so that the first row matching a file is the most specific."""

@dataclass(frozen=True)
class ImportResult:
    """What an import did: the files written (the map first; none when the source could not be
    used), every finding (the source's, then the checks' of the written files), the converted
    map's content (None when nothing was converted) and a one-line summary of it."""

    written: tuple[Path, ...]
    diagnostics: tuple[Diagnostic, ...]
    map: dict[str, Any] | None = None
    summary: str = ""

    @property
    def bad_input(self) -> bool:
        """True when the input could not be used at all (exit code 2)."""
        return any(d.bad_input for d in self.diagnostics) or not self.written


def format_of(path: str | os.PathLike[str]) -> Format | None:
    """The row of :data:`FORMATS` that reads ``path``, None when no importer does (or a marker
    is required and the file cannot be read)."""
    name = os.fspath(path).lower()
    head: bytes | None = None
    for fmt in FORMATS:
        if not name.endswith(fmt.suffix):
            continue
        if fmt.marker is None:
            return fmt
        if head is None:
            try:
                with open(path, "rb") as fh:
                    head = fh.read(_SNIFF)
            except OSError:
                head = b""
        if fmt.marker in head:
            return fmt
    return None


def import_file(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], **options: Any) -> ImportResult:
    """Import ``path`` into ``out_dir`` with the importer :func:`format_of` chooses (``options``:
    that importer's, e.g. OpenDRIVE's ``include``, CommonRoad's ``rules``)."""
    fmt = format_of(path)
    if fmt is None:
        raise ValueError(f"no importer reads '{path}'")  # callers check format_of first
    return importlib.import_module(fmt.module).import_file(path, out_dir, **options)
