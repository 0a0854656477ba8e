"""The crosswalk signals ``xwalk_busy`` and ``d_xwalk`` (twolevel/world/crosswalks.py) against values
computed by hand on scenarios/traffic/zebra.yaml (a zebra at x = 120 m of a straight street, the
route from x = 10 m on lane east), the batched sensing against the reference, the MPC's horizon
constants, and which runs record them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.sim.extra_columns import ExtraColumns
from twolevel.world.crosswalks import PAST, STEPPED, YIELD_DECEL
from twolevel.world.provided import ON_DEMAND_SIGNALS, PROVIDED_SIGNALS, SIGNALS
from twolevel.world.sensing import Memory, others_predicted, sense
from twolevel.world.signals import PASS_MARGIN, TrafficLog, horizon_constants, signals_along
from twolevel.world.traffic import TrafficState
from twolevel.world.traffic.pedestrians import ENTERING, STOP_SHORT

from helpers.world_files import load_world

ROOT = Path(__file__).resolve().parents[2]
ZEBRA = ROOT / "scenarios" / "traffic" / "zebra.yaml"
W = load_world(ZEBRA)
Y_EGO = -1.75  # the centre of lane east
X_CROSS = 120.0  # the zebra, on lane east at s = 120 (the route's s = 110)
LINE_X = X_CROSS - STOP_SHORT - W.ego.length / 2  # where the ego's reference point stands at the line
KERB_Y = W.crosswalks.origin[0, 1]  # where the pedestrian waits (right kerb, below the street)


def _at(x: float, v: float, walked: float, active: bool = True) -> dict[str, float]:
    """The signals for the ego at (x, Y_EGO) [m] at ``v`` [m/s], the pedestrian ``walked`` [m] from
    its kerb towards the far side."""
    log = TrafficLog(np.array([[X_CROSS]]), np.array([[KERB_Y + walked]]), np.array([[math.pi / 2]]),
                     np.array([[1.4 if walked > 0 else 0.0]]), np.array([[active]]), np.array([0.5]), np.array([0.5]))
    sig = signals_along(W, log, {"x": np.array([x]), "y": np.array([Y_EGO]), "psi": np.zeros(1), "v": np.array([v])})
    return {"busy": float(sig["xwalk_busy"][0]), "d": float(sig["d_xwalk"][0])}


def test_the_crosswalk_on_the_route_as_built() -> None:
    cw = W.crosswalks
    assert cw.n == 1 and cw.owner.tolist() == [0]
    assert cw.s[0] == pytest.approx(X_CROSS - 10.0)
    assert cw.line[0] == pytest.approx(X_CROSS - 10.0 - STOP_SHORT - 4.22 / 2)
    # the path from the right kerb (0.75 m outside the parking lane, y = -6) crosses lane east
    # (y from -3.5 to 0; its border with the parking lane where their centres' halfway lies, -3.25)
    assert KERB_Y == pytest.approx(-6.75, abs=0.06)
    assert cw.enter[0] == pytest.approx(-3.25 - KERB_Y, abs=0.06)
    assert cw.leave[0] == pytest.approx(0.0 - KERB_Y, abs=0.06)


@pytest.mark.parametrize(("x", "v", "walked", "active", "busy", "d"), [
    # waiting at the kerb, 40 m before the line at 13.9 m/s: can stop at 4 m/s² (24.1 m), busy
    (LINE_X - 40.0, 13.9, 0.0, True, 1.0, 40.0),
    # 28 m: stopping takes 3.45 m/s², below 4 (the planners' 3 m/s² would not): busy
    (LINE_X - 28.0, 13.9, 0.0, True, 1.0, 28.0),
    # waiting, 20 m before the line at 13.9 m/s: cannot stop comfortably, passes (not busy)
    (LINE_X - 20.0, 13.9, 0.0, True, 0.0, 20.0),
    # stepping onto the ego's lane (walked 2 m: within ENTERING of its edge), 20 m at 13.9 m/s: busy
    (LINE_X - 20.0, 13.9, 2.0, True, 1.0, 20.0),
    # on the ego's lane, ego standing 0.3 m before the line: busy
    (LINE_X - 0.3, 0.0, 5.0, True, 1.0, 0.3),
    # past the ego's lane (7.5 m walked, its far edge at 6.75 + PAST): not busy, the ego may go
    (LINE_X - 0.3, 0.0, 7.5, True, 0.0, 0.3),
    # gone from the scene (inactive): not busy
    (LINE_X - 0.3, 0.0, 0.0, False, 0.0, 0.3),
    # the line 3 m behind the ego: the waiting pedestrian no longer binds it, ...
    (LINE_X + 3.0, 5.0, 0.0, True, 0.0, -3.0),
    # ... one walking on its lane does (the ego ran the crosswalk: the rule sees it)
    (LINE_X + 3.0, 5.0, 5.0, True, 1.0, -3.0),
    # more than PASS_MARGIN past the line: no crosswalk applies
    (LINE_X + 6.0, 5.0, 5.0, True, 0.0, math.inf),
    # beyond r_near (50 m) of the line: none applies, and the pedestrian is not sensed
    (LINE_X - 60.0, 13.9, 0.0, True, 0.0, math.inf),
])
def test_signals_by_hand(x: float, v: float, walked: float, active: bool, busy: float, d: float) -> None:
    got = _at(x, v, walked, active)
    assert got["busy"] == busy
    assert got["d"] == pytest.approx(d, abs=1e-6) if math.isfinite(d) else got["d"] == math.inf


def test_without_traffic_the_line_is_measured_and_nothing_is_busy() -> None:
    sig = signals_along(W, None, {"x": np.array([LINE_X - 10.0, 200.0]), "y": np.full(2, Y_EGO), "psi": np.zeros(2),
                                  "v": np.full(2, 5.0)})
    assert sig["xwalk_busy"].tolist() == [0.0, 0.0]
    assert sig["d_xwalk"][0] == pytest.approx(10.0) and sig["d_xwalk"][1] == math.inf


@settings(max_examples=150, deadline=None)
@given(x=st.floats(0.0, 200.0), v=st.floats(0.0, 20.0), walked=st.floats(0.0, 13.5), active=st.booleans())
def test_signals_follow_their_definition(x: float, v: float, walked: float, active: bool) -> None:
    """The definition (module docstring) written out for one pedestrian, one sample at a time."""
    cw = W.crosswalks
    d = float(cw.line[0]) - (x - 10.0)
    seen = active and math.hypot(X_CROSS - x, KERB_Y + walked - Y_EGO) <= W.settings.r_near
    applies = -PASS_MARGIN <= d <= W.settings.r_near
    on_way = STEPPED < walked and walked >= float(cw.enter[0]) - ENTERING
    not_past = walked <= float(cw.leave[0]) + PAST
    can_stop = d >= v * v / (2 * YIELD_DECEL)
    busy = applies and seen and not_past and (on_way or can_stop)
    got = _at(x, v, walked, active)
    assert got["busy"] == float(busy)
    assert (got["d"] == pytest.approx(d, abs=1e-6)) if applies else got["d"] == math.inf
    # the rule's premise never asks a line behind the ego of a pedestrian who only waits
    if busy and d < 0:
        assert on_way


@settings(max_examples=25, deadline=None)
@given(x0=st.floats(40.0, 130.0), v0=st.floats(0.0, 15.0), walked=st.floats(0.0, 12.0),
       speed=st.floats(0.0, 1.4), seed=st.integers(0, 2**16))
def test_batched_sensing_equals_the_reference(x0: float, v0: float, walked: float, speed: float, seed: int) -> None:
    """What the low level senses over K predicted trajectories is the reference's value on each."""
    rng = np.random.default_rng(seed)
    K, T, dt = 3, 12, 0.1
    v = np.clip(v0 + np.cumsum(rng.uniform(-0.6, 0.3, (K, T)), axis=1), 0.0, None)
    x = x0 + np.cumsum(v * dt, axis=1)
    y = np.full((K, T), Y_EGO) + rng.uniform(-0.3, 0.3, (K, 1))
    psi = np.zeros((K, T))
    traffic = TrafficState(0.0, np.array([X_CROSS]), np.array([KERB_Y + walked]), np.array([math.pi / 2]),
                           np.array([speed]), np.array([-1]), np.zeros(1), np.zeros(1), np.ones(1, bool), np.zeros(1),
                           np.full(1, -1))
    others = others_predicted(W, traffic, float(x[0, 0]), float(y[0, 0]), float(x[0, 0]) - 10.0, T - 1, dt)
    got = sense(W, 0.0, dt, Memory.fresh(W), others, x, y, psi, v, np.zeros((K, T)), np.zeros((K, T)))
    assert set(got) == PROVIDED_SIGNALS
    for k in range(K):
        log = TrafficLog(others.x.T, others.y.T, others.psi.T, others.v.T, np.ones((T, others.n), bool),
                         np.full(others.n, 0.5), np.full(others.n, 0.5))
        ref = signals_along(W, log, {"x": x[k], "y": y[k], "psi": psi[k], "v": v[k]})
        for name in ON_DEMAND_SIGNALS:
            np.testing.assert_array_equal(got[name][k], ref[name], err_msg=f"{name} row {k}")


