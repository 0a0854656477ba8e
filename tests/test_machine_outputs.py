"""What a machine reads from stdout is only the documented output: every command, in every
machine format, with every solver backend, run as a real process (the real file descriptor 1,
which CliRunner's capture does not see: C libraries write to it directly)."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ("traffic_rules", "safety", "comparison", "scalability")


def _backends() -> list[str]:
    found = ["modes", "highs"]
    try:
        import gurobipy  # noqa: F401
    except ImportError:
        return found
    return found + ["gurobi"]


def run(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "twolevel", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def strict_json(text: str) -> object:
    """``text`` as exactly one strict JSON document (no NaN/Infinity, nothing before or after)."""
    def refuse(constant: str) -> object:
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


def number(value: object) -> float:
    """A robustness as the JSON convention writes it: a number, or "inf"/"-inf"."""
    assert value in ("inf", "-inf") or isinstance(value, (int, float)) and math.isfinite(value), value
    return float(value)  # type: ignore[arg-type]


CHECKED = ["rules/", "maps/", "scenarios/", "examples/check/flawed.stl"]


@pytest.mark.parametrize("fmt", ["json", "sarif", "github", "concise", "full"])
def test_check_writes_only_its_format_on_stdout(fmt: str) -> None:
    res = run("check", *CHECKED, "--dt", "0.1", "--horizon", "10", "--output-format", fmt)
    assert res.returncode == 1, res.stderr  # flawed.stl has errors
    if fmt == "json":
        doc = strict_json(res.stdout)
        assert doc["files_checked"] > 10 and doc["diagnostics"]  # type: ignore[index]
    elif fmt == "sarif":
        assert strict_json(res.stdout)["version"] == "2.1.0"  # type: ignore[index]
    elif fmt == "github":
        lines = res.stdout.splitlines()
        assert lines and all(re.match(r"::(error|warning|notice) file=", ln) for ln in lines), res.stdout
    elif fmt == "concise":
        lines = res.stdout.splitlines()
        assert lines and all(re.match(r"[^:]+:\d+:\d+: [A-Z]+\d+ \[(error|warning|info)\] ", ln) for ln in lines)
    else:
        assert "error[STL201]" in res.stdout and res.stdout.rstrip().endswith("warning(s)")


def test_monitor_json_is_strict_and_its_verdicts_follow_robustness(tmp_path: Path) -> None:
    """±inf robustness is written as a string, a rule whose robustness is undefined (NaN) is
    not judged (a finding, null robustness), and each verdict agrees with the sign of its
    robustness."""
    rules = tmp_path / "r.stl"
    rules.write_text(
        "input float v\ninput float d_stop\n"
        "always_true = true;\nnever = false;\nfar = d_stop >= 10;\nslow = v <= 20;\n"
        "undefined = d_stop - d_stop >= 0;\n"
    )
    trace = tmp_path / "trace.csv"
    trace.write_text("t,v,d_stop\n0,10,inf\n0.1,25,inf\n0.2,30,5\n")
    res = run("monitor", str(rules), str(trace), "--format", "json", "--series")
    assert res.returncode == 2, res.stderr  # one rule could not be evaluated
    assert "SIM607" in res.stderr and "undefined" in res.stderr
    doc = strict_json(res.stdout)
    got = {r["name"]: r for r in doc["rules"]}  # type: ignore[index]
    assert list(got) == ["always_true", "never", "far", "slow", "undefined"]  # the file's order
    undefined = got.pop("undefined")
    assert undefined == {"name": "undefined", "verdict": "not judged", "code": "SIM607", "robustness": None,
                         "satisfied": None, "first_violation_t": None}
    assert [r["verdict"] for r in got.values()] == ["holds", "violated", "violated", "violated"]
    assert got["always_true"]["robustness"] == "inf" and got["never"]["robustness"] == "-inf"
    assert got["far"]["robustness"] == "inf" and got["far"]["first_violation_t"] == pytest.approx(0.2)
    for r in got.values():
        rob = number(r["robustness"])
        assert r["satisfied"] == (rob >= 0)
        series = [number(x) for x in r["series"]]
        first = next((k for k, x in enumerate(series) if x < 0), None)
        assert r["first_violation_t"] == (None if first is None else pytest.approx(0.1 * first))


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_plan_json_is_strict_with_every_backend(scenario: str, backend: str) -> None:
    res = run("plan", f"scenarios/{scenario}.yaml", "--solver", backend, "--format", "json")
    assert res.returncode == 0, res.stderr
    doc = strict_json(res.stdout)
    assert doc["status"] in ("optimal", "feasible")  # type: ignore[index]
    # the look-ahead: 10 steps of 0.1 s, then 8 of 0.5 s (the safety scenario: the paper's 1 s)
    assert len(doc["plan"]) == (11 if scenario == "safety" else 19)  # type: ignore[index]
    assert all(len(row) == 7 for row in doc["plan"])  # type: ignore[index]
    for rule in doc["rules"]:  # type: ignore[index]
        number(rule["robustness"])


@pytest.mark.parametrize("backend", _backends())
def test_plan_table_and_emit_keep_solver_banners_off_stdout(backend: str, tmp_path: Path) -> None:
    model = tmp_path / "model.mps"
    res = run("plan", "scenarios/traffic_rules.yaml", "--solver", backend, "--format", "json", "--emit", str(model))
    assert res.returncode == 0, res.stderr
    assert strict_json(res.stdout)["status"] == "optimal"  # type: ignore[index]
    assert model.stat().st_size > 0
    table = run("plan", "scenarios/traffic_rules.yaml", "--solver", backend)
    assert table.returncode == 0 and table.stdout.lstrip().startswith("scenarios/traffic_rules.yaml: optimal")
    assert "HiGHS" not in table.stdout
