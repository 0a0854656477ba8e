"""The closed loop: both controller levels against the world, written to a run directory.

:func:`simulate_scenario` is what ``twolevel simulate`` calls. Each step of ``dt`` is five calls
of :class:`ClosedLoop`:

1. **sense** the current sample (route position, limits, stop lines, lights, vehicles within
   ``r_near``: :mod:`twolevel.world.sensing`);
2. **plan**: the high-level planner (:class:`~twolevel.control.planner.Planner`: the MILP MPC,
   or the NMPC baseline, :mod:`twolevel.control.registry`) from the ego's state, the traffic
   and stop-sign memory, and the recorded history of every signal;
3. **check**: the low level (:mod:`twolevel.control.low_level.controller`) forward-simulates the
   detailed model under the plan, monitors every rule and applies u*, a sampled control or full
   braking — each only when the safety layer verifies it, else the fail-safe verified earlier
   (:mod:`twolevel.control.low_level.guard`; ``safety=False`` leaves the paper's low level
   alone). With ``monitor=False`` (the paper's "without monitor") the plan's first control is
   applied directly (a → γ by the actuation map), unchecked and unverified;
4. **advance** the world: the ego's plant is the detailed four-wheel model
   (:mod:`twolevel.models.fourwheel`, compiled rollout with H = 1), the other participants
   step by their behaviours with the ego as a leader for IDM, lights cycle;
5. **record** the sample (state, control, decision, timings — the plant's too, so it comes
   after the advance — and signals), check collisions (:mod:`twolevel.sim.collisions`) and feed
   the online monitor, whose final robustness values fill the ``rob_<rule>`` columns
   (:mod:`twolevel.sim.robustness`).

Collisions (overlapping oriented boxes, checked against every vehicle, not only the sensed
ones) are recorded with time, place, the other vehicle and who is responsible
(:mod:`twolevel.sim.collisions`), never hidden.

**The safety layer.** Before the first step the initial state is checked
(:func:`~twolevel.safety.verify.verify_initial_state`); a start without a fail-safe is reported
(SIM616, and ``run.json``'s ``safety.initial``) and the run goes on: until a control verifies
the low level brakes, and those steps are recorded as ``unverified``. Every step records the
outcome (``verification``: verified / failsafe / unverified / off), the fail-safe in force
(``failsafe``), why the rules' choice did not verify (``refuted``) and, every
:data:`TTR_EVERY` steps (``ttr_every``), the **time to react** ``ttr_s`` [s]
(:func:`~twolevel.safety.verify.time_to_react` of the intended plan held on to
:data:`TTR_HORIZON`: how long the car could still follow it before a fail-safe becomes
necessary; −dt: not even now; ``TTR_HORIZON``: at least that long; empty between). It costs up
to a handful of verifications, so it is computed every few steps and not counted in the control
step's time; it is computed in every run, the layer on or off.

**The trace.** One row per step: :data:`~twolevel.sim.trace.BASE_COLUMNS`, the signal columns
the rules read (a, s, e, d_stop, light_red, d_light, d_lead, v_lead; v, v_max, min_gap and
n_near are base columns), a few controller columns (``candidates``; ``ll_violated``: the rules u*
broke on the detailed prediction, i.e. why the low level intervened; ``hl_status``, ``hl_qps``,
``t_plant_ms``; the safety layer's ``verification``, ``failsafe``, ``refuted``, ``ttr_s``,
``t_verify_ms``; ``t_step_cpu_ms``: the control step's CPU time), the criticality columns and,
when the rules quantify over participants, every participant's signals
(:mod:`twolevel.sim.extra_columns`), then ``rob_<rule>`` per rule: the robustness at that step on
the *executed* trajectory, by the online monitor — exactly what ``twolevel monitor rules.stl trace.csv``
computes from the same file. A rule whose window looks ahead L steps is final L steps later, so
rows are written with that delay; when the run ends, is interrupted (Ctrl-C) or crashes, the
remaining rows are completed with the windows truncated at the end (RTAMT's semantics) and
written before ``run.json`` records the status. Only a killed process loses the last L rows.

**The run directory** is held (:class:`~twolevel.sim.trace.RunDirectory`: locked, outputs
checked, ``run.json`` written) before the run's first action, so a crash at step 0 or an
interruption while compiled functions are built is recorded. Interruptions
(:mod:`twolevel.interruption`) stop the run at a checkpoint: between start-up phases and after
each step; while the compiled functions are built (a C compiler in a subprocess, no safe point
inside) at once; the closing writes are shielded.

**Rules no plan satisfies.** Each episode of steps in which the high level was infeasible is
explained once (:mod:`twolevel.sim.unsatisfiable`): SIM618 and the summary's ``unsatisfiable``.

**The goal.** On a route that stops at its goal, the run ends at the first step at which the ego
stands still (speed ≤ the scenario's stop_speed) within :data:`GOAL_ZONE` of the goal or past it;
the summary (and ``run.json``) records that time as ``goal_reached_t`` [s] (None otherwise). On a
route that does not stop there (``stop_at_goal: false``) the ego drives on at its desired speed
(the reference runs straight on past the route's end), ``goal_reached_t`` is the first step
within :data:`GOAL_ZONE` of the goal on the route's lane, and the run ends when the ego passes
the route's end.

**Determinism.** Everything but the timing columns (:data:`TIMING_COLUMNS`) is a function of
the scenario and the seed, provided the high level is (its time limit can make a plan depend on
the machine's speed; the default mode search is deterministic in practice).
"""

