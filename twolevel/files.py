"""Open input files safely: only regular files, never more than a size limit.

A FIFO, a device (``/dev/zero``), a socket or a directory given where a file is expected would
make a plain ``open().read()`` block or read forever. :func:`open_regular` opens without
blocking (``O_NONBLOCK``, so opening a FIFO returns at once), checks the *opened* file with
``fstat`` (no race between the check and the read) and refuses anything that is not a regular
file; :func:`read_regular` also reads at most ``limit + 1`` bytes, so a file that grows past the
limit is still refused without reading it whole.

Each reader (rule files, YAML, trace CSV) turns a :class:`Refusal` into its own diagnostic code.
This module imports nothing heavy (it is on ``twolevel check``'s path).
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass
from typing import BinaryIO, Literal

__all__ = ["Refusal", "open_regular", "read_regular", "read_text_quietly"]

RefusalKind = Literal["missing", "directory", "special", "denied", "error", "too-large"]


@dataclass(frozen=True)
class Refusal:
    """Why a path cannot be read: ``kind``, a human ``detail`` (what the file is, or the OS
    error) and, for ``too-large``, the ``size`` seen [bytes] (at least ``limit + 1``)."""

    kind: RefusalKind
    detail: str
    size: int | None = None


def _what(mode: int) -> str:
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _os_refusal(exc: OSError) -> Refusal:
    if isinstance(exc, FileNotFoundError):
        return Refusal("missing", "no such file")
    if isinstance(exc, IsADirectoryError):
        return Refusal("directory", "a directory")
    if isinstance(exc, PermissionError):
        return Refusal("denied", "permission denied")
    return Refusal("error", exc.strerror or str(exc))


def open_regular(path: str | os.PathLike[str], *, limit: int | None = None) -> tuple[BinaryIO | None, Refusal | None]:
    """``path`` opened for binary reading if it is a regular file (and, with ``limit``, its size
    is at most ``limit`` bytes by ``fstat``); else ``(None, refusal)``. Never blocks, never raises
    for a bad path. The caller closes the file."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        return None, _os_refusal(exc)
    except (ValueError, TypeError) as exc:  # NUL in the path, wrong type
        return None, Refusal("error", str(exc))
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            os.close(fd)
            return None, Refusal("directory", "a directory")
        if not stat.S_ISREG(st.st_mode):
            os.close(fd)
            return None, Refusal("special", _what(st.st_mode))
        if limit is not None and st.st_size > limit:
            os.close(fd)
            return None, Refusal("too-large", "larger than the limit", st.st_size)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb"), None
    except OSError as exc:
        os.close(fd)
        return None, _os_refusal(exc)


def read_regular(path: str | os.PathLike[str], limit: int) -> tuple[bytes | None, Refusal | None]:
    """The bytes of the regular file ``path`` if it holds at most ``limit`` bytes (reading at
    most ``limit + 1``); else ``(None, refusal)``."""
    fh, refusal = open_regular(path, limit=limit)
    if fh is None:
        return None, refusal
    try:
        with fh:
            data = fh.read(limit + 1)
    except OSError as exc:
        return None, _os_refusal(exc)
    if len(data) > limit:  # grew since fstat
        return None, Refusal("too-large", "larger than the limit", len(data))
    return data, None


def read_text_quietly(path: str, limit: int = 1 << 20) -> str:
    """The text of a regular file up to ``limit`` bytes, for showing source lines; "" for
    anything else (a FIFO or a device would block or never end)."""
    data, _ = read_regular(path, limit)
    return "" if data is None else data.decode("utf-8", errors="replace")
