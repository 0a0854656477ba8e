"""Fuzzing maps and scenarios: whatever ``check`` accepts, ``plan`` and ``simulate --duration 2``
run without an internal error and without a NaN state; whatever it refuses, it refuses with a
diagnostic at the offending value.

Inputs are the shipped scenarios and the seeds in ``fuzz_seeds/`` (which use every field),
mutated field by field by :mod:`twolevel.fuzz` (the same generators ``benchmarks/fuzz.py`` runs
for long campaigns). Under CI hypothesis draws the same examples every run (tests/conftest.py).
"""

from __future__ import annotations

import math
import random
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from twolevel.fuzz.mutation import Mutation, Pairs, apply, dump, mutate, numbers
from twolevel.fuzz.world import Case, Seed, generate, load_seed, probe, shipped_seeds, write_case
from twolevel.world.document import read_document
from twolevel.world.loader import load_scenario

ROOT = Path(__file__).resolve().parents[2]
SEEDS = shipped_seeds(ROOT) + [load_seed(Path(__file__).parent / "fuzz_seeds" / "scenario.yaml")]
RICH = SEEDS[-1]
NOT_FINITE_OR_HUGE = (math.nan, math.inf, -math.inf, 1e300)


def _case(seed: Seed, target: str, mutation: Mutation) -> Case:
    docs = {"scenario": seed.scenario, "map": seed.map}
    docs[target] = apply(docs[target], mutation)
    return Case(seed.name, docs["scenario"], docs["map"], ((target, mutation),), seed.rules)


def test_seeds_are_valid_and_use_every_kind_of_field() -> None:
    with tempfile.TemporaryDirectory() as d:
        for seed in SEEDS:
            outcome = probe(write_case(Case(seed.name, seed.scenario, seed.map, (), seed.rules), Path(d) / seed.name))
            assert outcome.verdict == "accepted" and outcome.codes == (), (seed.name, outcome)
    text = dump(RICH.scenario) + dump(RICH.map)
    for key in ("points", "waypoints", "via", "s_range", "speed_range", "vehicle", "idm", "cycle", "script",
                "successors", "lateral", "heading", "constants", "assumptions", "road_users", "expect",
                "parameters", "variants"):
        assert f"{key}:" in text, key
    assert "${" in text


# ------------------------------------------------------------------------ the mutation engine


_plain = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(min_size=1, max_size=5), inner, min_size=1, max_size=3),
    max_leaves=12,
)


@settings(max_examples=150, deadline=None)
@given(st.dictionaries(st.text(min_size=1, max_size=5), _plain, min_size=1, max_size=4))
def test_dumped_documents_read_back_as_they_were(data: dict) -> None:
    """The harness writes what it means: its YAML reads back to the same data."""
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "x.yaml"
        p.write_text(dump(data), encoding="utf-8")
        doc, diags = read_document(p)
    assert diags == [] and doc is not None and doc.data == data


def test_a_duplicated_key_is_written_twice_and_refused_there() -> None:
    m = Mutation(("ego", "speed"), "duplicate", 7.0)
    data = apply(RICH.scenario, m)
    assert isinstance(data["ego"], Pairs)
    with tempfile.TemporaryDirectory() as d:
        p = write_case(Case("rich", data, RICH.map, (("scenario", m),), RICH.rules), d)
        scn, diags = load_scenario(p)
    assert scn is None and [d.code for d in diags] == ["YML409"]
    assert dump(data).splitlines()[diags[0].span.line - 1].strip() == "speed: 7.0"


# ------------------------------------------------ every number: NaN, inf, huge → at the value


def _refused_at_the_value(seed: Seed, target: str, path: tuple, value: float, folder: Path) -> None:
    case = _case(seed, target, Mutation(path, "set", value))
    scenario = write_case(case, folder)
    mutated = scenario if target == "scenario" else scenario.parent.parent / "maps" / "m.yaml"
    doc, _ = read_document(mutated)
    assert doc is not None
    at = doc.where[path].value
    scn, diags = load_scenario(scenario)
    assert scn is None, (case, diags)
    spots = {(Path(d.span.file).resolve(), d.span.line, d.span.column) for d in diags if d.is_error}
    assert (mutated.resolve(), at.line, at.column) in spots, (case, diags)
    assert all(d.code.startswith("YML4") and d.hint for d in diags if d.is_error), diags


