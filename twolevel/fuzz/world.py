"""Fuzzing maps and scenarios: mutate real ones field-wise, then run what a user would run.

The invariant: whatever ``twolevel check`` says about an input, it says it with diagnostics
(never an exception); whatever it accepts loads, builds a world with finite numbers, and goes
through ``twolevel plan`` and ``twolevel simulate --duration 2`` without an internal error and
without a NaN in any vehicle's state.

A :class:`Seed` is a scenario with its map (as plain data) and the rule files it names; a
:class:`Case` is a seed after some mutations, written into a folder as ``scenarios/s.yaml``,
``maps/m.yaml`` and ``rules/*.stl``. :func:`probe` runs the stages and returns an
:class:`Outcome`.
"""

from __future__ import annotations

import csv
import json
import math
import random
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

from twolevel.fuzz.mutation import Mutation, Pairs, Path_, apply, dump, mutate
from twolevel.fuzz.rules import ACCEPTED, INCONSISTENT, INTERNAL, REFUSED, Outcome

__all__ = ["Seed", "Case", "load_seed", "shipped_seeds", "generate", "write_case", "probe", "NAN_STATE"]

#: The verdict of a run that wrote a non-finite vehicle state (the others are the rule target's:
#: "refused" and "accepted" keep the invariant; "internal-error" and "inconsistent", here a
#: later stage refusing what ``check`` accepted, break it).
NAN_STATE = "nan-state"


@dataclass(frozen=True)
class Seed:
    """A valid scenario and its map as plain data, and the rule files the scenario names (by the
    name it uses, ``../rules/<name>``, → their path)."""

    name: str
    scenario: Any
    map: Any
    rules: dict[str, str]


@dataclass(frozen=True)
class Case:
    """A seed after ``mutations`` (each applied to the scenario or the map, as ``target`` says)."""

    seed: str
    scenario: Any
    map: Any
    mutations: tuple[tuple[str, Mutation], ...]
    rules: dict[str, str]

    def __str__(self) -> str:
        return f"{self.seed}: " + "; ".join(f"{t} {m}" for t, m in self.mutations)


def load_seed(scenario_path: str | Path) -> Seed:
    """A seed from a scenario file: its map and rule files are found as the scenario names them."""
    from twolevel.world.document import read_document

    path = Path(scenario_path)
    doc, diags = read_document(path)
    if doc is None:
        raise ValueError(f"{path}: {diags[0].message}")
    data = doc.data
    map_path = (path.parent / data["map"]).resolve()
    mdoc, mdiags = read_document(map_path)
    if mdoc is None:
        raise ValueError(f"{map_path}: {mdiags[0].message}")
    rules: dict[str, str] = {}
    entries = []
    for entry in data.get("rules", []):
        file = entry if isinstance(entry, str) else entry["file"]
        name = Path(file).name
        rules[name] = str((path.parent / file).resolve())
        entries.append(f"../rules/{name}" if isinstance(entry, str) else {**entry, "file": f"../rules/{name}"})
    scenario = {**data, "map": "../maps/m.yaml", "rules": entries}
    return Seed(path.stem, scenario, mdoc.data, rules)


def shipped_seeds(root: str | Path) -> list[Seed]:
    """Seeds from the repository at ``root``: every scenario of ``scenarios/`` and ``examples/``."""
    root = Path(root)
    paths = sorted((root / "scenarios").glob("*.yaml")) + sorted((root / "examples").glob("*/scenario.yaml"))
    return [load_seed(p) for p in paths]


