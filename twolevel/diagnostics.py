"""Diagnostics: positions, codes, severities and their renderers.

Every stage of twolevel (parsing, type checking, YAML validation, encoding, simulation) reports
problems as :class:`Diagnostic` values; only the CLI decides what they mean for the exit code.
One serialised form (:meth:`Diagnostic.to_dict`) feeds every output format.

Codes carry their stage: ``STL1xx`` syntax, ``STL2xx`` types and signals, ``STL3xx`` style and
portability, ``YML4xx`` maps and scenarios, ``MIL5xx`` encoding and solving, ``IMP7xx`` importing
other tools' maps, ``SIM6xx``
simulation. A code is declared once, where its stage lives, with :class:`Code`; declaring it
registers it in :data:`REGISTRY`.

This module is imported by ``twolevel check``: it must stay free of heavy imports.
"""

from __future__ import annotations

import enum
import json
import os
import re
from dataclasses import dataclass
from urllib.parse import quote
from typing import Iterable, Mapping

__all__ = [
    "Severity",
    "Span",
    "Diagnostic",
    "Code",
    "REGISTRY",
    "sort_key",
    "render",
    "render_full",
    "render_concise",
    "render_json",
    "render_github",
    "render_sarif",
    "FORMATS",
    "LINE_BREAK",
    "source_lines",
]


class Severity(str, enum.Enum):
    """How bad a finding is. Errors fail a check; warnings fail it only under ``--strict``."""

    ERROR = "error"
    WARNING = "warning"
    INFO = "info"


@dataclass(frozen=True, order=True)
class Span:
    """A region of a source file. Lines and columns are 1-based; the end is inclusive of the
    last character's column + 1 (half-open, like most editors)."""

    file: str
    line: int = 1
    column: int = 1
    end_line: int = 0
    end_column: int = 0

    def __post_init__(self) -> None:
        if self.end_line < self.line or (self.end_line == self.line and self.end_column < self.column):
            object.__setattr__(self, "end_line", self.line)
            object.__setattr__(self, "end_column", self.column)

    @classmethod
    def whole_file(cls, file: str) -> "Span":
        """The span used for findings about a file as a whole (unreadable, empty, …)."""
        return cls(file, 1, 1, 1, 1)

    def to(self, other: "Span") -> "Span":
        """The span from the start of ``self`` to the end of ``other``."""
        return Span(self.file, self.line, self.column, other.end_line, other.end_column)

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.column}"


@dataclass(frozen=True)
class Diagnostic:
    """One finding: a code, how severe, what is wrong, where, and how to fix it."""

    code: str
    severity: Severity
    message: str
    span: Span
    hint: str | None = None

    def to_dict(self) -> dict[str, object]:
        """The one serialised form every output format is made from."""
        return {
            "file": self.span.file,
            "line": self.span.line,
            "column": self.span.column,
            "end_line": self.span.end_line,
            "end_column": self.span.end_column,
            "code": self.code,
            "severity": self.severity.value,
            "message": self.message,
            "hint": self.hint,
        }

    @property
    def is_error(self) -> bool:
        return self.severity is Severity.ERROR

    @property
    def bad_input(self) -> bool:
        """An error whose code says the command could not use its input at all (exit 2), rather
        than a finding about the input (exit 1): see :attr:`Code.bad_input`."""
        code = REGISTRY.get(self.code)
        return self.is_error and code is not None and code.bad_input


REGISTRY: dict[str, "Code"] = {}


@dataclass(frozen=True)
class Code:
    """A diagnostic code. Calling it makes a :class:`Diagnostic` with its default severity.

    >>> STL999 = Code("STL999", "example", Severity.WARNING, "An example.")
    >>> STL999("something odd", Span("a.stl", 2, 3)).code
    'STL999'

    ``bad_input``: an error of this code means the command could not use its input at all (a
    file that cannot be read, a rule that cannot be encoded, an unknown solver): the CLI exits 2
    (usage error) on it instead of 1 (a finding). The one place that decides it.
    """

    id: str
    name: str
    severity: Severity
    summary: str
    bad_input: bool = False

    def __post_init__(self) -> None:
        known = REGISTRY.get(self.id)
        if known is not None and known != self:
            raise ValueError(f"diagnostic code {self.id} declared twice")
        REGISTRY[self.id] = self

    def __call__(
        self,
        message: str,
        span: Span,
        hint: str | None = None,
        severity: Severity | None = None,
    ) -> Diagnostic:
        return Diagnostic(self.id, severity or self.severity, message, span, hint)