from __future__ import annotations

import contextlib
import gc
import math
import time
import traceback
from collections import deque
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from twolevel import interruption
from twolevel.control.high_level.conflicts import conflicting_rules
from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.low_level.controller import LowLevelController
from twolevel.control.low_level.guard import OFF, Check, Outcome
from twolevel.control.low_level.settings import LowLevelSettings
from twolevel.control.low_level.rules import RuleCheck, rule_checks
from twolevel.control.planner import EgoState, Planner, PlanResult, PlanStatus, Snapshot
from twolevel.control.registry import CONTROLLERS, planner_named
from twolevel.diagnostics import Diagnostic, Span
from twolevel.files import DirectoryBusy
from twolevel.models import fourwheel as fw
from twolevel.models.actuation import gamma_from_accel
from twolevel.models.params import VehicleParams
from twolevel.models.rollout import rollout
from twolevel.safety.verify import Verdict, context, time_to_react
from twolevel.sim.codes import SIM610, SIM611, SIM612, SIM613, SIM614, SIM615, SIM616, SIM617, SIM618, SIM632
from twolevel.sim.collisions import CollisionLog
from twolevel.sim.extra_columns import ExtraColumns
from twolevel.sim.frames import FrameWriter
from twolevel.sim.history import History
from twolevel.sim.provenance import run_metadata
from twolevel.sim.robustness import RuleColumns
from twolevel.sim.summary import Collision, RunSummary, StepDecision, StepInfo, summarise
from twolevel.sim.trace import BASE_COLUMNS, RunDirectory, RunStatus, TraceWriter
from twolevel.sim.traffic_engine import BuiltinTraffic, TrafficEngine, TrafficFailure
from twolevel.sim.unsatisfiable import UnsatisfiableLog
from twolevel.stl.typecheck import RuleSet
from twolevel.world import traffic as tr
from twolevel.world.loader import Scenario, load_scenario
from twolevel.world.provided import SIGNALS
from twolevel.world.sensing import Memory, Others, others_now, sense
from twolevel.world.world import World, build_world, load_rulesets

__all__ = ["simulate_scenario", "ClosedLoop", "StepInfo", "RunSummary", "Collision", "TIMING_COLUMNS",
           "SIGNAL_COLUMNS"]

GOAL_ZONE = 1.0
"""[m] How far before the goal a standstill counts as arrived."""
TIMING_COLUMNS = ("t_high_ms", "t_low_ms", "t_step_ms", "t_plant_ms", "t_verify_ms", "t_step_cpu_ms")
"""Timing columns, wall clock and the step's CPU time (excluded from determinism comparisons)."""
SIGNAL_COLUMNS = tuple(name for name in SIGNALS if name not in BASE_COLUMNS)
"""Signal columns beyond the base ones, named as the rules read them (a, s, e, d_stop, light_red,
d_light, d_lead, v_lead)."""
EXTRA_COLUMNS = ("candidates", "ll_violated", "hl_status", "hl_qps", "t_plant_ms", "verification", "failsafe",
                 "refuted", "ttr_s", "t_verify_ms", "t_step_cpu_ms")
TTR_EVERY = 5
"""The time to react is computed every this many steps (see the module docstring)."""
TTR_HORIZON = 3.0
"""[s] The intended plan, its last command held, is followed at most this long for the time to react."""
_LIGHT_NAMES = {0: "green", 1: "yellow", 2: "red"}


