"""examples/town: the committed map is what importing the committed OpenDRIVE gives, and the paper's
four scenarios on it simulate to a passing verdict (their `expect:`) with the built-in traffic."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

pytest.importorskip("carla")

from twolevel.cli import app  # noqa: E402
from twolevel.interop import import_file  # noqa: E402

TOWN = Path(__file__).resolve().parents[2] / "examples" / "town"
runner = CliRunner()


def test_the_committed_map_is_the_import_of_the_committed_xodr(tmp_path: Path) -> None:
    result = import_file(TOWN / "town.xodr", tmp_path)
    assert not [d for d in result.diagnostics if d.is_error]
    assert result.written
    assert result.written[0].read_text() == (TOWN / "town.yaml").read_text(), "run examples/town/generate.py"


def test_the_town_scenarios_check_clean() -> None:
    result = runner.invoke(app, ["check", str(TOWN), "-f", "concise"])
    assert result.exit_code == 0, result.output


@pytest.mark.slow
@pytest.mark.parametrize("name", ["traffic_rules", "comparison", "safety", "scalability"])
def test_the_paper_scenarios_pass_on_the_town_map(tmp_path: Path, name: str) -> None:
    result = runner.invoke(app, ["simulate", str(TOWN / f"{name}.yaml"), "--out", str(tmp_path / name)])
    run = json.loads((tmp_path / name / "run.json").read_text())
    assert result.exit_code == 0, (run.get("verdict"), result.output[-2000:])
    assert run["verdict"]["passed"]
    if name == "traffic_rules":  # it stood at the stop sign and at the red light before its goal
        summary = run["summary"]
        assert summary["goal_reached_t"] > 46.0, summary["goal_reached_t"]  # the light turns green at 46 s
