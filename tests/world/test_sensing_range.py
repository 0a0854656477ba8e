"""The sensing range and the look-ahead settings: ``check``'s warnings and errors at the right line,
the settings' validation, the rss_gap signal (offline and batched alike), and RSS's inverse."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from helpers.world_files import load_world
from twolevel.cli import app
from twolevel.control.high_level.settings import MPCSettings
from twolevel.world.look_ahead import DEFAULT_HORIZON_S, MAX_COARSE_STEPS, look_ahead_periods
from twolevel.world.assumptions import ResponseBounds, safe_distance, safe_speed, stopping_speed
from twolevel.pipeline.checking import check
from twolevel.world.loader import check_world_file, load_scenario
from twolevel.world.sensing import Memory, others_now, others_predicted, sense
from twolevel.world.signals import TrafficLog, signals_along
from twolevel.world.traffic import TrafficState
from twolevel.world.world import build_world

MAPS = Path(__file__).resolve().parents[2] / "maps"
runner = CliRunner()


def scenario(tmp: Path, controller: str, *, desired: str = "", participants: str = "[]") -> Path:
    """A highway scenario (limit 30 m/s) whose ``controller:`` section starts on line 9."""
    text = f"""kind: scenario
name: sensing
map: {MAPS / 'highway.yaml'}
ego:
  start: {{lane: middle, s: 20}}
  speed: 10{desired}