def sort_key(d: Diagnostic) -> tuple[str, int, int, str]:
    """Order diagnostics by file, position, then code."""
    return (d.span.file, d.span.line, d.span.column, d.code)


# --------------------------------------------------------------------------------------------
# Renderers. Each takes the diagnostics (already sorted) and returns text; none prints.
# --------------------------------------------------------------------------------------------


def render_concise(diags: Iterable[Diagnostic]) -> str:
    """``file:line:col: CODE message`` per line, like compilers and ruff's concise format."""
    lines = []
    for d in diags:
        lines.append(f"{d.span.file}:{d.span.line}:{d.span.column}: {d.code} [{d.severity.value}] {d.message}")
    return "\n".join(lines) + ("\n" if lines else "")


LINE_BREAK = re.compile(r"\r\n|\r|\n")
"""Where a line ends in a rule file (and in every file but YAML): LF, CRLF or a bare CR, as
editors count lines. Form feeds, vertical tabs and the other characters :meth:`str.splitlines`
also breaks at are not line breaks. The rule parser reads ``LINE_BREAK.sub("\\n", text)``, so its
positions and the source lines :func:`render_full` shows agree."""

_YAML_LINE_BREAK = re.compile(r"\r\n|[\r\n\x85\u2028\u2029]")
"""Where PyYAML, which gives the positions of YAML findings, ends a line (YAML 1.1 also breaks
at NEL, LS and PS)."""

_SHOWN = 300
"""Most characters of a source line shown under a finding [characters]."""


def source_lines(text: str, file: str = "") -> list[str]:
    """The lines of ``text`` as the reader of ``file`` counts them (:data:`LINE_BREAK`; YAML's
    breaks for ``.yaml``/``.yml``). A text ending with a line break has an empty last line."""
    breaks = _YAML_LINE_BREAK if file.endswith((".yaml", ".yml")) else LINE_BREAK
    return breaks.split(text)


def _visible(c: str) -> str:
    """One character of a source line as shown on a terminal: control and invisible characters
    become one visible stand-in each (so columns stay aligned and no escape sequence is sent)."""
    if c.isprintable() or c == "\t":
        return c
    return chr(0x2400 + ord(c)) if ord(c) < 0x20 else "\u2421" if c == "\x7f" else "\ufffd"