def simulate_scenario(
    scenario_path: str,
    out_dir: str,
    *,
    monitor: bool = True,
    safety: bool = True,
    ttr_every: int = TTR_EVERY,
    controller: str = "twolevel",
    seed: int | None = None,
    duration: float | None = None,
    progress: Callable[[StepInfo], None] | None = None,
    frames: bool = True,
) -> tuple[RunSummary | None, list[Diagnostic]]:
    """Run ``scenario_path`` in closed loop and write the run directory ``out_dir``.

    ``monitor=False`` applies the plan's controls directly (the paper's "without monitor");
    ``safety=False`` keeps the paper's low level but without the safety layer (no verification).
    ``ttr_every``: the time to react every that many steps (0: never; many short runs save a
    third of their time without it).
    ``controller``: the high level, one of :data:`~twolevel.control.registry.CONTROLLERS`.
    ``seed`` / ``duration`` [s] override the scenario's ``run`` settings. ``progress`` is called
    after every step with a :class:`StepInfo`; if it raises ``KeyboardInterrupt`` the run stops
    as on Ctrl-C. ``frames``: also write ``frames.jsonl`` for the animation.

    Returns the :class:`RunSummary` (``status`` complete / interrupted / crashed / aborted; None
    when the scenario or its rules could not be loaded) and every diagnostic. Interruption,
    internal errors and SUMO failing mid-run are diagnostics (SIM612, SIM613, SIM632), never
    tracebacks; the run directory keeps every
    completed step and ``run.json`` says how it ended.
    """
    where = Span.whole_file(scenario_path)
    if controller not in CONTROLLERS:
        return None, [SIM610(f"unknown controller '{controller}'", where,
                             hint=f"choose one of: {', '.join(CONTROLLERS)}")]
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        return None, [SIM611(f"the duration must be a positive number of seconds, got {duration}", where)]
    if seed is not None and seed < 0:
        return None, [SIM611(f"the seed must be ≥ 0, got {seed}", where)]
    diags: list[Diagnostic] = []
    try:  # start-up: an interruption here is reported (SIM612); nothing is written yet
        interruption.checkpoint()
        scn, diags = load_scenario(scenario_path)
        if scn is None or any(d.is_error for d in diags):
            return None, diags
        run = scn.spec.run.model_copy(update={k: v for k, v in (("seed", seed), ("duration", duration)) if v is not None})
        dt = scn.spec.controller.dt
        if int(round(run.duration / dt)) < 1:
            return None, diags + [SIM611(f"the duration {run.duration:g} s is shorter than one control step "
                                         f"(dt = {dt:g} s): nothing would run", where,
                                         hint=f"give --duration {dt:g} or more")]
        scn = replace(scn, spec=scn.spec.model_copy(update={"run": run}))
        interruption.checkpoint()
        world = build_world(scn)
        interruption.checkpoint()
        loop, more = ClosedLoop.create(world, scn, monitor=monitor, controller=controller, safety=safety,
                                       ttr_every=ttr_every)
        diags += more
        if loop is None:
            return None, diags
        interruption.checkpoint()
    except KeyboardInterrupt as exc:
        return None, diags + [SIM612(f"{interruption.describe(getattr(exc, 'signum', None))} during start-up, before "
                                     f"the run directory was written", where, hint=f"nothing was written to {out_dir}")]
    return loop.run(out_dir, progress, frames, diags)


@dataclass(frozen=True, eq=False)
class LoopState:
    """What carries from one step to the next: the ego's detailed state ``x`` (12,), the other
    ``traffic``, the sensing ``memory``, where the ego was on the route (``s_hint`` [m]) and the
    control it applied (``accel`` [m/s²], ``delta`` [rad])."""

    x: np.ndarray
    traffic: tr.TrafficState
    memory: Memory
    s_hint: float
    accel: float = 0.0
    delta: float = 0.0


@dataclass(frozen=True, eq=False)
class Sensed:
    """Step ``k`` at time ``t`` [s] as the ego senses it: its state, route position ``s0`` [m],
    the traffic, the vehicles within ``r_near`` (``others``), every signal now (``now``), the
    sensing memory before and after this sample, and the recorded past of every signal."""

    k: int
    t: float
    ego: EgoState
    s0: float
    traffic: tr.TrafficState
    others: Others
    now: dict[str, float]
    memory: Memory
    memory_after: Memory
    past: dict[str, np.ndarray]

    @property
    def v(self) -> float:
        """Signed speed [m/s]."""
        return float(self.ego.pose[3])


@dataclass(frozen=True, eq=False)
class Applied:
    """What the check decided: ``control`` [δ rad, γ] applied now, the ``accel`` [m/s²] it
    commands, the trace's ``decision``, the ``candidates`` sampled, the rules u* violated on
    the detailed prediction (``violated``, space-separated), the safety layer's record
    (``safety``; its verification time ``verify_ms``) and the plan as actuator commands
    (``intended`` (H, 2) [δ rad, γ])."""

    control: np.ndarray
    accel: float
    decision: StepDecision
    candidates: int
    violated: str
    safety: Check = OFF
    verify_ms: float = 0.0
    intended: np.ndarray | None = None


@dataclass(frozen=True)
class StepTimes:
    """Wall times of one step [ms]: the high level, the low level, both with sensing, the plant;
    and the CPU time of the process over both levels with sensing (``cpu``, what the step costs
    when other jobs share the cores)."""

    high: float
    low: float
    step: float
    plant: float
    cpu: float = math.nan


@dataclass(frozen=True, eq=False)
class Recorders:
    """Where a run's steps go: the trace, the frames for the animation (optional), and the
    history of every signal the controllers read."""

    trace: TraceWriter
    frames: FrameWriter | None
    history: History


