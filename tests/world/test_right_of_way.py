"""Right of way as signals (twolevel/world/right_of_way.py): the ego's next conflict area, and each
participant's time to reach and clear it and its priority — by hand on the T-junction, batched
sensing equal to the reference, and the rule file checked like every rule."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.world.loader import load_scenario
from twolevel.world.sensing import Memory, others_predicted, sense
from twolevel.world.signals import TrafficLog, participant_signals_along, signals_along
from twolevel.world.traffic import TrafficState
from twolevel.world.world import World, build_world

ROOT = Path(__file__).resolve().parents[2]
TRAFFIC = ROOT / "scenarios" / "traffic"


def _world(name: str) -> World:
    scn, diags = load_scenario(str(TRAFFIC / f"{name}.yaml"))
    assert scn is not None, [d.message for d in diags]
    return build_world(scn)


def _lane(w: World, name: str) -> int:
    return next(k for k, ln in enumerate(w.lanes.lanes) if ln.id == name)


def _ego_along(w: World, s: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
    p = w.route.position(s)
    return {"x": p[:, 0], "y": p[:, 1], "psi": w.route.heading_at(s), "v": v}


def _one(w: World, lane: str, s: float, v: float) -> TrafficLog:
    i = _lane(w, lane)
    p, h = w.lanes.pose(np.array([i]), np.array([s]))
    one = lambda a: np.asarray(a, float).reshape(1, 1)  # noqa: E731
    return TrafficLog(one(p[0, 0]), one(p[0, 1]), one(h[0]), one(v), np.ones((1, 1), bool), np.array([4.5]),
                      np.array([1.8]))


def test_the_left_turn_area_and_its_entry_and_exit_along_the_route() -> None:
    w = _world("left_turn_stream")
    z = w.zones
    assert len(z.area_s0) == 1 and z.area_s1[0] > z.area_s0[0]
    # the ego turns left from east_in (the route starts at s = 30 on it, 90 m long): the area
    # begins inside the junction box, past the end of east_in
    assert z.area_s0[0] > 90.0 - 30.0
    L = w.ego.length
    s = np.array([0.0, z.area_s0[0] - L / 2 - 1.0, z.area_s0[0], z.area_s1[0] + L / 2 + 0.5])
    sig = signals_along(w, None, _ego_along(w, s, np.array([5.0, 5.0, 0.0, 5.0])))
    np.testing.assert_allclose(sig["d_zone"][:3], z.area_s0[0] - (s[:3] + L / 2), atol=1e-6)
    np.testing.assert_allclose(sig["d_zone_out"][:3], z.area_s1[0] - (s[:3] - L / 2), atol=1e-6)
    assert sig["d_zone"][1] == pytest.approx(1.0) and sig["t_zone"][1] == pytest.approx(0.2)
    assert sig["t_zone"][2] == 0.0 and sig["t_zone_out"][2] == np.inf  # inside, standing
    assert sig["d_zone"][3] == np.inf and sig["d_zone_out"][3] == -np.inf  # left it: no area ahead


def test_oncoming_traffic_goes_first_and_its_time_to_reach_is_distance_over_speed() -> None:
    w = _world("left_turn_stream")
    z = w.zones
    west_in = _lane(w, "west_in")
    rows = np.flatnonzero(z.lane == west_in)
    assert len(rows) >= 1 and (z.first[rows] == 1).all()  # a left turn gives way to the opposite arm
    s_ego = np.array([z.area_s0[0] - 10.0])
    ego = _ego_along(w, s_ego, np.array([0.0]))
    for s_o, v_o in ((60.0, 11.0), (80.0, 5.0)):
        rel = participant_signals_along(w, _one(w, "west_in", s_o, v_o), ego, ids=("car",), t0=0.0)
        enter = z.enter[rows].min()
        assert rel["priority[car]"][0] == 1.0
        assert rel["t_reach[car]"][0] == pytest.approx((enter - (s_o + 2.25)) / v_o, rel=1e-6)
        assert rel["t_clear[car]"][0] == pytest.approx((z.leave[rows].max() - (s_o - 2.25)) / v_o, rel=1e-6)
        assert rel["d_exit[car]"][0] == pytest.approx(z.exit[rows].max() - (s_ego[0] - w.ego.length / 2), rel=1e-6)
    # standing at a distance: reaches nothing; past the junction (on east_out): absent
    rel = participant_signals_along(w, _one(w, "west_in", 60.0, 0.0), ego, ids=("car",))
    assert rel["t_reach[car]"][0] == np.inf and rel["priority[car]"][0] == 1.0
    rel = participant_signals_along(w, _one(w, "east_out", 5.0, 11.0), ego, ids=("car",))
    assert rel["t_reach[car]"][0] == np.inf and rel["priority[car]"][0] == 0.0 and rel["d_exit[car]"][0] == -np.inf


def test_the_priority_road_does_not_give_way_to_the_side_road() -> None:
    w = _world("blocked_exit")  # the ego goes straight on along the priority road
    z = w.zones
    side = _lane(w, "south_in")
    assert (z.first[z.lane == side] == 0).all() and (z.lane == side).any()
    ego = _ego_along(w, np.array([z.area_s0[0] - 20.0]), np.array([8.0]))
    rel = participant_signals_along(w, _one(w, "south_in", 70.0, 8.0), ego, ids=("car",))
    assert np.isfinite(rel["t_reach[car]"][0]) and rel["priority[car]"][0] == 0.0


def test_the_right_of_way_rules_check_clean_and_misuse_is_a_type_error(tmp_path: Path) -> None:
    r = CliRunner().invoke(app, ["check", str(ROOT / "rules" / "right_of_way.stl")])
    assert r.exit_code == 0, r.output
    bad = tmp_path / "bad.stl"
    bad.write_text("input float d_zone\nr = (d_zone <= 0) -> (t_reach(o) >= 2);\n")  # no quantifier binds o
    r = CliRunner().invoke(app, ["check", str(bad)])
    assert r.exit_code != 0 and "STL2" in r.output


@settings(max_examples=15, deadline=None)
@given(st.floats(0.0, 90.0), st.floats(0.0, 14.0), st.floats(-30.0, 15.0), st.floats(0.0, 10.0))
def test_batched_sensing_equals_the_reference(s_o: float, v_o: float, ds: float, v_e: float) -> None:
    """The zone signals over K candidate trajectories (sense, what the low level reads) equal
    signals_along / participant_signals_along sample by sample."""
    w = _left_turn()
    K, T, dt = 3, 12, w.settings.dt
    s0 = float(w.zones.area_s0[0]) + ds
    v = np.maximum(v_e + np.array([[-2.0], [0.0], [1.5]]) * dt * np.arange(T)[None], 0.0)
    s = s0 + np.cumsum(np.concatenate([np.zeros((K, 1)), v[:, :-1] * dt], axis=1), axis=1)
    pts = w.route.position(s)
    psi = w.route.heading_at(s)
    i = _lane(w, "west_in")
    p, h = w.lanes.pose(np.array([i]), np.array([s_o]))
    traffic = TrafficState(0.0, p[:, 0], p[:, 1], h, np.array([v_o]), np.array([i]), np.array([s_o]), np.zeros(1),
                           np.ones(1, bool), np.zeros(1), np.full(1, -1))
    others = others_predicted(w, traffic, float(pts[0, 0, 0]), float(pts[0, 0, 1]), s0, T - 1, dt)
    got = sense(w, 2.0, dt, Memory.fresh(w), others, pts[..., 0], pts[..., 1], psi, v, np.zeros((K, T)),
                np.zeros((K, T)))
    ids = [w.parts.ids[j] for j in others.index]
    for k in range(K):
        ego = {"x": pts[k, :, 0], "y": pts[k, :, 1], "psi": psi[k], "v": v[k]}
        ref = signals_along(w, None, ego, t0=2.0)
        for name in ("d_zone", "d_zone_out", "t_zone", "t_zone_out"):
            np.testing.assert_allclose(got[name][k], ref[name], rtol=1e-9, atol=1e-9, err_msg=name)
        if others.n:
            log = TrafficLog(others.x.T, others.y.T, others.psi.T, others.v.T, np.ones((T, others.n), bool),
                             w.parts.length[others.index], w.parts.width[others.index])
            names = tuple(n for n in ("t_reach", "priority", "d_exit") if n in w.participant_signals)
            assert len(names) == 3  # what rules/right_of_way.stl reads, so what sensing computes
            rel = participant_signals_along(w, log, ego, ids=ids, t0=2.0, names=names)
            for key, want in rel.items():
                np.testing.assert_allclose(got[key][k], want, rtol=1e-9, atol=1e-9, err_msg=key)


_CACHE: dict[str, World] = {}


def _left_turn() -> World:
    if "w" not in _CACHE:
        _CACHE["w"] = _world("left_turn_stream")
    return _CACHE["w"]
