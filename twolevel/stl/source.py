"""Read a rule file safely: every way a file can be unfit becomes a diagnostic.

Refused: a missing or unreadable path, a directory or other non-regular file (a FIFO would block
the reader), a file over :data:`MAX_BYTES` (checked with ``stat`` before reading), binary content
(NUL bytes), and text that is not UTF-8 (the position of the first bad byte is reported). A UTF-8
byte-order mark is dropped. Empty files are the parser's business (STL104).
"""

from __future__ import annotations

from twolevel.diagnostics import Diagnostic, Span, source_lines
from twolevel.files import read_regular
from twolevel.stl import codes

__all__ = ["read_source", "MAX_BYTES"]

MAX_BYTES = 1 << 20
"""Largest rule file accepted [bytes] (1 MiB)."""


def _byte_pos(data: bytes, offset: int) -> tuple[int, int]:
    """1-based line (lines end at LF, CRLF or CR, as the parser counts them) and column (in
    characters) of byte ``offset``."""
    before = source_lines(data[:offset].decode("utf-8", errors="replace"))
    return len(before), len(before[-1]) + 1


def read_source(path: str, *, max_bytes: int = MAX_BYTES) -> tuple[str | None, list[Diagnostic]]:
    """The text of the rule file at ``path``, or ``None`` and the reason."""
    whole = Span.whole_file(path)
    data, refusal = read_regular(path, max_bytes)
    if data is None:
        assert refusal is not None
        if refusal.kind == "missing":
            return None, [codes.STL100(f"no such file: {path}", whole)]
        if refusal.kind == "denied":
            return None, [codes.STL100(f"permission denied: {path}", whole)]
        if refusal.kind == "directory":
            return None, [codes.STL100(f"{path} is a directory, not a rule file", whole,
                                       hint="pass the .stl files inside it")]
        if refusal.kind == "special":
            return None, [codes.STL100(f"{path} is not a regular file: it is {refusal.detail}", whole)]
        if refusal.kind == "too-large":
            return None, [codes.STL107(
                f"file is {(refusal.size or 0) / 2**20:.1f} MiB; rule files are limited to {max_bytes / 2**20:g} MiB",
                whole, hint="is this really a rule file?")]
        return None, [codes.STL100(f"cannot read {path}: {refusal.detail}", whole)]
    nul = data.find(b"\x00")
    if nul >= 0:
        line, col = _byte_pos(data, nul)
        return None, [codes.STL105("file contains NUL bytes: it looks binary, not a rule file",
                                   Span(path, line, col, line, col + 1))]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line, col = _byte_pos(data, e.start)
        return None, [codes.STL106(f"invalid UTF-8: byte 0x{data[e.start]:02x} at line {line}, column {col}",
                                   Span(path, line, col, line, col + 1), hint="save the file as UTF-8")]
    if text.startswith("\ufeff"):
        text = text[1:]
    return text, []