def _excerpt(src: str, start: int) -> tuple[str, int]:
    """At most :data:`_SHOWN` characters of the source line ``src`` around 0-based column
    ``start``, and where ``start`` lands in the excerpt."""
    lo = 0
    if len(src) > _SHOWN:
        lo = max(0, min(start - _SHOWN // 3, len(src) - _SHOWN))
    shown = "".join(map(_visible, src[lo:lo + _SHOWN]))
    if lo + _SHOWN < len(src):
        shown += "…"
    if lo:
        return "…" + shown, start - lo + 1
    return shown, start


def render_full(diags: Iterable[Diagnostic], sources: Mapping[str, str] | None = None) -> str:
    """A multi-line block per finding with the source line and a caret under the span.

    Each source is split into lines once (linear in the sources and the findings)."""
    sources = sources or {}
    lines_of: dict[str, list[str] | None] = {}
    blocks = []
    for d in diags:
        sp = d.span
        out = [f"{sp.file}:{sp.line}:{sp.column}: {d.severity.value}[{d.code}]: {d.message}"]
        if sp.file not in lines_of:
            text = sources.get(sp.file)
            lines_of[sp.file] = None if text is None else source_lines(text, sp.file)
        lines = lines_of[sp.file]
        if lines is not None and 1 <= sp.line <= len(lines):
            raw = lines[sp.line - 1]
            start = min(max(sp.column - 1, 0), len(raw))
            src, at = _excerpt(raw, start)
            gutter = f"{sp.line:>5} | "
            out.append(gutter + src)
            width = sp.end_column - sp.column if sp.end_line == sp.line else 1
            width = max(1, min(width, len(src) - at))
            pad = "".join("\t" if c == "\t" else " " for c in src[:at])
            out.append(" " * (len(gutter) - 2) + "| " + pad + "^" * width)
        if d.hint:
            out.append(f"      = hint: {d.hint}")
        blocks.append("\n".join(out))
    return "\n\n".join(blocks) + ("\n" if blocks else "")


def render_json(diags: Iterable[Diagnostic], files_checked: int = 0, **extra: object) -> str:
    """``{"diagnostics": [...], "files_checked": N}``; lines and columns 1-based."""
    payload: dict[str, object] = {"diagnostics": [d.to_dict() for d in diags], "files_checked": files_checked}
    payload.update(extra)
    return json.dumps(payload, indent=2) + "\n"


def _gh_escape(text: str, prop: bool = False) -> str:
    text = text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")
    if prop:
        text = text.replace(":", "%3A").replace(",", "%2C")
    return text


def render_github(diags: Iterable[Diagnostic]) -> str:
    """GitHub Actions workflow commands: ``::error file=…,line=…,col=…::CODE message``.

    ``col``/``endColumn`` only for a span on one line: GitHub rejects columns on an annotation
    whose ``endLine`` differs from its ``line``."""
    lines = []
    for d in diags:
        sp = d.span
        level = {"error": "error", "warning": "warning"}.get(d.severity.value, "notice")
        msg = f"{d.code} {d.message}" + (f" (hint: {d.hint})" if d.hint else "")
        if sp.end_line == sp.line:
            where = f"line={sp.line},col={sp.column},endLine={sp.end_line},endColumn={sp.end_column}"
        else:
            where = f"line={sp.line},endLine={sp.end_line}"
        lines.append(
            f"::{level} file={_gh_escape(sp.file, True)},{where},title={_gh_escape(d.code, True)}::{_gh_escape(msg)}"
        )
    return "\n".join(lines) + ("\n" if lines else "")


def render_sarif(diags: Iterable[Diagnostic], tool_version: str = "0") -> str:
    """SARIF 2.1.0, one run, one rule per code used."""
    diags = list(diags)
    used = sorted({d.code for d in diags})
    rules = []
    for code in used:
        info = REGISTRY.get(code)
        rules.append(
            {
                "id": code,
                "name": info.name if info else code,
                "shortDescription": {"text": info.summary if info else code},
            }
        )
    level = {"error": "error", "warning": "warning", "info": "note"}
    results = []
    for d in diags:
        result: dict[str, object] = {
            "ruleId": d.code,
            "level": level[d.severity.value],
            "message": {"text": d.message + (f" (hint: {d.hint})" if d.hint else "")},
            "locations": [
                {
                    "physicalLocation": {
                        "artifactLocation": {"uri": quote(d.span.file.replace(os.sep, "/"))},
                        "region": {
                            "startLine": d.span.line,
                            "startColumn": d.span.column,
                            "endLine": d.span.end_line,
                            "endColumn": max(d.span.end_column, d.span.column),
                        },
                    }
                }
            ],
        }
        results.append(result)
    doc = {
        "$schema": "https://json.schemastore.org/sarif-2.1.0.json",
        "version": "2.1.0",
        "runs": [
            {
                "tool": {"driver": {"name": "twolevel", "version": tool_version, "rules": rules}},
                "results": results,
            }
        ],
    }
    return json.dumps(doc, indent=2) + "\n"


FORMATS = ("full", "concise", "json", "github", "sarif")


def render(
    fmt: str,
    diags: Iterable[Diagnostic],
    *,
    sources: Mapping[str, str] | None = None,
    files_checked: int = 0,
    tool_version: str = "0",
) -> str:
    """Render ``diags`` in one of :data:`FORMATS`."""
    diags = sorted(diags, key=sort_key)
    if fmt == "full":
        return render_full(diags, sources)
    if fmt == "concise":
        return render_concise(diags)
    if fmt == "json":
        return render_json(diags, files_checked)
    if fmt == "github":
        return render_github(diags)
    if fmt == "sarif":
        return render_sarif(diags, tool_version)
    raise ValueError(f"unknown output format {fmt!r}; expected one of {', '.join(FORMATS)}")
