"""The desired speed along a route (twolevel/world/speed_profile.py): under every cap, within the
comfort limits, slowing before bends, and in the worlds the scenarios build."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.world.loader import load_scenario
from twolevel.world.speed_profile import Comfort, bend_speed, speed_profile
from twolevel.world.world import build_world

ROOT = Path(__file__).resolve().parents[2]
SPACING = 0.5


def _profile_inputs(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, Comfort, float | None]:
    n = draw(st.integers(2, 400))
    s = SPACING * np.arange(n)
    pieces = draw(st.lists(st.tuples(st.integers(1, 200), st.floats(0.0, 40.0), st.floats(-0.2, 0.2)),
                           min_size=1, max_size=6))
    cap = np.concatenate([np.full(k, v) for k, v, _ in pieces])
    kappa = np.concatenate([np.full(k, c) for k, _, c in pieces])
    cap = np.resize(cap, n)
    kappa = np.resize(kappa, n - 1)
    comfort = Comfort(draw(st.floats(0.3, 4.0)), draw(st.floats(0.3, 4.0)), draw(st.floats(0.3, 10.0)),
                      draw(st.floats(0.5, 5.0)))
    v_end = draw(st.sampled_from([None, 0.0]))
    return s, cap, kappa, comfort, v_end


@settings(max_examples=60, deadline=None)
@given(st.composite(_profile_inputs)())
def test_the_profile_keeps_every_cap_and_the_comfort_accelerations(args) -> None:  # noqa: ANN001
    s, cap, kappa, comfort, v_end = args
    v = speed_profile(s, cap, kappa, comfort, v_end)
    assert v.shape == s.shape and np.all(np.isfinite(v)) and np.all(v >= 0)
    assert np.all(v <= cap + 1e-9)
    bend = bend_speed(kappa, comfort.lat_accel)
    assert np.all(v[:-1] <= bend + 1e-9) and np.all(v[1:] <= bend + 1e-9)
    if v_end == 0.0:
        assert v[-1] == 0.0
    slope = np.diff(v**2) / np.diff(s)  # d(v²)/ds = 2·a
    assert np.all(slope >= -2 * comfort.decel - 1e-6)
    assert np.all(slope <= 2 * comfort.accel + 1e-6)


def test_braking_for_a_bend_begins_before_it_and_builds_up() -> None:
    s = SPACING * np.arange(801)  # 400 m
    kappa = np.where((s[:-1] >= 250) & (s[:-1] < 300), 1 / 40.0, 0.0)
    comfort = Comfort(accel=2.0, decel=2.0, jerk=2.0, lat_accel=2.0)
    v = speed_profile(s, np.full_like(s, 20.0), kappa, comfort)
    v_bend = math.sqrt(2.0 * 40.0)
    assert v[s == 250][0] <= v_bend + 1e-9
    assert v[0] == pytest.approx(20.0)
    # braking from 20 m/s to the bend's 8.9 m/s at 2 m/s² takes 80 m; it starts earlier still
    start = s[np.flatnonzero(v < 20.0 - 1e-6)[0]]
    assert 250 - start > (20.0**2 - v_bend**2) / (2 * 2.0)
    decel = -np.diff(v**2) / (2 * SPACING)
    k = np.flatnonzero(decel > 1e-6)[0]
    assert decel[k] < 0.2 * comfort.decel  # gradually, not at once at full comfort deceleration
    assert decel.max() <= comfort.decel + 1e-9
    after = s[np.flatnonzero((s > 300) & (v >= 20.0 - 1e-6))[0]]
    assert after > 300 + (20.0**2 - v_bend**2) / (2 * 2.0) - 1e-6  # leaves it at the comfort acceleration


def test_invalid_comfort_limits_are_refused() -> None:
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ValueError):
            Comfort(decel=bad)


@pytest.mark.parametrize("name,radius", [("mountain_road", 28.25), ("sharp_left_turn", 5.25), ("fast_bend", 41.75)])
def test_the_everyday_bends_are_approached_at_their_comfortable_speed(name: str, radius: float) -> None:
    w = build_world(load_scenario(ROOT / "scenarios" / "everyday" / f"{name}.yaml")[0])
    route, comfort = w.route, w.settings.comfort
    lat = route.v_des[:-1] ** 2 * np.abs(route.kappa)
    assert lat.max() <= comfort.lat_accel + 1e-6
    tightest = np.abs(route.kappa).max()
    assert 1 / tightest == pytest.approx(radius, rel=1e-3)
    k = int(np.argmax(np.abs(route.kappa)))
    assert route.v_des[k] == pytest.approx(math.sqrt(comfort.lat_accel * radius), rel=0.02)
    assert route.v_des.max() > 2 * route.v_des[k] or name == "fast_bend"
    assert route.limit_at(route.s[k]) > route.v_des[k] + 3.0  # the limit alone would not slow it


def test_comfort_settings_reach_the_world(tmp_path: Path) -> None:
    text = (ROOT / "scenarios" / "everyday" / "fast_bend.yaml").read_text(encoding="utf-8")
    text = text.replace("map: ../../maps/", f"map: {ROOT / 'maps'}/").replace(
        "  - ../../rules/", f"  - {ROOT / 'rules'}/")
    gentle = text + "controller: {comfort_lat_accel: 1.0, comfort_decel: 1.0, v2i: true, weights: {u: 0.5}}\n"
    (tmp_path / "gentle.yaml").write_text(gentle, encoding="utf-8")
    (tmp_path / "plain.yaml").write_text(text, encoding="utf-8")
    plain = build_world(load_scenario(tmp_path / "plain.yaml")[0])
    soft = build_world(load_scenario(tmp_path / "gentle.yaml")[0])
    assert soft.settings.comfort.lat_accel == 1.0 and soft.settings.v2i and not plain.settings.v2i
    assert soft.settings.weights[0] == 0.5 and plain.settings.weights == (1.0, 1.0, (1.0, 1.0, 1.0, 1.0))
    assert soft.route.v_des.min() == pytest.approx(math.sqrt(1.0 * 41.75), rel=0.02)
    assert soft.route.v_des.min() < plain.route.v_des.min() - 2.0
    # braking more gently begins earlier
    first = lambda w: w.route.s[np.flatnonzero(w.route.v_des < w.route.v_des[0] - 1e-6)[0]]  # noqa: E731
    assert first(soft) < first(plain) - 20.0
