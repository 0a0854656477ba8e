"""Metrics of hand-made traces match hand computation."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers.report_runs import write_run
from twolevel.report.comparison import compare_metrics
from twolevel.report.metrics import COLLISION_LINE_M, compute_metrics, find_violations
from twolevel.sim.summary import intervals
from twolevel.sim.trace import TraceWriter, read_run

NAN = float("nan")

# Ten samples, dt = 0.1 s. Every column chosen so the expected numbers can be worked out by hand.
STEP_MS = [10, 20, 30, 40, 50, 60, 70, 80, 90, 200]
TRACK = [0.0, 0.1, 0.2, 0.3, 0.29, 0.1, 0.0, 0.0, 0.0, 0.0]
V = [10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 8.0, 10.0, 10.0]
VMAX = [NAN, 13.9, 13.9, 13.9, 13.9, 8.3, 8.3, 8.3, 8.3, 8.3]
GAP = [5.0, 3.0, 1.0, -0.5, -1.2, -0.1, 2.0, 3.0, -0.3, 4.0]
ROB = [1.0, -1.0, -2.0, -0.5, 0.5, NAN, -3.0, -3.0, 0.0, -1.0]
DECISION = ["mpc"] * 6 + ["sampled", "sampled", "brake", "fallback"]
LIGHT = ["none"] * 4 + ["red"] * 3 + ["green"] * 3
NEAR = [0, 1, 2, 3, 3, 2, 1, 0, 0, 0]
OUTCOME = ["verified"] * 6 + ["failsafe", "failsafe", "verified", "verified"]
TTR = [3.0, NAN, NAN, NAN, NAN, 0.5, NAN, NAN, NAN, NAN]


def _hand_rows() -> list[dict[str, object]]:
    return [
        {
            "t": round(0.1 * k, 10), "x": 2.0 * k, "y": 0.5, "v": V[k], "decision": DECISION[k],
            "t_high_ms": STEP_MS[k] / 2, "t_low_ms": STEP_MS[k] / 2 - 1, "t_step_ms": STEP_MS[k],
            "n_near": NEAR[k], "min_dist": GAP[k] + COLLISION_LINE_M, "min_gap": GAP[k],
            "tracking_error": TRACK[k], "v_max": VMAX[k], "light_state": LIGHT[k], "rob_speed": ROB[k],
            "verification": OUTCOME[k], "ttr_s": TTR[k],
        }
        for k in range(10)
    ]


@pytest.fixture
def hand(tmp_path):
    summary = {"collisions": [{"t": 0.3, "x": 6.0, "y": 0.5, "other": "car_1", "at_fault": True,
                               "verdict": "ego_at_fault", "reason": "drove into it"},
                              {"t": 0.8, "x": 16.0, "y": 0.5, "other": "car_2"}]}  # an older run: not classified
    write_run(tmp_path / "hand", _hand_rows(), rules=("speed",), summary=summary)
    return compute_metrics(read_run(tmp_path / "hand"))


def test_latency_percentiles_and_rate(hand) -> None:
    lt = hand.latency
    assert lt.total.p50 == pytest.approx(55.0)  # linear interpolation between 50 and 60
    assert lt.total.p95 == pytest.approx(90 + 0.55 * 110)  # rank 0.95 * 9 = 8.55
    assert lt.total.p99 == pytest.approx(90 + 0.91 * 110)
    assert lt.total.max == 200 and lt.total.min == 10 and lt.total.mean == pytest.approx(65.0)
    assert lt.high.p50 == pytest.approx(27.5) and lt.low.max == pytest.approx(99.0)
    assert lt.steps_over_budget == 1 and lt.share_over_budget == pytest.approx(0.1)
    assert hand.rate.hz.min == pytest.approx(5.0) and hand.rate.hz.max == pytest.approx(100.0)
    assert hand.rate.hz.p50 == pytest.approx(np.percentile(1000.0 / np.array(STEP_MS), 50))
    assert hand.rate.steps_below_10hz == 1


def test_tracking_speed_and_time_over_limit(hand) -> None:
    assert hand.tracking.max_m == pytest.approx(0.3) and hand.tracking.t_max_s == pytest.approx(0.3)
    assert hand.tracking.mean_m == pytest.approx(0.099)
    sp = hand.speed
    assert sp.max_overspeed_mps == pytest.approx(1.7) and sp.t_max_overspeed_s == pytest.approx(0.5)
    # over the limit at samples 5, 6, 8, 9 (sample 7 is at 8.0 ≤ 8.3): 4 × 0.1 s in two episodes
    assert sp.time_over_limit_s == pytest.approx(0.4) and sp.episodes_over_limit == 2
    # the first sample has no limit and is not judged: 0.4 s of 0.9 s judged
    assert sp.share_over_limit == pytest.approx(0.4 / 0.9)
    assert hand.duration_s == pytest.approx(1.0) and hand.dt_s == pytest.approx(0.1)


def test_violations_are_intervals_with_depths(hand) -> None:
    got = [(v.rule, round(v.t_start, 6), round(v.t_end, 6), v.depth, round(v.t_depth, 6), v.steps) for v in hand.violations]
    assert got == [
        ("speed", 0.1, 0.3, -2.0, 0.2, 3),
        ("speed", 0.6, 0.7, -3.0, 0.6, 2),  # NaN at 0.5 ends the first interval; 0.0 at 0.8 is satisfied
        ("speed", 0.9, 0.9, -1.0, 0.9, 1),
    ]
    (rule,) = hand.rules
    assert rule.initial == 1.0 and rule.final == -1.0 and rule.min == -3.0 and rule.t_min == pytest.approx(0.6)
    assert not rule.satisfied and rule.violations == 3 and rule.time_violated_s == pytest.approx(0.6)


def test_collisions_from_gap_and_summary(hand) -> None:
    eps = hand.collisions.episodes
    assert [(round(e.t_start, 6), round(e.t_end, 6), e.depth_m, e.x) for e in eps] == [(0.3, 0.5, -1.2, 6.0), (0.8, 0.8, -0.3, 16.0)]
    assert [r.other for r in hand.collisions.reported] == ["car_1", "car_2"]
    assert hand.collisions.collided and hand.collisions.count == 2
    assert [r.at_fault for r in hand.collisions.reported] == [True, None] and hand.collisions.at_fault == 1
    assert hand.collisions.reported[0].reason == "drove into it"
    d = hand.distance
    assert d.min_gap_m == -1.2 and d.t_min_gap_s == pytest.approx(0.4)
    assert d.min_dist_m == pytest.approx(COLLISION_LINE_M - 1.2) and d.below_line
    assert d.time_below_line_s == pytest.approx(0.4)  # centre distance < 4.22 m ⇔ gap < 0: samples 3, 4, 5, 8
    assert hand.problems == ()


def test_decisions_lights_nearby(hand) -> None:
    dec = hand.decisions
    assert dec.count("mpc") == 6 and dec.share("sampled") == pytest.approx(0.2)
    assert dec.share("brake") == pytest.approx(0.1) and dec.share("fallback") == pytest.approx(0.1) and dec.count("nmpc") == 0
    assert dict(dec.level_shares) == pytest.approx({"high": 0.7, "low": 0.3, "safety": 0.0, "nmpc": 0.0})
    assert hand.lights.share("none") == pytest.approx(0.4) and hand.lights.share("red") == pytest.approx(0.3)
    assert hand.lights.share("green") == pytest.approx(0.3) and hand.lights.share("yellow") == 0.0
    assert hand.nearby.max == 3 and hand.nearby.mean == pytest.approx(1.2)


def test_to_dict_is_strict_json(hand, tmp_path) -> None:
    text = json.dumps(hand.to_dict(), allow_nan=False)
    back = json.loads(text)
    assert back["violations"][0]["depth"] == -2.0 and back["collisions"]["count"] == 2
    assert back["speed"]["t_max_overspeed_s"] == pytest.approx(0.5)
    # infinities survive as strings, NaN as null
    rows = [{"t": 0.1 * k, "v": 1.0, "min_dist": math.inf, "rob_r": -math.inf if k == 1 else NAN} for k in range(3)]
    write_run(tmp_path / "inf", rows, rules=("r",))
    d = compute_metrics(read_run(tmp_path / "inf")).to_dict()
    json.dumps(d, allow_nan=False)
    assert d["distance"]["min_dist_m"] == "inf" and d["violations"][0]["depth"] == "-inf" and d["rules"][0]["initial"] is None


def test_summary_disagreeing_with_trace_is_a_problem(tmp_path) -> None:
    write_run(tmp_path / "r", _hand_rows(), rules=("speed",), summary={"collisions": []})
    m = compute_metrics(read_run(tmp_path / "r"))
    assert m.collisions.collided and m.collisions.reported == ()
    assert any("0 collision(s)" in p and "2 overlap episode(s)" in p for p in m.problems)


def test_missing_columns_drop_their_groups_and_say_so(tmp_path) -> None:
    with TraceWriter(tmp_path / "old", ("t", "x", "y", "v", "decision"), {}) as w:
        for k in range(4):
            w.write({"t": 0.1 * k, "x": k, "y": 0, "v": 3.0, "decision": "mpc"})
    m = compute_metrics(read_run(tmp_path / "old"))
    assert m.rows == 4 and m.latency is None and m.rate is None and m.tracking is None and m.distance is None
    assert m.speed is not None and m.speed.max_mps == 3.0 and m.speed.time_over_limit_s == 0.0
    assert m.decisions.count("mpc") == 4 and m.rules == () and not m.collisions.collided
    assert any("'t_step_ms' is missing" in p for p in m.problems)
    assert any("'min_gap' is missing" in p for p in m.problems)


def test_no_vehicle_near_gives_infinite_distance(tmp_path) -> None:
    rows = [{"t": 0.1 * k, "min_dist": math.inf, "min_gap": math.inf} for k in range(3)]
    write_run(tmp_path / "alone", rows, rules=())
    d = compute_metrics(read_run(tmp_path / "alone")).distance
    assert d.min_dist_m == math.inf and d.min_gap_m == math.inf and not d.below_line


def test_compare_ratios_to_first_run(hand, tmp_path) -> None:
    rows = _hand_rows()
    for r in rows:
        r["t_step_ms"] = 2 * float(r["t_step_ms"])
        r["tracking_error"] = 0.5 * float(r["tracking_error"])
    write_run(tmp_path / "slow", rows, rules=("speed",), summary={"collisions": []})
    other = compute_metrics(read_run(tmp_path / "slow"))
    table = compare_metrics([hand, other])
    assert table.runs == ("hand", "slow")
    assert table.row("latency_p50").values == (pytest.approx(55.0), pytest.approx(110.0))
    assert table.row("latency_p50").ratios == (1.0, pytest.approx(2.0))
    assert table.row("tracking_max").ratios[1] == pytest.approx(0.5)
    assert table.row("rate_p50").ratios[1] == pytest.approx(0.5)
    assert table.row("steps").values == (10, 10)
    assert table.row("share_mpc").values == (pytest.approx(60.0), pytest.approx(60.0))
    json.dumps(table.to_dict(), allow_nan=False)


def test_compare_ratio_undefined_when_first_is_zero(hand) -> None:
    calm = replace(hand, speed=replace(hand.speed, max_overspeed_mps=0.0), latency=None)
    table = compare_metrics([calm, hand])
    assert table.row("over_budget").values == (None, 1) and table.row("over_budget").ratios == (None, None)
    assert table.row("overspeed_max").values == (0.0, pytest.approx(1.7))
    assert table.row("overspeed_max").ratios == (None, None)
    assert table.row("tracking_max").ratios == (1.0, 1.0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(st.floats(-5, 5), st.just(NAN)), min_size=0, max_size=40))
def test_violation_intervals_cover_exactly_the_negative_samples(values) -> None:
    rob = np.array(values, dtype=float)
    t = np.arange(rob.size) * 0.1
    viol = find_violations("r", rob, t)
    covered = np.zeros(rob.size, dtype=bool)
    for v in viol:
        s, e = int(round(v.t_start / 0.1)), int(round(v.t_end / 0.1))
        assert e - s + 1 == v.steps
        assert not covered[s : e + 1].any()
        covered[s : e + 1] = True
        assert (rob[s : e + 1] < 0).all()
        assert v.depth == rob[s : e + 1].min()
        # maximal: the neighbours are not violations
        assert s == 0 or not rob[s - 1] < 0
        assert e == rob.size - 1 or not rob[e + 1] < 0
    with np.errstate(invalid="ignore"):
        assert np.array_equal(covered, rob < 0)
    starts, ends = intervals(rob < 0)
    assert len(starts) == len(viol)


def test_a_time_column_running_backwards_is_a_problem(tmp_path) -> None:
    """A reversed trace gave 'simulated time -0.5 s' without a word (review)."""
    from twolevel.report.metrics import compute_metrics
    from twolevel.sim.trace import TraceWriter, read_run

    with TraceWriter(tmp_path, ("t", "v"), {}) as w:
        for t in (0.5, 0.4, 0.3):
            w.write({"t": t, "v": 1.0})
    m = compute_metrics(read_run(tmp_path))
    assert any("does not increase at row 3" in p for p in m.problems)


def test_the_safety_layer_and_braking(hand) -> None:
    sf = hand.safety
    assert dict(sf.outcomes) == {"verified": 8, "failsafe": 2, "unverified": 0, "off": 0}
    assert sf.ttr_min_s == 0.5
    # v drops 10 → 8 m/s in one step (20 m/s²) and comes back: one step of nine brakes harder than 4 m/s²
    assert sf.decel_peak_mps2 == pytest.approx(20.0) and sf.hard_braking_share == pytest.approx(1 / 9)


def test_criticality_minima_figure_and_headline(tmp_path) -> None:
    """The criticality columns' minima (inf-only columns stay inf), the figure (with the safety
    layer's time to react where the trace has it) and the summary rows."""
    from twolevel.report.figures import Series, render_figures
    from twolevel.report.summary import headline

    inf = math.inf
    ttc = [inf, 8.0, 4.0, 2.5, 3.0, inf, inf, inf, inf, inf]
    thw = [3.0, 2.0, 1.2, 0.9, 1.1, 1.5, 2.0, inf, inf, inf]
    rows = _hand_rows()
    for k, row in enumerate(rows):
        row.update({"ttc_s": ttc[k], "thw_s": thw[k], "dhw_m": 10.0 * thw[k], "ttc_any_s": inf,
                    "ttr_s": 1.5 if k % 5 == 0 else NAN})
    run_dir = write_run(tmp_path / "crit", rows, rules=("speed",))
    m = compute_metrics(read_run(run_dir))
    c = m.criticality
    assert (c.min_ttc_s, c.t_min_ttc_s) == (2.5, pytest.approx(0.3))
    assert (c.min_thw_s, c.min_dhw_m, c.t_min_dhw_s) == (0.9, 9.0, pytest.approx(0.3))
    assert c.min_ttc_any_s == inf and math.isnan(c.t_min_ttc_any_s)
    assert m.to_dict()["criticality"]["min_ttc_any_s"] == "inf"
    rows_shown = dict(headline(m))
    assert rows_shown["min. time headway"] == "0.90 s at 0.3 s"
    figs, skipped = render_figures([Series("crit", read_run(run_dir), m)], None, formats=("png",))
    assert "criticality" in [f.name for f in figs]
    old = compute_metrics(read_run(write_run(tmp_path / "old", _hand_rows(), rules=("speed",))))
    assert old.criticality is None
    assert any("criticality" in s for s in render_figures([Series("old", read_run(tmp_path / "old"), old)], None,
                                                          formats=("png",))[1])
