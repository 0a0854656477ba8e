"""An imported file read once, with where each element stands in it (shared by every format).

:func:`read_xml` reads a file safely (a regular file, at most :data:`MAX_BYTES`), parses it with
expat and records each element's line and column, so that whatever an importer leaves out or
repairs is reported at the element it came from (file:line:col, a code, a hint). A document type
declaration is refused (no entity can expand: no billion laughs, no external entities). No heavy
imports: ``twolevel check FILE`` reads files through here.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from xml.parsers import expat

from twolevel.diagnostics import Diagnostic, Span
from twolevel.files import read_regular
from twolevel.interop.codes import IMP701, IMP702

__all__ = ["MAX_BYTES", "XmlSource", "read_xml"]

MAX_BYTES = 256 * 1024 * 1024
"""Largest file an importer reads [bytes] (a whole city's OpenDRIVE is a few tens of MB)."""


class _Refused(Exception):
    """A DTD in the document: parsing stops there."""


@dataclass
class XmlSource:
    """A parsed XML file: its ``root`` element, its ``text`` and the (line, column) of each element
    (1-based), looked up by :meth:`span`; ``findings`` collects what the importer reports."""

    file: str
    text: str
    root: ET.Element
    where: dict[int, tuple[int, int]]
    findings: list[Diagnostic] = field(default_factory=list)

    def span(self, element: ET.Element | None) -> Span:
        """Where ``element`` starts (the whole file when it is unknown)."""
        if element is None or id(element) not in self.where:
            return Span.whole_file(self.file)
        line, col = self.where[id(element)]
        return Span(self.file, line, col, line, col + 1 + len(element.tag))

    def report(self, code, message: str, element: ET.Element | None, hint: str | None = None) -> None:  # noqa: ANN001 - a Code
        """Add the finding ``code`` at ``element``."""
        self.findings.append(code(message, self.span(element), hint=hint))


def read_xml(path: str | os.PathLike[str]) -> tuple[XmlSource | None, list[Diagnostic]]:
    """The file at ``path`` parsed, or None and the diagnostics that say why not."""
    file = os.fspath(path)
    data, refusal = read_regular(file, MAX_BYTES)
    if refusal is not None or data is None:
        detail = refusal.detail if refusal is not None else "unreadable"
        if refusal is not None and refusal.kind == "too-large":
            detail = f"larger than {MAX_BYTES // (1024 * 1024)} MB"
        return None, [IMP701(f"cannot read '{file}': {detail}", Span.whole_file(file))]
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        return None, [IMP701(f"not UTF-8 text (byte {exc.start})", Span(file, line, 1), hint="save the file as UTF-8")]
    parser = expat.ParserCreate()
    builder = ET.TreeBuilder()
    where: dict[int, tuple[int, int]] = {}

    def start(tag: str, attrs: dict[str, str]) -> None:
        where[id(builder.start(tag, attrs))] = (parser.CurrentLineNumber, parser.CurrentColumnNumber + 1)

    def doctype(*_: object) -> None:
        raise _Refused

    parser.StartElementHandler = start
    parser.EndElementHandler = builder.end
    parser.CharacterDataHandler = builder.data
    parser.buffer_text = True
    parser.StartDoctypeDeclHandler = doctype
    parser.EntityDeclHandler = doctype
    try:
        parser.Parse(text, True)
        root = builder.close()
    except _Refused:
        return None, [IMP702("a document type declaration (DTD) is not accepted",
                             Span(file, parser.CurrentLineNumber, parser.CurrentColumnNumber + 1),
                             hint="remove the <!DOCTYPE ...> (entities could expand without bound)")]
    except expat.ExpatError as exc:
        return None, [IMP702(f"not well-formed XML: {expat.errors.messages.get(exc.code, str(exc))}",
                             Span(file, exc.lineno, exc.offset + 1))]
    except (AssertionError, RecursionError) as exc:  # TreeBuilder on an empty document; absurd nesting
        return None, [IMP702(f"not an XML document ({type(exc).__name__})", Span.whole_file(file))]
    return XmlSource(file, text, root, where), []
