"""Fuzzing campaigns: many generated inputs per target, in worker processes, tallied in order.

A *target* is a factory called once in each worker process (it loads what every input shares:
seed documents, a scratch folder) that returns the probe of one input: given the input's
:class:`random.Random` it generates the input, runs the stages and returns a :class:`Probe`.
Input ``i`` of a target is drawn from ``Random(f"{seed}:{target}:{i}")`` alone, so a campaign is
the same for a seed whatever the number of workers: results are merged in input order.

Each worker runs one input at a time. An input still running after ``timeout`` seconds is
stopped by an alarm inside the worker; a worker that does not answer ``grace`` seconds later
(stuck in compiled code that never returns to Python) is killed and replaced. Either way the
input counts as a hang, as does any input that took longer than :data:`HANG_S` of wall time (the
line printed for it gives its CPU time too: on a loaded machine the two differ); a worker that
dies (a crash of the interpreter, the kernel's out-of-memory killer) counts its input as an
internal error. With ``out``, the tally so far is written atomically to that JSON file every
``flush_s`` seconds and at the end (``status``: running, complete or interrupted), so an
interrupted campaign leaves a readable partial tally.

Only the standard library (and :mod:`twolevel.atomic`) is imported here; the targets import what
they need inside the workers.
"""

from __future__ import annotations

import multiprocessing
import os
import random
import signal
import time
from dataclasses import asdict, dataclass, field, replace
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any, Callable

__all__ = ["HANG_S", "Probe", "Tally", "Campaign", "run_campaign", "TARGETS", "HANG", "CRASH"]

HANG_S = 10.0
"""[s] An input whose stages took longer than this counts as a hang."""

HANG, CRASH = "hang", "worker-died"
"""Verdicts the campaign gives: an input stopped by the time limit, an input whose worker died."""


@dataclass(frozen=True)
class Probe:
    """One input's outcome: ``verdict`` ("refused", "accepted", or what broke the invariant),
    ``detail``, the input as ``text`` (sent back only when it broke the invariant or was slow),
    whether it was also planned and simulated (``ran``) and the CPU time its probe took [s]."""

    verdict: str
    detail: str = ""
    text: str = ""
    ran: bool = False
    cpu_s: float = 0.0


Target = Callable[[dict[str, Any]], Callable[[random.Random], Probe]]


@dataclass
class Tally:
    """Counts of one target's campaign and the inputs that broke the invariant. ``inputs`` are
    the first inputs (in order) whose outcome is known; ``load`` the 1-minute load average at the
    start and (so far) the end."""

    target: str
    requested: int
    inputs: int = 0
    refused: int = 0
    accepted: int = 0
    internal: int = 0
    nan_state: int = 0
    inconsistent: int = 0
    hangs: int = 0
    ran: int = 0
    seconds: float = 0.0
    load: tuple[float, float] = (0.0, 0.0)
    broken: list[str] = field(default_factory=list)

    def add(self, i: int, seed: int, probe: Probe, took: float, hang_s: float = HANG_S) -> str | None:
        """Count input ``i``'s outcome (it took ``took`` [s] of wall time; more than ``hang_s`` is a
        hang); the line describing it if it broke the invariant."""
        from twolevel.fuzz.rules import ACCEPTED, INCONSISTENT, INTERNAL, NAN_STATE, REFUSED
        from twolevel.fuzz.world import NAN_STATE as WORLD_NAN_STATE

        v = probe.verdict
        self.inputs += 1
        self.refused += v == REFUSED
        self.accepted += v == ACCEPTED
        self.internal += v in (INTERNAL, CRASH)
        self.nan_state += v in (NAN_STATE, WORLD_NAN_STATE)
        self.inconsistent += v == INCONSISTENT
        self.ran += probe.ran
        hang = v == HANG or took > hang_s
        self.hangs += hang
        if v in (REFUSED, ACCEPTED) and not hang:
            return None
        line = (f"{self.target} #{i} (seed {seed}): {v}, {took:.1f} s ({probe.cpu_s:.1f} s CPU): "
                f"{probe.text[:300]!r}\n    {probe.detail}")
        self.broken.append(line)
        return line


# ------------------------------------------------------------------------------------ targets


def _rules(options: dict[str, Any]) -> Callable[[random.Random], Probe]:
    from twolevel.fuzz.rules import generate, probe

    def one(rnd: random.Random) -> Probe:
        text = generate(rnd)
        out = probe(text, dt=rnd.choice([None, 0.1]), horizon=rnd.choice([None, 10]), seed=rnd.randrange(10**6))
        return Probe(out.verdict, out.detail, text)

    return one


