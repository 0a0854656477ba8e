"""Falsification: search a scenario's parameters for a run that breaks a criterion.

The **objective** is a robustness to minimise, read from the run's verdict (a margin: ≥ 0
passes, < 0 is a counterexample):

* ``rule:NAME`` — the rule's worst robustness over the run;
* ``at_fault`` — the at-fault collision margin (the ``no_collision`` criterion);
* ``criterion:NAME`` — any criterion's margin (``goal``, ``on_road``, ``max_decel``, …);
* ``verdict`` — the smallest margin of all the scenario's criteria.

The search runs in the unit box of the parameters (:mod:`twolevel.campaign.sampling`), one batch
at a time on the executor: **CMA-ES** (the ``cma`` package; ``pip install twolevel[falsify]``),
a **cross-entropy** method (no dependency; the fallback when ``cma`` is absent), or uniform
**random** search (the baseline). It stops after the batch holding the first counterexample
(the first in the order the runs were asked for, so the count does not depend on which worker
finished first) or when the budget of simulations is spent. Deterministic for a seed.
"""

from __future__ import annotations

import math
import os
import shutil
import signal
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Protocol, Sequence

import numpy as np

from twolevel.campaign.case import Case, CaseResult
from twolevel.campaign.sampling import values_at
from twolevel.world.schema import Parameter

__all__ = ["Objective", "parse_objective", "Search", "make_search", "falsify", "record", "FalsifyResult", "OPTIMIZERS",
           "ObjectiveError"]

OPTIMIZERS = ("cma", "ce", "random")
_BIG = 1e6  # stands in for +inf (a criterion that cannot be violated here) in the optimisers


class ObjectiveError(ValueError):
    """An objective that names nothing the scenario judges; the message says what exists."""


@dataclass(frozen=True)
class Objective:
    """Which margin of a run's verdict to minimise (``criterion`` None: the smallest of all)."""

    text: str
    criterion: str | None

    def of(self, result: CaseResult) -> float:
        """The objective's value for a run; NaN when the run could not be judged."""
        if result.outcome == "error" or not result.margins:
            return math.nan
        if self.criterion is None:
            return min(result.margins.values())
        return result.margins.get(self.criterion, math.nan)


def parse_objective(text: str, criteria: Sequence[str]) -> Objective:
    """The objective named by ``text`` (see the module), checked against the ``criteria`` the
    scenario judges. Raises :class:`ObjectiveError`."""
    text = text.strip()
    if text == "verdict":
        return Objective(text, None)
    if text == "at_fault":
        name = "no_collision"
    elif text.startswith("rule:"):
        name = text
    elif text.startswith("criterion:"):
        name = text.split(":", 1)[1]
    else:
        raise ObjectiveError(f"unknown objective '{text}': use rule:NAME, at_fault, criterion:NAME or verdict")
    if name not in criteria:
        raise ObjectiveError(f"the scenario does not judge '{name}' (it judges: {', '.join(criteria) or 'nothing'}); "
                             "add it under 'expect:'")
    return Objective(text, name)


class Search(Protocol):
    """An optimiser over the unit box: ``ask`` a batch of points, ``tell`` their values."""

    def ask(self) -> np.ndarray: ...

    def tell(self, points: np.ndarray, values: np.ndarray) -> None: ...


class _Random:
    def __init__(self, d: int, batch: int, seed: int) -> None:
        self.rng, self.d, self.batch = np.random.default_rng(seed), d, batch

    def ask(self) -> np.ndarray:
        return self.rng.random((self.batch, self.d))

    def tell(self, points: np.ndarray, values: np.ndarray) -> None:
        pass


