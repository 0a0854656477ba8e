"""``twolevel test``: a folder of passing and failing scenarios run as a suite through the real
CLI (worker processes), its exit code, JUnit XML (validated against its schema), JSON, GitHub
annotations, -k selection, --failed-first and the run directories kept for failures."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import xmlschema
from typer.testing import CliRunner

from twolevel.campaign.case import Case
from twolevel.campaign.suite import KeywordError, discover, order_failed_first, select
from twolevel.cli import app

HERE = Path(__file__).resolve().parent
SCENARIOS = HERE.parent / "scenarios"
SUITE = SCENARIOS / "suite"
runner = CliRunner()

EXPECTED = {  # case → the criteria it fails
    "reach.yaml": [], "goal_at.yaml": [], "goal_at.yaml::far": [], "goal_at.yaml::late": ["goal"],
    "short.yaml": ["goal"], "offroad.yaml": ["on_road"], "stuck.yaml": ["max_stopped"], "crash.yaml": ["no_collision"],
}


@pytest.fixture(scope="module")
def suite_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    tmp = tmp_path_factory.mktemp("suite")
    args = ["test", str(SUITE), "-j", "2", "--runs-dir", str(tmp / "runs"), "--junit-xml", str(tmp / "junit.xml"),
            "--json", str(tmp / "results.json"), "--github", "--cache-file", str(tmp / "cache.json")]
    return tmp, runner.invoke(app, args)


def _short(case_id: str) -> str:
    return case_id.split("/suite/")[-1]


@pytest.mark.slow
def test_the_suite_fails_when_a_case_fails_and_says_which(suite_run) -> None:  # noqa: ANN001
    tmp, res = suite_run
    assert res.exit_code == 1, res.output
    assert "8 cases: 3 passed, 5 failed, 0 errors" in res.stdout
    data = json.loads((tmp / "results.json").read_text())
    got = {_short(c["id"]): c["failed"] for c in data["cases"]}
    assert got == EXPECTED
    assert data["counts"] == {"passed": 3, "failed": 5, "error": 0} and data["passed"] is False
    assert [c["id"] for c in data["cases"]] == sorted(c["id"] for c in data["cases"])  # case order, not finishing order


@pytest.mark.slow
def test_junit_xml_is_valid_against_its_schema(suite_run) -> None:  # noqa: ANN001
    tmp, _ = suite_run
    schema = xmlschema.XMLSchema(str(HERE / "junit.xsd"))
    schema.validate(str(tmp / "junit.xml"))
    doc = schema.to_dict(str(tmp / "junit.xml"))
    suite = doc["testsuite"][0]
    assert (suite["@tests"], suite["@failures"], suite["@errors"]) == (8, 5, 0)
    failed = {(c["@classname"].split("/suite/")[-1], c["@name"]) for c in suite["testcase"] if "failure" in c}
    assert ("goal_at.yaml", "late") in failed and ("crash.yaml", "nominal") in failed and len(failed) == 5


@pytest.mark.slow
def test_github_annotations_point_at_the_criterion(suite_run) -> None:  # noqa: ANN001
    _, res = suite_run
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("::error ")]
    assert len(lines) == 5
    stuck = next(ln for ln in lines if "stuck.yaml%3A max_stopped" in ln)
    assert "file=" in stuck and ",line=12," in stuck  # the line of `expect: {goal: false, max_stopped: 2.0}`
    late = next(ln for ln in lines if "late%3A goal" in ln)
    assert ",line=18," in late  # the variant's own deadline


@pytest.mark.slow
def test_run_directories_are_kept_for_failures_and_reproduce(suite_run, tmp_path: Path) -> None:  # noqa: ANN001
    tmp, _ = suite_run
    data = json.loads((tmp / "results.json").read_text())
    for case in data["cases"]:
        assert (case["run_dir"] is None) == (case["outcome"] == "passed")
    crash = next(c for c in data["cases"] if c["id"].endswith("crash.yaml"))
    concrete = Path(crash["run_dir"]) / "scenario.yaml"
    again = runner.invoke(app, ["simulate", str(concrete), "--out", str(tmp_path / "again"), "--no-progress"])
    assert again.exit_code == 1
    verdict = json.loads((tmp_path / "again" / "run.json").read_text())["verdict"]
    assert verdict == crash["verdict"]
    assert set(json.loads((tmp / "cache.json").read_text())["failed"]) == {c["id"] for c in data["cases"] if c["failed"]}


def test_keyword_expressions_select_like_pytest() -> None:
    everything, _ = discover([str(SCENARIOS)])
    assert not {Path(c.id).name for c in everything} & {"road.yaml", "lane.yaml"}  # maps are not cases
    cases, _ = discover([str(SUITE)])
    ids = lambda expr: [_short(c.id) for c in select(cases, expr)]  # noqa: E731
    assert ids("goal_at") == ["goal_at.yaml", "goal_at.yaml::far", "goal_at.yaml::late"]
    assert ids("goal_at and not late") == ["goal_at.yaml", "goal_at.yaml::far"]
    assert ids("(crash or stuck) and not nothing") == ["crash.yaml", "stuck.yaml"]
    assert ids("CRASH") == ["crash.yaml"]
    assert len(ids(None)) == 8 and ids("nothing") == []
    for bad in ("crash and", "(crash", "or crash", "crash )"):
        with pytest.raises(KeywordError):
            select(cases, bad)


def test_failed_first_orders_by_the_last_failures() -> None:
    cases = [Case(x, x) for x in ("a", "b", "c", "d")]
    assert [c.id for c in order_failed_first(cases, {"c", "a"})] == ["a", "c", "b", "d"]
    assert [c.id for c in order_failed_first(cases, set())] == ["a", "b", "c", "d"]


def test_failed_first_runs_the_cached_failure_first(tmp_path: Path) -> None:
    cache = tmp_path / "cache.json"
    cache.write_text(json.dumps({"failed": [str(SUITE / "short.yaml")]}))
    args = ["test", str(SUITE), "-k", "reach or short", "-j", "1", "--failed-first", "--cache-file", str(cache),
            "--runs-dir", str(tmp_path / "runs"), "--json", str(tmp_path / "r.json")]
    res = runner.invoke(app, args)
    assert res.exit_code == 1, res.output
    order = [ln.split()[1] for ln in res.stdout.splitlines() if ln.startswith(("PASSED", "FAILED"))]
    assert [Path(x).name for x in order] == ["short.yaml", "reach.yaml"]


def test_usage_errors_exit_2(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    cache = ["--cache-file", str(tmp_path / "cache.json"), "--runs-dir", str(tmp_path / "runs")]
    assert runner.invoke(app, ["test", str(tmp_path / "empty"), *cache]).exit_code == 2
    assert runner.invoke(app, ["test", str(tmp_path / "missing"), *cache]).exit_code == 2
    assert runner.invoke(app, ["test", str(SUITE), "-k", "crash and", *cache]).exit_code == 2
    assert runner.invoke(app, ["test", str(SUITE), "-k", "nothing", *cache]).exit_code == 2
    assert runner.invoke(app, ["test", str(SUITE), "--scheduler", "nowhere", *cache]).exit_code == 2
    assert not (tmp_path / "cache.json").exists()  # nothing ran, nothing to remember


@pytest.mark.slow
def test_the_same_seed_gives_the_same_results(tmp_path: Path) -> None:
    outs = []
    for k in range(2):
        args = ["test", str(SUITE), "-k", "late or crash", "--seed", "5", "-j", "2", "--runs-dir",
                str(tmp_path / f"runs{k}"), "--json", str(tmp_path / f"r{k}.json"), "--cache-file", str(tmp_path / "c.json")]
        assert runner.invoke(app, args).exit_code == 1
        data = json.loads((tmp_path / f"r{k}.json").read_text())
        outs.append([{key: v for key, v in c.items() if key not in ("wall_s", "run_dir")} for c in data["cases"]])
        assert all(c["seed"] == 5 for c in data["cases"])
    assert outs[0] == outs[1]


def test_keywords_do_not_read_the_folders_above_the_suite(tmp_path: Path) -> None:
    # regression: -k matched the whole path, so a suite checked out below a folder named like a
    # word ("wt-lateral" for "late") selected nothing with "not late"
    suite = tmp_path / "calculated" / "suite"
    shutil.copytree(SUITE, suite)
    cases, _ = discover([str(suite)])
    assert [_short(c.id) for c in select(cases, "goal_at and not late")] == ["goal_at.yaml", "goal_at.yaml::far"]
    assert select(cases, "calculated") == [] and len(select(cases, "suite")) == len(cases)
    one, _ = discover([str(suite / "goal_at.yaml")])
    assert [c.keywords for c in one] == ["goal_at.yaml", "goal_at.yaml::far", "goal_at.yaml::late"]
