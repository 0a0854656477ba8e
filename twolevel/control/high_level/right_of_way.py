"""Right of way at junctions in the MPC: the conflict-area signals over the horizon, and the
give-way line its terminal condition keeps the ego able to stop at.

The definitions are :mod:`twolevel.world.right_of_way`'s (the reference). Over the fine part of
the horizon (k = 0..H):

* ``d_zone``,k = s_in − L/2 − s_k and ``d_zone_out``,k = s_out + L/2 − s_k, affine in the ego's
  state through the route progress s_k ≈ s̄_k + t̄_kᵀ(p_k − p̄_k) (:mod:`.problem`); the area is
  the one next at solve time (+inf / −inf: none).
* ``d_exit[ID]``,k = c − s_k, c the route position at which the ego's rear leaves its zone of
  the conflict with the participant's way (the latest over the horizon's predictions: affine);
* ``t_reach[ID]``, ``t_clear[ID]``, ``priority[ID]`` and ``present[ID]`` of every participant
  within ``r_near`` now: constants, the definitions evaluated on its constant-velocity prediction
  (``hc.xy``, as :func:`~twolevel.world.signals.horizon_constants` predicts it) with the area
  held; ``present`` +inf over the horizon. The encoder expands a rule's quantifier over them.

**The give-way line.** The rules see one second ahead; a car coming up to a junction at speed
cannot stop in that second. While a participant with priority is within ``r_near`` and the ego
may not yet go (:meth:`ZoneConstants.waiting`), or a slow vehicle ahead in the ego's lane leaves
no room behind the area's exit (:data:`BLOCK_GAP`: the junction cannot be cleared), the
terminal can-still-stop condition of :mod:`~twolevel.control.high_level.guards` keeps the ego
able to stop :data:`RUN_UP` metres before the area's entry, as it does at a stop line; with
nobody to give way to it does not apply. The ego may go when, for every participant with
priority, both hold:

* **the rule** — its constant-velocity ``t_reach`` is at least the gap the loaded rule asks for,
  margin + d_exit / speed (:class:`GapRule`, read from the rule's own constants by
  :func:`gap_rule`: the MILP and the line keep the same rule);
* **safety** — its earliest arrival under the world's assumptions about others
  (:func:`twolevel.safety.occupancy.reach_bounds`: accelerating at most as SPOT's engine model
  allows, up to speed_factor × its lane tree's limit — the model the safety layer's verifier
  predicts it with) is no sooner than the ego can be out of its way clearing as the verifier's
  clearing fail-safe does (:data:`CLEAR_ACCEL` from its speed now, no margin: the worst case is
  the margin). Once committed, the verifier keeps that fail-safe: the ego clears, it does not
  stop inside.
Units: m, s, m/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

from twolevel.safety.failsafe import FailSafeSettings
from twolevel.safety.network import network_of
from twolevel.safety.occupancy import reach_bounds, time_to_travel
from twolevel.stl.analysis import PRESENT, fold_term, participant_key, split_participant_key
from twolevel.stl.ast import Compare, Node, Num, ParticipantSignal, rewrite
from twolevel.stl.typecheck import RuleSet
from twolevel.world.provided import PARTICIPANT_ABSENT
from twolevel.world.right_of_way import (REACH_DISTANCE, ZONE_PARTICIPANT_SIGNALS, next_area,
                                         participant_zone_signals)
from twolevel.world.signals import HorizonConstants
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World

__all__ = ["RUN_UP", "CLEAR_ACCEL", "BLOCK_GAP", "GapRule", "gap_rule", "ZoneConstants", "zone_constants",
           "give_way_line", "zone_signals_over", "recorded_past", "participant_pasts", "MPC_ZONE_PATTERNS"]

RUN_UP = 1.0
"""[m] How far before a conflict area the ego waits for a gap (its front); from there it moves off
into the area accelerating, as rules/right_of_way.stl allows, and a stop sign's line (the area
starts a metre or two past it) is within its stop zone."""

CLEAR_ACCEL = max(FailSafeSettings().clear_accels)
"""[m/s²] The acceleration the ego is taken to clear a conflict area with: the safety layer's
clearing fail-safe's (:class:`~twolevel.safety.failsafe.FailSafeSettings`)."""


@dataclass(frozen=True)
class GapRule:
    """The gap a right-of-way rule asks of the ego before a participant with priority arrives,
    ``t_reach(o) >= margin + d_exit(o) / speed``: ``margin`` [s], ``speed`` [m/s] (also the
    least speed inside the area below which a vehicle ahead may block the exit). The defaults
    are rules/right_of_way.stl's t_margin and v_go."""

    margin: float = 1.5
    speed: float = 4.0

    def needs(self, d_exit: np.ndarray) -> np.ndarray:
        """The gap [s] the ego needs with its rear ``d_exit`` [m] from leaving o's way."""
        return self.margin + np.maximum(d_exit, 0.0) / self.speed


