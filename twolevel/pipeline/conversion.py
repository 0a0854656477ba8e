"""``twolevel import`` and ``twolevel export``, and ``twolevel check`` of a foreign scenario file:
values and diagnostics, the CLI chooses output and exit codes.

A foreign file is recognised by its content (:func:`foreign_format`: a CommonRoad XML file's
root element is ``<commonRoad>``); its importer (:mod:`twolevel.interop`) is imported only then,
so checking ``.stl`` and ``.yaml`` files never loads numpy.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from twolevel.diagnostics import Diagnostic, Span

__all__ = ["FOREIGN_SUFFIXES", "foreign_format", "ImportResult", "import_scenario", "check_foreign", "ExportResult",
           "export_run"]

FOREIGN_SUFFIXES = (".xml",)
_SNIFF = 4096  # bytes read to recognise a format


def foreign_format(path: str | os.PathLike[str]) -> str | None:
    """The format of a foreign scenario file (``"commonroad"``), None if it is none twolevel reads."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(_SNIFF)
    except OSError:
        return None
    return "commonroad" if b"<commonRoad" in head else None


@dataclass(frozen=True)
class ImportResult:
    """What ``twolevel import`` did: the files written (none when the source could not be read)
    and the findings: what did not convert (at the source's lines), then what ``check`` finds in
    the written files."""

    written: tuple[Path, ...]
    diagnostics: tuple[Diagnostic, ...]


def _checked(scenario: Path) -> list[Diagnostic]:
    from twolevel.world.lint import lint_world_file
    from twolevel.world.loader import check_world_file

    return check_world_file(scenario) + lint_world_file(scenario)


def import_scenario(source: str, out_dir: str, rules: Sequence[str] = ()) -> ImportResult:
    """Convert ``source`` (a CommonRoad XML scenario) into ``out_dir/map.yaml`` and
    ``out_dir/scenario.yaml``, listing ``rules`` (paths of rule files), and check what was written."""
    from twolevel.interop.commonroad import import_commonroad
    from twolevel.interop.output import SCENARIO_FILE, write_imported

    imported, diags = import_commonroad(source, rules=rules, out_dir=out_dir)
    if imported is None:
        return ImportResult((), tuple(diags))
    written = tuple(write_imported(imported, out_dir))
    return ImportResult(written, tuple(diags + _checked(Path(out_dir) / SCENARIO_FILE)))


def check_foreign(path: str) -> list[Diagnostic]:
    """``twolevel check`` of a foreign file: the importer's findings, then what checking the
    converted map and scenario finds (reported at the foreign file, naming the converted file's
    line)."""
    from twolevel.interop.commonroad import import_commonroad
    from twolevel.interop.output import SCENARIO_FILE, write_imported

    imported, diags = import_commonroad(path)
    if imported is None:
        return diags
    with tempfile.TemporaryDirectory(prefix="twolevel-check-") as tmp:
        write_imported(imported, tmp)
        found = _checked(Path(tmp) / SCENARIO_FILE)
    span = Span.whole_file(path)
    for d in found:
        where = f"{os.path.basename(d.span.file)}:{d.span.line}:{d.span.column}"
        diags.append(Diagnostic(d.code, d.severity, f"in the converted {where}: {d.message}", span, d.hint))
    return diags


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
