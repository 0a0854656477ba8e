"""The verifier on hand-built worlds: what it accepts, what it refutes, and who refutes it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers.safety_worlds import ego_on, place, world
from twolevel.models import fourwheel as fw
from twolevel.models.rollout import rollout
from twolevel.safety.verify import _back, context, time_to_react, verify_initial_state, verify_step

KEEP = np.array([0.0, 0.0])  # [δ, γ]: roll on
FULL = np.array([0.0, -1.0])


def reasons(v) -> list[tuple[str, str | None]]:
    return [(r.reason, r.participant or r.lane) for r in v.refutations]


# ------------------------------------------------------------------- a stalled car ahead


@pytest.mark.parametrize("gap, verified, kept", [(110.0, True, "brake 4"), (30.0, True, "brake 6"),
                                                 (20.0, True, "brake full"), (15.0, False, None)])
def test_stalled_car(gap, verified, kept):
    """At 15 m/s, ``gap`` [m] between the centres: far away the gentlest fail-safe verifies; closer
    only harder braking does; too close to stop, none does, and each is refuted by the stalled car."""
    w = world("stalled")
    ctx = context(w)
    traffic = place(w, w.traffic0, "stalled", "road", 10.0 + gap)
    v = verify_step(ctx, ego_on(w, "road", 10.0, 15.0), KEEP, traffic, 0.0)
    assert v.verified is verified
    assert (v.failsafe.name if v.failsafe else None) == kept
    assert all(r == ("collision", "stalled") for r in reasons(v))
    if not verified:
        assert len(v.refutations) == 3 and v.refuted_by.participant == "stalled"


def test_the_kept_failsafe_is_what_the_plant_does():
    """Executed step by step from the state after the intended step, the kept fail-safe
    reproduces the verified states exactly, and the car stands at its end."""
    w = world("stalled")
    ctx = context(w)
    x0 = ego_on(w, "road", 10.0, 15.0)
    v = verify_step(ctx, x0, KEEP, place(w, w.traffic0, "stalled", "road", 60.0), 0.0)
    x = rollout(x0, KEEP[None, None, :], w.settings.dt, ctx.params).states[0, 1]
    assert np.array_equal(x, v.failsafe.states[0])
    for k in range(v.failsafe.steps):
        x = rollout(x, v.failsafe.control_at(k)[None, None, :], w.settings.dt, ctx.params).states[0, 1]
    assert np.array_equal(x, v.failsafe.states[-1])
    assert abs(x[3]) <= ctx.settings.failsafe.v_stop
    assert x[0] + w.ego.length / 2 < 60.0 - w.parts.length[0] / 2


def test_an_unsafe_start_is_reported():
    w = world("stalled")
    ctx = context(w)
    traffic = place(w, w.traffic0, "stalled", "road", 20.0)
    assert not verify_initial_state(ctx, ego_on(w, "road", 10.0, 15.0), traffic).verified
    assert verify_initial_state(ctx, ego_on(w, "road", 10.0, 15.0), w.traffic0).verified


def test_time_to_react_shrinks_as_the_hazard_nears():
    """Holding 15 m/s towards the stalled car: far away the whole plan can be followed; nearer,
    fewer steps; too near, not even one."""
    w = world("stalled")
    ctx = context(w)
    plan = np.tile(KEEP, (10, 1))
    steps = [time_to_react(ctx, ego_on(w, "road", 10.0, 15.0), plan,
                           place(w, w.traffic0, "stalled", "road", 10.0 + gap), 0.0) for gap in (80.0, 27.0, 15.0)]
    assert steps[0].steps == 10 and steps[0].at_least
    assert 0 <= steps[1].steps < 10 and not steps[1].at_least
    assert steps[2].steps == -1
    assert steps[1].seconds == pytest.approx(steps[1].steps * w.settings.dt)


# ------------------------------------------------------------------- a crossing lane


def test_standing_inside_a_crossing_lane_is_refuted_before_it_verified():
    """Standing still: before the crossing it verifies; inside the crossing lane no braking
    fail-safe does (someone may come), and with the crossing car close enough nothing does."""
    w = world("crossing_scn")
    ctx = context(w)
    assert verify_initial_state(ctx, ego_on(w, "east", 92.0, 0.0), w.traffic0).verified
    traffic = place(w, w.traffic0, "crosser", "north", 88.0, v=10.0)  # 10 m from the crossing
    inside = verify_initial_state(ctx, ego_on(w, "east", 101.0, 0.0), traffic)
    assert not inside.verified
    assert ("standstill", "north") in reasons(inside)
    assert ("collision", "crosser") in reasons(inside)


def test_a_car_inside_a_junction_clears_it_when_it_can():
    """Standing inside the crossing with the crossing car far away: the fail-safe that verifies
    leaves the crossing (gaining speed), then brakes."""
    w = world("crossing_scn")
    ctx = context(w)
    v = verify_initial_state(ctx, ego_on(w, "east", 101.0, 0.0), place(w, w.traffic0, "crosser", "north", 10.0))
    assert v.verified and v.failsafe.name.startswith("clear")
    assert all(r.reason == "standstill" for r in v.refutations)
    end = v.failsafe.states[-1]
    assert end[0] - w.ego.length / 2 > 103.5  # behind it: the crossing lane is 100 ≤ x ≤ 103.5


def test_entering_a_junction_it_cannot_clear_is_refuted():
    """At 10 m/s just before the crossing, with the crossing car arriving: every fail-safe either
    stops inside the crossing lane or meets the car."""
    w = world("crossing_scn")
    ctx = context(w)
    x0 = ego_on(w, "east", 94.0, 10.0)
    near = verify_step(ctx, x0, KEEP, place(w, w.traffic0, "crosser", "north", 85.0, v=12.0), 0.0)
    assert not near.verified
    assert set(reasons(near)) <= {("standstill", "north"), ("collision", "crosser")}
    assert ("collision", "crosser") in reasons(near)
    far = verify_step(ctx, x0, KEEP, place(w, w.traffic0, "crosser", "north", 0.0, v=0.0), 0.0)
    assert far.verified


@pytest.mark.parametrize("t, verified", [(5.0, True), (40.0, False)])
def test_a_red_light_holds_crossing_traffic(t, verified):
    """The crossing car can stop for its light: while red the ego may cross in front of it; at
    green the same step is refuted."""
    w = world("crossing_light_scn")
    ctx = context(w)
    traffic = place(w, w.traffic0, "crosser", "north", 82.0, v=12.0)  # 13 m before its line: it can stop
    v = verify_step(ctx, ego_on(w, "east", 96.0, 10.0), KEEP, traffic, t)
    assert v.verified is verified
    if not verified:
        assert ("collision", "crosser") in reasons(v)


# ------------------------------------------------------------------- turning left


@pytest.mark.parametrize("s_oncoming, verified", [(10.0, True), (75.0, False)])
def test_an_oncoming_car_at_a_left_turn(s_oncoming, verified):
    """Inside the junction, turning left across the oncoming lane at 4 m/s: stopping there is
    never invariably safe; clearing the oncoming lane verifies only while the oncoming car is far."""
    w = world("left_turn")
    ctx = context(w)
    traffic = place(w, w.traffic0, "oncoming", "in_w", s_oncoming, v=12.0)
    v = verify_step(ctx, ego_on(w, "left_n", 4.0, 4.0), KEEP, traffic, 0.0)
    assert v.verified is verified
    assert ("standstill", "thru_w") in reasons(v)
    if verified:
        assert v.failsafe.name.startswith("clear")
    else:
        assert ("collision", "oncoming") in reasons(v)


def test_waiting_before_the_left_turn_verifies():
    w = world("left_turn")
    ctx = context(w)
    traffic = place(w, w.traffic0, "oncoming", "in_w", 80.0, v=12.0)
    assert verify_step(ctx, ego_on(w, "in_e", 82.0, 3.0), FULL, traffic, 0.0).verified


# ------------------------------------------------------------------- what others answer for


def test_followers_and_cut_ins_are_theirs_while_the_ego_keeps_its_lane():
    """A faster car behind on the ego's lane and one beside it on the next lane do not refute
    the ego while it is inside its lane; once it straddles the marking, both are checked."""
    w = world("lanes3")
    ctx = context(w)
    assert verify_step(ctx, ego_on(w, "middle", 200.0, 20.0), KEEP, w.traffic0, 0.0).verified
    straddling = verify_step(ctx, ego_on(w, "middle", 200.0, 20.0, lateral=1.2), KEEP, w.traffic0, 0.0)
    assert not straddling.verified
    assert {p for _, p in reasons(straddling)} & {"behind", "beside"}


def test_a_pedestrian_beside_the_road_slows_the_ego():
    """A pedestrian 3 m from the lane's edge ahead may step in: the gentle fail-safe is refuted by
    it; 25 m from the road it is not."""
    w = world("walker")
    ctx = context(w)
    x0 = ego_on(w, "road", 10.0, 15.0)
    near = verify_step(ctx, x0, KEEP, place(w, w.traffic0, "walker", xy=(35.0, 4.75, -np.pi / 2), v=1.4), 0.0)
    assert ("collision", "walker") in reasons(near)
    far = verify_step(ctx, x0, KEEP, place(w, w.traffic0, "walker", xy=(35.0, 30.0, -np.pi / 2), v=1.4), 0.0)
    assert far.verified and far.failsafe.name == "brake 4"


def test_the_route_hint_does_not_change_the_verdict():
    w = world("stalled")
    ctx = context(w)
    x0 = ego_on(w, "road", 10.0, 15.0)
    traffic = place(w, w.traffic0, "stalled", "road", 50.0)
    a = verify_step(ctx, x0, KEEP, traffic, 0.0)
    b = verify_step(ctx, x0, KEEP, traffic, 0.0, s_hint=0.0)
    assert a.verified == b.verified and a.failsafe.name == b.failsafe.name
    assert np.array_equal(a.failsafe.controls, b.failsafe.controls)


# ------------------------------------------------------------------- a bend: in its lane or not


def _on_route(w, s: float, e: float, rel: float, v: float) -> np.ndarray:
    """The ego's detailed state at route position ``s`` [m], lateral offset ``e`` [m] (left +),
    heading ``rel`` [rad] off the route's, rolling at ``v`` [m/s]."""
    r = w.route
    (x, y), h = r.position(np.array([s]))[0], float(r.heading_at(np.array([s]))[0])
    return fw.initial_state(x - e * np.sin(h), y + e * np.cos(h), h + rel, v)


