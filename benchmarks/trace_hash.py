"""Fingerprints of closed-loop behaviour: one hash per scenario of its trace and summary.

A refactoring that keeps behaviour identical keeps these hashes. For each scenario (the paper's
four by default) the run is simulated into a temporary folder; the hash covers every column of
``trace.csv`` except the wall-clock ones (``TIMING_COLUMNS``) and the ``summary`` of ``run.json``
without its timing figures. Prints ``name hash`` lines; compare the output of two checkouts with
``diff``. Not a test: the plans depend on the solver's time limit only when a step runs out of
time, which does not happen on the paper's scenarios on a quiet machine.

    python benchmarks/trace_hash.py [--duration S] [--drop COL,...] [scenario ...]
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import sys
import tempfile
from pathlib import Path

from twolevel.sim.engine import TIMING_COLUMNS, simulate_scenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ("traffic_rules", "safety", "scalability", "comparison")
#: Parts of the names of summary entries that are wall-clock figures or paths (they differ from run
#: to run): step times, wall time, real-time ratio, control rate, steps over budget, the run dir.
TIMING_KEYS = ("_ms", "wall_time", "realtime", "rate_hz", "over_budget", "run_dir")


def _strip_timing(value: object) -> object:
    if isinstance(value, dict):
        return {k: _strip_timing(v) for k, v in value.items()
                if not any(key in k for key in TIMING_KEYS)}
    if isinstance(value, list):
        return [_strip_timing(v) for v in value]
    return value


def fingerprint(run_dir: Path, drop: tuple[str, ...] = ()) -> str:
    """SHA-256 over the trace without its wall-clock columns (and the columns ``drop``) and the
    summary without timings."""
    h = hashlib.sha256()
    with open(run_dir / "trace.csv", newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        keep = [i for i, name in enumerate(header) if name not in TIMING_COLUMNS and name not in drop]
        for row in [header, *reader]:
            h.update(",".join(row[i] for i in keep).encode())
            h.update(b"\n")
    summary = json.loads((run_dir / "run.json").read_text(encoding="utf-8")).get("summary", {})
    h.update(json.dumps(_strip_timing(summary), sort_keys=True).encode())
    return h.hexdigest()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--duration", type=float, default=None, help="override each run's duration [s]")
    ap.add_argument("--drop", default="", help="columns left out, comma-separated (compare with a reference "
                    "taken before they were added)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenarios:
            path = ROOT / "scenarios" / f"{name}.yaml" if "/" not in name else Path(name)
            out = Path(tmp) / Path(name).stem
            summary, diags = simulate_scenario(str(path), str(out), duration=args.duration, frames=False)
            if summary is None:
                print(f"{name} failed: {[d.message for d in diags]}", file=sys.stderr)
                return 1
            drop = tuple(c for c in args.drop.split(",") if c)
            print(f"{Path(name).stem} {fingerprint(out, drop)}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