route: {{start: {{lane: middle, s: 20}}, goal: {{lane: middle, s: 1400}}, stop_at_goal: false}}
participants: {participants}
controller:
{controller}expect: {{goal: false}}
"""
    p = tmp / "s.yaml"
    p.write_text(text)
    return p


def findings(p: Path) -> list:
    """What ``twolevel check`` reports for a file (its loader's diagnostics and its lints)."""
    return list(check([str(p)]).diagnostics)


def test_a_sensing_range_too_short_for_the_speed_allowed_is_warned_at_its_line(tmp_path: Path) -> None:
    p = scenario(tmp_path, "  r_near: 20\n  sensor_range: 60\n")
    diags = findings(p)
    assert [(d.code, d.span.line, d.span.column) for d in diags] == [("YML431", 11, 17)]
    msg = diags[0].message
    need = safe_distance(30.0, 0.0, ResponseBounds(0.1, 3.0, 4.0, 8.0)) + 4.22 + 1.0
    v_bound = stopping_speed(60 - 4.22 - 1.0, ResponseBounds(0.1, 3.0, 4.0, 8.0))
    # the numbers: the range, the distance needed at the speed allowed, the speed kept to
    assert "sensing range 60 m" in msg and f"{need:.1f} m" in msg and "at 30 m/s" in msg
    assert f"at most {v_bound:.1f} m/s" in msg and "speed limit 30 m/s" in msg
    assert f"sensor_range to at least {math.ceil(need)} m" in diags[0].hint
    # a warning, not an error: the scenario loads, and the ego keeps to the bound
    scn, _ = load_scenario(p)
    assert scn is not None and build_world(scn).settings.v_sense == pytest.approx(v_bound)


def test_the_desired_speed_caps_the_speed_allowed(tmp_path: Path) -> None:
    # 14 m/s needs 26 m + one car length + D_safe: 60 m suffice, 30 m do not
    ok = scenario(tmp_path, "  r_near: 20\n  sensor_range: 60\n", desired="\n  desired_speed: 14")
    assert findings(ok) == []
    short = scenario(tmp_path, "  r_near: 20\n  sensor_range: 30\n", desired="\n  desired_speed: 14")
    d = findings(short)
    assert [x.code for x in d] == ["YML431"] and "desired speed 14 m/s" in d[0].message and "at 14 m/s" in d[0].message


def test_without_a_sensor_range_the_warning_points_at_the_controller_section(tmp_path: Path) -> None:
    # the default range (100 m) is too short for the highway's 30 m/s: the section is where to add it
    p = scenario(tmp_path, "  r_near: 20\n")
    d = findings(p)
    assert [(x.code, x.span.line) for x in d] == [("YML431", 9)] and "sensing range 100 m" in d[0].message


def test_the_cli_reports_it_and_strict_fails(tmp_path: Path) -> None:
    p = scenario(tmp_path, "  sensor_range: 60\n")
    res = runner.invoke(app, ["check", str(p), "-f", "json"], env={"GITHUB_ACTIONS": ""})
    out = json.loads(res.stdout)
    assert res.exit_code == 0 and [(d["code"], d["severity"], d["line"]) for d in out["diagnostics"]] == \
        [("YML431", "warning", 10)]
    assert runner.invoke(app, ["check", str(p), "--strict"], env={"GITHUB_ACTIONS": ""}).exit_code == 1


@pytest.mark.parametrize("controller, line, words", [
    ("  horizon_s: 4.05\n", 11, "horizon_s = 4.05 s is not a whole number of periods"),
    ("  horizon_s: 0.5\n", 11, "shorter than the fine part"),
    ("  coarse_dt: 0.25\n", 11, "coarse_dt = 0.25 s is not a whole number"),
    ("  coarse_steps: [0.5, 0.35]\n", 11, "a coarse step = 0.35 s"),
    ("  coarse_dt: 0.5\n  coarse_steps: [1.0]\n", 12, "not both"),
    ("  horizon_s: 3.0\n  coarse_steps: [1.0]\n", 11, "differs from H·dt + the coarse steps"),
    ("  r_near: 40\n  sensor_range: 30\n", 12, "shorter than r_near"),
])
def test_bad_look_ahead_and_range_settings_are_errors_at_their_line(tmp_path: Path, controller: str, line: int,
                                                                    words: str) -> None:
    p = scenario(tmp_path, controller + "  sensor_range: 150\n" if "sensor_range" not in controller else controller,
                 desired="\n  desired_speed: 14")
    d = [x for x in check_world_file(p) if x.is_error]
    assert len(d) == 1 and d[0].span.line == line and words in d[0].message, [(x.code, x.span.line, x.message) for x in d]
    assert d[0].code == ("YML414" if "r_near" in words else "YML430")
    assert load_scenario(p)[0] is None


def test_the_settings_validate_the_look_ahead_as_check_does() -> None:
    assert MPCSettings().steps == (0.1,) * 10 + (0.5,) * 8 and MPCSettings().look_ahead == pytest.approx(5.0)
    assert MPCSettings(horizon_s=1.0).N == 10 and MPCSettings(H=60).N == 60  # never shorter than the fine part
    assert MPCSettings(horizon_s=2.3).steps[10:] == pytest.approx((0.5, 0.5, 0.3))  # a shorter last step
    assert MPCSettings(coarse_steps=[0.5, 1.0]).periods == (1,) * 10 + (5, 10)
    for bad in (dict(horizon_s=0.5), dict(horizon_s=2.05), dict(coarse_dt=0.25), dict(coarse_dt=0.5, coarse_steps=(1,)),
                dict(horizon_s=3.0, coarse_steps=(1.0,)), dict(coarse_dt=0.1, horizon_s=30.0), dict(H=0)):
        with pytest.raises(ValueError):
            MPCSettings(**bad)


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 40), st.sampled_from([0.05, 0.1, 0.2]), st.integers(0, 100), st.integers(1, 20))
def test_the_look_ahead_is_the_fine_part_then_whole_periods_up_to_the_horizon(H: int, dt: float, extra: int,
                                                                               coarse: int) -> None:
    if -(-extra // coarse) > MAX_COARSE_STEPS:
        with pytest.raises(ValueError, match="coarse steps; at most"):
            look_ahead_periods(H, dt, (H + extra) * dt, coarse * dt)
        return
    periods = look_ahead_periods(H, dt, (H + extra) * dt, coarse * dt)
    assert periods[:H] == (1,) * H and sum(periods) == H + extra
    assert all(1 <= n <= coarse for n in periods[H:]) and all(n == coarse for n in periods[H:-1])
    default = look_ahead_periods(H, dt)
    assert sum(default) == max(round(DEFAULT_HORIZON_S / dt), H) and len(default) - H <= MAX_COARSE_STEPS


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 200.0), st.floats(0.0, 40.0), st.floats(0.0, 2.0), st.floats(0.5, 10.0))
@example(5e-324, 0.0, 5e-324, 4.0)  # subnormal terms once rounded the root below zero
def test_safe_speed_inverts_rss_distance(gap: float, v_front: float, rho: float, brake: float) -> None:
    r = ResponseBounds(rho, 3.0, brake, 8.0)
    v = safe_speed(gap, v_front, r)
    assert v >= 0.0
    if v > 0:  # the speed whose RSS distance is the gap, and any faster needs more
        assert safe_distance(v, v_front, r) == pytest.approx(gap, abs=1e-6 * max(1.0, gap))
        assert safe_distance(v + 0.01, v_front, r) > gap
    else:
        assert safe_distance(0.0, v_front, r) >= gap - 1e-9
    assert stopping_speed(gap, r) == safe_speed(gap, 0.0, r)
    # safe_distance is elementwise on arrays and equal to its scalar form (to the last bits)
    arr = safe_distance(np.array([0.0, v, 2 * v]), np.full(3, v_front), r)
    np.testing.assert_allclose(arr, [safe_distance(x, v_front, r) for x in (0.0, v, 2 * v)], rtol=1e-12, atol=1e-9)