def _value(term: Node, d: float) -> float:
    """A term of numbers and ``d_exit(o)`` at d_exit = ``d`` [m], folded
    (:func:`twolevel.stl.analysis.fold_term`; ``ValueError``: it reads more, or does not fold)."""
    bound = rewrite(term, lambda n: Num(d) if isinstance(n, ParticipantSignal) and n.name == "d_exit" else None)
    folded = fold_term(bound)
    if not isinstance(folded, Num):
        raise ValueError(term)
    return folded.value


def gap_rule(rulesets: Sequence[RuleSet]) -> GapRule:
    """The :class:`GapRule` of the first predicate ``t_reach(o) >= g(d_exit(o))`` (or
    ``g(...) <= t_reach(o)``) among the rules of ``rulesets``, g affine in d_exit with its
    constants bound (a scenario's override of t_margin or v_go included); the defaults when no
    rule has one."""
    for rs in rulesets:
        for r in rs.rules:
            for node in rs.formula(r.name).walk():
                if not isinstance(node, Compare):
                    continue
                if node.op in (">=", ">") and _is_t_reach(node.left):
                    g = node.right
                elif node.op in ("<=", "<") and _is_t_reach(node.right):
                    g = node.left
                else:
                    continue
                try:
                    m, slope, far = _value(g, 0.0), _value(g, 1.0) - _value(g, 0.0), _value(g, 100.0)
                except ValueError:
                    continue
                if slope > 0 and math.isclose(far, m + 100.0 * slope, rel_tol=1e-9, abs_tol=1e-9):
                    return GapRule(m, 1.0 / slope)
    return GapRule()


def _is_t_reach(term: Node) -> bool:
    return isinstance(term, ParticipantSignal) and term.name == "t_reach"


BLOCK_GAP = 2.0
"""[m] The room the ego needs, once it has left the area, behind a vehicle ahead slower than the
rule's least speed inside (:attr:`GapRule.speed`)."""

MPC_ZONE_PATTERNS = frozenset(participant_key(n, "*") for n in ZONE_PARTICIPANT_SIGNALS)
"""The participant signals the MPC predicts (as the patterns a rule's reads name them)."""


@dataclass(frozen=True, eq=False)
class ZoneConstants:
    """The next conflict area at solve time: route entry ``s_in`` and exit ``s_out`` [m]
    (±inf: none), the ego's route position ``s0`` [m] and ``length`` [m]; participants ``ids``
    (n,) within r_near and their ``values`` (n, H+1) over the fine part: ``t_reach``/``t_clear``
    [s], ``priority``, ``d_exit`` [m] (with the ego held at s0; the MPC makes it c − s_k);
    ``worst_reach`` (n,) [s]: when each could reach the area at the earliest under the world's
    assumptions (:func:`twolevel.safety.occupancy.reach_bounds`, the verifier's model);
    ``clear_time`` (n,) [s]: when the ego, clearing at :data:`CLEAR_ACCEL` from its speed now, is
    out of each one's way; ``gap``: the rule's :class:`GapRule`; ``blocked``: the exit is."""

    s_in: float = math.inf
    s_out: float = -math.inf
    s0: float = 0.0
    length: float = 0.0
    ids: tuple[str, ...] = ()
    values: Mapping[str, np.ndarray] = field(default_factory=dict)
    blocked: bool = False
    worst_reach: np.ndarray = field(default_factory=lambda: np.zeros(0))
    clear_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gap: GapRule = GapRule()

    def waiting(self) -> bool:
        """Whether the ego waits before the area: the exit is ``blocked``, or someone with
        priority comes sooner than the rule's gap at its speed now (``t_reach`` <
        :meth:`GapRule.needs`) or, at its earliest under the assumptions, before the ego could
        be out of its way (``worst_reach`` < ``clear_time``)."""
        p, d, t = self.values.get("priority"), self.values.get("d_exit"), self.values.get("t_reach")
        if self.blocked:
            return True
        if p is None or not len(p):
            return False
        with np.errstate(invalid="ignore"):
            short = (t[:, 0] < self.gap.needs(d[:, 0])) | (self.worst_reach < self.clear_time)
        return bool(np.any((p[:, 0] > 0.5) & short))


