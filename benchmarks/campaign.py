"""Campaign figures: executor throughput and overhead, and falsification against random search.

1. **Throughput**: ``--runs`` (≥ 200) short closed-loop runs (``benchmarks/scenarios/short.yaml``,
   2 s simulated each) on ``--workers`` local processes, then on a Dask local cluster with as
   many single-threaded worker processes. Printed: runs per minute, the run itself (the
   simulation inside its worker, mean), the cost per run seen by the campaign (wall time ×
   workers / runs), and the executor's overhead per run (the difference: writing the concrete
   scenario, judging, scheduling, transfer, idle workers) against the run and against a 10 s run
   (target: ≤ 10 %). Workers are warmed up first (start-up is printed separately).
2. **Search**: on planted problems (``tests/scenarios/campaign/planted.yaml``: a parked car,
   speed × distance, about a fifth of the box fails; ``benchmarks/scenarios/parked.yaml``: speed ×
   distance × lateral offset, about 1 % fails), simulations to the first
   counterexample for CMA-ES, cross-entropy and uniform random search on the same budget, over
   ``--seeds`` seeds (a search that found none counts as budget + 1, shown as ">budget").
   Target: ≥ 3× fewer than random search.
3. **psy-taliro** (``pip install psy-taliro``, a benchmark-only reference): its dual annealing
   on the 3-d parked-car problem with the same objective, sequential, when it is installed.

    python benchmarks/campaign.py [--runs 200] [--workers 2] [--seeds 5] [--budget 120] [--skip-dask]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHORT = ROOT / "benchmarks" / "scenarios" / "short.yaml"
PROBLEMS = {"parked-2d": ROOT / "tests" / "scenarios" / "campaign" / "planted.yaml",
            "parked-3d": ROOT / "benchmarks" / "scenarios" / "parked.yaml"}


def _params(path: Path):  # noqa: ANN202
    from twolevel.world.loader import load_scenario

    scn, diags = load_scenario(path)
    if scn is None:
        sys.exit(f"{path}: {[d.message for d in diags]}")
    return scn.spec.parameters


def _throughput(executor, label: str, n: int, workers: int, tmp: Path) -> dict:  # noqa: ANN001
    from twolevel.campaign import sampling
    from twolevel.campaign.case import Case
    from twolevel.campaign.suite import run_cases

    params = _params(SHORT)
    warm = [Case(f"warm{i}", str(SHORT), p) for i, p in enumerate(sampling.random_points(params, 2 * workers, 99))]
    t0 = time.perf_counter()
    run_cases(warm, executor, tmp / f"{label}-warm", frames=False)
    start_up = time.perf_counter() - t0
    cases = [Case(f"#{i + 1:04d}", str(SHORT), p) for i, p in enumerate(sampling.random_points(params, n, 1))]
    t0 = time.perf_counter()
    res = run_cases(cases, executor, tmp / label, frames=False)
    wall = time.perf_counter() - t0
    run_s = statistics.fmean(r.run_s for r in res.results)
    cost = wall * workers / n
    bad = sum(1 for r in res.results if r.outcome == "error")
    return {"label": label, "runs": n, "errors": bad, "wall": wall, "per_min": 60 * n / wall, "run_s": run_s,
            "cost": cost, "overhead": cost - run_s, "start_up": start_up}


def throughput(n: int, workers: int, dask: bool) -> None:
    from twolevel.campaign.executor import make_executor

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        with make_executor(None, workers) as ex:
            rows.append(_throughput(ex, "local processes", n, workers, Path(tmp)))
        if dask:
            try:
                from distributed import LocalCluster
            except ImportError:
                print("dask.distributed is not installed: pip install 'twolevel[dask]'")
            else:
                with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, make_executor(cluster.scheduler_address) as ex:
                    rows.append(_throughput(ex, "dask local cluster", n, workers, Path(tmp)))
    print(f"\n== throughput: {n} short closed-loop runs (2 s simulated each) on {workers} workers")
    print(f"{'executor':22s} {'runs/min':>9s} {'run [s]':>8s} {'cost/run [s]':>13s} {'overhead/run [s]':>17s} "
          f"{'% of run':>9s} {'% of 10 s run':>14s} {'start-up [s]':>13s} {'errors':>7s}")
    for r in rows:
        print(f"{r['label']:22s} {r['per_min']:9.1f} {r['run_s']:8.3f} {r['cost']:13.3f} {r['overhead']:17.3f} "
              f"{100 * r['overhead'] / r['run_s']:9.1f} {100 * r['overhead'] / 10.0:14.2f} {r['start_up']:13.1f} {r['errors']:7d}")


def _first(problem: Path, optimizer: str, seed: int, budget: int, executor, tmp: Path) -> tuple[int | None, str]:  # noqa: ANN001
    from twolevel.campaign import falsify as F
    from twolevel.campaign.suite import run_cases
    from twolevel.verdict.judge import criteria_of
    from twolevel.world.loader import load_scenario

    scn, _ = load_scenario(problem)
    obj = F.parse_objective("at_fault", criteria_of(scn))
    runs = tmp / f"{problem.stem}-{optimizer}-{seed}"
    res = F.falsify(str(problem), scn.spec.parameters, obj, budget=budget, optimizer=optimizer, seed=seed,
                    run_batch=lambda cases: list(run_cases(cases, executor, runs, frames=False).results))
    return res.first, res.optimizer


def search(seeds: int, budget: int, workers: int) -> None:
    from twolevel.campaign.executor import make_executor

    print(f"\n== falsification: simulations to the first counterexample (at_fault), budget {budget}, seeds 0..{seeds - 1}")
    print(f"{'problem':10s} {'optimizer':10s} {'per seed':34s} {'median':>7s} {'mean':>7s} {'found':>6s}")
    with tempfile.TemporaryDirectory() as tmp, make_executor(None, workers) as ex:
        for name, path in PROBLEMS.items():
            medians = {}
            for optimizer in ("cma", "ce", "random"):
                firsts = [_first(path, optimizer, s, budget, ex, Path(tmp))[0] for s in range(seeds)]
                counts = [f if f is not None else budget + 1 for f in firsts]
                shown = " ".join(str(f) if f is not None else f">{budget}" for f in firsts)
                medians[optimizer] = statistics.median(counts)
                print(f"{name:10s} {optimizer:10s} {shown:34s} {statistics.median(counts):7.1f} {statistics.fmean(counts):7.1f} "
                      f"{sum(f is not None for f in firsts):3d}/{seeds}", flush=True)
            for optimizer in ("cma", "ce"):
                print(f"{name:10s} random / {optimizer}: {medians['random'] / medians[optimizer]:.2f}× fewer simulations "
                      "(medians; target ≥ 3×)")


def psytaliro(budget: int, seeds: int) -> None:
    print("\n== psy-taliro reference (dual annealing, sequential) on the 3-d parked-car problem")
    try:
        import staliro
        from staliro.optimizers import DualAnnealing
    except ImportError:
        print("psy-taliro is not installed (pip install psy-taliro): skipped")
        return
    from twolevel.campaign import falsify as F
    from twolevel.campaign.case import Case, run_case
    from twolevel.verdict.judge import criteria_of
    from twolevel.world.loader import load_scenario

    path = PROBLEMS["parked-3d"]
    scn, _ = load_scenario(path)
    obj = F.parse_objective("at_fault", criteria_of(scn))
    names = list(scn.spec.parameters)
    with tempfile.TemporaryDirectory() as tmp:
        firsts = []
        for seed in range(seeds):
            counter = {"n": 0}

            @staliro.costfunc
            def cost(inputs) -> float:  # noqa: ANN001
                counter["n"] += 1
                values = {k: float(inputs.static[k]) for k in names}
                r = run_case(Case(f"t{counter['n']}", str(path), values), f"{tmp}/{seed}-{counter['n']}", False, False)
                v = obj.of(r)
                return 1e6 if v != v else min(v, 1e6)

            bounds = {k: tuple(scn.spec.parameters[k].range) for k in names}
            opts = staliro.TestOptions(static_inputs=bounds, iterations=budget, runs=1, seed=seed + 1)  # it wants > 0
            runs = staliro.staliro(cost, DualAnnealing(min_cost=0.0), opts)
            costs = [e.cost for e in runs[0].evaluations]
            firsts.append(next((i + 1 for i, c in enumerate(costs) if c < 0), None))
        shown = " ".join(str(f) if f is not None else f">{budget}" for f in firsts)
        counts = [f if f is not None else budget + 1 for f in firsts]
        print(f"{'parked-3d':10s} {'psy-taliro':10s} {shown:34s} {statistics.median(counts):7.1f} {statistics.fmean(counts):7.1f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200, help="runs for the throughput figures (≥ 200)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--budget", type=int, default=120)
    ap.add_argument("--skip-dask", action="store_true")
    ap.add_argument("--only", choices=("throughput", "search", "psytaliro"), default=None)
    args = ap.parse_args(argv)
    if args.only in (None, "throughput"):
        throughput(args.runs, args.workers, not args.skip_dask)
    if args.only in (None, "search"):
        search(args.seeds, args.budget, args.workers)
    if args.only in (None, "psytaliro"):
        psytaliro(args.budget, min(args.seeds, 3))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
