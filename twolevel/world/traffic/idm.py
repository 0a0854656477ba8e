"""The Intelligent Driver Model and the envelope every behaviour keeps.

IDM (Treiber, Hennecke, Helbing, "Congested traffic states in empirical observations and
microscopic simulations", Phys. Rev. E 62, 2000): a = a_max·(1 − (v/v0)^δ − (s*/s)²) with the
desired gap s* = s0 + max(0, v·T + v·Δv / (2·√(a·b))).

IDM by itself brakes as hard as its formula says: a car at 10 m/s placed 10 m behind a standing
one asks for about −29 m/s², which no tyre gives. Every behaviour here (IDM, MOBIL, manoeuvres,
walking; not waypoints, which are positions) is therefore kept inside the *envelope* of its kind
of road user as the safety layer assumes it (:mod:`twolevel.world.assumptions`): braking at most
``a_max`` (8 m/s² for vehicles, SPOT's friction limit), driving at most ``a_max`` and, above
``v_switch``, at most ``a_max · v_switch / v`` (the engine's power), and no faster than the
speed bound where it is (min(v_max, speed_factor · limit)) unless it already was. A participant
whose IDM wants more braking than the cap collides rather than stopping in an impossible
distance — as a real car would.
"""

from __future__ import annotations

import numpy as np

__all__ = ["idm_accel", "envelope", "speed_bound"]


def idm_accel(v: np.ndarray, v0: np.ndarray, gap: np.ndarray, dv: np.ndarray, p: np.ndarray) -> np.ndarray:
    """IDM acceleration [m/s²] at speed ``v`` [m/s] with desired speed ``v0`` [m/s], bumper gap
    ``gap`` [m] (+inf: free road) and approach rate ``dv`` = v − v_leader [m/s]; ``p`` (N, 6) the
    parameters (v0, T, s0, a, b, delta; v0 is taken from ``v0``)."""
    T, s0, a, b, delta = p[:, 1], p[:, 2], p[:, 3], p[:, 4], p[:, 5]
    s_star = s0 + np.maximum(0.0, v * T + v * dv / (2 * np.sqrt(a * b)))
    return a * (1 - (v / v0) ** delta - (s_star / np.maximum(gap, 0.01)) ** 2)


def envelope(acc: np.ndarray, v: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """``acc`` [m/s²] clipped to what the kind allows at speed ``v`` [m/s]: braking at most
    a_max, driving at most a_max and a_max · v_switch / v above v_switch (``bounds`` (N, 4): v_max,
    speed_factor, a_max, v_switch)."""
    a_max, v_sw = bounds[:, 2], bounds[:, 3]
    drive = np.where(v > v_sw, a_max * v_sw / np.maximum(v, 1e-9), a_max)
    return np.minimum(np.maximum(acc, -a_max), drive)


def speed_bound(v: np.ndarray, limit: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """The speed [m/s] not to exceed: min(v_max, speed_factor · ``limit``), or ``v`` if it is
    already faster (the assumptions then take its own speed as its bound)."""
    cap = np.minimum(bounds[:, 0], bounds[:, 1] * limit)
    return np.maximum(cap, v)
