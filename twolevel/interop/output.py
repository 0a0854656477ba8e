"""How an importer writes what it converted: a map (and a scenario, when the format has one) as
readable YAML files that ``twolevel check`` accepts (the same schema as hand-written ones), written
atomically; :func:`to_yaml` is the one YAML writer of every format (OpenDRIVE, CommonRoad, SUMO),
:func:`write_map` the one way a map-only format's map is written and checked.

Points ``[x, y]``, other short lists of numbers and polylines of points are flow lists (one line); numbers are rounded to
millimetres (``DIGITS``); the files start with a comment naming the source and the findings.
Shared by every format's importer (:mod:`twolevel.interop`).
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

from twolevel.atomic import write_text_atomic
from twolevel.diagnostics import Diagnostic, Span

if TYPE_CHECKING:
    from twolevel.interop import ImportResult

__all__ = ["Imported", "DIGITS", "to_yaml", "write_imported", "write_map", "MAP_FILE", "SCENARIO_FILE"]

DIGITS = 3  # decimals kept of every number [m, s, m/s]: millimetres
MAP_FILE = "map.yaml"
SCENARIO_FILE = "scenario.yaml"


@dataclass(frozen=True)
class Imported:
    """A converted scenario: the map and the scenario as the YAML documents' data (the scenario
    names the map as ``map.yaml`` beside it), and the findings about what did not convert."""

    map: dict[str, Any]
    scenario: dict[str, Any]
    diagnostics: tuple[Diagnostic, ...]
    source: str


def _rounded(value: Any) -> Any:
    if isinstance(value, float):
        r = round(value, DIGITS)
        return 0.0 if r == 0 else r
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_rounded(v) for v in value]
    return value


_PLAIN = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-/]*(?: [A-Za-z0-9_.\-/()]+)*\Z")
_UNPRINTABLE = re.compile("[^\x20-\x7e\xa0-\u2027\u202a-\ud7ff\ue000-\ufefe\uff00-\ufffd\U00010000-\U0010ffff]")
"""Characters escaped in a quoted string: those YAML does not allow raw and its line breaks (JSON
escapes only those below space)."""
_WORDS = {"true", "false", "yes", "no", "on", "off", "null", "y", "n"}  # plain, they would not read as strings


def _scalar(value: Any) -> str:
    """One plain value as YAML: strings plain when they read back as the same string, else quoted
    (JSON's double-quoted strings are YAML's)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return ".nan"
        if not math.isfinite(value):
            return ".inf" if value > 0 else "-.inf"
        text = repr(value)
        return text.replace("e", ".0e", 1) if "e" in text and "." not in text else text  # YAML 1.1: 1.0e+300
    text = str(value)
    if _PLAIN.match(text) and text.lower() not in _WORDS:
        return text
    return _UNPRINTABLE.sub(lambda m: f"\\u{ord(m.group()):04x}", json.dumps(text, ensure_ascii=False))


def _is_scalar(value: Any) -> bool:
    return value is None or isinstance(value, (bool, int, float, str))


def _flow(value: Any) -> str | None:
    """``value`` on one line when it is a scalar, a short list of scalars (a point ``[x, y]``), a
    polyline (a list of such lists: a lane's boundary) or a small mapping of scalars; else None."""
    if _is_scalar(value):
        return _scalar(value)
    if isinstance(value, list):
        if len(value) <= 4 and all(_is_scalar(v) for v in value):
            return "[" + ", ".join(_scalar(v) for v in value) + "]"
        if all(isinstance(v, list) and len(v) <= 4 and all(_is_scalar(x) for x in v) for v in value):
            return "[" + ", ".join("[" + ", ".join(_scalar(x) for x in v) + "]" for v in value) + "]"
    if isinstance(value, dict) and len(value) <= 4 and all(_is_scalar(v) for v in value.values()):
        return "{" + ", ".join(f"{_scalar(k)}: {_scalar(v)}" for k, v in value.items()) + "}"
    return None


