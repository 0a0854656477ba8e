"""`twolevel monitor` through the real CLI: verdicts, formats, exit codes, bad inputs."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from twolevel.cli import app

ROOT = Path(__file__).resolve().parents[2]
DRIVE = str(ROOT / "examples" / "monitor" / "drive.csv")
runner = CliRunner()


def run(*args: str):
    return runner.invoke(app, ["monitor", *args])


def test_violated_rule_exits_1_with_its_first_violation_time() -> None:
    res = run(str(ROOT / "rules" / "speed_limit.stl"), DRIVE, "--format", "json")
    assert res.exit_code == 1
    [rule] = json.loads(res.stdout)["rules"]
    assert rule["name"] == "speed_limit" and rule["satisfied"] is True
    assert abs(rule["first_violation_t"] - 3.3) < 1e-9


def test_rules_that_hold_exit_0_and_table_lists_them() -> None:
    res = run(str(ROOT / "rules" / "safe_distance.stl"), DRIVE)
    assert res.exit_code == 0, res.output
    assert "no_collision" in res.stdout and "holds" in res.stdout


def test_series_gives_one_value_per_sample() -> None:
    res = run(str(ROOT / "rules" / "speed_limit.stl"), DRIVE, "--format", "json", "--series")
    [rule] = json.loads(res.stdout)["rules"]
    assert len(rule["series"]) == 100


def test_const_overrides_change_the_verdict(tmp_path: Path) -> None:
    rules = tmp_path / "r.stl"
    rules.write_text("input float v\ninput float v_max\nconst float tol = 0.5\nfast = v <= v_max + tol;\n")
    strict = run(str(rules), DRIVE, "--format", "json")
    lenient = run(str(rules), DRIVE, "--format", "json", "--const", "tol=5")
    assert strict.exit_code == 1 and lenient.exit_code == 0


def test_unbound_constant_and_unknown_binding_exit_2(tmp_path: Path) -> None:
    rules = tmp_path / "r.stl"
    rules.write_text("input float v\nconst float lim\nslow = v <= lim;\n")
    res = run(str(rules), DRIVE)
    assert res.exit_code == 2 and "STL217" in res.stderr
    assert run(str(rules), DRIVE, "--const", "lim=30").exit_code == 0
    res = run(str(rules), DRIVE, "--const", "lim=30", "--const", "nope=1")
    assert res.exit_code == 2 and "STL219" in res.stderr


def test_missing_column_names_the_signal(tmp_path: Path) -> None:
    rules = tmp_path / "r.stl"
    rules.write_text("input float wiper\nw = wiper >= 0;\n")
    res = run(str(rules), DRIVE, "--format", "json")
    assert res.exit_code == 2 and "SIM602" in res.stderr and "wiper" in res.stderr
    assert "Traceback" not in res.output


def test_bad_traces_exit_2_with_a_located_diagnostic(tmp_path: Path) -> None:
    rules = str(ROOT / "rules" / "speed_limit.stl")
    cases = {
        "no_time.csv": ("v,v_max\n1,2\n", "SIM601"),
        "nonuniform.csv": ("t,v,v_max\n0,1,2\n0.1,1,2\n0.3,1,2\n", "SIM601"),
        "nan.csv": ("t,v,v_max\n0,1,2\n0.1,nan,2\n", "SIM603"),
        "text_time.csv": ("t,v,v_max\n0,1,2\nsoon,1,2\n", "SIM603"),
        "empty.csv": ("", "SIM60"),
    }
    for name, (text, code) in cases.items():
        (tmp_path / name).write_text(text)
        res = run(rules, str(tmp_path / name))
        assert res.exit_code == 2, name
        assert code in res.stderr, (name, res.stderr)
    (tmp_path / "bin.csv").write_bytes(b"\x00\xff\x00")
    assert run(rules, str(tmp_path / "bin.csv")).exit_code == 2
    assert run(rules, str(tmp_path / "missing.csv")).exit_code == 2


def test_a_simulator_style_trace_with_text_columns_is_accepted(tmp_path: Path) -> None:
    trace = tmp_path / "trace.csv"
    trace.write_text("t,v,v_max,decision,light_state\n0,10,13.9,mpc,green\n0.1,10.5,13.9,sampled,red\n")
    res = run(str(ROOT / "rules" / "speed_limit.stl"), str(trace), "--format", "json")
    assert res.exit_code == 0, res.output


def test_infinite_cells_are_values_not_errors(tmp_path: Path) -> None:
    """The simulator writes d_stop = inf when no stop line is near (regression)."""
    trace = tmp_path / "trace.csv"
    trace.write_text("t,d_stop,v\n0,inf,3\n0.1,inf,3\n0.2,12.5,2\n")
    rules = tmp_path / "r.stl"
    rules.write_text("input float d_stop\ninput float v\nnear = (d_stop < 20) -> (v <= 2.5);\n")
    res = run(str(rules), str(trace), "--format", "json", "--series")
    [rule] = json.loads(res.stdout)["rules"]
    assert res.exit_code == 0, res.output
    assert rule["series"][0] == "inf" or rule["series"][0] > 0


def test_interval_not_a_multiple_of_the_trace_period_is_refused(tmp_path: Path) -> None:
    """The monitor used to round [0:0.15] at dt = 0.1 to whole samples silently (review)."""
    rules = tmp_path / "r.stl"
    rules.write_text("input float v\ninput float v_max\nr = always[0:0.15] (v <= v_max + 5);\n")
    res = run(str(rules), DRIVE, "--format", "json")
    assert res.exit_code == 2 and "STL209" in res.stderr and res.stdout == ""


def test_non_finite_constants_are_refused() -> None:
    for value in ("nan", "inf"):
        res = run(str(ROOT / "rules" / "speed_limit.stl"), DRIVE, "--const", f"tol={value}")
        assert res.exit_code == 2, value


def test_a_fifo_as_the_rule_file_does_not_hang(tmp_path: Path) -> None:
    import os

    fifo = tmp_path / "rules.stl"
    os.mkfifo(fifo)
    res = run(str(fifo), DRIVE)
    assert res.exit_code == 2 and "STL100" in res.stderr
