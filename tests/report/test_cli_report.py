"""`twolevel report` through the real CLI."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from twolevel.cli import app

runner = CliRunner()


def test_report_writes_html_and_prints_the_headline(make_traffic_run) -> None:
    run = make_traffic_run("a", violate=True)
    other = make_traffic_run("b", slow=1.3)
    res = runner.invoke(app, ["report", str(run), "--compare", str(other), "--no-gif", "--figure-format", "png"])
    assert res.exit_code == 0, res.output
    assert (run / "report.html").exists() and (run / "summary.json").exists()
    assert "steps" in res.stdout and "report.html" in res.stdout
    assert not list((run / "figures").glob("*.svg"))


def test_report_on_a_directory_with_nothing_readable_exits_2(tmp_path: Path) -> None:
    res = runner.invoke(app, ["report", str(tmp_path / "empty")])
    assert res.exit_code == 2
    assert "Traceback" not in res.output


def test_report_on_a_crashed_run_warns_and_still_writes(make_traffic_run) -> None:
    run = make_traffic_run("c", status="crashed", n=40)
    res = runner.invoke(app, ["report", str(run), "--no-gif", "--figure-format", "png"])
    assert res.exit_code == 0
    assert "warning:" in res.stderr and "crashed" in res.stderr
    assert (run / "report.html").exists()