@dataclass
class LoopStats:
    """Per-step figures the run summary is computed from."""

    step_ms: list[float] = field(default_factory=list)
    cpu_ms: list[float] = field(default_factory=list)
    """The control step's CPU time [ms]."""
    high_ms: list[float] = field(default_factory=list)
    low_ms: list[float] = field(default_factory=list)
    tracking: list[float] = field(default_factory=list)
    """|lateral offset| from the route [m]."""
    over_limit: list[float] = field(default_factory=list)
    """Speed minus the limit in force [m/s]."""
    min_dist: list[float] = field(default_factory=list)
    """Centre distance to the nearest vehicle [m]."""
    min_gap: list[float] = field(default_factory=list)
    """Box separation to the nearest vehicle [m]."""
    decisions: list[StepDecision] = field(default_factory=list)
    speeds: list[float] = field(default_factory=list)
    """Signed speed [m/s]."""
    outcomes: list[str] = field(default_factory=list)
    """The safety layer's outcome."""
    ttr: list[float] = field(default_factory=list)
    """Time to react [s] (NaN where not computed)."""

    def __len__(self) -> int:
        return len(self.step_ms)

    def add(self, times: StepTimes, tracking: float, over_limit: float, min_dist: float, min_gap: float,
            decision: StepDecision, speed: float, outcome: str, ttr: float) -> None:
        self.step_ms.append(times.step)
        self.cpu_ms.append(times.cpu)
        self.high_ms.append(times.high)
        self.low_ms.append(times.low)
        self.tracking.append(tracking)
        self.over_limit.append(over_limit)
        self.min_dist.append(min_dist)
        self.min_gap.append(min_gap)
        self.decisions.append(decision)
        self.speeds.append(speed)
        self.outcomes.append(outcome)
        self.ttr.append(ttr)


def _traffic_engine(world: World, scn: Scenario) -> tuple[TrafficEngine | None, list[Diagnostic]]:
    """The engine of the scenario's ``traffic`` (the built-in one when it names none), started;
    None and the diagnostics when it cannot start."""
    spec = scn.spec.traffic
    if spec is None:
        return BuiltinTraffic(world), []
    from twolevel.sim.cosim import SumoTraffic  # noqa: PLC0415 - libsumo only when asked for

    return SumoTraffic.launch(world, spec, scn.path)


