"""Atomic file writes: a reader sees the old file or the whole new one, never a part.

The data goes to a uniquely named temporary file beside the target (so two writers never share
it), is flushed and ``fsync``-ed, then ``os.replace``-d over the target; on any failure (a full
disk, a signal) the temporary file is removed and the target is left as it was.

The target must be a regular file or nothing: a symbolic link or a special file there is refused
(:class:`~twolevel.files.UnsafeOutput`, an ``OSError``; :func:`twolevel.files.check_output`).
The temporary file is created exclusively, without following links, with mode ``0o666`` less the
process's umask, so the file that replaces the target has the user's normal permissions (not the
``0o600`` of ``tempfile.mkstemp``).
"""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path
from typing import Any

from twolevel.files import check_output

__all__ = ["write_bytes_atomic", "write_text_atomic", "write_json_atomic"]

_TRIES = 100


def _temporary(path: Path) -> tuple[int, Path]:
    """A new file beside ``path`` opened for writing, and its path."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    for _ in range(_TRIES):
        tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name beside {path}")


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns the path."""
    path = Path(path)
    check_output(path)
    fd, tmp = _temporary(path)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if os.path.lexists(tmp):
            os.unlink(tmp)
    return path


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """UTF-8 text, written atomically."""
    return write_bytes_atomic(path, text.encode("utf-8"))


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if hasattr(obj, "item"):
        return obj.item()
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def write_json_atomic(path: str | os.PathLike[str], payload: Any) -> Path:
    """``payload`` as indented JSON (numpy arrays and scalars as lists and numbers), atomically."""
    return write_text_atomic(path, json.dumps(payload, indent=2, default=_json_default) + "\n")
