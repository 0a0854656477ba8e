"""`twolevel check` through the real CLI: formats, exit codes, folders, scenarios, start-up cost."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from twolevel.cli import app

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()

WARN_ONLY = "input float v\ninput float w\nr = always[0:1] (v <= 3);\n"  # w unused: a warning
ERROR = "input float v\nr = always[0:1] (vx <= 3);\n"


def run(*args: str, env: dict[str, str] | None = None):
    return runner.invoke(app, list(args), env=env or {"GITHUB_ACTIONS": ""})


@pytest.fixture()
def files(tmp_path: Path) -> dict[str, Path]:
    (tmp_path / "warn.stl").write_text(WARN_ONLY)
    (tmp_path / "err.stl").write_text(ERROR)
    return {"warn": tmp_path / "warn.stl", "err": tmp_path / "err.stl", "dir": tmp_path}


PACK_WARNINGS = [("R_G1_safe_distance.stl", "STL212")] * 2 + [("R_G2_no_abrupt_braking.stl", "STL212")] * 2


def test_shipped_tree_is_clean() -> None:
    ex = ROOT / "examples"
    res = run("check", str(ROOT / "rules"), str(ROOT / "maps"), str(ROOT / "scenarios"), str(ex / "scenario"), "-f", "json")
    payload = json.loads(res.stdout)
    assert res.exit_code == 0, res.stdout
    # the everyday suite's bends too fast for their limits are warned about, by design (YML432), and
    # the CommonRoad pack's quadratic braking distances, which the MPC cannot encode (STL212, two in
    # each of R_G1 and R_G2)
    found = sorted((d["code"], Path(d["file"]).name, d["line"]) for d in payload["diagnostics"] if d["code"] != "STL212")
    bends = [("YML432", "fast_bend.yaml", 12)] + [("YML432", "mountain.yaml", n) for n in (12, 14, 16, 18, 20)]
    assert found == sorted(bends + [("YML432", "sharp_left.yaml", 28)]), payload["diagnostics"]
    pack = sorted((Path(d["file"]).name, d["code"]) for d in payload["diagnostics"] if d["code"] == "STL212")
    assert pack == PACK_WARNINGS
    assert payload["files_checked"] == len(list((ROOT / "rules").rglob("*.stl"))) + len(list((ROOT / "maps").glob("*.yaml"))) + len(list((ROOT / "scenarios").rglob("*.yaml"))) + 2


def test_regression_a_route_across_a_junction_is_linted_without_a_crash() -> None:
    """The bend lint looked every lane of the route up among the roads' lanes: a route through a
    junction's connecting lane was an internal error (KeyError)."""
    res = run("check", str(ROOT / "examples" / "world" / "four_way_stop.yaml"), "-f", "json")
    assert res.exit_code == 0, res.stdout
    assert json.loads(res.stdout)["diagnostics"] == []


def test_exit_codes(files: dict[str, Path]) -> None:
    assert run("check", str(files["warn"])).exit_code == 0
    assert run("check", "--strict", str(files["warn"])).exit_code == 1
    assert run("check", str(files["err"])).exit_code == 1
    assert run("check", "--exit-zero", str(files["err"])).exit_code == 0
    assert run("check", str(files["dir"] / "missing.stl")).exit_code == 2
    assert run("check", "-f", "xml", str(files["warn"])).exit_code == 2


def test_folder_checks_every_rule_file_below(files: dict[str, Path]) -> None:
    sub = files["dir"] / "nested"
    sub.mkdir()
    (sub / "deep.stl").write_text(ERROR)
    payload = json.loads(run("check", "-f", "json", str(files["dir"])).stdout)
    assert payload["files_checked"] == 3
    assert sorted({Path(d["file"]).name for d in payload["diagnostics"]}) == ["deep.stl", "err.stl", "warn.stl"]


def test_json_locates_the_undeclared_signal(files: dict[str, Path]) -> None:
    payload = json.loads(run("check", "-f", "json", str(files["err"])).stdout)
    [d] = [d for d in payload["diagnostics"] if d["code"] == "STL201"]
    assert (d["line"], d["column"], d["end_column"]) == (2, 18, 20)
    assert d["hint"] == "did you mean 'v'?"


def test_github_format_is_chosen_under_github_actions(files: dict[str, Path]) -> None:
    res = run("check", str(files["err"]), env={"GITHUB_ACTIONS": "true"})
    assert res.stdout.startswith("::") and "::error file=" in res.stdout and ",line=2,col=18," in res.stdout


def test_sarif_is_valid_json_with_results(files: dict[str, Path]) -> None:
    doc = json.loads(run("check", "-f", "sarif", str(files["err"]), str(files["warn"])).stdout)
    codes = {r["ruleId"] for r in doc["runs"][0]["results"]}
    assert {"STL201", "STL202"} <= codes