class ClosedLoop:
    """One closed-loop run of a scenario: the world, the planner and the low level, and the
    records kept between steps."""

    def __init__(self, world: World, scn: Scenario, planner: Planner, rulesets: list[RuleSet], monitor: bool,
                 controller: str, safety: bool = True, ttr_every: int = TTR_EVERY,
                 traffic: TrafficEngine | None = None) -> None:
        self.world, self.scn, self.planner = world, scn, planner
        self.traffic: TrafficEngine = traffic if traffic is not None else BuiltinTraffic(world)
        self.monitor, self.controller = monitor, controller
        self.label = StepDecision(planner.label)  # the decision of its unchecked steps (no monitor)
        self.safety = monitor and safety
        self.ttr_every = ttr_every
        self.rulesets = rulesets
        self.rules: list[RuleCheck]
        self.rules, self.consts = rule_checks(rulesets, world.settings.dt)
        fields = VehicleParams.__dataclass_fields__
        params = VehicleParams().with_overrides({k: v for k, v in world.ego.vehicle.items() if k in fields})
        self.params = replace(params, length=world.ego.length, width=world.ego.width)
        self.ctx = context(world, self.params)
        self.low = LowLevelController(world, self.rules, params=self.params, consts=self.consts, safety=self.ctx,
                                      settings=LowLevelSettings.of(world.settings, safety=self.safety))
        self.initial: Verdict | None = None
        self.stats = LoopStats()
        self.collisions = CollisionLog(self.ctx)
        self.extra = ExtraColumns(world)
        self.columns = RuleColumns(self.rules, self.consts, world.settings.dt, SIGNALS + self.extra.signals,
                                   participants=self.extra.ids)
        self.goal_reached_t: float | None = None
        self.t_wall0 = time.perf_counter()
        self.unsatisfiable = UnsatisfiableLog()
        self._carry: object = None  # the MILP planner's carry before the step's solve (to explain it)

    @classmethod
    def create(cls, world: World, scn: Scenario, *, monitor: bool, controller: str, safety: bool = True,
               ttr_every: int = TTR_EVERY) -> tuple["ClosedLoop | None", list[Diagnostic]]:
        """The loop of ``world`` with the planner named ``controller`` (``safety``: the low level's
        safety layer); None when the scenario's rules or the planner's settings are unusable (the
        diagnostics say why)."""
        sets, diags = load_rulesets(world)
        if any(d.is_error for d in diags):
            return None, diags
        planner, d = planner_named(controller, world)
        diags += d
        if planner is None:
            return None, diags
        traffic, d = _traffic_engine(world, scn)
        diags += d
        if traffic is None:
            return None, diags
        return cls(world, scn, planner, sets, monitor, controller, safety, ttr_every, traffic), diags

    # ------------------------------------------------------------------------------ the run
    def run(self, out_dir: str, progress: Callable[[StepInfo], None] | None, frames: bool,
            diags: list[Diagnostic]) -> tuple[RunSummary | None, list[Diagnostic]]:
        """Every step into ``out_dir``; the summary and the diagnostics (see :func:`simulate_scenario`).
        The directory is held (:class:`~twolevel.sim.trace.RunDirectory`) before anything else is
        done, so whatever happens next — a crash at step 0, an interruption while compiled
        functions are built — ``run.json`` records it."""
        where = Span.whole_file(self.scn.path)
        try:
            directory = RunDirectory(out_dir, {"scenario": str(self.scn.path)})
        except DirectoryBusy as exc:
            held = f"process {exc.holder}" if exc.holder else "another run"
            return None, diags + [SIM617(f"the run directory {out_dir} is being written by {held}: this run is "
                                         "refused", where, hint="choose another --out, or wait for that run to end")]
        except OSError as exc:
            return None, diags + [SIM615(f"cannot write the run directory '{out_dir}': {exc}", where,
                                         hint="choose another --out, or remove what is in the way")]
        with directory:
            return self._run_in(directory, progress, frames, diags, where)

    def _run_in(self, directory: RunDirectory, progress: Callable[[StepInfo], None] | None, frames: bool,
                diags: list[Diagnostic], where: Span) -> tuple[RunSummary, list[Diagnostic]]:
        out_dir = str(directory.path)
        rule_names = [r.name for r in self.rules]
        columns = (list(BASE_COLUMNS) + list(SIGNAL_COLUMNS) + list(EXTRA_COLUMNS) + list(self.extra.columns)
                   + [f"rob_{n}" for n in rule_names])
        status, error, unwritable = RunStatus.COMPLETE, "", False
        failure: TrafficFailure | None = None
        self.t_wall0 = time.perf_counter()
        writer: TraceWriter | None = None
        fw_writer: FrameWriter | None = None
        try:
            directory.meta.update(run_metadata(self.world, self.scn, monitor=self.monitor, controller=self.controller,
                                               timing_columns=TIMING_COLUMNS, safety=self.safety))
            writer = TraceWriter(directory, columns)
            if frames:
                fw_writer = FrameWriter(out_dir, self.world)
            self._steps(progress, writer, fw_writer)
        except KeyboardInterrupt as exc:
            status, error = RunStatus.INTERRUPTED, interruption.describe(getattr(exc, "signum", None))
        except OSError as exc:  # the disk is full, or the run directory went away
            status, error, unwritable = RunStatus.CRASHED, f"{type(exc).__name__}: {exc}", True
        except TrafficFailure as exc:  # SUMO rejected its own files: the input's fault, not twolevel's
            status, error, failure = RunStatus.ABORTED, f"SUMO failed at t = {exc.t:g} s: {exc.message}", exc
        except Exception as exc:  # an internal error: keep the run, say what happened
            status, error = RunStatus.CRASHED, f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"
        with interruption.shielded():  # what was completed is written whatever arrives now
            try:
                self.traffic.close()  # first: SUMO is closed whatever happens next
            except Exception as exc:  # libsumo's own failure: the run's files are still completed
                if status is not RunStatus.ABORTED:  # SUMO already failed: closing it may fail too
                    status, error = RunStatus.CRASHED, error or f"{type(exc).__name__}: {exc}"
            summary, error, unwritable = self._finish(directory, writer, fw_writer, status, error, unwritable)
        if self.initial is not None and not self.initial.verified:
            why = "; ".join(str(r) for r in self.initial.refutations) or "no fail-safe"
            diags.append(SIM616(f"the initial state has no verified fail-safe ({why})", where,
                                hint="the run went on, braking unverified until a control verified; move the ego or "
                                     "the others, or lower the initial speed"))
        if unwritable:
            diags.append(SIM615(f"cannot write the run directory {out_dir}: {error}", where,
                                hint="free disk space or choose another --out; the steps written so far are kept"))
        elif summary.status is RunStatus.INTERRUPTED:
            diags.append(SIM612(f"{error} after {summary.steps} steps ({summary.duration:g} s)", where,
                                hint=f"the completed steps are in {out_dir}"))
        elif summary.status is RunStatus.ABORTED and failure is not None:
            diags.append(SIM632(f"the run was aborted after {summary.steps} steps ({summary.duration:g} s): {error}",
                                where, hint=f"{failure.hint}; the completed steps are in {out_dir}"))
        elif summary.status is RunStatus.CRASHED:
            diags.append(SIM613(f"the run stopped after {summary.steps} steps: {error.splitlines()[0]}", where,
                                hint=f"the completed steps are in {out_dir}; run.json has the traceback"))
        for c in summary.collisions:
            fault = "the ego's fault" if c.at_fault else "not the ego's fault"
            diags.append(SIM614(f"collision with '{c.other}' at t = {c.t:.1f} s, ({c.x:.1f}, {c.y:.1f}) m, "
                                f"overlap {-c.gap:.2f} m: {fault} ({c.reason})", where))
        diags += self.infeasibility_diagnostics(where)
        return summary, diags

    def _finish(self, directory: RunDirectory, writer: TraceWriter | None, fw_writer: FrameWriter | None,
                status: RunStatus, error: str, unwritable: bool) -> tuple[RunSummary, str, bool]:
        """Complete the rows the online monitor still holds, close the trace and the frames and
        record how the run ended in ``run.json`` (with the summary; a crash's traceback); a
        failure to write turns the status into ``crashed`` (the directory is unwritable). The
        run's summary (its final status), the error and whether the directory is unwritable."""
        def failed(exc: OSError) -> None:
            nonlocal status, error, unwritable
            status, unwritable = RunStatus.CRASHED, True
            error = error or f"{type(exc).__name__}: {exc}"

        if writer is not None and not unwritable:
            try:
                self.columns.finish(writer)
            except OSError as exc:
                failed(exc)
            except Exception as exc:  # an interruption left the monitor mid-step: its last rows are lost
                directory.meta["unfinished"] = f"the last rows' robustness could not be completed: {exc!r}"
        if fw_writer is not None:
            try:
                fw_writer.close()
            except OSError as exc:
                failed(exc)
        meta = directory.meta
        if status is not RunStatus.COMPLETE:
            meta["error"] = error.splitlines()[0] if error else "no reason recorded"
            if "\n" in error:
                meta["traceback"] = error
        summary = self._summary(str(directory.path), status)
        meta["summary"] = summary.to_json()
        try:
            if writer is not None:
                writer.close(status, meta["summary"])
            else:
                directory.record(status)
        except OSError as exc:
            failed(exc)
        return replace(summary, status=status), error, unwritable

    def _summary(self, out_dir: str, status: RunStatus) -> RunSummary:
        st = self.stats
        n = len(st)
        rob = {k: np.asarray(v[:n]) for k, v in self.columns.robustness.items()}
        self.collisions.close(math.inf)
        return summarise(
            scenario=self.world.name, run_dir=str(out_dir), status=status, monitor=self.monitor,
            controller=self.controller, seed=self.world.settings.seed, dt=self.world.settings.dt,
            wall_time_s=time.perf_counter() - self.t_wall0, step_ms=st.step_ms, high_ms=st.high_ms,
            low_ms=st.low_ms, tracking=st.tracking, over_limit=st.over_limit, min_dist=st.min_dist,
            min_gap=st.min_gap, decisions=st.decisions,
            collisions=sorted(self.collisions.collisions, key=lambda c: c.t), robustness=rob,
            closest=self.collisions.closest(5), goal_reached_t=self.goal_reached_t, speeds=st.speeds,
            verification=st.outcomes, ttr=st.ttr, safety=self.safety, cpu_ms=st.cpu_ms,
            safe_start=None if self.initial is None else self.initial.verified,
            unsatisfiable=self.unsatisfiable.all(),
        )

    def _steps(self, progress: Callable[[StepInfo], None] | None, writer: TraceWriter,
               frames: FrameWriter | None) -> None:
        w, p = self.world, self.params
        s = w.settings
        dt = s.dt
        steps = int(round(s.duration / dt))
        x = fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, w.ego.v, p)
        traffic0 = self.traffic.start(w.traffic0, tr.EgoBox(w.ego.x, w.ego.y, w.ego.psi, w.ego.v, w.ego.length,
                                                            w.ego.width, w.route.lanes))
        state = LoopState(x, traffic0, Memory.fresh(w), float(w.route.local_coordinates(x[None, :2])[0][0]))
        keep = max([r.past for r in self.rules] + [self.planner.history_depth])
        out = Recorders(writer, frames, History(SIGNALS + self.extra.signals, keep))
        with interruption.prompt():  # minutes with a slow compiler, and nowhere to stop safely inside
            self.low.warm_up(x)
            rollout(x, np.zeros((1, 1, 2)), dt, p)  # compile the plant step before timing anything
        interruption.checkpoint()
        if self.safety:
            self.initial = self.low.start(x, state.traffic, 0.0, state.s_hint)
            writer.meta["safety"] = {"initial": _verdict_json(self.initial)}
            interruption.checkpoint()
        recent: deque[float] = deque(maxlen=20)
        self.goal_reached_t = None
        stops_at_goal = bool(w.route.v_des.size and w.route.v_des[-1] <= 1e-9)
        goal_s = float(w.route.s[-1])
        with _heap_frozen():  # a full collection over the setup's objects cost a step 40-70 ms
            for k in range(steps):
                c0, cpu0 = time.perf_counter(), time.process_time()
                sensed = self.sense(k, state, out.history)
                c1 = time.perf_counter()
                plan, u_star = self.plan(sensed)
                c2 = time.perf_counter()
                applied = self.check(sensed, plan, u_star)
                c3, cpu3 = time.perf_counter(), time.process_time()
                ttr = self.criticality(sensed, applied)
                state, plant_ms = self.advance(sensed, applied)
                times = StepTimes((c2 - c1) * 1e3, (c3 - c2) * 1e3, (c3 - c0) * 1e3, plant_ms, (cpu3 - cpu0) * 1e3)
                self.record(sensed, plan, applied, times, out, ttr)
                self.unsatisfiable.observe(sensed.t, not plan.ok and PlanStatus.INFEASIBLE in (plan.cause, plan.status),
                                           applied.decision, sensed.v, lambda: self.conflicts(sensed))
                recent.append(times.step)
                # the run ends when the ego stands still at the goal (GOAL_ZONE before it or past it),
                # or, on a route that does not stop there, when it drives past the route's end
                at_goal = sensed.s0 >= goal_s - GOAL_ZONE
                if stops_at_goal and at_goal and abs(sensed.v) <= s.stop_speed:
                    self.goal_reached_t = round(sensed.t, 9)
                elif not stops_at_goal and self.goal_reached_t is None and at_goal and \
                        abs(sensed.now["e"]) <= 0.5 * float(w.route.width_at(goal_s)):
                    self.goal_reached_t = round(sensed.t, 9)
                done = stops_at_goal and self.goal_reached_t is not None or not stops_at_goal and sensed.s0 >= goal_s
                if progress is not None:
                    wall = time.perf_counter() - self.t_wall0
                    progress(StepInfo(k + 1, steps, round((k + 1) * dt, 9), s.duration,
                                      1000.0 * len(recent) / max(sum(recent), 1e-9), times.step,
                                      int(sensed.now["n_near"]), applied.decision,
                                      (k + 1) * dt / wall if wall > 0 else math.inf))
                if done:
                    break
                interruption.checkpoint()  # a signal received during the step stops the run here

    # ------------------------------------------------------------------------------ one step
    def sense(self, k: int, state: LoopState, history: History) -> Sensed:
        """Step ``k``'s sample: the ego's pose and route position, the vehicles within r_near,
        every signal now (:func:`twolevel.world.sensing.sense`) and the recorded past."""
        w = self.world
        dt = w.settings.dt
        t = k * dt
        x = state.x
        X, Y, psi = float(x[0]), float(x[1]), float(x[2])
        v = float(math.copysign(math.hypot(x[3], x[4]), x[3]))
        s_arr, _ = w.route.project_near(np.array([[X, Y]]), np.array([state.s_hint]), 15.0 + abs(v) * dt)
        s0 = float(s_arr[0])
        others = others_now(w, state.traffic, X, Y, s0)
        one = lambda val: np.array([[val]])  # noqa: E731
        now = {n: float(a[0, 0]) for n, a in sense(w, t, dt, state.memory, others, one(X), one(Y), one(psi), one(v),
                                                   one(state.accel), one(state.delta), s_center=np.array([s0]),
                                                   half_window=15.0).items()}
        return Sensed(k, t, EgoState(np.array([X, Y, psi, v]), x), s0, state.traffic, others, now, state.memory,
                      state.memory.after(w, t, s0, v), history.view())

    def plan(self, sensed: Sensed) -> tuple[PlanResult, np.ndarray]:
        """The planner's answer and the controls u* (H, 2) [δ rad, a m/s²] to check: the plan's,
        or full braking when they are unusable."""
        H = self.world.settings.H
        self._carry = getattr(self.planner, "carry", None)
        plan = self.planner.solve(sensed.ego, sensed.t, Snapshot(sensed.traffic, sensed.memory_after.stops),
                                  sensed.past)
        u_star = np.asarray(plan.controls, dtype=float)
        if u_star.shape != (H, 2) or not np.all(np.isfinite(u_star)):
            u_star = np.tile([0.0, self.planner.params.a_min], (H, 1))
        return plan, u_star

    def check(self, sensed: Sensed, plan: PlanResult, u_star: np.ndarray) -> Applied:
        """The control to apply: the low level's decision, or without the monitor u*'s first."""
        x = sensed.ego.detailed
        assert x is not None
        if self.monitor:
            dec = self.low.decide(x, u_star, sensed.t, sensed.traffic, sensed.memory, sensed.s0, sensed.past,
                                  target=plan.states, step=sensed.k, now=sensed.others)
            control, accel, decision, tried = dec.control, dec.accel, StepDecision(dec.decision), dec.candidates
            why = " ".join(dec.violated)
            safety, verify_ms, intended = dec.safety, dec.timings_ms.get("verify", 0.0), dec.intended
        else:
            why = ""
            gamma = gamma_from_accel(u_star[:, 1], max(x[3], 0.0), self.params)
            intended = np.stack([u_star[:, 0], gamma], axis=1)
            control = intended[0].copy()
            accel, decision, tried = float(u_star[0, 1]), self.label, 0
            safety, verify_ms = OFF, 0.0
        if decision is StepDecision.MPC and plan.status is PlanStatus.FALLBACK:
            decision = StepDecision.FALLBACK
        return Applied(control, float(accel), decision, tried, why, safety, verify_ms, intended)

    def conflicts(self, sensed: Sensed) -> tuple[str, ...] | None:
        """The rules that made this step's planning problem infeasible (see
        :mod:`twolevel.sim.unsatisfiable`); None when the planner cannot say."""
        if not isinstance(self.planner, HighLevelController) or self._carry is None:
            return None
        return conflicting_rules(self.planner, sensed.ego, sensed.t, Snapshot(sensed.traffic, sensed.memory_after.stops),
                                 sensed.past, self._carry)

    def infeasibility_diagnostics(self, where: Span, most: int = 10) -> list[Diagnostic]:
        """One SIM618 per episode in which no plan satisfied every rule (the first ``most``)."""
        eps = self.unsatisfiable.all()
        out = [SIM618(ep.describe(), where, hint="the rules named cannot all hold there: change the scenario or the "
                                                 "rules (twolevel plan --trace RUN_DIR/trace.csv --at T re-solves a step)")
               for ep in eps[:most]]
        if len(eps) > most:
            out.append(SIM618(f"... and {len(eps) - most} more such episodes (run.json lists them all)", where))
        return out

    def criticality(self, sensed: Sensed, applied: Applied) -> float:
        """The time to react [s] every ``ttr_every`` steps (NaN in between; see the module
        docstring): how long the intended plan, its last command held to :data:`TTR_HORIZON`,
        could still be followed with a verified fail-safe after it."""
        if self.ttr_every <= 0 or sensed.k % self.ttr_every or applied.intended is None:
            return math.nan
        dt = self.world.settings.dt
        first = applied.safety.plan_first
        if first is False and applied.safety.outcome is Outcome.FAILSAFE:  # u*_0 did not verify, a fail-safe did
            return 0.0
        plan = np.asarray(applied.intended, dtype=float)
        n = max(len(plan), int(round(TTR_HORIZON / dt)))
        plan = np.concatenate([plan, np.repeat(plan[-1:], n - len(plan), axis=0)])
        x = sensed.ego.detailed
        assert x is not None
        known = 1 if first else -1  # its first step verified: one step is followable
        return round(time_to_react(self.ctx, x, plan, sensed.traffic, sensed.t, sensed.s0, known).seconds, 9)

    def advance(self, sensed: Sensed, applied: Applied) -> tuple[LoopState, float]:
        """The world one period later (the ego's plant, the traffic, the sensing memory), and the
        plant's and traffic's wall time [ms]."""
        w = self.world
        s = w.settings
        x = sensed.ego.detailed
        assert x is not None
        X, Y, psi, v = (float(c) for c in sensed.ego.pose)
        p0 = time.perf_counter()
        x_next = rollout(x, applied.control[None, None, :], s.dt, self.params).states[0, 1]
        box = lambda x, y, psi, v: tr.EgoBox(x, y, psi, v, w.ego.length, w.ego.width, w.route.lanes)  # noqa: E731
        after = box(float(x_next[0]), float(x_next[1]), float(x_next[2]),
                    float(math.copysign(math.hypot(x_next[3], x_next[4]), x_next[3])))
        traffic = self.traffic.step(sensed.traffic, s.dt, box(X, Y, psi, v), after)
        plant_ms = (time.perf_counter() - p0) * 1e3
        return LoopState(x_next, traffic, sensed.memory_after, sensed.s0, applied.accel,
                         float(applied.control[0])), plant_ms

    def record(self, sensed: Sensed, plan: PlanResult, applied: Applied, times: StepTimes, out: Recorders,
               ttr: float = math.nan) -> None:
        """The step's trace row, history sample, statistics, collisions and frame (``ttr``: the
        time to react [s], NaN when not computed this step)."""
        now = dict(sensed.now)
        now["a"], now["delta"] = applied.accel, float(applied.control[0])
        X, Y, psi, v = (float(c) for c in sensed.ego.pose)
        extra = self.extra.record(now, (X, Y, psi, v), sensed.others)
        out.history.append(now)
        t = sensed.t
        min_dist = self.collisions.observe(t, X, Y, psi, v, sensed.traffic)
        row = {"t": round(t, 9), "x": X, "y": Y, "psi": psi, "v": v, "delta": float(applied.control[0]),
               "gamma": float(applied.control[1]), "decision": applied.decision, "t_high_ms": times.high,
               "t_low_ms": times.low, "t_step_ms": times.step, "n_near": now["n_near"], "min_dist": min_dist,
               "min_gap": now["min_gap"], "tracking_error": abs(now["e"]), "v_max": now["v_max"],
               "light_state": self._light_state(t, now), "candidates": applied.candidates,
               "ll_violated": applied.violated, "hl_status": plan.status.value, "hl_qps": plan.qps,
               "verification": applied.safety.outcome.value, "failsafe": applied.safety.failsafe,
               "refuted": applied.safety.refuted, "ttr_s": ttr, "t_verify_ms": applied.verify_ms,
               "t_step_cpu_ms": times.cpu}
        row.update({c: now[c] for c in SIGNAL_COLUMNS})
        row.update(extra)
        self.stats.add(times, abs(now["e"]), v - now["v_max"], min_dist, now["min_gap"], applied.decision, v,
                       applied.safety.outcome.value, ttr)
        if out.frames is not None:
            out.frames.write(t, (X, Y, psi), np.asarray(plan.states), sensed.traffic)
        row["t_plant_ms"] = times.plant
        self.columns.push(row, now, out.trace)

    def _light_state(self, t: float, now: dict[str, float]) -> str:
        w = self.world
        if not math.isfinite(now["d_light"]) or len(w.route_lights) == 0:
            return "none"
        j = int(np.argmin(np.abs(w.route_lights - now["s"] - now["d_light"])))
        return _LIGHT_NAMES.get(int(w.lights.state_at(t)[w.route_light_index[j]]), "none")


@contextlib.contextmanager
def _heap_frozen() -> Iterator[None]:
    """The objects alive now (the world, the compiled models, the planners' setup: most of the
    heap) kept out of the garbage collector's collections while the steps run, and given back to
    it after. A full collection traversing them took 40-70 ms of the step it fell in (CPU), one
    with them frozen 8-13 ms; nothing else changes (the same objects are freed, later)."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _verdict_json(v: Verdict) -> dict[str, object]:
    """A verdict for ``run.json``: verified, the fail-safe kept, each refutation."""
    return {"verified": v.verified, "failsafe": v.failsafe.name if v.failsafe is not None else None,
            "refutations": [str(r) for r in v.refutations], "horizon_s": v.horizon, "participants": v.participants}
