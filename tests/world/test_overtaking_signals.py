"""The overtaking signals (over_centre, solid_left, no_overtaking: twolevel.world.area) and
rules/overtaking.stl: values by hand on the passing road (a dashed centre line, solid over east's
300–420 m, a no-overtaking zone over its 520–700 m), the same values from closed-loop sensing,
check clean and misuse a type error, and the MPC's encoding agrees with the offline monitor on
its plans while it passes a stalled car."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers.mpc_worlds import closed_loop, make_world
from helpers.world_files import load_world
from twolevel.cli import app
from twolevel.world.signals import signals_along

ROOT = Path(__file__).resolve().parents[2]
RULE = ROOT / "rules" / "overtaking.stl"
NAMES = ("over_centre", "solid_left", "no_overtaking")


def _passing_road(tmp_path: Path):  # noqa: ANN202
    """The passing road, the route along east from its s = 0 (route s = east's s)."""
    return make_world(tmp_path, "passing_road.yaml", "{start: {lane: east, s: 0}, speed: 10.0}",
                      "{start: {lane: east, s: 0}, goal: {lane: east, s: 790}}")


def _at(w, s: np.ndarray, e: np.ndarray) -> dict[str, np.ndarray]:  # noqa: ANN001
    xy = w.route.position(s, e)
    return signals_along(w, None, {"x": xy[:, 0], "y": xy[:, 1], "psi": w.route.heading_at(s),
                                   "v": np.full(len(s), 10.0)})


def test_signals_by_hand_on_the_passing_road(tmp_path: Path) -> None:
    w = _passing_road(tmp_path)
    half = w.ego.width / 2
    # inside the lane on the dashed stretch; over the solid stretch half over; in the zone, wholly out
    s = np.array([100.0, 350.0, 600.0, 450.0, 750.0])
    e = np.array([0.0, 1.75, 3.5, -0.5, 1.75 - half])
    sig = _at(w, s, e)
    np.testing.assert_allclose(sig["over_centre"], e + half - 1.75, atol=1e-6)  # the centre line at y = 0
    assert sig["over_centre"][0] < 0 and sig["over_centre"][1] == pytest.approx(half)
    assert sig["over_centre"][4] == pytest.approx(0.0, abs=1e-6)  # touching the line
    assert list(sig["solid_left"]) == [0.0, 1.0, 0.0, 0.0, 0.0]
    assert list(sig["no_overtaking"]) == [0.0, 0.0, 1.0, 0.0, 0.0]
    # the solid stretch and the zone end where the map says (route s = east's s here)
    edge = _at(w, np.array([299.0, 301.0, 419.0, 421.0, 519.0, 521.0, 699.0, 701.0]), np.zeros(8))
    assert list(edge["solid_left"]) == [0, 1, 1, 0, 0, 0, 0, 0]
    assert list(edge["no_overtaking"]) == [0, 0, 0, 0, 0, 1, 1, 0]


def test_a_road_without_an_oncoming_lane_has_no_centre_line(tmp_path: Path) -> None:
    w = make_world(tmp_path, "highway.yaml", "{start: {lane: middle, s: 20}, speed: 10.0}",
                   "{start: {lane: middle, s: 20}, goal: {lane: middle, s: 400}}")
    sig = _at(w, np.array([50.0, 200.0]), np.array([0.0, 4.0]))  # in the middle lane, in the left one
    assert (sig["over_centre"] == -np.inf).all()
    assert (sig["solid_left"] == 0).all() and (sig["no_overtaking"] == 0).all()


def test_closed_loop_sensing_gives_the_same_values(tmp_path: Path) -> None:
    from twolevel.world.sensing import Memory, Others, sense

    w = _passing_road(tmp_path)
    K, T = 2, 30
    s = np.linspace(280.0, 720.0, K * T).reshape(K, T)
    e = np.linspace(-1.0, 3.0, K * T).reshape(K, T)
    xy = w.route.position(s, e)
    psi, v = w.route.heading_at(s), np.full((K, T), 10.0)
    z = np.zeros((0, T))
    none = Others(z, z, z, z, z, z, np.zeros(0), np.zeros(0), np.zeros(0, int))
    got = sense(w, 0.0, 0.1, Memory.fresh(w), none, xy[..., 0], xy[..., 1], psi, v, np.zeros((K, T)),
                np.zeros((K, T)))
    for k in range(K):
        ref = signals_along(w, None, {"x": xy[k, :, 0], "y": xy[k, :, 1], "psi": psi[k], "v": v[k]})
        for name in NAMES:
            np.testing.assert_allclose(got[name][k], ref[name], atol=1e-9, err_msg=name)


def test_the_overtaking_rules_check_clean_and_misuse_is_a_type_error(tmp_path: Path) -> None:
    r = CliRunner().invoke(app, ["check", str(RULE)])
    assert r.exit_code == 0, r.output
    bad = tmp_path / "bad.stl"
    bad.write_text("input float over_centre\nr = always[0:1] (solid_lft > 0.5 -> over_centre <= 0);\n")  # a typo
    r = CliRunner().invoke(app, ["check", str(bad)])
    assert r.exit_code != 0 and "STL2" in r.output
    bad.write_text("r = forall o in vehicles: over_centre(o) <= 0;\n")  # the ego's signal, not a participant's
    r = CliRunner().invoke(app, ["check", str(bad)])
    assert r.exit_code != 0 and "STL2" in r.output


def _stalled_with_rules(tmp_path: Path, extra: Path) -> Path:
    """overtake_stalled with ``extra`` among its rules."""
    text = (ROOT / "scenarios" / "everyday" / "overtake_stalled.yaml").read_text()
    text = text.replace("../../", f"{ROOT}/").replace(
        "  - " + f"{ROOT}/rules/safe_distance.stl", f"  - {ROOT}/rules/safe_distance.stl\n  - {extra}")
    p = tmp_path / "stalled.yaml"
    p.write_text(text)
    return p


@pytest.mark.slow
def test_the_mpc_encoding_agrees_with_the_monitor_on_its_plans(tmp_path: Path) -> None:
    from twolevel.control.high_level.controller import HighLevelController
    from twolevel.control.high_level.settings import MPCSettings
    from twolevel.monitor.robustness import robustness
    from twolevel.world.world import load_rulesets

    # overtake_stalled loads rules/overtaking.stl; two more rules never binding (the road's left edge
    # is 3.5 m over the line) whose robustness reads over_centre's largest value over the plan and
    # the markings' flags. return_after_passing reads the recorded past: the controller gets the
    # history, and the monitor judges past + now + plan
    bound = tmp_path / "bound.stl"
    bound.write_text("// reads over_centre, solid_left and no_overtaking over the next second\n"
                     "input float over_centre\ninput float solid_left\ninput float no_overtaking\n"
                     "over_bound = always[0:1] (over_centre <= 4.0);\n"
                     "marks = always[0:1] ((solid_left + no_overtaking <= 0.5) or (over_centre <= 0));\n")
    w = load_world(_stalled_with_rules(tmp_path, bound))
    sets, diags = load_rulesets(w)
    assert not [d for d in diags if d.is_error], [d.message for d in diags]
    ctrl = HighLevelController(w, sets, MPCSettings(H=10, dt=0.1, time_limit=None))
    by = {r.name: rs for rs in sets for r in rs.rules}
    assert {"return_after_passing", "no_solid_crossing", "over_bound"} <= {r.name for r in ctrl.rules}  # all encoded
    # the ego's signals the rules read, and its path (the MPC reads it too); participants' are not recorded here
    reads = sorted({n for n in set().union(*(r.reads for r in ctrl.rules)) if "[" not in n} | {"x", "y"})
    xs, res, _ = closed_loop(ctrl, w, 100, history_names=reads)
    cols = ("x", "y", "psi", "v")
    lived = signals_along(w, None, {k: xs[:, i] for i, k in enumerate(cols)})
    depth = ctrl.history_depth
    checked = 0
    for i, r in enumerate(res):
        if not r.ok:
            continue
        xyv = r.states
        plan = signals_along(w, None, {k: xyv[:, j] for j, k in enumerate(cols)})
        lo = max(0, i - depth)
        sig = {n: np.concatenate([lived[n][lo:i], plan[n]]) for n in NAMES}
        for name in ("over_bound", "marks", "no_solid_crossing", "no_overtaking_zone", "return_after_passing"):
            rs = by[name]
            true = float(robustness(rs.formula(name), sig, 0.1, consts=rs.consts)[i - lo])
            claimed = r.rule_robustness[name]
            assert claimed >= -1e-6 and true >= -1e-6, (i, name, true, claimed)
            if np.isfinite(true) and np.isfinite(claimed):
                # e is linearised about the previous plan (centimetres on a straight road)
                assert true == pytest.approx(claimed, abs=0.05), (i, name, true, claimed)
        checked += 1
    assert checked > 80
    assert lived["over_centre"].max() > 0.5  # it did pass over the centre line, so over_centre's encoding was read out there


@pytest.mark.slow
def test_the_rules_hold_on_the_stalled_car_pass(tmp_path: Path) -> None:
    from twolevel.sim.engine import simulate_scenario

    path = ROOT / "scenarios" / "everyday" / "overtake_stalled.yaml"
    summary, diags = simulate_scenario(str(path), str(tmp_path / "run"), frames=False, ttr_every=0)
    assert summary is not None and summary.status == "complete", [d.message for d in diags]
    trace = Path(summary.run_dir) / "trace.csv"
    r = CliRunner().invoke(app, ["monitor", str(RULE), str(trace), "--format", "json", "--series"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    assert {x["name"] for x in out["rules"]} == {"no_solid_crossing", "no_overtaking_zone", "return_after_passing",
                                                 "no_passing_right"}
    from twolevel.monitor.tracefile import read_trace

    data, _ = read_trace(str(trace))
    assert data is not None
    assert np.max(np.asarray(data.columns["over_centre"], float)) > 0.5  # the pass went over the centre line, and came back
    for rule in out["rules"]:
        series = np.array([np.inf if v == "inf" else v for v in rule["series"]], dtype=float)
        assert (series >= 0).all(), rule["name"]


def test_the_mpc_returns_within_fifteen_seconds_of_leaving_its_lane() -> None:
    """return_after_passing binds on the recorded past: 0.4 m over the centre line for 14 s, the
    plan is back inside by the end of its first second (15 s); over for 4 s, nothing presses."""
    from twolevel.control.high_level.controller import HighLevelController
    from twolevel.control.high_level.settings import MPCSettings
    from twolevel.world.provided import SIGNALS
    from twolevel.world.world import load_rulesets

    w = load_world(ROOT / "scenarios" / "everyday" / "overtake_stalled.yaml")  # it loads rules/overtaking.stl
    sets, diags = load_rulesets(w)
    assert not [d for d in diags if d.is_error]
    ctrl = HighLevelController(w, sets, MPCSettings(H=10, dt=0.1, time_limit=None))
    assert "return_after_passing" in {r.name for r in ctrl.rules}
    cols = ("x", "y", "psi", "v")

    def drive(over: int) -> np.ndarray:
        """The plan's over_centre after 150 recorded samples at 10 m/s on the dashed stretch
        (route s 30–180 m, past the stalled car), the last ``over`` of them 0.4 m over the line."""
        s = 30.0 + np.arange(151.0)
        e = np.where(np.arange(151) < 150 - over, 0.0, 1.75 - w.ego.width / 2 + 0.4)
        xy = w.route.position(s, e)
        lived = signals_along(w, None, {"x": xy[:, 0], "y": xy[:, 1], "psi": w.route.heading_at(s), "v": np.full(151, 10.0)})
        history = {k: np.asarray(lived[k])[:-1] for k in SIGNALS if k in lived}
        assert history["over_centre"][-1] == pytest.approx(0.4) and not history["solid_left"].any()
        r = ctrl.solve(np.array([xy[-1, 0], xy[-1, 1], float(w.route.heading_at(s[-1:])[0]), 10.0]), 15.0, w.traffic0,
                       history)
        assert r.ok
        return signals_along(w, None, {k: r.states[:, j] for j, k in enumerate(cols)})["over_centre"]

    assert drive(140)[10] <= 1e-3  # over since 14 s ago: inside again at 15 s
    assert drive(40)[10] > 0.03  # over since 4 s ago: the plan returns at its own pace
