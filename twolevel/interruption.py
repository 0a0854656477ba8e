"""Interruptions: SIGINT (Ctrl-C), SIGTERM and SIGHUP as one request that work honours where
stopping is safe.

Left to Python, SIGINT raises ``KeyboardInterrupt`` wherever the main thread happens to be: in
the middle of an import (a raw traceback), inside a compiled extension that swallows the error
(the run goes on, or fails later on the stale error), between writing a row and recording it.
SIGTERM and SIGHUP kill the process outright (``run.json`` stays "running").

The command line (``twolevel/__main__.py``) calls :func:`install`: the three signals are then
handled alike. Inside :func:`deferred` (the ``simulate`` command, the start-up imports) the first
signal is only recorded, and the work calls :func:`checkpoint` where stopping is safe (between
start-up phases, after each completed step), which raises :class:`Interrupted` — a
``KeyboardInterrupt``, so every handler of Ctrl-C handles it — naming the signal. Every
checkpoint after the signal raises again, so an interruption that compiled code swallowed is
raised at the next one: a signal is never lost. A second signal while deferred raises at once
(the user insists: a phase that never reaches a checkpoint can still be stopped). Inside
:func:`shielded` (writing the last rows and ``run.json``) no signal raises; it is recorded and
the next checkpoint after the shield raises it. Outside both, an installed handler raises at
once, as Python does for Ctrl-C. Inside :func:`prompt` (within a deferred block: a phase with
no safe point inside that may take long, such as building compiled functions, whose compiler
runs in a subprocess) the first signal raises at once too: what the phase built is thrown away.

Without :func:`install` (twolevel used as a library) Python's own handling is left alone and
:func:`checkpoint` raises only for a signal this module recorded, i.e. never.

Signals that arrive while the Python interpreter itself starts, before any of twolevel's code
runs (its first few tens of milliseconds), get Python's default behaviour: nothing of twolevel
can run then. The module imports only the standard library.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from dataclasses import dataclass
from typing import Iterator

__all__ = ["Interrupted", "SIGNALS", "install", "deferred", "prompt", "shielded", "checkpoint", "received",
           "insisted", "clear", "describe", "exit_code"]

SIGNALS: tuple[int, ...] = tuple(int(getattr(signal, n)) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))
"""The signals handled alike: Ctrl-C, a polite kill (CI time-outs, ``docker stop``), a closed terminal."""


def describe(signum: int | None) -> str:
    """``interrupted by the user (Ctrl-C)`` for SIGINT (or an unknown cause), else
    ``interrupted by SIGTERM`` / ``SIGHUP``."""
    if signum is None or signum == signal.SIGINT:
        return "interrupted by the user (Ctrl-C)"
    try:
        return f"interrupted by {signal.Signals(signum).name}"
    except ValueError:
        return f"interrupted by signal {signum}"


def exit_code(signum: int | None) -> int:
    """The shell's convention for a command a signal stopped: 128 + its number (130 for Ctrl-C)."""
    return 128 + int(signal.SIGINT if signum is None else signum)


class Interrupted(KeyboardInterrupt):
    """Raised at a checkpoint (or at once, see the module docstring) for the signal ``signum``."""

    def __init__(self, signum: int) -> None:
        super().__init__(describe(signum))
        self.signum = signum


@dataclass
class _State:
    signum: int | None = None
    """The first signal received."""
    count: int = 0
    defer: int = 0
    prompt: int = 0
    shield: int = 0
    installed: bool = False
    deferring: bool = False


_state = _State()


def _handler(signum: int, frame: object) -> None:
    s = _state
    s.count += 1
    if s.signum is None:
        s.signum = signum
    if s.shield or (s.defer and not s.prompt and s.count == 1):
        return
    raise Interrupted(signum)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def install(*, deferring: bool = False) -> bool:
    """Handle :data:`SIGNALS` as described in the module docstring, for the rest of the
    process (idempotent). ``deferring``: the whole process is a :func:`deferred` block (a
    worker, whose parent forwards it one signal to stop at its next checkpoint, wherever it is
    waiting meanwhile). False when it cannot be done (not the main thread)."""
    if not _state.installed:
        if not _main_thread():
            return False
        for sig in SIGNALS:
            signal.signal(sig, _handler)
        _state.installed = True
    if deferring and not _state.deferring:
        _state.deferring = True
        _state.defer += 1
    return True


def insisted() -> bool:
    """More than one signal was received (the user insists: waiting politely should end)."""
    return _state.count > 1


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Within the block the first signal only is recorded (see :func:`checkpoint`)."""
    _state.defer += 1
    try:
        yield
    finally:
        _state.defer -= 1


@contextlib.contextmanager
def prompt() -> Iterator[None]:
    """Within the block a signal raises at once, even inside :func:`deferred` (a signal that came
    before the block raises at its start)."""
    checkpoint()
    _state.prompt += 1
    try:
        yield
    finally:
        _state.prompt -= 1


@contextlib.contextmanager
def shielded() -> Iterator[None]:
    """Within the block no signal raises (keep it short: writing what was completed)."""
    _state.shield += 1
    try:
        yield
    finally:
        _state.shield -= 1


def checkpoint() -> None:
    """Raise :class:`Interrupted` if a signal was received (every time, until :func:`clear`);
    a no-op inside :func:`shielded`."""
    s = _state
    if s.signum is not None and not s.shield:
        raise Interrupted(s.signum)


def clear() -> None:
    """Forget the signals received (a process that goes on with other work after handling one)."""
    _state.signum, _state.count = None, 0


def received() -> int | None:
    """The first signal received since :func:`install` (None: none)."""
    return _state.signum
