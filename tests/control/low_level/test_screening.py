"""Screening candidates on a prefix of the prediction (LowLevelSettings.screen) never changes
the low level's decision: same choice, robustness and count with screening on and off, in the
cases where it prunes everything, some, or nothing; and only prefix-bounded rules enable it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.control.low_level import sampling
from twolevel.control.low_level.controller import LowLevelController
from twolevel.control.low_level.rules import prefix_bounded
from twolevel.control.low_level.settings import LowLevelSettings
from twolevel.models import fourwheel as fw
from twolevel.stl.parser import parse
from twolevel.world.sensing import Memory

from helpers.mpc_worlds import highway_world


def parse_formula(text: str):  # noqa: ANN201
    rf, diags = parse(f"input float v\nr = {text};\n", "t.stl")
    assert rf is not None, [d.message for d in diags]
    return rf.rules[0].formula

GAP = "input float min_gap\ninput float v\nsafe = always[0:1] collision_free(1.0);\n"
BOTH = GAP + "input float v_max\nspeed = always[0:1] (v <= v_max + 0.5);\n"


def _pair(w, rs, v: float, u: np.ndarray, *, samples: int = 200, step: int = 0, y: float = 0.0,
          psi: float | None = None):  # noqa: ANN001
    out = []
    for screen in ((), (3,), (3, 6), (2, 5, 8)):
        ll = LowLevelController.from_rulesets(w, [rs], settings=LowLevelSettings(samples=samples, seed=7, screen=screen,
                                                                                 safety=False))
        x0 = fw.initial_state(w.ego.x, w.ego.y + y, w.ego.psi if psi is None else psi, v)
        out.append((ll, ll.decide(x0, u, 0.0, w.traffic0, Memory.fresh(w), 20.0, None, step=step)))
    (off_ll, off), *screened = out
    assert not off_ll.screens
    for on_ll, on in screened:
        assert on_ll.screens
        assert on.decision == off.decision and on.candidates == off.candidates
        np.testing.assert_array_equal(on.control, off.control)
        np.testing.assert_array_equal(on.states, off.states)
        assert on.robustness == off.robustness and on.mpc_robustness == off.mpc_robustness
    return on


@pytest.fixture
def kept(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, int]]:
    """(survivors, candidates) of every screened round (of every screening setting tried)."""
    out: list[tuple[int, int]] = []
    orig = sampling.screen

    def spy(*a, **k):  # noqa: ANN002, ANN003, ANN202
        scr = orig(*a, **k)
        out.append((int(scr.keep.sum()), len(scr.keep)))
        return scr

    monkeypatch.setattr(sampling, "screen", spy)
    return out


def test_everything_pruned_brakes_as_without_screening(tmp_path: Path, kept: list) -> None:
    # a stopped car 6 m ahead at 15 m/s: every candidate collides within the first steps
    w, rs = highway_world(tmp_path, GAP, "{id: stalled, behaviour: stationary, start: {lane: middle, s: 26}}")
    d = _pair(w, rs, 15.0, np.tile([0.0, -2.0], (10, 1)))
    assert d.decision == "brake" and d.candidates == 200
    assert kept == [(0, 32), (0, 64), (0, 104)] * 3


def test_late_violation_stops_screening_and_brakes_the_same(tmp_path: Path, kept: list) -> None:
    # 8 m ahead at 6 m/s: the collision shows after the screened prefix, nothing is pruned, so
    # the later rounds are not screened
    w, rs = highway_world(tmp_path, BOTH, "{id: stalled, behaviour: stationary, start: {lane: middle, s: 28}}")
    d = _pair(w, rs, 6.0, np.tile([0.0, 0.0], (10, 1)))
    assert d.decision == "brake" and kept[0] == (32, 32)


@pytest.mark.parametrize("v, a", [(30.3, 1.0), (30.2, 0.5), (30.0, 1.5)])
def test_partly_pruned_round_samples_the_same(tmp_path: Path, kept: list, v: float, a: float) -> None:
    # near the limit, accelerating: the candidates with more throttle break it within the prefix
    w, rs = highway_world(tmp_path, BOTH)
    d = _pair(w, rs, v, np.tile([0.0, a], (10, 1)))
    assert d.decision == "sampled"
    assert kept and 0 < kept[0][0] < kept[0][1]


@pytest.mark.parametrize("text, bounded", [
    ("always[0:1] (v <= 3)", True),
    ("always[0:1] collision_free(1.0)", True),
    ("(v <= 3) and always[0:1] (v >= 1)", True),
    ("historically[0:1] always[0:0.5] (v <= 3)", True),
    ("(v >= 5) implies always[0:1] (v <= 6)", True),
    ("next (v <= 3)", True),
    ("v <= 3", True),
    ("eventually[0:1] (v <= 3)", False),
    ("not always[0:1] (v <= 3)", False),
    ("(v <= 3) until[0:1] (v >= 4)", False),
    ("always[0:1] (v <= 3) implies (v >= 1)", False),
    ("always[0:1] eventually[0:0.5] (v <= 3)", False),
])
def test_prefix_bounded(text: str, bounded: bool) -> None:
    assert prefix_bounded(parse_formula(text)) is bounded


def test_standing_least_violating_choice_is_the_same(tmp_path: Path, kept: list) -> None:
    # stopped half across the lane marking while the next lane's traffic closes in from behind:
    # the least-violating choice compares every candidate's worst robustness; dropped candidates
    # whose prefix bound could beat the best are judged in full
    w, rs = highway_world(tmp_path, GAP, "{id: passing, behaviour: constant_velocity, start: {lane: left, s: 14}, speed: 14}")
    for samples in (40, 200):
        kept.clear()
        d = _pair(w, rs, 0.0, np.tile([-0.4, 2.0], (10, 1)), samples=samples, y=1.5, psi=0.15)
        assert d.decision == "least_violation"
        assert any(n < k for n, k in kept)  # screening dropped some
