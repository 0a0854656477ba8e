"""``twolevel import`` and ``twolevel export``, and ``twolevel check`` of another tool's file:
values and diagnostics, the CLI chooses output and exit codes.

Which importer reads a file is :func:`twolevel.interop.format_of`'s answer (its suffix, and for
``.xml`` its content); the importer is imported only then, so checking ``.stl`` and ``.yaml``
files never loads numpy.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from twolevel.diagnostics import Diagnostic, Span
from twolevel.interop import import_file

__all__ = ["check_import", "ExportResult", "export_run"]


def check_import(path: str) -> list[Diagnostic]:
    """``twolevel check`` of another tool's file: what its import reports, and what the checks find
    in the converted map and scenario (reported at the source file, naming the converted file's
    line: the converted files are temporary)."""
    with tempfile.TemporaryDirectory(prefix="twolevel-check-") as tmp:
        result = import_file(path, tmp)
        out = []
        for d in result.diagnostics:
            if d.span.file.startswith(tmp):
                where = f"{os.path.basename(d.span.file)}:{d.span.line}:{d.span.column}"
                d = Diagnostic(d.code, d.severity, f"in the converted {where}: {d.message}", Span.whole_file(path), d.hint)
            out.append(d)
    return out


@dataclass(frozen=True)
class ExportResult:
    """What ``twolevel export`` wrote and the findings on what it left out."""

    written: tuple[Path, ...]
    diagnostics: tuple[Diagnostic, ...]


def export_run(run_dir: str, out_dir: str, fmt: str = "commonroad") -> ExportResult:
    """Export the run in ``run_dir`` into ``out_dir`` in format ``fmt`` (``commonroad``: a
    solution file and the scenario with the ego as an obstacle)."""
    from twolevel.interop.commonroad_export import export_commonroad

    written, diags = export_commonroad(run_dir, out_dir)
    return ExportResult(tuple(written), tuple(diags))
