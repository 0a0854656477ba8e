"""What ``run.json`` records about a run's origin: the scenario, map and rule files with their
SHA-256 hashes, the settings, the software versions and the machine."""

from __future__ import annotations

import hashlib
import os
import platform
from importlib import metadata
from typing import Any, Sequence

from twolevel.sim.frames import map_lines
from twolevel.sim.summary import jsonable
from twolevel.world.loader import Scenario
from twolevel.world.world import World

__all__ = ["run_metadata", "sha256_of", "versions", "cpus"]


def sha256_of(path: str) -> str:
    """The SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 16), b""):
            h.update(chunk)
    return h.hexdigest()


def versions() -> dict[str, str]:
    """Python's and the numerical packages' versions."""
    out = {"python": platform.python_version()}
    for dist in ("numpy", "scipy", "casadi", "highspy", "clarabel", "twolevel"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


def cpus() -> int:
    """CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def run_metadata(world: World, scn: Scenario, *, monitor: bool, controller: str, timing_columns: Sequence[str],
                 safety: bool = True) -> dict[str, Any]:
    """The provenance part of ``run.json`` for a run of ``scn`` (its ``world``) with ``controller``;
    ``timing_columns``: the trace's wall-clock columns; ``safety``: the low level's safety layer
    was on (with the assumptions about others it rests on)."""
    s = world.settings
    t = scn.spec.traffic
    traffic: dict[str, Any] = {"engine": "builtin"}
    if t is not None:  # the other engine's files, as the scenario's own
        traffic = {"engine": t.engine, "net": {"path": t.net, "sha256": sha256_of(t.net)},
                   "routes": [{"path": r, "sha256": sha256_of(r)} for r in t.routes],
                   "random_trips": t.random_trips.vehicles if t.random_trips is not None else 0,
                   "seed": s.seed if t.seed is None else t.seed, "radius": t.radius, "slots": t.slots}
    return {
        "scenario": {"name": world.name, "path": scn.path, "sha256": sha256_of(scn.path)},
        "traffic": traffic,
        "map": {"path": scn.map.path, "sha256": sha256_of(scn.map.path)},
        "rules": [{"path": p, "sha256": sha256_of(p), "constants": dict(c)} for p, c in world.rule_files],
        "settings": {"H": s.H, "dt": s.dt, "r_near": s.r_near, "r": s.r, "D_safe": s.D_safe, "samples": s.samples,
                     "time_limit": s.time_limit, "solver": s.solver, "stop_speed": s.stop_speed,
                     "duration": s.duration, "seed": s.seed, "monitor": monitor,
                     "controller": controller, "vehicle": dict(world.ego.vehicle), "safety": safety,
                     "assumptions": jsonable(world.assumptions)},
        "seed": s.seed,
        "versions": versions(),
        "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                    "cpus": cpus()},
        "timing_columns": list(timing_columns),
        "map_lines": map_lines(world),
        # who took part: with the built-in traffic the scenario's participants are all there are
        # (``monitor`` tells a run without participants from one that did not record them); another
        # engine brings its own mid-run, so the list would not be complete
        "participants": list(world.parts.ids) if t is None else None,
    }
