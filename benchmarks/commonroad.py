"""CommonRoad scenarios imported and driven: one line per scenario, a summary, and the import time
of a 500-lanelet network (target < 2 s).

    python benchmarks/commonroad.py [DIR] [--rules R.stl ...] [--duration S] [--lanelets N]

Every ``*.xml`` below DIR that is a CommonRoad scenario is imported (``twolevel import``'s
conversion), checked, and simulated with the two-level controller and the safety layer. Without
DIR, the generated samples (:mod:`twolevel.interop.commonroad_samples`: straight, curve, merge,
signalised and stop-sign intersections) are written to a temporary folder and used. Columns:
the import's time [ms] and findings (IMP710 not converted / IMP714 approximated), lanes and
participants, the goal (reached at [s], or missed), at-fault collisions, each rule's verdict
(``rule✓``/``rule✗``: held / violated somewhere), the control step's wall time p50 / p99 [ms].
Needs commonroad-io (``pip install 'twolevel[commonroad]'``).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# this file's own folder first on sys.path would make `import commonroad` import this script
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
DEFAULT_RULES = [ROOT / "rules" / f"{name}.stl" for name in ("speed_limit", "stop_sign", "red_light")]


def _scenarios(folder: Path) -> list[Path]:
    from twolevel.interop import format_of

    return sorted(p for p in folder.rglob("*.xml") if (f := format_of(p)) is not None and f.name == "CommonRoad")


def _one(xml: Path, out: Path, rules: list[str], duration: float | None) -> dict:
    from twolevel.interop import import_file
    from twolevel.sim.engine import simulate_scenario

    t0 = time.perf_counter()
    res = import_file(xml, out, rules=rules)
    import_ms = 1e3 * (time.perf_counter() - t0)
    row: dict = {"name": xml.stem, "import_ms": import_ms,
                 "710": sum(d.code == "IMP710" for d in res.diagnostics),
                 "714": sum(d.code == "IMP714" for d in res.diagnostics),
                 "errors": [f"{d.code} {d.message}" for d in res.diagnostics if d.is_error]}
    if not res.written or row["errors"]:
        return row
    import yaml

    m = yaml.safe_load((out / "map.yaml").read_text())
    sc = yaml.safe_load((out / "scenario.yaml").read_text())
    row.update(lanes=len(m["lanes"]), parts=len(sc.get("participants", [])))
    summary, diags = simulate_scenario(str(out / "scenario.yaml"), str(out / "run"), duration=duration, frames=False)
    if summary is None:
        row["errors"] = [f"{d.code} {d.message}" for d in diags if d.is_error]
        return row
    from twolevel.verdict.judge import judge_run

    verdict, _ = judge_run(out / "run")
    crit = {c.name: c for c in (verdict.criteria if verdict is not None else ())}
    goal = crit.get("goal")
    row.update(goal=goal.measured if goal is not None and goal.passed else None, at_fault=summary.at_fault,
               goal_detail=goal.detail if goal is not None else "", rules={n[5:]: c.passed for n, c in crit.items() if n.startswith("rule:")},
               p50=summary.step_ms_median, p99=summary.step_ms_p99)
    return row


def _print(row: dict) -> None:
    head = f"{row['name']:<34} {row['import_ms']:>7.0f} {row['442']:>4} {row['443']:>4}"
    if row["errors"]:
        print(f"{head}  NOT IMPORTED: {'; '.join(row['errors'])[:160]}", flush=True)
        return
    goal = "missed" if row.get("goal") is None else f"{row['goal']:.1f} s"
    rules = " ".join(f"{k}{'✓' if v else '✗'}" for k, v in row.get("rules", {}).items())
    print(f"{head} {row['lanes']:>5} {row['parts']:>5} {goal:>8} {row['at_fault']:>5} "
          f"{row['p50']:>6.1f} {row['p99']:>6.1f}  {rules}", flush=True)


def _big(n: int, folder: Path) -> None:
    from twolevel.interop.commonroad import import_commonroad
    from twolevel.interop.commonroad_samples import grid_network

    path = grid_network(n, folder / f"ZAM_Grid{n}.xml")
    times, cpus = [], []
    for _ in range(3):
        t0, c0 = time.perf_counter(), time.process_time()
        imp, diags = import_commonroad(path)
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    assert imp is not None, diags
    print(f"\n{n}-lanelet network ({path.stat().st_size / 1e6:.2f} MB, {len(imp.map['lanes'])} lanes): import "
          f"best {min(times):.2f} s wall / {min(cpus):.2f} s CPU, worst {max(times):.2f} s wall (target < 2 s; "
          f"load {os.getloadavg()[0]:.1f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", nargs="?", help="folder searched for CommonRoad XML files (default: generated samples)")
    ap.add_argument("--rules", nargs="*", default=[str(p) for p in DEFAULT_RULES], help="rule files every scenario lists")
    ap.add_argument("--duration", type=float, default=None, help="override every run's duration [s]")
    ap.add_argument("--lanelets", type=int, default=500, help="size of the generated network timed for import (0: skip)")
    args = ap.parse_args()
    try:
        import commonroad  # noqa: F401
    except ImportError:
        sys.exit("needs commonroad-io: pip install 'twolevel[commonroad]'")
    work = Path(tempfile.mkdtemp(prefix="commonroad_bench_"))
    if args.dir:
        folder = Path(args.dir)
    else:
        from twolevel.interop.commonroad_samples import write_samples

        folder = work / "samples"
        write_samples(folder)
    files = _scenarios(folder)
    print(f"{len(files)} CommonRoad scenario(s) below {folder}; runs in {work}; load {os.getloadavg()[0]:.1f}")
    print(f"{'scenario':<34} {'imp ms':>7} {'442':>4} {'443':>4} {'lanes':>5} {'parts':>5} {'goal':>8} {'fault':>5} "
          f"{'p50':>6} {'p99':>6}  rules")
    rows = []
    for k, xml in enumerate(files):
        row = _one(xml, work / f"{k:03d}_{xml.stem}", args.rules, args.duration)
        rows.append(row)
        _print(row)
    done = [r for r in rows if not r["errors"]]
    print(f"\n{len(done)}/{len(rows)} imported and simulated; goal reached in "
          f"{sum(r.get('goal') is not None for r in done)}; at-fault collisions {sum(r.get('at_fault', 0) for r in done)}; "
          f"runs with a rule violated {sum(not all(r.get('rules', {}).values()) for r in done)}; findings "
          f"IMP710 {sum(r['710'] for r in rows)}, IMP714 {sum(r['714'] for r in rows)}; worst step p99 "
          f"{max((r['p99'] for r in done), default=float('nan')):.1f} ms")
    if args.lanelets:
        _big(args.lanelets, work)


if __name__ == "__main__":
    main()
