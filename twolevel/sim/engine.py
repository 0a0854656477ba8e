"""The closed loop: both controller levels against the world, written to a run directory.

:func:`simulate_scenario` is what ``twolevel simulate`` calls. Each step of ``dt``:

1. **sense** the current sample (route position, limits, stop lines, lights, vehicles within
   ``r_near``: :mod:`twolevel.world.sensing`);
2. **plan**: the high-level MPC (:mod:`twolevel.control.high_level`) from the ego's
   (X, Y, ψ, v), the traffic and stop-sign memory, and the recorded history of every signal;
3. **check**: the low level (:mod:`twolevel.control.low_level`) forward-simulates the detailed
   model under the plan, monitors every rule and applies u*, a sampled control or full
   braking. With ``monitor=False`` (the paper's "without monitor") the MPC's first control is
   applied directly (a → γ by the actuation map);
4. **record** the sample (state, control, decision, timings, signals) and feed the online
   monitor, whose final robustness values fill the ``rob_<rule>`` columns;
5. **advance** the world: the ego's plant is the detailed four-wheel model
   (:mod:`twolevel.models.fourwheel`, compiled rollout with H = 1), the other participants
   step by their behaviours with the ego as a leader for IDM, lights cycle.

Collisions (overlapping oriented boxes, checked against every vehicle, not only the sensed
ones) are recorded with time, place and the other vehicle, never hidden.

**The trace.** One row per step: :data:`~twolevel.sim.trace.BASE_COLUMNS`, the signal columns
the rules read (a, s, e, d_stop, light_red, d_light, d_lead, v_lead; v, v_max, min_gap and
n_near are base columns), a few controller columns (``candidates``; ``ll_violated``: the rules u*
broke on the detailed prediction, i.e. why the low level intervened; ``hl_status``, ``hl_qps``,
``t_plant_ms``), then ``rob_<rule>`` per rule: the robustness at that step on the *executed*
trajectory, by the online monitor — exactly what ``twolevel monitor rules.stl trace.csv``
computes from the same file. A rule whose window looks ahead L steps is final L steps later, so
rows are written with that delay; when the run ends, is interrupted (Ctrl-C) or crashes, the
remaining rows are completed with the windows truncated at the end (RTAMT's semantics) and
written before ``run.json`` records the status. Only a killed process loses the last L rows.

**The goal.** On a route that stops at its goal, the run ends at the first step at which the ego
stands still (speed ≤ the scenario's stop_speed) within :data:`GOAL_ZONE` of the goal or past it;
the summary (and ``run.json``) records that time as ``goal_reached_t`` [s] (None otherwise).

**Determinism.** Everything but the timing columns (``t_high_ms``, ``t_low_ms``, ``t_step_ms``,
``t_plant_ms``) is a function of the scenario and the seed, provided the high level is
(its time limit can make a plan depend on the machine's speed; the default mode search is
deterministic in practice).
"""

from __future__ import annotations

import hashlib
import math
import platform
import time
import traceback
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from twolevel.diagnostics import Diagnostic, Span
from twolevel.sim.codes import SIM610, SIM611, SIM612, SIM613, SIM614, SIM615
from twolevel.sim.summary import Closest, Collision, RunSummary, StepInfo, summarise
from twolevel.sim.trace import BASE_COLUMNS, TraceWriter

__all__ = ["simulate_scenario", "StepInfo", "RunSummary", "Collision", "TIMING_COLUMNS", "SIGNAL_COLUMNS"]

#: Wall-clock columns (excluded from determinism comparisons).
GOAL_ZONE = 1.0  # [m] how far before the goal a standstill counts as arrived
TIMING_COLUMNS = ("t_high_ms", "t_low_ms", "t_step_ms", "t_plant_ms")
#: Signal columns beyond the base ones, named as the rules read them.
SIGNAL_COLUMNS = ("a", "s", "e", "d_stop", "light_red", "d_light", "d_lead", "v_lead")
EXTRA_COLUMNS = ("candidates", "ll_violated", "hl_status", "hl_qps", "t_plant_ms")
#: The high level: the paper's MILC MPC ("twolevel") or the NMPC baseline on the kinematic or
#: the four-wheel model (design.md, "Report": the paper's comparison).
CONTROLLERS = ("twolevel", "nmpc", "nmpc-fourwheel")
_SIGNALS = ("x", "y", "psi", "v", "a", "delta", "s", "e", "v_max", "d_stop", "light_red", "d_light", "d_lead",
            "v_lead", "min_gap", "n_near")