@pytest.mark.parametrize("e, rel, back", [(-0.52, 0.126, False), (-0.3, 0.25, False), (-1.3, 0.126, True),
                                          (0.6, -0.35, True)])
def test_in_a_bend_the_box_is_judged_against_the_lane_under_each_corner(e, rel, back):
    """Moving off into the right turn of maps/tee_junction.yaml (radius ~8 m): a box whose corners
    all lie within the lane where each lies along the curving route is in its lane, and its
    fail-safes brake or clear along the route — not steer "back in lane" towards a place past
    the car far ahead in the lane it turns into (those were rolled out for hundreds of steps
    each control step). Far enough off, it is out of its lane and the fail-safes steer back."""
    w = world("scenarios/traffic/right_turn_stream.yaml")
    ctx = context(w)
    lead = place(w, w.traffic0, "from_left_3", "east_out", 20.0, v=11.0)  # ahead in the lane it turns into
    v = verify_initial_state(ctx, _on_route(w, 56.0, e, rel, 3.0), lead, s_hint=56.0)
    names = [r.failsafe for r in v.refutations] + ([v.failsafe.name] if v.failsafe else [])
    assert names and all(n.endswith("back in lane") is back for n in names)


# ------------------------------------------------------------------- out of the lane, passing


@pytest.mark.parametrize("s_car, v_car, counted", [
    (130.0, 20.0, False),  # ahead and moving away faster than the ego: not being passed
    (130.0, 12.0, False),  # ahead at the ego's own speed: the ego does not close on it
    (130.0, 8.0, True),  # ahead and slower: the ego is closing on it
    (101.0, 14.0, True),  # beside the ego, even a little faster: being passed
])
def test_only_a_vehicle_closed_on_or_beside_counts_as_being_passed(s_car, v_car, counted):
    """The ego out on the oncoming lane of maps/passing_road.yaml at 12 m/s, a car in the route's
    lane: it is being passed (the fail-safes may complete the pass past it, the verifier holds
    its speed) only when the ego is beside it or closing on it — a car ahead that drives away
    at the ego's speed or faster is not, and no fail-safe chases it to pass it."""
    w = world("scenarios/everyday/overtake_tractor_oncoming.yaml")
    ctx = context(w)
    x0 = _on_route(w, 100.0, 3.5, 0.0, 12.0)
    traffic = place(w, w.traffic0, "tractor", "east", s_car + 10.0, v=v_car)  # the route starts at s = 10
    e_goal, s_past, e_beside, v_past, _, passed = _back(ctx, traffic, 100.0, 3.5, x0[:3], 12.0)
    tractor = w.parts.ids.index("tractor")
    assert bool(passed[tractor]) is counted and passed.sum() == counted
    assert math.isfinite(s_past) is counted and math.isnan(e_beside) is not counted
    assert v_past == (pytest.approx(v_car, abs=1e-6) if counted else 0.0)
    v = verify_step(ctx, x0, KEEP, traffic, 0.0, s_hint=100.0)
    names = [r.failsafe for r in v.refutations] + ([v.failsafe.name] if v.failsafe else [])
    assert names and all(n.endswith("back in lane") for n in names)
    assert any(n.startswith("clear") for n in names) is counted  # completing the pass: only past one closed on
