"""Reading a YAML document safely, keeping the position of every key and value.

The document is composed with PyYAML's safe composer (libyaml when available): nodes keep
their marks, no object is ever constructed from a tag. We build plain Python values ourselves,
refusing what a safe loader must refuse — Python/unknown tags, ``!!binary``, alias bombs
(expanded-node and alias budgets, recursive aliases), duplicate keys, deep nesting — and files
that are too large (checked with ``stat`` before reading), binary, not UTF-8 or empty.

Imported by ``twolevel check``: standard library and PyYAML only.
"""

from __future__ import annotations

import copy
import functools
import os
import re
from dataclasses import dataclass, field
from typing import Any

import yaml
from yaml.constructor import SafeConstructor
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from twolevel.diagnostics import Diagnostic, Span
from twolevel.files import read_regular
from twolevel.world.codes import YML401, YML402, YML403, YML404, YML405, YML406, YML407, YML408, YML409, YML422

__all__ = ["Document", "Where", "read_document", "MAX_BYTES", "MAX_NODES", "MAX_ALIASES", "MAX_DEPTH"]

MAX_BYTES = 2 * 1024 * 1024  # [bytes] larger files are refused before reading
MAX_NODES = 200_000  # nodes after expanding aliases
MAX_ALIASES = 1_000  # alias uses per document
MAX_DEPTH = 64  # nesting of mappings and sequences

_Loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_TAG = "tag:yaml.org,2002:"
_SCALAR_TAGS = {_TAG + t for t in ("str", "int", "float", "bool", "null")}
_TIMESTAMP = _TAG + "timestamp"
_MERGE = _TAG + "merge"
# YAML 1.2's numbers that YAML 1.1 (PyYAML) reads as text: exponents without a dot or a sign
# (1e-3, 1e5, 1.0e5). Plain (unquoted) scalars of this form are numbers, as the user meant.
_FLOAT_12 = re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)[eE][-+]?[0-9]+")

Path_ = tuple[str | int, ...]


@dataclass(frozen=True)
class Where:
    """Position of one entry: the span of its key (None for list items and the root) and value."""

    key: Span | None
    value: Span

    @property
    def best(self) -> Span:
        """The key's span if there is a key, else the value's."""
        return self.key or self.value


@dataclass
class Document:
    """Plain Python data from one YAML file and the position of every entry by key path."""

    path: str
    data: Any
    where: dict[Path_, Where] = field(default_factory=dict)

    def locate(self, loc: Path_, *, value: bool = False) -> Span:
        """The span of the entry at ``loc`` (or its nearest existing parent)."""
        for n in range(len(loc), -1, -1):
            w = self.where.get(tuple(loc[:n]))
            if w is not None:
                if n < len(loc):  # the entry itself is absent: point at its parent's key
                    return w.best
                return w.value if value else w.best
        return Span.whole_file(self.path)


class _Refused(Exception):
    def __init__(self, diag: Diagnostic) -> None:
        super().__init__(diag.message)
        self.diag = diag


def _span(file: str, node: Node) -> Span:
    s, e = node.start_mark, node.end_mark
    return Span(file, s.line + 1, s.column + 1, e.line + 1, e.column + 1)


class _Builder:
    def __init__(self, file: str) -> None:
        self.file = file
        self.where: dict[Path_, Where] = {}
        self.nodes = 0
        self.aliases = 0
        self.seen: set[int] = set()
        self.active: set[int] = set()
        self.scalars = SafeConstructor()

    def build(self, node: Node, path: Path_, key: Span | None, depth: int) -> Any:
        self.nodes += 1
        if self.nodes > MAX_NODES:
            raise _Refused(YML408(f"the document expands to more than {MAX_NODES} nodes", _span(self.file, node),
                                  hint="a 'billion laughs' alias bomb? write the data out instead of nesting aliases"))
        if depth > MAX_DEPTH:
            raise _Refused(YML408(f"nesting deeper than {MAX_DEPTH} levels", _span(self.file, node)))
        if isinstance(node, (MappingNode, SequenceNode)):
            ident = id(node)
            if ident in self.active:
                raise _Refused(YML408("a recursive alias (a node that contains itself)", _span(self.file, node)))
            if ident in self.seen:
                self.aliases += 1
                if self.aliases > MAX_ALIASES:
                    raise _Refused(YML408(f"more than {MAX_ALIASES} alias uses", _span(self.file, node),
                                          hint="a 'billion laughs' alias bomb?"))
            self.seen.add(ident)
            self.active.add(ident)
        self.where[path] = Where(key, _span(self.file, node))
        try:
            if isinstance(node, ScalarNode):
                return self._scalar(node)
            if isinstance(node, SequenceNode):
                self._check_tag(node, _TAG + "seq")
                return [self.build(item, path + (i,), None, depth + 1) for i, item in enumerate(node.value)]
            if isinstance(node, MappingNode):
                self._check_tag(node, _TAG + "map")
                return self._mapping(node, path, depth)
            raise _Refused(YML406("unsupported YAML node", _span(self.file, node)))
        finally:
            self.active.discard(id(node))

    def _check_tag(self, node: Node, expected: str) -> None:
        if node.tag != expected:
            raise _Refused(YML407(f"tag '{node.tag}' is not allowed", _span(self.file, node),
                                  hint="only plain YAML (text, numbers, true/false, null, lists, mappings) is accepted"))

    def _scalar(self, node: ScalarNode) -> Any:
        if node.tag == _TIMESTAMP:
            return node.value
        if node.tag not in _SCALAR_TAGS:
            tag = node.tag.replace(_TAG, "!!")
            raise _Refused(YML407(f"tag '{tag}' is not allowed", _span(self.file, node),
                                  hint="python objects, binary data and custom tags are refused; write plain values"))
        if node.tag == _TAG + "str" and not node.style and _FLOAT_12.fullmatch(node.value):  # plain: "" (libyaml) or None
            return float(node.value)
        try:
            return self.scalars.construct_object(node, deep=True)
        except (yaml.YAMLError, ValueError) as exc:
            raise _Refused(YML406(f"cannot read this value: {exc}", _span(self.file, node))) from None

    def _mapping(self, node: MappingNode, path: Path_, depth: int) -> dict[Any, Any]:
        out: dict[Any, Any] = {}
        merged: dict[Any, Any] = {}
        for knode, vnode in node.value:
            if knode.tag == _MERGE:
                sources = vnode.value if isinstance(vnode, SequenceNode) else [vnode]
                for src in sources:
                    if not isinstance(src, MappingNode):
                        raise _Refused(YML406("'<<' merges only mappings", _span(self.file, src)))
                    value = self.build(src, path + ("<<",), _span(self.file, knode), depth + 1)
                    for k, v in value.items():
                        merged.setdefault(k, v)
                continue
            if not isinstance(knode, ScalarNode):
                raise _Refused(YML422("a key must be plain text, not a list or mapping", _span(self.file, knode)))
            key = self._scalar(knode)
            kspan = _span(self.file, knode)
            if key in out:
                first = self.where[path + (key,)].best
                raise _Refused(YML409(f"key '{key}' appears twice in this mapping", kspan,
                                      hint=f"first at line {first.line}; YAML would silently keep only the last"))
            out[key] = self.build(vnode, path + (key,), kspan, depth + 1)
        for k, v in merged.items():
            out.setdefault(k, v)
        return out


