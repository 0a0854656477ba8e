"""``plan_scenario`` (the library side of ``twolevel plan``): every shipped scenario gives a plan,
bad input gives diagnostics, infeasible problems name the rules that conflict."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from helpers.world_files import write_conflicting
from twolevel.pipeline.planning import plan_scenario

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = sorted((REPO / "scenarios").glob("*.yaml"))


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_every_shipped_scenario_plans(path: Path) -> None:
    rep, diags = plan_scenario(str(path), solver="highs")
    assert rep is not None, [d.message for d in diags]
    assert not any(d.is_error for d in diags)
    j = json.loads(json.dumps(rep.to_json()))
    assert set(j) >= {"status", "objective", "solve_ms", "binaries", "rows", "columns", "plan", "rules"}
    assert j["status"] == "optimal"
    plan = np.array(j["plan"], float)
    # the look-ahead: 10 steps of 0.1 s, then 8 of 0.5 s (the safety scenario: the paper's 1 s)
    steps = [0.1] * 10 + ([] if path.stem == "safety" else [0.5] * 8)
    assert plan.shape == (len(steps) + 1, 7)
    assert np.allclose(np.diff(plan[:, 0]), steps)
    assert all(r["robustness"] == "inf" or r["robustness"] >= -1e-6 for r in j["rules"])
    assert j["solve_ms"]["total"] > 0


def test_modes_and_highs_agree_on_the_scalability_scenario() -> None:
    a, _ = plan_scenario(str(REPO / "scenarios/scalability.yaml"), solver="highs")
    b, _ = plan_scenario(str(REPO / "scenarios/scalability.yaml"), solver="modes")
    assert a is not None and b is not None and a.binaries > 0
    assert b.objective == pytest.approx(a.objective, rel=0.01)


def test_emit_writes_the_model(tmp_path) -> None:
    for name in ("m.mps", "m.lp"):
        rep, diags = plan_scenario(str(REPO / "scenarios/scalability.yaml"), emit=str(tmp_path / name))
        assert rep is not None and rep.emitted == str(tmp_path / name)
        assert (tmp_path / name).stat().st_size > 1000


@pytest.mark.parametrize("kwargs, code", [
    (dict(solver="cplex"), "MIL512"),
    (dict(emit="model.txt"), "MIL514"),
    (dict(at=3.0), "MIL513"),
    (dict(at=3.0, trace="/nonexistent/trace.csv"), "MIL516"),
])
def test_bad_input_is_a_diagnostic(kwargs, code) -> None:
    rep, diags = plan_scenario(str(REPO / "scenarios/comparison.yaml"), **kwargs)
    assert rep is None and [d.code for d in diags] == [code]


def test_missing_scenario_is_a_diagnostic(tmp_path) -> None:
    rep, diags = plan_scenario(str(tmp_path / "none.yaml"))
    assert rep is None and diags and diags[0].code.startswith("YML")


def test_plan_at_a_recorded_time(tmp_path) -> None:
    rows = ["t,x,y,psi,v,delta,gamma"] + [f"{0.1 * k:.1f},{20 + 1.3 * k:.3f},0,0,13,0,0" for k in range(31)]
    (tmp_path / "trace.csv").write_text("\n".join(rows) + "\n")
    rep, diags = plan_scenario(str(REPO / "scenarios/scalability.yaml"), at=2.0, trace=str(tmp_path / "trace.csv"))
    assert rep is not None, [d.message for d in diags]
    assert rep.plan[0][0] == pytest.approx(2.0) and rep.plan[0][1] == pytest.approx(20 + 1.3 * 20)
    rep, diags = plan_scenario(str(REPO / "scenarios/scalability.yaml"), at=9.0, trace=str(tmp_path / "trace.csv"))
    assert rep is None and diags[-1].code == "MIL513"


def test_infeasible_plans_name_the_conflicting_rules(tmp_path) -> None:
    write_conflicting(tmp_path, REPO)
    rep, diags = plan_scenario(str(tmp_path / "s.yaml"))
    assert rep is not None and rep.status == "fallback"
    assert set(rep.conflicts) == {"go_fast", "stay_slow"}
    assert any(d.code == "MIL511" and "go_fast" in d.message for d in diags)


def _drive(tmp_path, end: str = "\n", v: str = "13") -> str:
    rows = ["t,x,y,psi,v,delta,gamma"] + [f"{0.1 * k:.1f},{20 + 1.3 * k:.3f},0,0,{v if k == 15 else 13},0,0"
                                          for k in range(31)]
    path = tmp_path / f"trace{len(end)}{v}.csv"
    path.write_bytes((end.join(rows) + end).encode())
    return str(path)


def test_plan_reads_traces_with_the_monitors_reader(tmp_path) -> None:
    """Line endings and quoting the monitor accepts, plan accepts alike; what it refuses is a
    diagnostic at its place, and a non-finite state is refused."""
    plans = [plan_scenario(str(REPO / "scenarios/scalability.yaml"), at=2.0, trace=_drive(tmp_path, end))[0]
             for end in ("\n", "\r\n", "\r")]
    assert all(p is not None for p in plans) and plans[0].plan == plans[1].plan == plans[2].plan
    rep, diags = plan_scenario(str(REPO / "scenarios/scalability.yaml"), at=2.0, trace=_drive(tmp_path, v="inf"))
    assert rep is None and [d.code for d in diags] == ["MIL516"] and "v is inf" in diags[0].message
    rep, diags = plan_scenario(str(REPO / "scenarios/scalability.yaml"), at=2.0, trace=_drive(tmp_path, v="fast"))
    assert rep is None and [d.code for d in diags] == ["MIL516"] and diags[0].span.line > 1


def test_plan_json_follows_the_non_finite_convention() -> None:
    import json
    import math

    from twolevel.control.planner import PlanStatus
    from twolevel.pipeline.planning import PlanReport

    rep = PlanReport(PlanStatus.FALLBACK, math.nan, {"total": math.inf, "solve": 1.23456}, 0, 0, 0,
                     ((0.0, 1.0, math.nan, 0.0, math.inf, 0.0, 0.0),), (("a", math.inf), ("b", -math.inf),
                                                                         ("c", math.nan), ("d", 0.5)))
    out = json.loads(json.dumps(rep.to_json(), allow_nan=False))
    assert out["objective"] is None and out["solve_ms"] == {"total": None, "solve": 1.2346}
    assert out["plan"] == [[0.0, 1.0, None, 0.0, None, 0.0, 0.0]] and out["certified"] == "none"
    assert [r["robustness"] for r in out["rules"]] == ["inf", "-inf", None, 0.5]
