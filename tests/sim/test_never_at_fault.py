"""The ego is never at fault: closed-loop runs of the reckless planner (which ignores everyone)
under the safety layer, among adversarial but legal others (:mod:`twolevel.safety.adversary`:
random braking down to the bounds, accelerating, legal cut-ins, pedestrians wandering within
SPOT's bounds). Whatever they do, no collision is the ego's fault, and every step has a
fail-safe. Runs that start unsafe (no fail-safe at t = 0) are not drawn: the guarantee is
conditional on a safe start, which the simulator reports (SIM616)."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from twolevel.safety.adversary import Adversary, scenario_text
from twolevel.sim.engine import simulate_scenario


def adversaries(seconds: int) -> st.SearchStrategy[Adversary]:
    accels = st.lists(st.floats(-8.0, 2.0), min_size=seconds, max_size=seconds).map(tuple)
    leader = st.builds(Adversary, role=st.just("leader"), ahead=st.floats(6.0, 70.0), v0=st.floats(0.0, 18.0),
                       accels=accels)
    left = st.builds(Adversary, role=st.just("left"), ahead=st.floats(-30.0, 70.0), v0=st.floats(0.0, 18.0),
                     accels=accels, change_at=st.one_of(st.none(), st.floats(0.0, float(seconds))))
    walker = st.builds(Adversary, role=st.just("walker"), ahead=st.floats(8.0, 80.0), v0=st.floats(0.0, 2.0),
                       accels=st.lists(st.floats(0.0, 0.6), min_size=seconds, max_size=seconds).map(tuple),
                       y=st.floats(-8.0, 8.0),
                       headings=st.lists(st.floats(-math.pi, math.pi), min_size=seconds, max_size=seconds).map(tuple))
    return st.one_of(leader, left, walker)


def run(others: list[Adversary], ego_v0: float, duration: float):  # noqa: ANN201 - RunSummary
    with tempfile.TemporaryDirectory() as tmp:
        path = scenario_text(Path(tmp), others, ego_v0, duration)
        summary, diags = simulate_scenario(str(path), str(Path(tmp) / "run"), controller="reckless", frames=False,
                                           ttr_every=0)
    assert summary is not None, [d.message for d in diags]
    assert summary.status == "complete"
    return summary


def check(summary) -> None:  # noqa: ANN001
    assume(summary.safe_start)
    assert not [c for c in summary.collisions if c.at_fault], summary.collisions
    assert summary.verification.get("unverified", 0) == 0, summary.verification


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(others=st.lists(adversaries(3), min_size=1, max_size=3), ego_v0=st.floats(0.0, 15.0))
def test_the_ego_is_never_at_fault_among_legal_adversaries(others, ego_v0) -> None:
    check(run(others, ego_v0, 2.5))


@pytest.mark.slow
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(others=st.lists(adversaries(10), min_size=2, max_size=6), ego_v0=st.floats(0.0, 15.0))
def test_the_ego_is_never_at_fault_over_longer_runs(others, ego_v0) -> None:
    check(run(others, ego_v0, 10.0))


def test_an_illegal_cut_in_is_dropped_a_legal_one_kept(tmp_path: Path) -> None:
    """The generator keeps a lane change into the ego's lane only where it leaves the ego the safe
    distance (else the property would test the cutter's duty, not the ego's)."""
    close = Adversary("left", 5.0, 10.0, (0.0,) * 5, change_at=0.5)
    far = Adversary("left", 70.0, 10.0, (0.0,) * 5, change_at=0.5)
    text = scenario_text(tmp_path, [close, far], 10.0, 5.0).read_text()
    ys = [[float(w.split("y: ")[1].rstrip("}")) for w in block.splitlines() if "y: " in w]
          for block in text.split("behaviour: scripted")[1:]]
    assert max(ys[0]) == min(ys[0]) == 1.75  # stays on the left lane
    assert ys[1][0] == 1.75 and ys[1][-1] == -1.75  # changes into the ego's (right) lane
