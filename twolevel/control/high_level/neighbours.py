"""The vehicles around the ego in the MPC: the participant signals ``v(o)``, ``d_lon(o)``,
``d_behind(o)`` and ``left_of(o)`` over the horizon, for rules that say where the ego may be
relative to another vehicle (``rules/overtaking.stl``'s ``no_passing_right``).

The definitions are :mod:`twolevel.world.relations`' (the reference; the table of
:mod:`twolevel.world.provided`). Over the fine part of the horizon (k = 0..H), for every
participant within ``r_near`` now, on its constant-velocity prediction (``hc.xy``, ``hc.psi``,
``hc.v``, as :func:`~twolevel.world.signals.horizon_constants` predicts it) projected on the route:

* ``v[ID]``,k: its speed along the route, a constant;
* ``d_lon[ID]``,k = c_k − s_k with c_k = s_o,k − l_o − L/2, and ``d_behind[ID]``,k = s_k − c'_k
  with c'_k = s_o,k + l_o + L/2: affine in the ego's route progress s_k
  (:mod:`~twolevel.control.high_level.problem`);
* ``left_of[ID]``,k = c''_k − e_k with c''_k = e_o,k − h_o − W/2 (−inf for a vehicle not running
  the route's way): affine in the ego's lateral offset e_k;
* ``present[ID]``: +inf over the horizon.

The ego's box is taken along the route, L/2 ahead and behind and W/2 to each side: the reference's
``d_behind`` and ``left_of`` are defined so (exact here); its ``d_lon`` counts the ego's heading
relative to the route ((L cos θ + W |sin θ|)/2 instead of L/2: a few centimetres at the headings
the MPC plans). The encoder expands a rule's quantifier over the participants. Units: m, m/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from twolevel.control.high_level.right_of_way import participant_pasts
from twolevel.stl.analysis import participant_key
from twolevel.world.relations import relations
from twolevel.world.signals import HorizonConstants
from twolevel.world.world import World

__all__ = ["NEIGHBOUR_SIGNALS", "MPC_NEIGHBOUR_PATTERNS", "NeighbourConstants", "neighbour_constants",
           "neighbour_signals_over", "left_leader"]

NEIGHBOUR_SIGNALS = ("v", "d_lon", "d_behind", "left_of")
"""The participant signals of this module."""

MPC_NEIGHBOUR_PATTERNS = frozenset(participant_key(n, "*") for n in NEIGHBOUR_SIGNALS)
"""The participant signals the MPC predicts through this module (as a rule's reads name them)."""

FAR = 1e3
"""[m] ``left_of`` at the steps of a horizon where its vehicle does not run the route's way while
it does at others (the reference's −inf there): far to the right, finite for the encoding."""

Affine = Callable[[np.ndarray, np.ndarray], object]
"""(past (P,), c (H+1,)) → an affine signal after the P recorded samples ``past``."""


@dataclass(frozen=True, eq=False)
class NeighbourConstants:
    """Participants ``ids`` within r_near at solve time and, over k = 0..H, (n, H+1) each: ``v``
    [m/s] along the route; ``lon`` [m] (d_lon = lon − s_k), ``behind`` [m] (d_behind = s_k −
    behind), ``left`` [m] (left_of = left − e_k; −inf: not running the route's way)."""

    ids: tuple[str, ...] = ()
    v: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))
    lon: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))
    behind: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))
    left: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))