def _ahead_world(tmp: Path):
    parts = ("[{id: near, behaviour: constant_velocity, start: {lane: left, s: 26}, speed: 10.0},"
             " {id: far, behaviour: constant_velocity, start: {lane: middle, s: 33}, speed: 6.0},"
             " {id: farther, behaviour: constant_velocity, start: {lane: middle, s: 95}, speed: 9.0}]")
    return load_world(scenario(tmp, "  r_near: 10\n  sensor_range: 60\n", desired="\n  desired_speed: 12",
                               participants=parts))


def test_rss_gap_is_the_sensed_vehicle_ahead_beyond_r_near(tmp_path: Path) -> None:
    w = _ahead_world(tmp_path)
    tr = w.traffic0
    ego = {"x": np.array([w.ego.x]), "y": np.array([w.ego.y]), "psi": np.array([0.0]), "v": np.array([10.0])}
    log = TrafficLog.of([tr], w.parts.length, w.parts.width)
    sig = signals_along(w, log, ego)
    gap = 33.0 - 20.0 - 4.22  # 'far' (13 m away, beyond r_near, within 60 m); 'farther' is beyond the range
    assert sig["rss_gap"][0] == pytest.approx(gap - safe_distance(10.0, 6.0, w.settings.response))
    assert math.isinf(sig["d_lead"][0]) and sig["n_near"][0] == 1  # the neighbourhood stays r_near's
    # the simulator's sensing: the same, with 'far' among the vehicles sensed now
    now = others_now(w, tr, w.ego.x, w.ego.y, 0.0)  # route positions: the route starts at the ego
    assert sorted(w.parts.ids[i] for i in now.index) == ["far", "near"]
    got = sense(w, 0.0, 0.1, Memory.fresh(w), now, *(np.array([[c]]) for c in (w.ego.x, w.ego.y, 0.0, 10.0, 0.0, 0.0)))
    for name in ("rss_gap", "d_lead", "n_near", "min_gap", "v_lead"):
        assert got[name][0, 0] == pytest.approx(sig[name][0]), name


def test_a_vehicle_sensed_only_for_rss_never_joins_the_neighbourhood_of_a_prediction(tmp_path: Path) -> None:
    # predicted over 1 s the ego closes on 'far' to within r_near, as the low level's candidates
    # may: it counts for rss_gap, never for n_near, min_gap or d_lead (sensed beyond r_near now)
    w = _ahead_world(tmp_path)
    tr = w.traffic0
    now = others_now(w, tr, w.ego.x, w.ego.y, 0.0)
    pred = others_predicted(w, tr, w.ego.x, w.ego.y, 0.0, 10, 0.1, now=now)
    xs = np.linspace(20.0, 32.0, 11)[None]  # a candidate from 20 m to 32 m in 1 s
    ys = np.full((1, 11), w.ego.y)
    got = sense(w, 0.0, 0.1, Memory.fresh(w), pred, xs, ys, np.zeros((1, 11)), np.full((1, 11), 10.0),
                np.zeros((1, 11)), np.zeros((1, 11)))
    far_x = 33.0 + 6.0 * 0.1 * np.arange(11)
    assert np.any(far_x - xs[0] <= w.settings.r_near)  # within r_near by the end of the prediction
    assert np.all(np.isinf(got["d_lead"])) and np.all(got["n_near"] <= 1)  # 'near' alone, while near
    assert np.all(np.isfinite(got["rss_gap"])) and np.all(got["rss_gap"] < far_x - xs[0])
