"""What the ego's motion felt like, from its recorded states: longitudinal acceleration, jerk
and lateral acceleration by finite differences of the trace (the executed motion of the
detailed model, not the commands)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Motion", "motion_of"]


@dataclass(frozen=True)
class Motion:
    """Derived motion between samples: ``t_acc`` (N−1,) [s] midpoints with ``accel`` [m/s²]
    (dv/dt) and ``lat_accel`` [m/s²] (v·dψ/dt, + left); ``t_jerk`` (N−2,) [s] with ``jerk``
    [m/s³] (da/dt)."""

    t_acc: np.ndarray
    accel: np.ndarray
    lat_accel: np.ndarray
    t_jerk: np.ndarray
    jerk: np.ndarray

    @property
    def peak_decel(self) -> tuple[float, float | None]:
        """Largest deceleration [m/s²] (0 if it never slowed) and when [s]."""
        return _peak(-self.accel, self.t_acc, floor=0.0)

    @property
    def peak_jerk(self) -> tuple[float, float | None]:
        """Largest |jerk| [m/s³] and when [s]."""
        return _peak(np.abs(self.jerk), self.t_jerk)

    @property
    def peak_lat_accel(self) -> tuple[float, float | None]:
        """Largest |lateral acceleration| [m/s²] and when [s]."""
        return _peak(np.abs(self.lat_accel), self.t_acc)


def _peak(values: np.ndarray, t: np.ndarray, floor: float = 0.0) -> tuple[float, float | None]:
    finite = np.isfinite(values)
    if not finite.any():
        return floor, None
    k = int(np.argmax(np.where(finite, values, -np.inf)))
    return (max(float(values[k]), floor), float(t[k])) if values[k] > floor else (floor, None)


def motion_of(t: np.ndarray, v: np.ndarray, psi: np.ndarray) -> Motion:
    """The :class:`Motion` of a trace: times ``t`` [s], signed speed ``v`` [m/s], heading
    ``psi`` [rad] (wrapped or not)."""
    t, v, psi = (np.asarray(a, dtype=float) for a in (t, v, psi))
    if t.size < 2:
        empty = np.zeros(0)
        return Motion(empty, empty, empty, empty, empty)
    dt = np.diff(t)
    dt = np.where(dt > 0, dt, np.nan)
    accel = np.diff(v) / dt
    lat = 0.5 * (v[1:] + v[:-1]) * np.diff(np.unwrap(psi)) / dt
    t_acc = 0.5 * (t[1:] + t[:-1])
    dta = np.diff(t_acc)
    jerk = np.diff(accel) / np.where(dta > 0, dta, np.nan) if t.size > 2 else np.zeros(0)
    return Motion(t_acc, accel, lat, 0.5 * (t_acc[1:] + t_acc[:-1]), jerk)