def test_dt_enables_the_multiple_of_dt_check(tmp_path: Path) -> None:
    f = tmp_path / "r.stl"
    f.write_text("input float v\nr = always[0:0.25] (v <= 3);\n")
    assert run("check", str(f)).exit_code == 0
    res = run("check", "-f", "json", "--dt", "0.1", str(f))
    assert res.exit_code == 1 and any(d["code"] == "STL209" for d in json.loads(res.stdout)["diagnostics"])


def test_horizon_flags_formulas_longer_than_the_mpc(tmp_path: Path) -> None:
    f = tmp_path / "r.stl"
    f.write_text("input float v\nr = always[0:2] (v <= 3);\n")
    res = run("check", "-f", "json", "--dt", "0.1", "--horizon", "10", str(f))
    assert any(d["code"] == "STL211" for d in json.loads(res.stdout)["diagnostics"])


def test_scenario_check_reports_a_signal_the_world_does_not_provide(tmp_path: Path) -> None:
    scen = ROOT / "examples" / "scenario"
    for name in ("map.yaml", "scenario.yaml"):
        (tmp_path / name).write_text((scen / name).read_text())
    (tmp_path / "odd.stl").write_text("input float v\ninput float wiper\nr = always[0:1] (v <= wiper);\n")
    text = (tmp_path / "scenario.yaml").read_text()
    text = text.replace("rules:\n", "rules:\n  - odd.stl\n").replace("../../rules/", str(ROOT / "rules") + "/")
    (tmp_path / "scenario.yaml").write_text(text)
    res = run("check", "-f", "json", str(tmp_path / "scenario.yaml"))
    found = [d for d in json.loads(res.stdout)["diagnostics"] if d["code"] == "STL216"]
    assert res.exit_code == 1 and found and "wiper" in found[0]["message"]


def test_hostile_inputs_give_diagnostics_not_tracebacks(tmp_path: Path) -> None:
    (tmp_path / "bin.stl").write_bytes(b"\x00\x01\x02garbage")
    (tmp_path / "latin.stl").write_bytes("input float v\n// caf\xe9\n".encode("latin-1"))
    (tmp_path / "deep.stl").write_text("input float v\nr = " + "(" * 10000 + "v > 0" + ")" * 10000 + ";\n")
    (tmp_path / "bomb.yaml").write_text("a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n" for p, c in zip("abcdefgh", "bcdefghi")))
    (tmp_path / "empty.yaml").write_text("")
    res = run("check", "-f", "json", str(tmp_path))
    assert res.exception is None or isinstance(res.exception, SystemExit)
    codes = {Path(d["file"]).name: d["code"] for d in json.loads(res.stdout)["diagnostics"]}
    assert codes["bin.stl"] == "STL105" and codes["latin.stl"] == "STL106" and codes["deep.stl"] == "STL108"
    assert codes["bomb.yaml"] == "YML408" and codes["empty.yaml"] == "YML405"


def test_check_does_not_import_numpy_or_solvers() -> None:
    code = textwrap.dedent(
        f"""
        import sys
        from typer.testing import CliRunner
        from twolevel.cli import app
        res = CliRunner().invoke(app, ["check", "-f", "json", {str(ROOT / 'rules')!r}, {str(ROOT / 'scenarios' / 'traffic_rules.yaml')!r}])
        assert res.exit_code == 0, res.stdout
        heavy = sorted(m for m in ("numpy", "scipy", "casadi", "highspy", "clarabel", "matplotlib") if m in sys.modules)
        print(",".join(heavy))
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == ""


def test_console_script_runs_as_a_subprocess() -> None:
    exe = Path(sys.executable).with_name("twolevel")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "twolevel"]
    out = subprocess.run(cmd + ["check", "-f", "concise", str(ROOT / "rules")], capture_output=True, text=True, env={**os.environ, "GITHUB_ACTIONS": ""})
    assert out.returncode == 0 and "Traceback" not in out.stderr
    # concise: one line per finding, here only the CommonRoad pack's STL212 warnings
    assert sorted((Path(line.split(":")[0]).name, line.split()[1]) for line in out.stdout.splitlines()) == PACK_WARNINGS


def test_the_flawed_example_reports_what_its_readme_shows() -> None:
    readme = (ROOT / "examples" / "check" / "README.md").read_text()
    expected = [line for line in readme.splitlines() if line.startswith("examples/check/flawed.stl:")]
    res = subprocess.run(
        [sys.executable, "-m", "twolevel", "check", "examples/check/flawed.stl", "--dt", "0.1", "--horizon", "10", "-f", "concise"],
        capture_output=True, text=True, cwd=ROOT,
    )
    assert res.returncode == 1
    assert res.stdout.splitlines() == expected


def test_horizon_needs_dt_and_dt_must_be_finite() -> None:
    """--horizon alone was silently ignored and --dt inf made every interval a multiple (review)."""
    assert run("check", str(ROOT / "rules"), "--horizon", "5").exit_code == 2
    assert run("check", str(ROOT / "rules"), "--dt", "inf").exit_code == 2