class _CrossEntropy:
    """A Gaussian sampling distribution refitted to the best 30 % of each batch, smoothed, its
    spread kept above ``floor`` (so it does not collapse before it reaches the region)."""

    def __init__(self, d: int, batch: int, seed: int, elite: float = 0.3, smoothing: float = 0.8,
                 floor: float = 0.05) -> None:
        self.rng, self.batch = np.random.default_rng(seed), batch
        self.mean, self.std = np.full(d, 0.5), np.full(d, 0.3)
        self.n_elite, self.alpha, self.floor = max(3, int(math.ceil(elite * batch))), smoothing, floor

    def ask(self) -> np.ndarray:
        return np.clip(self.mean + self.std * self.rng.standard_normal((self.batch, self.mean.size)), 0.0, 1.0)

    def tell(self, points: np.ndarray, values: np.ndarray) -> None:
        best = points[np.argsort(values, kind="stable")[: self.n_elite]]
        self.mean = self.alpha * best.mean(axis=0) + (1 - self.alpha) * self.mean
        self.std = np.maximum(self.alpha * best.std(axis=0) + (1 - self.alpha) * self.std, self.floor)


class _Cma:
    def __init__(self, d: int, batch: int | None, seed: int) -> None:
        import cma

        opts = {"bounds": [0.0, 1.0], "seed": seed + 1, "verbose": -9, "CMA_diagonal": False}
        if batch:
            opts["popsize"] = batch
        self.es = cma.CMAEvolutionStrategy(np.full(d, 0.5), 0.3, opts)
        self.batch = self.es.popsize
        self._asked: list[np.ndarray] = []

    def ask(self) -> np.ndarray:
        self._asked = self.es.ask()
        return np.clip(np.asarray(self._asked, dtype=float), 0.0, 1.0)

    def tell(self, points: np.ndarray, values: np.ndarray) -> None:
        self.es.tell(self._asked, [float(v) for v in values])


def make_search(optimizer: str, d: int, batch: int | None, seed: int) -> tuple[Search, str]:
    """The optimiser and the name of the one used (``cma`` falls back to ``ce`` without the
    ``cma`` package)."""
    if optimizer == "cma":
        try:
            return _Cma(d, batch, seed), "cma"
        except ImportError:
            optimizer = "ce"
    default = 4 + int(3 * math.log(max(d, 1)))
    if optimizer == "ce":
        return _CrossEntropy(d, batch or max(12, 2 * default), seed), "ce"
    if optimizer == "random":
        return _Random(d, batch or max(8, default), seed), "random"
    raise ValueError(f"unknown optimizer '{optimizer}': choose one of {', '.join(OPTIMIZERS)}")


@dataclass(frozen=True)
class FalsifyResult:
    """Every run in order, its batch, the objective's values, the optimiser used, and the first
    counterexample (its position, 1-based, among the runs; None when none was found)."""

    results: tuple[CaseResult, ...]
    batches: tuple[int, ...]
    values: tuple[float, ...]
    optimizer: str
    first: int | None
    interrupted: int | None = None
    """The signal that stopped the search (None: it ran to a counterexample or its budget)."""

    @property
    def counterexample(self) -> CaseResult | None:
        return self.results[self.first - 1] if self.first is not None else None

    @property
    def best(self) -> CaseResult | None:
        finite = [(v, i) for i, v in enumerate(self.values) if not math.isnan(v)]
        return self.results[min(finite)[1]] if finite else None


