"""A rule the trace cannot judge is never a pass: ``twolevel monitor`` on a trace that records no
participants (a run whose loaded rules read none) says so for every rule that quantifies over
them — an error at the rule in its .stl file with a hint, the verdict "not judged" in the table
and the JSON, exit 2 — while the other rules of the file are judged as usual. A run directory
whose run.json says the run had no participants is the exception: there the empty set is the
truth."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from twolevel import pipeline
from twolevel.cli import app

ROOT = Path(__file__).resolve().parents[2]
OVERTAKING = ROOT / "rules" / "overtaking.stl"


def _trace(tmp_path: Path) -> str:
    """A drive with the ego-only signals overtaking.stl reads and no participant columns: what a
    run records when none of its loaded rules reads a participant signal."""
    rows = ["t,v,over_centre,solid_left,no_overtaking"]
    rows += [f"{0.1 * k:.1f},20,-1.5,0,0" for k in range(30)]
    path = tmp_path / "trace.csv"
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return str(path)


def _line_of(rule: str) -> int:
    lines = OVERTAKING.read_text(encoding="utf-8").splitlines()
    return next(k for k, ln in enumerate(lines, 1) if ln.startswith(f"{rule} ="))


def test_a_participant_rule_on_a_trace_without_participants_is_not_judged(tmp_path: Path) -> None:
    trace = _trace(tmp_path)
    res = CliRunner().invoke(app, ["monitor", str(OVERTAKING), trace, "--format", "json"])
    assert res.exit_code == 2, res.output
    doc = json.loads(res.stdout)
    verdicts = {r["name"]: r for r in doc["rules"]}
    assert list(verdicts) == ["no_solid_crossing", "no_overtaking_zone", "return_after_passing", "no_passing_right"]
    assert verdicts["no_passing_right"] == {"name": "no_passing_right", "verdict": "not judged", "code": "SIM609",
                                            "robustness": None, "satisfied": None, "first_violation_t": None}
    assert all(verdicts[n]["verdict"] == "holds" for n in ("no_solid_crossing", "no_overtaking_zone",
                                                           "return_after_passing"))
    finding = next(ln for ln in res.stderr.splitlines() if "SIM609" in ln)
    assert finding.startswith(f"{OVERTAKING}:{_line_of('no_passing_right')}:1: SIM609 [error]")
    assert "no_passing_right" in finding and "cannot be judged" in finding


def test_the_table_says_not_judged_and_the_hint_says_how_to_record_participants(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["monitor", str(OVERTAKING), _trace(tmp_path)], env={"COLUMNS": "200"})
    assert res.exit_code == 2
    row = next(ln for ln in res.stdout.splitlines() if "no_passing_right" in ln)
    assert "not judged (SIM609)" in row and "holds" not in row
    sim609 = [d for d in pipeline.monitor(str(OVERTAKING), _trace(tmp_path)).diagnostics if d.code == "SIM609"]
    assert len(sim609) == 1 and "twolevel simulate" in (sim609[0].hint or "")


# ------------------------------------------------- a run that had no participants (its run.json says so)


@pytest.fixture(scope="module")
def lone_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real run of a scenario without participants (one second of weave_30): its trace has no
    participant column because there was nobody, and its run.json says so."""
    out = tmp_path_factory.mktemp("lone") / "run"
    res = CliRunner().invoke(app, ["simulate", str(ROOT / "scenarios" / "everyday" / "weave_30.yaml"),
                                   "--duration", "1", "-o", str(out), "--no-progress"])
    assert res.exit_code == 0, res.output
    assert json.loads((out / "run.json").read_text(encoding="utf-8"))["participants"] == []
    return out


def test_a_run_without_participants_is_judged_over_the_empty_set(lone_run: Path) -> None:
    res = CliRunner().invoke(app, ["monitor", str(OVERTAKING), str(lone_run / "trace.csv"), "--format", "json"])
    assert res.exit_code == 0, res.output
    verdicts = {r["name"]: r for r in json.loads(res.stdout)["rules"]}
    assert verdicts["no_passing_right"]["verdict"] == "holds"  # nobody to pass on the right: true, not unknown
    assert verdicts["no_passing_right"]["robustness"] == "inf"
    assert "SIM609" not in res.stderr


@pytest.mark.parametrize("meta", ['{"participants": ["car 1", "car 2"]}', "{not json", '["a list"]',
                                  '{"participants": null}', '{"participants": [1]}'])
def test_only_a_run_json_that_says_none_took_part_lifts_sim609(lone_run: Path, tmp_path: Path, meta: str) -> None:
    (tmp_path / "trace.csv").write_bytes((lone_run / "trace.csv").read_bytes())
    (tmp_path / "run.json").write_text(meta, encoding="utf-8")
    diags = pipeline.monitor(str(OVERTAKING), str(tmp_path / "trace.csv")).diagnostics
    sim609 = [d for d in diags if d.code == "SIM609"]
    assert len(sim609) == 1 and "no_passing_right" in sim609[0].message
    assert ("its run had 2: car 1, car 2" in sim609[0].message) == meta.startswith('{"participants": ["car')
