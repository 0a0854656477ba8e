"""A rule the trace cannot judge is never a pass: ``twolevel monitor`` on a trace that records no
participants (a run whose loaded rules read none) says so for every rule that quantifies over
them — an error at the rule in its .stl file with a hint, the verdict "not judged" in the table
and the JSON, exit 2 — while the other rules of the file are judged as usual."""

from __future__ import annotations

import json
from pathlib import Path

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
