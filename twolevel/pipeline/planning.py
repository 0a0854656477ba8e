"""``twolevel plan``: one MPC problem of a scenario, solved and reported (library side).

:func:`plan_scenario` builds the world at the scenario's start — or, with ``trace`` and ``at``,
the ego state recorded at time ``at`` of a run (other traffic re-simulated to that time, reacting
to the recorded ego; the recorded past as the rules' history) — solves one step with the chosen
solver and returns a :class:`PlanReport` and diagnostics. An infeasible problem names the rules
that conflict (:func:`explain_infeasibility`). ``emit`` writes the model (``.mps`` / ``.lp``; the
linear part: with the HiGHS solver its L1 counterpart, which is the MILP HiGHS solves).
Bad input comes back as diagnostics (YML4xx, STL2xx, MIL5xx), never as an exception.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twolevel.control.codes import MIL511, MIL512, MIL513, MIL514, MIL516
from twolevel.control.high_level.conflicts import explain_infeasibility
from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.high_level.settings import SOLVERS, MPCSettings
from twolevel.control.planner import PlanStatus
from twolevel.diagnostics import Diagnostic, Span
from twolevel.milp.highs import write_model
from twolevel.milp.l1_surrogate import l1_surrogate
from twolevel.monitor.tracefile import read_trace
from twolevel.sim.summary import jsonable
from twolevel.world.loader import load_scenario
from twolevel.world.signals import signals_along
from twolevel.world.traffic import EgoBox
from twolevel.world.traffic import step as traffic_step
from twolevel.world.world import build_world

__all__ = ["PlanReport", "plan_scenario", "explain_infeasibility"]


@dataclass(frozen=True)
class PlanReport:
    """What ``twolevel plan`` prints: status, objective, solve times [ms], model size, the plan
    rows over the whole look-ahead (t [s], X [m], Y [m], ψ [rad], v [m/s], δ [rad], a [m/s²]; H
    steps of dt, then the coarse steps; the last state has no control: δ, a repeat the last),
    each rule's robustness, and the conflicting rules if any."""

    status: PlanStatus
    objective: float
    solve_ms: dict[str, float]
    binaries: int
    rows: int
    columns: int
    plan: tuple[tuple[float, ...], ...]
    rules: tuple[tuple[str, float], ...]
    solver: str = "highs"
    qps: int = 0
    certified: bool = False
    conflicts: tuple[str, ...] = ()
    message: str = ""
    emitted: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def certificate(self) -> str:
        """What the solver proved: ``optimal`` (a plan, optimal within the gap), ``infeasible``
        (no plan satisfies the rules: what is shown is the fallback, which claims nothing) or
        ``none``."""
        if not self.certified:
            return "none"
        return "optimal" if self.status.ok else "infeasible"

    def to_json(self) -> dict[str, Any]:
        """The JSON object of ``--format json``, by the documented convention: a robustness of
        ±inf (a rule trivially true or false) is the string "inf"/"-inf"; any other number that is
        not finite (a fallback's objective, a NaN time) is null."""
        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        out: dict[str, Any] = {
            "status": self.status.value,
            "certified": self.certificate,
            "objective": num(self.objective),
            "solve_ms": {k: None if num(v) is None else round(v, 4) for k, v in self.solve_ms.items()},
            "binaries": self.binaries,
            "rows": self.rows,
            "columns": self.columns,
            "plan": [[num(v) for v in row] for row in self.plan],
            "rules": [{"name": n, "robustness": jsonable(float(r))} for n, r in self.rules],
        }
        if self.conflicts:
            out["conflicts"] = list(self.conflicts)
        if self.message:
            out["message"] = self.message
        return out

    def table(self) -> tuple[tuple[str, ...], list[tuple[str, ...]]]:
        """Header and rows of the default table output (formatted strings)."""
        head = ("t [s]", "X [m]", "Y [m]", "psi [rad]", "v [m/s]", "delta [rad]", "a [m/s2]")
        return head, [tuple(f"{v:.3f}" for v in row) for row in self.plan]


_STATE_COLUMNS = ("t", "x", "y", "psi", "v")
_TRACE_COLUMNS = ("x", "y", "psi", "v", "delta", "gamma", "a")


def _read_trace(path: str, at: float) -> tuple[dict[str, np.ndarray] | None, list[Diagnostic]]:
    """The recorded columns up to the sample at ``at`` [s] (``t`` and the ego's), read by the
    one trace reader (:func:`twolevel.monitor.tracefile.read_trace`); its first error becomes a
    MIL516 at the same place."""
    span = Span(path)
    if not math.isfinite(at):
        return None, [MIL513(f"--at must be a finite time in seconds, got {at}", span)]
    trace, diags = read_trace(path)
    bad = next((d for d in diags if d.is_error), None)
    if trace is None or bad is not None:
        why = bad.message if bad is not None else "unreadable"
        return None, [MIL516(f"cannot read the trace: {why}", bad.span if bad is not None else span,
                             hint=(bad.hint if bad is not None and bad.hint else "give RUN_DIR/trace.csv of a simulate run"))]
    text = next((trace.unusable[k] for k in _STATE_COLUMNS[1:] if k in trace.unusable), None)
    if text is not None:  # a cell that is not a number, where the reader found it
        return None, [MIL516(f"cannot read the trace: {text.message}", text.span, hint=text.hint)]
    missing = [k for k in _STATE_COLUMNS[1:] if k not in trace.columns]
    if missing:
        return None, [MIL516(f"the trace needs numeric columns {', '.join(_STATE_COLUMNS)} (missing: "
                             f"{', '.join(missing)})", span)]
    t = trace.t
    i = int(np.argmin(np.abs(t - at)))
    if abs(t[i] - at) > trace.dt / 2 + 1e-9:
        return None, [MIL513(f"time {at} s is not in the trace ({t[0]:.2f} … {t[-1]:.2f} s)", span,
                             hint="pick --at within the recorded run")]
    cols = {"t": t[: i + 1]}
    cols.update({k: np.asarray(trace.columns[k][: i + 1], dtype=float) for k in _TRACE_COLUMNS
                 if k in trace.columns and k not in trace.unusable})
    for k in _STATE_COLUMNS[1:]:
        j = np.flatnonzero(~np.isfinite(cols[k]))
        if j.size:
            return None, [MIL516(f"the trace's {k} is {cols[k][j[0]]} at t = {t[j[0]]:g} s: the state must be finite", span)]
    return cols, []


