"""Long fuzzing campaigns: generate inputs per target and count what the toolchain did with them.

    python benchmarks/fuzz.py                          # every target, 500 inputs each
    python benchmarks/fuzz.py --target rules --inputs 100000 --seed 3 --keep fuzz-failures
    python benchmarks/fuzz.py --target world --inputs 20000 --run-every 20

One function per target returns a :class:`Tally`; the table prints, per target: inputs, inputs
answered with diagnostics (refused), accepted, internal errors, NaN states, inconsistent results
(positions outside the input, findings or verdicts that change with the formatting, a printed rule
file that parses back differently), and hangs (an input whose stages took more than 10 s; one still
running after ``--timeout`` seconds is stopped and counted). Every broken input is printed (and,
with ``--keep DIR``, written there to reproduce). The invariant: a diagnostic or a valid result,
never an internal error, a NaN state or a hang. Deterministic for a seed.

Targets:
- ``rules``: rule-file text (:mod:`twolevel.fuzz.rules`): files written from the grammar and
  mangled; ``check`` under three line-ending conventions, every renderer, printing back, and the
  monitor over a short trace for what ``check`` accepts.
- ``traces``: trace CSVs (:mod:`twolevel.fuzz.traces`): ``monitor`` on a drive written plainly,
  in ``--variants`` other formats (which must give the same verdicts) and once mangled.
- ``world``: maps and scenarios (:mod:`twolevel.fuzz.world`): the shipped scenarios and
  tests/world/fuzz_seeds/ mutated field-wise; ``check`` on each, and for what it accepts loading
  and the built world, and (every ``--run-every``-th) ``plan`` and ``simulate --duration 2`` with
  no NaN in any vehicle's state ("ran" counts those).
"""

from __future__ import annotations

import argparse
import random
import signal
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

REPO = Path(__file__).resolve().parents[1]
HANG_S = 10.0  # [s] an input taking longer than this counts as a hang


@dataclass
class Tally:
    """Counts of one target's campaign and the inputs that broke the invariant."""

    inputs: int = 0
    refused: int = 0
    accepted: int = 0
    internal: int = 0
    nan_state: int = 0
    inconsistent: int = 0
    hangs: int = 0
    ran: int = 0  # accepted inputs also planned and simulated
    seconds: float = 0.0
    broken: list[str] = field(default_factory=list)


class _Timeout(Exception):
    pass


def _alarm(signum: int, frame: object) -> None:
    raise _Timeout()


def _campaign(name: str, inputs: int, seed: int, timeout: float, keep: Path | None,
              one: Callable[[random.Random], tuple[object, str, str]]) -> Tally:
    """Run ``one`` (input → outcome verdict, detail, the input as text) on ``inputs`` draws."""
    from twolevel.fuzz.rules import ACCEPTED, INCONSISTENT, INTERNAL, NAN_STATE, REFUSED
    from twolevel.fuzz.world import NAN_STATE as WORLD_NAN_STATE

    tally = Tally()
    start = time.perf_counter()
    signal.signal(signal.SIGALRM, _alarm)
    for i in range(inputs):
        rnd = random.Random(f"{seed}:{i}")
        text = ""
        t0 = time.perf_counter()
        signal.setitimer(signal.ITIMER_REAL, timeout)
        try:
            verdict, detail, text = one(rnd)  # type: ignore[assignment]
        except _Timeout:
            verdict, detail = "hang", f"still running after {timeout:g} s"
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        took = time.perf_counter() - t0
        tally.inputs += 1
        tally.refused += verdict == REFUSED
        tally.accepted += verdict == ACCEPTED
        tally.internal += verdict == INTERNAL
        tally.nan_state += verdict in (NAN_STATE, WORLD_NAN_STATE)
        tally.inconsistent += verdict == INCONSISTENT
        hang = verdict == "hang" or took > HANG_S
        tally.hangs += hang
        if verdict not in (REFUSED, ACCEPTED) or hang:
            line = f"{name} #{i} (seed {seed}): {verdict}, {took:.1f} s: {text[:300]!r}\n    {detail}"
            tally.broken.append(line)
            print(line, flush=True)
            if keep is not None:
                (keep / f"{name}-{seed}-{i}.txt").write_text(f"{text}\n\n{detail}\n", encoding="utf-8")
    tally.seconds = time.perf_counter() - start
    return tally