def falsify(scenario: str, params: Mapping[str, Parameter], objective: Objective, *, budget: int,
            run_batch: Callable[[list[Case]], list[CaseResult]], optimizer: str = "cma", seed: int = 0,
            batch: int | None = None, on_batch: Callable[[int, list[CaseResult], list[float]], None] | None = None
            ) -> FalsifyResult:
    """Minimise ``objective`` over ``params`` of ``scenario`` with at most ``budget`` runs;
    ``run_batch`` runs a list of cases (in parallel) and returns their results in order; when it
    raises :class:`~twolevel.campaign.suite.SuiteInterrupted` the search ends with the cases that
    completed (``interrupted`` the signal)."""
    from twolevel import interruption
    from twolevel.campaign.suite import SuiteInterrupted

    search, used = make_search(optimizer, len(params), batch, seed)
    results: list[CaseResult] = []
    batches: list[int] = []
    values: list[float] = []
    first: int | None = None
    interrupted: int | None = None
    generation = 0
    while len(results) < budget and first is None and interrupted is None:
        generation += 1
        try:
            points = search.ask()
            take = points[: budget - len(results)]
            cases = [Case(f"#{len(results) + i + 1:04d}", scenario, values_at(params, u)) for i, u in enumerate(take)]
            got = run_batch(cases)
        except SuiteInterrupted as exc:
            got, interrupted = list(exc.results), exc.signum
        except KeyboardInterrupt as exc:  # between batches: nothing was running
            interrupted = getattr(exc, "signum", None) or interruption.received() or int(signal.SIGINT)
            break
        with interruption.shielded():  # the runs and their values stay in step whatever arrives now
            vals = [objective.of(r) for r in got]
            for i, v in enumerate(vals):
                if first is None and v < 0:
                    first = len(results) + i + 1
            results += got
            batches += [generation] * len(got)
            values += vals
        try:
            interruption.checkpoint()  # a signal received in the shield
            if len(take) == len(points) and interrupted is None:  # a partial batch is not told (the optimiser expects whole ones)
                finite = np.array([_BIG if math.isnan(v) else min(max(v, -_BIG), _BIG) for v in vals])
                search.tell(points, finite)
            if on_batch is not None:
                on_batch(generation, got, vals)
        except KeyboardInterrupt as exc:
            interrupted = interrupted or getattr(exc, "signum", None) or interruption.received() or int(signal.SIGINT)
    return FalsifyResult(tuple(results), tuple(batches), tuple(values), used, first, interrupted)


COUNTEREXAMPLE_FILE = "counterexample.yaml"
COUNTEREXAMPLE_RUN = "counterexample"
SUMMARY_FILE = "falsify.json"


def record(result: FalsifyResult, objective: Objective, folder: str | os.PathLike[str], seed: int) -> dict[str, Any]:
    """Write a search's outcome into ``folder``: ``falsify.json`` (the summary returned) and,
    when one was found, the counterexample as a standalone scenario (``counterexample.yaml``)
    with a copy of its run directory (``counterexample/``)."""
    from twolevel.atomic import write_json_atomic
    from twolevel.campaign.case import write_concrete
    from twolevel.interruption import describe
    from twolevel.sim.summary import jsonable

    out = Path(folder)
    best = result.best
    summary: dict[str, Any] = {
        "objective": objective.text, "optimizer": result.optimizer, "seed": seed, "simulations": len(result.results),
        "first_counterexample": result.first,
        "interrupted": None if result.interrupted is None else describe(result.interrupted),
        "counterexample": None if result.counterexample is None else dict(result.counterexample.case.parameters),
        "best": None if best is None else {"parameters": dict(best.case.parameters),
                                           "objective": result.values[result.results.index(best)]},
    }
    ce = result.counterexample
    if ce is not None and result.first is not None:
        header = (f"counterexample found by twolevel falsify ({result.optimizer}, seed {seed}) after {result.first} "
                  f"simulations:\n{objective.text} = {result.values[result.first - 1]:.6g}; "
                  f"failed: {', '.join(ce.failed) or ce.outcome}")
        path, _ = write_concrete(ce.case, out / COUNTEREXAMPLE_FILE, header)
        summary["counterexample_file"] = str(path)
        if ce.run_dir:
            shutil.rmtree(out / COUNTEREXAMPLE_RUN, ignore_errors=True)
            shutil.copytree(ce.run_dir, out / COUNTEREXAMPLE_RUN)
            summary["counterexample_run"] = str(out / COUNTEREXAMPLE_RUN)
    write_json_atomic(out / SUMMARY_FILE, jsonable(summary))
    return summary