def _traces(options: dict[str, Any]) -> Callable[[random.Random], Probe]:
    from twolevel.fuzz.traces import PLAIN, generate, probe, write

    folder = options["scratch"]
    variants = int(options.get("variants", 3))

    def one(rnd: random.Random) -> Probe:
        case = generate(rnd)
        out = probe(case, variants=variants, seed=rnd.randrange(10**6), folder=folder)
        text = write(case, PLAIN, random.Random(0)).decode() + "\n" + case.rules
        return Probe(out.verdict, out.detail, text)

    return one


def _world(options: dict[str, Any]) -> Callable[[random.Random], Probe]:
    from twolevel.fuzz.mutation import dump
    from twolevel.fuzz.world import ACCEPTED, generate, load_seed, probe, shipped_seeds, write_case

    root = Path(options["root"])
    seeds = shipped_seeds(root) + [load_seed(root / "tests/world/fuzz_seeds/scenario.yaml")]
    run_every = int(options.get("run_every", 1))
    scratch = Path(options["scratch"])

    def one(rnd: random.Random) -> Probe:
        k = rnd.randrange(len(seeds))
        case = generate(seeds[k], rnd)
        run = rnd.randrange(run_every) == 0  # drawn for every input: the same whatever the workers
        solver = rnd.choice(["modes", "highs"])
        scenario = write_case(case, scratch / str(k))  # one folder per seed: its rule files stay
        out = probe(scenario, run=False)
        ran = out.verdict == ACCEPTED and run
        if ran:
            out = probe(scenario, run=True, solver=solver)
        text = f"# {case}\n# scenarios/s.yaml\n{dump(case.scenario)}# maps/m.yaml\n{dump(case.map)}"
        return Probe(out.verdict, out.detail, text, ran)

    return one


TARGETS: dict[str, Target] = {"rules": _rules, "traces": _traces, "world": _world}
"""The targets by name (:mod:`twolevel.fuzz.rules`, :mod:`~twolevel.fuzz.traces`,
:mod:`~twolevel.fuzz.world`); ``world`` plans and simulates an accepted input with probability
1/``run_every`` (drawn per input)."""


# ------------------------------------------------------------------------------------ workers


class _Alarm(BaseException):
    pass


_probing = False
"""A worker is inside an input's probe (the alarm interrupts only that)."""


def _alarm(signum: int, frame: object) -> None:
    if _probing:
        raise _Alarm()


