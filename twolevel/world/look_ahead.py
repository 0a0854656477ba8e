"""The MPC's look-ahead as a scenario declares it (``controller: {H, dt, horizon_s, coarse_dt,
coarse_steps}``): its steps as whole numbers of periods. The scenario's to declare and
``twolevel check``'s to validate (pure Python, no numpy); the MPC builds on it
(:class:`~twolevel.control.high_level.settings.MPCSettings`).
"""

from __future__ import annotations

from typing import Sequence

__all__ = ["DEFAULT_HORIZON_S", "COARSE_PERIODS", "MAX_COARSE_STEPS", "look_ahead_periods"]

DEFAULT_HORIZON_S = 5.0
"""[s] The default look-ahead: long enough to stop from the speeds of the paper's scenarios with
a comfortable deceleration (14 m/s at 4 m/s² takes 3.5 s), and the horizon of the fail-safe
verification's fine intervals and more (:mod:`twolevel.safety.verify`)."""

COARSE_PERIODS = 5
"""Periods per coarse step by default (0.5 s at the paper's dt = 0.1 s)."""

MAX_COARSE_STEPS = 50
"""At most that many coarse steps (each adds a step of columns and rows to every MPC model)."""


def _periods(value: float, dt: float, what: str) -> int:
    """``value`` [s] as a whole number ≥ 1 of periods ``dt`` [s]; ValueError otherwise."""
    n = round(value / dt)
    if n < 1 or abs(value - n * dt) > 1e-6 * max(1.0, abs(value)):
        raise ValueError(f"{what} = {value:g} s is not a whole number of periods dt = {dt:g} s")
    return int(n)


def look_ahead_periods(H: int, dt: float, horizon_s: float | None = None, coarse_dt: float | None = None,
                     coarse_steps: Sequence[float] | None = None) -> tuple[int, ...]:
    """The MPC's step lengths as whole numbers of periods dt [s]: ``H`` steps of one period, then coarse steps up to
    ``horizon_s`` [s] (None: the larger of :data:`DEFAULT_HORIZON_S` and H·dt, or H·dt plus the
    explicit ``coarse_steps``), each ``coarse_dt`` [s] long (None: :data:`COARSE_PERIODS`·dt) with
    a shorter last one when the rest is not a multiple, or exactly ``coarse_steps`` [s]. Raises
    ValueError (a message naming the setting) for lengths that are not whole numbers of periods,
    a look-ahead shorter than the fine part, both ``coarse_dt`` and ``coarse_steps``, a
    ``horizon_s`` that disagrees with ``coarse_steps``, or more than :data:`MAX_COARSE_STEPS`."""
    if coarse_dt is not None and coarse_steps is not None:
        raise ValueError("give coarse_dt or coarse_steps, not both")
    fine = H * dt
    if coarse_steps is not None:
        periods = [_periods(float(c), dt, "a coarse step") for c in coarse_steps]
        if horizon_s is not None and _periods(horizon_s, dt, "horizon_s") != H + sum(periods):
            raise ValueError(f"horizon_s = {horizon_s:g} s differs from H·dt + the coarse steps = "
                             f"{fine + sum(periods) * dt:g} s")
    else:
        if horizon_s is None:
            total = max(round(DEFAULT_HORIZON_S / dt), H)
        else:
            total = _periods(horizon_s, dt, "horizon_s")
            if total < H:
                raise ValueError(f"horizon_s = {horizon_s:g} s is shorter than the fine part H·dt = {fine:g} s")
        c = COARSE_PERIODS if coarse_dt is None else _periods(coarse_dt, dt, "coarse_dt")
        rest = total - H
        periods = [c] * (rest // c) + ([rest % c] if rest % c else [])
    if len(periods) > MAX_COARSE_STEPS:
        raise ValueError(f"{len(periods)} coarse steps; at most {MAX_COARSE_STEPS} (use longer coarse steps)")
    return (1,) * H + tuple(periods)