def _block(value: Any, indent: int) -> list[str]:
    """The lines of a mapping or list that does not fit on one line, ``indent`` spaces in."""
    pad = " " * indent
    out: list[str] = []
    if isinstance(value, dict):
        for k, v in value.items():
            flow = _flow(v)
            if flow is not None:
                out.append(f"{pad}{_scalar(k)}: {flow}")
            else:
                out.append(f"{pad}{_scalar(k)}:")
                out.extend(_block(v, indent if isinstance(v, list) else indent + 2))
        return out
    for item in value:
        flow = _flow(item)
        if flow is not None:
            out.append(f"{pad}- {flow}")
        else:
            lines = _block(item, indent + 2)
            out.append(f"{pad}- {lines[0][indent + 2:]}")
            out.extend(lines[1:])
    return out


def to_yaml(data: dict[str, Any], header: str = "") -> str:
    """``data`` (mappings, lists and plain values) as block-style YAML, numbers rounded to
    :data:`DIGITS` decimals, with short lists of numbers (``[x, y]``), polylines (lists of them: a
    lane's boundary, one line) and small mappings of plain values (``{t: 0.0, x: 1.0, y: 2.0}``)
    in flow style; ``header`` as comment lines on top. Written directly, not through PyYAML's
    emitter (a city's map in a fraction of its time)."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    body = _block(_rounded(data), 0) if data else ["{}"]
    return "\n".join(lines + body) + "\n"


def _header(imported: Imported, what: str) -> str:
    n = len(imported.diagnostics)
    head = f"{what} imported from {os.path.basename(imported.source)} by twolevel import"
    if not n:
        return head + "; everything converted."
    shown = [f"  {d.code} line {d.span.line}: {d.message}" for d in imported.diagnostics[:20]]
    more = [f"  … and {n - 20} more"] if n > 20 else []
    return "\n".join([head + f"; {n} finding(s) on what did not convert exactly:", *shown, *more])


def write_imported(imported: Imported, out_dir: str | os.PathLike[str]) -> Sequence[Path]:
    """Write ``map.yaml`` and ``scenario.yaml`` into ``out_dir`` (created); their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [write_text_atomic(out / MAP_FILE, to_yaml(imported.map, _header(imported, "Map"))),
            write_text_atomic(out / SCENARIO_FILE, to_yaml(imported.scenario, _header(imported, "Scenario")))]


def _nodes(value: Any) -> int:
    """YAML nodes of ``value`` as the map loader counts them (each mapping, sequence and scalar
    value; keys are not counted: twolevel/world/document.py)."""
    if isinstance(value, dict):
        return 1 + sum(_nodes(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return 1 + sum(_nodes(v) for v in value)
    return 1


def write_map(data: dict[str, Any], header: str, source: str | os.PathLike[str], target: str | os.PathLike[str],
              findings: Sequence[Diagnostic] = ()) -> ImportResult:
    """Write the converted map ``data`` to ``target`` (atomically, ``header`` as its first comment
    lines) and check it with the map loader: the result holds ``findings`` (the source's), then the
    loader's at the YAML's lines and IMP721 at ``source`` when they hold errors — or IMP720 instead
    of checking when the map is larger than the loader reads."""
    from twolevel.interop import ImportResult
    from twolevel.interop.codes import IMP720, IMP721
    from twolevel.world.document import MAX_BYTES, MAX_NODES
    from twolevel.world.loader import check_world_file

    text = to_yaml(data, header)
    out = Path(target)
    out.parent.mkdir(parents=True, exist_ok=True)
    written = write_text_atomic(out, text)
    diags = list(findings)
    summary = (f"{len(data['lanes'])} lanes, {len(data.get('speed_limits', []))} speed-limit signs, "
               f"{len(data.get('stop_signs', []))} stop signs, {len(data.get('traffic_lights', []))} lights")
    whole = Span.whole_file(os.fspath(source))
    size, nodes = len(text.encode("utf-8")), _nodes(data)
    if size > MAX_BYTES or nodes > MAX_NODES:
        diags.append(IMP720(f"the map has {size / 1e6:.1f} MB and about {nodes} YAML nodes; the map loader reads at "
                            f"most {MAX_BYTES / 1e6:.1f} MB and {MAX_NODES} nodes", whole,
                            hint="import a part of the map, or raise the loader's limits"))
        return ImportResult((written,), tuple(diags), data, summary)
    found = check_world_file(written)
    diags.extend(found)
    if any(d.is_error for d in found):
        diags.append(IMP721(f"the imported map {written.name} does not pass the map checks (above)", whole))
    return ImportResult((written,), tuple(diags), data, summary)
