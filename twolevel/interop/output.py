"""How an importer writes what it converted: a map (and a scenario, when the format has one) as
readable YAML files that ``twolevel check`` accepts (the same schema as hand-written ones), written
atomically; :func:`to_yaml` is the one YAML writer of every format (OpenDRIVE, CommonRoad).

Points ``[x, y]`` and other short lists of numbers stay on one line; numbers are rounded to
millimetres (``DIGITS``); the files start with a comment naming the source and the findings.
Shared by every format's importer (:mod:`twolevel.interop`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from twolevel.atomic import write_text_atomic
from twolevel.diagnostics import Diagnostic

__all__ = ["Imported", "DIGITS", "to_yaml", "write_imported", "MAP_FILE", "SCENARIO_FILE"]

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


def to_yaml(data: dict[str, Any], header: str = "") -> str:
    """``data`` as block-style YAML with short lists of numbers (``[x, y]``) and small mappings of
    plain values (``{t: 0.0, x: 1.0, y: 2.0}``) on one line."""
    import yaml

    class Dumper(yaml.SafeDumper):
        pass

    def lists(dumper: yaml.SafeDumper, value: list[Any]) -> Any:
        flat = len(value) <= 4 and all(isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in value)
        return dumper.represent_sequence("tag:yaml.org,2002:seq", value, flow_style=flat)

    def mappings(dumper: yaml.SafeDumper, value: dict[str, Any]) -> Any:
        flat = len(value) <= 4 and all(isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in value.values())
        return dumper.represent_mapping("tag:yaml.org,2002:map", value.items(), flow_style=flat)

    Dumper.add_representer(list, lists)
    Dumper.add_representer(dict, mappings)
    body = yaml.dump(_rounded(data), Dumper=Dumper, sort_keys=False, allow_unicode=True, width=120)
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    return "\n".join(lines) + ("\n" if lines else "") + body


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