def _line_of_offset(raw: bytes, offset: int) -> tuple[int, int]:
    before = raw[:offset]
    line = before.count(b"\n") + 1
    column = offset - (before.rfind(b"\n") + 1) + 1
    return line, column


def read_document(path: str | os.PathLike[str]) -> tuple[Document | None, list[Diagnostic]]:
    """Read ``path`` as one YAML document of plain data with positions, or refuse it.

    Returns ``(document, [])`` or ``(None, [diagnostic])``; never raises for bad input.
    """
    file = str(path)
    whole = Span.whole_file(file)
    raw, refusal = read_regular(path, MAX_BYTES)
    if raw is None:
        assert refusal is not None
        if refusal.kind == "missing":
            return None, [YML401(f"no such file: {file}", whole)]
        if refusal.kind == "directory":
            return None, [YML401(f"{file} is a directory, not a YAML file", whole)]
        if refusal.kind == "special":
            return None, [YML401(f"{file} is not a regular file: it is {refusal.detail}", whole,
                                 hint="give the path of a YAML file")]
        if refusal.kind == "too-large":
            return None, [YML402(f"file is {(refusal.size or 0) / 1e6:.1f} MB; the limit is {MAX_BYTES / 1e6:.1f} MB", whole,
                                 hint="maps and scenarios are small; generate traffic with 'populations' instead of listing it")]
        return None, [YML401(f"cannot read {file}: {refusal.detail}", whole)]
    data, where, diags = _from_bytes(file, raw)
    if data is None:
        return None, list(diags)
    return Document(file, copy.deepcopy(data), dict(where)), []


@functools.lru_cache(maxsize=16)
def _from_bytes(file: str, raw: bytes) -> tuple[Any, dict[Path_, Where], tuple[Diagnostic, ...]]:
    """The data and positions of the document ``raw`` read from ``file`` (None and the refusal).

    A function of its arguments, so the last few are kept (loading a scenario reads it and its
    map again per stage and per parameter corner ``check`` tries); callers get a copy of the
    data, which they may change."""
    doc, diags = _compose(file, raw)
    return (None, {}, tuple(diags)) if doc is None else (doc.data, doc.where, ())


def _compose(file: str, raw: bytes) -> tuple[Document | None, list[Diagnostic]]:
    whole = Span.whole_file(file)
    nul = raw.find(b"\x00")
    if nul >= 0:
        line, col = _line_of_offset(raw, nul)
        return None, [YML403("binary file (NUL byte), not YAML text", Span(file, line, col),
                             hint="is this the right file?")]
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line, col = _line_of_offset(raw, exc.start)
        return None, [YML404(f"not UTF-8: byte 0x{raw[exc.start]:02x} cannot be decoded", Span(file, line, col),
                             hint="save the file as UTF-8")]
    try:
        node = yaml.compose(text, Loader=_Loader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        span = Span(file, mark.line + 1, mark.column + 1) if mark else whole
        problem = exc.problem or "invalid YAML"
        ctx = f" ({exc.context})" if exc.context else ""
        return None, [YML406(f"YAML syntax: {problem}{ctx}", span)]
    except yaml.YAMLError as exc:
        return None, [YML406(f"YAML syntax: {exc}", whole)]
    except RecursionError:
        return None, [YML408(f"nesting too deep to read", whole)]
    if node is None:
        return None, [YML405("the file holds no YAML document", whole, hint="an empty file or only comments")]
    builder = _Builder(file)
    try:
        data = builder.build(node, (), None, 0)
    except _Refused as refused:
        return None, [refused.diag]
    except RecursionError:
        return None, [YML408("nesting too deep to read", whole)]
    if not isinstance(data, dict):
        return None, [YML422("the document must be a mapping of keys to values (key: value)", _span(file, node))]
    return Document(file, data, builder.where), []