def _worker(conn: Connection, name: str, target: Target, seed: int, timeout: float, hang_s: float,
            options: dict[str, Any], scratch: str) -> None:
    """A worker's loop: receive an input's index, send back (index, probe, seconds); stop on None.
    The input's text goes back only when it broke the invariant or took longer than ``hang_s``."""
    global _probing
    from twolevel.fuzz.rules import ACCEPTED, REFUSED
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops the workers (a terminal's Ctrl-C reaches all)
    signal.signal(signal.SIGALRM, _alarm)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # solver banners printed from compiled code would interleave with the tally
    os.close(devnull)
    one = target({**options, "scratch": scratch})
    while True:
        try:
            i = conn.recv()
        except EOFError:
            return
        if i is None:
            return
        rnd = random.Random(f"{seed}:{name}:{i}")
        t0, c0 = time.perf_counter(), time.process_time()
        signal.setitimer(signal.ITIMER_REAL, timeout)
        try:
            _probing = True
            probe = one(rnd)
            _probing = False
        except _Alarm:
            probe = Probe(HANG, f"still running after {timeout:g} s (stopped by the alarm)")
        except Exception as exc:  # noqa: BLE001 - a target's own failure is an internal error of the input
            probe = Probe(CRASH, f"the probe raised {type(exc).__name__}: {exc}")
        finally:
            _probing = False
            signal.setitimer(signal.ITIMER_REAL, 0)
        took = time.perf_counter() - t0
        keep = probe.text if probe.verdict not in (REFUSED, ACCEPTED) or took > hang_s else ""
        conn.send((i, replace(probe, text=keep, cpu_s=time.process_time() - c0), took))


@dataclass
class _Slot:
    process: Any
    conn: Connection
    index: int | None = None
    started: float = 0.0


@dataclass
class Campaign:
    """How a campaign runs: ``jobs`` worker processes, an input stopped after ``timeout`` [s]
    (its worker killed ``grace`` [s] later; one taking more than ``hang_s`` [s] is a hang), the tally written to ``out`` every ``flush_s`` [s],
    broken inputs written into ``keep``, ``options`` for the targets (``root``: the repository,
    ``variants``, ``run_every``), ``scratch``: a folder for the workers' files."""

    seed: int = 0
    jobs: int = 1
    timeout: float = 120.0
    grace: float = 10.0
    hang_s: float = HANG_S
    out: Path | None = None
    flush_s: float = 5.0
    keep: Path | None = None
    scratch: Path | None = None
    options: dict[str, Any] = field(default_factory=dict)
    report: Callable[[str], None] = print
    tallies: list[Tally] = field(default_factory=list)
    status: str = "running"

    def write(self) -> None:
        """The tally so far into ``out`` (atomically), if given."""
        if self.out is None:
            return
        from twolevel.atomic import write_json_atomic

        write_json_atomic(self.out, {
            "status": self.status, "seed": self.seed, "jobs": self.jobs, "timeout": self.timeout, "hang_s": self.hang_s,
            "options": {k: v for k, v in self.options.items() if k != "root"},
            "updated": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "targets": [asdict(t) for t in self.tallies],
        })


def _start(ctx: Any, name: str, target: Target, c: Campaign, scratch: str) -> _Slot:
    parent, child = ctx.Pipe()
    p = ctx.Process(target=_worker, args=(child, name, target, c.seed, c.timeout, c.hang_s, c.options, scratch), daemon=True)
    p.start()
    child.close()
    return _Slot(p, parent)


def _stop(slot: _Slot) -> None:
    if slot.process.is_alive():
        slot.process.kill()
    slot.process.join(5)
    slot.conn.close()


def run_campaign(name: str, inputs: int, c: Campaign, target: Target | None = None) -> Tally:
    """``inputs`` inputs of the target ``name`` (:data:`TARGETS`, or ``target``) under ``c``;
    the tally is appended to ``c.tallies`` at once and kept up to date (see the module docstring).
    A ``KeyboardInterrupt`` stops the workers and propagates, the tally written as it stands."""
    import tempfile

    target = target or TARGETS[name]
    tally = Tally(name, inputs, load=(os.getloadavg()[0],) * 2)
    c.tallies.append(tally)
    ctx = multiprocessing.get_context("spawn")
    start = time.perf_counter()
    done: dict[int, tuple[Probe, float]] = {}
    next_i = 0
    last_write = 0.0
    with tempfile.TemporaryDirectory(prefix=f"fuzz-{name}-", dir=c.scratch) as scratch:
        slots: list[_Slot] = []
        jobs = max(1, min(c.jobs, inputs))
        try:
            slots = [_start(ctx, name, target, c, os.path.join(scratch, str(k))) for k in range(jobs)]
            while tally.inputs < inputs:
                for k, slot in enumerate(slots):
                    if slot.index is None and next_i < inputs:
                        try:
                            slot.conn.send(next_i)
                        except OSError:  # a dead worker: its pipe reads as ended below
                            pass
                        slot.index, slot.started = next_i, time.perf_counter()
                        next_i += 1
                busy = [s for s in slots if s.index is not None]
                ready = wait([s.conn for s in busy], timeout=0.5)
                now = time.perf_counter()
                for k, slot in enumerate(slots):
                    if slot.index is None:
                        continue
                    if slot.conn in ready:
                        try:
                            i, probe, took = slot.conn.recv()
                        except (EOFError, OSError):
                            slot.process.join(5)
                            i, probe, took = slot.index, Probe(CRASH, f"the worker died (exit code "
                                                                     f"{slot.process.exitcode})"), now - slot.started
                        else:
                            done[i] = (probe, took)
                            slot.index = None
                            continue
                    elif now - slot.started > c.timeout + c.grace:
                        i, probe, took = slot.index, Probe(HANG, f"no answer after {now - slot.started:.0f} s: "
                                                                 f"the worker was killed"), now - slot.started
                    else:
                        continue
                    done[i] = (probe, took)  # a dead or stuck worker: replaced by a fresh one
                    _stop(slot)
                    slots[k] = _start(ctx, name, target, c, os.path.join(scratch, f"{k}-{i}"))
                while tally.inputs in done:
                    i = tally.inputs
                    probe, took = done.pop(i)
                    line = tally.add(i, c.seed, probe, took, c.hang_s)
                    if line is not None:
                        c.report(line)
                        if c.keep is not None:
                            (c.keep / f"{name}-{c.seed}-{i}.txt").write_text(f"{probe.text}\n\n{probe.detail}\n",
                                                                            encoding="utf-8")
                tally.seconds = time.perf_counter() - start
                tally.load = (tally.load[0], os.getloadavg()[0])
                if now - last_write >= c.flush_s:
                    c.write()
                    last_write = now
        finally:
            for slot in slots:
                if slot.index is None and slot.process.is_alive():
                    try:
                        slot.conn.send(None)
                    except OSError:
                        pass
                    slot.process.join(2)
                _stop(slot)
            tally.seconds = time.perf_counter() - start
            tally.load = (tally.load[0], os.getloadavg()[0])
            c.write()
    return tally
