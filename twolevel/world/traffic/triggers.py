"""When a scripted action starts: at a time, some time after the previous action, or when the
ego comes within a distance or a time gap of the participant.

Codes: :data:`AFTER` (``after: s`` — seconds after the previous action of the chain ended; the
first one's "previous" ends at t = 0), :data:`AFTER_START` (``after_start: s`` — seconds after
the previous one started), :data:`AT` (``at: t`` — at time t [s]), :data:`EGO_WITHIN`
(``ego_within: d`` — the ego's centre within d [m] of the participant's), :data:`EGO_HEADWAY`
(``ego_headway: τ`` — that distance, divided by the ego's speed, within τ [s]). Without the ego
(a replay without it) the ego conditions never hold.
"""

from __future__ import annotations

import numpy as np

__all__ = ["AFTER", "AFTER_START", "AT", "EGO_WITHIN", "EGO_HEADWAY", "TRIGGERS", "fires"]

AFTER, AFTER_START, AT, EGO_WITHIN, EGO_HEADWAY = 0, 1, 2, 3, 4
TRIGGERS = {"after": AFTER, "after_start": AFTER_START, "at": AT, "ego_within": EGO_WITHIN, "ego_headway": EGO_HEADWAY}
"""YAML key → trigger code."""


def fires(kind: np.ndarray, value: np.ndarray, t: float, started: np.ndarray, ended: np.ndarray,
          ego_dist: np.ndarray, ego_speed: float) -> np.ndarray:
    """Whether each trigger (``kind``, ``value``) holds at time ``t`` [s], given when the previous
    action ``started`` and ``ended`` [s] (+inf: still running) and the ego's distance [m] (+inf:
    no ego) and speed [m/s]."""
    headway = ego_dist / max(ego_speed, 0.1)
    return np.select(
        [kind == AFTER, kind == AFTER_START, kind == AT, kind == EGO_WITHIN, kind == EGO_HEADWAY],
        [t >= ended + value - 1e-9, t >= started + value - 1e-9, t >= value - 1e-9, ego_dist <= value, headway <= value],
        False)
