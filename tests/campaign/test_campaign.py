"""Campaigns: parameter sampling, the optimisers, falsification of a planted counterexample
(and none where there is none) through the real CLI, the results table, and the same table
from local processes and from a Dask cluster."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from typer.testing import CliRunner

from twolevel.campaign import sampling
from twolevel.campaign.executor import make_executor, worker_threads
from twolevel.campaign.falsify import make_search
from twolevel.campaign.results import TIMING_COLUMNS, read_rows
from twolevel.cli import app
from twolevel.world.loader import load_scenario
from twolevel.world.schema import Parameter

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
PLANTED = SCENARIOS / "campaign" / "planted.yaml"
NONE = SCENARIOS / "campaign" / "none.yaml"
runner = CliRunner()


@given(st.floats(0, 1), st.floats(0, 1), st.floats(-50, 50), st.floats(0.1, 30), st.floats(0.1, 20))
def test_every_parameter_maps_the_unit_interval_onto_its_values(u: float, w: float, lo: float, width: float, std: float) -> None:
    ranged = Parameter(range=(lo, lo + width))
    normal = Parameter(normal={"mean": lo + width / 3, "std": std}, range=(lo, lo + width))
    for p in (ranged, normal):
        a, b = sampling.value_at(p, min(u, w)), sampling.value_at(p, max(u, w))
        assert lo - 1e-9 <= a <= b <= lo + width + 1e-9  # inside the range, monotone
    choice = Parameter(choices=[3, 1, 2])
    assert sampling.value_at(choice, u) in (3, 1, 2)
    assert sampling.value_at(Parameter(range=(0, 10), integer=True), u) == round(10 * u)


def test_grids_and_samples() -> None:
    params = {"a": Parameter(range=(0, 1), steps=3), "b": Parameter(choices=[5, 6])}
    assert sampling.grid(params) == [{"a": 0.0, "b": 5.0}, {"a": 0.0, "b": 6.0}, {"a": 0.5, "b": 5.0},
                                     {"a": 0.5, "b": 6.0}, {"a": 1.0, "b": 5.0}, {"a": 1.0, "b": 6.0}]
    one = sampling.random_points(params, 20, seed=4)
    assert one == sampling.random_points(params, 20, seed=4) != sampling.random_points(params, 20, seed=5)
    assert all(0 <= p["a"] <= 1 and p["b"] in (5, 6) for p in one)
    with pytest.raises(ValueError):
        sampling.grid({f"p{i}": Parameter(range=(0, 1), steps=100) for i in range(3)})


@pytest.mark.parametrize("optimizer", ["cma", "ce"])
def test_the_optimisers_find_a_small_region_random_search_rarely_hits(optimizer: str) -> None:
    target = np.array([0.83, 0.12, 0.6])
    def f(x: np.ndarray) -> np.ndarray:  # negative only within 0.05 of the target: 0.05 % of the box
        return np.linalg.norm(x - target, axis=1) - 0.05

    def evaluations_to_hit(name: str, seed: int) -> int:
        search, used = make_search(name, 3, 8, seed)
        n = 0
        while n < 2000:
            x = search.ask()
            v = f(x)
            if (v < 0).any():
                return n + int(np.argmax(v < 0)) + 1
            search.tell(x, v)
            n += len(x)
        return n

    smart = [evaluations_to_hit(optimizer, s) for s in range(5)]
    blind = [evaluations_to_hit("random", s) for s in range(5)]
    assert max(smart) < 400 and np.median(blind) > 3 * np.median(smart), (smart, blind)


def test_local_workers_run_with_one_blas_thread() -> None:
    with make_executor(None, 1) as ex:
        assert set(ex.submit(worker_threads).result().values()) == {"1"}


@pytest.mark.slow
def test_falsify_finds_the_planted_counterexample_and_writes_it_standalone(tmp_path: Path) -> None:
    out = tmp_path / "fa"
    res = runner.invoke(app, ["falsify", str(PLANTED), "--objective", "at_fault", "--budget", "24", "--seed", "0",
                              "--batch", "4", "-j", "2", "--out", str(out)])
    assert res.exit_code == 1, res.output
    summary = json.loads((out / "falsify.json").read_text())
    assert summary["first_counterexample"] is not None and summary["first_counterexample"] <= 24
    ce = summary["counterexample"]
    assert ce["speed"] > 7.0  # the bad region: fast, with the parked car within reach
    text = (out / "counterexample.yaml").read_text()
    assert "parameters" not in text and "${" not in text and "extends" not in text
    scn, diags = load_scenario(out / "counterexample.yaml")
    assert scn is not None and scn.spec.ego.speed == pytest.approx(ce["speed"]), diags
    again = runner.invoke(app, ["simulate", str(out / "counterexample.yaml"), "--out", str(tmp_path / "again"), "--no-progress"])
    assert again.exit_code == 1
    verdict = json.loads((tmp_path / "again" / "run.json").read_text())["verdict"]
    assert "no_collision" in [c["name"] for c in verdict["criteria"] if not c["passed"]]
    assert (out / "counterexample" / "trace.csv").exists() and (out / "report.html").exists()
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert len(rows) == summary["simulations"] and float(rows[summary["first_counterexample"] - 1]["objective"]) < 0
    assert all(float(r["objective"]) >= 0 for r in rows[: summary["first_counterexample"] - 1])
    assert {"p.speed", "p.gap", "objective", "m.no_collision", "outcome", "run_dir"} <= set(rows[0])


@pytest.mark.slow
def test_falsify_reports_none_where_none_exists(tmp_path: Path) -> None:
    out = tmp_path / "none"
    res = runner.invoke(app, ["falsify", str(NONE), "--objective", "at_fault", "--budget", "8", "-j", "2",
                              "--optimizer", "ce", "--batch", "4", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "no counterexample in 8 simulations" in res.stdout
    assert not (out / "counterexample.yaml").exists()
    rows = read_rows(out / "results.json")
    assert len(rows) == 8 and {r["batch"] for r in rows} == {1, 2} and all(r["objective"] >= 0 and r["outcome"] == "passed" for r in rows)


def test_objectives_must_name_what_the_scenario_judges(tmp_path: Path) -> None:
    for objective in ("rule:nope", "criterion:max_jerk", "speed"):
        res = runner.invoke(app, ["falsify", str(PLANTED), "--objective", objective, "--out", str(tmp_path)])
        assert res.exit_code == 2 and "Traceback" not in res.output, (objective, res.output)
    res = runner.invoke(app, ["sweep", str(SCENARIOS / "suite" / "reach.yaml"), "--grid", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "declares no parameters" in res.output


def _table(folder: Path) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in read_rows(folder / "results.json")]


@pytest.mark.slow
def test_a_dask_cluster_gives_the_table_local_processes_give(tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed (pip install 'twolevel[dask]')")
    args = ["sweep", str(NONE), "--samples", "3", "--seed", "3", "--objective", "at_fault"]
    assert runner.invoke(app, [*args, "-j", "2", "--out", str(tmp_path / "local")]).exit_code == 0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        res = runner.invoke(app, [*args, "--scheduler", cluster.scheduler_address, "--out", str(tmp_path / "dask")])
        assert res.exit_code == 0, res.output
    local, remote = _table(tmp_path / "local"), _table(tmp_path / "dask")
    assert len(local) == 3 and local == remote
    assert all(math.isfinite(r["objective"]) for r in local)


def test_results_load_in_pandas(tmp_path: Path) -> None:
    pd = pytest.importorskip("pandas", reason="pandas is not installed")
    res = runner.invoke(app, ["sweep", str(SCENARIOS / "suite" / "goal_at.yaml"), "--samples", "2", "-j", "1",
                              "--out", str(tmp_path)])
    assert res.exit_code == 0
    frame = pd.read_csv(tmp_path / "results.csv")
    assert list(frame["index"]) == [1, 2] and frame["p.goal"].between(20, 60).all()
    assert pd.read_json(tmp_path / "results.json", orient="records").shape[0] == 2