_LIGHT_NAMES = {0: "green", 1: "yellow", 2: "red"}


def _sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 16), b""):
            h.update(chunk)
    return h.hexdigest()


def _versions() -> dict[str, str]:
    from importlib import metadata

    out = {"python": platform.python_version()}
    for dist in ("numpy", "scipy", "casadi", "highspy", "clarabel", "twolevel"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


@dataclass
class _Pending:
    """Rows waiting for their rules' final robustness."""

    rows: deque[dict[str, Any]]
    first: int  # step index of rows[0]


def simulate_scenario(
    scenario_path: str,
    out_dir: str,
    *,
    monitor: bool = True,
    controller: str = "twolevel",
    seed: int | None = None,
    duration: float | None = None,
    progress: Callable[[StepInfo], None] | None = None,
    frames: bool = True,
) -> tuple[RunSummary | None, list[Diagnostic]]:
    """Run ``scenario_path`` in closed loop and write the run directory ``out_dir``.

    ``monitor=False`` applies the MPC's controls directly (the paper's "without monitor").
    ``seed`` / ``duration`` [s] override the scenario's ``run`` settings. ``progress`` is called
    after every step with a :class:`StepInfo`; if it raises ``KeyboardInterrupt`` the run stops
    as on Ctrl-C. ``frames``: also write ``frames.jsonl`` for the animation.

    Returns the :class:`RunSummary` (``status`` complete / interrupted / crashed; None when the
    scenario or its rules could not be loaded) and every diagnostic. Interruption and internal
    errors are diagnostics (SIM612, SIM613), never tracebacks; the run directory keeps every
    completed step and ``run.json`` says how it ended.
    """
    from twolevel.world.loader import load_scenario
    from twolevel.world.world import build_world

    where = Span.whole_file(scenario_path)
    if controller not in CONTROLLERS:
        return None, [SIM610(f"unknown controller '{controller}'", where,
                             hint=f"choose one of: {', '.join(CONTROLLERS)}")]
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        return None, [SIM611(f"the duration must be a positive number of seconds, got {duration}", where)]
    if seed is not None and seed < 0:
        return None, [SIM611(f"the seed must be ≥ 0, got {seed}", where)]
    scn, diags = load_scenario(scenario_path)
    if scn is None or any(d.is_error for d in diags):
        return None, diags
    run = scn.spec.run.model_copy(update={k: v for k, v in (("seed", seed), ("duration", duration)) if v is not None})
    scn = replace(scn, spec=scn.spec.model_copy(update={"run": run}))
    world = build_world(scn)
    loop, more = _Loop.create(world, scn, monitor=monitor, controller=controller)
    diags += more
    if loop is None:
        return None, diags
    try:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return None, diags + [SIM615(f"cannot create the run directory '{out_dir}': {exc}", where)]
    return loop.run(out_dir, progress, frames, diags)


class _Loop:
    """One closed-loop run (state kept between steps)."""

    def __init__(self, world: Any, scn: Any, hl: Any, ll: Any, rulesets: list[Any], monitor: bool,
                 controller: str) -> None:
        from twolevel.control.low_level.rules import rule_checks
        from twolevel.models.params import VehicleParams

        self.world, self.scn, self.hl, self.ll = world, scn, hl, ll
        self.monitor, self.controller = monitor, controller
        self.rulesets = rulesets
        self.rules, self.consts = rule_checks(rulesets, world.settings.dt)
        fields = VehicleParams.__dataclass_fields__
        self.params = VehicleParams().with_overrides({k: v for k, v in world.ego.vehicle.items() if k in fields})
        self.params = replace(self.params, length=world.ego.length, width=world.ego.width)

    @classmethod
    def create(cls, world: Any, scn: Any, *, monitor: bool, controller: str) -> tuple["_Loop | None", list[Diagnostic]]:
        from twolevel.control.high_level.controller import HighLevelController
        from twolevel.control.low_level.controller import LowLevelController
        from twolevel.world.world import load_rulesets

        sets, diags = load_rulesets(world)
        if any(d.is_error for d in diags):
            return None, diags
        if controller.startswith("nmpc"):
            from twolevel.control.nmpc.controller import NmpcController

            model = "fourwheel" if controller == "nmpc-fourwheel" else "kinematic"
            hl, d = NmpcController.from_world(world, model=model)
        else:
            hl, d = HighLevelController.from_world(world)
        diags += d
        if hl is None:
            return None, diags
        loop = cls(world, scn, hl, None, sets, monitor, controller)
        loop.ll = LowLevelController(world, loop.rules, params=loop.params, consts=loop.consts)
        return loop, diags

    # ------------------------------------------------------------------------------ metadata
    def _meta(self) -> dict[str, Any]:
        from twolevel.sim.frames import map_lines

        w, scn = self.world, self.scn
        s = w.settings
        return {
            "scenario": {"name": w.name, "path": scn.path, "sha256": _sha256(scn.path)},
            "map": {"path": scn.map.path, "sha256": _sha256(scn.map.path)},
            "rules": [{"path": p, "sha256": _sha256(p), "constants": dict(c)} for p, c in w.rule_files],
            "settings": {"H": s.H, "dt": s.dt, "r_near": s.r_near, "r": s.r, "D_safe": s.D_safe, "samples": s.samples,
                         "time_limit": s.time_limit, "solver": s.solver, "stop_speed": s.stop_speed,
                         "duration": s.duration, "seed": s.seed, "monitor": self.monitor,
                         "controller": self.controller, "vehicle": dict(w.ego.vehicle)},
            "seed": s.seed,
            "versions": _versions(),
            "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                        "cpus": _cpus()},
            "timing_columns": list(TIMING_COLUMNS),
            "map_lines": map_lines(w),
        }

    # ------------------------------------------------------------------------------ the loop
    def run(self, out_dir: str, progress: Callable[[StepInfo], None] | None, frames: bool,
            diags: list[Diagnostic]) -> tuple[RunSummary | None, list[Diagnostic]]:
        from twolevel.monitor.errors import MonitorError
        from twolevel.monitor.online import OnlineMonitor
        from twolevel.stl import ast

        rule_names = [r.name for r in self.rules]
        columns = list(BASE_COLUMNS) + list(SIGNAL_COLUMNS) + list(EXTRA_COLUMNS) + [f"rob_{n}" for n in rule_names]
        try:
            online: OnlineMonitor | None = OnlineMonitor([ast.Rule(r.name, r.formula) for r in self.rules],
                                                         self.world.settings.dt, consts=self.consts)
        except MonitorError:
            online = None  # unbounded future: robustness filled at the end from the offline monitor
        self.online = online
        self.robustness: dict[str, list[float]] = {n: [] for n in rule_names}
        self.pending = _Pending(deque(), 0)
        self.stats: dict[str, list[Any]] = {k: [] for k in ("step", "high", "low", "track", "over", "dist", "gap",
                                                            "decision")}
        self.collisions: list[Collision] = []
        self._open: dict[int, list[float]] = {}  # other index → [t, x, y, gap, t_last]
        n_parts = len(self.world.parts.ids)
        self._closest = np.full(n_parts, np.inf)  # per vehicle: smallest centre distance [m] ...
        self._closest_t = np.zeros(n_parts)  # ... and when [s]
        status, error = "complete", ""
        self.t_wall0 = time.perf_counter()
        fw_writer = None
        try:
            with TraceWriter(out_dir, columns, self._meta()) as writer:
                self.writer = writer
                if frames:
                    from twolevel.sim.frames import FrameWriter

                    fw_writer = FrameWriter(out_dir, self.world)
                try:
                    self._steps(progress, fw_writer)
                except BaseException:
                    self._finish_rows()
                    writer.meta["summary"] = self._summary(out_dir, "interrupted").to_json()
                    raise
                self._finish_rows()
                writer.meta["summary"] = self._summary(out_dir, "complete").to_json()
        except KeyboardInterrupt:
            status = "interrupted"
        except OSError as exc:  # the disk is full, or the run directory went away
            status, error = "unwritable", f"{type(exc).__name__}: {exc}"
        except Exception as exc:  # an internal error: keep the run, say what happened
            status, error = "crashed", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"
        finally:
            if fw_writer is not None:
                try:
                    fw_writer.close()
                except OSError as exc:
                    status, error = "unwritable", error or f"{type(exc).__name__}: {exc}"
        summary = self._summary(out_dir, "crashed" if status == "unwritable" else status)
        where = Span.whole_file(self.scn.path)
        if status == "unwritable":
            diags.append(SIM615(f"cannot write the run directory {out_dir}: {error}", where,
                                hint="free disk space or choose another --out; the steps written so far are kept"))
        elif status == "interrupted":
            diags.append(SIM612(f"interrupted after {summary.steps} steps ({summary.duration:g} s)", where,
                                hint=f"the completed steps are in {out_dir}"))
        elif status == "crashed":
            diags.append(SIM613(f"the run stopped after {summary.steps} steps: {error.splitlines()[0]}", where,
                                hint=f"the completed steps are in {out_dir}; run.json has the traceback"))
            from twolevel.sim.trace import RUN_FILE, write_json_atomic
            import json

            try:
                meta = json.loads((Path(out_dir) / RUN_FILE).read_text(encoding="utf-8"))
                meta["traceback"] = error
                meta["summary"] = summary.to_json()
                write_json_atomic(Path(out_dir) / RUN_FILE, meta)
            except (OSError, ValueError) as exc:
                diags.append(SIM615(f"cannot record the traceback in {RUN_FILE}: {exc}", where))
        for c in summary.collisions:
            diags.append(SIM614(f"collision with '{c.other}' at t = {c.t:.1f} s, ({c.x:.1f}, {c.y:.1f}) m, "
                                f"overlap {-c.gap:.2f} m", where))
        return summary, diags

    def _summary(self, out_dir: str, status: str) -> RunSummary:
        st = self.stats
        n = len(st["step"])
        rob = {k: np.asarray(v[:n]) for k, v in self.robustness.items()}
        self._close_collisions(math.inf)
        return summarise(
            scenario=self.world.name, run_dir=str(out_dir), status=status, monitor=self.monitor,
            controller=self.controller, seed=self.world.settings.seed, dt=self.world.settings.dt,
            wall_time_s=time.perf_counter() - self.t_wall0, step_ms=st["step"], high_ms=st["high"], low_ms=st["low"],
            tracking=st["track"], over_limit=st["over"], min_dist=st["dist"], min_gap=st["gap"],
            decisions=st["decision"], collisions=sorted(self.collisions, key=lambda c: c.t), robustness=rob,
            closest=[Closest(self.world.parts.ids[i], float(self._closest[i]), float(self._closest_t[i]))
                     for i in np.argsort(self._closest, kind="stable")[:5] if np.isfinite(self._closest[i])],
            goal_reached_t=getattr(self, "goal_reached_t", None),
        )

    def _steps(self, progress: Callable[[StepInfo], None] | None, frames: Any) -> None:
        from twolevel.control.planner import EgoState, PlanStatus, Snapshot
        from twolevel.world.sensing import Memory, others_now, sense
        from twolevel.models import fourwheel as fw
        from twolevel.models.actuation import gamma_from_accel
        from twolevel.models.rollout import rollout
        from twolevel.sim.history import History
        from twolevel.world import traffic as tr

        w, p = self.world, self.params
        s = w.settings
        dt, H = s.dt, s.H
        steps = int(round(s.duration / dt))
        x = fw.initial_state(w.ego.x, w.ego.y, w.ego.psi, w.ego.v, p)
        traffic = w.traffic0
        memory = Memory.fresh(w)
        keep = max([r.past for r in self.rules] + [self.hl_depth()])
        history = History(_SIGNALS, keep)
        s_hint = float(w.route.local_coordinates(x[None, :2])[0][0])
        self.ll.warm_up(x)
        rollout(x, np.zeros((1, 1, 2)), dt, p)  # compile the plant step before timing anything
        a_prev, delta_prev = 0.0, 0.0
        recent: deque[float] = deque(maxlen=20)
        self.goal_reached_t = None
        stops_at_goal = bool(w.route.v_des.size and w.route.v_des[-1] <= 1e-9)
        goal_s = float(w.route.s[-1])
        for k in range(steps):
            t = k * dt
            c0 = time.perf_counter()
            X, Y, psi = float(x[0]), float(x[1]), float(x[2])
            v = float(math.copysign(math.hypot(x[3], x[4]), x[3]))
            s_arr, _ = w.route.project_near(np.array([[X, Y]]), np.array([s_hint]), 15.0 + abs(v) * dt)
            s0 = float(s_arr[0])
            s_hint = s0
            others = others_now(w, traffic, X, Y, s0)
            one = lambda val: np.array([[val]])  # noqa: E731
            now = {n: float(a[0, 0]) for n, a in sense(w, t, dt, memory, others, one(X), one(Y), one(psi), one(v),
                                                       one(a_prev), one(delta_prev), s_center=np.array([s0]),
                                                       half_window=15.0).items()}
            mem_after = memory.after(w, t, s0, v)
            past = history.view()
            c1 = time.perf_counter()
            ego = EgoState(np.array([X, Y, psi, v]), x)
            plan = self.hl.solve(ego, t, Snapshot(traffic, mem_after.stops), past)
            c2 = time.perf_counter()
            u_star = np.asarray(plan.controls, dtype=float)
            if u_star.shape != (H, 2) or not np.all(np.isfinite(u_star)):
                u_star = np.tile([0.0, self.hl.params.a_min], (H, 1))
            if self.monitor:
                dec = self.ll.decide(x, u_star, t, traffic, memory, s0, past, target=plan.states, step=k,
                                     now=others)
                control, accel, decision, tried = dec.control, dec.accel, dec.decision.value, dec.candidates
                why = " ".join(dec.violated)
            else:
                why = ""
                control = np.array([u_star[0, 0], float(gamma_from_accel(u_star[0, 1], max(x[3], 0.0), p))])
                accel, decision, tried = float(u_star[0, 1]), "nmpc" if self.controller.startswith("nmpc") else "mpc", 0
            if decision == "mpc" and plan.status is PlanStatus.FALLBACK:
                decision = "fallback"
            c3 = time.perf_counter()
            t_high, t_low = (c2 - c1) * 1e3, (c3 - c2) * 1e3
            t_step = (c3 - c0) * 1e3
            now["a"], now["delta"] = float(accel), float(control[0])
            history.append(now)
            # --- the record of this step ---------------------------------------------------
            min_dist = self._collisions(t, X, Y, psi, traffic)
            light = self._light_state(t, now)
            row = {"t": round(t, 9), "x": X, "y": Y, "psi": psi, "v": v, "delta": float(control[0]),
                   "gamma": float(control[1]), "decision": decision, "t_high_ms": t_high, "t_low_ms": t_low,
                   "t_step_ms": t_step, "n_near": now["n_near"], "min_dist": min_dist, "min_gap": now["min_gap"],
                   "tracking_error": abs(now["e"]), "v_max": now["v_max"], "light_state": light,
                   "candidates": tried, "ll_violated": why, "hl_status": plan.status.value, "hl_qps": plan.qps}
            row.update({c: now[c] for c in SIGNAL_COLUMNS})
            st = self.stats
            st["step"].append(t_step); st["high"].append(t_high); st["low"].append(t_low)
            st["track"].append(abs(now["e"])); st["over"].append(v - now["v_max"]); st["dist"].append(min_dist)
            st["gap"].append(now["min_gap"]); st["decision"].append(decision)
            if frames is not None:
                frames.write(t, (X, Y, psi), np.asarray(plan.states), traffic)
            # --- advance the world ------------------------------------------------------------
            p0 = time.perf_counter()
            x = rollout(x, control[None, None, :], dt, p).states[0, 1]
            traffic = tr.step(traffic, dt, lanes=w.lanes, parts=w.parts, limits=w.limits, lights=w.lights,
                              stops=w.stops, ego=tr.EgoBox(X, Y, psi, v, w.ego.length), stop_speed=s.stop_speed)
            row["t_plant_ms"] = (time.perf_counter() - p0) * 1e3
            self._record(row, now)
            memory = mem_after
            a_prev, delta_prev = float(accel), float(control[0])
            recent.append(t_step)
            # the run ends when the ego stands still at the goal (GOAL_ZONE before it or past it)
            if stops_at_goal and s0 >= goal_s - GOAL_ZONE and abs(v) <= s.stop_speed:
                self.goal_reached_t = round(t, 9)
            if progress is not None:
                wall = time.perf_counter() - self.t_wall0
                progress(StepInfo(k + 1, steps, round((k + 1) * dt, 9), s.duration,
                                  1000.0 * len(recent) / max(sum(recent), 1e-9), t_step, int(now["n_near"]), decision,
                                  (k + 1) * dt / wall if wall > 0 else math.inf))
            if self.goal_reached_t is not None:
                break

    def hl_depth(self) -> int:
        return max((r.depth for r in getattr(self.hl, "rules", [])), default=0)

    # ------------------------------------------------------------------------------ records
    def _light_state(self, t: float, now: dict[str, float]) -> str:
        w = self.world
        if not math.isfinite(now["d_light"]) or len(w.route_lights) == 0:
            return "none"
        j = int(np.argmin(np.abs(w.route_lights - now["s"] - now["d_light"])))
        return _LIGHT_NAMES.get(int(w.lights.state_at(t)[w.route_light_index[j]]), "none")

    def _collisions(self, t: float, X: float, Y: float, psi: float, traffic: Any) -> float:
        """Centre distance to the nearest vehicle [m]; opens/extends collision episodes."""
        from twolevel.world.sensing import rect_separation

        w = self.world
        if traffic.x.size == 0 or not traffic.active.any():
            self._close_collisions(t)
            return math.inf
        dist = np.where(traffic.active, np.hypot(traffic.x - X, traffic.y - Y), np.inf)
        closer = dist < self._closest
        self._closest = np.where(closer, dist, self._closest)
        self._closest_t = np.where(closer, t, self._closest_t)
        close = np.flatnonzero(dist <= 0.5 * (np.hypot(w.ego.length, w.ego.width)
                                              + np.hypot(w.parts.length, w.parts.width)))
        hit: dict[int, float] = {}
        if close.size:
            sep = rect_separation(X, Y, psi, w.ego.length, w.ego.width, traffic.x[close], traffic.y[close],
                                  traffic.psi[close], w.parts.length[close], w.parts.width[close])
            hit = {int(i): float(g) for i, g in zip(close, sep) if g < 0}
        for i, g in hit.items():
            ep = self._open.get(i)
            if ep is None:
                self._open[i] = [t, X, Y, g, t]
            else:
                ep[3], ep[4] = min(ep[3], g), t
        self._close_collisions(t, keep=set(hit))
        return float(dist.min())

    def _close_collisions(self, t: float, keep: set[int] | None = None) -> None:
        for i in [i for i in self._open if keep is None or i not in keep]:
            t0, x0, y0, g, t1 = self._open.pop(i)
            self.collisions.append(Collision(t0, t1, x0, y0, self.world.parts.ids[i], g))

    def _record(self, row: dict[str, Any], now: dict[str, float]) -> None:
        """Queue the row; write every row whose robustness is final."""
        pend = self.pending
        pend.rows.append(row)
        if self.online is None:
            self._offline_samples = getattr(self, "_offline_samples", [])
            self._offline_samples.append(now)
            return
        for rule, i, value in self.online.update(now):
            pend_i = i - pend.first
            if 0 <= pend_i < len(pend.rows):
                pend.rows[pend_i][f"rob_{rule}"] = value
            self.robustness[rule].append(value)
        names = [f"rob_{r.name}" for r in self.rules]
        while pend.rows and all(n in pend.rows[0] for n in names):
            self.writer.write(pend.rows.popleft())
            pend.first += 1

    def _finish_rows(self) -> None:
        """Complete and write the rows still waiting (windows truncated at the end)."""
        pend = self.pending
        if not pend.rows:
            return
        if self.online is not None:
            final = self.online.finish()
        else:
            from twolevel.monitor.robustness import evaluate_rules
            from twolevel.stl import ast

            samples = getattr(self, "_offline_samples", [])
            sig = {n: np.array([smp[n] for smp in samples]) for n in _SIGNALS}
            final = evaluate_rules([ast.Rule(r.name, r.formula) for r in self.rules], sig, self.world.settings.dt,
                                   consts=self.consts)
        for rule, series in final.items():
            have = len(self.robustness[rule])
            self.robustness[rule].extend(float(v) for v in series[have:])
        for j, row in enumerate(pend.rows):
            i = pend.first + j
            for rule in final:
                row.setdefault(f"rob_{rule}", float(final[rule][i]))
            self.writer.write(row)
        pend.first += len(pend.rows)
        pend.rows.clear()


def _cpus() -> int:
    import os

    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