def fuzz_rules(inputs: int, seed: int, *, timeout: float = 120.0, keep: Path | None = None) -> Tally:
    """Rule-file text: ``inputs`` generated files, each checked under LF, CRLF and CR, rendered,
    printed back and (when accepted) monitored."""
    from twolevel.fuzz.rules import generate, probe

    def one(rnd: random.Random) -> tuple[str, str, str]:
        text = generate(rnd)
        out = probe(text, dt=rnd.choice([None, 0.1]), horizon=rnd.choice([None, 10]), seed=rnd.randrange(10**6))
        return out.verdict, out.detail, text

    return _campaign("rules", inputs, seed, timeout, keep, one)


def fuzz_traces(inputs: int, seed: int, *, timeout: float = 120.0, keep: Path | None = None,
                variants: int = 3) -> Tally:
    """Trace CSVs: ``inputs`` generated drives, each monitored plainly, in ``variants`` other
    formats and once mangled."""
    from twolevel.fuzz.traces import PLAIN, generate, probe, write

    def one(rnd: random.Random) -> tuple[str, str, str]:
        case = generate(rnd)
        out = probe(case, variants=variants, seed=rnd.randrange(10**6))
        text = write(case, PLAIN, random.Random(0)).decode() + "\n" + case.rules
        return out.verdict, out.detail, text

    return _campaign("traces", inputs, seed, timeout, keep, one)


def fuzz_world(inputs: int, seed: int, *, timeout: float = 120.0, keep: Path | None = None,
               run_every: int = 1) -> Tally:
    """Maps and scenarios: ``inputs`` mutated seeds, each checked; what check accepts is loaded
    and built, and every ``run_every``-th of those planned and simulated for 2 s."""
    from twolevel.fuzz.mutation import dump
    from twolevel.fuzz.world import ACCEPTED, generate, load_seed, probe, shipped_seeds, write_case

    seeds = shipped_seeds(REPO) + [load_seed(REPO / "tests/world/fuzz_seeds/scenario.yaml")]
    accepted = [0]

    def one(rnd: random.Random) -> tuple[str, str, str]:
        case = generate(rnd.choice(seeds), rnd)
        text = f"# {case}\n# scenarios/s.yaml\n{dump(case.scenario)}# maps/m.yaml\n{dump(case.map)}"
        with tempfile.TemporaryDirectory() as d:
            scenario = write_case(case, d)
            out = probe(scenario, run=False)
            if out.verdict == ACCEPTED:
                accepted[0] += 1
                if accepted[0] % run_every == 0:
                    out = probe(scenario, run=True, solver=rnd.choice(["modes", "highs"]))
        return out.verdict, out.detail, text

    tally = _campaign("world", inputs, seed, timeout, keep, one)
    tally.ran = accepted[0] // run_every
    return tally


TARGETS: dict[str, Callable[..., Tally]] = {"rules": fuzz_rules, "traces": fuzz_traces, "world": fuzz_world}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--target", choices=sorted(TARGETS), action="append", help="a target (default: all)")
    ap.add_argument("--inputs", type=int, default=500, help="inputs per target")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--variants", type=int, default=3, metavar="N", help="traces: other formats per drive")
    ap.add_argument("--run-every", type=int, default=1, metavar="N",
                    help="world: plan and simulate every N-th accepted input (1: all)")
    ap.add_argument("--timeout", type=float, default=120.0, metavar="SECONDS", help="stop an input after this long")
    ap.add_argument("--keep", type=Path, metavar="DIR", help="write every broken input into DIR")
    args = ap.parse_args()
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.target or sorted(TARGETS):
        kwargs = {"traces": {"variants": args.variants}, "world": {"run_every": args.run_every}}.get(name, {})
        t = TARGETS[name](args.inputs, args.seed, timeout=args.timeout, keep=args.keep, **kwargs)
        rows.append((name, t))
    head = ("target", "inputs", "refused", "accepted", "ran", "internal", "nan-state", "inconsistent",
            f"hangs>{HANG_S:g}s", "inputs/s")
    print(" ".join(f"{h:>12}" for h in head))
    for name, t in rows:
        cells = (name, t.inputs, t.refused, t.accepted, t.ran, t.internal, t.nan_state, t.inconsistent, t.hangs,
                 f"{t.inputs / t.seconds:.1f}" if t.seconds else "-")
        print(" ".join(f"{c:>12}" for c in cells))
    if any(t.broken for _, t in rows):
        sys.exit(1)


if __name__ == "__main__":
    main()
