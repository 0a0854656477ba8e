"""The processes of a session (``start_new_session=True``): what a command left behind."""

from __future__ import annotations

import os
import time


def session(sid: int) -> list[int]:
    """The processes still alive (not zombies) in the session ``sid``."""
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()  # state, ppid, pgrp, session, ...
        except OSError:
            continue
        if fields[0] != "Z" and int(fields[3]) == sid:
            out.append(int(entry))
    return out


def left_behind(sid: int, wait_s: float = 5.0) -> list[int]:
    """The processes of the session ``sid`` still alive after up to ``wait_s`` [s] (its leader
    has ended; the kernel may take a moment to reap the rest)."""
    deadline = time.monotonic() + wait_s
    while session(sid) and time.monotonic() < deadline:
        time.sleep(0.05)
    return session(sid)
