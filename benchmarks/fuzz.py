"""Long fuzzing campaigns: generate inputs per target and count what the toolchain did with them.

    python benchmarks/fuzz.py                          # every target, 500 inputs each
    python benchmarks/fuzz.py --target rules --inputs 100000 --seed 3 --keep fuzz-failures
    python benchmarks/fuzz.py --target world --inputs 20000 --run-every 20 --jobs 2 --out world.json
    python benchmarks/fuzz.py --target rules=40000 --target traces=45000 --target world=15000 --out fuzz.json

The campaign (:mod:`twolevel.fuzz.campaign`) runs ``--jobs`` worker processes; input ``i`` of a
target depends only on (``--seed``, the target, ``i``), and results are counted in input order, so
the table is the same for a seed whatever ``--jobs``. The table prints, per target: inputs,
inputs answered with diagnostics (refused), accepted, accepted inputs also planned and simulated
(ran), internal errors (a worker that died included), NaN states, inconsistent results (positions
outside the input, findings or verdicts that change with the formatting, a printed rule file that
parses back differently), hangs (an input whose stages took more than 10 s; one still running after
``--timeout`` seconds is stopped — by an alarm, or by killing its worker — and counted), seconds,
inputs per second and the 1-minute load average at the target's start and end. Every broken input
is printed (and, with ``--keep DIR``, written there to reproduce). With ``--out FILE`` the tally
is written to that JSON file (atomically, every few seconds and at the end), so an interrupted
campaign (Ctrl-C, SIGTERM, SIGHUP: exit 128 + the signal's number) leaves its partial tally there.
The invariant: a diagnostic or a valid result, never an internal error, a NaN state or a hang.

Targets:
- ``rules``: rule-file text (:mod:`twolevel.fuzz.rules`): files written from the grammar and
  mangled; ``check`` under three line-ending conventions, every renderer, printing back, and the
  monitor over a short trace for what ``check`` accepts.
- ``traces``: trace CSVs (:mod:`twolevel.fuzz.traces`): ``monitor`` on a drive written plainly,
  in ``--variants`` other formats (which must give the same verdicts) and once mangled.
- ``world``: maps and scenarios (:mod:`twolevel.fuzz.world`): the shipped scenarios and
  tests/world/fuzz_seeds/ mutated field-wise; ``check`` on each, and for what it accepts loading
  and the built world, and (one in ``--run-every``, drawn per input) ``plan`` and
  ``simulate --duration 2`` with no NaN in any vehicle's state ("ran" counts those).
"""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _target(text: str) -> tuple[str, int | None]:
    name, _, count = text.partition("=")
    from twolevel.fuzz.campaign import TARGETS

    if name not in TARGETS:
        raise argparse.ArgumentTypeError(f"unknown target {name!r} (choose from {', '.join(sorted(TARGETS))})")
    return name, int(count) if count else None


def _table(tallies: list) -> str:
    from twolevel.fuzz.campaign import HANG_S

    head = ("target", "inputs", "refused", "accepted", "ran", "internal", "nan-state", "inconsistent",
            f"hangs>{HANG_S:g}s", "seconds", "inputs/s", "load")
    rows = [" ".join(f"{h:>12}" for h in head)]
    for t in tallies:
        cells = (t.target, f"{t.inputs}/{t.requested}" if t.inputs < t.requested else t.inputs, t.refused,
                 t.accepted, t.ran, t.internal, t.nan_state, t.inconsistent, t.hangs, f"{t.seconds:.0f}",
                 f"{t.inputs / t.seconds:.1f}" if t.seconds else "-", f"{t.load[0]:.1f}→{t.load[1]:.1f}")
        rows.append(" ".join(f"{c:>12}" for c in cells))
    total = sum(t.inputs for t in tallies)
    rows.append(f"{'total':>12} {total:>12}")
    return "\n".join(rows)


def _raise(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(signum)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--target", type=_target, action="append", metavar="NAME[=INPUTS]",
                    help="a target, with its own number of inputs (default: every target)")
    ap.add_argument("--inputs", type=int, default=500, help="inputs per target (unless given with it)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=1, metavar="N", help="worker processes")
    ap.add_argument("--variants", type=int, default=3, metavar="N", help="traces: other formats per drive")
    ap.add_argument("--run-every", type=int, default=1, metavar="N",
                    help="world: plan and simulate one accepted input in N (1: all)")
    ap.add_argument("--timeout", type=float, default=120.0, metavar="SECONDS", help="stop an input after this long")
    ap.add_argument("--out", type=Path, metavar="FILE", help="write the tally (JSON) there as it grows")
    ap.add_argument("--keep", type=Path, metavar="DIR", help="write every broken input into DIR")
    args = ap.parse_args()
    from twolevel.fuzz.campaign import TARGETS, Campaign, run_campaign

    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
    campaign = Campaign(seed=args.seed, jobs=args.jobs, timeout=args.timeout, out=args.out, keep=args.keep,
                        options={"root": str(REPO), "variants": args.variants, "run_every": args.run_every},
                        report=lambda line: print(line, flush=True))
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _raise)
    code = 0
    try:
        for name, count in args.target or [(n, None) for n in sorted(TARGETS)]:
            run_campaign(name, args.inputs if count is None else count, campaign)
        campaign.status = "complete"
    except KeyboardInterrupt as exc:
        campaign.status = "interrupted"
        code = 128 + (exc.args[0] if exc.args and isinstance(exc.args[0], int) else signal.SIGINT)
    campaign.write()
    print(_table(campaign.tallies), flush=True)
    if campaign.status == "interrupted":
        print(f"interrupted: the tally above is partial{f' (also in {args.out})' if args.out else ''}",
              file=sys.stderr)
    sys.exit(code or (1 if any(t.broken for t in campaign.tallies) else 0))


if __name__ == "__main__":
    main()
