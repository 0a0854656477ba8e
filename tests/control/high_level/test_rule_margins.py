"""``controller: margins`` {rule: m}: the scenario sets how far inside its bound the MPC keeps a
rule (replacing MPCSettings' default map); a margin for a rule no rule file defines, a negative,
non-finite or non-numeric one is an error at its line (through the real CLI); the plan keeps a
user's margin, and a step whose known values leave less room than the margin is planned with the
plain eps instead of failing."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.high_level.settings import MPCSettings
from twolevel.control.planner import EgoState, PlanStatus
from twolevel.world.loader import load_scenario
from twolevel.world.world import build_world

REPO = Path(__file__).resolve().parents[3]
runner = CliRunner()
EPS = MPCSettings().eps


def scenario(tmp: Path, controller: str, speed: float = 13.0) -> Path:
    """The highway, the ego in its middle lane at ``speed`` [m/s] wanting 27 m/s (its sensing
    bound), speed_limit.stl bound to v ≤ 15 m/s (the 30 m/s limit, tol −15) beside
    safe_distance.stl; ``controller`` is the YAML flow mapping on line 8."""
    p = tmp / "s.yaml"
    p.write_text(f"""kind: scenario
name: margins
map: {REPO / 'maps' / 'highway.yaml'}
ego: {{start: {{lane: middle, s: 20}}, speed: {speed}}}
route: {{start: {{lane: middle, s: 20}}, goal: {{lane: middle, s: 600}}, stop_at_goal: false}}
rules: [{{file: {REPO / 'rules' / 'speed_limit.stl'}, constants: {{tol: -15}}}}, {REPO / 'rules' / 'safe_distance.stl'}]
run: {{duration: 5, seed: 0}}
controller: {controller}
""")
    return p


def check_json(p: Path) -> tuple[int, list[dict]]:
    res = runner.invoke(app, ["check", str(p), "-f", "json"], env={"GITHUB_ACTIONS": ""})
    return res.exit_code, json.loads(res.stdout)["diagnostics"]


def test_margins_from_the_scenario_reach_the_mpc_settings(tmp_path: Path) -> None:
    code, diags = check_json(scenario(tmp_path, "{margins: {speed_limit: 1.0, keep_gap: 0.5}}"))
    assert code == 0 and [d for d in diags if d["severity"] == "error"] == []
    st = MPCSettings.of_world(build_world(load_scenario(tmp_path / "s.yaml")[0]).settings)
    assert dict(st.margins) == {"speed_limit": 1.0, "keep_gap": 0.5}  # the default map replaced
    # an empty map: no margins at all; no key: the default
    scenario(tmp_path, "{margins: {}}")
    assert MPCSettings.of_world(build_world(load_scenario(tmp_path / "s.yaml")[0]).settings).margins == ()
    scenario(tmp_path, "{}")
    assert MPCSettings.of_world(build_world(load_scenario(tmp_path / "s.yaml")[0]).settings).margins == \
        MPCSettings().margins


@pytest.mark.parametrize("controller, code, at", [
    ("{margins: {speed_limt: 1.0}}", "YML435", "speed_limt"),  # a typo: at the key
    ("{margins: {clear_junction: 0.2}}", "YML435", "clear_junction"),  # the default's rule, not loaded here
    ("{margins: {speed_limit: -0.1}}", "YML414", "-0.1"),
    ("{margins: {speed_limit: .inf}}", "YML414", ".inf"),
    ("{margins: {speed_limit: .nan}}", "YML414", ".nan"),
    ("{margins: {speed_limit: fast}}", "YML413", "fast"),
    ("{margins: {speed_limit: true}}", "YML413", "true"),
    ("{margins: [speed_limit, 1.0]}", "YML413", "["),
])
def test_a_bad_margin_is_an_error_at_its_line_through_the_cli(tmp_path: Path, controller: str, code: str,
                                                             at: str) -> None:
    p = scenario(tmp_path, controller)
    exit_code, diags = check_json(p)
    errors = [d for d in diags if d["severity"] == "error"]
    assert exit_code != 0 and [d["code"] for d in errors] == [code], errors
    assert (Path(errors[0]["file"]).name, errors[0]["line"]) == ("s.yaml", 8)
    assert errors[0]["column"] == p.read_text().splitlines()[7].index(at) + 1
    if code == "YML435":
        assert errors[0]["hint"] == "rules defined: keep_gap, no_collision, speed_limit"
    assert load_scenario(p)[0] is None
    # simulate refuses it with the same diagnostic, never a traceback
    res = runner.invoke(app, ["simulate", str(p), "--out", str(tmp_path / "run")], env={"GITHUB_ACTIONS": ""})
    assert res.exit_code != 0 and code in res.output and "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)


def _plan(p: Path):  # noqa: ANN202
    w = build_world(load_scenario(p)[0])
    ctrl, diags = HighLevelController.from_world(w)
    assert ctrl is not None, [d.message for d in diags]
    e = w.ego
    return ctrl.solve(EgoState(np.array([e.x, e.y, e.psi, e.v])), 0.0, w.traffic0)


@pytest.mark.parametrize("margin", [0.0, 0.3, 1.0])
def test_the_plan_sits_eps_plus_the_users_margin_inside_the_bound(tmp_path: Path, margin: float) -> None:
    """Wanting 27 m/s from 13 m/s under v ≤ 15 m/s, the plan accelerates to the bound less eps
    and the scenario's margin [m/s], and the plan's monitored robustness is that margin."""
    res = _plan(scenario(tmp_path, f"{{margins: {{speed_limit: {margin}}}}}"))
    assert res.ok and res.status is not PlanStatus.FALLBACK
    assert res.states[:, 3].max() == pytest.approx(15.0 - EPS - margin, abs=1e-6)
    assert res.rule_robustness["speed_limit"] == pytest.approx(EPS + margin, abs=1e-6)


def test_a_margin_the_known_speed_leaves_no_room_for_is_dropped_for_that_step(tmp_path: Path) -> None:
    """At 14.5 m/s now the rule's value this step is at most 0.5 m/s (the speed now is known), so
    a 1 m/s margin cannot hold: the step is planned with the plain eps (it used to be infeasible
    by constants, and the step fell back to the previous plan or braking)."""
    res = _plan(scenario(tmp_path, "{margins: {speed_limit: 1.0}}", speed=14.5))
    assert res.ok and res.status is not PlanStatus.FALLBACK, res.message
    assert res.states[:, 3].max() == pytest.approx(15.0 - EPS, abs=1e-6)
    assert res.rule_robustness["speed_limit"] >= EPS - 1e-9


def test_where_no_plan_keeps_the_margins_every_rule_is_planned_on_its_bound(tmp_path: Path) -> None:
    """Two rules that leave 0.4 m/s between them from 0.5 s on (at least 14 from the next step, at most 14.4 m/s):
    each alone keeps a 0.5 m/s margin, together they cannot — though no single step's known
    values say so. The step is planned with both on their bounds instead of falling back (a
    margin is room for the detailed car, never a reason to brake or keep an old plan)."""
    (tmp_path / "band.stl").write_text("input float v\nbrisk = always[0.1:1] (v >= 14.0);\n"
                                       "gentle = always[0.5:1] (v <= 14.4);\n")
    p = scenario(tmp_path, "{margins: {brisk: 0.5}}", speed=14.2)
    p.write_text(p.read_text().replace(
        f"rules: [{{file: {REPO / 'rules' / 'speed_limit.stl'}, constants: {{tol: -15}}}}, "
        f"{REPO / 'rules' / 'safe_distance.stl'}]", "rules: [band.stl]"))
    res = _plan(p)
    assert res.ok and res.status is not PlanStatus.FALLBACK, res.message
    assert "no plan keeps the margins" in res.message
    v = res.states[1:, 3]
    assert (v >= 14.0 + EPS - 1e-6).all() and (v[5:] <= 14.4 - EPS + 1e-6).all()
    assert res.rule_robustness["brisk"] < 0.5  # the margin could not be kept
