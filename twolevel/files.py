"""Files opened safely: inputs only when regular and within a size limit; outputs never through
a symbolic link or into a special file; run directories locked against a second writer.

A FIFO, a device (``/dev/zero``), a socket or a directory given where a file is expected would
make a plain ``open().read()`` block or read forever. :func:`open_regular` opens without
blocking (``O_NONBLOCK``, so opening a FIFO returns at once), checks the *opened* file with
``fstat`` (no race between the check and the read) and refuses anything that is not a regular
file; :func:`read_regular` also reads at most ``limit + 1`` bytes, so a file that grows past the
limit is still refused without reading it whole.

Each reader (rule files, YAML, trace CSV) turns a :class:`Refusal` into its own diagnostic code.

Outputs (:func:`create_output`, and :mod:`twolevel.atomic` through :func:`check_output`): a
symbolic link at an output's path is refused, never followed (it could point anywhere: writing
through it would overwrite another file), and so is anything that is not a regular file (a FIFO
would block the writer, a device swallow the data); a regular file there is replaced by a new one.
Files are created with mode ``0o666`` less the process's umask, the user's normal permissions.
A refusal is an :class:`UnsafeOutput`, an ``OSError`` whose message names the file and what it is.

:class:`DirectoryLock` holds an exclusive ``flock`` on a directory (a run directory) for as long
as a run writes it; the kernel releases it when the process dies, so a killed run never leaves a
stale lock. A directory already locked is a :class:`DirectoryBusy`.

This module imports nothing heavy (it is on ``twolevel check``'s path).
"""

from __future__ import annotations

import errno
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Callable, Literal

__all__ = ["Refusal", "open_regular", "read_regular", "read_text_quietly", "UnsafeOutput", "check_output",
           "create_output", "DirectoryBusy", "DirectoryLock"]

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


# --------------------------------------------------------------------------------- outputs


class UnsafeOutput(OSError):
    """An output path holds a symbolic link or something other than a regular file (the message
    says which and where)."""

    def __str__(self) -> str:
        return self.strerror or super().__str__()


def check_output(path: str | os.PathLike[str]) -> bool:
    """Whether a regular file exists at ``path`` (False: nothing there). Raises
    :class:`UnsafeOutput` for a symbolic link or anything but a regular file, without following
    or opening it."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return False
    if stat.S_ISLNK(st.st_mode):
        raise UnsafeOutput(errno.ELOOP, f"{os.fspath(path)} is a symbolic link: refusing to write through it "
                                        "(remove it, or write elsewhere)")
    if not stat.S_ISREG(st.st_mode):
        what = "a directory" if stat.S_ISDIR(st.st_mode) else _what(st.st_mode)
        raise UnsafeOutput(errno.EEXIST, f"{os.fspath(path)} is {what}, not a regular file: refusing to write it")
    return True


def create_output(path: str | os.PathLike[str]) -> int:
    """A new, empty regular file at ``path`` opened for writing (a file descriptor, close-on-exec;
    the caller closes it). A regular file already there is replaced; a symbolic link or a special
    file is refused (:class:`UnsafeOutput`). Mode ``0o666`` less the umask."""
    if check_output(path):
        os.unlink(path)
    try:  # O_EXCL: never follows a link, never opens what appeared since the check
        return os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
                       | getattr(os, "O_CLOEXEC", 0), 0o666)
    except FileExistsError:
        raise UnsafeOutput(errno.EEXIST, f"{os.fspath(path)} appeared while it was being created: "
                                         "another process writes there") from None


# --------------------------------------------------------------------------------- locks


class DirectoryBusy(OSError):
    """Another process (``holder``: its id when known) holds the directory's lock."""

    def __init__(self, directory: str, holder: int | None) -> None:
        who = f"process {holder}" if holder else "another process"
        super().__init__(errno.EWOULDBLOCK, f"{directory} is being written by {who}")
        self.directory = directory
        self.holder = holder

    def __str__(self) -> str:
        return self.strerror or super().__str__()


class DirectoryLock:
    """An exclusive lock on ``directory`` (created if missing) for this process, taken at once
    or refused (:class:`DirectoryBusy`, whose ``holder`` is what ``holder()`` says: the holder
    records its process id where the caller knows to look); :meth:`release` it (or use
    ``with``). The lock is a ``flock`` on the directory itself, so nothing is added to it and the
    kernel releases it when the process dies (a killed run never leaves a stale lock). A file
    system without ``flock`` leaves the directory unlocked (``locked`` is False) rather than
    unusable."""

    def __init__(self, directory: str | os.PathLike[str], holder: Callable[[], int | None] | None = None) -> None:
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self._fd: int | None = os.open(self.directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0)
                                       | getattr(os, "O_CLOEXEC", 0))
        self.locked = False
        try:
            self.locked = _flock(self._fd)
        except BlockingIOError:
            self.release()
            raise DirectoryBusy(str(self.directory), holder() if holder is not None else None) from None
        except BaseException:
            self.release()
            raise

    def release(self) -> None:
        """Give the lock up (idempotent)."""
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)  # closing the descriptor releases the flock

    def __enter__(self) -> "DirectoryLock":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _flock(fd: int) -> bool:
    """Lock ``fd`` exclusively without waiting: True when locked, False when the file system
    cannot lock; ``BlockingIOError`` when another process holds it."""
    try:
        import fcntl
    except ImportError:  # not on a POSIX system
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:  # held by another: the caller says by whom
        raise
    except OSError as exc:
        if exc.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
            return False
        raise
    return True
