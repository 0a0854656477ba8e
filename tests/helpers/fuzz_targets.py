"""Targets for :mod:`twolevel.fuzz.campaign`'s own tests (importable by its spawned workers): each
input draws what it does from its own random generator, so a test can replay the draws."""

from __future__ import annotations

import os
import random
import signal
import time
from typing import Any, Callable

from twolevel.fuzz.campaign import Probe

KINDS = ("ok", "ok", "slow", "sleeps", "stuck", "dies")


def misbehaving(options: dict[str, Any]) -> Callable[[random.Random], Probe]:
    """A target whose inputs are fine, slow (``options["slow_s"]`` [s]), sleep in Python (the alarm
    stops them), are stuck where no alarm reaches (SIGALRM blocked: the worker must be killed) or
    end their worker."""

    def one(rnd: random.Random) -> Probe:
        kind = rnd.choice(KINDS)
        if kind == "slow":
            time.sleep(options["slow_s"])
        elif kind == "sleeps":
            time.sleep(60)
        elif kind == "stuck":
            signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGALRM])
            time.sleep(60)
        elif kind == "dies":
            os._exit(3)
        return Probe("accepted", text=f"a {kind} input")

    return one
