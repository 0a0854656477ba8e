"""``twolevel check``: rule files, maps and scenarios checked without solving anything.

Returns the findings as diagnostics (:class:`CheckResult`); the CLI only chooses the output
format and the exit code (:func:`exit_code`). Heavy modules are imported inside the functions
that need them, so ``twolevel check`` never loads numpy or a solver.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Sequence

from twolevel.diagnostics import Diagnostic, Severity, Span
from twolevel.files import read_text_quietly
from twolevel.interop import FORMATS, format_of
from twolevel.pipeline.codes import CLI001, CLI002, CLI003

RULE_SUFFIXES = (".stl",)
YAML_SUFFIXES = (".yaml", ".yml")

@dataclass(frozen=True)
class CheckResult:
    """What ``check`` found: the diagnostics, how many files it read, and their text (for
    rendering source lines under a finding)."""

    diagnostics: tuple[Diagnostic, ...]
    files_checked: int
    sources: Mapping[str, str] = field(default_factory=dict)

    @property
    def bad_input(self) -> bool:
        """True when some input could not be used at all (exit code 2; :attr:`Code.bad_input`)."""
        return any(d.bad_input for d in self.diagnostics)


def collect_paths(paths: Sequence[str]) -> tuple[list[str], list[Diagnostic]]:
    """Expand folders into the rule, map and scenario files below them, sorted; keep files as
    given. Hidden folders and virtual environments are skipped."""
    files: list[str] = []
    diags: list[Diagnostic] = []
    for raw in paths:
        p = Path(raw)
        if p.is_dir():
            found = []
            for root, dirs, names in os.walk(p):
                dirs[:] = sorted(d for d in dirs if not d.startswith(".") and d not in ("__pycache__", "node_modules"))
                for name in sorted(names):
                    if name.endswith(RULE_SUFFIXES + YAML_SUFFIXES):
                        found.append(os.path.join(root, name))
            if not found:
                diags.append(CLI003(f"no .stl, .yaml or .yml file below '{raw}'", Span.whole_file(raw)))
            files.extend(found)
        elif p.exists():
            if not raw.endswith(RULE_SUFFIXES + YAML_SUFFIXES) and format_of(raw) is None:
                diags.append(
                    CLI002(
                        f"'{raw}' is not a rule file (.stl), a map/scenario (.yaml, .yml) or a file to import "
                        f"({', '.join(f'{f.name} {f.suffix}' for f in FORMATS)})",
                        Span.whole_file(raw),
                        hint="pass rule files, maps, scenarios, other tools' maps and scenarios or folders holding them",
                    )
                )
            else:
                files.append(raw)
        else:
            diags.append(CLI001(f"no such file or folder: '{raw}'", Span.whole_file(raw)))
    # a file named twice (directly and through its folder) is checked once
    seen: set[str] = set()
    unique = [f for f in files if not (os.path.normpath(f) in seen or seen.add(os.path.normpath(f)))]
    return unique, diags


def check(paths: Sequence[str], *, dt: float | None = None, horizon: int | None = None) -> CheckResult:
    """Check rule files, maps and scenarios (and, for a scenario, its map and rule files with
    the signals its world provides), and other tools' maps and scenarios through their importer (folders:
    only ``.stl`` and ``.yaml`` files below them). Nothing is solved or simulated.

    ``dt`` [s] enables the multiple-of-dt check on intervals; with ``horizon`` [steps] too,
    formulas whose future horizon exceeds ``horizon * dt`` are reported.
    """
    files, diags = collect_paths(paths)
    sources: dict[str, str] = {}
    for file in files:
        if file.endswith(RULE_SUFFIXES):
            from twolevel.stl.lint import check_file
            from twolevel.world.provided import PROVIDED_PARTICIPANT_SIGNALS

            result = check_file(file, dt=dt, horizon=horizon, participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
            diags.extend(result.diagnostics)
            if result.source is not None:
                sources[file] = result.source
        elif format_of(file) is not None:
            from twolevel.pipeline.conversion import check_import

            diags.extend(check_import(file))
            sources.setdefault(file, read_text_quietly(file))
        else:
            from twolevel.world.lint import lint_world_file
            from twolevel.world.loader import check_world_file

            diags.extend(check_world_file(file))
            diags.extend(lint_world_file(file))
            sources.setdefault(file, read_text_quietly(file))
    return CheckResult(tuple(dedupe(diags)), len(files), sources)


def dedupe(diags: Iterable[Diagnostic]) -> list[Diagnostic]:
    """Each finding once (a rule file checked directly and through a scenario, or loaded by
    both controller levels, reports it once), in the order first seen."""
    seen: set[Diagnostic] = set()
    out = []
    for d in diags:
        if d not in seen:
            seen.add(d)
            out.append(d)
    return out


def exit_code(diags: Iterable[Diagnostic], *, strict: bool = False, exit_zero: bool = False) -> int:
    """0 clean, 1 errors (warnings too under ``strict``); ``exit_zero`` forces 0."""
    if exit_zero:
        return 0
    fail = {Severity.ERROR} | ({Severity.WARNING} if strict else set())
    return 1 if any(d.severity in fail for d in diags) else 0
