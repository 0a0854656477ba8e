"""Not passing on the right (rules/overtaking.stl, no_passing_right): the participant signals
d_behind(o) and left_of(o) (twolevel.world.relations) by hand, the same values from batched
sensing, check clean and misuse a type error, the MPC encodes the rule and agrees with the monitor,
and on the motorway scenario undertake_motorway the ego follows a slower car in the left lane
instead of undertaking it (without the rule it undertakes)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from helpers.world_files import load_world
from twolevel.cli import app
from twolevel.world.relations import relations
from twolevel.world.sensing import Memory, others_predicted, sense
from twolevel.world.signals import TrafficLog, participant_signals_along
from twolevel.world.traffic import TrafficState

ROOT = Path(__file__).resolve().parents[2]
RULE = ROOT / "rules" / "overtaking.stl"
SCENARIO = ROOT / "scenarios" / "everyday" / "undertake_motorway.yaml"


@pytest.fixture(scope="module")
def world():  # noqa: ANN201
    return load_world(SCENARIO)  # the motorway along x, lanes right (e = 0) and left (e = 3.5), 3.5 m wide


def _rel(world, others: list[tuple[float, float, float, float]], e: float = 0.0, psi: float = 0.0):  # noqa: ANN001, ANN202
    """Others as (s, e, heading, speed), each 4 m × 2 m; the ego (its own box) at s = 100, ``e``."""
    o = np.array(others, dtype=float)
    n = len(o)
    ego = {"s": np.array([100.0]), "e": np.array([e]), "psi": np.array([psi])}
    other = {"s": o[:, 0], "e": o[:, 1], "psi": o[:, 2], "v": o[:, 3]}
    return relations(world.route, ego, (world.ego.length, world.ego.width), other, np.full(n, 4.0), np.full(n, 2.0),
                     np.ones(n, bool))


def test_signals_by_hand(world) -> None:  # noqa: ANN001
    L, W = world.ego.length, world.ego.width
    r = _rel(world, [(103.0, 3.5, 0.0, 20.0),  # beside, in the left lane
                     (130.0, 3.5, 0.0, 20.0),  # ahead in the left lane
                     (80.0, 3.5, 0.0, 20.0),  # behind in the left lane
                     (100.0, 0.0, 0.0, 20.0),  # level in the ego's lane (not left of it)
                     (100.0, 3.5, math.pi, 20.0),  # oncoming on the left
                     (100.0, 2.2, 0.0, 20.0)])  # straddling: its body overlaps the ego's laterally
    assert r["d_behind"][0] == pytest.approx((100 - L / 2) - (103 + 2))
    assert r["d_lon"][0] == pytest.approx((103 - 2) - (100 + L / 2)) and r["d_lon"][0] < 0  # so beside
    assert r["left_of"][0] == pytest.approx((3.5 - 1) - W / 2)  # 2.5 − W/2 m of daylight between the bodies
    assert r["d_lon"][1] > 0 and r["d_behind"][2] == pytest.approx((100 - L / 2) - 82) and r["d_behind"][2] > 0
    assert r["left_of"][3] == pytest.approx(-1 - W / 2)  # o's right side is 1 m right of the ego's centre
    assert r["left_of"][4] == -np.inf  # running the other way: never left_of
    assert r["left_of"][5] == pytest.approx(1.2 - W / 2) and r["left_of"][5] < 0.5
    # the ego's heading is left out: the same values turned 0.1 rad
    turned = _rel(world, [(103.0, 3.5, 0.0, 20.0)], psi=0.1)
    assert turned["d_behind"][0] == pytest.approx(r["d_behind"][0]) and turned["left_of"][0] == pytest.approx(r["left_of"][0])
    # and the ego in the left lane: the car in the right lane is not left of it
    assert _rel(world, [(103.0, 0.0, 0.0, 20.0)], e=3.5)["left_of"][0] < 0


@settings(max_examples=15, deadline=None)
@given(st.floats(60.0, 160.0), st.floats(0.0, 30.0), st.floats(-0.5, 4.0), st.floats(15.0, 32.0))
def test_batched_sensing_equals_the_reference(s_o: float, v_o: float, e_o: float, v_e: float) -> None:
    w = load_world(SCENARIO)
    K, T, dt = 3, 12, w.settings.dt
    v = np.maximum(v_e + np.array([[-2.0], [0.0], [1.5]]) * dt * np.arange(T)[None], 0.0)
    s = 100.0 + np.cumsum(np.concatenate([np.zeros((K, 1)), v[:, :-1] * dt], axis=1), axis=1)
    e = np.linspace(0.0, 1.0, K)[:, None] * np.ones((1, T))
    pts = w.route.position(s, e)
    psi = w.route.heading_at(s) + 0.02
    lane = 1  # the left lane
    p, h = w.lanes.pose(np.array([lane]), np.array([s_o]))
    traffic = TrafficState(0.0, p[:, 0], p[:, 1] + (e_o - 3.5), h, np.array([v_o]), np.array([lane]), np.array([s_o]),
                           np.zeros(1), np.ones(1, bool), np.zeros(1), np.full(1, -1))
    others = others_predicted(w, traffic, float(pts[0, 0, 0]), float(pts[0, 0, 1]), 100.0, T - 1, dt)
    got = sense(w, 0.0, dt, Memory.fresh(w), others, pts[..., 0], pts[..., 1], psi, v, np.zeros((K, T)),
                np.zeros((K, T)))
    if not others.n:
        return
    ids = [w.parts.ids[j] for j in others.index]
    names = ("present", "v", "d_lon", "d_behind", "left_of")
    assert set(names[1:]) <= set(w.participant_signals)  # what no_passing_right reads, so what sensing computes
    log = TrafficLog(others.x.T, others.y.T, others.psi.T, others.v.T, np.ones((T, others.n), bool),
                     w.parts.length[others.index], w.parts.width[others.index])
    for k in range(K):
        ego = {"x": pts[k, :, 0], "y": pts[k, :, 1], "psi": psi[k], "v": v[k]}
        ref = participant_signals_along(w, log, ego, ids=ids, names=names)
        for key, want in ref.items():
            np.testing.assert_allclose(got[key][k], want, rtol=1e-9, atol=1e-9, err_msg=key)


def test_the_rule_checks_clean_and_misuse_is_a_type_error(tmp_path: Path) -> None:
    r = CliRunner().invoke(app, ["check", str(RULE)])
    assert r.exit_code == 0, r.output
    bad = tmp_path / "bad.stl"
    for text in ("input float v\nr = always[0:1] ((left_of > 0) -> (v <= 20));\n",  # the participant's signal, no o
                 "input float v\nr = always[0:1] ((left_of(o) > 0) -> (v <= 20));\n",  # no quantifier binds o
                 "input float v\nr = forall o in vehicles: (left_off(o) > 0) -> (v <= v(o));\n",  # a typo
                 "input float v\nr = forall o in vehicles: (d_behind(p) <= 0) -> (v <= v(o));\n"):  # another variable
        bad.write_text(text)
        r = CliRunner().invoke(app, ["check", str(bad)])
        assert r.exit_code != 0 and "STL2" in r.output, (text, r.output)


def test_the_mpc_encodes_the_rule_and_agrees_with_the_monitor(tmp_path: Path) -> None:
    """Coming up at 30 m/s behind the slower car in the left lane, ten MPC steps: the rule is
    encoded (not left to the low level), each plan's robustness by the monitor on the MPC's own
    signals equals the monitor's on the plan's true signals, and the plans never draw level faster."""
    from helpers.mpc_worlds import closed_loop
    from twolevel.control.high_level.controller import HighLevelController
    from twolevel.control.high_level.settings import MPCSettings
    from twolevel.monitor.robustness import robustness
    from twolevel.world.signals import signals_along
    from twolevel.world.world import load_rulesets

    text = SCENARIO.read_text().replace("../../", f"{ROOT}/").replace("s: 110}", "s: 45}")  # 25 m ahead, within r_near
    path = tmp_path / "close.yaml"
    path.write_text(text)
    w = load_world(path)
    sets, diags = load_rulesets(w)
    assert not [d for d in diags if d.is_error]
    ctrl = HighLevelController(w, sets, MPCSettings(H=10, dt=0.1, time_limit=None))
    assert "no_passing_right" in {r.name for r in ctrl.rules}
    assert not [d for d in ctrl.diagnostics if d.code == "MIL510"]
    by = {r.name: rs for rs in sets for r in rs.rules}
    xs, res, trs = closed_loop(ctrl, w, 60)
    rs = by["no_passing_right"]
    cols = ("x", "y", "psi", "v")
    checked = 0
    for i, r in enumerate(res):
        assert r.ok
        T = len(r.states)
        tr = trs[i]
        log = TrafficLog(np.array([tr.x + tr.v * np.cos(tr.psi) * 0.1 * k for k in range(T)]),
                         np.array([tr.y + tr.v * np.sin(tr.psi) * 0.1 * k for k in range(T)]),
                         np.repeat(tr.psi[None], T, 0), np.repeat(tr.v[None], T, 0), np.ones((T, len(tr.x)), bool),
                         w.parts.length, w.parts.width)
        ego = {k: r.states[:, j] for j, k in enumerate(cols)}
        sig = signals_along(w, None, ego) | participant_signals_along(w, log, ego, names=("present", "v", "d_lon",
                                                                                       "d_behind", "left_of"))
        true = float(robustness(rs.formula("no_passing_right"), sig, 0.1, consts=rs.consts)[0])
        claimed = r.rule_robustness["no_passing_right"]
        assert claimed >= -1e-6 and true >= -1e-6, (i, true, claimed)
        if np.isfinite(true) and np.isfinite(claimed):
            assert true == pytest.approx(claimed, abs=0.05), (i, true, claimed)
            checked += 1
    assert checked >= 10  # the car was beside-or-near often enough for the rule to have a finite value
    s_car = 45.0 + 22.0 * 0.1 * np.arange(len(xs))
    assert (xs[:, 0] < s_car).all()  # the ego's centre never passed the car's


def _simulate(scenario: Path, out: Path) -> tuple[dict[str, np.ndarray], Path]:
    from twolevel.monitor.tracefile import read_trace
    from twolevel.sim.engine import simulate_scenario

    summary, diags = simulate_scenario(str(scenario), str(out), frames=False, ttr_every=0)
    assert summary is not None and summary.status == "complete", [d.message for d in diags]
    trace = Path(summary.run_dir) / "trace.csv"
    data, _ = read_trace(str(trace))
    assert data is not None
    return {k: np.asarray(v, float) for k, v in data.columns.items()}, trace


@pytest.mark.slow
def test_the_ego_follows_the_slower_car_on_the_left(tmp_path: Path) -> None:
    cols, trace = _simulate(SCENARIO, tmp_path / "run")
    r = CliRunner().invoke(app, ["monitor", str(RULE), str(trace), "--format", "json", "--series"])
    assert r.exit_code == 0, r.output
    out = {x["name"]: x for x in json.loads(r.output)["rules"]}
    series = np.array([np.inf if v == "inf" else v for v in out["no_passing_right"]["series"]], dtype=float)
    assert (series >= 0).all() and np.isfinite(series).any()  # judged while the car was near, and held
    present = cols["present[slow_left]"] > 0
    assert present.sum() > 50
    assert (cols["d_behind[slow_left]"][present] < 0).all()  # the ego's rear never got past the car's front
    assert (cols["d_lon[slow_left]"][present][-20:] > -0.5).all()  # it ends behind the car's rear, following
    assert 22.0 <= cols["v"][-1] < 24.0  # slowed from 30 m/s to close in on the car's 22 m/s gently
    # without the rule the same drive undertakes the car: the ego ends far ahead of it
    text = SCENARIO.read_text().replace("../../", f"{ROOT}/").replace(f"  - {ROOT}/rules/overtaking.stl\n", "")
    text = text.replace(", no_passing_right", "")
    plain = tmp_path / "plain.yaml"
    plain.write_text(text)
    cols0, _ = _simulate(plain, tmp_path / "run0")
    car_end = 90.0 + 22.0 * 0.1 * (len(cols0["s"]) - 1)  # its route position (the route starts at the lane's 20 m)
    assert float(cols0["s"][-1]) > car_end + 50.0 and float(cols0["v"][-1]) > 28.0
