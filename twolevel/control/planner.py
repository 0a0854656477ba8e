"""The interface of a high-level planner, which the MILP MPC and the NMPC baseline both implement.

One step of a planner::

    res = planner.solve(ego, t, world_state, history)     # -> PlanResult
    planner.reset()                                       # forget the previous plan

* ``ego``: an :class:`EgoState` — the pose (X [m], Y [m], ψ [rad], v [m/s]) and, when the
  caller simulates the detailed model, its 12-component state (:mod:`twolevel.models.fourwheel`);
  a bare sequence of 4 (or 12) numbers is read as one (:meth:`EgoState.of`). Each planner reads
  what its model needs: the MPC the pose, the four-wheel NMPC the detailed state.
* ``t`` [s]; ``world_state``: the other traffic now, a
  :class:`~twolevel.world.traffic.TrafficState` or a :class:`Snapshot` (traffic + stop-sign
  memory), None for an empty road (:data:`WorldState`).
* ``history``: recorded past samples of the rule signals, ``{name: array}`` oldest first,
  *excluding* the current step (may be None). ``history["delta"][-1]`` and ``history["a"][-1]``,
  when present, are the control applied in the last step.
* :class:`PlanResult`: a :class:`PlanStatus`, the controls (H, 2) [δ rad, a m/s²] and states
  (H+1, 4) [X, Y, ψ, v] of the plan over H periods dt (what the low level checks), the whole
  plan over a longer look-ahead when the planner has one (:class:`LookAhead`), and the solver's
  figures.

The simulation engine (:mod:`twolevel.sim.engine`) calls planners only through
:class:`Planner`; :mod:`twolevel.control.registry` makes one by the name a run chooses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping, Protocol, Sequence, TypeVar, Union, runtime_checkable

import numpy as np

from twolevel.control.codes import MIL512
from twolevel.diagnostics import Diagnostic, Span
from twolevel.milp.solution import ValueEnum
from twolevel.models.params import BicycleParams
from twolevel.world.signals import StopMemory, update_stop_memory
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World, load_rulesets

__all__ = ["PlanStatus", "PlanResult", "LookAhead", "EgoState", "Snapshot", "WorldState", "PreviousPlan", "Planner",
           "planner_of_world", "stop_memory_of", "DETAILED_STATES"]

DETAILED_STATES = 12
"""Components of the detailed four-wheel state (:data:`twolevel.models.fourwheel.NX`)."""


class PlanStatus(ValueEnum):
    """How a planning step ended (prints and compares as its value, like the solvers' statuses)."""

    OPTIMAL = "optimal"
    """A plan that satisfies every rule, optimal (certified within the gap)."""
    FEASIBLE = "feasible"
    """A plan that satisfies every rule, not certified optimal."""
    FALLBACK = "fallback"
    """No plan found: the previous plan shifted by one step, or full braking."""
    INFEASIBLE = "infeasible"
    """No plan satisfies every rule (a solve path's answer before the fallback)."""
    TIME_LIMIT = "time_limit"
    """No plan found within the time limit (a solve path's answer before the fallback)."""
    UNCHECKED = "unchecked"
    """A plan made without regard to the rules (:mod:`twolevel.control.reckless`)."""

    @property
    def ok(self) -> bool:
        """A plan that satisfies the rules."""
        return self in (PlanStatus.OPTIMAL, PlanStatus.FEASIBLE)


@dataclass(frozen=True, eq=False)
class LookAhead:
    """A plan over a look-ahead whose steps differ in length: ``periods`` (N,) (each step in
    periods dt, the first H of one), ``dt`` [s], ``states`` (N+1, 4) [X, Y, ψ, v] and ``controls``
    (N, 2) [δ rad, a m/s²] (held over each step)."""

    periods: np.ndarray
    dt: float
    states: np.ndarray
    controls: np.ndarray

    @property
    def times(self) -> np.ndarray:
        """(N+1,) [s] from now."""
        return self.dt * np.concatenate([[0], np.cumsum(self.periods)])


@dataclass(frozen=True, eq=False)
class PlanResult:
    """One planning step's answer. The NMPC fills the MILP's fields that do not apply with their
    neutral values (see :mod:`twolevel.control.nmpc.controller`)."""

    status: PlanStatus
    cost: float
    """The plan's cost (NaN for the fallback)."""
    controls: np.ndarray
    """(H, 2) [δ rad, a m/s²]; on the fallback the previous plan shifted, or full braking."""
    states: np.ndarray
    """(H+1, 4) [X m, Y m, ψ rad, v m/s]; row 0 is the ego state."""
    mode: np.ndarray
    """The choice per disjunction of the MILP (empty for the NMPC)."""
    binaries: int
    rows: int
    columns: int
    qps: int
    """QPs solved (the MPC) or IPOPT iterations (the NMPC)."""
    certified: bool
    """The status is proven (optimal within the gap, or infeasible)."""
    timings_ms: dict[str, float]
    """Phase → wall time [ms] (the MPC: linearise, assembly, backend, the solve path's phases,
    solve, total, monitor; the NMPC: prepare, parameters, solve, total)."""
    rule_robustness: dict[str, float]
    """Rule → robustness at the current step of the plan (offline monitor, high-level signals)."""
    message: str = ""
    gap: float = float("nan")
    """Relative optimality gap of the answer."""
    diagnostics: tuple[Diagnostic, ...] = ()
    solver: str = "modes"
    """The solve path (modes, highs, gurobi) or ``nmpc-<model>``."""
    cause: PlanStatus | None = None
    """Why the MPC fell back: how its solve path ended (:attr:`PlanStatus.INFEASIBLE`, no plan
    satisfies the rules, or :attr:`PlanStatus.TIME_LIMIT`); None when it did not fall back, when
    no solve ran (a rule could not be encoded), and for the NMPC (IPOPT's status is in
    ``message``)."""
    look_ahead: LookAhead | None = None
    """The whole plan when it looks further than ``states`` (None: ``states`` is all of it)."""

    @property
    def ok(self) -> bool:
        """A plan that satisfies the rules (optimal or feasible)."""
        return self.status.ok


@dataclass(frozen=True, eq=False)
class EgoState:
    """The ego now: ``pose`` (4,) = (X [m], Y [m], ψ [rad], v [m/s]) and, when known, the
    ``detailed`` (12,) four-wheel state (:mod:`twolevel.models.fourwheel`)."""

    pose: np.ndarray
    detailed: np.ndarray | None = None

    @classmethod
    def of(cls, state: "EgoState | Sequence[float] | np.ndarray") -> "EgoState":
        """``state`` itself, or a bare sequence read as a pose (4 numbers) or as a detailed
        state (12 numbers, whose first four — X, Y, ψ, vx — are then the pose)."""
        if isinstance(state, EgoState):
            return state
        arr = np.asarray(state, dtype=float).ravel()
        if arr.size == DETAILED_STATES:
            return cls(arr[:4].copy(), arr.copy())
        return cls(arr.copy())


@dataclass(frozen=True)
class Snapshot:
    """The world as the controller sees it now: other traffic and the stop-sign memory."""

    traffic: TrafficState
    memory: StopMemory | None = None

    @classmethod
    def of(cls, world_state: "WorldState") -> "Snapshot":
        """``world_state`` as a snapshot: traffic alone has no memory; None is an empty road."""
        if world_state is None:
            return cls(_empty_traffic())
        if isinstance(world_state, Snapshot):
            return world_state
        return cls(world_state)


WorldState = Union[TrafficState, Snapshot, None]
"""What a planner is told of the world now (see :class:`Snapshot`)."""


@dataclass(frozen=True, eq=False)
class PreviousPlan:
    """The MPC's last plan: made at ``t`` [s], ``states`` (N+1, 4), ``controls`` (N, 2) [δ rad,
    a m/s²] over its whole look-ahead, ``mode`` (choice per disjunction), ``periods`` (N,) its
    steps in periods (None: N steps of one). The next step linearises about it shifted by one
    period, seeds the mode search with it, and falls back to it."""

    t: float
    states: np.ndarray
    controls: np.ndarray
    mode: np.ndarray
    periods: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.periods is None:
            object.__setattr__(self, "periods", np.ones(len(self.controls), dtype=int))

    def spans(self, periods: int | tuple[int, ...] | np.ndarray) -> bool:
        """Whether it covers the look-ahead of ``periods`` (per step; a number H: H steps of one)."""
        want = np.ones(periods, dtype=int) if isinstance(periods, (int, np.integer)) else np.asarray(periods)
        return self.controls.shape[0] == len(want) and bool(np.array_equal(self.periods, want))

    def precedes(self, t: float, dt: float, periods: int | tuple[int, ...] | np.ndarray) -> bool:
        """Whether it was made one period ``dt`` [s] before ``t`` [s] over the same look-ahead."""
        return abs(t - self.t - dt) < 1e-6 and self.spans(periods)

    @classmethod
    def of(cls, t: float, res: PlanResult) -> "PreviousPlan":
        la = res.look_ahead
        if la is None:
            return cls(t, res.states, res.controls, res.mode)
        return cls(t, la.states, la.controls, res.mode, np.asarray(la.periods))


@runtime_checkable
class Planner(Protocol):
    """A high-level planner (see the module docstring)."""

    params: BicycleParams
    """The kinematic bicycle's parameters (``a_min`` brakes when a plan is unusable)."""
    label: str
    """The decision recorded when its first control is applied unchecked (no monitor)."""

    @property
    def history_depth(self) -> int:
        """Past samples [steps] of the rule signals the planner reads."""

    def solve(self, ego: EgoState | Sequence[float] | np.ndarray, t: float, world_state: WorldState = None,
              history: Mapping[str, np.ndarray] | None = None) -> PlanResult:
        """One planning step."""

    def reset(self) -> None:
        """Forget the previous plan."""


class _Diagnosed(Protocol):
    diagnostics: list[Diagnostic]


C = TypeVar("C", bound=_Diagnosed)


def planner_of_world(cls: Callable[..., C], world: World, settings: object, params: BicycleParams | None,
                     **kw: object) -> tuple[C | None, list[Diagnostic]]:
    """``cls(world, rulesets, settings, params=…, **kw)`` with the world's own rule files and, by
    default, the bicycle parameters of the world's ego; (None, diagnostics) when a rule file has
    an error or the constructor rejects its arguments (MIL512). Shared by the MPC and the NMPC."""
    sets, diags = load_rulesets(world)
    if any(d.is_error for d in diags):
        return None, diags
    if params is None:
        params = BicycleParams().with_overrides({k: v for k, v in world.ego.vehicle.items()
                                                 if k in BicycleParams.__dataclass_fields__})
    try:
        ctrl = cls(world, sets, settings, params=params, **kw)
    except ValueError as e:
        return None, diags + [MIL512(str(e), Span(world.name))]
    return ctrl, diags + ctrl.diagnostics


def stop_memory_of(world: World, memory: StopMemory | None, hist: Mapping[str, np.ndarray], dt: float
                   ) -> StopMemory | None:
    """``memory``, or when none was given the stop memory replayed from the history's ``s`` [m]
    and ``v`` [m/s] samples (None when the route has no stop line or the history lacks them)."""
    if memory is None and len(world.route_stops) and "s" in hist and "v" in hist:
        memory = StopMemory.fresh(world)
        for s, v in zip(hist["s"], hist["v"]):
            memory = update_stop_memory(memory, world, float(s), float(v), dt)
    return memory


def _empty_traffic() -> TrafficState:
    z = np.zeros(0)
    return TrafficState(0.0, z, z, z, z, np.zeros(0, int), z, z, np.zeros(0, bool), z, np.zeros(0, int))