def test_horizon_constants_hold_the_busy_crosswalk_over_the_horizon() -> None:
    ego = (LINE_X - 40.0, Y_EGO, 0.0, 13.9)
    waiting = TrafficState(0.0, np.array([X_CROSS]), np.array([KERB_Y]), np.array([math.pi / 2]), np.zeros(1),
                           np.array([-1]), np.zeros(1), np.zeros(1), np.ones(1, bool), np.zeros(1), np.full(1, -1))
    hc = horizon_constants(W, waiting, 0.0, ego)
    assert hc.s_xwalk == pytest.approx(float(W.crosswalks.line[0]))
    assert hc.xwalk_busy.tolist() == [1.0] * (W.settings.H + 1)
    across = TrafficState(0.0, np.array([X_CROSS]), np.array([KERB_Y + 9.0]), np.array([math.pi / 2]), np.zeros(1),
                          np.array([-1]), np.zeros(1), np.zeros(1), np.ones(1, bool), np.zeros(1), np.full(1, -1))
    assert not horizon_constants(W, across, 0.0, ego).xwalk_busy.any()


def test_runs_record_the_crosswalk_signals_only_when_a_rule_reads_them() -> None:
    assert W.on_demand_signals == ("xwalk_busy", "d_xwalk")
    assert set(ON_DEMAND_SIGNALS) <= set(ExtraColumns(W).columns)
    assert not set(ON_DEMAND_SIGNALS) & set(SIGNALS)  # not among the columns every run records
    other = load_world(ROOT / "scenarios" / "traffic" / "cut_in.yaml")
    assert other.on_demand_signals == () and not set(ON_DEMAND_SIGNALS) & set(ExtraColumns(other).columns)


def test_the_low_levels_history_is_not_cut_by_on_demand_signals_a_run_does_not_record() -> None:
    """Regression: the low level's judge took the shortest history over every provided signal,
    the on-demand ones included, which a run without a rule reading them never records: no past
    at all, and return_after_passing (15 s of past) failed on overtake_stalled's pass."""
    from twolevel.control.low_level.judge import history_length

    recorded = {n: np.zeros(20) for n in SIGNALS}
    assert history_length(recorded, 15) == 15
    assert history_length(recorded | {"xwalk_busy": np.zeros(5)}, 15) == 5
