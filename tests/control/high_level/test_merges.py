"""Waiting at a merge with no sign for a gap the safety layer can prove
(:mod:`twolevel.control.high_level.merges`): where the merges and their lines are on the shipped
maps, when the line binds, and in closed loop the regressions it fixes — on scenarios/traffic/
merge.yaml and merge_sparse.yaml the ego arrived beside a car where the lanes meet and the
safety layer braked at 8.9 m/s²."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from twolevel.control.high_level.merges import merge_line, route_merges
from twolevel.control.high_level.right_of_way import RUN_UP
from twolevel.sim.trace import read_run

from helpers.judged_runs import judged_run
from helpers.world_files import load_world

ROOT = Path(__file__).resolve().parents[3]
TRAFFIC = ROOT / "scenarios" / "traffic"


@pytest.fixture(scope="module")
def world():
    return load_world(TRAFFIC / "merge.yaml")


def _corner_gap(w, s: float) -> float:
    """[m] How far the nearest corner of the ego's box, centred on the route at ``s`` [m] and
    turned with it, is outside main_a's lane (negative: inside)."""
    main_a = w.lanes.index["main_a"]
    (x, y), h = w.route.position(np.array([s]))[0], float(w.route.heading_at(np.array([s]))[0])
    c, n = np.array([math.cos(h), math.sin(h)]), np.array([-math.sin(h), math.cos(h)])
    pts = np.array([[x, y] + a * w.ego.length / 2 * c + b * w.ego.width / 2 * n for a in (1, -1) for b in (1, -1)])
    _, lat = w.lanes.project(np.full(4, main_a), pts)
    return float(np.min(np.abs(lat)) - w.lanes.width[main_a] / 2)


def test_the_ramp_merges_into_main_b_and_its_line_keeps_d_safe_from_main_a(world) -> None:
    rm = route_merges(world)
    assert rm.s.shape == (1,) and list(rm.lane) == [world.lanes.index["main_a"]]
    # where main_b begins on the route: the ramp's length after the route's start on it (s = 20 m)
    assert rm.s[0] == pytest.approx(world.lanes.length[world.lanes.index["ramp"]] - 20.0, abs=0.5)
    contact = rm.line[0] + RUN_UP
    assert rm.line[0] < contact < rm.s[0]
    assert _corner_gap(world, contact) <= world.settings.D_safe + 1e-6
    assert _corner_gap(world, contact - 1.0) > world.settings.D_safe  # the first such place (0.5 m vertices)


def test_no_merge_at_a_junction_or_on_a_single_road() -> None:
    # merge_yield's merge is a junction (the ramp yields by rule); traffic_rules' route has none
    assert not route_merges(load_world(ROOT / "scenarios" / "everyday" / "merge_platoon.yaml")).s.size
    assert not route_merges(load_world(ROOT / "scenarios" / "traffic_rules.yaml")).s.size


def _line(w, *, s0: float, v0: float = 12.0, traffic=None) -> float:
    tr = w.traffic0 if traffic is None else traffic
    xy = tuple(float(c) for c in w.route.position(np.array([s0]))[0])
    return merge_line(w, tr, xy, s0, v0)


def test_waits_while_a_car_could_get_there_first(world) -> None:
    line = route_merges(world).line[0]
    assert _line(world, s0=60.0) == pytest.approx(line)  # the platoon is coming
    tr = world.traffic0
    assert math.isinf(_line(world, s0=60.0, traffic=replace(tr, active=np.zeros_like(tr.active))))  # nobody
    # only the last car, far back on main_a, slow: the ego can be past the merge first
    far = replace(tr, active=np.arange(len(tr.active)) == len(tr.active) - 1, s=np.zeros_like(tr.s),
                  v=np.full_like(tr.v, 2.0))
    assert math.isinf(_line(world, s0=line - 10.0, v0=10.0, traffic=far))


def test_crept_past_the_line_it_stops_where_it_is_and_once_at_main_a_it_has_committed(world) -> None:
    line = route_merges(world).line[0]
    assert _line(world, s0=line + 0.3, v0=0.4) == pytest.approx(line + 0.3 + 0.4**2 / (2 * world.settings.comfort.decel))
    assert math.isinf(_line(world, s0=line + RUN_UP + 0.1))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["merge", "merge_sparse"])
def test_the_ego_waits_before_the_lanes_meet_instead_of_braking_hard(tmp_path: Path, name: str) -> None:
    """Regression: both runs needed the safety layer's full braking (8.9 m/s², 87 and 35
    fail-safe steps); now every step is the plan's, within 4 m/s² (the runs' max_decel)."""
    run = judged_run(TRAFFIC / f"{name}.yaml", tmp_path / name)
    cols = read_run(run).columns
    w = load_world(TRAFFIC / f"{name}.yaml")
    assert set(np.unique(cols["decision"])) == {"mpc"}
    standing = cols["v"] < 0.05
    # it never stood with its box within D_safe of main_a (the line holds it before)
    assert all(_corner_gap(w, s) > w.settings.D_safe - 0.1 for s in cols["s"][standing])
    assert cols["s"][-1] > route_merges(w).s[0] + 200.0  # on main_b, at the goal
    if name == "merge_sparse":
        assert standing.sum() * w.settings.dt <= 0.5  # the car went first, the ego joined behind it