def neighbour_constants(world: World, hc: HorizonConstants, s_bar: np.ndarray, H: int) -> NeighbourConstants:
    """The :class:`NeighbourConstants` over the first H steps of ``hc``; ``s_bar`` (≥ H+1,) [m]:
    the ego's route positions about which the step is linearised (where the predictions are
    projected; the constants do not depend on them)."""
    n = len(hc.index)
    if not n:
        return NeighbourConstants()
    f = slice(0, H + 1)
    route = world.route
    s = np.asarray(s_bar[f], float)
    xy = hc.xy[:, f].reshape(-1, 2)
    so, eo = route.project_near(xy, np.tile(s, n), world.settings.r_near + 5.0)
    so, eo = so.reshape(n, H + 1).T, eo.reshape(n, H + 1).T  # (H+1, n)
    ego = {"s": s[:, None], "e": np.zeros((H + 1, 1)), "psi": route.heading_at(s)[:, None]}
    other = {"s": so, "e": eo, "psi": hc.psi[:, f].T, "v": np.broadcast_to(hc.v[None, :], (H + 1, n))}
    rel = relations(route, ego, (world.ego.length, world.ego.width), other, hc.length, hc.width,
                    np.ones((H + 1, n), dtype=bool))
    ids = tuple(world.parts.ids[i] for i in hc.index)
    return NeighbourConstants(ids, rel["v"].T.copy(), (rel["d_lon"] + s[:, None]).T.copy(),
                              (s[:, None] - rel["d_behind"]).T.copy(), rel["left_of"].T.copy())


def neighbour_signals_over(nc: NeighbourConstants | None, names: frozenset[str] | set[str], H: int, P: int,
                           ahead: Affine, behind: Affine, left: Affine, hist: Callable[[str, float], np.ndarray]
                           ) -> dict[str, object]:
    """The participant signals of ``names`` this module provides over the trace (P past samples,
    now, k = 1..H): ``ahead(past, c)`` is the affine signal c − s_k, ``behind(past, c)`` s_k − c,
    ``left(past, c)`` c − e_k; ``hist(name, now)``: the recorded past of ``name`` then ``now``
    (what is not recorded reads as absent)."""
    if nc is None:
        return {}
    present, rows = participant_pasts(nc.ids, names, NEIGHBOUR_SIGNALS, H, P, hist)
    out: dict[str, object] = dict(present)
    build: Mapping[str, tuple[Affine, np.ndarray]] = {"d_lon": (ahead, nc.lon), "d_behind": (behind, nc.behind),
                                                      "left_of": (left, nc.left)}
    for j, name, key, pst in rows:
        if name == "v":
            out[key] = np.concatenate([pst, nc.v[j]])
            continue
        make, c = build[name]
        row = c[j]
        if not np.isfinite(row).any():  # left_of of a vehicle not running the route's way
            out[key] = np.concatenate([pst, row])
        else:  # one that turns within the horizon: far to the right there, finite for the encoding
            out[key] = make(pst, np.maximum(row, -FAR))
    return out


def left_leader(hc: HorizonConstants, lengths: np.ndarray, widths: np.ndarray, s0: float, e0: float, length: float,
                width: float, v_des: float, times: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The vehicle the MPC's reference must not draw level with faster than it: among the
    vehicles sensed now (``hc.seen*``; ``lengths``/``widths`` [m] indexed by participant) that run
    the route's way wholly left of the ego (a body of ``length`` × ``width`` [m] at route position
    ``s0``, lateral offset ``e0`` [m]), with their rear ahead of its front and slower than
    ``v_des`` [m/s], the one the ego would draw level with first. Returns where the ego's centre
    draws level with its rear, at ``times`` (N+1,) [s] (constant velocity) [m], and its speed
    [m/s]; None: none. no_passing_right holds over the MPC's first second (its rules' span); this
    keeps the look-ahead beyond it from driving up faster (the rule's slow-traffic exception is
    left to the rule: the reference matches the speed)."""
    if not len(hc.seen):
        return None
    lo, wo = lengths[hc.seen], widths[hc.seen]
    rear = hc.seen_s - 0.5 * lo - 0.5 * length  # where the ego's centre is level with o's rear
    ok = ((hc.seen_v > 0.0) & (hc.seen_e - 0.5 * wo > e0 + 0.5 * width) & (rear > s0) & (hc.seen_v < v_des))
    if not ok.any():
        return None
    reach = np.where(ok, (rear - s0) / np.maximum(v_des - hc.seen_v, 1e-3), np.inf)  # when the ego would be level
    j = int(np.argmin(reach))
    return rear[j] + hc.seen_v[j] * np.asarray(times, float), float(hc.seen_v[j])