def _numeric_fields(seeds: list[Seed]) -> list[tuple[Seed, str, tuple]]:
    return [(seed, target, path) for seed in seeds for target in ("scenario", "map")
            for path in numbers(getattr(seed, target))]


def test_every_number_of_the_rich_seed_refuses_nan_inf_and_huge_at_its_value() -> None:
    """Each numeric field of the seed that uses every field, each set to NaN / inf / -inf / 1e300
    in turn (one value per field here, all of them in the slow test): a YML4xx error with a hint
    at that value's line and column."""
    fields = _numeric_fields([RICH])
    assert len(fields) > 100
    with tempfile.TemporaryDirectory() as d:
        for k, (seed, target, path) in enumerate(fields):
            _refused_at_the_value(seed, target, path, NOT_FINITE_OR_HUGE[k % 4], Path(d))


@pytest.mark.slow
def test_every_number_of_every_seed_refuses_every_non_finite_or_huge_value() -> None:
    with tempfile.TemporaryDirectory() as d:
        for seed, target, path in _numeric_fields(SEEDS):
            for value in (math.nan, math.inf, 1e300):  # -inf fails where +inf does (tried above)
                _refused_at_the_value(seed, target, path, value, Path(d))


# ------------------------------------------------------------------ random mutations: the invariant


def _held(rnd: random.Random, *, run: bool) -> None:
    seed = rnd.choice(SEEDS)
    case = generate(seed, rnd)
    with tempfile.TemporaryDirectory() as d:
        outcome = probe(write_case(case, d), run=run, solver=rnd.choice(["modes", "highs"]))
    assert not outcome.broken, f"{case}\n{outcome}"


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.randoms(use_true_random=False))
def test_check_answers_every_mutation_with_diagnostics_and_what_it_accepts_builds(rnd: random.Random) -> None:
    _held(rnd, run=False)


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.randoms(use_true_random=False))
def test_what_check_accepts_plans_and_simulates(rnd: random.Random) -> None:
    _held(rnd, run=True)


def test_numbers_inside_their_ranges_are_accepted_and_run() -> None:
    """Boundary values the schema allows (a lane 10 m wide, a horizon of 200 steps, …) run
    through plan and simulate: a fixed sample, so that a regression shows in the fast suite."""
    rnd = random.Random(20240611)
    done = 0
    with tempfile.TemporaryDirectory() as d:
        while done < 3:
            case = generate(RICH, rnd, max_mutations=1)
            outcome = probe(write_case(case, Path(d) / str(done)), run=False)
            assert not outcome.broken, f"{case}\n{outcome}"
            if outcome.verdict == "accepted" and case.mutations and case.mutations[0][1].op == "set":
                assert not probe(write_case(case, Path(d) / str(done)), run=True).broken, case
                done += 1


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.randoms(use_true_random=False), st.sampled_from(["full", "concise", "json", "github", "sarif"]))
def test_the_cli_check_answers_every_mutation_in_every_format(rnd: random.Random, fmt: str) -> None:
    """Through the real CLI: exit 0 or 1 (or 2 for an unreadable file), diagnostics rendered, no
    traceback and no internal error, in every output format."""
    from typer.testing import CliRunner

    from twolevel.cli import app

    case = generate(rnd.choice(SEEDS), rnd)
    with tempfile.TemporaryDirectory() as d:
        scenario = write_case(case, d)
        res = CliRunner().invoke(app, ["check", str(scenario), "--output-format", fmt])
    assert res.exception is None or isinstance(res.exception, SystemExit), f"{case}\n{res.exception!r}"
    assert res.exit_code in (0, 1, 2) and "internal error" not in res.output and "Traceback" not in res.output, case


def test_mutations_reach_every_kind_of_change() -> None:
    rnd = random.Random(7)
    ops = {mutate(RICH.scenario, rnd).op for _ in range(300)}
    assert ops == {"set", "drop", "duplicate", "add", "empty"}