def _bounds(root: str) -> Any:
    """The allowed range of the number at a path of a scenario (``root`` "scenario") or a map,
    from the schema's constraints (or the vehicle parameters' ranges)."""
    from twolevel.models.params import BICYCLE_RANGES, VEHICLE_RANGES
    from twolevel.world.loader import _model_at
    from twolevel.world.schema import MapFile, ScenarioFile

    model = ScenarioFile if root == "scenario" else MapFile

    def bounds(path: Path_) -> tuple[float, float] | None:
        if root == "scenario" and path[:2] == ("ego", "vehicle") and len(path) == 3:
            rng = {**BICYCLE_RANGES, **VEHICLE_RANGES}.get(str(path[2]))
            return (rng.lo, rng.hi) if rng else None
        parent = _model_at(model, path[:-1])
        field_ = getattr(parent, "model_fields", {}).get(path[-1]) if isinstance(path[-1], str) else None
        if field_ is None:
            return None
        lo, hi = -math.inf, math.inf
        for c in field_.metadata:
            lo = max(lo, float(getattr(c, "ge", getattr(c, "gt", -math.inf))))
            hi = min(hi, float(getattr(c, "le", getattr(c, "lt", math.inf))))
        return (lo, hi) if math.isfinite(lo) else None

    return bounds


def generate(seed: Seed, rnd: random.Random, max_mutations: int = 3) -> Case:
    """``seed`` with 1 to ``max_mutations`` random mutations (mostly one), each of the scenario or
    the map. A repeated key (which turns a mapping into pairs) is always the last mutation."""
    docs = {"scenario": seed.scenario, "map": seed.map}
    done: list[tuple[str, Mutation]] = []
    count = 1 if rnd.random() < 0.6 else rnd.randint(1, max_mutations)
    for _ in range(count):
        target = "scenario" if rnd.random() < 0.6 else "map"
        if isinstance(docs[target], Pairs):
            break
        m = mutate(docs[target], rnd, _bounds(target))
        docs[target] = apply(docs[target], m)
        done.append((target, m))
        if m.op == "duplicate" and isinstance(m.path[-1], str):
            break
    return Case(seed.name, docs["scenario"], docs["map"], tuple(done), seed.rules)


