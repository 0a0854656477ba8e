"""Judging a run directory: its recorded trace and summary against its scenario's criteria.

:func:`judge_run` loads the scenario the run names (or the one given), builds its world (the
lanes, the route, the ego's box), judges :mod:`twolevel.verdict.criteria` and records the
verdict in ``run.json`` (key ``verdict``, beside the engine's ``summary``) with the lane edges
the report draws (key ``road_edges``) and the ride's figures (key ``ride``,
:mod:`twolevel.verdict.ride`), atomically. Nothing of the run is re-simulated.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

from twolevel.diagnostics import Diagnostic, Span
from twolevel.verdict.criteria import Verdict, judge
from twolevel.verdict.ride import RIDE_KEY, Ride, ride_of

__all__ = ["judge_run", "recorded_verdict", "recorded_ride", "criteria_of", "VERDICT_KEY", "EDGES_KEY"]

VERDICT_KEY = "verdict"
EDGES_KEY = "road_edges"


def judge_run(run_dir: str | os.PathLike[str], scenario: str | os.PathLike[str] | None = None, *,
              parameters: Mapping[str, float] | None = None, write: bool = True
              ) -> tuple[Verdict | None, list[Diagnostic]]:
    """Judge the run in ``run_dir`` against ``scenario`` (default: the path ``run.json``
    records) with ``parameters`` (default: nominal); with ``write``, record the verdict in
    ``run.json``. Returns ``(verdict or None, diagnostics)``; None when the run or the scenario
    cannot be read. Never raises for bad input."""
    from twolevel.atomic import write_json_atomic
    from twolevel.verdict.codes import SIM620
    from twolevel.sim.trace import RUN_FILE, read_run
    from twolevel.verdict.drivable import lane_edges
    from twolevel.world.loader import load_scenario
    from twolevel.world.world import build_world

    run = read_run(run_dir)
    path = scenario if scenario is not None else (run.meta.get("scenario") or {}).get("path")
    where = Span.whole_file(str(Path(run_dir) / RUN_FILE))
    if path is None or not run.meta:
        return None, [SIM620(f"cannot judge {run_dir}: {'; '.join(run.problems) or 'no scenario recorded'}", where)]
    scn, diags = load_scenario(path, parameters)
    if scn is None:
        return None, diags
    world = build_world(scn)
    meta = dict(run.meta)
    verdict = judge(scn.spec.expect, world, run.columns, meta.get("summary") or {}, str(meta.get("status", "unknown")),
                    meta.get("settings"))
    if write:
        meta[VERDICT_KEY] = verdict.to_json()
        meta[RIDE_KEY] = ride_of(world, run.columns, _goal_time(verdict, meta),
                                 float((meta.get("settings") or {}).get("stop_speed", world.settings.stop_speed))).to_json()
        meta[EDGES_KEY] = lane_edges(world.lanes)
        try:
            write_json_atomic(Path(run_dir) / RUN_FILE, meta)
        except OSError as exc:
            diags.append(SIM620(f"cannot record the verdict in {RUN_FILE}: {exc}", where))
    return verdict, diags


def _goal_time(verdict: Verdict, meta: Mapping[str, Any]) -> float | None:
    """[s] When the goal was reached: the goal criterion's measure, else the engine's record."""
    goal = verdict.get("goal")
    if goal is not None:
        return goal.measured
    reached = (meta.get("summary") or {}).get("goal_reached_t")
    return None if reached is None else float(reached)


def recorded_ride(meta: Mapping[str, object]) -> Ride | None:
    """The ride recorded in a run's ``run.json`` (None when the run was never judged)."""
    raw = meta.get(RIDE_KEY)
    return Ride.from_json(raw) if isinstance(raw, Mapping) else None


def recorded_verdict(meta: Mapping[str, object]) -> Verdict | None:
    """The verdict ``run.json`` holds (None if the run was never judged)."""
    raw = meta.get(VERDICT_KEY)
    return Verdict.from_json(raw) if isinstance(raw, Mapping) else None


def criteria_of(scn: Any) -> list[str]:
    """The names of the criteria a loaded scenario's runs are judged by, in verdict order."""
    from twolevel.verdict.criteria import RULE_PREFIX
    from twolevel.world.world import build_world, load_rulesets

    e = scn.spec.expect
    names = [n for n, on in (("goal", e.goal is not None), ("on_road", e.on_road is not None),
                             ("no_collision", e.no_collision)) if on]
    if e.rules == "all":
        sets, _ = load_rulesets(build_world(scn))
        names += [RULE_PREFIX + r.name for rs in sets for r in rs.rules]
    else:
        names += [RULE_PREFIX + r for r in e.rules]
    return names + [n for n in ("max_decel", "max_jerk", "max_lat_accel", "min_gap", "max_stopped") if getattr(e, n) is not None]
