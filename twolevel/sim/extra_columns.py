"""Trace columns beyond the closed loop's own: criticality per step, and every participant's
signals when the scenario's rules quantify over participants.

* **Criticality** (:mod:`twolevel.world.criticality`): ``ttc_s`` (time to collision with the
  vehicle ahead), ``thw_s`` (time headway), ``dhw_m`` (distance headway), ``ttc_any_s`` (time to
  collision with any participant within r_near, constant velocities); +inf when there is no
  vehicle ahead or no collision course. The time to react is the safety layer's column.
* **On-demand signals** (:data:`twolevel.world.provided.ON_DEMAND_SIGNALS`: ``xwalk_busy``,
  ``d_xwalk``): those a rule reads, as sensing gives them.
* **Participants** (:mod:`twolevel.world.provided`): for every participant of the scenario and
  every participant signal the rules read, the column ``NAME[ID]``, and ``present[ID]`` (+inf
  while it is within r_near, −inf elsewhere, where its other columns hold their absent values).
  Sensing gives the vehicles in range; :meth:`ExtraColumns.record` completes the sample with the
  others and with ``a(o)``, the change of the recorded ``v(o)`` over the step (the closed loop
  senses one sample at a time). The history the controllers read and the online monitor's samples
  carry the same values, so ``twolevel monitor RULES trace.csv`` reproduces the ``rob_`` columns.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from twolevel.stl.analysis import PRESENT, participant_key
from twolevel.world.criticality import headways, time_to_collision_any
from twolevel.world.relations import absent_sample
from twolevel.world.sensing import Others
from twolevel.world.world import World

__all__ = ["CRITICALITY_COLUMNS", "ExtraColumns"]

CRITICALITY_COLUMNS = ("ttc_s", "thw_s", "dhw_m", "ttc_any_s")
"""The criticality columns of a trace, in order (see the module docstring)."""


class ExtraColumns:
    """The extra columns of one run of ``world``: :attr:`columns` in the trace (criticality
    first), :attr:`signals` in every sample (the on-demand signals the rules read, :attr:`demand`,
    then the participants' signals), :attr:`ids` the
    participants the rules' quantifiers range over (none when no rule quantifies)."""

    def __init__(self, world: World) -> None:
        self.world = world
        names = world.participant_signals
        self.ids: tuple[str, ...] = world.parts.ids if names else ()
        self.names = names
        self.demand: tuple[str, ...] = world.on_demand_signals
        self._keys = tuple(participant_key(n, pid) for pid in self.ids for n in names)  # the participants' columns
        self.signals: tuple[str, ...] = self.demand + self._keys
        self.columns: tuple[str, ...] = CRITICALITY_COLUMNS + self.signals
        self._absent = absent_sample(names)
        self._v: dict[str, float] = {}  # v(o) at the previous sample of each participant present there

    def record(self, now: dict[str, float], pose: tuple[float, float, float, float], others: Others
               ) -> dict[str, Any]:
        """Complete the sample ``now`` in place (participants out of range, ``a(o)``) and return
        this step's extra cells; ``pose`` = (x, y, psi, v) of the ego [m, m, rad, m/s], ``others``
        the vehicles sensed (within r_near)."""
        cells = self._criticality(now, pose, others)
        cells.update({key: now[key] for key in self.demand})
        if not self.ids:
            return cells
        dt = self.world.settings.dt
        seen = {}
        for pid in self.ids:
            if now.get(participant_key(PRESENT, pid), -np.inf) > 0:
                v = now[participant_key("v", pid)] if "v" in self.names else np.nan
                if "a" in self.names:
                    prev = self._v.get(pid)
                    now[participant_key("a", pid)] = 0.0 if prev is None else (v - prev) / dt
                seen[pid] = v
            else:
                now.update({participant_key(n, pid): value for n, value in self._absent.items()})
        self._v = seen
        cells.update({key: now[key] for key in self._keys})
        return cells

    def _criticality(self, now: Mapping[str, float], pose: tuple[float, float, float, float], others: Others
                     ) -> dict[str, Any]:
        h = headways(now["d_lead"], now["v"], now["v_lead"])
        w = self.world
        near = np.hypot(others.x[:, 0] - pose[0], others.y[:, 0] - pose[1]) <= w.settings.r_near
        ttc_any = time_to_collision_any(pose, (w.ego.length, w.ego.width),
                                        (others.x[:, 0], others.y[:, 0], others.psi[:, 0], others.v[:, 0]),
                                        others.length, others.width, near)
        return {"ttc_s": float(h["ttc"]), "thw_s": float(h["thw"]), "dhw_m": float(h["dhw"]),
                "ttc_any_s": float(ttc_any)}