def zone_constants(world: World, hc: HorizonConstants, s0: float, H: int, traffic: TrafficState,
                   v0: float = 0.0, gap: GapRule = GapRule()) -> ZoneConstants:
    """The :class:`ZoneConstants` at route position ``s0`` [m] and speed ``v0`` [m/s] over the
    first H steps of ``hc``; ``traffic``: the participants now (their lanes, for the worst case);
    ``gap``: the rule's."""
    z = world.zones
    k = int(next_area(z, np.array(s0), float(world.ego.length), world.settings.r_near))
    if k < 0:
        return ZoneConstants(length=float(world.ego.length), gap=gap)
    n = len(hc.index)
    ids = tuple(world.parts.ids[i] for i in hc.index)
    f = slice(0, H + 1)
    other = {"x": hc.xy[:, f, 0].T, "y": hc.xy[:, f, 1].T, "psi": hc.psi[:, f].T,
             "v": np.broadcast_to(hc.v[None, :], (H + 1, n))}
    vals = participant_zone_signals(world, np.full(H + 1, s0), hc.t[f], other, hc.length,
                                    np.ones((H + 1, n), dtype=bool)) if n else {}
    L = float(world.ego.length)
    worst, clear = np.zeros(0), np.zeros(0)
    if n:
        reach = reach_bounds(network_of(world), traffic, np.asarray(hc.index), world.assumptions, world.parts.user)
        worst = reach.earliest(vals[REACH_DISTANCE][0])
        d_exit = np.maximum(vals["d_exit"][0], 0.0)
        clear = time_to_travel(np.full(n, max(v0, 0.0)), np.full(n, np.inf), np.full(n, CLEAR_ACCEL),
                               np.full(n, np.inf), d_exit)
    # the exit is blocked when the vehicle ahead in the ego's lane (slower than the rule's least
    # speed inside, v_ahead held) would leave no room for the ego behind the area's exit
    room = float(hc.s_ahead[min(H, len(hc.s_ahead) - 1)]) - hc.ahead_offset - BLOCK_GAP
    blocked = hc.ahead >= 0 and hc.v_ahead < gap.speed and room < float(z.area_s1[k]) + L / 2
    return ZoneConstants(float(z.area_s0[k]), float(z.area_s1[k]), s0, L, ids,
                         {name: np.asarray(v).T for name, v in vals.items()}, bool(blocked), worst, clear, gap)


def give_way_line(zc: ZoneConstants | None) -> float:
    """[m] The route position of the ego's centre at which it must be able to stop (+inf: none)."""
    if zc is None or not math.isfinite(zc.s_in) or not zc.waiting():
        return math.inf
    return zc.s_in - zc.length / 2 - RUN_UP


def zone_signals_over(zc: ZoneConstants | None, names: frozenset[str] | set[str], H: int, P: int,
                      route_s: Callable[[np.ndarray, float], object], hist: Callable[[str, float], np.ndarray]
                      ) -> dict[str, object]:
    """The signals of ``names`` this module provides over the trace (P past samples from
    ``hist``, now, k = 1..H). ``route_s(past, c)`` is the affine signal c − s_k after the P
    samples ``past``; ``hist(name, now)``: the recorded past of ``name`` then ``now`` (what is
    not recorded reads as absent)."""
    zc = zc or ZoneConstants()
    out: dict[str, object] = {}
    for name, c, none in (("d_zone", zc.s_in - zc.length / 2, np.inf),
                          ("d_zone_out", zc.s_out + zc.length / 2, -np.inf)):
        if name in names:
            pst = recorded_past(hist, P, name, none)
            out[name] = route_s(pst, c) if math.isfinite(c) else np.concatenate([pst, np.full(H + 1, none)])
    present, rows = participant_pasts(zc.ids, names, ZONE_PARTICIPANT_SIGNALS, H, P, hist)
    out.update(present)
    for j, name, key, pst in rows:
        row = zc.values[name][j] if name in zc.values else np.full(H + 1, PARTICIPANT_ABSENT[name])
        if name == "d_exit" and np.isfinite(row).any():  # c − s_k: where the ego leaves o's way
            out[key] = route_s(pst, float(np.max(row[np.isfinite(row)])) + zc.s0)
        else:
            out[key] = np.concatenate([pst, row])
    return out


def recorded_past(hist: Callable[[str, float], np.ndarray], P: int, key: str, absent: float) -> np.ndarray:
    """(P,) The samples of ``key`` before now (``hist(key, now)``: the recorded past then
    ``now``), ``absent`` where none is recorded."""
    h = hist(key, absent)[:-1]
    return np.concatenate([np.full(P - len(h), absent), h])


def participant_pasts(ids: Sequence[str], names: frozenset[str] | set[str], signals: Sequence[str], H: int, P: int,
                      hist: Callable[[str, float], np.ndarray]
                      ) -> tuple[dict[str, np.ndarray], list[tuple[int, str, str, np.ndarray]]]:
    """For the participant signals of ``signals`` that ``names`` read of every participant
    (``name[*]``), when any: ``present[ID]`` of each of ``ids`` over the trace (its recorded past,
    then +inf over the H+1 steps), and (j, name, key, past) for each participant j and signal
    name: its column ``key`` and its P recorded samples (absent: the signal's absent value) that
    the caller's horizon rows follow."""
    wanted = [split_participant_key(nm) for nm in names]
    wanted = [w[0] for w in wanted if w is not None and w[1] == "*" and w[0] in signals]
    if not wanted:
        return {}, []
    present, rows = {}, []
    for j, pid in enumerate(ids):
        key = participant_key(PRESENT, pid)
        present[key] = np.concatenate([recorded_past(hist, P, key, -np.inf), np.full(H + 1, np.inf)])
        for name in wanted:
            key = participant_key(name, pid)
            rows.append((j, name, key, recorded_past(hist, P, key, PARTICIPANT_ABSENT[name])))
    return present, rows
