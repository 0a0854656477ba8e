"""The traffic scenarios (scenarios/traffic/) in the closed loop: each is simulated with the real
controller and safety layer, judged against its own ``expect:`` (as ``twolevel simulate`` judges
it), and its traffic is stepped again against the recorded ego to check what the scenario is
about — traffic that lets the ego in, a cut-in written with primitives, cars passing a parked one,
pedestrians at a crosswalk, a cyclist, an all-way stop."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.sim.engine import simulate_scenario
from twolevel.verdict.judge import judge_run
from twolevel.world.loader import load_scenario
from twolevel.world.traffic.ego import MERGE_AHEAD, MERGE_SPEED
from twolevel.world.world import World, build_world

from helpers.traffic_worlds import replay

ROOT = Path(__file__).resolve().parents[2]
TRAFFIC = ROOT / "scenarios" / "traffic"
DT = 0.1


def _run(tmp_path: Path, name: str) -> tuple[World, list, list[dict[str, float]]]:
    """Simulate scenario ``name``, assert it meets its own criteria, and replay its traffic."""
    path = TRAFFIC / f"{name}.yaml"
    summary, diags = simulate_scenario(str(path), str(tmp_path / name), frames=False, ttr_every=0)
    assert summary is not None and summary.status == "complete", [d.message for d in diags]
    verdict, _ = judge_run(summary.run_dir, str(path))
    assert verdict.passed, [c.detail for c in verdict.failed]
    w = build_world(load_scenario(path)[0])
    states, rows = replay(w, Path(summary.run_dir) / "trace.csv")
    return w, states, rows


def _col(states: list, field: str, i: int) -> np.ndarray:
    return np.array([getattr(st, field)[i] for st in states])


def _ids(w: World) -> dict[str, int]:
    return {pid: i for i, pid in enumerate(w.parts.ids)}


def _lane(w: World, name: str) -> int:
    return next(k for k, ln in enumerate(w.lanes.lanes) if ln.id == name)


@pytest.mark.slow
def test_merge_traffic_lets_the_ego_in(tmp_path: Path) -> None:
    w, states, rows = _run(tmp_path, "merge")
    ramp = _lane(w, "ramp")
    ego_lane, ego_s, _ = w.lanes.lookup(np.array([[r["x"], r["y"]] for r in rows]),
                                        heading=np.array([r["psi"] for r in rows]))
    to_end = np.where(ego_lane == ramp, w.lanes.length[ramp] - ego_s, np.inf)
    signalling = (to_end <= MERGE_AHEAD) & (np.array([r["v"] for r in rows]) >= MERGE_SPEED)
    assert signalling.any()
    acc = np.array([st.memory.accel for st in states[1:len(rows) + 1]])  # (T, N)
    braked = acc[signalling].min()
    assert -0.5 * 4.0 - 1e-9 <= braked < -0.3  # somebody opened a gap, within politeness · b_safe
    assert all(_col(states, "lane", i)[-1] in (-1, _lane(w, "main_b")) for i in range(len(w.parts.ids)))


@pytest.mark.slow
def test_cut_in_by_primitives_brakes_to_a_stop_in_the_egos_lane(tmp_path: Path) -> None:
    w, states, rows = _run(tmp_path, "cut_in")
    c = _ids(w)["cutter"]
    lane, v = _col(states, "lane", c), _col(states, "v", c)
    right = _lane(w, "right")
    changed = int(np.argmax(lane == right))
    assert lane[0] == _lane(w, "left") and (lane[changed:] == right).all()  # it cut in and stayed
    standing = (v < 0.05) & (lane == right)
    assert standing.sum() * DT >= 3.0 - 1e-9 and v[-1] > 5.0  # stood 3 s, drove off
    assert min(r["v"] for r in rows) < 0.5  # the ego stopped behind it


@pytest.mark.slow
def test_parked_cars_are_passed_not_queued_behind(tmp_path: Path) -> None:
    w, states, _ = _run(tmp_path, "parked")
    ids = _ids(w)
    half_in = float(w.traffic0.s[ids["half_in"]])
    for name in ("passer_1", "passer_2"):
        i = ids[name]
        lane, s = _col(states, "lane", i), _col(states, "s", i)
        assert (lane == _lane(w, "left")).any()  # it moved over ...
        assert lane[-1] == _lane(w, "right") and s[-1] > half_in + 10  # ... past it, and back


@pytest.mark.slow
def test_pedestrians_cross_at_the_crosswalk_and_cars_stop_for_them(tmp_path: Path) -> None:
    w, states, _ = _run(tmp_path, "crosswalk")
    ids = _ids(w)
    for name in ("from_right", "from_left", "steps_out"):
        assert max(st.memory.phase[ids[name]] for st in states[1:]) == 3  # across
    assert min(min(_col(states, "v", ids[c])) for c in ("car_1", "car_2")) < 0.5  # a car stopped for them


@pytest.mark.slow
def test_a_cyclist_keeps_right_and_the_ego_follows_it(tmp_path: Path) -> None:
    w, states, rows = _run(tmp_path, "cyclist")
    ids = _ids(w)
    bike = ids["cyclist"]
    lat = _col(states, "lateral", bike)
    assert (lat < -1.0).all()  # 0.3 m from the right edge of a 3.5 m lane: −1.125
    x_bike = _col(states, "x", bike)[: len(rows)]
    assert (np.array([r["x"] for r in rows]) < x_bike).all()  # never passed it
    assert min(_col(states, "v", bike)) == pytest.approx(3.0)  # its speed profile


_SPANS = {"east": (-3.5, 0.0), "west": (0.0, 3.5), "north": (100.0, 103.5), "south": (96.5, 100.0)}
"""Where each lane of the all-way stop runs across the other street: y (east, west) or x (north,
south) [m]. Lanes of the two streets cross in the squares these spans make."""


def _boxes(x: np.ndarray, y: np.ndarray, psi: np.ndarray, hl: np.ndarray | float, hw: np.ndarray | float
           ) -> tuple[np.ndarray, ...]:
    """Axis-aligned bounds (x0, x1, y0, y1) [m] of boxes (centre, heading, half length and width)."""
    c, s = np.abs(np.cos(psi)), np.abs(np.sin(psi))
    ex, ey = hl * c + hw * s, hl * s + hw * c
    return x - ex, x + ex, y - ey, y + ey


@pytest.mark.slow
def test_an_all_way_stop_with_idm_traffic_giving_way(tmp_path: Path) -> None:
    w, states, rows = _run(tmp_path, "four_way_stop")
    T = len(rows)
    x, y, psi = (np.array([getattr(st, f) for st in states[:T]]) for f in ("x", "y", "psi"))
    active = np.array([st.active for st in states[:T]])
    ego = np.array([[r["x"], r["y"], r["psi"]] for r in rows])
    # every body (participants, then the ego) with the lane it comes along
    lanes = [w.lanes.lanes[ln].id for ln in w.traffic0.lane] + ["east"]
    bx = [np.column_stack([a, b]) for a, b in zip(_boxes(x, y, psi, w.parts.length / 2, w.parts.width / 2),
                                                    _boxes(ego[:, 0], ego[:, 1], ego[:, 2], w.ego.length / 2,
                                                           w.ego.width / 2))]
    on = np.column_stack([active, np.ones(T, bool)])
    for ew in ("east", "west"):
        for ns in ("north", "south"):  # the square where lanes ew and ns cross: one body at a time
            (y0, y1), (x0, x1) = _SPANS[ew], _SPANS[ns]
            inside = on & (bx[0] < x1 - 0.05) & (bx[1] > x0 + 0.05) & (bx[2] < y1 - 0.05) & (bx[3] > y0 + 0.05)
            a = inside[:, [k for k, ln in enumerate(lanes) if ln == ew]].any(axis=1)
            b = inside[:, [k for k, ln in enumerate(lanes) if ln == ns]].any(axis=1)
            assert not (a & b).any(), (ew, ns)
    last = states[T - 1]
    assert (last.served >= 0).all()  # everybody stood at its line, and went
    assert (~last.active | (last.s > 110)).all()  # across the crossing (or off the map beyond it)