def plan_scenario(
    scenario_path: str, *, solver: str = "highs", at: float | None = None, trace: str | None = None,
    emit: str | None = None, time_limit: float | None = 10.0,
) -> tuple[PlanReport | None, list[Diagnostic]]:
    """Solve one MPC step of a scenario (see the module docstring). ``time_limit`` [s] per solve."""
    span = Span(str(scenario_path))
    if solver not in SOLVERS:
        return None, [MIL512(f"unknown solver '{solver}'", span, hint=f"choose one of {', '.join(SOLVERS)}")]
    if emit is not None and Path(emit).suffix.lower() not in (".mps", ".lp"):
        return None, [MIL514(f"cannot emit '{emit}': the file must end in .mps or .lp", span)]
    if (at is None) != (trace is None):
        return None, [MIL513("--at and --trace go together (the state at time T of a recorded run)", span,
                             hint="omit both to plan at the scenario's start")]
    scn, diags = load_scenario(scenario_path)
    if scn is None:
        return None, diags
    world = build_world(scn)
    ws = world.settings
    settings = MPCSettings.of_world(ws, solver=solver, time_limit=time_limit)
    ctrl, d2 = HighLevelController.from_world(world, settings)
    diags += d2
    if ctrl is None:
        return None, diags
    e = world.ego
    ego = np.array([e.x, e.y, e.psi, e.v])
    traffic = world.traffic0
    history: dict[str, np.ndarray] = {}
    t0 = 0.0
    if trace is not None and at is not None:
        rec, d3 = _read_trace(trace, at)
        diags += d3
        if rec is None:
            return None, diags
        n = rec["t"].size
        ego = np.array([rec[k][-1] for k in ("x", "y", "psi", "v")])
        t0 = float(rec["t"][-1])
        for k in range(n - 1):  # other traffic, reacting to the recorded ego
            traffic = traffic_step(traffic, float(rec["t"][k + 1] - rec["t"][k]), lanes=world.lanes,
                                   parts=world.parts, limits=world.limits, lights=world.lights, stops=world.stops,
                                   ego=EgoBox(rec["x"][k], rec["y"][k], rec["psi"][k], rec["v"][k], e.length, e.width,
                                              world.route.lanes),
                                   stop_speed=ws.stop_speed)
        if n > 1:
            acc = rec.get("a", rec.get("gamma", np.zeros(n)))
            past = {"x": rec["x"][:-1], "y": rec["y"][:-1], "psi": rec["psi"][:-1], "v": rec["v"][:-1],
                    "delta": rec.get("delta", np.zeros(n))[:-1], "a": acc[:-1]}
            history = signals_along(world, None, past, t0=float(rec["t"][0]), dt=ws.dt)
    res = ctrl.solve(ego, t0, traffic, history)
    conflicts: tuple[str, ...] = ()
    bad_input = any(d.bad_input for d in (*diags, *res.diagnostics))
    if res.cause is PlanStatus.INFEASIBLE and not bad_input:
        # rules conflict only when the problem is infeasible, not when it timed out or a rule
        # could not be encoded (those say so themselves)
        step, past_s, P = ctrl.prepare(ego, t0, traffic, history)
        conflicts = explain_infeasibility(ctrl, step, past_s, P)
        what = f"rules {', '.join(conflicts)} conflict" if conflicts else "no single rule or pair explains it"
        diags.append(MIL511(f"no plan satisfies every rule at t = {t0:.2f} s: {what}", span,
                            hint="dropping any one of the named rules makes the problem feasible"))
    emitted = None
    if emit is not None:
        ctrl.reset()
        step, past_s, P = ctrl.prepare(ego, t0, traffic, history)
        asm = ctrl.build(step, past_s, P)
        try:
            write_model(l1_surrogate(asm.model) if solver == "highs" else asm.model, emit)
            emitted = str(emit)
        except OSError as e2:
            diags.append(MIL514(f"cannot write {emit}: {e2}", span))
    st = ctrl.settings
    la = res.look_ahead  # the whole look-ahead: the fine steps, then the coarse ones
    times, states, u = (t0 + la.times, la.states, la.controls) if la is not None else \
        (t0 + st.dt * np.arange(st.H + 1), res.states, res.controls)
    controls = np.vstack([u, u[-1:]])
    plan = tuple((float(times[k]), *map(float, states[k]), *map(float, controls[k])) for k in range(len(times)))
    report = PlanReport(res.status, res.cost, dict(res.timings_ms), res.binaries, res.rows, res.columns, plan,
                        tuple(res.rule_robustness.items()), solver, res.qps, res.certified, conflicts, res.message,
                        emitted)
    return report, diags + [d for d in res.diagnostics if d not in diags]
