"""Other tools' maps made twolevel maps: one module per format, one table choosing among them.

``twolevel import FILE --out DIR`` (and ``twolevel check FILE``) picks the importer by the file's
suffix from :data:`FORMATS`; each importer turns the parsed file (:mod:`twolevel.interop.source`:
elements with their lines) into the content of a map file of free-form lanes and reports what it
left out, repaired or assumed at the element it came from (:mod:`twolevel.interop.codes`).
:func:`import_map` writes the map (:func:`map_yaml`, atomically) and checks it with the map
loader, so that what ``import`` writes, ``check``, ``plan`` and ``simulate`` read.

No heavy imports here: a format's reader (an optional extra) is imported when a file of it is read.
"""

from __future__ import annotations

import importlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twolevel.diagnostics import Diagnostic, Span
from twolevel.interop.codes import IMP720, IMP721

__all__ = ["FORMATS", "Imported", "format_of", "convert_file", "import_map", "map_yaml"]

FORMATS: dict[str, tuple[str, str]] = {
    ".xodr": ("twolevel.interop.opendrive", "OpenDRIVE"),
}
"""File suffix → (importer module, format name). An importer module has ``Options`` and
``convert(source, options) -> dict | None``."""


@dataclass(frozen=True)
class Imported:
    """The outcome of an import: the map's content (None when nothing could be used), the file
    written (None when nothing was), and every finding."""

    data: dict[str, Any] | None
    written: Path | None
    diagnostics: tuple[Diagnostic, ...]

    @property
    def bad_input(self) -> bool:
        """True when the input could not be used at all (exit code 2)."""
        return any(d.bad_input for d in self.diagnostics)


def format_of(path: str | os.PathLike[str]) -> tuple[str, str] | None:
    """(importer module, format name) of a file by its suffix, None when no importer reads it."""
    return FORMATS.get(Path(path).suffix.lower())


def convert_file(path: str | os.PathLike[str], **options: Any) -> tuple[dict[str, Any] | None, list[Diagnostic]]:
    """The map a file of a known format describes, and the findings (``options``: the importer's)."""
    from twolevel.interop.source import read_xml

    fmt = format_of(path)
    if fmt is None:
        raise ValueError(f"no importer for '{path}'")  # callers check format_of first
    module = importlib.import_module(fmt[0])
    src, diags = read_xml(path)
    if src is None:
        return None, diags
    data = module.convert(src, module.Options(**options))
    return data, src.findings


def _point_list(points: list[list[float]]) -> str:
    return "[" + ", ".join(f"[{x:.3f}, {y:.3f}]" for x, y in points) + "]"


def map_yaml(data: dict[str, Any], header: str = "") -> str:
    """A map's content as YAML text: one block per lane, points as flow lists in mm (JSON values,
    which are YAML), ``header`` as comment lines on top."""
    out = [f"# {line}".rstrip() for line in header.splitlines()]
    for key, value in data.items():
        if isinstance(value, list):
            out.append(f"{key}:")
            for item in value:
                first = True
                for k, v in item.items():
                    text = _point_list(v) if k in ("left_bound", "right_bound", "centre") else json.dumps(v)
                    out.append(f"  {'- ' if first else '  '}{k}: {text}")
                    first = False
        else:
            out.append(f"{key}: {json.dumps(value)}")
    return "\n".join(out) + "\n"


def import_map(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], **options: Any) -> Imported:
    """Convert ``path`` and write ``<out_dir>/<stem>.yaml``; the written map is checked by the map
    loader (its findings, at the YAML's lines, come with the import's)."""
    from twolevel.atomic import write_text_atomic
    from twolevel.world.document import MAX_BYTES, MAX_NODES
    from twolevel.world.loader import check_world_file

    data, diags = convert_file(path, **options)
    if data is None:
        return Imported(None, None, tuple(diags))
    name = format_of(path)[1]  # type: ignore[index]
    header = (f"Imported from {Path(path).name} ({name}) by `twolevel import`: free-form lanes r<road>_<section>_<lane>.\n"
              "Regenerate rather than edit by hand.")
    text = map_yaml(data, header)
    os.makedirs(out_dir, exist_ok=True)
    target = write_text_atomic(Path(out_dir) / f"{Path(path).stem}.yaml", text)
    size = len(text.encode("utf-8"))
    nodes = sum(2 * len(v) + 1 for ln in data["lanes"] for k, v in ln.items() if k.endswith("_bound"))
    if size > MAX_BYTES or nodes > MAX_NODES:
        diags.append(IMP720(f"the map has {size / 1e6:.1f} MB and about {nodes} YAML nodes; the map loader reads at "
                            f"most {MAX_BYTES / 1e6:.1f} MB and {MAX_NODES} nodes", Span.whole_file(os.fspath(path)),
                            hint="import a part of the map (fewer roads), or raise the loader's limits"))
        return Imported(data, target, tuple(diags))
    found = check_world_file(target)
    diags.extend(d for d in found)
    if any(d.is_error for d in found):
        diags.append(IMP721(f"the imported map {target.name} does not pass the map checks (above)",
                            Span.whole_file(os.fspath(path))))
    return Imported(data, target, tuple(diags))