def write_case(case: Case, folder: str | Path) -> Path:
    """Write ``case`` into ``folder`` (``scenarios/s.yaml``, ``maps/m.yaml``, ``rules/``); the
    scenario's path."""
    folder = Path(folder)
    for sub in ("scenarios", "maps", "rules"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    for name, source in case.rules.items():
        target = folder / "rules" / name
        if not target.exists():
            shutil.copyfile(source, target)
    (folder / "maps" / "m.yaml").write_text(dump(case.map), encoding="utf-8")
    scenario = folder / "scenarios" / "s.yaml"
    scenario.write_text(dump(case.scenario), encoding="utf-8")
    return scenario


def _finite_world(world: Any) -> str:
    """What in a built world is not finite ("" when everything is)."""
    import numpy as np

    arrays = {
        "lane points": world.lanes.points, "route points": world.route.points, "route s": world.route.s,
        "route desired speed": world.route.v_des, "traffic x": world.traffic0.x, "traffic y": world.traffic0.y,
        "traffic v": world.traffic0.v, "ego": np.array([world.ego.x, world.ego.y, world.ego.psi, world.ego.v]),
    }
    bad = [name for name, a in arrays.items() if not np.all(np.isfinite(a))]
    return ", ".join(bad)


def _nan_rows(trace: Path) -> str:
    """The first row of ``trace`` whose ego state is not finite ("" if none)."""
    with trace.open(newline="", encoding="utf-8") as f:
        for k, row in enumerate(csv.DictReader(f)):
            for name in ("x", "y", "psi", "v"):
                try:
                    ok = math.isfinite(float(row[name]))
                except (KeyError, TypeError, ValueError):
                    ok = False
                if not ok:
                    return f"row {k + 1}: {name} = {row.get(name)!r}"
    return ""


def _nan_frames(frames: Path) -> str:
    """The first frame in which a vehicle's pose is not finite ("" if none, or no frames)."""
    if not frames.exists():
        return ""
    with frames.open(encoding="utf-8") as f:
        for k, line in enumerate(f):
            frame = json.loads(line)
            for who, rows in (("ego", [frame.get("ego", [])]), ("others", frame.get("others", []))):
                if not all(isinstance(v, (int, float)) and math.isfinite(v) for row in rows for v in row):
                    return f"frame {k + 1} (t = {frame.get('t')}): {who} not finite"
    return ""


def probe(scenario: str | Path, *, run: bool = False, solver: str = "modes") -> Outcome:
    """Check ``scenario``; if check reports no error, load it and build its world, and with
    ``run`` also ``plan`` it (with ``solver``) and ``simulate --duration 2`` it (into
    ``<folder>/run``)."""
    from twolevel.diagnostics import REGISTRY
    from twolevel.pipeline import check

    try:
        result = check([str(scenario)])
    except Exception as exc:  # the invariant: never
        return Outcome(INTERNAL, f"check raised {type(exc).__name__}: {exc}")
    codes = tuple(sorted({d.code for d in result.diagnostics}))
    bad = [d for d in result.diagnostics if d.span.line < 1 or d.span.column < 1 or d.code not in REGISTRY]
    if bad:
        return Outcome(INTERNAL, f"diagnostic without a position or a declared code: {bad[0]}", codes)
    if any(d.is_error for d in result.diagnostics):
        return Outcome(REFUSED, "", codes)
    stage = "load"
    try:
        from twolevel.world.loader import load_scenario
        from twolevel.world.world import build_world

        scn, diags = load_scenario(scenario)
        if scn is None:
            return Outcome(INCONSISTENT, f"load refused what check accepted: {diags[:1]}", codes)
        stage = "build"
        world = build_world(scn)
        bad_numbers = _finite_world(world)
        if bad_numbers:
            return Outcome(NAN_STATE, f"the built world has non-finite {bad_numbers}", codes)
    except Exception as exc:
        return Outcome(INTERNAL, f"{stage} raised {type(exc).__name__}: {exc}", codes)
    if not run:
        return Outcome(ACCEPTED, "", codes)
    return _run(Path(scenario), solver, codes)


def _errors(diags: Iterable[Any]) -> str:
    return "; ".join(f"{d.code} {d.message}" for d in diags if d.is_error)[:300]


def _run(scenario: Path, solver: str, codes: tuple[str, ...]) -> Outcome:
    """``twolevel plan`` and ``twolevel simulate --duration 2`` as the CLI runs them (the same
    library functions; the CLI adds only rendering and exit codes)."""
    from twolevel.pipeline.planning import plan_scenario
    from twolevel.sim.engine import simulate_scenario

    try:
        report, diags = plan_scenario(str(scenario), solver=solver, time_limit=5.0)
    except Exception as exc:
        return Outcome(INTERNAL, f"plan raised {type(exc).__name__}: {exc}", codes)
    if report is None or any(d.bad_input for d in diags):  # what the CLI exits 2 on
        return Outcome(INCONSISTENT, f"plan refused what check accepted: {_errors(diags)}", codes)
    if report.status in ("optimal", "feasible") and not all(math.isfinite(v) for row in report.plan for v in row):
        return Outcome(NAN_STATE, f"plan ({report.status}) has a non-finite value", codes)
    run_dir = scenario.parent.parent / "run"
    shutil.rmtree(run_dir, ignore_errors=True)
    try:
        summary, diags = simulate_scenario(str(scenario), str(run_dir), duration=2.0)
    except Exception as exc:
        return Outcome(INTERNAL, f"simulate raised {type(exc).__name__}: {exc}", codes)
    if summary is None:
        return Outcome(INCONSISTENT, f"simulate refused what check accepted: {_errors(diags)}", codes)
    if summary.status != "complete":
        return Outcome(INTERNAL, f"simulate ended '{summary.status}': {_errors(diags)}", codes)
    try:
        meta = json.loads((run_dir / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        return Outcome(INTERNAL, f"simulate left no readable run.json: {e}", codes)
    if meta.get("status") != "complete":
        return Outcome(INTERNAL, f"run.json says '{meta.get('status')}' after a complete run", codes)
    nan = _nan_rows(run_dir / "trace.csv") or _nan_frames(run_dir / "frames.jsonl")
    if nan:
        return Outcome(NAN_STATE, f"simulate wrote a non-finite state, {nan}", codes)
    return Outcome(ACCEPTED, "", codes)
